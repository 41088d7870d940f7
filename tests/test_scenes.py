"""The scene library (robots/*.toml) and Scene built in code, checked independently.

Every scene file states its expected outcome in its comment header. Here each one is solved
with ``pinsettle.solve`` and the answer is checked against a reference written with pinocchio
and numpy only (tests/scene_reference.py): the scene file is read again with tomllib, the
model is built again with ``pinocchio.buildModelFromUrdf`` (and ``buildReducedModel`` for
locked joints), and the net static generalized force of gravity, springs and loads is
recomputed from Jacobians.
pinsettle's own ``static_force``/``residual`` serve only as something to cross-check against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import contact_reference  # tests/contact_reference.py
import loop_reference  # tests/loop_reference.py (pytest puts tests/ on sys.path)
import numpy as np
import pinocchio
import pinsettle
import pytest
from scene_reference import Reference, wrap
from scipy.optimize import brentq, fsolve

ROBOTS = Path(__file__).parents[1] / "robots"
SCENES = sorted(p.stem for p in ROBOTS.glob("*.toml"))
PENDULUM_URDF = ROBOTS / "pendulum.urdf"
SLIDER_URDF = ROBOTS / "slider.urdf"
PLANAR_URDF = ROBOTS / "planar_3link.urdf"
DISK_URDF = ROBOTS / "torque_disk.urdf"

# Largest acceptable net static force at a converged answer (N m or N), recomputed by the
# reference: the default runs (Newton's polish on) end at round-off, at most 1.95e-14 measured
# over every solve of this module (loads up to ~1,000 N m); 100 times that.
MAX_RESIDUAL = 2e-12
# How far (rad or m) a converged answer may be from the reference's own rest (scipy's fsolve on
# the reference force, the neutral joints and the joints pressed on a stop held): at most
# 2.2e-14 measured (panda_fingers_locked); 100 times that. Fixed, not grown with the residual
# the solver reports: a solver that stopped early is as far off as it is.
MAX_DISTANCE = 2e-12


# The reference: scene physics re-implemented with pinocchio (tests/scene_reference.py).


def pair(
    model: pinocchio.Model,
    *,
    gravity=None,
    start=None,
    locked=(),
    joint_springs=(),
    springs=(),
    joint_loads=(),
    point_loads=(),
) -> tuple[pinsettle.Scene, Reference]:
    """The same elements given to a pinsettle.Scene (through its API) and to a Reference."""
    scene = pinsettle.Scene(model, gravity=gravity)
    full = pinocchio.Model(model)
    if gravity is not None:
        full.gravity = pinocchio.Motion(np.array(gravity, float), np.zeros(3))
    ref = Reference(full, locked=list(locked), start=dict(start or {}))
    scene.set_start(start or {})
    scene.lock(*locked)
    for joint, k, rest in joint_springs:
        scene.add_joint_spring(joint, k, rest)
        ref.joint_springs.append((joint, k, rest))
    for fa, pa, fb, pb, k, rest_length in springs:
        scene.add_spring((fa, pa), {"frame": fb, "point": pb}, k, rest_length)
        ref.springs.append((fa, np.array(pa, float), fb, np.array(pb, float), k, rest_length))
    for joint, effort in joint_loads:
        scene.add_load(joint, effort)
        ref.joint_loads.append((joint, np.atleast_1d(np.array(effort, float))))
    for frame, point, force, torque in point_loads:
        scene.add_load(frame=frame, point=point, force=force, torque=torque)
        ref.point_loads.append(
            (frame, np.array(point, float), np.array(force, float), np.array(torque, float))
        )
    return scene, ref


# --- what each scene file says it does (numbers copied from its comment header) --------------


@dataclass(frozen=True)
class Expected:
    """Joint values and stiffness eigenvalues as written in a scene's comment header.

    ``neutral`` joints can take any value at an equilibrium; their numbers are those of the
    run the comment describes, and only the pose's difference across the neutral directions is
    checked against them (test_scene_neutral_directions). ``eigen_range`` is (smallest,
    largest) where the comment gives only those. ``at_limit``: the joints resting on a stop
    and which ('lower' or 'upper'); the eigenvalues are then those of the stiffness restricted
    to the other joints.
    """

    joints: dict[str, str] = field(default_factory=dict)
    eigenvalues: tuple[str, ...] = ()
    eigen_range: tuple[str, str] | None = None
    neutral: tuple[str, ...] = ()
    stable: bool = True  # False: stable-or-neutral (zero eigenvalues along ``neutral``)
    at_limit: dict[str, str] = field(default_factory=dict)


EXPECTED = {
    "pendulum": Expected({"hinge": "0"}, ("9.81",)),
    "bistable_pendulum": Expected({"hinge": "0.637354"}, ("35.63",)),
    "chain20": Expected({f"joint{i}": "0" for i in range(1, 21)}, eigen_range=("0.0336", "108.0")),
    "double_pendulum_springs": Expected(
        {"joint1": "0.738965", "joint2": "-0.105215"}, ("0.645", "1.514")
    ),
    "panda_fingers_locked": Expected(
        {
            "panda_joint1": "0.080985",
            "panda_joint2": "1.7628",
            "panda_joint3": "-0.010341",
            "panda_joint4": "-1.656010",
            "panda_joint5": "0.706446",
            "panda_joint6": "2.414132",
            "panda_joint7": "-0.899372",
            "panda_finger_joint1": "0.02",
            "panda_finger_joint2": "0.02",
        },
        ("0", "0.0258", "0.1511", "2.554", "23.68", "29.94"),
        neutral=("panda_joint1",),
        stable=False,
        at_limit={"panda_joint2": "upper"},
    ),
    "panda": Expected(
        {
            "panda_joint1": "0.081483",
            "panda_joint2": "1.7628",
            "panda_joint3": "-0.010341",
            "panda_joint4": "-1.656015",
            "panda_joint5": "0.706973",
            "panda_joint6": "2.412858",
            "panda_joint7": "-0.917299",
            "panda_finger_joint1": "0.04",
            "panda_finger_joint2": "0",
        },
        ("0", "0.0305", "0.1513", "2.558", "23.68", "29.94"),
        neutral=("panda_joint1",),
        stable=False,
        at_limit={
            "panda_joint2": "upper",
            "panda_finger_joint1": "upper",
            "panda_finger_joint2": "lower",
        },
    ),
    "xarm7": Expected(
        {
            "joint1": "-0.003254",
            "joint2": "2.0944",
            "joint3": "0.045640",
            "joint4": "1.802980",
            "joint5": "0.357910",
            "joint6": "0.756170",
            "joint7": "1.497062",
        },
        ("0", "0.00964", "0.08342", "1.0277", "12.11", "12.91"),
        neutral=("joint1",),
        stable=False,
        at_limit={"joint2": "upper"},
    ),
    "planar_3link_spring": Expected(
        {"joint1": "-0.138592", "joint2": "-0.144181", "joint3": "-1.566479"},
        ("2.00", "8.83", "180.06"),
    ),
    "slider_spring": Expected({"slider": "-0.03924"}, ("500",)),
    "ur5": Expected(
        {
            "shoulder_pan_joint": "-0.1385",
            "shoulder_lift_joint": "1.570796",
            "elbow_joint": "0",
            "wrist_1_joint": "-1.570796",
            "wrist_2_joint": "-0.1385",
            "wrist_3_joint": "0.0409",
        },
        ("0", "0", "0", "0.1725", "10.69", "64.51"),
        neutral=("shoulder_pan_joint", "wrist_2_joint", "wrist_3_joint"),
        stable=False,
    ),
    "pendulum_upright": Expected({"hinge": "0"}, ("9.81",)),
    "ur5_saddle": Expected(
        {
            "shoulder_pan_joint": "0.0098",
            "shoulder_lift_joint": "1.570796",
            "elbow_joint": "0",
            "wrist_1_joint": "-1.570796",
            "wrist_2_joint": "0.0362",
            "wrist_3_joint": "3.1420",
        },
        ("0", "0", "0", "0.1725", "10.69", "64.51"),
        neutral=("shoulder_pan_joint", "wrist_2_joint", "wrist_3_joint"),
        stable=False,
    ),
    "ur5_tool_spring": Expected(
        {
            "shoulder_pan_joint": "0.150114",
            "shoulder_lift_joint": "1.065076",
            "elbow_joint": "-2.293533",
            "wrist_1_joint": "3.818607",
            "wrist_2_joint": "-1.487249",
            "wrist_3_joint": "-2.1290",
        },
        ("0", "3.76", "5.97", "21.5", "36.7", "129.0"),
        neutral=("wrist_3_joint",),
        stable=False,
    ),
}
EQUILIBRIUM_SCENES = sorted(EXPECTED)
# Scenes without an equilibrium: the potential falls without bound.
NO_EQUILIBRIUM_SCENES = ["free_fall", "overloaded_pendulum", "torque_disk"]
# Scenes that start at rest exactly on an unstable equilibrium.
UNSTABLE_START_SCENES = ["pendulum_upright", "ur5_saddle"]
# Closed-loop scenes: tests/test_loops.py checks them (closed form, SLSQP, header numbers).
# Loop scenes, checked in tests/test_loops.py (and, with a stop, tests/test_limits.py).
LOOP_SCENES = sorted([*loop_reference.MECHANISMS, "fourbar_stop"])
# Checked by tests/test_contacts.py against tests/contact_reference.py.
CONTACT_SCENES = contact_reference.CONTACT_SCENES

# Points named in the comments: (scene, frame, point in the frame, world position as written).
POSITIONS = [
    ("bistable_pendulum", "arm", (0.0, 0.0, -1.0), ("-0.5951", None, "-0.8037")),
    ("planar_3link_spring", "link3", (0.0, 0.0, -0.5), ("0.6893", "0", "-0.8379")),
    ("ur5", "tool0", (0.0, 0.0, 0.0), (None, None, "-0.823")),
    ("panda_fingers_locked", "panda_hand_tcp", (0.0, 0.0, 0.0), (None, None, "-0.393")),
    ("panda", "panda_hand_tcp", (0.0, 0.0, 0.0), (None, None, "-0.392")),
    ("xarm7", "link_eef", (0.0, 0.0, 0.0), (None, None, "-0.389")),
    ("ur5_tool_spring", "tool0", (0.0, 0.0, 0.0), ("0.3365", "0.1682", "0.2104")),
]


def rounding(text: str) -> float:
    """Half a unit of the last digit written: the rounding error of a number in a comment (a
    number written without a decimal point, like 0 or 500, is exact)."""
    if "." not in text:
        return 0.0
    return 0.5 * 10.0 ** -len(text.split(".")[1])


def header(name: str) -> str:
    """The comment header of a scene file."""
    lines = (ROBOTS / f"{name}.toml").read_text(encoding="utf-8").splitlines()
    return "\n".join(line for line in lines if line.startswith("#"))


@pytest.fixture(scope="module")
def solved():
    """Each library scene loaded, solved with its own settings, and its Reference: once."""
    cache: dict[str, tuple[pinsettle.Scene, pinsettle.Result, Reference]] = {}

    def get(name: str):
        if name not in cache:
            path = ROBOTS / f"{name}.toml"
            scene = pinsettle.load_scene(path)
            cache[name] = (scene, pinsettle.solve(scene), Reference.from_toml(path))
        return cache[name]

    return get


def pressed_joints(ref: Reference, q_full: np.ndarray) -> list[str]:
    """The joints resting on a stop at q_full whose stop pushes (a reaction beyond 1e-9 of the
    largest static force: the one the stability verdict counts as held), by the reference."""
    model = ref.reduced(q_full)
    q = ref.to_reduced(model, q_full)
    force = ref.force_reduced(model, q)
    contacts = ref.rest_conditions(model, q, force)[1]
    tol = 1e-9 * np.max(np.abs(force), initial=0.0)
    return [name for name, (_, reaction) in contacts.items() if reaction > tol]


def restricted_stiffness(ref: Reference, q_full: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """The reference stiffness (finite differences) restricted to the velocity indices of the
    joints not pressed on a stop, and those indices."""
    model = ref.reduced(q_full)
    q = ref.to_reduced(model, q_full)
    k = ref.stiffness_reduced(model, q)
    held = set()
    for name in pressed_joints(ref, q_full):
        j = model.getJointId(name)
        held.update(range(model.idx_vs[j], model.idx_vs[j] + model.nvs[j]))
    free = [i for i in range(model.nv) if i not in held]
    return k[np.ix_(free, free)], free


def independent_root(ref: Reference, q_full: np.ndarray, neutral=()) -> np.ndarray:
    """An equilibrium found by scipy's fsolve on the Reference force, started at q_full, with
    the neutral joints held at their value there (their stiffness is zero), and the joints
    pressed on a stop held on it (their force is taken by the stop)."""
    neutral = (*neutral, *pressed_joints(ref, q_full))
    model = ref.reduced(q_full)
    q0 = ref.to_reduced(model, q_full)
    fixed = {model.idx_vs[model.getJointId(name)] for name in neutral}
    free = [i for i in range(model.nv) if i not in fixed]

    def q_of(x):
        dv = np.zeros(model.nv)
        dv[free] = x
        return pinocchio.integrate(model, q0, dv)

    x = fsolve(
        lambda x: ref.force_reduced(model, q_of(x))[free],
        np.zeros(len(free)),
        xtol=1e-14,
        full_output=True,  # no warning when it cannot improve on round-off; checked by callers
    )[0]
    return ref.to_full(model, q_of(x), q_full)


# --- the reference itself is right -----------------------------------------------------------


def test_the_library_is_covered():
    # Every scene file has a header with its expectation, and this module checks all of them.
    assert SCENES == sorted([*EXPECTED, *NO_EQUILIBRIUM_SCENES, *LOOP_SCENES, *CONTACT_SCENES])
    for name in SCENES:
        assert "Expected:" in header(name), name
    assert pinsettle.scene_names() == SCENES  # the installed library is this folder


@pytest.mark.parametrize("name", EQUILIBRIUM_SCENES)
def test_expected_numbers_are_those_of_the_header(name):
    # The numbers in EXPECTED were copied from the comments: they must still be there.
    text = header(name)
    for value in [*EXPECTED[name].joints.values(), *EXPECTED[name].eigenvalues]:
        assert value.lstrip("-") in text, (name, value)


@pytest.mark.parametrize(  # loops: test_loops; contacts: test_contacts
    "name", [n for n in SCENES if n not in LOOP_SCENES and n not in CONTACT_SCENES]
)
def test_reference_agrees_with_scene_static_force(name, solved):
    scene, result, ref = solved(name)
    assert np.array_equal(ref.q_start(), scene.q0())
    rng = np.random.default_rng(sum(map(ord, name)))
    configurations = [scene.q0(), result.q] + [ref.random_configuration(rng) for _ in range(6)]
    for q in configurations:
        expected = ref.force(q)
        got = scene.static_force(q)
        assert got.shape == expected.shape
        scale = max(1.0, np.max(np.abs(expected)))
        assert np.allclose(got, expected, rtol=1e-9, atol=1e-9 * scale), (q, got, expected)
        # With stops, the residual of a rest against them (q may be outside their range).
        assert scene.residual(q) == pytest.approx(ref.rest_residual(q), rel=1e-9, abs=1e-12)


def mixed_scenes():
    """Scenes built in code with every kind of element, on several joint types."""
    ur5 = pinsettle.load_robot("ur5")
    yield pair(
        ur5,
        joint_springs=[("elbow_joint", 15.0, 0.4)],
        springs=[
            ("forearm_link", (0.1, 0.0, 0.2), "upper_arm_link", (0.0, 0.05, 0.3), 80.0, 0.1),
            ("tool0", (0.0, 0.0, 0.1), "universe", (0.3, -0.2, 0.5), 50.0, 0.0),
        ],
        joint_loads=[("wrist_1_joint", 0.7)],
        point_loads=[("forearm_link", (0.0, 0.1, 0.2), (3.0, -2.0, 5.0), (0.4, 0.2, -0.3))],
    )
    panda = pinsettle.load_robot("panda")
    yield pair(
        panda,
        gravity=[1.0, -2.0, -9.0],
        start={"panda_finger_joint1": 0.03, "panda_finger_joint2": 0.01, "panda_joint4": -1.5},
        locked=["panda_finger_joint1", "panda_finger_joint2"],
        springs=[("panda_leftfinger", (0.0, 0.01, 0.04), "universe", (0.5, 0.0, 0.3), 30.0, 0.05)],
        point_loads=[("panda_rightfinger", (0.0, 0.0, 0.02), (0.0, 4.0, 0.0), (0.0, 0.0, 0.5))],
        joint_loads=[("panda_joint2", -1.0)],
    )
    # Continuous joints, stored as (cos, sin): springs with a rest near pi wrap around.
    continuous = pinsettle.load_robot("double_pendulum_continuous")
    names = [continuous.names[1], continuous.names[2]]
    yield pair(
        continuous,
        joint_springs=[(names[0], 2.0, math.pi - 0.1), (names[1], 1.0, -3.0)],
        joint_loads=[(names[1], 0.2)],
    )
    # A free-flyer root (quaternion) with a spring to the world and loads on the root.
    floating = pinsettle.load_urdf(PENDULUM_URDF, floating=True)
    yield pair(
        floating,
        start={"root_joint": [0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0], "hinge": 0.5},
        springs=[("arm", (0.0, 0.0, -1.0), "universe", (1.0, 0.0, 0.0), 20.0, 0.3)],
        joint_loads=[("root_joint", [1.0, 0.0, -2.0, 0.1, 0.2, 0.0])],
        point_loads=[("base", (0.1, 0.0, 0.0), (0.0, 0.0, 5.0), (0.0, 0.3, 0.0))],
    )


@pytest.mark.parametrize("index", range(4), ids=["ur5", "panda-locked", "continuous", "floating"])
def test_reference_agrees_with_scene_static_force_for_every_element(index):
    scene, ref = list(mixed_scenes())[index]
    rng = np.random.default_rng(index)
    for _ in range(6):
        q = ref.random_configuration(rng)
        expected = ref.force(q)
        scale = max(1.0, np.max(np.abs(expected)))
        assert np.allclose(scene.static_force(q), expected, rtol=1e-9, atol=1e-9 * scale)


@pytest.mark.parametrize(
    "name",
    ["bistable_pendulum", "planar_3link_spring", "double_pendulum_springs", "ur5_tool_spring"],
)
def test_static_force_is_the_gradient_of_the_potential(name, solved):
    # V = gravity potential + spring energies; its gradient along each tangent direction,
    # by central differences, is the static force of the reference and of the scene.
    scene, _, ref = solved(name)
    model = ref.full
    rng = np.random.default_rng(1)
    h = 1e-6
    for _ in range(4):
        q = ref.random_configuration(rng)
        gradient = np.zeros(model.nv)
        for i in range(model.nv):
            step = np.zeros(model.nv)
            step[i] = h
            plus = ref.potential_reduced(model, pinocchio.integrate(model, q, step))
            minus = ref.potential_reduced(model, pinocchio.integrate(model, q, -step))
            gradient[i] = (plus - minus) / (2 * h)
        scale = max(1.0, np.max(np.abs(gradient)))
        assert np.allclose(ref.force(q), gradient, rtol=0.0, atol=1e-6 * scale)
        assert np.allclose(scene.static_force(q), gradient, rtol=0.0, atol=1e-6 * scale)


def test_continuous_potential_gradient_with_wrapped_springs():
    scene, ref = list(mixed_scenes())[2]
    model = ref.full
    h = 1e-6
    rng = np.random.default_rng(5)
    for _ in range(6):
        q = ref.random_configuration(rng, scale=3.0)
        gradient = np.zeros(model.nv)
        for i in range(model.nv):
            step = np.zeros(model.nv)
            step[i] = h
            plus = ref.potential_reduced(model, pinocchio.integrate(model, q, step))
            minus = ref.potential_reduced(model, pinocchio.integrate(model, q, -step))
            gradient[i] = (plus - minus) / (2 * h)
        # Loads are not in the potential: remove the joint load from the force.
        force = scene.static_force(q)
        force[1] += 0.2
        assert np.allclose(force, gradient, rtol=0.0, atol=1e-6)


# --- every scene of the library gives its stated outcome --------------------------------------


@pytest.mark.parametrize("name", EQUILIBRIUM_SCENES)
def test_scene_converges_to_an_equilibrium(name, solved):
    scene, result, ref = solved(name)
    assert result.status == "converged" and result.converged
    assert result.q.shape == (scene.model.nq,)
    residual = ref.rest_residual(result.q)  # the plain residual when nothing rests on a stop
    assert residual < MAX_RESIDUAL
    contacts = ref.contacts(result.q)
    assert {name: side for name, (side, _) in contacts.items()} == EXPECTED[name].at_limit
    assert result.at_limit == EXPECTED[name].at_limit
    # The residual reported is the one recomputed independently, up to the round-off of two
    # different sums over forces of ~10 N m (1e-14 N m).
    assert result.residual == pytest.approx(residual, rel=1e-9, abs=1e-13)
    # At rest: the stopping rule bounds the energy of the final state.
    assert result.kinetic_energy <= result.settings.max_e
    assert result.joints == scene.joint_values(result.q)


@pytest.mark.parametrize("name", EQUILIBRIUM_SCENES)
def test_scene_joint_values_are_the_stated_ones(name, solved):
    scene, result, ref = solved(name)
    expected = EXPECTED[name]
    root = independent_root(ref, result.q, expected.neutral)
    assert ref.rest_residual(root) < 1e-10
    assert np.max(np.abs(root - result.q)) <= MAX_DISTANCE, np.abs(root - result.q)
    root_values = scene.joint_values(root)
    assert list(result.joints) == [scene.model.names[j] for j in range(1, scene.model.njoints)]
    for joint, text in expected.joints.items():
        if joint in expected.neutral:
            continue  # anywhere along its neutral direction: test_scene_neutral_directions
        value = float(text)
        assert result.joints[joint] == pytest.approx(value, abs=rounding(text) + MAX_DISTANCE)
        # The exact equilibrium (scipy) matches the comment to its last digit or 1e-6.
        assert abs(root_values[joint] - value) <= max(rounding(text), 1e-6), joint


@pytest.mark.parametrize(
    "name, overrides",
    [
        ("planar_3link_spring", {"dt": 0.2}),
        ("ur5_tool_spring", {"dt_safety": 1.0}),
        ("xarm7", {"dt_safety": 1.0}),
    ],
)
def test_energy_the_step_made_is_no_runaway(name, overrides, solved):
    # A step too large for a mechanism makes energy of its own. Its bursts, cut short by the
    # damping events, travel far and release ever more, as a fall does, and these runs ended
    # `no_equilibrium`. But gravity and the springs did a tiny fraction of that work on the
    # way: such a runaway is rolled back with the step halved, and the mechanism settles at the
    # rest the default settings find (checked by the reference physics).
    # Newton's takeover off: the guard is the damping's (with it, ur5_tool_spring is taken to
    # its rest at step 13, before its step makes any energy).
    scene, default, ref = solved(name)
    result = pinsettle.solve(scene, newton_takeover=False, **overrides)
    assert result.status == "converged", result.reason
    assert result.dt_reductions >= 1
    assert ref.rest_residual(result.q) < MAX_RESIDUAL
    assert result.stability == default.stability
    if not EXPECTED[name].neutral:
        assert np.max(np.abs(result.q - default.q)) < 1e-9


def stated_pose(scene: pinsettle.Scene, q: np.ndarray, joints: dict[str, str]) -> np.ndarray:
    """q with the 1-DoF joints of ``joints`` set to the values written (continuous joints
    as their angle)."""
    model = scene.model
    q = q.copy()
    for joint, text in joints.items():
        j = model.getJointId(joint)
        i = model.idx_qs[j]
        if model.nqs[j] == 2:  # continuous: (cos, sin)
            q[i : i + 2] = math.cos(float(text)), math.sin(float(text))
        else:
            assert model.nqs[j] == 1, joint
            q[i] = float(text)
    return q


@pytest.mark.parametrize("name", [n for n in EQUILIBRIUM_SCENES if EXPECTED[n].neutral])
def test_scene_neutral_directions(name, solved):
    # A neutral joint can end anywhere along its neutral direction: the value the header gives
    # is that of one run, and pinning it would test nothing but the path taken. What is checked
    # instead: the rest is an equilibrium, the verdict is neutral with as many zero directions
    # as the header says, and the answer differs from the header's pose only along the zero
    # directions of the reference stiffness there (its eigenvectors, not a choice of joints).
    scene, result, ref = solved(name)
    expected = EXPECTED[name]
    assert ref.rest_residual(result.q) < MAX_RESIDUAL
    # The reference's own rest with the neutral joints where the solver left them.
    root = independent_root(ref, result.q, expected.neutral)
    assert np.max(np.abs(root - result.q)) <= MAX_DISTANCE, np.abs(root - result.q)
    assert result.stability == "neutral"
    assert result.neutral_directions == len(expected.neutral)
    stated = stated_pose(scene, result.q, expected.joints)
    model = ref.reduced(stated)
    k, free = restricted_stiffness(ref, stated)
    eigenvalues, vectors = np.linalg.eigh(0.5 * (k + k.T))
    top = max(1.0, np.max(np.abs(eigenvalues)))
    zero = np.abs(eigenvalues) <= 1e-6 * top
    assert zero.sum() == len(expected.neutral), eigenvalues
    neutral = vectors[:, zero]  # orthonormal, on the joints off their stops
    step = pinocchio.difference(model, ref.to_reduced(model, stated), ref.to_reduced(model, root))
    off = np.ones(model.nv, dtype=bool)
    off[free] = False
    assert np.max(np.abs(step[off]), initial=0.0) <= 1e-9  # joints on a stop stay there
    across = step[free] - neutral @ (neutral.T @ step[free])
    # The reference's rest differs from the header's pose by the header's digits (half a unit
    # of the last one) off the neutral directions; the neutral part is free.
    digits = max(
        rounding(text)
        for joint, text in expected.joints.items()
        if model.existJointName(joint) and model.idx_vs[model.getJointId(joint)] in free
    )
    # The header's pose is a rest too, to its digits.
    assert ref.rest_residual(stated) <= MAX_RESIDUAL + top * digits * len(free)
    assert np.max(np.abs(across)) <= digits + MAX_DISTANCE, (across, neutral.T @ step[free])


@pytest.mark.parametrize("name", EQUILIBRIUM_SCENES)
def test_scene_stiffness_eigenvalues_are_the_stated_ones(name, solved):
    scene, result, ref = solved(name)
    expected = EXPECTED[name]
    model = ref.reduced(result.q)
    # On the joints not pressed on a stop (all of them when none is).
    k, free = restricted_stiffness(ref, result.q)
    assert len(free) == model.nv - len(expected.at_limit)
    eigenvalues = np.linalg.eigvalsh(0.5 * (k + k.T))
    top = max(1.0, np.max(np.abs(eigenvalues)))
    # Stable or neutral: no direction of negative stiffness beyond round-off.
    assert eigenvalues.min() > -1e-6 * top, eigenvalues
    neutral = np.abs(eigenvalues) <= 1e-6 * top
    assert neutral.sum() == len(expected.neutral), eigenvalues
    if expected.stable:
        assert eigenvalues.min() > 1e-2, eigenvalues
    else:
        # The zero stiffness is along the neutral joints: moving one of them alone costs
        # nothing (its column of K vanishes); every other direction is stiff.
        for joint in expected.neutral:
            column = k[:, free.index(model.idx_vs[model.getJointId(joint)])]
            assert np.max(np.abs(column)) <= 1e-6 * top, (joint, column)
        # Far from the neutral cut (1e-6 of the largest): xarm7's softest direction is
        # 0.00964 N m/rad for a largest eigenvalue of 12.8.
        assert eigenvalues[~neutral].min() > 1e-4 * top
    if expected.eigenvalues:
        assert len(eigenvalues) == len(expected.eigenvalues)
        for got, text in zip(eigenvalues, expected.eigenvalues, strict=True):
            tol = max(rounding(text), 1e-3 * abs(float(text))) if float(text) else 1e-6 * top
            assert abs(got - float(text)) <= tol, (got, text)
    if expected.eigen_range:
        low, high = expected.eigen_range
        assert eigenvalues[0] == pytest.approx(float(low), abs=rounding(low))
        assert eigenvalues[-1] == pytest.approx(float(high), abs=rounding(high))


@pytest.mark.parametrize("name, frame, point, xyz", POSITIONS, ids=[p[0] for p in POSITIONS])
def test_scene_points_end_where_stated(name, frame, point, xyz, solved):
    _, result, ref = solved(name)
    model = ref.full
    data = model.createData()
    pinocchio.framesForwardKinematics(model, data, result.q)
    position = data.oMf[Reference._frame(model, frame)].act(np.array(point))
    for got, text in zip(position, xyz, strict=True):
        if text is not None:
            assert abs(got - float(text)) <= rounding(text) + 1e-6, (position, xyz)


# --- particular scenes ------------------------------------------------------------------------


def pendulum_constants(model: pinocchio.Model) -> tuple[float, float, float]:
    """(m, g, l) of the pendulum: bob mass, gravity magnitude, distance of the bob below the
    hinge, read from the model."""
    inertia = model.inertias[model.getJointId("hinge")]
    return inertia.mass, float(np.linalg.norm(model.gravity.linear)), -inertia.lever[2]


def bistable_angle(m, g, arm, k, rest_length, h) -> float:
    """theta* of the bistable pendulum from dV/dtheta = 0 (see the scene's header)."""
    d = k * rest_length * h / (k * h + m * g)
    return math.acos((arm**2 + h**2 - d**2) / (2 * arm * h))


def test_pendulum_hangs_straight_down(solved):
    scene, result, ref = solved("pendulum")
    assert np.array_equal(scene.q0(), [1.0])
    assert abs(result.joints["hinge"]) < 1e-6
    m, g, arm = pendulum_constants(ref.full)
    assert ref.eigenvalues(result.q) == pytest.approx([m * g * arm], rel=1e-6)  # 9.81


def test_slider_sags_by_m_g_over_k(solved):
    _, result, ref = solved("slider_spring")
    m = ref.full.inertias[ref.full.getJointId("slider")].mass
    g = -ref.full.gravity.linear[2]
    k = ref.joint_springs[0][1]
    assert (m, g, k) == (2.0, 9.81, 500.0)
    assert result.joints["slider"] == pytest.approx(-m * g / k, abs=1e-8)
    assert ref.eigenvalues(result.q) == pytest.approx([k], rel=1e-6)


@pytest.fixture(scope="module")
def bistable_theta() -> float:
    ref = Reference.from_toml(ROBOTS / "bistable_pendulum.toml")
    m, g, arm = pendulum_constants(ref.full)
    (frame_a, point_a, frame_b, point_b, k, rest_length) = ref.springs[0]
    assert (frame_a, frame_b) == ("arm", "universe") and point_a[2] == -arm
    theta = bistable_angle(m, g, arm, k, rest_length, h=-point_b[2])
    # The reference equilibrium by bracketing: the same angle.
    root = brentq(lambda t: ref.force(np.array([t]))[0], 0.1, 1.5, xtol=1e-14)
    assert root == pytest.approx(theta, abs=1e-10)
    assert theta == pytest.approx(0.637354, abs=5e-7)
    return theta


@pytest.mark.parametrize("start", [0.2, -0.2, 1e-3, -1e-3])
def test_bistable_pendulum_goes_to_the_side_it_starts_on(start, bistable_theta):
    scene = pinsettle.load_scene(ROBOTS / "bistable_pendulum.toml")
    ref = Reference.from_toml(ROBOTS / "bistable_pendulum.toml")
    scene.set_start(hinge=start)
    result = pinsettle.solve(scene)
    assert result.converged
    assert result.joints["hinge"] == pytest.approx(math.copysign(bistable_theta, start), abs=1e-6)
    assert ref.residual(result.q) < MAX_RESIDUAL
    (eigenvalue,) = ref.eigenvalues(result.q)
    assert eigenvalue == pytest.approx(35.63, abs=0.005)  # stable, both sides alike
    # The same through q0 (the scene's own start stays +0.2 then).
    scene.set_start(hinge=0.2)
    again = pinsettle.solve(scene, [start])
    assert np.array_equal(again.q, result.q)


def test_bistable_pendulum_hanging_down_is_an_unstable_equilibrium(bistable_theta):
    scene = pinsettle.load_scene(ROBOTS / "bistable_pendulum.toml")
    ref = Reference.from_toml(ROBOTS / "bistable_pendulum.toml")
    down = np.zeros(1)
    assert ref.residual(down) < 1e-12  # an equilibrium ...
    (eigenvalue,) = ref.eigenvalues(down)
    assert eigenvalue == pytest.approx(-30.19, abs=0.005)  # ... with negative stiffness
    m, g, arm = pendulum_constants(ref.full)
    _, _, _, anchor, k, rest_length = ref.springs[0]
    h = -anchor[2]
    d = h - arm  # the spring's length there: 1 m, 0.5 m short of its rest length
    assert eigenvalue == pytest.approx(m * g * arm + k * (d - rest_length) * arm * h / d, rel=1e-6)
    # Released exactly there, the solver finds the rest unstable, pushes it off along the
    # negative stiffness direction and it falls to one side.
    result = pinsettle.solve(scene, down)
    assert result.converged and result.pushes >= 1 and result.stability == "stable"
    assert abs(result.joints["hinge"]) == pytest.approx(bistable_theta, abs=1e-6)


@pytest.mark.parametrize("energy", ["exact", "simplified"])
@pytest.mark.parametrize("kt", [0.0, 0.5])
def test_each_energy_measure_and_kt(energy, kt, bistable_theta):
    slider = pinsettle.load_scene(ROBOTS / "slider_spring.toml")
    result = pinsettle.solve(slider, energy=energy, kt=kt)
    assert result.converged
    assert (result.settings.energy, result.settings.kt) == (energy, kt)
    assert result.joints["slider"] == pytest.approx(-2.0 * 9.81 / 500.0, abs=1e-8)
    assert slider.settings == pinsettle.Settings()  # overrides do not stick to the scene
    bistable = pinsettle.load_scene(ROBOTS / "bistable_pendulum.toml")
    ref = Reference.from_toml(ROBOTS / "bistable_pendulum.toml")
    for start in (0.2, -0.2):
        result = pinsettle.solve(bistable, [start], energy=energy, kt=kt)
        assert result.converged
        assert ref.residual(result.q) < MAX_RESIDUAL
        assert result.joints["hinge"] == pytest.approx(
            math.copysign(bistable_theta, start), abs=1e-6
        )


def test_the_runaway_verdict_does_not_depend_on_the_stopping_window():
    # The runaway test samples on its own span (100 steps from a reset), not every ds steps: a
    # short stopping window must not call a slow swing's first quarter a runaway sooner.
    scene = pinsettle.load_scene(pinsettle.scene_path("torque_disk"))
    runs = [pinsettle.solve(scene, ds=ds) for ds in (2, 10, 100, 300)]
    assert all(r.status == "no_equilibrium" for r in runs)
    assert len({r.steps for r in runs}) == 1
    assert runs[0].steps > 100 * 2**8


def test_torque_disk_has_no_equilibrium(solved):
    scene, result, ref = solved("torque_disk")
    assert result.status == "no_equilibrium" and not result.converged
    assert "falls without bound" in result.reason
    # Decided by the runaway test, well before any step limit: two runs of at most nine
    # doublings of its first span of 100 steps (eight growths of the release per doubling;
    # the first comparison is of two spans), the second after damping went to kt = 0.
    assert result.steps <= 2 * 100 * 2**9 + 1 < scene.settings.max_steps
    assert result.peaks == 0  # the energy never stops growing
    # Balanced: gravity does nothing, the net static force is the effort, everywhere.
    assert ref.residual(result.q) == pytest.approx(1.0, rel=1e-12)
    assert result.residual == pytest.approx(1.0, rel=1e-12)
    # Uniform acceleration 1 N m / 0.02 kg m^2 = 50 rad/s^2 from rest, whatever the steps.
    inertia = ref.full.inertias[1].inertia[1, 1]
    assert inertia == pytest.approx(0.02)
    speed = result.sim_time / inertia
    assert result.v[0] == pytest.approx(speed, rel=1e-9)
    assert result.kinetic_energy == pytest.approx(0.5 * inertia * speed**2, rel=1e-9)
    traced = pinsettle.solve(scene, trace_every=100)
    assert np.array_equal(traced.q, result.q)
    energy = traced.trace.kinetic_energy
    assert len(energy) > 100 and np.all(np.diff(energy) > 0)
    # The last sample may be of the final state: the step's energy (from the momenta ABA
    # leaves) and the result's (from a forward kinematics pass) then agree to round-off.
    assert energy[-1] <= result.kinetic_energy * (1.0 + 1e-14)


@pytest.mark.parametrize("name", NO_EQUILIBRIUM_SCENES)
def test_no_equilibrium_scenes_are_decided_in_bounded_time(name, solved):
    scene, result, ref = solved(name)
    assert result.status == "no_equilibrium" and not result.converged
    assert "falls without bound" in result.reason
    # By the runaway test (at most two runs of nine doublings of its first span, 100 steps:
    # RunawayMonitor::kFirstSample), not by the step limit.
    assert result.steps <= 2 * 100 * 2**9 + 1 < scene.settings.max_steps
    assert result.dt_reductions == 0 and np.all(np.isfinite(result.q))
    # Far from rest: the net static force stays of the size of the loads.
    assert ref.residual(result.q) == pytest.approx(result.residual, rel=1e-9)
    assert result.residual >= 1.0 - 1e-12  # at least the 1 N m of the weakest load


def test_free_fall_is_named_before_any_step(solved):
    scene, result, ref = solved("free_fall")
    # Nothing holds the floating body: the net force along its free translation is its weight in
    # every pose, so the run ends before its first step, naming the joint and the force.
    assert result.steps == 0 and result.sim_time == 0.0
    assert np.array_equal(result.q, pinocchio.neutral(scene.model))  # its start
    assert "'root_joint'" in result.reason and "9.81 N" in result.reason
    # The force, recomputed independently at random poses: the weight, m g = 9.81 N.
    model = scene.model
    data = model.createData()
    for _ in range(5):
        q = pinocchio.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
        force = pinocchio.computeGeneralizedGravity(model, data, q)[:3]
        assert np.linalg.norm(force) == pytest.approx(9.81, rel=1e-12)
    assert ref.residual(result.q) == pytest.approx(9.81, rel=1e-12)


def test_overloaded_pendulum_turns_the_way_the_load_pushes(solved, tmp_path):
    scene, result, ref = solved("overloaded_pendulum")
    # The load (+40 N m) beats the most spring and gravity can hold (29.81 N m): the hinge
    # turns ever further in the load's direction.
    assert result.joints["hinge"] > 100 * 2 * math.pi
    assert result.v[0] > 0
    # Just below the limit (a 29 N m load) the same arm holds: sin(t) = 29 / 29.81.
    text = (ROBOTS / "overloaded_pendulum.toml").read_text(encoding="utf-8")
    assert text.count("effort = 40.0") == 1
    held = tmp_path / "held.toml"
    held.write_text(text.replace("effort = 40.0", "effort = 29.0"), encoding="utf-8")
    (tmp_path / "pendulum.urdf").write_text(
        (ROBOTS / "pendulum.urdf").read_text(encoding="utf-8"), encoding="utf-8"
    )
    settled = pinsettle.solve(pinsettle.load_scene(held))
    assert settled.converged and settled.stability == "stable"
    assert math.sin(settled.joints["hinge"]) == pytest.approx(29.0 / 29.81, abs=1e-6)


@pytest.mark.parametrize("name", UNSTABLE_START_SCENES)
def test_unstable_start_scenes_reach_a_stable_rest(name, solved):
    scene, result, ref = solved(name)
    start = pinsettle.assess_stability(scene, scene.q0())
    # The start is an equilibrium (within round-off) ...
    assert ref.residual(scene.q0()) < 1e-9
    # ... but not a stable one ...
    assert start.verdict == "unstable" and start.min_eigenvalue < 0
    # ... and the answer is not the start, and is a stable-or-neutral rest.
    assert result.converged and result.stability in ("stable", "neutral")
    assert result.min_stiffness_eigenvalue > -1e-6
    assert np.max(np.abs(result.q - scene.q0())) > 1.0
    assert ref.residual(result.q) < 1e-6


def test_ur5_saddle_is_left_by_a_push(solved):
    scene, result, ref = solved("ur5_saddle")
    # The solver is at rest on the saddle at once (gravity 3e-10 N m), so it must push.
    assert result.pushes >= 1


def test_panda_locked_fingers_stay_exactly_where_they_start(solved):
    scene, result, ref = solved("panda_fingers_locked")
    full = scene.model
    assert full.nq == 9 and result.q.shape == (9,) and result.v.shape == (9,)
    assert scene.compile().model.nv == 7  # the fingers are out of the solve
    for finger in ("panda_finger_joint1", "panda_finger_joint2"):
        j = full.getJointId(finger)
        assert result.q[full.idx_qs[j]] == 0.02  # exactly: never integrated
        assert result.v[full.idx_vs[j]] == 0.0
        assert result.joints[finger] == 0.02
    # Locked elsewhere through q0: they stay at that value instead.
    q0 = scene.q0()
    q0[full.idx_qs[full.getJointId("panda_finger_joint1")]] = 0.035
    other = pinsettle.solve(scene, q0, max_steps=2000)
    assert other.joints["panda_finger_joint1"] == 0.035
    assert other.joints["panda_finger_joint2"] == 0.02


def test_chain20_hangs_straight_down(solved):
    _, result, ref = solved("chain20")
    assert len(result.joints) == 20
    assert max(abs(wrap(value)) for value in result.joints.values()) < 1e-5
    assert ref.eigenvalues(result.q).min() > 0.03


def test_ur5_base_rotation_is_neutral_without_the_spring(solved):
    _, result, ref = solved("ur5")
    assert ref.residual(result.q) < MAX_RESIDUAL
    turned = result.q.copy()
    turned[0] += 1.0  # shoulder_pan_joint: a vertical axis
    assert ref.residual(turned) < MAX_RESIDUAL
    # With the spring to an anchor off the axis, turning the base is not free any more.
    _, result, ref = solved("ur5_tool_spring")
    turned = result.q.copy()
    turned[0] += 0.1
    assert ref.residual(turned) > 1.0


def test_ur5_tool_spring_tension_and_the_other_pose(solved):
    _, result, ref = solved("ur5_tool_spring")
    model = ref.full
    data = model.createData()
    pinocchio.framesForwardKinematics(model, data, result.q)
    tool = data.oMf[model.getFrameId("tool0")].translation
    anchor = ref.springs[0][3]
    length = np.linalg.norm(anchor - tool)
    assert length == pytest.approx(0.396, abs=5e-4)
    assert ref.springs[0][4] * length == pytest.approx(79.2, abs=0.05)
    assert ref.potential_reduced(model, result.q) == pytest.approx(7.423, abs=5e-4)
    # The wrist-flipped pose of the comment: an equilibrium too, stable, of lower potential.
    flipped = result.q.copy()
    flipped[3:5] = [-1.0118, 1.4887]
    flipped = independent_root(ref, flipped, neutral=("wrist_3_joint",))
    assert ref.residual(flipped) < 1e-10
    assert ref.eigenvalues(flipped)[1:].min() > 1.0
    assert ref.potential_reduced(model, flipped) == pytest.approx(7.384, abs=5e-4)
    assert np.max(np.abs(np.delete(flipped - result.q, [3, 4, 5]))) < 0.006


# --- scenes built in code ---------------------------------------------------------------------


def test_gravity_per_scene():
    model = pinsettle.load_urdf(SLIDER_URDF)
    default = np.array(model.gravity.linear)
    sag = {}
    for gz in (-10.0, -20.0):
        scene = pinsettle.Scene(model, gravity=[0.0, 0.0, gz]).add_joint_spring("slider", 500.0)
        assert np.array_equal(scene.gravity, [0.0, 0.0, gz])
        result = pinsettle.solve(scene)
        assert result.converged
        sag[gz] = result.joints["slider"]
    assert sag[-20.0] == pytest.approx(-2.0 * 20.0 / 500.0, abs=1e-8)
    assert sag[-20.0] == pytest.approx(2.0 * sag[-10.0], rel=1e-6)
    assert np.array_equal(model.gravity.linear, default)  # the scene has its own copy


def test_gravity_from_a_scene_file(tmp_path):
    text = (ROBOTS / "slider_spring.toml").read_text(encoding="utf-8")
    text = text.replace('urdf = "slider.urdf"', f'urdf = "{SLIDER_URDF}"\ngravity = [0, 0, -20]')
    path = tmp_path / "heavy.toml"
    path.write_text(text, encoding="utf-8")
    result = pinsettle.solve(pinsettle.load_scene(path))
    assert result.joints["slider"] == pytest.approx(-2.0 * 20.0 / 500.0, abs=1e-8)
    assert Reference.from_toml(path).residual(result.q) < MAX_RESIDUAL


def test_sideways_gravity():
    # Gravity along +x: the bob (at x = -sin(hinge)) hangs towards +x, at hinge = -pi/2.
    scene, ref = pair(pinsettle.load_urdf(PENDULUM_URDF), gravity=[9.81, 0.0, 0.0])
    result = pinsettle.solve(scene)
    assert result.converged
    assert result.joints["hinge"] == pytest.approx(-math.pi / 2, abs=1e-6)
    assert ref.residual(result.q) < MAX_RESIDUAL
    assert ref.eigenvalues(result.q).min() > 9.0


CODE_VS_FILE = {
    "pendulum": (
        lambda: (
            pinsettle.Scene.from_urdf(PENDULUM_URDF, settings={"kt": 0.3})
            .set_start(hinge=0.3)
            .add_joint_spring("hinge", 5.0, rest=0.2, damping=0.1)
            .add_spring({"frame": "arm", "point": [0, 0, -1]}, ("universe", [1, 0, -1]), 20.0, 0.5)
            .add_load("hinge", 0.4)
            .add_load(frame="arm", point=[0, 0, -0.5], force=[0, 0, -3], torque=[0, 0.1, 0])
        ),
        f"""
        [model]
        urdf = "{PENDULUM_URDF}"
        [start]
        hinge = 0.3
        [[joint_spring]]
        joint = "hinge"
        stiffness = 5.0
        rest = 0.2
        damping = 0.1
        [[spring]]
        a = {{ frame = "arm", point = [0.0, 0.0, -1.0] }}
        b = {{ frame = "universe", point = [1.0, 0.0, -1.0] }}
        stiffness = 20.0
        rest_length = 0.5
        [[load]]
        joint = "hinge"
        effort = 0.4
        [[load]]
        frame = "arm"
        point = [0.0, 0.0, -0.5]
        force = [0.0, 0.0, -3.0]
        torque = [0.0, 0.1, 0.0]
        [solver]
        kt = 0.3
        """,
    ),
    "planar-locked": (
        lambda: (
            pinsettle.Scene.from_urdf(PLANAR_URDF)
            .set_start(joint1=-0.2, joint2=0.4)
            .lock("joint2")
            .add_joint_spring("joint3", 3.0, rest=0.5)
            .add_spring(("link3", [0, 0, -0.5]), ("link1", [0.05, 0, -0.25]), 40.0, rest_length=0.1)
            .add_load(frame="link3", point=[0, 0, -0.5], force=[2, 0, 0])
            .add_load("joint1", -0.5)
        ),
        f"""
        [model]
        urdf = "{PLANAR_URDF}"
        locked = ["joint2"]
        [start]
        joint1 = -0.2
        joint2 = 0.4
        [[joint_spring]]
        joint = "joint3"
        stiffness = 3.0
        rest = 0.5
        [[spring]]
        a = {{ frame = "link3", point = [0, 0, -0.5] }}
        b = {{ frame = "link1", point = [0.05, 0, -0.25] }}
        stiffness = 40.0
        rest_length = 0.1
        [[load]]
        frame = "link3"
        point = [0, 0, -0.5]
        force = [2, 0, 0]
        [[load]]
        joint = "joint1"
        effort = -0.5
        """,
    ),
}


@pytest.mark.parametrize("case", sorted(CODE_VS_FILE))
def test_scene_in_code_is_the_scene_file(case, tmp_path):
    build, text = CODE_VS_FILE[case]
    path = tmp_path / f"{case}.toml"
    path.write_text("\n".join(line.strip() for line in text.splitlines()), encoding="utf-8")
    from_file = pinsettle.load_scene(path)
    in_code = build()
    assert in_code.settings == from_file.settings
    assert in_code.locked == from_file.locked
    assert np.array_equal(in_code.q0(), from_file.q0())
    a, b = pinsettle.solve(in_code), pinsettle.solve(from_file)
    assert a.converged
    assert np.array_equal(a.q, b.q) and a.steps == b.steps
    ref = Reference.from_toml(path)
    assert ref.residual(a.q) < MAX_RESIDUAL
    assert ref.eigenvalues(a.q).min() > 0.0
    rng = np.random.default_rng(3)
    for _ in range(4):
        q = ref.random_configuration(rng)
        assert np.allclose(in_code.static_force(q), ref.force(q), rtol=1e-9, atol=1e-9)
        assert np.array_equal(in_code.static_force(q), from_file.static_force(q))


def bob_x_sign(model: pinocchio.Model) -> float:
    """d(x of the bob)/d(hinge) at 0, by pinocchio's forward kinematics: -1 for this URDF."""
    data = model.createData()
    xs = []
    for angle in (-1e-3, 1e-3):
        pinocchio.framesForwardKinematics(model, data, np.array([angle]))
        xs.append(data.oMf[model.getFrameId("arm")].act(np.array([0.0, 0.0, -1.0]))[0])
    return math.copysign(1.0, xs[1] - xs[0])


@pytest.mark.parametrize("force", [5.0, -3.0, 20.0])
def test_point_load_on_the_pendulum(force):
    model = pinsettle.load_urdf(PENDULUM_URDF)
    m, g, arm = pendulum_constants(model)
    scene, ref = pair(model, point_loads=[("arm", (0.0, 0.0, -1.0), (force, 0.0, 0.0), (0, 0, 0))])
    result = pinsettle.solve(scene)
    assert result.converged
    # V = m g l (1 - cos t) - F x(t), x = s l sin(t): tan(t) = s F / (m g).
    expected = math.atan2(bob_x_sign(model) * force, m * g)
    assert result.joints["hinge"] == pytest.approx(expected, abs=1e-6)
    assert math.copysign(1.0, result.joints["hinge"]) == -math.copysign(1.0, force)
    assert ref.residual(result.q) < MAX_RESIDUAL


@pytest.mark.parametrize("effort, kt", [(3.0, 0.5), (-3.0, 0.5), (6.0, 0.5), (9.0, 0.0)])
def test_joint_load_on_the_pendulum(effort, kt):
    # (With 9 N m, close to m g l = 9.81, the first swing goes over the top; with kt = 0.5
    # the pendulum then keeps spinning round and never settles, so that case runs with kt = 0.)
    model = pinsettle.load_urdf(PENDULUM_URDF)
    m, g, arm = pendulum_constants(model)
    joint, ref = pair(model, joint_loads=[("hinge", effort)])
    # The same moment as a torque about the hinge axis (y), applied at a point of the arm.
    point, _ = pair(model, point_loads=[("arm", (0.0, 0.0, -0.5), (0, 0, 0), (0, effort, 0))])
    a, b = pinsettle.solve(joint, kt=kt), pinsettle.solve(point, kt=kt)
    assert a.converged and b.converged
    # V = m g l (1 - cos t) - tau t: sin(t) = tau / (m g l), on the side the effort pushes.
    assert a.joints["hinge"] == pytest.approx(math.asin(effort / (m * g * arm)), abs=1e-6)
    assert b.joints["hinge"] == pytest.approx(a.joints["hinge"], abs=1e-6)
    assert ref.residual(a.q) < MAX_RESIDUAL


@pytest.mark.parametrize("kind", ["spring", "joint_spring"])
def test_damping_changes_the_motion_not_the_equilibrium(kind):
    def build(damping):
        if kind == "spring":
            return (
                pinsettle.Scene.from_urdf(PENDULUM_URDF)
                .set_start(hinge=0.2)
                .add_spring(("arm", [0, 0, -1]), ("universe", [0, 0, -2]), 40.0, 1.5, damping)
            )
        return pinsettle.Scene.from_urdf(SLIDER_URDF).add_joint_spring(
            "slider", 500.0, 0.0, damping
        )

    undamped, damped = pinsettle.solve(build(0.0)), pinsettle.solve(build(5.0))
    assert undamped.converged and damped.converged
    assert damped.q == pytest.approx(undamped.q, abs=1e-6)
    assert build(5.0).residual(damped.q) < MAX_RESIDUAL
    # The damping's own runs differ (with the defaults Newton may end both at the first event).
    alone = {"newton_takeover": False}
    assert pinsettle.solve(build(5.0), **alone).steps != pinsettle.solve(build(0.0), **alone).steps
    # The damper acts during the motion: same start, different states after a few steps.
    early_a = pinsettle.solve(build(0.0), max_steps=3)  # before the first peak stops both
    early_b = pinsettle.solve(build(5.0), max_steps=3)
    assert not np.allclose(early_a.v, early_b.v, rtol=1e-6, atol=0.0)
    # ... and does not enter the static force.
    q = np.array([0.1]) if kind == "spring" else np.array([0.01])
    assert np.array_equal(build(0.0).static_force(q), build(5.0).static_force(q))


def test_continuous_joint_spring_wraps_around():
    # A balanced disk (continuous joint: q = (cos, sin)) on a spring with rest 3.0 rad, pushed
    # on by 0.5 N m: the spring stretches by 0.5 rad across +-pi, to 3.5 rad = 3.5 - 2 pi.
    model = pinsettle.load_urdf(DISK_URDF)
    assert model.nq == 2 and model.nv == 1
    scene, ref = pair(
        model,
        start={"wheel": -3.0},
        joint_springs=[("wheel", 1.0, 3.0)],
        joint_loads=[("wheel", 0.5)],
    )

    def at(angle):
        return np.array([math.cos(angle), math.sin(angle)])

    # At -3.0 the wrapped stretch is -3.0 - 3.0 + 2 pi = 0.283 rad, not -6.
    assert scene.static_force(at(-3.0)) == pytest.approx([2 * math.pi - 6.0 - 0.5], abs=1e-12)
    assert ref.force(at(-3.0)) == pytest.approx(scene.static_force(at(-3.0)), abs=1e-12)
    result = pinsettle.solve(scene)
    assert result.converged
    root = brentq(lambda t: ref.force(at(t))[0], -3.1, -2.5, xtol=1e-14)
    assert root == pytest.approx(3.5 - 2 * math.pi, abs=1e-12)
    assert result.joints["wheel"] == pytest.approx(root, abs=1e-6)
    assert ref.eigenvalues(result.q) == pytest.approx([1.0], rel=1e-6)
    assert np.linalg.norm(result.q) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("source", ["code", "file"])
def test_scene_without_elements_is_the_bare_solve(source):
    if source == "code":
        scene = pinsettle.Scene.from_urdf(PENDULUM_URDF).set_start(hinge=1.0)
    else:
        scene = pinsettle.load_scene(ROBOTS / "pendulum.toml")
    assert not scene.has_elements
    a = pinsettle.solve(scene)
    b = pinsettle.solve(scene.model, scene.q0())
    assert a.converged
    assert np.array_equal(a.q, b.q) and np.array_equal(a.v, b.v)
    assert (a.steps, a.peaks, a.residual) == (b.steps, b.peaks, b.residual)


def test_ur5_scene_is_the_bare_ur5(solved):
    _, result, _ = solved("ur5")
    bare = pinsettle.solve(pinsettle.load_robot("ur5"))
    assert np.array_equal(result.q, bare.q) and result.steps == bare.steps

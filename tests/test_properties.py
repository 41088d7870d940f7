"""Property-based tests (hypothesis): random models, starts, velocities and settings.

Models: Pinocchio's own sample manipulator and random humanoid, and random chains built here
with random joint types (revolute about x, y or z, prismatic, spherical, free-flyer, planar,
continuous), placements and masses over 8 decades (1e-4 to 1e4 kg). Starts are random points of
the configuration manifold (``integrate(neutral, v)``), velocities and settings are drawn within
their documented ranges (README's settings table), and each solve is bounded (at most 2,000
steps and 1 s). Properties:

- no crash, no hang: a solve ends within its step and time budget with finite q and v;
- a ``converged`` answer has the residual it claims, recomputed with
  ``pinocchio.computeGeneralizedGravity`` (nothing of pinsettle's);
- the stability verdict agrees with the eigenvalues of a finite-difference stiffness computed
  here (central differences of computeGeneralizedGravity through ``pinocchio.integrate``);
- settings out of their ranges raise ValueError, of the wrong type TypeError, naming the field.

The runs are derandomized (``derandomize=True``): the same examples every time, so a failure
replays; hypothesis prints the failing example (and ``print_blob`` a reproduction blob).
Joint stops are off (``limits=False``) so that the residual is the plain static force.
"""

from __future__ import annotations

import math
import re
import time

import numpy as np
import pinocchio
import pinsettle
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, event, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

MAX_STEPS = 2000
MAX_TIME = 1.0  # s per solve
WALL_MARGIN = 2.0  # s beyond max_time for the setup and the final stability report

PROPERTIES = settings(
    max_examples=60,
    derandomize=True,
    database=None,
    deadline=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

JOINTS = {
    "RX": pinocchio.JointModelRX,
    "RY": pinocchio.JointModelRY,
    "RZ": pinocchio.JointModelRZ,
    "PX": pinocchio.JointModelPX,
    "PY": pinocchio.JointModelPY,
    "PZ": pinocchio.JointModelPZ,
    "spherical": pinocchio.JointModelSpherical,
    "free-flyer": pinocchio.JointModelFreeFlyer,
    "planar": pinocchio.JointModelPlanar,
    "continuous": pinocchio.JointModelRUBY,
    # Motion subspaces that turn with the joint's own angles (Pinocchio's gravity derivatives
    # miss that turn: the stiffness differences gravity there).
    "universal": lambda: pinocchio.JointModelUniversal(
        np.array([1.0, 0, 0]), np.array([0, 0, 1.0])
    ),
    "spherical-zyx": pinocchio.JointModelSphericalZYX,
    "ellipsoid": lambda: pinocchio.JointModelEllipsoid(0.1, 0.2, 0.05),
}

finite = {"allow_nan": False, "allow_infinity": False}


@st.composite
def inertias(draw) -> pinocchio.Inertia:
    """A body of mass 1e-4 .. 1e4 kg (8 decades), its centre of mass within 1 m, its
    rotational inertia that of a box of mass m with sides 1 cm .. 1 m (positive definite)."""
    mass = 10.0 ** draw(st.floats(-4.0, 4.0, **finite))
    com = np.array(draw(st.lists(st.floats(-1.0, 1.0, **finite), min_size=3, max_size=3)))
    sides = np.array(draw(st.lists(st.floats(0.01, 1.0, **finite), min_size=3, max_size=3)))
    a, b, c = sides**2
    box = mass / 12.0 * np.diag([b + c, a + c, a + b])
    return pinocchio.Inertia(mass, com, box)


@st.composite
def placements(draw) -> pinocchio.SE3:
    xyz = np.array(draw(st.lists(st.floats(-1.0, 1.0, **finite), min_size=3, max_size=3)))
    rpy = np.array(draw(st.lists(st.floats(-math.pi, math.pi, **finite), min_size=3, max_size=3)))
    return pinocchio.SE3(pinocchio.rpy.rpyToMatrix(rpy), xyz)


@st.composite
def chains(draw) -> tuple[pinocchio.Model, list[str]]:
    """A chain (or a tree: each joint hangs from the last one or one of its ancestors) of 1 to 5
    joints of random types, each carrying a body."""
    model = pinocchio.Model()
    kinds = draw(st.lists(st.sampled_from(sorted(JOINTS)), min_size=1, max_size=5))
    for k, kind in enumerate(kinds):
        # Depth-first order, as Pinocchio's subtree algorithms need: the new joint hangs from
        # the last one or one of its ancestors (the root included).
        parent = draw(st.sampled_from(_ancestors_or_self(model, k)))
        joint = model.addJoint(parent, JOINTS[kind](), draw(placements()), f"j{k}_{kind}")
        model.appendBodyToJoint(joint, draw(inertias()), pinocchio.SE3.Identity())
    return model, kinds


def sample_manipulator(draw) -> pinocchio.Model:
    """Pinocchio's sample manipulator, its bodies' masses (and inertias) scaled by random
    factors over 8 decades."""
    model = pinocchio.buildSampleModelManipulator()
    for j in range(1, model.njoints):
        scale = 10.0 ** draw(st.floats(-4.0, 4.0, **finite))
        inertia = model.inertias[j]
        model.inertias[j] = pinocchio.Inertia(
            inertia.mass * scale, inertia.lever, inertia.inertia * scale
        )
    return model


def humanoid(draw) -> pinocchio.Model:
    """Pinocchio's random humanoid (free-flyer root), its randomness seeded from the draw."""
    pinocchio.seed(draw(st.integers(0, 2**31 - 1)))
    return pinocchio.buildSampleModelHumanoidRandom(draw(st.booleans()))


@st.composite
def models(draw) -> tuple[str, pinocchio.Model]:
    source = draw(st.sampled_from(["chain", "chain", "chain", "manipulator", "humanoid"]))
    if source == "chain":
        model, kinds = draw(chains())
        return "chain " + ",".join(kinds), model
    if source == "manipulator":
        return source, sample_manipulator(draw)
    return source, humanoid(draw)


def configuration(draw, model: pinocchio.Model, scale: float = 3.0) -> np.ndarray:
    """A point of the configuration manifold: neutral moved by a random tangent vector."""
    v = draw(st.lists(st.floats(-scale, scale, **finite), min_size=model.nv, max_size=model.nv))
    return pinocchio.integrate(model, pinocchio.neutral(model), np.array(v))


@st.composite
def solver_settings(draw) -> dict:
    """Settings within the README's ranges, with a bounded budget."""
    out = {
        "kt": draw(st.floats(0.0, 1.0, exclude_max=True, **finite)),
        "energy": draw(st.sampled_from(["exact", "simplified"])),
        "backtrack": draw(st.booleans()),
        "polish": draw(st.booleans()),
        "scale_stiff_modes": draw(st.booleans()),
        "dt_growth": draw(st.one_of(st.just("auto"), st.floats(1.0, 4.0, **finite))),
        "dt_safety": draw(st.floats(0.0, 1.0, exclude_min=True, **finite)),
        "err": draw(st.sampled_from([0.0, 1e-12, 1e-9, 1e-6])),
        "ds": draw(st.integers(1, 200)),
        "max_e": draw(st.sampled_from([0.0, 1e-16, 1e-12, 1e-8])),
        "max_steps": draw(st.integers(1, MAX_STEPS)),
        "max_time": MAX_TIME,
        "trace_every": draw(st.integers(0, 10)),
        "trace_capacity": draw(st.integers(2, 100)),
        "trace_configurations": draw(st.booleans()),
        "check_every": draw(st.integers(1, 512)),
    }
    if draw(st.booleans()):
        out["dt"] = 10.0 ** draw(st.floats(-5.0, -2.0, **finite))
    return out


def gravity(model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
    return pinocchio.computeGeneralizedGravity(model, model.createData(), q).copy()


def fd_stiffness_eigenvalues(model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
    """Eigenvalues of the symmetric part of d g / dq, g = computeGeneralizedGravity, by central
    differences along each tangent direction (pinocchio.integrate), step 1e-6 rad or m."""
    h = 1e-6
    K = np.empty((model.nv, model.nv))
    for i in range(model.nv):
        e = np.zeros(model.nv)
        e[i] = h
        K[:, i] = (
            gravity(model, pinocchio.integrate(model, q, e))
            - gravity(model, pinocchio.integrate(model, q, -e))
        ) / (2 * h)
    return np.linalg.eigvalsh(0.5 * (K + K.T))


def stiffness_floor(model: pinocchio.Model) -> float:
    """An absolute floor for comparing stiffnesses (N m/rad): 1e-9 of m g L over the bodies,
    L their reach (round-off where every eigenvalue vanishes, e.g. a slider on the level)."""
    reach = 1.0 + sum(np.linalg.norm(p.translation) for p in model.jointPlacements)
    weight = sum(inertia.mass for inertia in model.inertias) * 9.81
    return 1e-9 * weight * (reach + max(np.linalg.norm(i.lever) for i in model.inertias))


def check_verdict(
    verdict: str, min_eigenvalue: float, eigenvalues: np.ndarray, floor: float
) -> None:
    """The verdict against the finite-difference eigenvalues. Where they are clear (beyond
    1e-5 of the largest, far above the differences' noise and the solver's own tolerance of
    1e-9 of the largest) the verdict must follow them; in between either side is right."""
    top = float(np.max(np.abs(eigenvalues)))
    band = 1e-5 * top + floor
    smallest = float(eigenvalues[0])
    if smallest > band:
        assert verdict == "stable", (verdict, eigenvalues)
    elif smallest < -band:
        assert verdict == "unstable", (verdict, eigenvalues)
    if verdict == "stable":
        assert smallest > -band, eigenvalues
    elif verdict == "unstable":
        assert smallest < band, eigenvalues
    else:
        assert verdict == "neutral" and abs(smallest) <= band, (verdict, eigenvalues)
    # The smallest eigenvalue the solver reports is the same, up to the differences' error.
    assert min_eigenvalue == pytest.approx(smallest, abs=band), (min_eigenvalue, eigenvalues)


@settings(PROPERTIES, max_examples=1500)
@given(data=st.data())
def test_random_solves_end_well(data):
    name, model = data.draw(models(), label="model")
    q0 = configuration(data.draw, model)
    speed = data.draw(st.sampled_from([0.0, 0.1, 2.0]), label="speed")
    v0 = np.array(
        data.draw(
            st.lists(st.floats(-speed, speed, **finite), min_size=model.nv, max_size=model.nv),
            label="v0",
        )
    )
    overrides = data.draw(solver_settings(), label="settings")
    begin = time.perf_counter()
    result = pinsettle.solve(model, q0, v0=v0, limits=False, **overrides)
    elapsed = time.perf_counter() - begin
    event(f"{name.split()[0]}: {result.status}")
    # Bounded: within its budget, never a hang.
    assert result.steps <= overrides["max_steps"]
    assert elapsed <= MAX_TIME + WALL_MARGIN, (name, elapsed)
    assert np.all(np.isfinite(result.q)) and np.all(np.isfinite(result.v)), name
    assert result.status in {"converged", "max_steps", "time_limit", "no_equilibrium", "diverged"}
    if result.converged:
        # The residual it claims is the one recomputed with Pinocchio alone.
        recomputed = float(np.max(np.abs(gravity(model, result.q))))
        scale = float(
            np.max(np.abs(gravity(model, pinocchio.neutral(model))), initial=0.0)
            + sum(inertia.mass for inertia in model.inertias) * 9.81
        )
        assert result.residual == pytest.approx(recomputed, rel=1e-9, abs=1e-13 * scale), name
        assert result.stability in ("stable", "neutral"), name


@settings(PROPERTIES, max_examples=600)
@given(data=st.data())
def test_verdict_agrees_with_finite_differences(data):
    # At any configuration (an equilibrium or not), the verdict of assess_stability is the sign
    # pattern of the eigenvalues of the finite-difference stiffness.
    name, model = data.draw(models(), label="model")
    q = configuration(data.draw, model)
    report = pinsettle.assess_stability(model, q, limits=False)
    event(f"{name.split()[0]}: {report.verdict}")
    eigenvalues = fd_stiffness_eigenvalues(model, q)
    floor = stiffness_floor(model)
    check_verdict(report.verdict, report.min_eigenvalue, eigenvalues, floor)
    band = 1e-5 * np.max(np.abs(eigenvalues)) + floor
    assert np.allclose(report.eigenvalues, eigenvalues, rtol=0.0, atol=band), name


@settings(PROPERTIES, max_examples=500)
@given(data=st.data())
def test_verdict_of_a_converged_rest_agrees_with_finite_differences(data):
    # From a start near a rest (a chain hanging, the manipulator, small random moves), the
    # solve converges; its verdict and smallest eigenvalue are those of the differences.
    model, kinds = data.draw(chains(), label="model")
    q0 = configuration(data.draw, model, scale=0.5)
    result = pinsettle.solve(model, q0, limits=False, max_steps=20000, max_time=MAX_TIME)
    event(f"{result.status}, {result.stability}")
    if not result.converged:
        return  # a free body or slider falls for ever: nothing to compare
    eigenvalues = fd_stiffness_eigenvalues(model, result.q)
    check_verdict(
        result.stability, result.min_stiffness_eigenvalue, eigenvalues, stiffness_floor(model)
    )


@settings(PROPERTIES, max_examples=100)
@given(data=st.data())
def test_trees_out_of_depth_first_order_are_refused(data):
    # Joints added in any order: in depth-first order (each joint's subtree right after it)
    # the model is solved; otherwise every entry point refuses it, naming the joint, since
    # Pinocchio's crba and derivatives would give a wrong mass matrix and stiffness.
    model = pinocchio.Model()
    n = data.draw(st.integers(2, 6), label="joints")
    for k in range(n):
        parent = data.draw(st.integers(0, k), label=f"parent of j{k}")
        joint = model.addJoint(parent, pinocchio.JointModelRY(), data.draw(placements()), f"j{k}")
        model.appendBodyToJoint(joint, data.draw(inertias()), pinocchio.SE3.Identity())
    ordered = all(
        model.parents[j] in _ancestors_or_self(model, j - 1) for j in range(2, model.njoints)
    )
    event("depth-first" if ordered else "other order")
    q = pinocchio.neutral(model)
    if ordered:
        pinsettle.solve(model, q, limits=False, max_steps=100)
        return
    for call in (
        lambda: pinsettle.solve(model, q, limits=False, max_steps=100),
        lambda: pinsettle.assess_stability(model, q, limits=False),
        lambda: pinsettle.static_force(model, q),
    ):
        with pytest.raises(ValueError, match="depth-first") as error:
            call()
        assert "joint 'j" in str(error.value)


def _ancestors_or_self(model: pinocchio.Model, j: int) -> list[int]:
    out = [j]
    while out[-1] != 0:
        out.append(model.parents[out[-1]])
    return out


# A tree the property tests found (shrunk by hand to 4 joints): nothing holds its sliders, so it
# has no equilibrium. Without stiff-mode scaling the solver says so (no_equilibrium, 204,801
# steps); with it (the default) the energy blows up to 1e149 and the run ends diverged after 30
# step halvings at 14,257 steps. (type, parent, rpy, xyz, mass, centre of mass, inertia diagonal)
FALLING_TREE = [
    ("RUBY", 0, (-1.675051843623155, -0.34842407425548405, -1.6750518436231554),
     (-0.21717890853703437, 0.31107395973943874, 0.655259913454191), 42.91944477530857,
     (0.564422731540057, 0.47659316276617125, 0.0),
     (2.604701675110491, 0.7724916708805696, 2.5823888131149757)),
    ("PY", 1, (math.pi, -0.9209417550891275, math.pi), (-0.8844793560574913, 0.0, 0.5),
     1003.4585299298648, (-0.5014258369071442, 0.24094711171607197, 0.0),
     (51.61012423474706, 80.73361147157912, 118.42253063323257)),
    ("Spherical", 2, (-1.675051843623155, 0.31586152636756726, -3.1415926535897927),
     (-0.21717890853703437, 0.31107395973943874, 0.655259913454191), 1.0,
     (-0.3631322317305531, 0.9710581034043977, -0.5288970401995047),
     (0.041666666666666664, 0.10416500000833334, 0.10416500000833334)),
    ("PX", 0, (5.960464477539066e-08, 1.1920928959999998e-07, 2.5654844965991632),
     (0.4060556156368553, -0.04188347955564997, 0.0), 0.9999769744141629,
     (0.9230318114133951, -0.5217181419067213, -0.3333333333333333),
     (0.0016782582189923193, 0.0384509707080033, 0.039988106048537884)),
]  # fmt: skip


def falling_tree() -> pinocchio.Model:
    model = pinocchio.Model()
    for kind, parent, rpy, xyz, mass, com, diagonal in FALLING_TREE:
        placement = pinocchio.SE3(pinocchio.rpy.rpyToMatrix(np.array(rpy)), np.array(xyz))
        joint = model.addJoint(parent, getattr(pinocchio, f"JointModel{kind}")(), placement, kind)
        inertia = pinocchio.Inertia(mass, np.array(com), np.diag(diagonal))
        model.appendBodyToJoint(joint, inertia, pinocchio.SE3.Identity())
    return model


@pytest.mark.parametrize("scale", [True, False])
def test_a_falling_tree_is_no_equilibrium_not_a_blow_up(scale):
    model = falling_tree()
    result = pinsettle.solve(model, limits=False, scale_stiff_modes=scale)
    assert result.status == "no_equilibrium", (result.status, result.reason)
    # Not a blow-up caught late. With an earlier rule (modes 1e6 times above the softest, kept
    # when the frequency dropped by more than the step's cost) this tree's modes were scaled
    # and its energy exploded (at kt = 0.5 diverged after 30 halvings, at kt = 0 six halvings
    # before the runaway test); today's rule scales none of them here. Why scaled dynamics blew
    # up in this fast fall is still open.
    assert result.scaled_modes == 0
    assert result.dt_reductions == 0, result.reason


def test_a_falling_tree_with_the_joint_inertia_releases_what_gravity_did():
    # With scale_joint_inertia the added inertia is re-chosen along the fall, and each rise of
    # it scales the velocity to keep the energy. Counted as energy taken out, those rises made
    # the release the runaway monitor sums several times what gravity did, irregular from one
    # doubling to the next, and the run ended max_steps. The release it reports is checked
    # against the potential energy recomputed with Pinocchio (no push, so it counts from the
    # start; its last sample is one step before the end).
    model = falling_tree()
    result = pinsettle.solve(model, limits=False, scale_joint_inertia=True)
    assert result.status == "no_equilibrium", (result.status, result.reason)
    assert result.scaled_joints > 0 and result.pushes == 0
    released = float(re.search(r"falls without bound: (\S+) J released", result.reason)[1])
    data = model.createData()
    start = pinocchio.computePotentialEnergy(model, data, pinocchio.neutral(model))
    end = pinocchio.computePotentialEnergy(model, data, result.q)
    assert released == pytest.approx(start - end, rel=0.05), (released, start - end)


# --- settings out of range or of the wrong type ------------------------------------------------

OUT_OF_RANGE = {
    "dt": st.one_of(st.floats(max_value=-1e-300), st.just(math.nan), st.just(math.inf)),
    "dt_safety": st.one_of(
        st.floats(max_value=0.0), st.floats(min_value=1.0, exclude_min=True), st.just(math.nan)
    ),
    "dt_growth": st.one_of(st.floats(max_value=1.0, exclude_max=True), st.just(math.nan)),
    "kt": st.one_of(st.floats(max_value=-1e-300), st.floats(min_value=1.0), st.just(math.nan)),
    "err": st.one_of(st.floats(max_value=-1e-300), st.just(math.nan), st.just(math.inf)),
    "ds": st.integers(max_value=0),
    "max_e": st.one_of(st.floats(max_value=-1e-300), st.just(math.nan), st.just(math.inf)),
    "max_steps": st.integers(max_value=0),
    "max_time": st.one_of(st.floats(max_value=0.0), st.just(math.nan)),
    "trace_every": st.integers(max_value=-1),
    "trace_capacity": st.integers(max_value=1),
    "check_every": st.integers(max_value=0),
    "energy": st.text(max_size=12).filter(lambda s: s not in ("exact", "simplified")),
}

WRONG_TYPES = {
    "dt": st.one_of(st.booleans(), st.none(), st.lists(st.floats(), max_size=2)),
    "kt": st.one_of(st.text(max_size=5), st.booleans(), st.none()),
    "ds": st.one_of(st.floats(**finite), st.text(max_size=5), st.booleans()),
    "max_steps": st.one_of(st.floats(**finite), st.none()),
    "energy": st.one_of(st.integers(), st.floats(), st.booleans()),
    "backtrack": st.one_of(st.integers(), st.text(max_size=5), st.none()),
    "polish": st.one_of(st.integers(), st.floats()),
    "trace_every": st.one_of(st.floats(**finite), st.lists(st.integers(), max_size=2)),
}


@pytest.fixture(scope="module")
def pendulum() -> pinocchio.Model:
    model = pinocchio.Model()
    joint = model.addJoint(0, pinocchio.JointModelRY(), pinocchio.SE3.Identity(), "hinge")
    inertia = pinocchio.Inertia(1.0, np.array([0.0, 0.0, -1.0]), np.eye(3) * 1e-3)
    model.appendBodyToJoint(joint, inertia, pinocchio.SE3.Identity())
    return model


@settings(PROPERTIES, max_examples=60)
@given(data=st.data())
def test_settings_out_of_range_name_the_field(pendulum, data):
    key = data.draw(st.sampled_from(sorted(OUT_OF_RANGE)), label="setting")
    value = data.draw(OUT_OF_RANGE[key], label="value")
    with pytest.raises(ValueError, match=key):
        pinsettle.solve(pendulum, [0.5], **{key: value})


@settings(PROPERTIES, max_examples=60)
@given(data=st.data())
def test_settings_of_the_wrong_type_name_the_field(pendulum, data):
    key = data.draw(st.sampled_from(sorted(WRONG_TYPES)), label="setting")
    value = data.draw(WRONG_TYPES[key], label="value")
    if key == "dt" and isinstance(value, float):
        return  # a float is a step
    with pytest.raises(TypeError, match=key):
        pinsettle.solve(pendulum, [0.5], **{key: value})


@settings(PROPERTIES, max_examples=40)
@given(data=st.data())
def test_bad_starts_name_the_argument(data):
    # Starts and velocities of the wrong size or with non-finite entries: ValueError naming it.
    model, _ = data.draw(chains(), label="model")
    which = data.draw(st.sampled_from(["q0", "v0"]), label="argument")
    size = model.nq if which == "q0" else model.nv
    q_good, v_good = pinocchio.neutral(model), np.zeros(model.nv)
    good = q_good if which == "q0" else v_good
    bad = data.draw(
        st.one_of(
            st.integers(0, 12).filter(lambda n: n != size).map(np.zeros),
            st.sampled_from([math.nan, math.inf, -math.inf]).map(
                lambda x: np.where(np.arange(size) == size - 1, x, good)
            ),
        ),
        label="value",
    )
    kwargs = {"v0": bad} if which == "v0" else {}
    q0 = bad if which == "q0" else q_good
    with pytest.raises(ValueError, match=which):
        pinsettle.solve(model, q0, limits=False, max_steps=10, **kwargs)

"""Property-based tests (hypothesis): random models, starts, velocities and settings.

Models: Pinocchio's own sample manipulator and random humanoid, and random chains built here
with random joint types (revolute about x, y or z, prismatic, spherical, free-flyer, planar,
continuous), placements and masses over 8 decades (1e-4 to 1e4 kg). Starts are random points of
the configuration manifold (``integrate(neutral, v)``), velocities and settings are drawn within
their documented ranges (README's settings table), and each solve is bounded (at most 2,000
steps and 1 s). Scenes: random chains of 1-DoF joints with joint springs, point springs, joint
and point loads, stops, couplings and a loop, each element given both to a ``pinsettle.Scene``
and to tests/scene_reference.py. Properties:

- no crash, no hang: a solve ends within its step and time budget with finite q and v;
- a ``converged`` answer is a rest: its residual, recomputed with
  ``pinocchio.computeGeneralizedGravity`` (or the scene reference: the conditions of a rest
  against stops, the force along the motions loops and couplings allow), is at round-off of the
  model's force scale when Newton's polish was kept, and otherwise within what the stopping
  energy allows;
- the runs that must converge do: every chain whose configurations are bounded (no slider, no
  free body) released near a rest, and every random scene (each joint on a spring, so that the
  potential has a minimum), up to a least share measured;
- the stability verdict is the one the solver's own rule gives on the eigenvalues of a
  finite-difference stiffness computed here (tests/verdict_reference.py: central differences of
  the reference force, on the joints off their stops and the motions loops and couplings
  allow), wherever the differences' error cannot tip it, and most cases are such;
- settings out of their ranges raise ValueError, of the wrong type TypeError, naming the field.

The runs are derandomized (``derandomize=True``): the same examples every time, so a failure
replays; hypothesis prints the failing example (and ``print_blob`` a reproduction blob).
Joint stops are off (``limits=False``) on the random models so that the residual is the plain
static force; the scenes set their own.
"""

from __future__ import annotations

import math
import re
import time
from collections import Counter

import numpy as np
import pinocchio
import pinsettle
import pytest
from scene_reference import Reference
from verdict_reference import (
    Verdict,
    describe,
    gravity_force,
    has_varying_joints,
    scene_verdict,
    tree_verdict,
)

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, event, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

MAX_STEPS = 2000
MAX_TIME = 1.0  # s per solve
# The wall-time guard of the runs that must converge: a guard against a hang only (their step
# limit bounds them). In full-suite runs, 4 of the 162 bounded chains of the converged-rest test
# ended unconverged at a 1 s budget, twice in a row, while alone all 162 converge (the whole test
# takes 13 s): wall time, not steps, decided them.
CONVERGE_TIME = 10.0  # s per solve
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


def force_scale(model: pinocchio.Model) -> float:
    """The model's force scale (N m or N): its largest gravity effort at neutral plus its whole
    weight."""
    return float(
        np.max(np.abs(gravity(model, pinocchio.neutral(model))), initial=0.0)
        + sum(inertia.mass for inertia in model.inertias) * 9.81
    )


# A converged run whose Newton polish was kept ends at round-off along every direction of
# clear stiffness (Newton's step does not move along the neutral ones): measured over this
# module's examples and 5,000 more, at most 3e-16 of the force scale on the chains, 1.7e-14 on
# the scenes, once 9.6e-14 (1e-12 leaves a margin of 10 over that). Where the solver
# differences its stiffness (joints whose axes turn, loops), Newton's step is that far off and
# stops earlier: at most 4e-8 measured (1e-6).
POLISHED_RESIDUAL = 1e-12
POLISHED_RESIDUAL_DIFFERENCED = 1e-6
# Any converged run (polished or not) is a rest: the potential energy it has left to release
# before the rest, 1/2 f^T K^-1 f (eigenvalues taken at least the solver's tolerance), is at
# most 100 max_e (the stopping energy), or round-off of the force scale for max_e = 0. Twice
# that here, for the stiffness's change on the way.
REST_ENERGY_FACTOR = 200.0
# The least share of the runs that must converge which must: the chains of bounded joints
# released near a rest, the scenes. Measured over 2,500 examples: 95-100% of the chains (every
# miss a round-off eigenvalue read as unstable, pushed and spinning for ever, issue 40), 99-100%
# of the scenes (a miss: 20,000 steps not enough). Below it a solver stopped early or sent
# astray by a wrong verdict fails.
LEAST_CONVERGED_SHARE = 0.98
# The share of verdicts the reference decides (no eigenvalue within the differences' error of
# the solver's band), so that the verdict checks cannot pass by being undecided. Measured over
# 600 to 2,000 examples each: 94% at random configurations, 75-81% at the chains' rests (their
# neutral directions sit at the band's edge where masses span 8 decades), 99.7% on the scenes.
LEAST_DECIDED_SHARE = {"configurations": 0.85, "rests": 0.65, "scenes": 0.95}


def check_converged_residual(
    result: pinsettle.Result, scale: float, verdict: Verdict, differenced: bool, name: str
) -> None:
    """A converged run is a rest, by the reference's force along the free motions
    (verdict.force) and stiffness: round-off when Newton's polish was kept, and in any case
    little potential energy left to release."""
    assert result.converged
    residual = verdict.residual
    if result.polished:
        bound = (POLISHED_RESIDUAL_DIFFERENCED if differenced else POLISHED_RESIDUAL) * scale
        stiff = verdict.stiff_residual()
        assert stiff <= bound, (name, stiff, bound, describe(verdict), result.summary())
    energy = verdict.rest_energy()
    allowed = REST_ENERGY_FACTOR * result.settings.max_e + 1e-22 * scale
    assert energy <= allowed, (name, energy, allowed, residual, describe(verdict))


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
        # The residual it claims is the one recomputed with Pinocchio alone, and that is a rest.
        recomputed = float(np.max(np.abs(gravity(model, result.q))))
        scale = force_scale(model)
        assert result.residual == pytest.approx(recomputed, rel=1e-9, abs=1e-13 * scale), name
        verdict = tree_verdict(model, gravity_force(model), result.q)
        check_converged_residual(result, scale, verdict, has_varying_joints(model), name)
        assert result.stability in ("stable", "neutral"), name
        verdict.check(result.stability)


def test_verdict_agrees_with_finite_differences():
    # At any configuration (an equilibrium or not), the verdict of assess_stability is the one
    # the solver's rule gives on the eigenvalues of the finite-difference stiffness, and so are
    # its eigenvalues (within the differences' error).
    decided = Counter()

    @settings(PROPERTIES, max_examples=600)
    @given(data=st.data())
    def verdicts(data):
        name, model = data.draw(models(), label="model")
        q = configuration(data.draw, model)
        report = pinsettle.assess_stability(model, q, limits=False)
        event(f"{name.split()[0]}: {report.verdict}")
        verdict = tree_verdict(model, gravity_force(model), q)
        decided[verdict.decided] += 1
        verdict.check(report.verdict, report.min_eigenvalue)
        assert np.allclose(
            report.eigenvalues,
            verdict.eigenvalues,
            rtol=0.0,
            atol=verdict.noise + verdict.tolerances[1],
        ), (name, report.eigenvalues, describe(verdict))

    verdicts()
    share = decided[True] / sum(decided.values())
    assert share >= LEAST_DECIDED_SHARE["configurations"], decided


# Joints whose configurations form a bounded set: a chain of them has a lowest pose, so
# released near a rest it must come to one.
BOUNDED = {"RX", "RY", "RZ", "spherical", "continuous", "universal", "spherical-zyx", "ellipsoid"}


def test_verdict_of_a_converged_rest_agrees_with_finite_differences():
    # From a start near a rest (small random moves from neutral), a chain of bounded joints must
    # converge (a least share of them, none falling); a chain with sliders or free bodies may
    # fall. Every converged rest is one (its residual recomputed) and its verdict and smallest
    # eigenvalue are those of the differences.
    outcomes = Counter()

    @settings(PROPERTIES, max_examples=500)
    @given(data=st.data())
    def rests(data):
        model, kinds = data.draw(chains(), label="model")
        q0 = configuration(data.draw, model, scale=0.5)
        result = pinsettle.solve(model, q0, limits=False, max_steps=20000, max_time=CONVERGE_TIME)
        bounded = set(kinds) <= BOUNDED
        event(f"{'bounded' if bounded else 'unbounded'}: {result.status}, {result.stability}")
        outcomes[bounded, result.converged] += 1
        if not result.converged:
            assert result.status in ("max_steps", "no_equilibrium", "time_limit"), result.status
            return  # counted: the bounded ones must converge, below
        name = ",".join(kinds)
        verdict = tree_verdict(model, gravity_force(model), result.q)
        outcomes["decided", verdict.decided] += 1
        check_converged_residual(
            result, force_scale(model), verdict, has_varying_joints(model), name
        )
        verdict.check(result.stability, result.min_stiffness_eigenvalue)

    rests()
    bounded_runs = outcomes[True, True] + outcomes[True, False]
    # Enough chains drawn are bounded for the share below to mean something. The draws are
    # not the same from run to run (derandomized, Hypothesis' engine still adapts to what the
    # runs did): 149 of 500 in a clean checkout after the takeover's round-off fix, 150 or
    # more before it and here on the development machine.
    assert bounded_runs >= 140, outcomes
    assert outcomes[True, True] >= LEAST_CONVERGED_SHARE * bounded_runs, outcomes
    decided = outcomes["decided", True] / (outcomes["decided", True] + outcomes["decided", False])
    assert decided >= LEAST_DECIDED_SHARE["rests"], outcomes


# --- random scenes: springs, loads, stops, couplings and loops ---------------------------------

# 1-DoF joints of one coordinate, and the continuous ones (cos, sin).
SCENE_JOINTS = {
    "RX": pinocchio.JointModelRX,
    "RY": pinocchio.JointModelRY,
    "RZ": pinocchio.JointModelRZ,
    "PX": pinocchio.JointModelPX,
    "PY": pinocchio.JointModelPY,
    "PZ": pinocchio.JointModelPZ,
    "HX": lambda: pinocchio.JointModelHX(0.1),
    "HZ": lambda: pinocchio.JointModelHZ(-0.2),
    "continuous": pinocchio.JointModelRUBY,
}


def small_vector(draw, bound: float) -> list[float]:
    """A vector of 3 multiples of 0.05 in [-bound, bound]: scenes on a coarse grid, where a
    point is on an axis exactly or clearly off it (a loop 1e-20 m off its hinge's axis holds
    the hinge for the solver, for the reference's rank cut it holds nothing; neither is wrong)."""
    n = round(bound / 0.05)
    return [i * 0.05 for i in draw(st.lists(st.integers(-n, n), min_size=3, max_size=3))]


@st.composite
def coarse_placements(draw) -> pinocchio.SE3:
    rpy = np.array(draw(st.lists(st.integers(-12, 12), min_size=3, max_size=3))) * math.pi / 12
    return pinocchio.SE3(pinocchio.rpy.rpyToMatrix(rpy), np.array(small_vector(draw, 1.0)))


@st.composite
def scenes(draw) -> tuple[str, Reference, list[tuple[str, str, float, float]]]:
    """A random chain of 2 to 5 one-DoF joints (revolute, prismatic, helical, continuous), each
    carrying a body of 0.1 to 10 kg and a body frame, and its elements as a Reference: a joint
    spring on every joint but the continuous ones (so that the potential grows without bound and
    has a minimum), point springs, joint loads, point forces (torques only without a continuous
    joint, which one would turn for ever), stops around the start, a coupling and a point loop
    to the world, assembled at the start. Returns (description, reference, couplings as
    (follower, leader, multiplier, offset)); scene_of builds the pinsettle.Scene."""
    model = pinocchio.Model()
    kinds = draw(st.lists(st.sampled_from(sorted(SCENE_JOINTS)), min_size=2, max_size=5))
    names = []
    for k, kind in enumerate(kinds):
        parent = draw(st.sampled_from(_ancestors_or_self(model, k)))
        name = f"j{k}_{kind}"
        joint = model.addJoint(parent, SCENE_JOINTS[kind](), draw(coarse_placements()), name)
        mass = 10.0 ** draw(st.floats(-1.0, 1.0, **finite))
        lever = np.array(small_vector(draw, 0.5))
        model.appendBodyToJoint(
            joint, pinocchio.Inertia(mass, lever, mass * 0.01 * np.eye(3)), pinocchio.SE3.Identity()
        )
        model.addFrame(
            pinocchio.Frame(f"b{k}", joint, 0, pinocchio.SE3.Identity(), pinocchio.FrameType.BODY)
        )
        names.append(name)
    ref = Reference(model)
    linear = [n for n, kind in zip(names, kinds, strict=True) if kind != "continuous"]
    has_continuous = len(linear) < len(names)
    parts = []
    # Start: each joint within 1 rad or m of zero; a follower where its coupling puts it.
    ref.start = {n: draw(st.floats(-1.0, 1.0, **finite)) for n in names}
    couplings = []
    if len(linear) >= 2 and draw(st.booleans()):
        follower, leader = draw(st.permutations(linear))[:2]
        multiplier = draw(st.sampled_from([-1.5, -0.5, 0.5, 2.0]))
        offset = draw(st.floats(-0.3, 0.3, **finite))
        couplings.append((follower, leader, multiplier, offset))
        ref.start[follower] = multiplier * ref.start[leader] + offset
        parts.append("coupling")
    for name in linear:
        stiffness = 10.0 ** draw(st.floats(0.0, 3.0, **finite))
        ref.joint_springs.append((name, stiffness, draw(st.floats(-1.0, 1.0, **finite))))
    frames = [f"b{k}" for k in range(len(names))]
    for _ in range(draw(st.integers(0, 2))):
        a = draw(st.sampled_from(frames))
        b = draw(st.sampled_from(["universe", *(f for f in frames if f != a)]))  # two bodies
        ref.springs.append(
            (
                a,
                np.array(small_vector(draw, 0.5)),
                b,
                np.array(small_vector(draw, 1.0)),
                10.0 ** draw(st.floats(0.0, 3.0, **finite)),
                draw(st.floats(0.0, 1.0, **finite)),
            )
        )
        parts.append("spring")
    for _ in range(draw(st.integers(0, 2)) if linear else 0):
        effort = np.array([draw(st.floats(-5.0, 5.0, **finite))])
        ref.joint_loads.append((draw(st.sampled_from(linear)), effort))
        parts.append("joint load")
    for _ in range(draw(st.integers(0, 2))):
        frame = draw(st.sampled_from(frames))
        point = np.array(small_vector(draw, 0.5))
        force = np.array(small_vector(draw, 20.0))
        torque = np.zeros(3) if has_continuous else np.array(small_vector(draw, 2.0))
        ref.point_loads.append((frame, point, force, torque))
        parts.append("point load")
    followers = {c[0] for c in couplings}
    for name in linear:
        if name in followers or not draw(st.booleans()):
            continue
        lower = ref.start[name] - draw(st.floats(0.05, 1.0, **finite))
        upper = ref.start[name] + draw(st.floats(0.05, 1.0, **finite))
        side = draw(st.sampled_from(["both", "lower", "upper"]))
        lower, upper = (None if side == "upper" else lower), (None if side == "lower" else upper)
        ref.limit_entries.append((name, lower, upper))
        parts.append("stop")
    if draw(st.booleans()):
        # A point of a body held where it is at the start: a loop to the world, kept only where
        # it leaves the mechanism some motion.
        frame = draw(st.sampled_from(frames))
        point = np.array(small_vector(draw, 0.5))
        q0 = ref.q_start()
        data = model.createData()
        pinocchio.framesForwardKinematics(model, data, q0)
        ref.loops.append(
            (frame, point, "universe", data.oMf[model.getFrameId(frame)].act(point), "point")
        )
        rows = ref.loop_jacobian(model, q0)[1]
        jacobian = np.vstack([rows, *_coupling_rows(model, couplings)])
        sigma = np.linalg.svd(jacobian, compute_uv=False)
        clear = sigma > 1e-2 * sigma[0]
        # Kept where it leaves some motion, its equations are clearly independent or clearly
        # redundant (a singular start would make the rank a matter of round-off), and it holds
        # something: a point on a hinge's axis has a Jacobian of round-off, which the solver
        # counts as an equation (its rank cut is relative: reported, not tested here).
        if (
            model.nv - clear.sum() >= 1
            and np.all(clear | (sigma < 1e-12 * sigma[0]))
            and np.linalg.norm(rows, 2) > 1e-2
        ):
            parts.append("loop")
        else:
            ref.loops.pop()
    return ",".join(kinds) + ": " + (", ".join(parts) or "springs only"), ref, couplings


def scene_of(ref: Reference, couplings) -> pinsettle.Scene:
    """The reference's mechanism as a pinsettle.Scene, through its API."""
    scene = pinsettle.Scene(ref.full)
    for follower, leader, multiplier, offset in couplings:
        scene.add_coupling(follower, leader, multiplier, offset)
    scene.set_start(ref.start)
    for name, stiffness, rest in ref.joint_springs:
        scene.add_joint_spring(name, stiffness, rest)
    for frame_a, point_a, frame_b, point_b, stiffness, rest_length in ref.springs:
        scene.add_spring(
            {"frame": frame_a, "point": point_a},
            {"frame": frame_b, "point": point_b},
            stiffness,
            rest_length,
        )
    for name, effort in ref.joint_loads:
        scene.add_load(name, float(effort[0]))
    for frame, point, force, torque in ref.point_loads:
        scene.add_load(frame=frame, point=point, force=force, torque=torque)
    for name, lower, upper in ref.limit_entries:
        scene.set_limit(name, lower=lower, upper=upper)
    for frame_a, point_a, frame_b, point_b, kind in ref.loops:
        scene.add_loop(
            {"frame": frame_a, "point": point_a}, {"frame": frame_b, "point": point_b}, kind
        )
    return scene


def _coupling_rows(model: pinocchio.Model, couplings) -> list[np.ndarray]:
    rows = []
    for follower, leader, multiplier, _ in couplings:
        row = np.zeros(model.nv)
        row[model.idx_vs[model.getJointId(follower)]] = 1.0
        row[model.idx_vs[model.getJointId(leader)]] = -multiplier
        rows.append(row)
    return rows


def check_scene_rest(ref: Reference, couplings, result: pinsettle.Result, scale: float) -> Verdict:
    """The conditions of a rest at result.q, by the reference: the loops closed and the
    couplings held, every stop pushing (never pulling) and no force along the motions left
    free; returns the reference verdict there."""
    q = result.q
    model = ref.reduced(q)
    for follower, leader, multiplier, offset in couplings:
        x = q[model.idx_qs[model.getJointId(follower)]]
        y = q[model.idx_qs[model.getJointId(leader)]]
        assert abs(x - multiplier * y - offset) <= 1e-10, (follower, x, multiplier * y + offset)
    if ref.loops:
        assert np.max(np.abs(ref.loop_jacobian(model, q)[0])) <= 1e-10
    for name, (low, high) in ref.stops(model).items():
        x = q[model.idx_qs[model.getJointId(name)]]
        assert low <= x <= high, (name, x, low, high)
    verdict = scene_verdict(ref, q, couplings)
    assert verdict.pull <= POLISHED_RESIDUAL_DIFFERENCED * scale, verdict.pull  # stops push
    if not (ref.loops or couplings):
        # A tree: the conditions of a rest against stops, joint by joint (KKT).
        violation = ref.rest_conditions(model, q, ref.force_reduced(model, q))[0]
        tolerance = max(POLISHED_RESIDUAL_DIFFERENCED * scale, 2.0 * result.residual)
        assert float(np.max(violation, initial=0.0)) <= tolerance, violation
    return verdict


def test_random_scenes_settle_at_rests_the_reference_confirms():
    # Every random scene has a rest (each joint on a spring); released from its start with the
    # default settings it must converge (a least share), at a rest the reference confirms, with
    # the reference's verdict.
    outcomes = Counter()

    @settings(PROPERTIES, max_examples=300)
    @given(data=st.data())
    def rests(data):
        description, ref, couplings = data.draw(scenes(), label="scene")
        for part in description.split(": ")[1].split(", "):
            event(part)
        scene = scene_of(ref, couplings)
        result = pinsettle.solve(scene, max_steps=20000, max_time=MAX_TIME)
        outcomes[result.status] += 1
        if not result.converged:
            assert result.status in ("max_steps", "time_limit"), (description, result.reason)
            return  # counted: the least share below
        rng = np.random.default_rng(0)
        scale = max(
            ref.residual(ref.q_start()),
            *(ref.residual(ref.random_configuration(rng)) for _ in range(3)),
        )
        verdict = check_scene_rest(ref, couplings, result, scale)
        outcomes["decided", verdict.decided] += 1
        differenced = bool(ref.loops or couplings or has_varying_joints(scene.model))
        check_converged_residual(result, scale, verdict, differenced, description)
        verdict.check(result.stability, result.min_stiffness_eigenvalue)

    rests()
    runs = sum(n for key, n in outcomes.items() if isinstance(key, str))
    assert outcomes["converged"] >= LEAST_CONVERGED_SHARE * runs, outcomes
    decided = outcomes["decided", True] / max(1, outcomes["converged"])
    assert decided >= LEAST_DECIDED_SHARE["scenes"], outcomes


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


def falling_tree(free_root: bool = False) -> pinocchio.Model:
    """The tree, by default without its second root (the PX slider): nothing holds that one
    either, and the solver names such a root's fall before any step (explainFreeFall); without
    it, the fall along the PY slider below the revolute root is the runaway test's to see."""
    model = pinocchio.Model()
    for kind, parent, rpy, xyz, mass, com, diagonal in FALLING_TREE[: None if free_root else 3]:
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
    # With its second root, a slider on the world that gravity pulls along: named at once.
    whole = pinsettle.solve(falling_tree(free_root=True), limits=False, scale_stiff_modes=scale)
    assert whole.status == "no_equilibrium" and whole.steps == 0
    assert "nothing holds joint 'PX'" in whole.reason


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

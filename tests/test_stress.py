"""The stress suite (benchmarks/stress.py) as tests: every extreme case, each energy measure and
kt in {0, 0.5, 0.9}, must end converged at the independent Newton root (1e-6 in every joint), a
rest that the reference's own finite-difference stiffness finds stable or neutral, or with the
status the case expects; never non-finite, never past its wall-clock budget."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "stress.py"
_spec = importlib.util.spec_from_file_location("pinsettle_stress", _PATH)
stress = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = stress  # dataclasses look their module up there
_spec.loader.exec_module(stress)

RUNS = stress.runs()


@pytest.mark.parametrize(
    "case, energy, kt", RUNS, ids=[f"{c.name}-{e}-kt{kt:g}" for c, e, kt in RUNS]
)
def test_stress_case(case, energy, kt):
    outcome = stress.run(case, energy, kt)
    assert outcome.passed, f"{case.name} ({energy}, kt={kt}): {outcome.why}"
    assert outcome.seconds < stress.MAX_TIME  # the budget, not a speed claim: never a hang
    if case.expect == "equilibrium":
        assert outcome.error <= stress.JOINT_TOLERANCE
    else:
        assert math.isnan(outcome.error) and outcome.status == case.expect


def test_the_suite_covers_the_extremes_of_the_issue():
    names = {c.name for c in stress.cases()}
    groups = {c.group for c in stress.cases()}
    assert {"stiffness", "mass ratio", "scale", "chain length", "gravity"} <= groups
    assert {"far start", "saddle start", "no equilibrium"} <= groups
    assert "slider spring k=1e+08" in names and "chain of 100" in names and "chain of 2" in names
    assert {"gravity 0 m/s^2", "gravity 1000 m/s^2"} <= names
    assert len(RUNS) == len(stress.cases()) * 2 * 3


def test_the_reference_is_independent_and_right():
    # The suite's Newton reference against a closed form: a pendulum with a joint spring,
    # m g l sin(t) = -k (t - rest) at rest (l the rod's centre of mass, 0.5 m).
    model = stress.chain([1.0], [1.0])
    physics = stress.Physics(model, joint_springs=[("j0", 20.0, 1.0)])
    root, uncertainty = stress.newton(physics, np.array([0.5]))
    t = root[0]
    assert uncertainty < 1e-12
    assert 1.0 * 9.81 * 0.5 * math.sin(t) == pytest.approx(-20.0 * (t - 1.0), abs=1e-12)
    # And its static force is that of pinsettle's scene of the same physics.
    scene = physics.scene()
    q = np.array([0.3])
    assert stress.static_force(physics, q) == pytest.approx(scene.static_force(q), abs=1e-12)


def test_the_reference_verdict_is_its_own():
    # The suite's stability verdict comes from its own finite-difference stiffness.
    pendulum = stress.Physics(stress.chain([1.0], [1.0]))
    hanging = stress.stability(pendulum, np.array([0.0]))
    upright = stress.stability(pendulum, np.array([math.pi]))
    assert hanging.verdict == "stable"
    assert hanging.min_eigenvalue == pytest.approx(9.81 * 0.5, rel=1e-6)  # m g l
    assert upright.verdict == "unstable"
    assert upright.min_eigenvalue == pytest.approx(-9.81 * 0.5, rel=1e-6)
    # The UR5 hanging down turns freely about the vertical: zero eigenvalues, neutral; with its
    # upper arm standing up it is an equilibrium again, a maximum (-m g l of the arm).
    ur5 = stress.Physics(stress.pinsettle.load_robot("ur5"))
    down = np.array([0.0, math.pi / 2, 0.0, -math.pi / 2, 0.0, 0.0])
    up = np.array([0.0, -math.pi / 2, 0.0, -math.pi / 2, 0.0, 0.0])
    assert np.max(np.abs(stress.static_force(ur5, down))) < 1e-9
    assert np.max(np.abs(stress.static_force(ur5, up))) < 1e-9
    assert stress.stability(ur5, down).verdict == "neutral"
    assert stress.stability(ur5, up).verdict == "unstable"
    assert stress.stability(ur5, up).min_eigenvalue < -10.0


def answer_at(q: float):
    """A stand-in for pinsettle.solve that says it converged to a stable rest at q (1 DoF)."""

    class Answer:
        v = np.zeros(1)
        status = "converged"
        converged = True
        stability = "stable"
        steps = 0
        residual = 0.0
        dt_reductions = 0
        scaled_modes = 0

    Answer.q = np.array([q])
    return lambda *args, **kwargs: Answer()


def test_a_rest_on_a_saddle_fails_whatever_the_solver_says(monkeypatch):
    # A solver that stops a pendulum exactly upright and calls it stable: the case must fail
    # on the reference's own eigenvalues (Newton agrees the pose is an equilibrium).
    physics = stress.Physics(stress.chain([1.0], [1.0]))
    case = stress.Case(
        "upright pendulum, wrongly stable", "test", stress._physics_case(physics, [math.pi])
    )

    monkeypatch.setattr(stress.pinsettle, "solve", answer_at(math.pi))
    outcome = stress.run(case, "exact", 0.5)
    assert not outcome.passed
    assert "saddle" in outcome.why and outcome.reference_stability == "unstable"
    assert outcome.error <= stress.JOINT_TOLERANCE  # it is an equilibrium: only its kind fails


def test_a_rest_at_a_stop_is_checked_by_the_conditions_of_a_stop(monkeypatch):
    # A hanging pendulum with stops at 0.3 and 1.0 rad comes to rest on the lower one: gravity
    # presses it there, the reference holds that joint and checks the sign of the force.
    physics = stress.Physics(stress.chain([1.0], [1.0]), stops=[("j0", 0.3, 1.0)])
    case = stress.Case("pendulum on a stop", "test", stress._physics_case(physics, [0.8]))
    real = stress.run(case, "exact", 0.5)
    assert real.passed, real.why
    assert real.status == "converged"
    held, broken = stress.pressed(physics, np.array([0.3]))
    assert list(held) == [0] and broken == ""

    # Resting on the upper stop: gravity pulls it away, no stop can hold it there.
    monkeypatch.setattr(stress.pinsettle, "solve", answer_at(1.0))
    outcome = stress.run(case, "exact", 0.5)
    assert not outcome.passed and "pulled away" in outcome.why
    # Beyond a stop.
    monkeypatch.setattr(stress.pinsettle, "solve", answer_at(1.2))
    outcome = stress.run(case, "exact", 0.5)
    assert not outcome.passed and "outside" in outcome.why
    # Without the stops the reference finds that 0.3 rad is no equilibrium.
    free = stress.Case(
        "pendulum, no stop", "test", stress._physics_case(stress.Physics(physics.model), [0.8])
    )
    monkeypatch.setattr(stress.pinsettle, "solve", answer_at(0.3))
    assert not stress.run(free, "exact", 0.5).passed


def test_the_reference_reads_the_model_limits_as_pinsettle_does():
    ur5 = stress.pinsettle.load_robot("ur5")
    ours = {name: (lower, upper) for name, lower, upper in stress.model_stops(ur5)}
    assert ours == stress.pinsettle._scene.model_stops(ur5)


def test_stiff_mode_scaling_is_used_only_where_it_pays(chain_urdf):
    """Scaling r modes costs every step an nv x nv inverse mass matrix: on a uniform 200-link
    chain (its modes spread past the cap in some poses) it once took 29 modes, 6 % more steps
    and 2.4 times the time of the unscaled run; on a 9-link chain of
    1e-4 to 1e4 kg and 1 mm to 100 m links it saves nine steps in ten."""
    chain = pinocchio.buildModelFromXML(chain_urdf(200))
    q0 = np.zeros(chain.nq)
    q0[0] = np.pi / 2
    default = pinsettle.solve(chain, q0, limits=False)
    # The default growth of the step, which 'auto' leaves out without the scaling.
    growth = pinsettle.Settings().effective_dt_growth
    plain = pinsettle.solve(chain, q0, limits=False, scale_stiff_modes=False, dt_growth=growth)
    assert default.converged and default.scaled_modes == 0
    assert default.steps == plain.steps and np.array_equal(default.q, plain.q)

    n = 9
    graded = stress.chain(np.logspace(-4, 4, n), np.logspace(-3, 2, n)[::-1])
    scaled = pinsettle.solve(graded, np.full(n, 0.5), limits=False)
    unscaled = pinsettle.solve(graded, np.full(n, 0.5), limits=False, scale_stiff_modes=False)
    assert scaled.converged and unscaled.converged and scaled.scaled_modes > 0
    assert scaled.steps < 0.2 * unscaled.steps, (scaled.steps, unscaled.steps)
    assert _turns_apart(scaled.q, unscaled.q) < 1e-6


def test_a_spread_without_a_gap_is_scaled_down_and_keeps_the_rest():
    """A 9-link chain of 100 m down to 1 mm links has no gap in its spectrum, only a spread
    (each mode a few times above the next): scaling the modes more than 1e3 times above the
    softest cuts its steps more than tenfold (the unscaled run takes 16,858), and the rest is
    the unscaled run's (its 1 mm tip may end whole turns away: the same pose), a zero of
    Pinocchio's own gravity torque."""
    n = 9
    graded = stress.chain(np.ones(n), np.logspace(-3, 2, n)[::-1])
    q0 = np.full(n, 0.5)
    # The damping's own runs (Newton taking over at a damping event would end both sooner).
    scaled = pinsettle.solve(graded, q0, limits=False, newton_takeover=False)
    unscaled = pinsettle.solve(
        graded, q0, limits=False, scale_stiff_modes=False, newton_takeover=False
    )
    assert scaled.converged and unscaled.converged and scaled.scaled_modes > 0
    assert scaled.steps < 0.1 * unscaled.steps, (scaled.steps, unscaled.steps)
    assert _turns_apart(scaled.q, unscaled.q) < 1e-6
    data = graded.createData()
    gravity = pinocchio.computeGeneralizedGravity(graded, data, scaled.q)
    scale = np.abs(pinocchio.computeGeneralizedGravity(graded, data, q0)).max()
    assert np.abs(gravity).max() < 1e-10 * scale
    assert scaled.stability == "stable"


def _turns_apart(a: np.ndarray, b: np.ndarray) -> float:
    """Largest difference of two sets of revolute angles, whole turns aside (rad)."""
    return float(np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b))))).max())

"""pinsettle.solve: equilibria checked with pinocchio outside the solver, statuses, trace,
callback, Ctrl-C and settings handling."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pinocchio
import pinsettle
import pytest

G = 9.81  # pinocchio's default gravity (m/s^2)


def gravity(model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
    """Generalized gravity g(q), recomputed with a fresh Data: the static residual."""
    return pinocchio.computeGeneralizedGravity(model, model.createData(), q).copy()


def stiffness(model: pinocchio.Model, q: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """K = dg/dq by central differences along the tangent directions (pinocchio.integrate)."""
    k = np.zeros((model.nv, model.nv))
    for i in range(model.nv):
        step = np.zeros(model.nv)
        step[i] = h
        plus = gravity(model, pinocchio.integrate(model, q, step))
        minus = gravity(model, pinocchio.integrate(model, q, -step))
        k[:, i] = (plus - minus) / (2 * h)
    return k


def assert_stable_equilibrium(model, result, max_residual):
    """Converged, g(q) ~ 0 recomputed with pinocchio, and no direction of negative stiffness.

    At a stable equilibrium the potential energy has a minimum: the symmetric part of
    K = dg/dq (the Hessian of the potential) is positive semi-definite. Neutral directions
    (a rotation about a vertical axis) give eigenvalues ~ 0, hence the -1e-6 margin.
    """
    assert result.status == "converged"
    assert result.converged
    residual = np.max(np.abs(gravity(model, result.q)))
    assert residual < max_residual
    assert result.residual == pytest.approx(residual, rel=1e-12, abs=1e-300)
    k = stiffness(model, result.q)
    # The finite differences agree with pinocchio's analytic derivative of g.
    analytic = pinocchio.computeGeneralizedGravityDerivatives(model, model.createData(), result.q)
    assert np.allclose(k, analytic, rtol=0.0, atol=1e-6 * max(1.0, np.abs(analytic).max()))
    eigenvalues = np.linalg.eigvalsh(0.5 * (k + k.T))
    assert eigenvalues.min() > -1e-6, eigenvalues
    return eigenvalues


def assert_consistent_result(model, result):
    """The reported energies and residual are those of the reported state."""
    data = model.createData()
    exact = pinocchio.computeKineticEnergy(model, data, result.q, result.v)
    assert result.kinetic_energy == pytest.approx(exact, rel=1e-10, abs=1e-300)
    assert result.simplified_kinetic_energy == pytest.approx(
        pinsettle.kinetic_energies(model, result.q, result.v)[1], rel=1e-10, abs=1e-300
    )
    assert result.residual == pytest.approx(
        np.max(np.abs(gravity(model, result.q))), rel=1e-12, abs=0.0
    )
    assert result.q.shape == (model.nq,)
    assert result.v.shape == (model.nv,)


# --- The pendulum: the answer is known, q = 0 ---------------------------------------------

# max_e = 1e-20 J over the 100-sample window leaves an amplitude of ~1e-11 rad, i.e. a residual
# m g l |q| ~ 1e-10 N m, well below the 1e-8 asked for.
PENDULUM_CASES = {
    "released_at_1": ([1.0], {}),
    "released_at_-2.5": ([-2.5], {}),
    "kt_0": ([1.0], {"kt": 0.0}),
    "simplified_energy": ([1.0], {"energy": "simplified"}),
    "backtrack": ([1.0], {"backtrack": True}),
    "backtrack_kt_0.2_from_-2.5": ([-2.5], {"backtrack": True, "kt": 0.2}),
    "damping_alone": ([1.0], {"newton_takeover": False}),
}


@pytest.mark.parametrize("q0, overrides", PENDULUM_CASES.values(), ids=PENDULUM_CASES.keys())
def test_pendulum_settles_hanging_down(pendulum, q0, overrides):
    result = pinsettle.solve(pendulum, q0, max_e=1e-20, **overrides)
    assert result.status == "converged"
    assert abs(result.q[0]) < 1e-8  # analytic answer: straight down (not 2 pi k, k != 0)
    assert np.max(np.abs(gravity(pendulum, result.q))) < 1e-8
    assert result.peaks >= 1  # it swung and was damped: q0 is not an equilibrium
    if not result.settings.newton_takeover:  # (the default may end it at a damping event)
        assert result.steps > result.settings.ds  # the stopping rule's window was filled
    assert_consistent_result(pendulum, result)


def test_pendulum_launched_from_rest_position(pendulum):
    # Kicked at q = 0 with 2 rad/s (0.5 m g l (1 - cos q) < E: it swings below the top).
    result = pinsettle.solve(pendulum, [0.0], v0=[2.0], max_e=1e-20)
    assert result.converged
    assert abs(result.q[0]) < 1e-8
    assert result.settings.kt == 0.0  # the default


def test_kt_scales_the_velocity_at_each_peak(pendulum):
    # With a trace of every step: the step right after a damping event re-evaluates the same
    # configuration with kt v, so its exact energy is kt^2 times the previous sample's, and the
    # simulated time does not advance (without backtracking, which moves the configuration).
    kt = 0.3
    result = pinsettle.solve(
        pendulum,
        [1.0],
        kt=kt,
        trace_every=1,
        trace_capacity=10**6,
        max_e=1e-14,
        backtrack=False,
        newton_takeover=False,  # every event a damping, to the stopping rule
    )
    assert result.converged
    trace = result.trace
    assert trace.stride == 1 and len(trace.step) == result.steps
    e = trace.kinetic_energy
    damped = [
        k
        for k in range(1, len(e) - 1)
        if e[k] > 0 and e[k + 1] == pytest.approx(kt**2 * e[k], rel=1e-12, abs=0.0)
    ]
    assert len(damped) == result.peaks
    for k in damped:
        assert trace.time[k + 1] == trace.time[k]
        # The sample before the damping step is a local maximum of the energy.
        assert e[k - 1] > e[k] and e[k - 1] > e[k - 2]


def test_kt_0_stops_the_motion_at_each_peak(pendulum):
    result = pinsettle.solve(
        pendulum,
        [1.0],
        kt=0.0,
        trace_every=1,
        trace_capacity=10**6,
        max_e=1e-20,
        newton_takeover=False,  # every event a damping, to the stopping rule
    )
    assert result.trace.stride == 1  # every step kept
    assert result.converged
    # Released at rest, then each damping event zeroes the velocity: one exactly-zero energy
    # sample at the start and one after each peak.
    zeros = np.flatnonzero(result.trace.kinetic_energy == 0.0)
    assert zeros[0] == 0
    assert len(zeros) == result.peaks + 1


# --- Robots: stable equilibria checked with gravity and stiffness ---------------------------

# max_e = 1e-16 J keeps the residual of the UR5 below 1e-8 N m (1e-6 asked for); the default
# 1e-12 leaves ~5e-7.
UR5_SETTINGS = [
    {"energy": "exact", "kt": 0.5},
    {"energy": "exact", "kt": 0.0},
    {"energy": "simplified", "kt": 0.5},
    {"energy": "simplified", "kt": 0.0},
]


@pytest.mark.parametrize("overrides", UR5_SETTINGS, ids=lambda s: f"{s['energy']}-kt{s['kt']}")
def test_ur5_settles_to_a_stable_pose(ur5, overrides):
    result = pinsettle.solve(ur5, np.zeros(ur5.nq), max_e=1e-16, **overrides)
    eigenvalues = assert_stable_equilibrium(ur5, result, max_residual=1e-6)
    # The hanging arm is free to turn about the vertical base axis: a neutral direction.
    assert abs(eigenvalues[0]) < 1e-6
    assert_consistent_result(ur5, result)


def test_ur5_neutral_pose_is_not_an_equilibrium(ur5):
    # Otherwise the test above would be trivial.
    assert np.max(np.abs(gravity(ur5, pinocchio.neutral(ur5)))) > 1.0


def test_double_pendulum_settles_strictly_stable(double_pendulum):
    q0 = pinocchio.neutral(double_pendulum)
    assert np.max(np.abs(gravity(double_pendulum, q0))) > 1e-6  # released off equilibrium
    result = pinsettle.solve(double_pendulum, q0, max_e=1e-16)
    eigenvalues = assert_stable_equilibrium(double_pendulum, result, max_residual=1e-6)
    assert eigenvalues.min() > 1e-3  # no neutral direction: a strict minimum


TURNING_JOINTS = {
    "universal": lambda: pinocchio.JointModelUniversal(
        np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    ),
    "spherical-zyx": pinocchio.JointModelSphericalZYX,
    "ellipsoid": lambda: pinocchio.JointModelEllipsoid(0.1, 0.2, 0.3),
}


@pytest.mark.parametrize("kind", sorted(TURNING_JOINTS))
def test_pendulums_on_joints_whose_axes_turn_settle_to_round_off(kind):
    """A universal, a ZYX-spherical and an ellipsoid joint turn their own axes with their
    angles; Pinocchio's gravity derivatives miss that turn, so the solver differences the
    stiffness there. Released at 1.2 rad on every coordinate, the pendulum settles (the ZYX one
    took 767,804 steps on the analytic derivative) and the polish brings the residual to
    round-off (on the ellipsoid, whose rest has a neutral direction, a rank cut applied after
    the decomposition once left 7e-5 N m). Checked with g(q) recomputed here and the
    eigenvalues of a stiffness differenced here."""
    model = pinocchio.Model()
    joint = model.addJoint(0, TURNING_JOINTS[kind](), pinocchio.SE3.Identity(), "gimbal")
    model.appendBodyToJoint(
        joint,
        pinocchio.Inertia(2.0, np.array([0.1, -0.05, -0.3]), np.diag([0.02, 0.03, 0.01])),
        pinocchio.SE3.Identity(),
    )
    result = pinsettle.solve(model, np.full(model.nq, 1.2), limits=False)
    assert result.status == "converged"
    weight = 2.0 * 9.81 * np.linalg.norm([0.1, -0.05, -0.3])  # the largest gravity torque
    residual = np.max(np.abs(gravity(model, result.q)))
    assert residual <= 1e-12 * weight, (residual, result.residual_before_polish)
    assert result.residual == pytest.approx(residual, rel=1e-12, abs=1e-300)
    assert result.steps < 2_000
    k = stiffness(model, result.q)
    eigenvalues = np.linalg.eigvalsh(0.5 * (k + k.T))
    band = 1e-6 * np.abs(eigenvalues).max()
    assert eigenvalues.min() > -band, eigenvalues
    expected = "neutral" if np.abs(eigenvalues).min() <= band else "stable"
    assert str(result.stability) == expected, eigenvalues


# The Panda's arm passes through its joint stops on its way to hanging down: these two tests
# are about the equilibria of the unlimited model (g(q) = 0, the full stiffness), so they turn
# the limits off (tests/test_limits.py settles the real Panda on its stops).


@pytest.mark.parametrize("energy", ["exact", "simplified"])
def test_panda_arm_settles_to_a_stable_pose(panda_arm, energy):
    result = pinsettle.solve(panda_arm, max_e=1e-16, energy=energy, limits=False)
    assert_stable_equilibrium(panda_arm, result, max_residual=1e-6)


def test_panda_with_free_fingers_has_no_equilibrium(panda, panda_arm):
    """Without its stops the full Panda's fingers are prismatic joints without spring or
    limit: where the arm hangs, gravity has a component along them and they slide away for
    ever. The solver must not claim convergence (this is physics, not a solver failure)."""
    arm = pinsettle.solve(panda_arm, max_e=1e-16, limits=False)
    q_full = np.concatenate([arm.q, [0.0, 0.0]])
    assert np.max(np.abs(gravity(panda, q_full)[-2:])) > 1e-2
    result = pinsettle.solve(panda, max_steps=20_000, limits=False)
    assert result.status == "max_steps"
    assert not result.converged
    assert np.max(np.abs(result.q[-2:])) > panda.upperPositionLimit[-1]  # past the 4 cm stop
    assert result.residual > 1.0


def test_resolving_from_an_equilibrium_stays_there(double_pendulum):
    first = pinsettle.solve(double_pendulum, max_e=1e-16)
    second = pinsettle.solve(double_pendulum, first.q, max_e=1e-16)
    assert second.converged
    assert second.steps < first.steps
    assert np.allclose(second.q, first.q, atol=1e-7)


def test_solve_is_deterministic(ur5):
    a = pinsettle.solve(ur5, max_e=1e-14)
    b = pinsettle.solve(ur5, max_e=1e-14)
    assert a.steps == b.steps and a.peaks == b.peaks
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.v, b.v)


# --- Free-flyer: no equilibrium, falls for ever --------------------------------------------


def test_free_flyer_fall_is_named_at_once(solo12):
    # Nothing holds the floating quadruped: the net force on its free flyer is its weight in
    # every pose, so the run ends before its first step with that force named.
    q0 = pinocchio.neutral(solo12)
    result = pinsettle.solve(solo12, q0, max_steps=2000, dt=1e-3)
    assert result.status == "no_equilibrium" and not result.converged
    assert result.steps == 0 and np.array_equal(result.q, q0)
    total_mass = sum(inertia.mass for inertia in solo12.inertias)
    weight = np.linalg.norm(gravity(solo12, q0)[:3])
    assert weight == pytest.approx(total_mass * G, rel=1e-12)
    assert "'root_joint'" in result.reason and f"{weight:.4g} N" in result.reason
    assert result.residual == pytest.approx(np.max(np.abs(gravity(solo12, q0))), rel=1e-12)


def weightless(model: pinocchio.Model) -> pinocchio.Model:
    model = model.copy()
    model.gravity.linear[:] = 0.0
    return model


def test_free_flyer_drifts_at_its_velocity(solo12):
    # Without gravity nothing pulls (no fall to name) and nothing changes the momentum: from a
    # straight drift the whole robot moves as one body, z_n = z_0 + n dt v, semi-implicit Euler
    # exactly, with a unit quaternion throughout.
    model = weightless(solo12)
    n = 2000
    q0 = pinocchio.neutral(model)
    v0 = np.zeros(model.nv)
    v0[2] = -0.5
    result = pinsettle.solve(model, q0, v0=v0, max_steps=n, dt=1e-3)
    assert result.status == "max_steps" and not result.converged and result.steps == n
    assert result.peaks == 0  # the energy stays constant
    assert abs(np.linalg.norm(result.q[3:7]) - 1.0) < 1e-9
    data = model.createData()
    com0 = pinocchio.centerOfMass(model, data, q0).copy()
    com = pinocchio.centerOfMass(model, data, result.q).copy()
    assert com - com0 == pytest.approx([0.0, 0.0, -0.5 * n * 1e-3], abs=1e-9)


def test_free_flyer_spinning_keeps_a_unit_quaternion(solo12):
    model = weightless(solo12)  # with gravity the fall is named before any step
    pinocchio.seed(7)
    bounds = np.full(model.nq, 1.0)  # explicit finite bounds for the free-flyer translation
    q0 = pinocchio.randomConfiguration(model, -bounds, bounds)
    v0 = np.random.default_rng(7).normal(scale=3.0, size=model.nv)
    result = pinsettle.solve(model, q0, v0=v0, max_steps=2000)
    # Weightless, the damping brings the spin to a stop anywhere: a neutral rest.
    assert result.steps > 0 and result.status in ("converged", "max_steps")
    assert not result.converged or result.stability == "neutral"
    assert abs(np.linalg.norm(result.q[3:7]) - 1.0) < 1e-9
    assert not np.allclose(result.q[3:7], q0[3:7])  # it did rotate


# --- Statuses --------------------------------------------------------------------------


def test_max_steps(pendulum):
    result = pinsettle.solve(pendulum, [1.0], max_steps=5, dt=1e-3)
    assert result.status == "max_steps"
    assert result.steps == 5
    assert result.peaks == 0
    assert result.sim_time == pytest.approx(5 * result.settings.dt)
    assert 0.0 < result.q[0] < 1.0  # it started to fall towards 0
    assert_consistent_result(pendulum, result)


def test_time_limit(ur5):
    # max_e = 0 can never hold with ds >= 2 (the newest sample must be below a positive one),
    # and without the takeover nothing else ends the run.
    result = pinsettle.solve(ur5, max_e=0.0, max_time=1e-9, check_every=64, newton_takeover=False)
    assert result.status == "time_limit"
    assert result.steps > 0 and result.steps % 64 == 0  # the clock is read every check_every


def test_diverged_keeps_the_last_finite_state(pendulum):
    # An energy of ~1e400 J overflows at the first step, and at every roll-back to the start:
    # halving the step cannot help, so after 30 halvings the run is declared diverged.
    result = pinsettle.solve(pendulum, [1.0], v0=[1e200])
    assert result.status == "diverged"
    assert result.dt_reductions == 30 and result.steps == 31
    assert "halved 30 times" in result.reason
    assert result.q.tolist() == [1.0] and result.v.tolist() == [1e200]


def test_diverged_on_a_huge_time_step(pendulum):
    # dt v overflows when the configuration is integrated, even at 2^-30 dt.
    result = pinsettle.solve(pendulum, [1.0], dt=1e300, max_steps=100)
    assert result.status == "diverged" and result.dt_reductions == 30
    assert result.dt == pytest.approx(1e300 * 2.0**-30)
    assert np.all(np.isfinite(result.q)) and np.all(np.isfinite(result.v))


@pytest.mark.parametrize("dt", [0.2, 1.0, 10.0])
def test_a_step_past_the_stability_limit_is_halved_until_it_settles(dt):
    # Mass 2 kg on a 500 N/m spring: omega = 15.8 rad/s, explicit Euler is stable only for
    # dt < 2 / omega = 0.126 s. A fixed step beyond that explodes; the guard rolls back to the
    # last good state, halves the step and goes on, to the exact answer -m g / k. (Without the
    # slider's stops at +-0.5 m, which bound the motion and keep the energy from exploding.)
    # kt = 0.5: the halving stops at the first stable step, 0.078 s (h omega = 1.24), and there
    # kt = 0 overshoots: the peak is seen one step late, and stopping dead there leaves the
    # slider 1.25 times as far out each time (README, `dt`).
    scene = pinsettle.load_scene(pinsettle.scene_path("slider_spring"))
    result = pinsettle.solve(scene, dt=dt, max_e=1e-16, limits=False, kt=0.5)
    assert result.status == "converged"
    assert result.dt_reductions >= 1
    assert result.dt == dt * 0.5**result.dt_reductions < 2.0 / np.sqrt(500.0 / 2.0)
    assert result.q[0] == pytest.approx(-2.0 * 9.81 / 500.0, abs=1e-9)
    assert result.reason == ""


# --- Trace ---------------------------------------------------------------------------


def test_trace_is_none_by_default(pendulum):
    assert pinsettle.solve(pendulum, [1.0], max_steps=100).trace is None


def test_trace_every_10(pendulum):
    q0, v0 = np.array([1.0]), np.array([0.5])
    result = pinsettle.solve(pendulum, q0, v0=v0, trace_every=10, max_e=1e-14, dt=1e-3)
    trace = result.trace
    assert trace.stride == 10
    assert np.all(trace.step % 10 == 0)
    assert np.all(np.diff(trace.step) == 10)  # capacity not reached: every 10th step
    assert trace.step[0] == 0
    assert trace.step[-1] > result.steps - 1 - trace.stride  # covers the whole run
    assert np.all(trace.kinetic_energy >= 0) and np.all(trace.simplified_kinetic_energy >= 0)
    assert np.all(np.diff(trace.time) >= 0)  # time never goes back, backtracking or not
    assert np.all(trace.time <= trace.step * result.settings.dt + 1e-12)
    # The first sample is the start state.
    exact0, simplified0 = pinsettle.kinetic_energies(pendulum, q0, v0)
    assert trace.kinetic_energy[0] == pytest.approx(
        pinocchio.computeKineticEnergy(pendulum, pendulum.createData(), q0, v0), rel=1e-12
    )
    assert trace.simplified_kinetic_energy[0] == pytest.approx(simplified0, rel=1e-12)
    assert trace.kinetic_energy[0] == pytest.approx(exact0, rel=1e-12)


def test_trace_capacity_bounds_the_samples(pendulum):
    result = pinsettle.solve(
        pendulum,
        [1.0],
        trace_every=1,
        trace_capacity=16,
        max_e=1e-14,
        dt=1e-3,
        newton_takeover=False,  # the damping's long run, to its stopping rule
    )
    assert result.steps > 1000
    trace = result.trace
    assert 8 <= len(trace.step) <= 16
    assert trace.stride > 1 and trace.stride & (trace.stride - 1) == 0  # doubled, from 1
    assert np.all(trace.step % trace.stride == 0)
    assert np.all(np.diff(trace.step) > 0)
    assert trace.step[0] == 0
    assert trace.step[-1] > result.steps - 1 - trace.stride  # still covers the whole run
    for name in ("time", "kinetic_energy", "simplified_kinetic_energy"):
        assert len(getattr(trace, name)) == len(trace.step)


# --- Callback and Ctrl-C ----------------------------------------------------------------


def test_callback_true_aborts(ur5):
    calls = []

    def stop_on_third_call():
        calls.append(None)
        return len(calls) == 3

    # Newton's takeover off: with it the UR5 is at rest by step 23, before the third call.
    result = pinsettle.solve(
        ur5, max_e=0.0, check_every=10, callback=stop_on_third_call, newton_takeover=False
    )
    assert result.status == "aborted"
    assert len(calls) == 3
    assert result.steps == 10 * len(calls)
    assert not np.allclose(result.q, pinocchio.neutral(ur5))  # the current state is returned
    assert_consistent_result(ur5, result)


def test_callback_is_called_every_check_every_steps(pendulum):
    calls = []
    # A stopping window of 100 steps (and no takeover): the pendulum does not settle within
    # the 100-step budget.
    result = pinsettle.solve(
        pendulum,
        [1.0],
        max_steps=100,
        ds=100,
        check_every=10,
        callback=lambda: calls.append(None),
        newton_takeover=False,
    )
    assert result.status == "max_steps"
    assert len(calls) == 9  # at steps 10, 20, ..., 90 (returning None means go on)


def test_callback_exception_propagates(pendulum):
    class Stop(Exception):
        pass

    def fail():
        raise Stop("from the callback")

    with pytest.raises(Stop, match="from the callback"):
        pinsettle.solve(pendulum, [1.0], check_every=5, callback=fail)
    # The interpreter is still usable afterwards.
    assert pinsettle.solve(pendulum, [1.0], max_steps=5).steps == 5


CTRL_C_SCRIPT = textwrap.dedent(
    """
    import signal
    import sys
    import pinsettle

    # Python's own Ctrl-C handling, whoever started this process (a shell's background job
    # starts it with SIGINT ignored, and Python then leaves it so).
    signal.signal(signal.SIGINT, signal.default_int_handler)
    model = pinsettle.load_robot("ur5")
    use_callback = sys.argv[1] == "callback"
    announced = []

    def announce():
        # Called from inside the solver loop: the solve is certainly running.
        if not announced:
            announced.append(True)
            print("started", flush=True)
        return False

    if not use_callback:
        print("started", flush=True)
    # max_e = 0 never holds, nor Newton takes over: the run only ends on the signal.
    result = pinsettle.solve(
        model,
        max_e=0.0,
        max_steps=10**12,
        newton_takeover=False,
        callback=announce if use_callback else None,
    )
    print("status", result.status, flush=True)
    """
)


@pytest.mark.skipif(sys.platform == "win32", reason="sends SIGINT")
@pytest.mark.parametrize("mode", ["callback", "no-callback"])
def test_ctrl_c_aborts_the_solve(mode):
    proc = subprocess.Popen(
        [sys.executable, "-c", CTRL_C_SCRIPT, mode],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "started"
        time.sleep(1.0)
        assert proc.poll() is None  # still solving
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert "KeyboardInterrupt" not in err
    assert out.strip().splitlines()[-1] == "status aborted"
    assert proc.returncode == 0


# --- Settings -----------------------------------------------------------------------------


def test_settings_fields():
    s = pinsettle.Settings(kt=0.3, ds=7, energy="simplified", backtrack=True)
    assert s.kt == 0.3 and s.ds == 7 and s.energy == "simplified" and s.backtrack is True
    assert s.dt == pinsettle.Settings().dt  # untouched fields keep their default
    s.kt = 0.1
    assert s.kt == 0.1
    s.check()  # valid: no exception


def test_settings_defaults():
    s = pinsettle.Settings()
    assert s.to_dict() == {
        "dt": "auto",
        "dt_safety": "auto",
        "kt": 0.0,
        "err": 1e-12,
        "ds": 10,
        "max_e": 1e-6,
        "max_steps": 1_000_000,
        "max_time": float("inf"),
        "energy": "exact",
        "backtrack": True,
        "polish": True,
        "newton_takeover": True,
        "scale_stiff_modes": True,
        "scale_joint_inertia": "auto",
        "dt_growth": "auto",
        "trace_every": 0,
        "trace_capacity": 10_000,
        "trace_configurations": False,
        "check_every": 256,
    }


def test_dt_safety_auto_is_the_measured_factor_of_the_other_settings(pendulum):
    s = pinsettle.Settings()
    assert s.dt_safety == "auto" and s.effective_dt_safety == 0.3  # backtracking, exact energy
    assert pinsettle.Settings(backtrack=False).effective_dt_safety == 0.2
    assert pinsettle.Settings(energy="simplified").effective_dt_safety == 0.2
    assert pinsettle.Settings(dt_safety=0.25, backtrack=False).effective_dt_safety == 0.25
    # The solver uses it: the same run, to the bit, as the factor given by hand.
    for overrides, factor in (({}, 0.3), ({"backtrack": False}, 0.2)):
        auto = pinsettle.solve(pendulum, [1.0], **overrides)
        given = pinsettle.solve(pendulum, [1.0], dt_safety=factor, **overrides)
        assert auto.steps == given.steps and np.array_equal(auto.q, given.q)
        assert auto.settings.dt_safety == "auto" and given.settings.dt_safety == factor


def test_dt_growth_auto_is_the_measured_growth_of_the_other_settings(pendulum):
    s = pinsettle.Settings()
    assert s.dt_growth == "auto" and s.effective_dt_growth == 2.5  # backtracking, exact energy
    assert pinsettle.Settings(backtrack=False).effective_dt_growth == 1.0
    assert pinsettle.Settings(energy="simplified").effective_dt_growth == 1.0
    assert pinsettle.Settings(scale_stiff_modes=False).effective_dt_growth == 1.0
    assert pinsettle.Settings(dt_growth=1.5, backtrack=False).effective_dt_growth == 1.5
    for overrides, growth in (({}, 2.5), ({"energy": "simplified"}, 1.0)):
        auto = pinsettle.solve(pendulum, [1.0], **overrides)
        given = pinsettle.solve(pendulum, [1.0], dt_growth=growth, **overrides)
        assert auto.steps == given.steps and np.array_equal(auto.q, given.q)


def test_a_step_grown_between_peaks_settles_a_chain_in_fewer_steps_at_the_same_rest(chain_urdf):
    """The 20-link chain released horizontal: 1,457 steps with the step fixed between
    estimates, 903 with the default growth (2.5), at the same rest, hanging straight down (a
    zero of Pinocchio's own gravity torque)."""
    chain = pinocchio.buildModelFromXML(chain_urdf(20))
    q0 = np.zeros(chain.nq)
    q0[0] = np.pi / 2
    # The damping's own runs: Newton taking over at a damping event would end both sooner;
    # without the joint inertia (the default gives it from 20 links), whose own short run
    # leaves the growth little to do.
    plain = {"limits": False, "newton_takeover": False, "scale_joint_inertia": False}
    grown = pinsettle.solve(chain, q0, **plain)
    fixed = pinsettle.solve(chain, q0, dt_growth=1, **plain)
    assert grown.converged and fixed.converged
    assert grown.steps < 0.7 * fixed.steps, (grown.steps, fixed.steps)
    assert grown.dt_reductions == 0 and grown.stability == "stable"
    assert np.abs(grown.q - fixed.q).max() < 1e-8
    data = chain.createData()
    scale = np.abs(pinocchio.computeGeneralizedGravity(chain, data, q0)).max()
    gravity = pinocchio.computeGeneralizedGravity(chain, data, grown.q)
    assert np.abs(gravity).max() < 1e-10 * scale


def test_trace_records_configurations_and_events_for_playback():
    scene = pinsettle.load_scene(pinsettle.scene_path("panda_fingers_locked"))
    plain = pinsettle.solve(scene, trace_every=50, dt=1e-3)
    r = pinsettle.solve(scene, trace_every=50, trace_configurations=True, dt=1e-3)
    assert plain.trace.q is None
    # Recording q changes nothing in the run itself.
    assert r.steps == plain.steps and np.array_equal(r.q, plain.q)
    t = r.trace
    assert t.q.shape == (len(t.step), scene.model.nq)  # full model: locked fingers included
    assert np.allclose(t.q[:, -2:], 0.02)
    # Each recorded q is the state at its step: the first one is the start, moved into the
    # joints' limits (panda_joint4 starts at 0, above its upper limit -0.0698).
    full = scene.model
    assert np.allclose(
        t.q[0], np.clip(scene.q0(), full.lowerPositionLimit, full.upperPositionLimit)
    )
    assert r.start_clamped == {"panda_joint4": pytest.approx(0.0698)}
    # Every damping event is listed, in order, inside the run.
    assert t.event_kind.count("damping") == r.peaks
    assert np.all(np.diff(t.event_step) >= 0) and t.event_step[-1] < r.steps
    # A damping event re-evaluates the dynamics without advancing time: one step each.
    kinds = np.array(t.event_kind)
    damping = kinds == "damping"
    earlier = np.cumsum(damping) - damping  # damping events before each event
    dt = r.settings.dt
    assert np.allclose(t.event_time[damping], (t.event_step - earlier)[damping] * dt, atol=1e-9)
    # The arm falls onto panda_joint2's upper stop: an impact, at the end of its step, naming
    # the joint; the other events name none.
    impact = kinds == "impact"
    assert impact.any() and set(kinds) <= {"damping", "impact"}
    assert np.allclose(t.event_time[impact], (t.event_step - earlier + 1)[impact] * dt, atol=1e-9)
    hit = {full.names[int(j)] for j in t.event_joint[impact]}
    assert "panda_joint2" in hit and hit <= set(r.at_limit) | set(r.start_clamped) | hit
    assert np.all(t.event_joint[~impact] == -1)


def test_settings_repr_replace_to_dict_eq():
    s = pinsettle.Settings(kt=0.3)
    text = repr(s)
    assert text.startswith("Settings(") and "kt=0.3" in text and "energy='exact'" in text
    t = s.replace(dt=2e-3, energy="simplified")
    assert (t.dt, t.kt, t.energy) == (2e-3, 0.3, "simplified")
    assert (s.dt, s.energy) == ("auto", "exact")  # the original is unchanged
    assert isinstance(t, pinsettle.Settings) and t is not s
    assert s.replace() == s and t != s
    d = s.to_dict()
    assert d["kt"] == 0.3
    assert pinsettle.Settings(**d) == s  # round trip


def test_settings_passed_to_solve_is_not_modified(pendulum):
    s = pinsettle.Settings(kt=0.3, max_steps=50, newton_takeover=False)
    before = s.to_dict()
    result = pinsettle.solve(pendulum, [1.0], s, kt=0.1, max_steps=20)
    assert s.to_dict() == before
    assert result.settings is not s
    assert result.settings.kt == 0.1  # overrides win over the settings object
    assert result.steps == 20


def test_dict_settings_and_overrides(pendulum):
    result = pinsettle.solve(pendulum, [1.0], {"kt": 0.0, "max_steps": 7, "newton_takeover": False})
    assert result.settings.kt == 0.0 and result.steps == 7
    result = pinsettle.solve(pendulum, [1.0], {"max_steps": 7}, max_steps=3)
    assert result.steps == 3


def test_settings_ints_accept_numpy_integers(pendulum):
    result = pinsettle.solve(pendulum, [1.0], max_steps=np.int64(4), kt=np.float64(0.2))
    assert result.steps == 4 and result.settings.kt == 0.2
    assert pinsettle.Settings(kt=0).kt == 0.0  # an int for a float field is fine


def test_result_summary_names_the_joints(ur5):
    result = pinsettle.solve(ur5, max_steps=10)
    text = result.summary()
    assert "status           max_steps" in text
    assert all(ur5.names[j] in text for j in range(1, ur5.njoints))


def _summary_line(text: str, head: str) -> str:
    lines = [line for line in text.splitlines() if line.startswith(head)]
    assert len(lines) == 1, text
    return lines[0][len(head) :].strip()


def test_summary_gives_the_units_and_the_joints_free_to_move(ur5):
    result = pinsettle.solve(ur5)
    assert result.stability == "neutral" and result.neutral_directions == 3
    text = result.summary(ur5)
    assert _summary_line(text, "residual").startswith(f"{result.residual:.3e} N m (")
    # The joints whose motion alone costs nothing, by Pinocchio's gravity derivatives: a zero
    # column (and row) of K. Hanging down, the UR5 turns freely about the vertical at the
    # base and at the wrist, and its last joint turns the flange about its own axis.
    k = pinocchio.computeGeneralizedGravityDerivatives(ur5, ur5.createData(), result.q)
    free = [
        ur5.names[j]
        for j in range(1, ur5.njoints)
        if np.abs(k[:, ur5.idx_vs[j]]).max() <= 1e-9 * np.abs(k).max()
    ]
    assert free == ["shoulder_pan_joint", "wrist_2_joint", "wrist_3_joint"], k
    assert _summary_line(text, "stability") == (
        "neutral (smallest stiffness eigenvalue 0 N m/rad: 3 directions free to move at no "
        "cost, moving " + ", ".join(free) + ")"
    )
    # Without the model: no joint kinds, no names.
    bare = result.summary()
    assert _summary_line(bare, "residual").startswith(f"{result.residual:.3e} N m or N (")
    assert _summary_line(bare, "stability") == (
        "neutral (smallest stiffness eigenvalue 0: 3 directions free to move at no cost)"
    )


def test_summary_prints_a_neutral_verdicts_round_off_eigenvalue_as_zero():
    scene = pinsettle.load_scene("ur5_tool_spring")
    result = pinsettle.solve(scene)
    report = pinsettle.assess_stability(scene, result.q)
    # The smallest eigenvalue is round-off, not 0, and within the verdict's tolerance.
    assert result.stability == "neutral" and result.min_stiffness_eigenvalue != 0.0
    assert abs(result.min_stiffness_eigenvalue) <= report.tolerance
    line = _summary_line(result.summary(scene), "stability")
    assert line.startswith("neutral (smallest stiffness eigenvalue 0 N m/rad: 1 direction "), line
    # The flange turns about the spring's line through tool0 at no cost.
    assert line.endswith("free to move at no cost, moving wrist_3_joint)"), line


def test_summary_units_of_a_prismatic_and_of_a_mixed_mechanism(panda):
    scene = pinsettle.load_scene("slider_spring")  # a 500 N/m joint spring on a slider
    result = pinsettle.solve(scene)
    text = result.summary(scene)
    assert _summary_line(text, "residual").startswith(f"{result.residual:.3e} N (")
    assert _summary_line(text, "stability") == "stable (smallest stiffness eigenvalue 500 N/m)"
    # The Panda's fingers slide: its residual mixes N m and N. They rest on their stops: the
    # stiffness is that of the arm's joints off the stops, in N m/rad.
    result = pinsettle.solve(panda)
    assert {"panda_finger_joint1", "panda_finger_joint2"} <= set(result.at_limit), result.at_limit
    text = result.summary(panda)
    assert _summary_line(text, "residual").startswith(f"{result.residual:.3e} N m or N (")
    assert _summary_line(text, "stability").startswith(
        "neutral (smallest stiffness eigenvalue 0 N m/rad on the joints off their stops: 1 "
        "direction free to move at no cost, moving panda_joint1)"
    )


def test_summary_of_a_rest_held_in_every_motion():
    # Four sticking corners hold the box in every motion: K restricted to nothing.
    scene = pinsettle.load_scene("box_on_floor")
    result = pinsettle.solve(scene)
    assert result.stability == "stable" and len(result.contacts) == 4
    assert result.min_stiffness_eigenvalue == 0.0 and result.neutral_directions == 0
    text = result.summary(scene)
    assert _summary_line(text, "stability") == "stable (held in every motion by its contacts)"
    assert _summary_line(text, "residual").startswith(f"{result.residual:.3e} N m or N (")


# --- Rest on an equilibrium: the stability verdict decides ---------------------------------


def test_released_at_a_stable_equilibrium_converges_at_once(pendulum):
    # q = 0 is an exact equilibrium: the energy stays exactly 0 for a window; the stiffness
    # there is positive, so that rest is accepted without a push.
    result = pinsettle.solve(pendulum, [0.0], max_e=1e-20, max_steps=50000)
    assert result.status == "converged"
    assert result.pushes == 0
    assert result.stability == "stable"
    assert result.steps <= result.settings.ds + 1
    assert result.q[0] == 0.0
    assert result.min_stiffness_eigenvalue == pytest.approx(9.81, rel=1e-9)


def test_released_upright_is_pushed_off_and_hangs_down(pendulum):
    # q = pi is an equilibrium too (up to the round-off of sin(pi)), but a maximum: it must not
    # be reported converged there. With a fixed small step the round-off creeps too slowly and
    # the solver pushes it off; with the automatic step it falls away by itself. (The URDF's
    # stop at 3.1416 rad, 7.3e-6 rad away, would catch a push that way: limits off, this is
    # about the push.)
    result = pinsettle.solve(
        pendulum, [np.pi], max_e=1e-20, max_steps=200000, dt=1e-3, limits=False
    )
    assert result.status == "converged"
    assert result.pushes >= 1
    assert result.stability == "stable"
    assert abs(np.sin(result.q[0])) < 1e-8 and np.cos(result.q[0]) > 0
    result = pinsettle.solve(pendulum, [np.pi], max_e=1e-20, limits=False)
    assert result.status == "converged"
    assert result.stability == "stable"
    assert abs(np.sin(result.q[0])) < 1e-8 and np.cos(result.q[0]) > 0


def test_without_gravity_converges_at_once_as_neutral(ur5):
    model = ur5.copy()
    model.gravity = pinocchio.Motion.Zero()
    result = pinsettle.solve(model, max_steps=5000)
    assert result.residual == 0.0
    assert result.status == "converged"
    assert result.stability == "neutral"
    assert result.neutral_directions == model.nv
    assert result.pushes == 0
    # A step from rest that changes neither v nor q, to the bit, repeats for ever: the rest is
    # assessed at the next step, not after a window of ds steps of zero energy.
    assert result.steps == 2


def test_an_exact_saddle_start_is_pushed_off_at_once():
    # The double pendulum's neutral pose is upright, its gravity exactly zero there: stationary
    # from the first step, assessed at the second, unstable, pushed off; then it hangs down.
    model = pinsettle.load_robot("double_pendulum_simple")
    q0 = pinocchio.neutral(model)
    assert not np.any(pinocchio.computeGeneralizedGravity(model, model.createData(), q0))
    result = pinsettle.solve(model, q0, trace_every=1)
    events = zip(result.trace.event_step, result.trace.event_kind, strict=True)
    pushes = [step for step, kind in events if kind == "push"]
    assert pushes[:1] == [1], (pushes, list(result.trace.event_kind))
    assert result.converged and result.stability == "stable" and result.pushes == 1
    g = pinocchio.computeGeneralizedGravity(model, model.createData(), result.q)
    assert np.abs(g).max() < 1e-9

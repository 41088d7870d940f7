"""What a run may call a rest, and what it may call a fall (issue 40, items 1 to 3).

- ``converged`` means a rest: a run that is quiet only because it hardly moves (a step so small
  that q does not change) is not one. Judged by the static force recomputed with Pinocchio.
- A root that translates freely under a net force (a floating body, a humanoid whose limbs
  swing, a free object beside a fixed robot) has no rest: ``no_equilibrium`` at once, with the
  force named, equal to the weight Pinocchio computes. Where anything holds it (a spring to the
  world, a stop), the run goes on as before.
- A stiffness that is zero up to round-off reads as neutral, not unstable: the verdict's
  tolerance has a floor tied to the model's own weight and size.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest

ROBOTS = Path(__file__).resolve().parents[1] / "robots"


def pendulum() -> pinocchio.Model:
    return pinocchio.buildModelFromUrdf(str(ROBOTS / "pendulum.urdf"))


def static_force(model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
    return pinocchio.computeGeneralizedGravity(model, model.createData(), q)


@pytest.mark.parametrize("dt", [1e-12, 1e-14])
def test_a_run_too_slow_to_move_is_not_a_rest(dt):
    # Released at 1 rad with a step so small that q never changes: the energy stays below
    # max_e and q is 'stalled', which once ended the run as converged at 8.25 N m (the gravity
    # torque m g L sin 1). Now the rest check asks how much potential energy is left, and the
    # run is not called converged.
    model = pendulum()
    q0 = np.array([1.0])
    result = pinsettle.solve(model, q0, dt=dt, max_steps=3000, polish=False)
    torque = abs(static_force(model, result.q)[0])
    assert torque == pytest.approx(9.81 * np.sin(1.0), rel=1e-6)
    assert result.status != "converged", (result.status, result.residual)
    assert not result.converged


def test_every_converged_run_of_a_quiet_start_is_at_a_rest():
    # The same start with the automatic step: a real rest, hanging down, at round-off.
    model = pendulum()
    result = pinsettle.solve(model, np.array([1.0]))
    assert result.status == "converged"
    assert abs(static_force(model, result.q)[0]) < 1e-12
    assert abs(result.q[0]) < 1e-12


def floating_body() -> pinocchio.Model:
    return pinsettle.load_urdf(ROBOTS / "free_body.urdf", floating=True)


def test_a_free_body_is_called_a_fall_at_once_with_its_weight():
    model = floating_body()
    start = time.perf_counter()
    result = pinsettle.solve(model)
    assert time.perf_counter() - start < 5.0
    assert result.status == "no_equilibrium" and result.steps == 0
    assert "falls without bound" in result.reason and "'root_joint'" in result.reason
    # The net force named is the weight, recomputed by Pinocchio: the free flyer's first three
    # generalized forces are the net force on the body, whatever its orientation.
    q = pinocchio.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    weight = np.linalg.norm(static_force(model, q)[:3])
    assert weight == pytest.approx(1.0 * 9.81, rel=1e-12)
    assert f"{weight:.4g} N" in result.reason


def test_a_fall_named_at_once_keeps_its_one_state_in_the_trace():
    # Playback needs a configuration to show: the trace holds the start, the run's only state.
    result = pinsettle.solve(floating_body(), trace_every=1, trace_configurations=True)
    assert result.status == "no_equilibrium" and result.steps == 0
    assert list(result.trace.step) == [0]
    assert np.array_equal(result.trace.q[0], result.q)


def test_a_humanoid_falls_whatever_its_limbs_do():
    # Pinocchio's sample humanoid on a free flyer, limbs bent at random and pushed: once the
    # runaway test had to see the released energy grow while the limbs' swings set off damping
    # events that stopped the fall each time (humanoid_CMU fell 340 km in 24 s).
    model = pinocchio.buildSampleModelHumanoidRandom(True)
    rng = np.random.default_rng(3)
    q0 = pinocchio.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    v0 = rng.normal(size=model.nv)
    start = time.perf_counter()
    result = pinsettle.solve(model, q0, v0=v0, limits=False)
    assert time.perf_counter() - start < 5.0
    assert result.status == "no_equilibrium", (result.status, result.reason)
    data = model.createData()
    pinocchio.computeTotalMass(model, data)
    weight = np.linalg.norm(static_force(model, q0)[:3])
    assert weight == pytest.approx(data.mass[0] * 9.81, rel=1e-9)


def test_a_free_object_beside_a_fixed_robot_is_named():
    # A pendulum fixed to the world and a free box beside it: two roots, the box falls.
    arm = pendulum()
    box = floating_body()
    model = pinocchio.appendModel(arm, box, 0, pinocchio.SE3.Identity())
    result = pinsettle.solve(model, limits=False)
    assert result.status == "no_equilibrium"
    assert "'root_joint'" in result.reason and "1 body, 1 kg" in result.reason


def test_a_body_held_by_a_spring_to_the_world_is_not_a_fall():
    # The same free body hung from the world by a spring: it rests where the spring carries
    # its weight (stretch m g / k), so no certificate may end that run.
    scene = pinsettle.Scene(floating_body())
    scene.add_spring("universe", ("body", (0.0, 0.0, 0.0)), stiffness=100.0)
    result = pinsettle.solve(scene)
    assert result.status == "converged", (result.status, result.reason)
    assert result.q[2] == pytest.approx(-9.81 / 100.0, abs=1e-9)
    assert scene.residual(result.q) < 1e-9


def test_a_prismatic_root_on_its_stop_is_not_a_fall():
    # A slider along z at the root with a lower stop: the stop holds it.
    model = pinocchio.Model()
    joint = model.addJoint(0, pinocchio.JointModelPZ(), pinocchio.SE3.Identity(), "slide")
    model.appendBodyToJoint(
        joint, pinocchio.Inertia.FromBox(2.0, 0.1, 0.1, 0.1), pinocchio.SE3.Identity()
    )
    model.lowerPositionLimit[:] = -0.5
    model.upperPositionLimit[:] = 0.5
    result = pinsettle.solve(model)
    assert result.status == "converged", (result.status, result.reason)
    assert result.q[0] == pytest.approx(-0.5)
    free = pinsettle.solve(model, limits=False)
    assert free.status == "no_equilibrium" and "'slide'" in free.reason


def wheel_robot() -> pinocchio.Model:
    # A fixed base carrying two wheels on continuous joints whose centres of mass lie on their
    # axes, at an angle so that the gravity derivatives are sums with round-off: the stiffness
    # is zero in exact arithmetic and round-off of either sign in floating point.
    model = pinocchio.Model()
    for k, rpy in enumerate([(0.3, 0.0, 0.7), (-1.1, 0.2, 0.4)]):
        rotation = pinocchio.rpy.rpyToMatrix(np.array(rpy))
        placement = pinocchio.SE3(rotation, np.array([k, 0.3, 0.5]))
        joint = model.addJoint(0, pinocchio.JointModelRUBZ(), placement, f"wheel{k}")
        inertia = pinocchio.Inertia(3.0, np.zeros(3), np.diag([0.1, 0.1, 0.2]))
        model.appendBodyToJoint(joint, inertia, pinocchio.SE3.Identity())
    return model


def test_a_stiffness_of_round_off_reads_neutral():
    model = wheel_robot()
    for _ in range(20):
        q = pinocchio.randomConfiguration(model)
        report = pinsettle.assess_stability(model, q, limits=False)
        assert report.verdict == "neutral", report.eigenvalues
    result = pinsettle.solve(model, limits=False)
    assert result.status == "converged" and result.stability == "neutral"
    assert result.pushes == 0 and result.steps < 100

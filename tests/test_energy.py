"""pinsettle.kinetic_energies and pinsettle.static_residual against independent computations."""

from __future__ import annotations

import numpy as np
import pinocchio
import pinsettle
import pytest

ROBOTS = ["pendulum", "ur5", "panda", "solo12", "double_pendulum", "humanoid"]
RTOL = 1e-10


def random_states(model: pinocchio.Model, seed: int, count: int = 5):
    """Reproducible random (q, v): pinocchio's generator seeded for q, numpy's for v.

    Bounds are explicit and finite, since a free-flyer's translation has infinite limits.
    """
    pinocchio.seed(seed)
    rng = np.random.default_rng(seed)
    lower = np.full(model.nq, -np.pi)
    upper = np.full(model.nq, np.pi)
    for _ in range(count):
        q = pinocchio.randomConfiguration(model, lower, upper)
        v = rng.normal(scale=2.0, size=model.nv)
        yield q, v


def is_body(inertia: pinocchio.Inertia) -> bool:
    """The simplified measure's rule: a joint carries a body when it has mass or inertia."""
    return inertia.mass > 0.0 or np.any(inertia.inertia != 0.0)


def simplified_local(model, q, v) -> float:
    """Crocoddyl-style: velocity of a frame placed at each centre of mass, from data.v."""
    data = model.createData()
    pinocchio.forwardKinematics(model, data, q, v)
    total = 0.0
    for i in range(1, model.njoints):
        inertia = model.inertias[i]
        if not is_body(inertia):
            continue
        at_com = pinocchio.SE3(np.eye(3), inertia.lever)
        vel = pinocchio.getFrameVelocity(
            model, data, i, at_com, pinocchio.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )
        total += vel.linear @ vel.linear + vel.angular @ vel.angular
    return total


def world_body_velocities(model, q, v):
    """(body index, world velocity of its centre of mass, world angular velocity, world rotation)
    from the WORLD-frame spatial velocity and data.oMi; no joint-local quantity is used."""
    data = model.createData()
    pinocchio.forwardKinematics(model, data, q, v)
    for i in range(1, model.njoints):
        inertia = model.inertias[i]
        ov = pinocchio.getVelocity(model, data, i, pinocchio.ReferenceFrame.WORLD)
        com = data.oMi[i].act(inertia.lever)
        yield i, ov.linear + np.cross(ov.angular, com), ov.angular, data.oMi[i].rotation


def simplified_world(model, q, v) -> float:
    return sum(
        v_com @ v_com + w @ w
        for i, v_com, w, _ in world_body_velocities(model, q, v)
        if is_body(model.inertias[i])
    )


def exact_world(model, q, v) -> float:
    """Sum over bodies of 1/2 m |v_com|^2 + 1/2 w^T I_c w, all in the world frame."""
    total = 0.0
    for i, v_com, w, rotation in world_body_velocities(model, q, v):
        inertia = model.inertias[i]
        inertia_world = rotation @ inertia.inertia @ rotation.T
        total += 0.5 * inertia.mass * v_com @ v_com + 0.5 * w @ inertia_world @ w
    return total


def simplified_finite_difference(model, q, v, h=1e-5) -> float:
    """Centre-of-mass velocities and angular velocities by central differences of the body
    placements along q(t) = integrate(q, t v): independent of any velocity pinocchio computes."""
    data = model.createData()

    def placements(t):
        pinocchio.forwardKinematics(model, data, pinocchio.integrate(model, q, t * v))
        return [data.oMi[i].copy() for i in range(model.njoints)]

    plus, minus = placements(h), placements(-h)
    total = 0.0
    for i in range(1, model.njoints):
        inertia = model.inertias[i]
        if not is_body(inertia):
            continue
        v_com = (plus[i].act(inertia.lever) - minus[i].act(inertia.lever)) / (2 * h)
        w = pinocchio.log3(plus[i].rotation @ minus[i].rotation.T) / (2 * h)
        total += v_com @ v_com + w @ w
    return total


@pytest.fixture(params=ROBOTS)
def robot(request) -> pinocchio.Model:
    return request.getfixturevalue(request.param)


def test_exact_energy_matches_pinocchio(robot):
    data = robot.createData()
    for q, v in random_states(robot, seed=1):
        exact, _ = pinsettle.kinetic_energies(robot, q, v)
        assert exact > 0.0
        assert exact == pytest.approx(pinocchio.computeKineticEnergy(robot, data, q, v), rel=RTOL)
        # 1/2 v^T M v, the mass matrix from CRBA (only its upper triangle is filled).
        upper = pinocchio.crba(robot, data, q)
        mass = np.triu(upper) + np.triu(upper, 1).T
        assert exact == pytest.approx(0.5 * v @ mass @ v, rel=RTOL)
        assert exact == pytest.approx(exact_world(robot, q, v), rel=RTOL)


def test_simplified_energy_matches_reimplementations(robot):
    for q, v in random_states(robot, seed=2):
        _, simplified = pinsettle.kinetic_energies(robot, q, v)
        assert simplified > 0.0
        assert simplified == pytest.approx(simplified_local(robot, q, v), rel=RTOL)
        assert simplified == pytest.approx(simplified_world(robot, q, v), rel=RTOL)
        # Central differences: truncation and round-off errors of about 1e-9 relative.
        assert simplified == pytest.approx(simplified_finite_difference(robot, q, v), rel=1e-7)


def test_energies_are_quadratic_in_velocity(robot):
    for q, v in random_states(robot, seed=3, count=2):
        assert pinsettle.kinetic_energies(robot, q, np.zeros(robot.nv)) == (0.0, 0.0)
        exact, simplified = pinsettle.kinetic_energies(robot, q, v)
        exact3, simplified3 = pinsettle.kinetic_energies(robot, q, -3.0 * v)
        assert exact3 == pytest.approx(9.0 * exact, rel=RTOL)
        assert simplified3 == pytest.approx(9.0 * simplified, rel=RTOL)


@pytest.mark.parametrize("q", [0.0, 1.0, -2.5])
def test_pendulum_energies_analytic(pendulum, q):
    # Bob of 1 kg at 1 m, inertia 1e-3 about y: E = 1/2 (m l^2 + Iyy) w^2; the simplified
    # measure is |v_com|^2 + |w|^2 = (l w)^2 + w^2.
    w = 1.7
    exact, simplified = pinsettle.kinetic_energies(pendulum, np.array([q]), np.array([w]))
    assert exact == pytest.approx(0.5 * (1.0 + 1e-3) * w**2, rel=RTOL)
    assert simplified == pytest.approx(2.0 * w**2, rel=RTOL)


def test_simplified_energy_skips_massless_frames(chain_with_massless_link):
    model = chain_with_massless_link
    q, v = np.array([0.3, -0.8, 1.1]), np.array([1.0, -2.0, 0.5])
    _, simplified = pinsettle.kinetic_energies(model, q, v)
    assert simplified == pytest.approx(simplified_world(model, q, v), rel=RTOL)
    # Counting the massless middle frame as a body would give a different (larger) value.
    data = model.createData()
    pinocchio.forwardKinematics(model, data, q, v)
    middle = data.v[2]
    with_frame = simplified + middle.linear @ middle.linear + middle.angular @ middle.angular
    assert simplified != pytest.approx(with_frame, rel=1e-6)


def test_simplified_energy_counts_a_massless_body_with_inertia():
    # Mass 0 but a rotational inertia: a body (a flywheel), so it counts.
    model = pinocchio.Model()
    joint = model.addJoint(0, pinocchio.JointModelRZ(), pinocchio.SE3.Identity(), "spin")
    model.appendBodyToJoint(
        joint,
        pinocchio.Inertia(0.0, np.zeros(3), np.diag([1.0, 1.0, 2.0])),
        pinocchio.SE3.Identity(),
    )
    exact, simplified = pinsettle.kinetic_energies(model, np.array([0.4]), np.array([3.0]))
    assert exact == pytest.approx(0.5 * 2.0 * 9.0, rel=RTOL)
    assert simplified == pytest.approx(9.0, rel=RTOL)


def test_static_residual_is_max_generalized_gravity(robot):
    data = robot.createData()
    for q, _ in random_states(robot, seed=4, count=3):
        expected = np.max(np.abs(pinocchio.computeGeneralizedGravity(robot, data, q)))
        assert pinsettle.static_residual(robot, q) == pytest.approx(expected, rel=1e-12)


def test_static_residual_of_pendulum_analytic(pendulum):
    # Torque of gravity on a 1 kg bob at 1 m: m g l sin(q).
    for q in [0.0, 0.5, -2.0]:
        expected = 9.81 * abs(np.sin(q))
        assert pinsettle.static_residual(pendulum, np.array([q])) == pytest.approx(
            expected, rel=1e-12, abs=1e-14
        )

"""The library scenes on the ground with a closed form or a stated stance: a car settling on its
suspension (robots/vehicle.toml), talos standing (robots/talos_standing.toml).

Each answer is checked with tests/contact_reference.py (the balance recomputed with Pinocchio's
own Jacobians, the cones, the gaps) and against what the scene's header states. The car's
numbers come from the lever rule: each suspension spring carries its corner's share of the
chassis weight (bilinear in the centre of mass's place between the axles and between the
sides), so it is compressed by share / K, and each tyre carries that share and its hub's weight.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest
from contact_reference import check_rest, read_contacts, read_joint_springs
from scipy.spatial import ConvexHull

ROBOTS = Path(__file__).parents[1] / "robots"
G = 9.81


def header(path: Path) -> str:
    lines = path.read_text(encoding="utf-8").splitlines()
    return "\n".join(line for line in lines if line.startswith("#"))


def solve_and_check(path: Path):
    """The scene solved, and its rest checked independently: converged, balanced to round-off,
    forces in their cones, nothing sunk in, the loaded points touching, stable."""
    scene = pinsettle.load_scene(path)
    result = pinsettle.solve(scene)
    assert result.status == "converged", result.reason
    planes, spheres = read_contacts(path)
    stops = {j: (side, result.limit_reactions[j]) for j, side in result.at_limit.items()}
    springs = read_joint_springs(path)
    check = check_rest(scene.model, result.q, planes, spheres, result.contacts, springs, stops)
    assert check.balance <= 1e-9 * check.scale
    assert check.worst_cone <= 1e-9 * check.scale
    assert check.min_gap >= -1e-6 and check.worst_touch <= 1e-6
    assert result.stability == "stable"
    # The ground carries the whole weight, the mass from Pinocchio, to 1e-9 relative.
    weight = pinocchio.computeTotalMass(scene.model) * G
    lift = check.total_normal + check.total_tangential
    assert np.allclose(lift, [0.0, 0.0, weight], rtol=1e-9, atol=1e-9 * weight)
    return scene, result, springs


# --- the car on its suspension ------------------------------------------------------------------


def car_model(urdf: Path) -> pinocchio.Model:
    """The car's URDF read by Pinocchio alone, its chassis on a free-flyer."""
    return pinocchio.buildModelFromUrdf(str(urdf), pinocchio.JointModelFreeFlyer())


def corner_shares(model: pinocchio.Model, joints: list[str]) -> dict[str, float]:
    """Each suspension joint's share of the chassis weight (N) by the lever rule: the chassis's
    centre of mass between the front and rear axles and between the left and right wheels,
    from the model's inertia and joint placements."""
    chassis = model.inertias[1]  # the free-flyer's body
    cx, cy, _ = chassis.lever
    where = {j: model.jointPlacements[model.getJointId(j)].translation for j in joints}
    xs, ys = sorted({p[0] for p in where.values()}), sorted({p[1] for p in where.values()})
    assert len(xs) == 2 and len(ys) == 2  # two axles, two sides
    front, left = (cx - xs[0]) / (xs[1] - xs[0]), (cy - ys[0]) / (ys[1] - ys[0])
    along = {xs[1]: front, xs[0]: 1.0 - front}  # the front axle's share, the rear's
    across = {ys[1]: left, ys[0]: 1.0 - left}
    return {j: chassis.mass * G * along[x] * across[y] for j, (x, y, _) in where.items()}


def assert_settled_on_suspension(path: Path, urdf: Path) -> dict[str, float]:
    """The car of `path` at its closed-form rest: each spring compressed by its share / K, each
    tyre carrying its share and its hub's weight, the chassis level at the ride height (its
    springs are chosen so that the four compressions are equal). Returns the closed form's
    numbers of the first spring's corner."""
    _, result, springs = solve_and_check(path)
    model = car_model(urdf)
    joints = [joint for joint, _, _ in springs]
    shares = corner_shares(model, joints)
    compression = {joint: shares[joint] / k for joint, k, _ in springs}
    for joint, _, rest in springs:
        assert result.joints[joint] - rest == pytest.approx(compression[joint], rel=1e-6), joint
    # The tyre on each hub (the body the suspension joint carries) carries its corner's share
    # and the hub's weight.
    _, spheres = read_contacts(path)
    tyres = {model.frames[model.getFrameId(s.frame)].parentJoint: s for s in spheres}
    forces = {c.name: c.normal_force for c in result.contacts}
    assert len(forces) == len(joints) == len(tyres)
    for joint in joints:
        j = model.getJointId(joint)
        tyre = forces[tyres[j].name]
        assert tyre == pytest.approx(shares[joint] + model.inertias[j].mass * G, rel=1e-9), joint
    # Nothing sideways: the level rest needs none (the least-norm forces hold no more).
    weight = pinocchio.computeTotalMass(model) * G
    assert all(np.linalg.norm(c.tangential_force) <= 1e-9 * weight for c in result.contacts)
    # Equal compressions: the chassis level, its height the tyre's radius plus the hub's depth
    # below the chassis origin.
    assert np.ptp(list(compression.values())) <= 1e-12 * max(compression.values())
    joint, _, rest = springs[0]
    j = model.getJointId(joint)
    ride = tyres[j].radius - model.jointPlacements[j].translation[2] - (rest + compression[joint])
    assert abs(result.q[6]) == pytest.approx(1.0, abs=1e-9)  # not turned
    assert result.q[2] == pytest.approx(ride, rel=1e-9)
    return {
        "ride": ride,
        "joint": rest + compression[joint],
        "compression": compression[joint],
        "share": shares[joint],
        "tyre": forces[tyres[j].name],
        "weight": weight,
    }


def test_vehicle_settles_to_its_ride_height():
    path = ROBOTS / "vehicle.toml"
    numbers = assert_settled_on_suspension(path, ROBOTS / "vehicle.urdf")
    # The closed form's numbers (not the solver's) are those written in the header.
    written = {
        "ride": f"{numbers['ride']:.5f}",
        "joint": f"{numbers['joint']:.5f}",
        "compression": f"{numbers['compression']:.5f}",
        "share": f"{numbers['share']:.1f}",
        "tyre": f"{numbers['tyre']:.1f}",
        "weight": f"{numbers['weight']:.1f}",
    }
    assert written == {
        "ride": "0.51825",
        "joint": "-0.21825",
        "compression": "0.08175",
        "share": "2452.5",
        "tyre": "2648.7",
        "weight": "10594.8",
    }
    text = header(path)
    for value in written.values():
        assert value in text, value


def test_vehicle_with_its_mass_off_centre_shares_it_by_the_lever_rule(tmp_path):
    # The chassis's centre of mass moved 0.5 m forward and 0.15 m to the left: the corners
    # carry 0.42 (front left), 0.28, 0.18 and 0.12 (rear right) of its weight. Each spring's
    # stiffness is its share over 0.0981 m, so the four compressions are equal and the
    # chassis stays level, while the tyres' loads differ.
    urdf = (ROBOTS / "vehicle.urdf").read_text(encoding="utf-8")
    centred = '<origin xyz="0 0 0" rpy="0 0 0"/>\n      <mass value="1000.0"/>'
    assert urdf.count(centred) == 1
    urdf = urdf.replace(centred, centred.replace('"0 0 0"', '"0.5 0.15 0"', 1))
    (tmp_path / "vehicle.urdf").write_text(urdf, encoding="utf-8")
    joints = [joint for joint, _, _ in read_joint_springs(ROBOTS / "vehicle.toml")]
    shares = corner_shares(car_model(tmp_path / "vehicle.urdf"), joints)
    assert [shares[j] / (1000.0 * G) for j in joints] == pytest.approx([0.42, 0.28, 0.18, 0.12])
    parts = (ROBOTS / "vehicle.toml").read_text(encoding="utf-8").split("stiffness = 30000.0")
    assert len(parts) == len(joints) + 1  # the springs in the order read_joint_springs gives
    stiffness = [f"stiffness = {float(shares[joint] / 0.0981)!r}" for joint in joints]
    path = tmp_path / "vehicle.toml"
    text = parts[0] + "".join(k + p for k, p in zip(stiffness, parts[1:], strict=True))
    path.write_text(text, encoding="utf-8")
    numbers = assert_settled_on_suspension(path, tmp_path / "vehicle.urdf")
    assert numbers["compression"] == pytest.approx(0.0981, rel=1e-12)
    assert numbers["ride"] == pytest.approx(0.3 + 0.3 - 0.0981, rel=1e-12)


def test_vehicle_at_a_step_too_large_for_its_tyres_still_settles(tmp_path):
    # At a fixed step of 0.2 s the car's bursts once travelled and released ever more, as a
    # fall does, and the run ended `no_equilibrium` (or, before, at a marginal rest 21 N off
    # balance); then the step was halved. With the tyres' impulses solved to their laws (not
    # left where the sweeps stalled) the step holds as it is: the car comes to the closed-form
    # rest either way.
    (tmp_path / "vehicle.urdf").write_text(
        (ROBOTS / "vehicle.urdf").read_text(encoding="utf-8"), encoding="utf-8"
    )
    path = tmp_path / "vehicle.toml"
    path.write_text(
        (ROBOTS / "vehicle.toml").read_text(encoding="utf-8") + "\n[solver]\ndt = 0.2\n",
        encoding="utf-8",
    )
    scene = pinsettle.load_scene(path)
    assert scene.settings.dt == 0.2
    assert pinsettle.solve(scene).status == "converged"
    assert_settled_on_suspension(path, tmp_path / "vehicle.urdf")


# --- talos standing ------------------------------------------------------------------------------


def test_talos_stands_on_its_soles_towards_half_sitting():
    path = ROBOTS / "talos_standing.toml"
    scene, result, springs = solve_and_check(path)
    model = scene.model
    # Every 1-DoF joint on a spring towards the SRDF's half_sitting pose, read by Pinocchio.
    from pinsettle._model_files import robot_srdf

    reference = pinocchio.buildModelFromUrdf(str(pinsettle.robot_urdf("talos")))
    pinocchio.loadReferenceConfigurations(reference, str(robot_srdf("talos")))
    pose = reference.referenceConfigurations["half_sitting"]
    one_dof = [reference.names[j] for j in range(1, reference.njoints) if reference.nqs[j] == 1]
    assert [joint for joint, _, _ in springs] == one_dof
    for joint, _, rest in springs:
        assert rest == pose[reference.idx_qs[reference.getJointId(joint)]], joint
    # It stands on all eight sole corners, each pressing.
    _, spheres = read_contacts(path)
    assert sorted(c.name for c in result.contacts) == sorted(s.name for s in spheres)
    assert len(spheres) == 8 and all(c.normal_force > 0.0 for c in result.contacts)
    # The weight of the header, from Pinocchio's total mass.
    mass = pinocchio.computeTotalMass(model)
    assert (f"{mass:.6f}", f"{mass * G:.2f}") == ("90.272192", "885.57")
    assert "90.272192 kg" in header(path) and "885.57 N" in header(path)
    # The centre of pressure is straight below the centre of mass, inside the support polygon.
    com = pinocchio.centerOfMass(model, model.createData(), result.q)
    points = np.array([c.point for c in result.contacts])
    normal = np.array([c.normal_force for c in result.contacts])
    assert normal @ points[:, :2] / normal.sum() == pytest.approx(com[:2], abs=1e-8)
    hull = ConvexHull(points[:, :2])
    assert np.all(hull.equations @ np.array([*com[:2], 1.0]) < 0.0)

"""Ground contacts: bodies coming to rest on planes with Coulomb friction.

Every answer is checked with tests/contact_reference.py (the balance recomputed with
Pinocchio's own Jacobians, the cones, the gaps) and against closed forms: a box on a floor
carries m g / 4 at each corner; on a slope it sticks exactly when tan(theta) <= mu, with
tangential force m g sin(theta); a sphere rolls down any slope and rests neutrally on a floor.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinsettle
import pytest
from contact_reference import (
    CONTACT_SCENES,
    add_stance_springs,
    assert_rests_on_the_floor,
    check_rest,
    read_contacts,
    read_joint_springs,
    weight,
)
from contact_reference import scene_parts as parts

ROBOTS = Path(__file__).parents[1] / "robots"
G = 9.81
MASS = 1.0  # free_body.urdf
CORNERS = [(x, y, -0.05) for x in (-0.1, 0.1) for y in (-0.05, 0.05)]


def body_scene(
    theta: float = 0.0, mu: float = 0.5, radius: float | None = None, lift: float = 0.02
) -> pinsettle.Scene:
    """free_body.urdf on a slope of theta (rad) about y: on its four bottom corners, or on a
    sphere of `radius` at its centre. It starts level with the slope, `lift` (m) above it."""
    scene = pinsettle.load_scene(ROBOTS / "free_fall.toml")
    normal = (-math.sin(theta), 0.0, math.cos(theta))
    scene.add_ground(normal=normal, friction=mu, name="slope")
    if radius is None:
        for corner in CORNERS:
            scene.add_contact("body", corner)
        height = 0.05 + lift
    else:
        scene.add_contact("body", radius=radius)
        height = radius + lift
    w, y = math.cos(-theta / 2), math.sin(-theta / 2)
    scene.set_start(root_joint=[*(height * np.array(normal)), w, 0.0, y, 0.0])
    return scene


def assert_rest(scene: pinsettle.Scene, result: pinsettle.Result, planes=None, spheres=None):
    """The rest conditions, independently: balance to round-off, forces in their cones,
    nothing sunk in, the loaded points touching."""
    if planes is None:
        planes, spheres = parts(scene)
    assert result.status == "converged", result.reason
    check = check_rest(scene.model, result.q, planes, spheres, result.contacts)
    assert check.balance <= 1e-9 * check.scale
    assert check.worst_cone <= 1e-9 * check.scale
    assert check.min_gap >= -1e-6
    assert check.worst_touch <= 1e-6
    assert result.kinetic_energy <= result.settings.max_e
    return check


#: Scenes whose contacts slide before they stick (no spring holds the legs): a foot stops where
#: friction first holds it, at its cone's edge, and the rest may be 'marginal'.
SLID_TO_REST = {"go1_motors_off"}


@pytest.mark.parametrize("name", CONTACT_SCENES)
def test_library_scene_rests_with_its_forces_balanced(name):
    path = ROBOTS / f"{name}.toml"
    scene = pinsettle.load_scene(path)
    result = pinsettle.solve(scene)
    planes, spheres = read_contacts(path)
    assert result.status == "converged", result.reason
    stops = {j: (side, result.limit_reactions[j]) for j, side in result.at_limit.items()}
    check = check_rest(
        scene.model, result.q, planes, spheres, result.contacts, read_joint_springs(path), stops
    )
    assert check.balance <= 1e-9 * check.scale
    assert check.worst_cone <= 1e-9 * check.scale
    assert check.min_gap >= -1e-6 and check.worst_touch <= 1e-6
    if name in SLID_TO_REST:
        # Its feet slid until friction held them: one may rest at its cone's edge.
        assert result.stability in ("stable", "marginal")
        mu = {plane.name: plane.friction for plane in planes}
        for c in result.contacts:
            if c.marginal:
                ratio = np.linalg.norm(c.tangential_force) / c.normal_force
                assert ratio >= 0.99 * mu[c.ground] * (1 - 1e-9), c.name
        assert (result.stability == "marginal") == any(c.marginal for c in result.contacts)
    else:
        assert result.stability == "stable"
    # The ground carries the weight, to 1e-9 relative.
    lift = check.total_normal + check.total_tangential
    assert np.allclose(lift, [0.0, 0.0, weight(scene.model)], rtol=1e-9, atol=1e-9)
    assert result.residual <= 1e-9 * check.scale
    # The weight's number is the one in the header.
    assert f"{weight(scene.model):.3f}".rstrip("0") in path.read_text(encoding="utf-8")


def test_box_on_a_floor_carries_a_quarter_of_its_weight_at_each_corner():
    result = pinsettle.solve(pinsettle.load_scene(ROBOTS / "box_on_floor.toml"))
    assert len(result.contacts) == 4
    for c in result.contacts:
        assert c.normal_force == pytest.approx(MASS * G / 4, rel=1e-9)
        assert np.linalg.norm(c.tangential_force) <= 1e-9
        assert c.sticking
    # The JSON object carries them too.
    listed = result.to_dict()["contacts"]
    assert [c["normal_force"] for c in listed] == [c.normal_force for c in result.contacts]
    assert listed[0]["point"] == result.contacts[0].point.tolist()
    # Its centre 0.05 m above the floor, level.
    assert result.q[2] == pytest.approx(0.05, abs=1e-6)
    assert abs(result.q[6]) == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("tan_theta", [0.0, 0.2, 0.45, 0.49])
def test_box_sticks_on_a_slope_no_steeper_than_the_friction_allows(tan_theta):
    theta = math.atan(tan_theta)
    scene = body_scene(theta, mu=0.5)
    result = pinsettle.solve(scene)
    check = assert_rest(scene, result)
    n = np.array([-math.sin(theta), 0.0, math.cos(theta)])
    assert check.total_normal == pytest.approx(MASS * G * math.cos(theta) * n, abs=1e-9)
    # Up the slope, m g sin(theta).
    up = np.array([math.cos(theta), 0.0, math.sin(theta)])
    assert check.total_tangential == pytest.approx(MASS * G * math.sin(theta) * up, abs=1e-9)
    assert all(c.sticking for c in result.contacts) or tan_theta == 0.0
    assert result.stability == "stable"


@pytest.mark.parametrize("tan_theta", [0.55, 1.0])
def test_box_slides_down_a_slope_steeper_than_the_friction_allows(tan_theta):
    result = pinsettle.solve(body_scene(math.atan(tan_theta), mu=0.5))
    assert result.status == "no_equilibrium"
    assert "root_joint" in result.reason
    # It went down the slope (-x).
    assert result.q[0] < -1.0


def test_sphere_on_a_floor_is_neutral():
    scene = body_scene(0.0, radius=0.05)
    result = pinsettle.solve(scene)
    check = assert_rest(scene, result)
    assert result.stability == "neutral"
    # Rolling about its contact point in two directions, turning about the normal.
    assert result.neutral_directions == 3
    assert check.total_normal == pytest.approx([0.0, 0.0, MASS * G], abs=1e-9)


@pytest.mark.parametrize("mu", [0.2, 1.0])
def test_sphere_rolls_down_any_slope(mu):
    result = pinsettle.solve(body_scene(0.2, mu=mu, radius=0.05))
    assert result.status == "no_equilibrium"
    assert result.q[0] < -1.0


def test_the_rest_on_a_slope_does_not_depend_on_the_drop_height_when_it_sticks_at_once():
    # Level with the slope, all four corners land together and stick at the impact (the
    # impulse's tangential share is within the cone when tan(theta) <= mu): the box rests
    # where it lands, straight below its start along the slope's normal.
    theta = math.atan(0.3)
    for lift in (0.0, 0.02):
        result = pinsettle.solve(body_scene(theta, lift=lift))
        n = np.array([-math.sin(theta), 0.0, math.cos(theta)])
        assert result.status == "converged"
        assert result.q[:3] @ n == pytest.approx(0.05, abs=1e-6)


# --- bad input -----------------------------------------------------------------------------


def is_marginal(contact: pinsettle.Contact, mu: float, load: float, edge: bool = False) -> bool:
    """The marginal rule recomputed from the reported forces: at most 1e-3 of the load carried,
    or, where no forces inside cones of 0.99 mu balance the rest (`edge`, known to the caller),
    the tangential force within 1 % of the cone's edge."""
    tangential = float(np.linalg.norm(contact.tangential_force))
    return contact.normal_force <= 1e-3 * load or (
        edge and tangential > 0.0 and tangential >= 0.99 * mu * contact.normal_force * (1 - 1e-9)
    )


@pytest.mark.parametrize("tan_theta", [0.45, 0.49, 0.497])
def test_a_box_within_a_percent_of_sliding_is_marginal(tan_theta):
    theta = math.atan(tan_theta)
    scene = body_scene(theta, mu=0.5)
    result = pinsettle.solve(scene)
    assert_rest(scene, result)
    # The corners' forces sum to m g (sin, cos): if each had |f_t| <= 0.99 mu f_n, so would the
    # sum, tan(theta) <= 0.495. At 0.497 no forces balance the box 1 % inside the cones: it is
    # within 1 % of sliding. Below 0.495 such forces exist, and they are the ones reported.
    edge = tan_theta > 0.99 * 0.5
    load = weight(scene.model)
    for c in result.contacts:
        ratio = np.linalg.norm(c.tangential_force) / c.normal_force
        assert c.marginal == is_marginal(c, 0.5, load, edge)
        if not edge:
            assert ratio <= 0.99 * 0.5 * (1 + 1e-9) and not c.marginal
    assert any(c.marginal for c in result.contacts) == edge
    assert result.stability == ("marginal" if edge else "stable")
    assert ("marginal" in result.summary()) == edge
    listed = result.to_dict()["contacts"]
    assert [c["marginal"] for c in listed] == [c.marginal for c in result.contacts]


@pytest.mark.parametrize("lift", [5e-7, -1e-5, -1e-3])
def test_a_contact_that_carries_almost_nothing_is_marginal(lift):
    # slider_spring: a 2 kg block on a 500 N/m spring rests at -m g / k = -0.03924 m, its
    # bottom face then at -0.08924 m. A floor `lift` below that: at 5e-7 m the face rests on
    # the spring alone, within the closing tolerance of the floor (a contact with no force);
    # 1e-5 m above, the floor takes about k * 1e-5 = 5e-3 N of the 19.62 N; 1 mm above, 0.5 N.
    scene = pinsettle.load_scene(ROBOTS / "slider_spring.toml")
    scene.add_ground(point=(0.0, 0.0, -0.08924 - lift), friction=0.5, name="floor")
    scene.add_contact("block", (0.0, 0.0, -0.05), name="face")
    result = pinsettle.solve(scene)
    assert result.status == "converged", result.reason
    [face] = result.contacts
    assert face.gap >= -1e-6
    # The floor carries what the spring does not, at the rest's slider position.
    load = weight(scene.model)
    carried = load + 500.0 * result.q[0]
    assert face.normal_force == pytest.approx(carried, abs=1e-9 * load)
    assert carried == pytest.approx(max(0.0, -500.0 * lift), abs=500.0 * 1e-6)
    assert face.marginal == is_marginal(face, 0.5, load) == (carried <= 1e-3 * load)
    assert result.stability == ("marginal" if face.marginal else "stable")


def test_ground_errors_name_the_parameter():
    scene = pinsettle.load_scene(ROBOTS / "free_fall.toml")
    with pytest.raises(pinsettle.SceneError, match="normal must have a non-zero length"):
        scene.add_ground(normal=(0.0, 0.0, 0.0))
    with pytest.raises(pinsettle.SceneError, match="friction"):
        scene.add_ground(friction=-0.1)
    with pytest.raises(pinsettle.SceneError, match="point"):
        scene.add_ground(point=(0.0, float("nan"), 0.0))
    scene.add_ground(name="floor")
    with pytest.raises(pinsettle.SceneError, match="new ground's name"):
        scene.add_ground(name="floor")


def test_contact_errors_name_the_parameter():
    scene = pinsettle.load_scene(ROBOTS / "free_fall.toml")
    with pytest.raises(pinsettle.SceneError, match="frame.*'bdy'"):
        scene.add_contact("bdy")
    with pytest.raises(pinsettle.SceneError, match="radius"):
        scene.add_contact("body", radius=-0.01)
    with pytest.raises(pinsettle.SceneError, match="fixed to the world"):
        scene.add_contact("universe")


def test_contacts_without_a_ground_are_an_error():
    scene = pinsettle.load_scene(ROBOTS / "free_fall.toml")
    scene.add_contact("body")
    with pytest.raises(pinsettle.SceneError, match=r"no \[\[ground\]\]"):
        pinsettle.solve(scene)


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ("[[ground]]\nnormal = [0, 0, 0]", r"\[\[ground\]\] #1.*normal"),
        ("[[ground]]\nfriction = -1", r"\[\[ground\]\] #1.*friction"),
        ("[[ground]]\nmu = 0.5", r"\[\[ground\]\] #1.*mu"),
        ('[[ground]]\n[[contact]]\nframe = "nope"', r"\[\[contact\]\] #1.*nope"),
        ("[[ground]]\n[[contact]]\npoint = [0, 0, 0]", r"\[\[contact\]\] #1.*frame"),
    ],
)
def test_scene_file_errors_name_the_table_and_key(tmp_path, table, message):
    text = (ROBOTS / "free_fall.toml").read_text(encoding="utf-8")
    path = tmp_path / "scene.toml"
    (tmp_path / "free_body.urdf").write_text(
        (ROBOTS / "free_body.urdf").read_text(encoding="utf-8"), encoding="utf-8"
    )
    path.write_text(text + "\n" + table + "\n", encoding="utf-8")
    with pytest.raises(pinsettle.SceneError, match=message):
        pinsettle.load_scene(path)


# --- the floating robots of example-robot-data --------------------------------------------

QUADRUPED_FEET = {
    "anymal": (["LF_FOOT", "LH_FOOT", "RF_FOOT", "RH_FOOT"], 0.031, 200.0, "standing"),
    "solo12": (["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"], 0.016, 5.0, "standing"),
    "go1": (["FL_foot", "FR_foot", "RL_foot", "RR_foot"], 0.02, 40.0, "standing"),
}
# talos stands on its soles, a rectangle of four points each.
SOLE_CORNERS = [(x, y, 0.0) for x in (-0.1, 0.1) for y in (-0.065, 0.065)]


def robot_on_floor(name: str) -> tuple[pinsettle.Scene, list[tuple[str, float, float]]]:
    """The robot floating, its joints on springs towards its SRDF stance, 2 cm above a floor
    (friction 0.8) on its feet (quadrupeds: spheres; talos: its soles' corners)."""
    import pinocchio
    from pinsettle._model_files import robot_srdf

    scene = pinsettle.Scene.from_robot(name, floating=True)
    scene.load_srdf(robot_srdf(name))
    if name == "talos":
        scene.set_pose("half_sitting")
        soles = [f"{side}_sole_link" for side in ("left", "right")]
        points = [(sole, corner, 0.0) for sole in soles for corner in SOLE_CORNERS]
        stiffness = 3000.0
    else:
        feet, radius, stiffness, pose = QUADRUPED_FEET[name]
        scene.set_pose(pose)
        points = [(foot, (0.0, 0.0, 0.0), radius) for foot in feet]
    model, q = scene.model, scene.q0()
    springs = add_stance_springs(scene, stiffness)
    scene.add_ground(friction=0.8, name="floor")
    data = model.createData()
    pinocchio.framesForwardKinematics(model, data, q)
    low = min(data.oMf[model.getFrameId(f)].act(np.array(p))[2] - r for f, p, r in points)
    for frame, point, radius in points:
        scene.add_contact(frame, point, radius)
    q = q.copy()
    q[2] += 0.02 - low
    scene.set_start(root_joint=[*q[:3], q[6], q[3], q[4], q[5]])
    return scene, springs


def com_over_support(model, q, contacts) -> bool:
    """Whether the centre of mass lies over the convex hull of the contact points (a flat
    floor: their x, y)."""
    import pinocchio
    from scipy.spatial import Delaunay

    com = pinocchio.centerOfMass(model, model.createData(), q)
    points = np.array([c.point[:2] for c in contacts])
    return bool(Delaunay(points).find_simplex(com[:2]) >= 0)


@pytest.mark.parametrize("name", ["anymal", "solo12", "go1", "talos"])
def test_floating_robots_stand_on_their_feet(name):
    scene, springs = robot_on_floor(name)
    result = pinsettle.solve(scene)
    # The floor carries the weight, to 1e-9 relative (talos: 885.57 N).
    assert_rests_on_the_floor(scene, result, springs)
    assert com_over_support(scene.model, result.q, result.contacts)
    assert result.stability == "stable"


@pytest.mark.parametrize(
    ("name", "pose", "trunk"),
    [("anymal", "standing", "base"), ("solo12", "standing", ""), ("talos", "half_sitting", "")],
)
def test_a_floating_robot_with_its_motors_off_lies_on_its_body(name, pose, trunk):
    # No spring holds the joints: dropped from its stance on all its collision shapes, its legs
    # give way and it lies on the floor, its trunk at most half its standing height (anymal on
    # its body's boxes, thighs and feet; solo12, whose trunk has no collision shape, on its
    # shoulders, upper legs and feet: its forces lie inside their cones, so it is stable;
    # talos, 824 collision points, on its knees, arms and head, several joints on their stops).
    from pinsettle._model_files import robot_srdf

    scene = pinsettle.Scene.from_robot(name, floating=True)
    scene.load_srdf(robot_srdf(name))
    scene.set_pose(pose)
    scene.add_ground(friction=0.8, name="floor")
    scene.add_collision_contacts()
    result = pinsettle.solve(scene)
    check = assert_rests_on_the_floor(scene, result)
    assert result.stability in ("stable", "marginal")
    assert com_over_support(scene.model, result.q, result.contacts)
    assert result.q[2] < 0.5 * scene.q0()[2]
    if trunk:  # the trunk's boxes carry most of its weight
        on_body = sum(c.normal_force for c in result.contacts if c.name.startswith(trunk))
        assert on_body >= 0.5 * check.total_normal[2]


def test_a_contact_names_its_body():
    # go1 lying with its motors off: each foot's point on its foot link, the trunk's four on
    # the trunk; the JSON of the command line carries the body too.
    scene = pinsettle.load_scene(ROBOTS / "go1_motors_off.toml")
    result = pinsettle.solve(scene)
    bodies = {c.name: c.body for c in result.contacts}
    assert bodies, result.summary()
    for name, body in bodies.items():
        expected = "trunk" if name.startswith("trunk") else name
        assert body == expected, (name, body)
    assert all("body" in c for c in result.to_dict()["contacts"])
    assert "trunk#2 (trunk)" in result.summary()

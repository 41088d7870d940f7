"""Contacts taken from a model's own collision geometry ([model] contacts = "collision",
Scene.add_collision_contacts): URDF shapes, meshes' hulls, MJCF floors and geoms.

Every contact is checked where Pinocchio or MuJoCo put its shape: the world points of the
contacts against the shapes' placements from pinocchio.updateGeometryPlacements (a box's
corners, a capsule's end centres, a cylinder's rims, a mesh's hull), against MuJoCo's geom
positions, and which geoms touch the floor and with what friction against MuJoCo's own contacts.
The rests are checked with tests/contact_reference.py (balance with Pinocchio's Jacobians,
cones, gaps) and the floor carrying m g to 1e-9.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest
from contact_reference import (
    add_stance_springs,
    assert_rests_on_the_floor,
    read_contacts,
    weight,
)

ROBOTS = Path(__file__).parents[1] / "robots"
G = 9.81


def world_points(scene: pinsettle.Scene, q: np.ndarray) -> dict[str, tuple[np.ndarray, float]]:
    """Each contact's centre in the world at q, and its radius (Pinocchio's frames)."""
    model = scene.model
    data = model.createData()
    pinocchio.framesForwardKinematics(model, data, q)
    return {
        c.name: (data.oMf[model.getFrameId(c.frame)].act(np.array(c.point)), c.radius)
        for c in scene.contacts
    }


# --- the shapes, one by one ------------------------------------------------------------------

FREE_BODY = ROBOTS / "free_body.urdf"


def free_body_with(*shapes) -> tuple[pinsettle.Scene, pinocchio.GeometryModel]:
    """The 1 kg free body with collision shapes (name, coal shape, placement in its joint)."""
    scene = pinsettle.Scene.from_urdf(FREE_BODY, floating=True)
    geometry = pinocchio.GeometryModel()
    frame = scene.model.getFrameId("body")
    joint = scene.model.getJointId("root_joint")
    for name, shape, placement in shapes:
        geometry.addGeometryObject(pinocchio.GeometryObject(name, joint, frame, placement, shape))
    return scene, geometry


def placements(scene, geometry, q):
    """oMg of each geometry object at q (Pinocchio's updateGeometryPlacements)."""
    model = scene.model
    data, gdata = model.createData(), geometry.createData()
    pinocchio.forwardKinematics(model, data, q)
    pinocchio.updateGeometryPlacements(model, data, geometry, gdata)
    return {obj.name: gdata.oMg[k] for k, obj in enumerate(geometry.geometryObjects)}


def random_q(scene, seed=3):
    np.random.seed(seed)
    return pinocchio.randomConfiguration(
        scene.model, -np.ones(scene.model.nq), np.ones(scene.model.nq)
    )


def test_each_shape_gives_its_points_where_pinocchio_places_it():
    import coal

    turned = pinocchio.SE3(pinocchio.rpy.rpyToMatrix(0.3, -0.4, 1.1), np.array([0.05, -0.02, 0.1]))
    mesh_points = np.random.default_rng(0).normal(size=(200, 3)) * [0.03, 0.02, 0.05]
    mesh = coal.BVHModelOBBRSS()
    mesh.beginModel(0, len(mesh_points))
    mesh.addVertices(mesh_points)
    mesh.endModel()
    scene, geometry = free_body_with(
        ("ball", coal.Sphere(0.04), turned),
        ("pill", coal.Capsule(0.02, 0.3), turned),  # radius, length: half length 0.15
        ("brick", coal.Box(0.2, 0.1, 0.06), turned),  # full sides
        ("can", coal.Cylinder(0.05, 0.08), turned),
        ("rock", mesh, turned),
    )
    scene.add_collision_contacts(geometry=geometry, hull_points=1000)
    q = random_q(scene)
    got = world_points(scene, q)
    at = placements(scene, geometry, q)
    # Sphere: its centre, its radius.
    assert np.allclose(got["ball"][0], at["ball"].translation, atol=1e-12)
    assert got["ball"][1] == 0.04
    # Capsule: the centres of its end spheres, along its z axis, its radius.
    axis = at["pill"].rotation[:, 2]
    for name, sign in (("pill#1", -1), ("pill#2", 1)):
        assert np.allclose(got[name][0], at["pill"].translation + sign * 0.15 * axis, atol=1e-12)
        assert got[name][1] == 0.02
    # Box: its 8 corners, points.
    corners = {
        tuple(np.round(at["brick"].act(np.array([x, y, z])), 12))
        for x in (-0.1, 0.1)
        for y in (-0.05, 0.05)
        for z in (-0.03, 0.03)
    }
    brick = [got[f"brick#{k}"] for k in range(1, 9)]
    assert {tuple(np.round(p, 12)) for p, _ in brick} == corners
    assert all(r == 0.0 for _, r in brick) and "brick#9" not in got
    # Cylinder: 8 points on each rim circle (radius 0.05 about the axis, 0.04 from the middle).
    rim = [got[f"can#{k}"][0] for k in range(1, 17)]
    local = [at["can"].actInv(p) for p in rim]
    assert np.allclose([math.hypot(p[0], p[1]) for p in local], 0.05, atol=1e-12)
    assert sorted(np.round([p[2] for p in local], 12)) == [-0.04] * 8 + [0.04] * 8
    angles = sorted(math.atan2(p[1], p[0]) % (2 * math.pi) for p in local[:8])
    assert np.allclose(np.diff(angles), 2 * math.pi / 8, atol=1e-12)
    # Mesh: the vertices of its convex hull (scipy's, here), all of them below the cap.
    from scipy.spatial import ConvexHull

    hull = mesh_points[ConvexHull(mesh_points).vertices]
    rock = np.array(
        [at["rock"].actInv(p) for name, (p, _) in got.items() if name.startswith("rock")]
    )
    assert len(rock) == len(hull) < 1000
    assert {tuple(np.round(p, 9)) for p in rock} == {tuple(np.round(p, 9)) for p in hull}


def test_a_hull_thinned_to_its_cap_keeps_its_extent():
    import coal
    from scipy.spatial import ConvexHull

    # 2000 points on an ellipsoid: a hull of about 2000 vertices.
    rng = np.random.default_rng(1)
    u = rng.normal(size=(2000, 3))
    points = u / np.linalg.norm(u, axis=1)[:, None] * [0.1, 0.05, 0.03]
    mesh = coal.BVHModelOBBRSS()
    mesh.beginModel(0, len(points))
    mesh.addVertices(points)
    mesh.endModel()
    scene, geometry = free_body_with(("egg", mesh, pinocchio.SE3.Identity()))
    scene.add_collision_contacts(geometry=geometry)  # the default cap, 16
    kept = np.array([c.point for c in scene.contacts])
    assert len(kept) == 16
    hull = points[ConvexHull(points).vertices]
    assert all(np.min(np.linalg.norm(hull - p, axis=1)) < 1e-12 for p in kept)  # hull vertices
    # How far the thinned hull falls short of the full one, along many directions: what the
    # note says, at most (it was measured on its own directions).
    note = next(n for n in scene.notes if "thinned" in n)
    said = float(note.split("by at most ")[1].split(" mm")[0]) * 1e-3
    v = rng.normal(size=(5000, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    shortfall = (hull @ v.T).max(axis=0) - (kept @ v.T).max(axis=0)
    assert 0 < shortfall.max() <= 1.1 * said
    # Along the axes it keeps the extremes: the body rests on a floor at its full height.
    for axis in range(3):
        assert kept[:, axis].max() == pytest.approx(hull[:, axis].max(), abs=1e-4)
        assert kept[:, axis].min() == pytest.approx(hull[:, axis].min(), abs=1e-4)


def test_a_box_from_its_collision_shape_rests_on_its_four_bottom_corners(tmp_path):
    # free_body.urdf with a collision box: the same rest as box_on_floor's four given corners,
    # m g / 4 on each bottom corner (least norm), the top corners off the floor.
    urdf = tmp_path / "box.urdf"
    text = FREE_BODY.read_text(encoding="utf-8")
    urdf.write_text(
        text.replace(
            "</visual>",
            '</visual>\n    <collision><geometry><box size="0.2 0.1 0.1"/></geometry></collision>',
        ),
        encoding="utf-8",
    )
    scene = pinsettle.Scene.from_urdf(urdf, floating=True)
    scene.add_ground(friction=0.5)
    scene.add_collision_contacts()
    assert len(scene.contacts) == 8 and all(c.frame == "body" for c in scene.contacts)
    scene.set_start(root_joint=[0.0, 0.0, 0.2, 1.0, 0.0, 0.0, 0.0])
    result = pinsettle.solve(scene)
    assert_rests_on_the_floor(scene, result)
    assert result.q[2] == pytest.approx(0.05, abs=1e-6)
    assert len(result.contacts) == 4
    for c in result.contacts:
        assert c.normal_force == pytest.approx(G / 4, rel=1e-9)
        assert c.point[2] == pytest.approx(0.0, abs=1e-6)


# --- the floating robots of example-robot-data ---------------------------------------------

#: Joint spring stiffness towards the SRDF stance (N m/rad) and the stance, as
#: tests/test_contacts.py drops them on given feet.
STANCES = {
    "go1": (40.0, "standing"),
    "anymal": (200.0, "standing"),
    "solo12": (5.0, "standing"),
    "talos": (3000.0, "half_sitting"),
}


def expected_count(scene: pinsettle.Scene, cap: int = 16) -> int:
    """The contacts the rules give, counted from the robot's collision GeometryModel."""
    import coal
    from pinsettle._collision_contacts import urdf_geometry
    from scipy.spatial import ConvexHull

    count = 0
    for obj in urdf_geometry(scene.model, scene.urdf).geometryObjects:
        g = obj.geometry
        if obj.parentJoint == 0:
            continue
        if isinstance(g, coal.Sphere):
            count += 1
        elif isinstance(g, coal.Capsule):
            count += 2
        elif isinstance(g, coal.Box):
            count += 8
        elif isinstance(g, coal.Cylinder):
            count += 16
        else:
            vertices = np.array(g.vertices())
            count += min(cap, len(ConvexHull(vertices).vertices))
    return count


def robot_drop(name: str):
    from pinsettle._model_files import robot_srdf

    scene = pinsettle.Scene.from_robot(name, floating=True)
    scene.load_srdf(robot_srdf(name))
    stiffness, pose = STANCES[name]
    scene.set_pose(pose)
    q = scene.q0()
    springs = add_stance_springs(scene, stiffness)
    scene.add_ground(friction=0.8, name="floor")
    scene.add_collision_contacts()
    # 2 cm above the floor: the lowest contact of the stance.
    low = min(p[2] - r for p, r in world_points(scene, q).values())
    q = q.copy()
    q[2] += 0.02 - low
    scene.set_start(root_joint=[*q[:3], q[6], q[3], q[4], q[5]])
    return scene, springs


#: The contacts each robot gets (checked against the rules by expected_count) and the
#: geometries it stands on.
ROBOT_CONTACTS = {
    "go1": (404, "_foot_0"),
    "anymal": (492, "_FOOT_0"),
    "solo12": (272, "_FOOT_0"),
    "talos": (824, "_6_link_0"),
}


@pytest.mark.parametrize("name", sorted(ROBOT_CONTACTS))
def test_floating_robots_stand_on_the_feet_of_their_collision_geometry(name):
    scene, springs = robot_drop(name)
    count, feet = ROBOT_CONTACTS[name]
    assert len(scene.contacts) == count == expected_count(scene)
    result = pinsettle.solve(scene)
    assert_rests_on_the_floor(scene, result, springs)
    # It stands on its feet (quadrupeds: the four foot shapes; talos: its two ankle meshes).
    standing = {c.name.split("#")[0] for c in result.contacts if c.normal_force > 0}
    assert standing and all(shape.endswith(feet) for shape in standing), standing
    assert len(standing) == (2 if name == "talos" else 4)


def test_what_is_taken_is_noted_and_exclude_leaves_shapes_out():
    scene = pinsettle.Scene.from_robot("go1", floating=True)
    cameras = ["camera_chin", "camera_face", "camera_left", "camera_rearDown", "camera_right"]
    scene.add_collision_contacts(exclude=[*cameras, "FL_calf_rotor_0"])
    note = scene.notes[-1]
    assert "collision contacts: 348 points from 32 shapes" in note
    assert "(4 spheres, 13 boxes, 15 cylinders)" in note
    assert not any(c.frame in cameras or c.name.startswith("FL_calf_rotor") for c in scene.contacts)
    # Locked joints: a body held to the world by them gives no contact.
    fixed = pinsettle.Scene.from_robot("ur5")
    fixed.add_collision_contacts()
    assert "shapes fixed to the world left out" in fixed.notes[-2] or any(
        "fixed to the world" in n for n in fixed.notes
    )
    assert not any(c.frame == "base_link" for c in fixed.contacts)


# --- MJCF floors and geoms -------------------------------------------------------------------


def test_the_library_ant_stands_on_its_mjcf_floor_as_mujoco_puts_it(mujoco):
    path = ROBOTS / "mjcf_ant.toml"
    scene = pinsettle.load_scene(path)
    # The floor of the file; the 13 geoms MuJoCo collides with it (the belly left out).
    assert [(g.name, g.point, g.normal, g.friction) for g in scene.grounds] == [
        ("floor", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.0)
    ]
    xml = ROBOTS / "mjcf_ant.xml"
    mj = mujoco.MjModel.from_xml_path(str(xml))
    data = mujoco.MjData(mj)
    mujoco.mj_forward(mj, data)
    floor = mj.geom("floor").id
    colliding = [
        g
        for g in range(mj.ngeom)
        if g != floor
        and (
            mj.geom_contype[g] & mj.geom_conaffinity[floor]
            or mj.geom_contype[floor] & mj.geom_conaffinity[g]
        )
    ]
    names = {c.name.split("#")[0] for c in scene.contacts}
    assert names == {mj.geom(g).name for g in colliding} and "belly" not in names
    # Each contact where MuJoCo puts its geom at qpos0: a sphere's centre, a capsule's ends.
    got = world_points(scene, scene.q0())
    for g in colliding:
        name, centre = mj.geom(g).name, data.geom_xpos[g]
        radius = mj.geom_size[g][0]
        if mj.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE:
            assert np.allclose(got[name][0], centre, atol=1e-12) and got[name][1] == radius
            continue
        axis = data.geom_xmat[g].reshape(3, 3)[:, 2] * mj.geom_size[g][1]
        ends = sorted(tuple(np.round(p, 12)) for p in (centre - axis, centre + axis))
        mine = sorted(tuple(np.round(got[f"{name}#{k}"][0], 12)) for k in (1, 2))
        assert ends == mine and got[f"{name}#1"][1] == radius
    # The rest: on its four feet, the floor carrying m g (Pinocchio's masses) to 1e-9.
    result = pinsettle.solve(scene)
    planes, spheres = read_contacts(path)
    assert [s.name for s in spheres] == [c.name for c in scene.contacts]
    check = assert_rests_on_the_floor(scene, result)
    assert weight(scene.model) == pytest.approx(mj.body_mass.sum() * G, rel=1e-12)
    assert check.total_normal[2] == pytest.approx(56.482, abs=5e-4)  # the header's number
    assert result.stability == "stable"
    assert sorted(c.name for c in result.contacts) == [
        f"{leg}_ankle_geom#1" for leg in ("fourth", "left", "right", "third")
    ]
    # MuJoCo's damped rest: the torso within its soft contacts' sinking (a few mm) of ours.
    mj.opt.noslip_iterations = 10  # its soft friction lets the feet creep otherwise
    data = mujoco.MjData(mj)
    while data.time < 5.0:
        mujoco.mj_step(mj, data)
    assert np.abs(data.qvel).max() < 1e-4
    sink = -min(data.contact[i].dist for i in range(data.ncon))
    assert 0 < sink < 2e-3
    assert abs(data.qpos[2] - result.q[2]) < 2e-3


FLOOR_FILE = """<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="1 1 0.1" {floor}/>
    <body name="block" pos="0 0 {height}">
      <freejoint/>
      {geoms}
    </body>
  </worldbody>
  {contact}
</mujoco>
"""


def mjcf(tmp_path, geoms, floor="", contact="", height="0.05", name="file.xml"):
    path = tmp_path / name
    path.write_text(
        FLOOR_FILE.format(geoms=geoms, floor=floor, contact=contact, height=height),
        encoding="utf-8",
    )
    return path


@pytest.mark.parametrize(
    ("floor", "geom", "expected"),
    [
        ("", "", 1.0),  # MuJoCo's default
        ('friction="0.6"', 'friction="0.9"', 0.9),  # the larger
        ('friction="0.6" priority="1"', 'friction="0.9"', 0.6),  # the higher priority's
        ('friction="0.6"', 'friction="0.3" priority="2"', 0.3),
        ('friction="0.6"', 'condim="1"', 1.0),  # condim: the larger, 3
        ('friction="0.6"', 'condim="1" priority="1"', 0.0),  # frictionless
    ],
)
def test_a_floor_takes_mujocos_friction_of_the_pair(tmp_path, mujoco, floor, geom, expected):
    path = mjcf(tmp_path, f'<geom type="sphere" size="0.1" {geom}/>', floor=floor)
    scene = pinsettle.Scene.from_mjcf(path)
    scene.add_collision_contacts()
    assert scene.grounds[0].friction == expected
    # MuJoCo's own contact of the sphere 5 cm into the floor: its friction and dimension.
    mj = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(mj)
    mujoco.mj_forward(mj, data)
    assert data.ncon == 1
    contact = data.contact[0]
    assert (contact.dim == 1 and expected == 0.0) or contact.friction[0] == expected


def test_mjcf_geoms_touch_the_floor_as_mujoco_collides_them(tmp_path, mujoco):
    # contype/conaffinity, an <exclude> of a body and the world, an explicit <pair>, a plane
    # turned by its zaxis: which geoms are contacts is what MuJoCo collides.
    geoms = """
      <geom name="a" type="sphere" size="0.02" pos="0.1 0 -0.04"/>
      <geom name="b" type="box" size=".02 .02 .02" pos="-0.1 0 -0.04" contype="2" conaffinity="2"/>
      <geom name="c" type="cylinder" size=".02 .02" pos="0 0.1 -0.04" contype="0" conaffinity="1"/>
      <geom name="d" type="capsule" size=".02 .03" pos="0 -0.1 -0.04" contype="4" conaffinity="0"/>
      <body name="arm" pos="0 0 -0.04">
        <joint name="hinge" axis="1 0 0"/>
        <geom name="e" type="sphere" size="0.02" contype="0" conaffinity="0"/>
        <geom name="f" type="sphere" size="0.02" pos="0 0.05 0"/>
      </body>"""
    contact = (
        '<contact><exclude body1="world" body2="arm"/>'
        '<pair geom1="floor" geom2="e" friction="0.4"/></contact>'
    )
    path = mjcf(tmp_path, geoms, floor='contype="1" conaffinity="3"', contact=contact)
    scene = pinsettle.Scene.from_mjcf(path)
    scene.add_collision_contacts()
    ours = {c.name.split("#")[0] for c in scene.contacts}
    mj = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(mj)
    mujoco.mj_forward(mj, data)  # every geom is 2 cm into the floor
    theirs = {mj.geom(data.contact[i].geom2).name for i in range(data.ncon)}
    assert ours == theirs == {"a", "b", "c", "e"}
    counts = {name: sum(c.name.split("#")[0] == name for c in scene.contacts) for name in ours}
    assert counts == {"a": 1, "b": 8, "c": 16, "e": 1}
    # Pair frictions 1 (a, b, c) and 0.4 (e, the <pair>'s own): the floor takes the smallest.
    assert scene.grounds[0].friction == 0.4
    assert any("grip more" in n and "a, b, c" in n for n in scene.notes)


def test_a_turned_floor_and_an_mjcf_mesh(tmp_path):
    # A plane tilted 0.2 rad about x: its normal is its z axis. A mesh geom (vertices in
    # <asset>): its hull's vertices, placed by the geom.
    vertices = "0 0 0  0.1 0 0  0 0.1 0  0 0 0.1  0.03 0.03 0.03"
    path = tmp_path / "slope.xml"
    path.write_text(
        f"""<mujoco>
  <compiler angle="radian"/>
  <asset><mesh name="tet" vertex="{vertices}"/></asset>
  <worldbody>
    <geom name="slope" type="plane" size="1 1 0.1" euler="0.2 0 0"/>
    <body name="rock" pos="0 0 1"><freejoint/>
      <geom type="mesh" mesh="tet" pos="0.01 0 0"/>
    </body>
  </worldbody>
</mujoco>""",
        encoding="utf-8",
    )
    scene = pinsettle.Scene.from_mjcf(path)
    scene.add_collision_contacts()
    (ground,) = scene.grounds
    assert np.allclose(ground.normal, [0.0, -math.sin(0.2), math.cos(0.2)], atol=1e-12)
    assert ground.name == "slope" and ground.friction == 1.0
    points = sorted(tuple(np.round(c.point, 6)) for c in scene.contacts)  # MuJoCo's float32
    tet = [(0.01, 0, 0), (0.11, 0, 0), (0.01, 0.1, 0), (0.01, 0, 0.1)]  # the inner one is not
    assert points == sorted(tuple(np.round(p, 6)) for p in tet)
    assert [c.name for c in scene.contacts] == [f"rock:geom1#{k}" for k in range(1, 5)]


def test_a_scene_file_takes_the_floors_unless_it_gives_grounds(tmp_path):
    path = mjcf(tmp_path, '<geom name="ball" type="sphere" size="0.1"/>', floor='friction="0.7"')
    toml = tmp_path / "scene.toml"
    toml.write_text('[model]\nmjcf = "file.xml"\ncontacts = "collision"\n', encoding="utf-8")
    scene = pinsettle.load_scene(toml)
    assert [(g.name, g.friction) for g in scene.grounds] == [("floor", 1.0)]
    assert not any("floor floor (plane geoms)" in n for n in scene.notes)
    assert any("unless contacts hold it" in n for n in scene.notes)  # the free block's note
    toml.write_text(
        '[model]\nmjcf = "file.xml"\ncontacts = "collision"\n[[ground]]\nfriction = 0.3\n',
        encoding="utf-8",
    )
    scene = pinsettle.load_scene(toml)
    assert [(g.name, g.friction) for g in scene.grounds] == [("ground1", 0.3)]
    assert any("the scene's grounds replace them" in n for n in scene.notes)
    # Without a contacts key (and for the file alone), the floors are taken as MuJoCo does;
    # with contacts = "none" the floor is noted and left out.
    toml.write_text('[model]\nmjcf = "file.xml"\n', encoding="utf-8")
    default = pinsettle.load_scene(toml)
    assert [(g.name, g.friction) for g in default.grounds] == [("floor", 1.0)]
    assert default.contacts == pinsettle.load_scene(path).contacts and default.contacts
    toml.write_text('[model]\nmjcf = "file.xml"\ncontacts = "none"\n', encoding="utf-8")
    for plain in (pinsettle.load_scene(toml), pinsettle.load_scene(path, contacts="none")):
        assert not plain.grounds and not plain.contacts
        assert any("floor floor (plane geoms)" in n and "play no part" in n for n in plain.notes)


def test_a_urdf_scene_file_gives_the_same_contacts_as_the_python_call(tmp_path):
    toml = tmp_path / "go1.toml"
    toml.write_text(
        '[model]\nrobot = "go1"\nfloating = true\ncontacts = "collision"\nhull_points = 8\n'
        'contacts_exclude = ["camera_chin"]\n[[ground]]\n',
        encoding="utf-8",
    )
    from_file = pinsettle.load_scene(toml)
    in_code = pinsettle.Scene.from_robot("go1", floating=True)
    in_code.add_ground()
    in_code.add_collision_contacts(hull_points=8, exclude=["camera_chin"])
    assert from_file.contacts == in_code.contacts and len(from_file.contacts) == 396


# --- bad input -------------------------------------------------------------------------------


def test_collision_contact_errors_name_what_is_wrong(tmp_path):
    import coal

    scene = pinsettle.Scene.from_urdf(FREE_BODY, floating=True)
    with pytest.raises(pinsettle.SceneError, match=r"free_body.urdf has no collision geometry"):
        scene.add_collision_contacts()
    bare = pinsettle.Scene(scene.model)
    with pytest.raises(
        pinsettle.SceneError, match="no model file.*geometry=pinocchio.GeometryModel"
    ):
        bare.add_collision_contacts()
    with pytest.raises(pinsettle.SceneError, match="geometry must be a pinocchio.GeometryModel"):
        bare.add_collision_contacts(geometry="model.urdf")
    for bad in (3, 2.5, True, "16"):
        with pytest.raises(pinsettle.SceneError, match="hull_points must be an integer >= 4"):
            bare.add_collision_contacts(hull_points=bad)
    _, geometry = free_body_with(("cone", coal.Cone(0.1, 0.2), pinocchio.SE3.Identity()))
    with pytest.raises(pinsettle.SceneError, match=r"'cone' \(frame 'body'\) is a cone"):
        bare.add_collision_contacts(geometry=geometry)
    _, geometry = free_body_with(("flat", coal.Box(0.1, 0.0, 0.1), pinocchio.SE3.Identity()))
    with pytest.raises(pinsettle.SceneError, match=r"'flat'.*size must be 3 positive"):
        bare.add_collision_contacts(geometry=geometry)
    go1 = pinsettle.Scene.from_robot("go1", floating=True)
    with pytest.raises(pinsettle.SceneError, match=r"exclude: .*'FL_fot'.*did you mean 'FL_foot"):
        go1.add_collision_contacts(exclude=["FL_fot"])
    go1.add_contact("FL_foot", name="FL_foot_0")
    with pytest.raises(pinsettle.SceneError, match="contact name 'FL_foot_0' is taken"):
        go1.add_collision_contacts()


@pytest.mark.parametrize(
    ("geoms", "floor", "message"),
    [
        (
            '<geom name="egg" type="ellipsoid" size="0.1 0 0.2"/>',
            "",
            r"<geom name=\"egg\">.*size: must be positive",
        ),
        (
            '<geom name="neg" type="sphere" size="-0.1"/>',
            "",
            r"<geom name=\"neg\">.*size: must be positive",
        ),
        (
            '<geom name="b" type="sphere" size="0.1" friction="-1"/>',
            "",
            r"<geom name=\"b\">.* friction: .*>= 0",
        ),
        (
            '<geom name="b" type="sphere" size="0.1"/>',
            'friction="-0.5"',
            r"<geom name=\"floor\">.*friction.*>= 0",
        ),
    ],
)
def test_mjcf_contact_errors_name_the_element(tmp_path, geoms, floor, message):
    path = mjcf(tmp_path, geoms, floor=floor)
    with pytest.raises((pinsettle.SceneError, ValueError), match=message):
        scene = pinsettle.Scene.from_mjcf(path)
        scene.add_collision_contacts()


def test_a_geom_left_out_by_name_gives_no_error(tmp_path):
    path = mjcf(
        tmp_path,
        '<geom name="egg" type="ellipsoid" size="0.1 0.1 0.2"/><geom name="ball" size="0.1"/>',
    )
    scene = pinsettle.Scene.from_mjcf(path)
    scene.add_collision_contacts(exclude=["egg"])
    assert [c.name for c in scene.contacts] == ["ball"]


def test_a_geom_touching_one_floor_and_not_another_is_refused(tmp_path):
    path = tmp_path / "two.xml"
    path.write_text(
        """<mujoco><worldbody>
  <geom name="low" type="plane" size="1 1 0.1"/>
  <geom name="wall" type="plane" size="1 1 .1" zaxis="1 0 0" pos="-1 0 0" contype="2"
        conaffinity="2"/>
  <body name="ball" pos="0 0 1"><freejoint/><geom name="b" size="0.1"/></body>
</worldbody></mujoco>""",
        encoding="utf-8",
    )
    scene = pinsettle.Scene.from_mjcf(path)
    with pytest.raises(
        pinsettle.SceneError, match=r"<geom name=\"b\">.*collides with floor low but not with wall"
    ):
        scene.add_collision_contacts()


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ('contacts = "mesh"', r"\[model\] contacts must be 'collision'.*got 'mesh'"),
        ("hull_points = 8", r"\[model\] hull_points is for contacts from the model's collision"),
        (
            'contacts = "collision"\nhull_points = 2',
            r"\[model\] contacts: hull_points must be an integer >= 4",
        ),
        (
            'contacts = "collision"\ncontacts_exclude = "a"',
            r"\[model\] contacts_exclude must be a list",
        ),
        (
            'contacts = "collision"',
            r"\[model\] contacts: .*free_body.urdf has no collision geometry",
        ),
    ],
)
def test_scene_file_errors_name_the_key(tmp_path, table, message):
    (tmp_path / "free_body.urdf").write_text(
        FREE_BODY.read_text(encoding="utf-8"), encoding="utf-8"
    )
    path = tmp_path / "scene.toml"
    path.write_text(
        f'[model]\nurdf = "free_body.urdf"\nfloating = true\n{table}\n', encoding="utf-8"
    )
    with pytest.raises(pinsettle.SceneError, match=message):
        pinsettle.load_scene(path)

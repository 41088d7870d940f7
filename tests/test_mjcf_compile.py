"""What MuJoCo's compiler computes from an MJCF file, computed as it does and checked against
MuJoCo's own compiled model (``mujoco.MjModel``), never against pinsettle's numbers:

- ``<compiler settotalmass>``: every body's mass and inertia scaled by one factor, last
  (gymnasium's half_cheetah.xml, dm_control's cheetah.xml);
- ``springdamper`` on a joint: its stiffness and damping from the joint's inertia at qpos0
  (dm_control's dog.xml);
- a free joint given ``limited`` or a ``range`` (by a default class: MuJoCo's own saved copy of
  dm_control's quadruped) is unlimited, as MuJoCo compiles it;
- ellipsoid geoms as contact shapes: spheres inside the ellipsoid, at most a stated fraction
  of its smallest semi-axis short of it (humanoid_CMU's hands, the quadruped's torso), the
  distances of the rests checked by MuJoCo's own collision of the ellipsoid.

The rests of the real files, hung from their torso, are judged by the gallery's judge
(tests/third_party_models.py: MuJoCo's static force at the answer).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest
import third_party_models as gallery  # tests/third_party_models.py (tests/ is on sys.path)
from conftest import mujoco_warnings
from contact_reference import assert_rests_on_the_floor
from pinsettle._collision_contacts import ELLIPSOID_TOL, directions, ellipsoid_points
from pinsettle._mjcf import MjcfError, load_mjcf
from test_mjcf_files import model_file, one_line_error, run

HALF_CHEETAH = ("gymnasium", "envs", "mujoco", "assets", "half_cheetah.xml")
CHEETAH = ("dm_control", "suite", "cheetah.xml")
DOG = ("dm_control", "suite", "dog.xml")
DOG_V2 = ("dm_control", "locomotion", "walkers", "assets", "dog_v2", "dog.xml")
HUMANOID_CMU = ("dm_control", "suite", "humanoid_CMU.xml")
QUADRUPED = ("dm_control", "suite", "quadruped.xml")


def mj_compile(mujoco, path: Path):
    """MuJoCo's model of the file, its compile warnings kept off MUJOCO_LOG.TXT (MuJoCo 4.0
    warns that settotalmass is deprecated)."""
    with mujoco_warnings(mujoco):
        return mujoco.MjModel.from_xml_path(str(path))


def write(tmp_path: Path, text: str, name: str = "model.xml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def copy_of(source: Path, out: Path, remove_joints=(), edit=lambda root: None) -> Path:
    """A copy of a model file elsewhere (its includes and asset folders made absolute), some
    joints removed (a body hung from its parent where the file places it)."""
    root = ET.parse(source).getroot()
    for el in root.iter("include"):
        el.set("file", str(source.parent / el.get("file", "")))
    for el in root.iter("compiler"):
        for key in ("meshdir", "texturedir", "assetdir"):
            if key in el.attrib:
                el.set(key, str(source.parent / el.get(key, "")) + "/")
    for parent in root.iter():
        for child in list(parent):
            if child.tag in ("joint", "freejoint") and child.get("name") in remove_joints:
                parent.remove(child)
    edit(root)
    ET.ElementTree(root).write(out)
    return out


# --- settotalmass -------------------------------------------------------------------------------


def assert_masses_are_mujocos(mujoco, path: Path, **kw) -> None:
    """Each body's mass, centre of mass and principal moments as MuJoCo compiles them."""
    mj = mj_compile(mujoco, path)
    ours = load_mjcf(path, **kw).inertias
    for b in range(1, mj.nbody):
        name = mj.body(b).name
        if mj.body_mass[b] == 0:
            assert name not in ours or ours[name][0] == 0, name
            continue
        mass, com, inertia = ours[name]
        assert mass == pytest.approx(mj.body_mass[b], rel=1e-9), name
        assert np.abs(com - mj.body_ipos[b]).max() <= 1e-9 * max(1.0, np.abs(com).max()), name
        moments = np.sort(np.linalg.eigvalsh(inertia))
        assert np.abs(moments - np.sort(mj.body_inertia[b])).max() <= 1e-9 * moments.max(), name


@pytest.mark.parametrize("parts", [HALF_CHEETAH, CHEETAH], ids=lambda p: p[0])
def test_settotalmass_of_real_files_is_mujocos(mujoco, parts):
    path = model_file(*parts)
    assert 'settotalmass="14"' in path.read_text()
    assert_masses_are_mujocos(mujoco, path)
    model = load_mjcf(path)
    assert sum(m for m, _, _ in model.inertias.values()) == pytest.approx(14.0, rel=1e-12)
    assert any("<compiler settotalmass>" in n and "0.660885" in n for n in model.notes)


SCALED = """<mujoco>
  <compiler settotalmass="{total}" boundmass="0.01" boundinertia="0.001"/>
  <worldbody>
    <body name="base" pos="0 0 1">
      <joint name="hip" axis="0 1 0"/>
      <inertial pos="0.1 0 0" quat="0.9 0.1 0.2 0" mass="2" diaginertia="0.1 0.2 0.25"/>
      <body name="empty" pos="0.2 0 0">
        <joint name="knee" axis="0 1 0"/>
        <body name="foot" pos="0.2 0 0">
          <joint name="ankle" axis="1 0 0"/>
          <geom type="box" size="0.1 0.05 0.02" density="300" euler="10 20 30"/>
          <geom type="capsule" fromto="0 0 0 0 0 -0.2" size="0.02"/>
        </body>
      </body>
    </body>
    <body name="crate" pos="1 0 0.2"><freejoint/><geom type="box" size="0.1 0.1 0.1"/></body>
  </worldbody>
</mujoco>
"""


@pytest.mark.parametrize("free_objects", ["keep", "lock"])
def test_settotalmass_scales_after_boundmass_as_mujoco(tmp_path, mujoco, free_objects):
    # An explicit <inertial>, a body of bounded mass without geoms, geoms of two kinds and a free
    # object (a body in MuJoCo whether it is kept or locked): all scaled, the bound first.
    path = write(tmp_path, SCALED.format(total=5))
    assert_masses_are_mujocos(mujoco, path, free_objects=free_objects)
    masses = load_mjcf(path, free_objects=free_objects).inertias
    assert set(masses) == {"base", "empty", "foot", "crate"}
    assert sum(m for m, _, _ in masses.values()) == pytest.approx(5.0, rel=1e-12)
    # The rest of the hanging leg: the same as without the scaling (gravity and inertia scale
    # alike), at a different gravity torque that MuJoCo confirms.
    plain = write(tmp_path, SCALED.replace(' settotalmass="{total}"', ""), "plain.xml")
    scaled, unscaled = pinsettle.load_scene(path), pinsettle.load_scene(plain)
    assert np.allclose(pinsettle.solve(scaled).q, pinsettle.solve(unscaled).q, atol=1e-8)


# --- springdamper -------------------------------------------------------------------------------


def assert_springdampers_are_mujocos(mujoco, path: Path, **kw) -> dict:
    """Each springdamper joint's stiffness and damping as MuJoCo compiles them, and its spring."""
    mj = mj_compile(mujoco, path)
    model = load_mjcf(path, **kw)
    springs = {name: (k, rest) for name, k, rest in model.joint_springs}
    assert model.springdampers
    for name, (stiffness, damping) in model.springdampers.items():
        j = mj.joint(name).id
        assert stiffness == pytest.approx(mj.jnt_stiffness[j], rel=1e-9), name
        dofs = range(mj.jnt_dofadr[j], mj.jnt_dofadr[j] + 1)
        assert all(damping == pytest.approx(mj.dof_damping[d], rel=1e-9) for d in dofs), name
        assert springs[name][0] == stiffness
        assert springs[name][1] == pytest.approx(mj.qpos_spring[mj.jnt_qposadr[j]], abs=1e-12)
    # Every other spring is the file's own stiffness.
    for name, (k, _) in springs.items():
        assert k == pytest.approx(mj.jnt_stiffness[mj.joint(name).id], rel=1e-12), name
    return model.springdampers


@pytest.mark.parametrize("parts", [DOG, DOG_V2], ids=["suite", "locomotion"])
def test_springdamper_of_the_dog_is_mujocos(mujoco, parts):
    path = model_file(*parts)
    assert len(assert_springdampers_are_mujocos(mujoco, path)) == 21  # its tail's joints


SPRINGDAMPER = """<mujoco>
  <compiler settotalmass="7"/>
  <default><joint armature="0.05"/></default>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="shoulder" axis="0 1 0" ref="20" springdamper="0.2 0.7" springref="10"/>
      <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.04"/>
      <body name="forearm" pos="0.4 0 0">
        <joint name="elbow_y" axis="0 1 0" springdamper="0.1 1" stiffness="3"/>
        <joint name="elbow_x" axis="1 0 0" springdamper="0.3 0.5" armature="0.2"/>
        <geom type="box" size="0.2 0.03 0.03" pos="0.2 0 0"/>
      </body>
    </body>
    {others}
  </worldbody>
</mujoco>
"""
SLIDERS = """
    <body name="lift" pos="1 0 0">
      <joint name="lift" type="slide" axis="0 0 1" springdamper="0.5 1" armature="0.3"/>
      <geom size="0.1"/>
    </body>
    <body name="cart" pos="-1 0 0">
      <joint name="rail" type="slide" axis="1 0 0" springdamper="0.5 1" armature="0.3"/>
      <geom size="0.1" pos="0 0 0.2"/>
    </body>"""


def test_springdamper_takes_the_inertia_at_qpos0_as_mujoco(tmp_path, mujoco):
    # A ref (qpos0 is not the zero pose), armature by default and its own, two joints on one
    # body, a stiffness replaced, masses scaled first; a slider on the world with its mass at
    # its origin (MuJoCo's simple body: its mass alone, the armature left out) and one without.
    path = write(tmp_path, SPRINGDAMPER.format(others=SLIDERS))
    gains = assert_springdampers_are_mujocos(mujoco, path)
    mj = mj_compile(mujoco, path)
    lift, cart = (mj.body_mass[mj.body(name).id] for name in ("lift", "cart"))
    assert gains["lift"] == pytest.approx((lift / 0.5**2, 2 * lift / 0.5), rel=1e-12)
    assert gains["rail"] == pytest.approx(((cart + 0.3) / 0.5**2, 2 * (cart + 0.3) / 0.5))


def test_springdamper_leaves_out_the_free_joint_floating_adds(tmp_path, mujoco):
    # MuJoCo's file has no free joint: the arm's inertias are those of the arm on its base.
    text = SPRINGDAMPER.format(others="").replace(
        '<body name="arm" pos="0 0 1">', '<body name="base"><geom size="0.2"/><body name="arm">'
    )
    path = write(tmp_path, text.replace("</worldbody>", "</body></worldbody>"))
    fixed = assert_springdampers_are_mujocos(mujoco, path)
    assert assert_springdampers_are_mujocos(mujoco, path, floating=True).keys() == fixed.keys()


def test_springdamper_with_springs_off_is_noted_and_no_spring(tmp_path):
    text = SPRINGDAMPER.format(others="").replace(
        "<worldbody>", '<option><flag spring="disable"/></option><worldbody>'
    )
    model = load_mjcf(write(tmp_path, text))
    assert model.joint_springs == [] and set(model.springdampers) == {
        "shoulder",
        "elbow_y",
        "elbow_x",
    }
    assert any("springs of shoulder, elbow_y, elbow_x not applied" in n for n in model.notes)
    assert any("joint damping of shoulder, elbow_y, elbow_x" in n for n in model.notes)


@pytest.mark.parametrize(
    "joint, fragments",
    [
        ('springdamper="0 1"', ["springdamper", "must be positive", "MuJoCo refuses"]),
        ('springdamper="0.1 -1"', ["springdamper", "must be positive"]),
        ('springdamper="0.1"', ["springdamper", "expected 2 numbers"]),
        ('type="ball" springdamper="0.1 1"', ["springdamper", "ball joint"]),
    ],
)
def test_springdamper_errors_are_mujocos(tmp_path, mujoco, joint, fragments):
    path = write(
        tmp_path,
        f'<mujoco><worldbody><body name="b"><joint name="j" {joint}/><geom size="0.1"/>'
        "</body></worldbody></mujoco>",
    )
    message = str(pytest.raises(MjcfError, load_mjcf, path).value)
    for fragment in fragments:
        assert fragment in message, message
    if "ball" not in joint:  # MuJoCo refuses these too (a ball's spring it would honour)
        with pytest.raises(ValueError):
            mj_compile(mujoco, path)


# --- a free joint's range and limited ---------------------------------------------------------


FREE_LIMITED = """<mujoco>
  <default><joint limited="true" range="-30 30"/></default>
  <worldbody>
    <body name="torso" pos="0 0 1">
      <joint name="root" type="free" {free}/>
      <geom size="0.1"/>
      <body name="leg" pos="0 0 -0.2"><joint name="hip" axis="0 1 0"/><geom size="0.05"/></body>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.mark.parametrize("free", ["", 'range="1 -1"', 'limited="true"', 'limited="false"'])
def test_a_free_joint_is_unlimited_as_mujoco_compiles_it(tmp_path, mujoco, free):
    path = write(tmp_path, FREE_LIMITED.format(free=free))
    mj = mj_compile(mujoco, path)
    assert list(mj.jnt_limited) == [0, 1]
    model = load_mjcf(path)
    hip = model.model.idx_qs[model.model.getJointId("hip")]
    assert model.model.upperPositionLimit[hip] == pytest.approx(np.radians(30))
    # The class's range reaches the free joint whatever its limited: said, as left out.
    assert any("free joint root (MuJoCo compiles a free joint unlimited)" in n for n in model.notes)


@pytest.mark.parametrize(
    "element, fragments",
    [
        ('<joint name="root" type="free" range="1"/>', ["range", "expected 2 numbers"]),
        ('<joint name="root" type="free" limited="yes"/>', ["limited", "expected one of"]),
        ('<freejoint name="root" range="-1 1"/>', ["<freejoint> takes name, group and align"]),
        ('<freejoint name="root" limited="false"/>', ["not limited", "MuJoCo refuses it too"]),
    ],
)
def test_what_mujoco_refuses_on_a_free_joint_is_refused(tmp_path, mujoco, element, fragments):
    path = write(
        tmp_path,
        f'<mujoco><worldbody><body name="b">{element}<geom size="0.1"/></body></worldbody>'
        "</mujoco>",
    )
    with pytest.raises(ValueError):
        mj_compile(mujoco, path)
    message = str(pytest.raises(MjcfError, load_mjcf, path).value)
    for fragment in fragments:
        assert fragment in message, message


def saved_quadruped(mujoco, tmp_path: Path) -> Path:
    """MuJoCo's own saved copy of dm_control's quadruped (its free joint limited by its class)."""
    model = mj_compile(mujoco, model_file(*QUADRUPED))
    path = tmp_path / "quadruped_saved.xml"
    mujoco.mj_saveLastXML(str(path), model)
    text = path.read_text()
    assert '<joint name="root" type="free"' in text and 'limited="true"' in text
    return path


def test_the_saved_quadruped_is_refused_for_its_tendon_equalities_only(tmp_path, mujoco):
    path = saved_quadruped(mujoco, tmp_path)
    line = one_line_error(run("solve", str(path)))
    assert "tendon equality" in line and '<tendon name="coupling_front_left">' in line
    assert "free joint" not in line and 'name="root"' not in line


# --- the real files' rests, hung from their torso, judged by MuJoCo ----------------------------


@pytest.mark.parametrize(
    "parts, joints, flags",
    [
        # Off their floors (the judge leaves contacts out): the hung legs on their springs.
        (HALF_CHEETAH, ("rootx", "rootz", "rooty"), ("--no-contacts",)),
        (CHEETAH, ("rootx", "rootz", "rooty"), ("--no-contacts",)),
        (DOG, ("root",), ("--free-objects", "lock", "--no-contacts")),  # its ball locked
    ],
    ids=["half_cheetah", "cheetah", "dog"],
)
def test_hung_real_files_rest_as_mujoco_judges(tmp_path, mujoco, parts, joints, flags):
    # The torso held where the file places it (its root joints removed): the legs (and the
    # dog's tail on its springdamper springs) settle on their springs and stops.
    path = copy_of(model_file(*parts), tmp_path / "hung.xml", joints)
    done = gallery.run_cli(path, False, flags)
    assert done.code == 0 and done.answer is not None, done.stderr[-500:]
    verdict = gallery.judge_mjcf(path, done.answer, False)
    assert not verdict.falls and not verdict.problems, verdict.problems
    assert done.answer["residual"] <= gallery.REL_TOL * verdict.scale


def test_the_hung_half_cheetah_without_its_mass_scaling_is_not_mujocos_rest(tmp_path, mujoco):
    # The judge tells the masses apart: the rest of the unscaled masses is not a rest of the
    # file MuJoCo compiles (its legs' weight differs by 1 / 0.66 on the same springs).
    source = model_file(*HALF_CHEETAH)
    joints = ("rootx", "rootz", "rooty")
    hung = copy_of(source, tmp_path / "hung.xml", joints)

    def unscale(root: ET.Element) -> None:
        for el in root.iter("compiler"):
            el.attrib.pop("settotalmass", None)

    unscaled = copy_of(source, tmp_path / "unscaled.xml", joints, unscale)
    done = gallery.run_cli(unscaled, False)
    assert done.code == 0 and done.answer is not None, done.stderr[-500:]
    assert not gallery.judge_mjcf(unscaled, done.answer, False).problems
    assert any("not a rest" in p for p in gallery.judge_mjcf(hung, done.answer, False).problems)


# --- ellipsoids as contact shapes ---------------------------------------------------------------


@pytest.mark.parametrize(
    "semi_axes",
    [(0.048, 0.02, 0.06), (0.3, 0.27, 0.2), (0.2, 0.09, 0.11), (0.01, 0.01, 0.1), (1, 1, 1)],
)
def test_ellipsoid_spheres_lie_inside_it_within_the_tolerance(semi_axes):
    # Against the ellipsoid's exact support |A n| along 20000 random directions (not those the
    # points were chosen on): never beyond it, never more than the tolerance short of it.
    centres, radius, shortfall = ellipsoid_points(semi_axes)
    axes = np.asarray(semi_axes, float)
    rng = np.random.default_rng(3)
    n = rng.normal(size=(20000, 3))
    n /= np.linalg.norm(n, axis=1)[:, None]
    n = np.vstack([n, directions()])
    gap = np.linalg.norm(n * axes, axis=1) - ((n @ centres.T).max(axis=1) + radius)
    assert gap.min() >= -1e-12 * axes.max()
    assert gap.max() <= ELLIPSOID_TOL * axes.min() and shortfall <= ELLIPSOID_TOL * axes.min()
    assert radius == pytest.approx(axes.min() ** 2 / axes.max())
    assert len(centres) == 1 if len(set(semi_axes)) == 1 else len(centres) <= 1030


EGG = """<mujoco>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1"/>
    <body name="egg" pos="0 0 0.3" euler="{euler}">
      <freejoint name="egg_free"/>
      <geom name="egg" type="ellipsoid" size="0.08 0.05 0.12" mass="1"/>
    </body>
  </worldbody>
</mujoco>
"""


def mujoco_distance(mujoco, mj, data, geom: str, floor: str = "floor") -> float:
    return float(mujoco.mj_geomDistance(mj, data, mj.geom(geom).id, mj.geom(floor).id, 1.0, None))


@pytest.mark.parametrize("euler", ["40 -25 10", "10 80 0"])
def test_an_ellipsoid_rests_on_its_shortest_axis_as_in_mujoco(tmp_path, mujoco, euler):
    path = write(tmp_path, EGG.format(euler=euler))
    scene = pinsettle.Scene.from_mjcf(path)
    scene.add_collision_contacts()
    assert any("1 ellipsoid as" in n for n in scene.notes)
    result = pinsettle.solve(scene)
    assert_rests_on_the_floor(scene, result)
    assert result.stability == "stable"
    # On its shortest axis, 5 cm up, as the ellipsoid rests; on the spheres within the
    # tolerance of it (a face of three of them near the axis's end can hold it).
    q = result.q
    tolerance = ELLIPSOID_TOL * 0.05
    assert 0.05 - tolerance <= q[2] <= 0.05 + 1e-9
    axis = pinocchio.Quaternion(q[6], *q[3:6]).matrix()[:, 1]
    assert abs(axis[2]) >= np.cos(np.radians(5))
    # MuJoCo's own ellipsoid at that pose touches its floor, sunk in by at most the tolerance;
    # its damped settle is there too.
    mj = mj_compile(mujoco, path)
    data = mujoco.MjData(mj)
    data.qpos[:] = np.concatenate([q[:3], [q[6]], q[3:6]])
    mujoco.mj_forward(mj, data)
    assert -tolerance <= mujoco_distance(mujoco, mj, data, "egg") <= 1e-9
    mj.dof_damping[:] = 0.5
    data = mujoco.MjData(mj)
    while data.time < 6.0:
        mujoco.mj_step(mj, data)
    # (still rocking slowly about its long axis at 6 s: its height varies by micrometres)
    assert np.abs(data.qvel[:3]).max() < 1e-3 and abs(data.qpos[2] - 0.05) < 2e-3


def assert_ellipsoids_rest_as_mujoco_places_them(mujoco, path, result, names) -> None:
    """At the rest, MuJoCo's own distance from each named ellipsoid to the floor: it sinks in
    by at most the tolerance (the contact spheres inside it stay out), and one whose spheres
    carry a force touches."""
    mj = mj_compile(mujoco, path)
    data = mujoco.MjData(mj)
    joints = result.to_dict()["joints"]
    for j in range(mj.njnt):
        if mj.joint(j).name in joints:
            value = np.atleast_1d(joints[mj.joint(j).name])
            data.qpos[mj.jnt_qposadr[j] : mj.jnt_qposadr[j] + len(value)] = value
    mujoco.mj_forward(mj, data)
    touching = {c.name.split("#")[0] for c in result.contacts}
    for name in names:
        distance = mujoco_distance(mujoco, mj, data, name)
        tolerance = ELLIPSOID_TOL * mj.geom_size[mj.geom(name).id].min()
        assert distance >= -tolerance - 1e-6, (name, distance, tolerance)
        assert name not in touching or distance <= 1e-6, (name, distance)


def mujoco_springs(mujoco, path: Path) -> list[tuple[str, float, float]]:
    """The joint springs as MuJoCo compiles them (hinges and slides): the rest's check."""
    mj = mj_compile(mujoco, path)
    return [
        (mj.joint(j).name, float(mj.jnt_stiffness[j]), float(mj.qpos_spring[mj.jnt_qposadr[j]]))
        for j in range(mj.njnt)
        if mj.jnt_stiffness[j] and int(mj.jnt_type[j]) in (2, 3)
    ]


def test_humanoid_cmu_lies_on_its_floor_hands_and_all(mujoco):
    path = model_file(*HUMANOID_CMU)
    scene = pinsettle.Scene.from_mjcf(path)
    scene.add_collision_contacts()
    assert any("2 ellipsoids as" in n for n in scene.notes)
    result = pinsettle.solve(scene)
    assert_rests_on_the_floor(scene, result, mujoco_springs(mujoco, path))
    touching = {c.name.split("#")[0] for c in result.contacts}
    assert {"lhand", "rhand"} & touching, touching
    assert_ellipsoids_rest_as_mujoco_places_them(mujoco, path, result, ["lhand", "rhand"])


def test_the_saved_quadruped_lies_on_its_torso(tmp_path, mujoco):
    # Its tendon equalities disabled (the way forward its refusal gives), its ball taken out.
    def edit(root: ET.Element) -> None:
        option = ET.SubElement(root, "option")
        ET.SubElement(option, "flag", equality="disable")
        world = root.find("worldbody")
        assert world is not None
        world.remove(next(b for b in world.findall("body") if b.get("name") == "ball"))

    path = copy_of(saved_quadruped(mujoco, tmp_path), tmp_path / "quadruped.xml", edit=edit)
    scene = pinsettle.Scene.from_mjcf(path)
    scene.add_collision_contacts()
    assert any("free joint root (MuJoCo compiles a free joint unlimited)" in n for n in scene.notes)
    assert any("1 ellipsoid as" in n and "'torso'" in n for n in scene.notes)
    result = pinsettle.solve(scene)
    assert_rests_on_the_floor(scene, result, mujoco_springs(mujoco, path))
    assert "torso" in {c.name.split("#")[0] for c in result.contacts}
    assert_ellipsoids_rest_as_mujoco_places_them(mujoco, path, result, ["torso"])

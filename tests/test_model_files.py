"""Models as users have them (issue 16): a URDF or a MuJoCo MJCF file where a scene goes,
``[model] mjcf``, SRDF poses, and the errors of files that cannot be read.

The MJCF reader is checked against MuJoCo itself (the ``mujoco`` package of the test extra):

- every example-robot-data robot MuJoCo can load, written by MuJoCo from its URDF
  (``mj_saveLastXML``), rests where the URDF rests, to 1e-8 per joint;
- on MJCF files written here with MuJoCo's harder features (``<frame>``, euler sequences in
  degrees, several joints in a body, ``ref``, default classes, masses from geoms, a free
  body), the bodies' poses, the generalized gravity and the joint springs' forces of
  pinsettle's model equal MuJoCo's at random configurations, and the ranges equal MuJoCo's
  ``jnt_range``/``jnt_limited``;
- a rest with springs and ranges satisfies the conditions of a rest recomputed with the
  independent reference (tests/scene_reference.py, on an equivalent URDF written here) and with
  MuJoCo's own forces; a four-bar closed by a ``connect`` matches the closed form of
  tests/loop_reference.py.
"""

from __future__ import annotations

import ctypes
import json
import math
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import loop_reference
import numpy as np
import pinocchio
import pinsettle
import pytest
from conftest import mujoco_warnings
from scene_reference import Reference

ROBOTS = Path(__file__).resolve().parents[1] / "robots"

# Robots whose URDF MuJoCo 4.0 refuses to compile (its inertia checks are stricter than
# Pinocchio's: a rotational inertia that is not positive definite), with MuJoCo's reason.
MUJOCO_REFUSES = {
    "anymal": "inertia must have positive eigenvalues",
    "finger_edu": "inertia must have positive eigenvalues",
    "go1": "inertia must have positive eigenvalues",
}

SETTINGS = {"polish": True, "max_e": 1e-16}


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pinsettle", *args], capture_output=True, text=True, timeout=120
    )


def one_line_error(proc: subprocess.CompletedProcess) -> str:
    """The single line of error of a run that ended with exit 2."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pinsettle: error: "), proc.stderr
    return lines[0]


def wrap(angle: float) -> float:
    return math.remainder(angle, 2 * math.pi)


@pytest.fixture(scope="module")
def full_precision(mujoco):
    """MuJoCo writes 6 significant digits by default: a rounded quaternion turns a body by
    1e-6 rad. Its own tests write 17 through an exported function of libmujoco
    (``_mjPRIVATE__set_xml_precision``, see MuJoCo's src/xml/xml_numeric_format.h); so do
    these, and set 6 back afterwards."""
    libraries = sorted(Path(mujoco.__file__).parent.glob("libmujoco*"))
    assert libraries, f"no libmujoco next to {mujoco.__file__}"
    lib = ctypes.CDLL(str(libraries[0]))
    lib._mjPRIVATE__set_xml_precision(17)
    yield
    lib._mjPRIVATE__set_xml_precision(6)


def write_mjcf(mujoco, xml: str, path: Path) -> Path:
    """``xml`` (an MJCF or URDF text) compiled by MuJoCo and saved by it as MJCF; MuJoCo's
    compile warnings (a URDF joint's limits of 0 0, which MuJoCo ignores) kept off its log."""
    with mujoco_warnings(mujoco):
        model = mujoco.MjModel.from_xml_string(xml)
    mujoco.mj_saveLastXML(str(path), model)
    return path


def urdf_for_mujoco(name: str) -> str:
    """The robot's URDF without meshes (solving never loads them; MuJoCo would need them) and
    without <mimic> tags (pinsettle reads a URDF as Pinocchio does by default, each joint free;
    MuJoCo would make a mimic a joint equality). balanceinertia only evens out rotational
    inertias MuJoCo finds invalid (allegro_right_hand's): no effect on a rest."""
    root = ET.parse(pinsettle.robot_urdf(name)).getroot()
    for parent in root.iter():
        for child in list(parent):
            if child.tag in ("visual", "collision", "mimic"):
                parent.remove(child)
    ET.SubElement(ET.SubElement(root, "mujoco"), "compiler", balanceinertia="true")
    return ET.tostring(root, encoding="unicode")


# --- MJCF written by MuJoCo from the robots' URDFs ----------------------------------------------


@pytest.mark.parametrize("name", pinsettle.robot_names())
def test_mjcf_written_by_mujoco_rests_where_the_urdf_rests(name, tmp_path, mujoco, full_precision):
    try:
        path = write_mjcf(mujoco, urdf_for_mujoco(name), tmp_path / f"{name}.xml")
    except ValueError as error:
        assert name in MUJOCO_REFUSES, f"MuJoCo refuses {name}: {error}"
        assert MUJOCO_REFUSES[name] in str(error)
        return
    assert name not in MUJOCO_REFUSES, f"MuJoCo loads {name} now: test it"
    text = path.read_text()
    urdf = pinsettle.Scene(pinsettle.load_robot(name, floating=False))  # root fixed, as MuJoCo
    mjcf = pinsettle.load_scene(path)
    assert mjcf.mjcf == path and mjcf.urdf is None
    r_urdf = pinsettle.solve(urdf, **SETTINGS)
    r_mjcf = pinsettle.solve(mjcf, **SETTINGS)
    assert r_urdf.converged and r_mjcf.converged, (r_urdf.summary(), r_mjcf.summary())
    assert set(r_mjcf.joints) == set(r_urdf.joints)
    assert r_mjcf.at_limit == r_urdf.at_limit
    assert (r_mjcf.stability, r_mjcf.neutral_directions) == (
        r_urdf.stability,
        r_urdf.neutral_directions,
    )
    # The MJCF's rest, put into the URDF model, is a rest there: the residual of a rest against
    # stops recomputed with the reference (pinocchio's gravity, the stops from the URDF).
    urdf.set_start(r_mjcf.joints)
    reference = Reference(pinsettle.load_robot(name, floating=False))
    scale = max(1.0, float(np.max(np.abs(reference.force(urdf.q0())))))
    assert reference.rest_residual(urdf.q0()) < 1e-9 * scale
    # The same to 1e-8 on every joint the rest determines. With neutral directions (a UR's
    # base turning about the vertical, a hand's free finger) the rest is a set, and two runs
    # on models equal to round-off end at different points of it: the joints that move along
    # the zero-stiffness directions are left out, the others compared.
    determined = determined_joints(reference, r_urdf.q, r_urdf.at_limit)
    left_out = set(r_urdf.joints) - set(determined)
    assert len(left_out) >= r_urdf.neutral_directions  # k independent directions: >= k joints
    if r_urdf.neutral_directions == 0:
        assert not left_out
    for joint in determined:
        assert abs(wrap(r_mjcf.joints[joint] - r_urdf.joints[joint])) < 1e-8, joint
    # MuJoCo wrote what it fused: a URDF's fixed links become <frame>s (Pinocchio's parser
    # would drop the bodies inside them).
    if name in ("panda", "talos", "ur5"):
        assert "<frame" in text


def determined_joints(reference: Reference, q: np.ndarray, at_limit: dict) -> list[str]:
    """The joints a rest determines: those on a stop, and those with no part in the null space
    of the reference's finite-difference stiffness restricted to the joints off their stops
    (1-DoF joints: a fixed root)."""
    model = reference.full
    stiffness = reference.stiffness_reduced(model, q)
    stiffness = 0.5 * (stiffness + stiffness.T)
    names = [model.names[j] for j in range(1, model.njoints)]
    free = [model.idx_vs[model.getJointId(n)] for n in names if n not in at_limit]
    values, vectors = np.linalg.eigh(stiffness[np.ix_(free, free)])
    null = vectors[:, np.abs(values) <= 1e-7 * np.max(np.abs(values))]
    moving = {free[i] for i in range(len(free)) if np.abs(null[i]).max(initial=0.0) > 1e-6}
    return [n for n in names if model.idx_vs[model.getJointId(n)] not in moving]


def test_mujoco_refusals_are_still_refusals(mujoco):
    for name, reason in MUJOCO_REFUSES.items():
        with pytest.raises(ValueError, match=reason):
            mujoco.MjModel.from_xml_string(urdf_for_mujoco(name))


# --- MJCF files written here, against MuJoCo -------------------------------------------------

ARM = """
<mujoco model="arm">
  <compiler angle="degree" eulerseq="zYx"/>
  <option gravity="0.5 -1 -7"/>
  <default>
    <joint damping="0.1"/>
    <geom density="800"/>
    <default class="arm">
      <joint axis="0 1 0" stiffness="2" springref="15" range="-90 60"/>
      <geom type="capsule" size="0.04 0.2"/>
      <default class="visual">
        <geom contype="0" conaffinity="0" group="1" density="0" type="box" size="1 1 1"/>
      </default>
    </default>
  </default>
  <worldbody>
    <geom type="plane" size="1 1 0.1"/>
    <site name="world_site" pos="0.3 0.2 -0.4" euler="10 20 30"/>
    <frame pos="0.1 0 0.5" euler="0 0 30">
      <body name="base" pos="0 0.2 0" axisangle="1 1 0 40" childclass="arm">
        <inertial pos="0.01 0.02 -0.03" euler="5 6 7" mass="2" diaginertia="0.01 0.02 0.03"/>
        <joint name="a1" ref="20"/>
        <joint name="a2" type="slide" axis="1 0.2 0" pos="0.1 0 0" ref="0.05" range="-0.2 0.3"/>
        <joint name="a3" axis="0 0 1" pos="0 0.1 0" limited="false"/>
        <geom class="visual"/>
        <body name="link" pos="0 0 -0.4" xyaxes="0 1 0 -1 0 0.2">
          <joint name="b1" pos="0 0 0.1" ref="-30"/>
          <geom fromto="0 0 0 0.1 0.2 -0.3"/>
          <geom type="sphere" size="0.05" pos="0.1 0 0" mass="0.3"/>
          <frame zaxis="1 1 1" pos="0 0 -0.1">
            <site name="tip" pos="0.05 0 0" euler="0 90 0"/>
            <body name="hand" pos="0.02 0.03 0.04">
              <joint name="c1" class="main" type="ball" pos="0.01 0 0"/>
              <geom type="ellipsoid" size="0.03 0.04 0.05" euler="30 0 0"/>
              <geom type="box" size="0.02 0.03 0.01" pos="0 0.1 0" group="4"/>
              <geom type="cylinder" size="0.02 0.05" pos="0 -0.1 0" group="3"/>
              <geom type="box" size="0.02 0.03 0.01" pos="0 0.2 0" group="6"/>
            </body>
          </frame>
        </body>
      </body>
    </frame>
    <body name="other" pos="-0.5 0 0.3" quat="0.9 0.1 -0.2 0.3">
      <joint name="o1" axis="1 0 0" stiffness="1.5" springref="-10"/>
      <inertial pos="0 0 -0.2" mass="1.5" diaginertia="0.1 0.1 0.1"/>
    </body>
  </worldbody>
  <actuator><motor joint="a1" name="a1_motor"/></actuator>
</mujoco>
"""

FREE = """
<mujoco model="free">
  <compiler angle="radian"/>
  <worldbody>
    <frame pos="0 0 1" quat="0.9 0 0.3 0.1">
      <body name="torso" pos="0.1 0.2 0.5" quat="0.9 0.1 0 0.2">
        <freejoint name="root"/>
        <inertial pos="0 0 0" mass="5" diaginertia="0.1 0.1 0.1"/>
        <body name="arm" pos="0 0 -0.3" euler="0.1 0.2 0.3">
          <joint name="shoulder" axis="0 1 0" ref="0.3"/>
          <joint name="twist" axis="1 0 0" pos="0 0.05 0"/>
          <inertial pos="0 0 -0.2" mass="1" diaginertia="0.01 0.01 0.01"/>
        </body>
      </body>
    </frame>
  </worldbody>
</mujoco>
"""


def to_pinocchio_q(mj_model, qpos: np.ndarray) -> np.ndarray:
    """MuJoCo's qpos in Pinocchio's order of a configuration: quaternions w x y z -> x y z w."""
    out = []
    for j in range(mj_model.njnt):
        a = mj_model.jnt_qposadr[j]
        kind = mj_model.jnt_type[j]
        if kind == 0:  # free
            out += [*qpos[a : a + 3], *qpos[a + 4 : a + 7], qpos[a + 3]]
        elif kind == 1:  # ball
            out += [*qpos[a + 1 : a + 4], qpos[a]]
        else:
            out.append(qpos[a])
    return np.array(out)


def random_qpos(mj_model, rng) -> np.ndarray:
    qpos = mj_model.qpos0.copy()
    for j in range(mj_model.njnt):
        a = mj_model.jnt_qposadr[j]
        kind = mj_model.jnt_type[j]
        if kind in (0, 1):
            at = a + 3 if kind == 0 else a
            quat = rng.normal(size=4)
            qpos[at : at + 4] = quat / np.linalg.norm(quat)
            if kind == 0:
                qpos[a : a + 3] = rng.normal(size=3)
        else:
            qpos[a] = rng.uniform(-1.5, 1.5)
    return qpos


@pytest.mark.parametrize("xml", [ARM, FREE], ids=["arm", "free"])
def test_mjcf_model_is_mujocos(xml, tmp_path, mujoco):
    path = tmp_path / "model.xml"
    path.write_text(xml)
    scene = pinsettle.load_scene(path, contacts="none")  # the model alone (ARM has a floor)
    model = scene.model
    mj = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(mj)
    rng = np.random.default_rng(3)
    frames = {f.name: i for i, f in enumerate(model.frames) if f.type == pinocchio.FrameType.BODY}
    for trial in range(4):
        qpos = mj.qpos0.copy() if trial == 0 else random_qpos(mj, rng)
        data.qpos[:] = qpos
        data.qvel[:] = 0
        mujoco.mj_forward(mj, data)
        q = to_pinocchio_q(mj, qpos)
        pdata = model.createData()
        pinocchio.framesForwardKinematics(model, pdata, q)
        for body in range(1, mj.nbody):
            name = mujoco.mj_id2name(mj, mujoco.mjtObj.mjOBJ_BODY, body)
            placement = pdata.oMf[frames[name]]
            assert np.abs(placement.translation - data.xpos[body]).max() < 1e-12, name
            assert np.abs(placement.rotation - data.xmat[body].reshape(3, 3)).max() < 1e-12
        if xml is ARM:  # a fixed root: velocity coordinates are MuJoCo's
            # At rest MuJoCo's bias force is the generalized gravity; the static force of the
            # scene is that minus the joint springs' passive force.
            expected = data.qfrc_bias - data.qfrc_spring
            assert np.abs(scene.static_force(q) - expected).max() < 1e-12
    assert pinocchio.computeTotalMass(model) == pytest.approx(float(np.sum(mj.body_mass)), 1e-14)
    # Depth-first joint order, as pinsettle requires (a joint's subtree right after it): the
    # two-joint body and the branches come out in MuJoCo's order.
    for j in range(1, model.njoints):
        subtree = list(model.subtrees[j])
        assert subtree == list(range(j, j + len(subtree))), model.names[j]
    names = [mujoco.mj_id2name(mj, mujoco.mjtObj.mjOBJ_JOINT, k) for k in range(mj.njnt)]
    assert list(model.names)[1:] == names
    # The start is MuJoCo's qpos0: the refs, and the free body where the file puts it.
    assert np.abs(scene.q0() - to_pinocchio_q(mj, mj.qpos0)).max() < 1e-15
    assert np.abs(model.gravity.linear - mj.opt.gravity).max() == 0


def test_mjcf_ranges_are_mujocos(tmp_path, mujoco):
    # limited, autolimits and angle units as MuJoCo decides them, against its compiled model.
    variants = [
        ('<compiler angle="degree"/>', 'range="-30 45"', True),
        ('<compiler angle="radian"/>', 'range="-0.5 0.7"', True),
        ("", 'range="-30 45" limited="false"', False),
        ("", 'range="-30 45" limited="true"', True),
        ('<compiler autolimits="false"/>', 'range="-30 45" limited="true"', True),
        ('<compiler autolimits="false"/>', 'range="-30 45" limited="false"', False),
        ("", "", False),
    ]
    for compiler, joint, limited in variants:
        for kind in ("hinge", "slide"):
            xml = f"""<mujoco>{compiler}<worldbody><body name="b"><joint name="j" type="{kind}"
                {joint}/><geom size="0.1"/></body></worldbody></mujoco>"""
            path = tmp_path / "range.xml"
            path.write_text(xml)
            mj = mujoco.MjModel.from_xml_path(str(path))
            model = pinsettle.load_scene(path).model
            assert bool(mj.jnt_limited[0]) == limited, (compiler, joint)
            expected = mj.jnt_range[0] if limited else [-math.inf, math.inf]
            got = [model.lowerPositionLimit[0], model.upperPositionLimit[0]]
            assert got == pytest.approx(list(expected), rel=1e-15), (compiler, joint, kind)


# --- a rest with springs and ranges, against the reference and MuJoCo --------------------------

# A slider on a spring carrying a planar 3-link arm (hinges about y, x-z plane): springs on the
# slider and the first two hinges, a range on each; the third link hangs onto its upper stop.
LINKS = [("j1", 0.5, 1.0), ("j2", 0.4, 0.8), ("j3", 0.3, 0.5)]  # joint, length (m), mass (kg)
SPRINGS = {"slide": (200.0, 0.1), "j1": (30.0, 20.0), "j2": (4.0, -10.0)}  # k, rest (m, deg)
RANGES = {"slide": (-0.5, 0.5), "j1": None, "j2": (-90.0, 90.0), "j3": (-45.0, 30.0)}


def spring_arm_mjcf() -> str:
    def body(k: int) -> str:
        if k == len(LINKS):
            return ""
        joint, length, mass = LINKS[k]
        at = LINKS[k - 1][1] if k else 0.0
        attrs = f'name="{joint}"'
        if joint in SPRINGS:
            attrs += f' stiffness="{SPRINGS[joint][0]}" springref="{SPRINGS[joint][1]}"'
        if RANGES[joint]:
            attrs += f' range="{RANGES[joint][0]} {RANGES[joint][1]}"'
        return f"""<body name="link{k + 1}" pos="{at} 0 0"><joint class="hinge" {attrs}/>
            <inertial pos="{length / 2} 0 0" mass="{mass}" diaginertia="0.01 0.01 0.01"/>
            {body(k + 1)}</body>"""

    k, rest = SPRINGS["slide"]
    low, high = RANGES["slide"]
    return f"""<mujoco model="spring_arm">
      <default><default class="hinge"><joint type="hinge" axis="0 1 0"/></default></default>
      <worldbody><body name="carriage"><joint name="slide" type="slide" axis="0 0 1"
        stiffness="{k}" springref="{rest}" range="{low} {high}"/>
        <inertial pos="0 0 0" mass="0.7" diaginertia="0.01 0.01 0.01"/>{body(0)}
      </body></worldbody></mujoco>"""


def spring_arm_urdf() -> str:
    """The same mechanism as a URDF, for the reference (ranges in radians; no range: 1e10)."""

    def limit(joint: str, scale: float) -> str:
        low, high = RANGES[joint] or (-1e10, 1e10)
        low, high = (low * scale, high * scale) if RANGES[joint] else (low, high)
        return f'<limit lower="{low!r}" upper="{high!r}" effort="1" velocity="1"/>'

    def inertial(mass: float, x: float) -> str:
        return (
            f'<inertial><origin xyz="{x} 0 0"/><mass value="{mass}"/><inertia ixx="0.01" '
            'ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>'
        )

    parts = [
        '<robot name="spring_arm"><link name="world"/>',
        f'<link name="carriage">{inertial(0.7, 0.0)}</link>',
        '<joint name="slide" type="prismatic"><parent link="world"/><child link="carriage"/>'
        f'<axis xyz="0 0 1"/>{limit("slide", 1.0)}</joint>',
    ]
    parent, at = "carriage", 0.0
    for k, (joint, length, mass) in enumerate(LINKS):
        parts.append(f'<link name="link{k + 1}">{inertial(mass, length / 2)}</link>')
        parts.append(
            f'<joint name="{joint}" type="revolute"><parent link="{parent}"/><child '
            f'link="link{k + 1}"/><origin xyz="{at} 0 0"/><axis xyz="0 1 0"/>'
            f"{limit(joint, math.pi / 180)}</joint>"
        )
        parent, at = f"link{k + 1}", length
    return "".join(parts) + "</robot>"


def test_springs_and_ranges_against_the_reference_and_mujoco(tmp_path, mujoco):
    path = tmp_path / "spring_arm.xml"
    path.write_text(spring_arm_mjcf())
    scene = pinsettle.load_scene(path)
    result = pinsettle.solve(scene, **SETTINGS)
    assert result.converged, result.summary()
    # The independent reference on an equivalent URDF: the springs in radians, written here.
    urdf = tmp_path / "spring_arm.urdf"
    urdf.write_text(spring_arm_urdf())
    reference = Reference(pinocchio.buildModelFromUrdf(str(urdf)))
    for joint, (k, rest) in SPRINGS.items():
        reference.joint_springs.append((joint, k, rest if joint == "slide" else math.radians(rest)))
    q = result.q  # same joints in the same order: the configurations are the same vectors
    assert reference.rest_residual(q) < 1e-9
    contacts = reference.contacts(q)
    assert {joint: side for joint, (side, _) in contacts.items()} == result.at_limit
    assert result.at_limit == {"j3": "upper"}  # the last link hangs on its upper stop
    assert result.joints["j3"] == pytest.approx(math.radians(30.0), abs=1e-15)
    assert result.limit_reactions["j3"] == pytest.approx(contacts["j3"][1], rel=1e-9)
    # Stable on the joints off their stops: the reference's finite-difference stiffness.
    assert result.stability == "stable"
    stiffness = reference.stiffness_reduced(reference.full, q)[:3, :3]
    assert np.linalg.eigvalsh(0.5 * (stiffness + stiffness.T)).min() > 0
    # MuJoCo's own forces at the rest: gravity (bias at rest) minus its spring forces vanish
    # off the stops and push the last link onto its upper stop.
    mj = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(mj)
    data.qpos[:] = q
    mujoco.mj_forward(mj, data)
    net = data.qfrc_bias - data.qfrc_spring
    assert np.abs(net[:3]).max() < 1e-9
    assert net[3] < 0  # into the upper stop
    assert q[3] == pytest.approx(mj.jnt_range[3][1], abs=1e-15)
    # The closed form of the slider: its spring carries the whole weight.
    weight = float(np.sum(mj.body_mass)) * 9.81
    k, rest = SPRINGS["slide"]
    assert result.joints["slide"] == pytest.approx(rest - weight / k, abs=1e-12)


def test_springs_and_gravity_option(tmp_path):
    def slider(option: str) -> Path:
        path = tmp_path / "slider.xml"
        path.write_text(
            f"""<mujoco>{option}<worldbody><body name="b"><joint name="s" type="slide"
            axis="0 0 1" stiffness="50" springref="0.2"/><inertial pos="0 0 0" mass="2"
            diaginertia="1 1 1"/></body></worldbody></mujoco>"""
        )
        return path

    for option, g in [
        ("", 9.81),
        ('<option gravity="0 0 -3"/>', 3.0),
        ('<option gravity="0 0 -3"><flag gravity="disable"/></option>', 0.0),
    ]:
        scene = pinsettle.load_scene(slider(option))
        assert scene.gravity == pytest.approx([0.0, 0.0, -g])
        result = pinsettle.solve(scene, **SETTINGS)
        assert result.joints["s"] == pytest.approx(0.2 - 2 * g / 50, abs=1e-13), option
    scene = pinsettle.load_scene(slider('<option><flag spring="disable"/></option>'))
    assert not scene.joint_springs and "springs" in " ".join(scene.notes)
    # A scene's [model] gravity wins over the file's.
    toml = tmp_path / "scene.toml"
    slider('<option gravity="0 0 -3"/>')
    toml.write_text('[model]\nmjcf = "slider.xml"\ngravity = [0.0, 0.0, -1.0]\n')
    result = pinsettle.solve(pinsettle.load_scene(toml), **SETTINGS)
    assert result.joints["s"] == pytest.approx(0.2 - 2 * 1.0 / 50, abs=1e-13)


# --- a four-bar closed by a connect, against the closed form ---------------------------------


def fourbar_mjcf(t: float, form: str) -> str:
    """robots/fourbar (crank 0.15 m / 0.5 kg, coupler 0.4 m / 1 kg, rocker 0.3 m / 0.8 kg,
    pivots 0.4 m apart, hinges about y) drawn assembled at crank angle t, the joints' ref
    saying their angles there (degrees, MuJoCo's default); the crank spring of
    robots/fourbar.toml (4 N m/rad, rest -1.2 rad) as stiffness and springref; the loop as a
    connect by bodies (the point on the rocker taken where the anchor is at qpos0) or by two
    sites."""
    joints = loop_reference.fourbar().joints(t)
    deg = {name: math.degrees(value) for name, value in joints.items()}
    if form == "bodies":
        loop = '<connect body1="coupler" body2="rocker" anchor="0.4 0 0"/>'
    else:
        loop = '<connect site1="coupler_end" site2="rocker_end"/>'

    def rod(length: float, mass: float) -> str:
        return (
            f'<inertial pos="{length / 2} 0 0" mass="{mass}" '
            f'diaginertia="{mass * length**2 / 12} {mass * length**2 / 12} 1e-5"/>'
        )

    return f"""<mujoco model="fourbar">
      <default><joint axis="0 1 0"/></default>
      <worldbody>
        <body name="crank" axisangle="0 1 0 {deg["crank_joint"]!r}">
          <joint name="crank_joint" ref="{deg["crank_joint"]!r}" stiffness="4"
            springref="{math.degrees(-1.2)!r}"/>{rod(0.15, 0.5)}
          <body name="coupler" pos="0.15 0 0" axisangle="0 1 0 {deg["coupler_joint"]!r}">
            <joint name="coupler_joint" ref="{deg["coupler_joint"]!r}"/>{rod(0.4, 1.0)}
            <site name="coupler_end" pos="0.4 0 0"/>
          </body>
        </body>
        <body name="rocker" pos="0.4 0 0" axisangle="0 1 0 {deg["rocker_joint"]!r}">
          <joint name="rocker_joint" ref="{deg["rocker_joint"]!r}"/>{rod(0.3, 0.8)}
          <site name="rocker_end" pos="0.3 0 0"/>
        </body>
      </worldbody>
      <equality>{loop}</equality>
    </mujoco>"""


@pytest.mark.parametrize("form", ["bodies", "sites"])
def test_connect_loop_matches_the_closed_form(form, tmp_path):
    (tmp_path / "fourbar.xml").write_text(fourbar_mjcf(-1.4, form))
    # The 10 N load of robots/fourbar.toml from a scene file around the MJCF.
    (tmp_path / "fourbar.toml").write_text(
        textwrap.dedent(
            """\
            # the four-bar of an MJCF file with a load
            [model]
            mjcf = "fourbar.xml"
            [[load]]
            frame = "coupler"
            point = [0.2, 0.0, 0.0]
            force = [0.0, 0.0, -10.0]
            """
        )
    )
    scene = pinsettle.load_scene(tmp_path / "fourbar.toml")
    assert len(scene.loops) == 1 and scene.loops[0].kind == "point"
    if form == "bodies":  # drawn assembled: the start (qpos0) closes the loop already
        assert np.abs(scene.loop_error(scene.q0())).max() < 1e-12
    result = pinsettle.solve(scene, **SETTINGS)
    assert result.converged and result.mobility == 1, result.summary()
    assert result.constraint_error < 1e-10
    mechanism = loop_reference.fourbar()
    expected = mechanism.equilibrium(result.joints["crank_joint"], 0.1)
    assert expected.pop("stable") is True and result.stability == "stable"
    for joint, value in expected.items():
        assert result.joints[joint] == pytest.approx(value, abs=1e-8), joint


def test_weld_by_bodies_holds_the_pose_of_qpos0(tmp_path):
    # A pendulum welded to the world where the file draws it does not move, whatever gravity.
    path = tmp_path / "weld.xml"
    path.write_text(
        """<mujoco><compiler angle="radian"/><worldbody>
        <body name="arm" pos="0 0 1"><joint name="hinge" axis="0 1 0" ref="0.7"/>
          <inertial pos="0.5 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
          <body name="tip" pos="1 0 0"><joint name="wrist" axis="0 1 0"/>
            <inertial pos="0.2 0 0" mass="1" diaginertia="0.01 0.01 0.01"/></body>
        </body></worldbody>
        <equality><weld body1="tip" anchor="0.1 0 0"/></equality></mujoco>"""
    )
    scene = pinsettle.Scene.from_mjcf(path)
    assert [loop.kind for loop in scene.loops] == ["frame"]
    assert np.abs(scene.loop_error(scene.q0())).max() < 1e-12
    assert scene.mobility() == 0  # the weld leaves the two hinges nothing: a structure
    assert "<equality>: the loops leave the mechanism no degree of freedom" in one_line_error(
        run("solve", str(path))
    )
    # With torquescale 0 the weld is a connect at the anchor: it holds the tip's anchor where
    # qpos0 puts it and leaves the tip its rotation. With a ball wrist: hinge 1 + ball 3 - 3.
    text = path.read_text().replace('anchor="0.1 0 0"', 'anchor="0.1 0 0" torquescale="0"')
    path.write_text(text.replace('name="wrist" axis="0 1 0"', 'name="wrist" type="ball"'))
    scene = pinsettle.load_scene(path)
    assert [loop.kind for loop in scene.loops] == ["point"] and scene.mobility() == 1
    assert np.abs(scene.loop_error(scene.q0())).max() < 1e-12


# --- what MJCF says that is noted, refused, or an error --------------------------------------


def test_mjcf_notes_what_has_no_force_at_rest(tmp_path):
    path = tmp_path / "arm.xml"
    path.write_text(ARM)
    # Its floor left out (its hand is an ellipsoid, which contacts cannot be taken from).
    scene = pinsettle.load_scene(path, contacts="none")
    notes = " | ".join(scene.notes)
    assert "damping" in notes and "a1" in notes and "1 actuator (a1_motor)" in notes
    proc = run("solve", str(path), "--json", "--no-contacts")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["notes"] == scene.notes
    proc = run("solve", str(path), "--no-contacts")
    assert proc.returncode == 0 and "note             ignored: 1 actuator" in proc.stdout


REFUSED = [
    (
        "<tendon><fixed name='t' stiffness='3'><joint joint='j' coef='1'/></fixed></tendon>",
        "",
        ['<fixed name="t">', "tendon spring"],
    ),
    (
        "<tendon><fixed name='t' range='0 1'><joint joint='j' coef='1'/></fixed></tendon>",
        "",
        ["tendon limit"],
    ),
    ("<equality><joint joint1='j' joint2='k'/></equality>", "", ["<joint>", "joint equality"]),
    ("", " gravcomp='1'", ["gravcomp", "gravity compensation"]),
    ("<option density='1.2'/>", "", ["<option density>", "buoyancy"]),
]


@pytest.mark.parametrize("section, body_attrs, fragments", REFUSED)
def test_mjcf_refuses_what_it_cannot_honour(section, body_attrs, fragments, tmp_path):
    path = tmp_path / "refused.xml"
    path.write_text(
        f"""<mujoco>{section}<worldbody><body name="b"{body_attrs}><joint name="j"/>
        <geom size="0.1"/><body name="c"><joint name="k"/><geom size="0.1"/></body>
        </body></worldbody></mujoco>"""
    )
    with pytest.raises(pinsettle.SceneError) as error:
        pinsettle.load_scene(path)
    message = str(error.value)
    assert message.startswith(f"{path}: cannot be honoured in statics: ")
    for fragment in fragments:
        assert fragment in message, message
    line = one_line_error(run("solve", str(path)))
    assert fragments[0] in line


@pytest.mark.parametrize(
    "joint, fragments",
    [
        ('type="ball" range="0 30"', ["ball joint", "cone limit"]),
        ('type="ball" stiffness="2"', ["stiffness", "ball joint"]),
        ('stiffness="2 1"', ["polynomial spring"]),
        ('type="ball" springdamper="0.1 1"', ["springdamper", "ball joint"]),
    ],
)
def test_mjcf_refuses_joint_statics_it_cannot_honour(joint, fragments, tmp_path):
    path = tmp_path / "joint.xml"
    path.write_text(
        f'<mujoco><worldbody><body name="b"><joint name="j" {joint}/><geom size="0.1"/>'
        "</body></worldbody></mujoco>"
    )
    with pytest.raises(pinsettle.SceneError) as error:
        pinsettle.load_scene(path)
    for fragment in ['<joint name="j"', *fragments]:
        assert fragment in str(error.value), str(error.value)


def test_mjcf_mass_from_a_mesh_is_refused(tmp_path):
    (tmp_path / "part.stl").write_bytes(b"solid part\nendsolid part\n")
    path = tmp_path / "mesh.xml"
    body = '<body name="b"><joint name="j"/><geom name="shell" type="mesh" mesh="part"/></body>'
    path.write_text(
        f'<mujoco><asset><mesh name="part" file="part.stl"/></asset><worldbody>{body}'
        "</worldbody></mujoco>"
    )
    with pytest.raises(pinsettle.SceneError, match=r"<geom name=\"shell\"> of body 'b'.*mesh"):
        pinsettle.load_scene(path)
    # With an <inertial> the mesh is only drawn: fine.
    path.write_text(
        path.read_text().replace(
            '<joint name="j"/>',
            '<joint name="j"/><inertial pos="0 0 -1" mass="1" diaginertia="1 1 1"/>',
        )
    )
    assert pinsettle.load_scene(path).model.nv == 1


def test_mjcf_missing_include_and_assets_are_named(tmp_path):
    path = tmp_path / "scene.xml"
    path.write_text(
        """<mujoco><include file="robot/arm.xml"/><include file="robot/gone.xml"/>
        <worldbody><body name="b"><joint name="j"/><geom size="0.1"/></body></worldbody>
        </mujoco>"""
    )
    (tmp_path / "robot").mkdir()
    (tmp_path / "robot" / "arm.xml").write_text(
        """<mujoco><compiler meshdir="meshes"/><asset><mesh name="m" file="link.stl"/>
        <texture name="t" type="2d" file="skin.png"/></asset></mujoco>"""
    )
    message = one_line_error(run("solve", str(path)))
    assert "included file not found: robot/gone.xml" in message
    path.write_text(path.read_text().replace('<include file="robot/gone.xml"/>', ""))
    message = one_line_error(run("solve", str(path)))
    assert "asset files not found" in message
    assert (
        "mesh <mesh name=\"m\"> file 'link.stl'" in message and str(tmp_path / "meshes") in message
    )
    assert "'skin.png'" in message


def test_mjcf_include_is_read(tmp_path):
    # MuJoCo Menagerie's layout: scene.xml includes the robot (paths from the main file).
    (tmp_path / "robot").mkdir()
    (tmp_path / "robot" / "arm.xml").write_text(
        """<mujoco model="arm"><worldbody><body name="b" pos="0 0 1"><joint name="j"
        axis="0 1 0"/><inertial pos="0.5 0 0" mass="1" diaginertia="1 1 1"/></body>
        </worldbody></mujoco>"""
    )
    path = tmp_path / "scene.xml"
    path.write_text(
        '<mujoco model="scene"><include file="robot/arm.xml"/><worldbody><geom '
        'type="plane" size="1 1 1"/></worldbody></mujoco>'
    )
    result = pinsettle.solve(pinsettle.load_scene(path), **SETTINGS)
    assert result.converged and abs(wrap(result.joints["j"] - math.pi / 2)) < 1e-8


def test_mjcf_floating(tmp_path):
    path = tmp_path / "free.xml"
    path.write_text(FREE)
    scene = pinsettle.load_scene(path)
    assert scene.model.joints[1].shortname() == "JointModelFreeFlyer"
    assert scene.model.names[1] == "root"
    two = tmp_path / "two.xml"
    two.write_text(ARM)
    line = one_line_error(run("solve", str(two), "--floating"))
    assert "2 top-level bodies (base, other)" in line
    hinge = tmp_path / "hinge.xml"
    hinge.write_text(
        '<mujoco><worldbody><body name="b"><joint name="j"/><geom size="0.1"/></body>'
        "</worldbody></mujoco>"
    )
    assert "attached by joint 'j' already" in one_line_error(run("solve", str(hinge), "--floating"))
    fixed = tmp_path / "fixed.xml"
    fixed.write_text(
        '<mujoco><worldbody><body name="b" pos="0 0 2"><geom size="0.1"/><body name="c">'
        '<joint name="j"/><geom size="0.1"/></body></body></worldbody></mujoco>'
    )
    scene = pinsettle.load_scene(fixed, floating=True)
    assert scene.model.names[1] == "root_joint" and scene.model.nq == 8
    # Starts where the file puts the body.
    assert scene.start["root_joint"][:3].tolist() == [0.0, 0.0, 2.0]
    proc = run("solve", str(fixed), "--floating", "--max-steps", "1", "--json")
    assert len(json.loads(proc.stdout)["joints"]["root_joint"]) == 7


def test_mjcf_bad_values_are_named(tmp_path):
    for joint, fragment in [
        ('range="1 abc"', "range: expected numbers, got '1 abc'"),
        ('range="1"', "range: expected 2 numbers, got 1"),
        ('range="30 -30"', "range: lower 30 must be below upper -30"),
        ('limited="true"', 'limited="true" without a range'),
        ('type="cardan"', "type: expected one of hinge, slide, ball, free, got 'cardan'"),
        ('axis="0 0 0"', "axis: zero-length axis"),
        ('stiffness="-1"', "stiffness: must be >= 0"),
    ]:
        path = tmp_path / "bad.xml"
        path.write_text(
            f'<mujoco><worldbody><body name="b"><joint name="j" {joint}/><geom size="0.1"/>'
            "</body></worldbody></mujoco>"
        )
        with pytest.raises(pinsettle.SceneError) as error:
            pinsettle.load_scene(path)
        assert fragment in str(error.value) and '<joint name="j">' in str(error.value)


# --- any model file where a scene goes --------------------------------------------------------


def test_urdf_file_where_a_scene_goes(tmp_path):
    urdf = ROBOTS / "pendulum.urdf"
    scene = pinsettle.load_scene(urdf)
    assert scene.urdf == urdf and scene.model.nq == 1 and scene.limits
    proc = run("solve", str(urdf), "--start", "hinge=1.0", "--json", "--polish")
    out = json.loads(proc.stdout)
    assert proc.returncode == 0 and out["converged"] and out["notes"] == []
    assert abs(out["joints"]["hinge"]) < 1e-10
    # The same model read by Pinocchio directly: its gravity vanishes at the answer.
    model = pinocchio.buildModelFromUrdf(str(urdf))
    assert (
        np.abs(
            pinocchio.computeGeneralizedGravity(model, model.createData(), np.array(out["q"]))
        ).max()
        < 1e-9
    )
    # The suffix does not decide: a URDF named .xml is a URDF.
    copy = tmp_path / "pendulum.xml"
    copy.write_text(urdf.read_text())
    assert pinsettle.load_scene(copy).urdf == copy
    floating = pinsettle.load_scene(urdf, floating=True)
    assert floating.model.nq == 8
    with pytest.raises(pinsettle.SceneError, match="floating applies to a model file"):
        pinsettle.load_scene(ROBOTS / "pendulum.toml", floating=True)


def test_load_scene_takes_a_library_name():
    scene = pinsettle.load_scene("pendulum")
    assert scene.path == pinsettle.scene_path("pendulum") and scene.name == "pendulum"
    with pytest.raises(FileNotFoundError, match="no such scene in the library"):
        pinsettle.load_scene("no_such_scene")


def test_neither_urdf_nor_mjcf_names_each_parser(tmp_path):
    cases = {
        "notes.txt": ("hello: world\n", ["scene (TOML)", "URDF (urdfdom)", "as MJCF: not well"]),
        "arm.urdf": ("not xml at all\n", ["URDF (urdfdom)", "as MJCF: not well-formed XML"]),
        "thing.xml": (
            "<thing/>",
            ["Could not find the 'robot' element", "as MJCF: the root element is <thing>"],
        ),
    }
    for name, (text, fragments) in cases.items():
        path = tmp_path / name
        path.write_text(text)
        line = one_line_error(run("solve", str(path)))
        assert "neither a scene, a URDF nor an MJCF file" in line
        for fragment in fragments:
            assert fragment in line, line
    assert "scene (TOML)" not in one_line_error(run("solve", str(tmp_path / "thing.xml")))
    # A file that opens as MJCF or URDF but is not well-formed: that reader's reason only.
    broken = tmp_path / "broken.xml"
    broken.write_text("<!-- a robot -->\n<mujoco model='m'>\n  <worldbody>\n</mujoco>\n")
    line = one_line_error(run("solve", str(broken)))
    assert f"{broken}: not well-formed XML: mismatched tag: line 4" in line
    broken.write_text("<robot name='r'>\n  <link name='a'>\n</robot>\n")
    assert "the URDF does not parse" in one_line_error(run("solve", str(broken)))


# --- SRDF poses ---------------------------------------------------------------------------


def srdf_pose(path: Path, pose: str) -> dict[str, list[float]]:
    root = ET.parse(path).getroot()
    for state in root.iter("group_state"):
        if state.get("name") == pose:
            return {j.get("name"): [float(x) for x in j.get("value").split()] for j in state}
    raise KeyError(pose)


def test_talos_starts_half_sitting(tmp_path):
    toml = tmp_path / "talos.toml"
    toml.write_text('# Talos\n[model]\nrobot = "talos"\n[start]\npose = "half_sitting"\n')
    scene = pinsettle.load_scene(toml)
    srdf = pinsettle.robots.robots_dir() / "talos_data" / "srdf" / "talos.srdf"
    assert scene.srdf == [srdf]
    expected = srdf_pose(srdf, "half_sitting")
    start = scene.joint_values(scene.q0())
    assert "root_joint" in expected and "root_joint" not in start  # the root is fixed here
    for joint, values in expected.items():
        if joint != "root_joint":
            assert start[joint] == pytest.approx(values[0], abs=1e-15), joint
    assert any("root_joint" in note for note in scene.notes)
    assert any(abs(v) > 0.1 for v in start.values())  # a bent pose, not neutral
    result = pinsettle.solve(scene, **SETTINGS)
    assert result.converged
    reference = Reference(pinsettle.load_robot("talos", floating=False))
    assert reference.rest_residual(result.q) < 1e-8
    # Floating, the free-flyer takes the SRDF's root pose too.
    toml.write_text(toml.read_text().replace("[start]", "floating = true\n[start]"))
    scene = pinsettle.load_scene(toml)
    x, y, z, qx, qy, qz, qw = expected["root_joint"]  # the SRDF holds Pinocchio's q, w last
    assert scene.joint_values(scene.q0())["root_joint"] == pytest.approx(
        [x, y, z, qw, qx, qy, qz], abs=1e-15
    )
    # And through the CLI, with an override on top of the pose.
    proc = run("solve", str(toml), "--start", "arm_left_4_joint=-1.0", "--max-steps", "1")
    assert proc.returncode == 1, proc.stderr


def test_srdf_errors(tmp_path):
    (tmp_path / "pendulum.urdf").write_text((ROBOTS / "pendulum.urdf").read_text())

    def scene(srdf: str, pose: str = "up") -> Path:
        (tmp_path / "p.srdf").write_text(f'<robot name="p">{srdf}</robot>')
        toml = tmp_path / "s.toml"
        toml.write_text(
            f'[model]\nurdf = "pendulum.urdf"\nsrdf = "p.srdf"\n[start]\npose = "{pose}"\n'
        )
        return toml

    good = (
        '<group_state name="up" group="g"><joint name="hinge" value="3.0"/></group_state>'
        '<group_state name="side" group="g"><joint name="hinge" value="1.5"/></group_state>'
        '<disable_collisions link1="arm" link2="base" reason="Adjacent"/>'
    )
    assert pinsettle.load_scene(scene(good)).start["hinge"] == pytest.approx(3.0)
    cases = [
        (good, "down", ["[start] pose", "unknown pose 'down'", "poses: side, up"]),
        (
            '<group_state name="up" group="g"><joint name="elbow" value="1"/></group_state>',
            "up",
            ["names joint the model does not have: elbow", "does not match the model"],
        ),
        (
            '<group_state name="up" group="g"><joint name="hinge" value="abc"/></group_state>',
            "up",
            ["pose 'up', joint 'hinge'", "value must be numbers, got 'abc'"],
        ),
        (
            '<group_state name="up" group="g"><joint name="hinge" value="1 2"/></group_state>',
            "up",
            ["2 values for a joint", "takes 1"],
        ),
    ]
    for srdf, pose, fragments in cases:
        path = scene(srdf, pose)
        with pytest.raises(pinsettle.SceneError) as error:
            pinsettle.load_scene(path)
        for fragment in fragments:
            assert fragment in str(error.value), str(error.value)
        assert fragments[-1] in one_line_error(run("solve", str(path)))
    toml = tmp_path / "s.toml"
    toml.write_text('[model]\nurdf = "pendulum.urdf"\nsrdf = "gone.srdf"\n')
    assert "SRDF file not found" in one_line_error(run("solve", str(toml)))
    toml.write_text('[model]\nurdf = "pendulum.urdf"\n[start]\npose = "home"\n')
    assert "the model has no named poses" in one_line_error(run("solve", str(toml)))
    # From Python, a path that is no path is named as such.
    pendulum = pinsettle.Scene.from_urdf(tmp_path / "pendulum.urdf")
    with pytest.raises(TypeError, match="path must be an SRDF file's path .*got None"):
        pendulum.load_srdf(None)


def test_mjcf_keyframes_are_poses(tmp_path):
    path = tmp_path / "free.xml"
    path.write_text(
        FREE.replace(
            "</worldbody>",
            '</worldbody><keyframe><key name="home" qpos="1 2 3 0 1 0 0 0.4 -0.2"/></keyframe>',
        )
    )
    scene = pinsettle.load_scene(path)
    assert scene.poses == ["home", "qpos0"]
    scene.set_pose("home")
    values = scene.joint_values(scene.q0())
    assert values["root"] == pytest.approx([1, 2, 3, 0, 1, 0, 0])  # by name: MuJoCo's qpos
    assert values["shoulder"] == pytest.approx(0.4) and values["twist"] == pytest.approx(-0.2)

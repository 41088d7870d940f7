"""User-facing conventions and URDF reading (issue 40, items 5 and 6).

- A joint's value by name (``--start``, a scene's ``[start]``, ``Scene.set_start``, ``set_pose``,
  ``Result.joints``, the JSON's ``joints``) writes a quaternion w first, as MuJoCo's qpos: a
  free joint x, y, z, qw, qx, qy, qz, a ball joint qw, qx, qy, qz. Checked against MuJoCo's own
  body placements (``mj_kinematics``) and against the closed-form rotation of a quaternion;
  Pinocchio's ``q`` (``Result.q``, the JSON's ``q``) keeps w last.
- A command-line user reads errors about a joint's value by the key typed, never Pinocchio's
  configuration indices.
- A URDF with whitespace or a comment before its XML declaration is read; an error about a
  URDF names the real fault, in one short line that says what to do.

MuJoCo is needed by the placements' checks (the ``test`` extra installs it): they skip without
it unless PINSETTLE_REQUIRE_MUJOCO is set, which turns its absence into a failure.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest
from pinsettle import __main__ as cli
from test_model_files import one_line_error, run  # the CLI's runner and its error line

ROBOTS = Path(__file__).resolve().parents[1] / "robots"


def required(module: str, switch: str):
    """The module, or a skip naming it; with the environment switch set, a failure."""
    if os.environ.get(switch):
        return __import__(module)
    return pytest.importorskip(module, reason=f"{module} is not installed ({switch} unset)")


def rotation(w: float, x: float, y: float, z: float) -> np.ndarray:
    """The rotation matrix of the unit quaternion w + x i + y j + z k (Hamilton), in closed
    form: no library's quaternion order involved."""
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def unit_quaternion(rng: np.random.Generator) -> list[float]:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return [float(x) for x in q]


# A free body with a ball joint and a hinge below it (MuJoCo's qpos: root 7, neck 4, tilt 1).
FREE_BALL_MJCF = """<mujoco model="free_ball">
  <worldbody>
    <body name="torso" pos="0 0 1.5" quat="0.9 0.1 0.3 0.2">
      <freejoint name="root"/>
      <geom type="box" size="0.2 0.1 0.3" mass="3"/>
      <body name="head" pos="0.1 0 0.4">
        <joint name="neck" type="ball"/>
        <geom type="sphere" size="0.1" pos="0 0.05 0.2" mass="1"/>
        <body name="hat" pos="0 0.1 0.3">
          <joint name="tilt" type="hinge" axis="1 0 0"/>
          <geom type="capsule" fromto="0 0 0 0.2 0 0.1" size="0.03" mass="0.5"/>
        </body>
      </body>
    </body>
  </worldbody>
  <keyframe><key name="k" qpos="0.3 -0.2 1.1 0.5 0.5 -0.5 0.5 0.8 0 0.6 0 0.4"/></keyframe>
</mujoco>
"""
BODIES = ("torso", "head", "hat")


@pytest.fixture(scope="module")
def free_ball(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("conventions") / "free_ball.xml"
    path.write_text(FREE_BALL_MJCF)
    return path


@pytest.fixture(scope="module")
def qpos() -> np.ndarray:
    """A pose in MuJoCo's qpos: position, root quaternion w first, neck quaternion w first,
    tilt."""
    rng = np.random.default_rng(40)
    return np.array([0.3, -0.4, 1.2, *unit_quaternion(rng), *unit_quaternion(rng), 0.7])


def by_name(qpos: np.ndarray) -> dict[str, object]:
    return {
        "root": [float(x) for x in qpos[0:7]],
        "neck": [float(x) for x in qpos[7:11]],
        "tilt": float(qpos[11]),
    }


def mujoco_placements(mujoco, path: Path, qpos: np.ndarray) -> dict[str, tuple]:
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    return {
        body: (
            np.array(data.xpos[model.body(body).id]),
            np.array(data.xmat[model.body(body).id]).reshape(3, 3),
        )
        for body in BODIES
    }


def assert_same_placements(scene: pinsettle.Scene, q: np.ndarray, expected: dict) -> None:
    model = scene.model
    data = model.createData()
    pinocchio.framesForwardKinematics(model, data, q)
    for body, (position, rot) in expected.items():
        placement = data.oMf[model.getFrameId(body)]
        assert np.abs(placement.translation - position).max() < 1e-12, body
        assert np.abs(placement.rotation - rot).max() < 1e-12, body


# --- a joint's value by name: MuJoCo's qpos ----------------------------------------------------


def test_set_start_takes_mujoco_qpos(mujoco, free_ball, qpos):
    scene = pinsettle.load_scene(free_ball)
    scene.set_start(by_name(qpos))
    assert_same_placements(scene, scene.q0(), mujoco_placements(mujoco, free_ball, qpos))
    # Read back as given; Pinocchio's q holds each quaternion w last.
    assert scene.start["root"] == pytest.approx(qpos[0:7], abs=1e-15)
    assert scene.start["neck"] == pytest.approx(qpos[7:11], abs=1e-15)
    assert scene.q0()[3:7] == pytest.approx([*qpos[4:7], qpos[3]], abs=1e-15)


def test_scene_file_start_takes_mujoco_qpos(mujoco, free_ball, qpos, tmp_path):
    toml = tmp_path / "scene.toml"
    values = by_name(qpos)
    toml.write_text(
        f'[model]\nmjcf = "{free_ball}"\n[start]\n'
        + "".join(f"{joint} = {value!r}\n" for joint, value in values.items())
    )
    scene = pinsettle.load_scene(toml)
    assert_same_placements(scene, scene.q0(), mujoco_placements(mujoco, free_ball, qpos))


def test_start_flag_takes_mujoco_qpos(mujoco, free_ball, qpos):
    flags = [
        f"root={','.join(repr(float(x)) for x in qpos[0:7])}",
        f"neck={','.join(repr(float(x)) for x in qpos[7:11])}",
        f"tilt={float(qpos[11])!r}",
    ]
    args = cli.build_parser().parse_args(
        ["solve", str(free_ball), *[a for flag in flags for a in ("--start", flag)]]
    )
    scene, q0 = cli._load_scene(args)
    assert_same_placements(scene, q0, mujoco_placements(mujoco, free_ball, qpos))


def test_json_joints_are_mujoco_qpos_and_q_is_pinocchios(mujoco, free_ball, qpos):
    # One run through the command line: its joints by name, put into MuJoCo's qpos, place the
    # bodies where Pinocchio's forward kinematics at its q puts them.
    starts = [
        "--start",
        f"root={','.join(repr(float(x)) for x in qpos[0:7])}",
        "--start",
        f"neck={','.join(repr(float(x)) for x in qpos[7:11])}",
    ]
    proc = run("solve", str(free_ball), *starts, "--max-steps", "20", "--json")
    assert proc.returncode in (0, 1), proc.stderr
    out = json.loads(proc.stdout)
    joints = out["joints"]
    assert len(joints["root"]) == 7 and len(joints["neck"]) == 4
    reported = np.array([*joints["root"], *joints["neck"], joints["tilt"]])
    scene = pinsettle.load_scene(free_ball)
    assert_same_placements(
        scene, np.array(out["q"]), mujoco_placements(mujoco, free_ball, reported)
    )
    # 20 steps of a free fall move the body by far less than a turn: still near the start.
    assert np.abs(np.array(joints["root"][3:]) - qpos[3:7]).max() < 1e-3


def test_result_joints_are_mujoco_qpos(mujoco, free_ball, qpos):
    scene = pinsettle.load_scene(free_ball)
    scene.set_start(by_name(qpos))
    result = pinsettle.solve(scene, max_steps=50)
    joints = result.joints
    reported = np.array([*joints["root"], *joints["neck"], joints["tilt"]])
    assert_same_placements(scene, result.q, mujoco_placements(mujoco, free_ball, reported))
    assert scene.joint_values(result.q) == joints


def test_mjcf_pose_and_keyframe_start_where_mujoco_puts_them(mujoco, free_ball):
    # The file's own pose of the free body (qpos0) and its keyframe, through set_pose.
    scene = pinsettle.load_scene(free_ball)
    model = mujoco.MjModel.from_xml_path(str(free_ball))
    assert_same_placements(
        scene, scene.q0(), mujoco_placements(mujoco, free_ball, np.array(model.qpos0))
    )
    assert scene.start["root"][3:] == pytest.approx(
        np.array([0.9, 0.1, 0.3, 0.2]) / np.linalg.norm([0.9, 0.1, 0.3, 0.2]), abs=1e-15
    )
    scene.set_pose("k")
    key = np.array(model.key("k").qpos)
    assert_same_placements(scene, scene.q0(), mujoco_placements(mujoco, free_ball, key))


def test_free_flyer_of_a_urdf_in_closed_form():
    scene = pinsettle.load_scene(ROBOTS / "free_body.urdf", floating=True)
    w, x, y, z = unit_quaternion(np.random.default_rng(1))
    scene.set_start(root_joint=[0.1, 0.2, 0.3, w, x, y, z])
    data = scene.model.createData()
    pinocchio.forwardKinematics(scene.model, data, scene.q0())
    placement = data.oMi[scene.model.getJointId("root_joint")]
    assert np.abs(placement.rotation - rotation(w, x, y, z)).max() < 1e-14
    assert placement.translation == pytest.approx([0.1, 0.2, 0.3], abs=1e-15)
    # The result by name the same way (a free fall: 10 steps turn nothing).
    result = pinsettle.solve(scene, max_steps=10)
    assert result.joints["root_joint"][3:] == pytest.approx([w, x, y, z], abs=1e-12)
    assert result.q[3:7] == pytest.approx([x, y, z, w], abs=1e-12)


def test_ball_joint_in_closed_form():
    model = pinocchio.Model()
    ball = model.addJoint(0, pinocchio.JointModelSpherical(), pinocchio.SE3.Identity(), "ball")
    model.appendBodyToJoint(
        ball,
        pinocchio.Inertia(1.0, np.array([0.0, 0.0, -1.0]), np.eye(3) * 1e-2),
        pinocchio.SE3.Identity(),
    )
    scene = pinsettle.Scene(model)
    w, x, y, z = unit_quaternion(np.random.default_rng(2))
    scene.set_start(ball=[w, x, y, z])
    data = model.createData()
    pinocchio.forwardKinematics(scene.model, data, scene.q0())
    assert np.abs(data.oMi[1].rotation - rotation(w, x, y, z)).max() < 1e-14
    # It hangs: the bob straight below the ball, whatever the turn about the vertical.
    result = pinsettle.solve(scene)
    assert result.converged
    w, x, y, z = result.joints["ball"]
    assert rotation(w, x, y, z) @ np.array([0.0, 0.0, -1.0]) == pytest.approx(
        [0.0, 0.0, -1.0], abs=1e-6
    )


def test_srdf_pose_of_a_free_flyer_is_the_srdf_configuration():
    # The SRDF gives Pinocchio's q (x, y, z, qx, qy, qz, qw): set_pose starts exactly there.
    scene = pinsettle.Scene.from_robot("talos", floating=True)
    srdf = pinsettle._model_files.robot_srdf("talos")
    scene.load_srdf(srdf)
    scene.set_pose("half_sitting")
    expected = pinocchio.normalize(scene.model, scene.model.referenceConfigurations["half_sitting"])
    assert np.abs(scene.q0() - expected).max() < 1e-15
    root = scene.start["root_joint"]
    assert root[3:] == pytest.approx([expected[6], *expected[3:6]], abs=1e-15)


def test_a_nearly_unit_quaternion_is_normalised():
    scene = pinsettle.load_scene(ROBOTS / "free_body.urdf", floating=True)
    scene.set_start(root_joint=[0, 0, 1, 0.7071, 0, 0, 0.7071])  # typed to 4 digits
    q = scene.q0()
    assert np.linalg.norm(q[3:7]) == pytest.approx(1.0, abs=1e-15)
    assert q[3:7] == pytest.approx([0, 0, math.sqrt(0.5), math.sqrt(0.5)], abs=1e-15)


# --- errors about a joint's value, as the user typed it ----------------------------------------


def test_start_flag_with_a_bad_quaternion_names_the_flag(free_ball):
    line = one_line_error(run("solve", str(free_ball), "--start", "root=0,0,1.4,2,0,0,0"))
    assert "--start root=0,0,1.4,2,0,0,0: the quaternion (qw, qx, qy, qz) = (2, 0, 0, 0)" in line
    assert "norm 2" in line and "unit quaternion, w first" in line
    assert "q0[" not in line and "pinocchio.normalize" not in line
    line = one_line_error(run("solve", str(free_ball), "--start", "neck=0,0,0,0"))
    assert "--start neck=0,0,0,0:" in line and "norm 0" in line and "q0[" not in line


def test_start_flag_with_a_wrong_count_says_what_the_value_holds(free_ball):
    line = one_line_error(run("solve", str(free_ball), "--start", "root=0,0,1.4"))
    assert "--start root=0,0,1.4: joint 'root' must have 7 entries, got 3" in line
    assert "x, y, z, qw, qx, qy, qz" in line


def test_scene_start_with_a_bad_quaternion_names_the_key(free_ball, tmp_path):
    toml = tmp_path / "scene.toml"
    toml.write_text(f'[model]\nmjcf = "{free_ball}"\n[start]\nneck = [0.0, 0.0, 0.0, 0.0]\n')
    line = one_line_error(run("solve", str(toml)))
    assert "[start]" in line and "'neck'" in line and "norm 0" in line
    assert "q0[" not in line and "pinocchio.normalize" not in line
    with pytest.raises(pinsettle.SceneError, match=r"^start 'neck': the quaternion .* norm 2"):
        pinsettle.load_scene(free_ball).set_start(neck=[2.0, 0.0, 0.0, 0.0])


def test_the_configuration_check_reads_as_a_start_on_the_command_line(solo12):
    # What the C++ check tells a Python user who passes Pinocchio's q ...
    q0 = pinocchio.neutral(solo12)
    q0[3:7] *= 2.0
    with pytest.raises(ValueError) as error:
        pinsettle.solve(solo12, q0)
    assert str(error.value).startswith("q0[0:7] (joint 'root_joint'")
    # ... a command-line user reads by the joint's name and the order --start takes.
    line = cli._for_the_command_line(str(error.value))
    assert line.startswith("the start of joint 'root_joint' (JointModelFreeFlyer)")
    assert "norm 2" in line and "w first" in line and "--start root_joint=" in line
    assert "q0[" not in line and "pinocchio.normalize" not in line
    assert cli._for_the_command_line("kt must be in [0, 1)") == "kt must be in [0, 1)"


# --- URDF reading ------------------------------------------------------------------------------

# A reduced copy of pybullet_data's differential/diff_ring.urdf: a blank line before the XML
# declaration, a ring turning about the vertical, an arm on it and its twin coupled by <mimic>.
INERTIA = '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>'
DIFF_RING = f"""<?xml version="1.0" ?>
<robot name="diff_ring">
  <link name="world"/>
  <link name="ring"><inertial><mass value="1"/>{INERTIA}</inertial></link>
  <joint name="ring_world" type="continuous">
    <parent link="world"/><child link="ring"/><axis xyz="0 0 1"/>
  </joint>
  <link name="arm"><inertial><origin xyz="0.5 0 0"/><mass value="1"/>{INERTIA}</inertial></link>
  <joint name="arm_ring" type="revolute">
    <parent link="ring"/><child link="arm"/><origin xyz="0 0 0.1"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <link name="twin"><inertial><origin xyz="-0.5 0 0"/><mass value="1"/>{INERTIA}</inertial></link>
  <joint name="twin_ring" type="revolute">
    <parent link="ring"/><child link="twin"/><origin xyz="0 0 0.1"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="arm_ring" multiplier="-1"/>
  </joint>
</robot>
"""


@pytest.mark.parametrize(
    "prologue",
    ["\n", "  \n\t", "\ufeff\n", "<!-- written by a tool -->\n"],
    ids=["blank-line", "spaces", "bom-and-blank-line", "comment"],
)
def test_urdf_with_something_before_the_xml_declaration(tmp_path, prologue):
    clean = tmp_path / "clean.urdf"
    clean.write_text(DIFF_RING, encoding="utf-8")
    path = tmp_path / "diff_ring.urdf"
    path.write_text(prologue + DIFF_RING, encoding="utf-8")
    scene = pinsettle.load_scene(path)
    reference = pinsettle.load_scene(clean)
    assert list(scene.model.names) == list(reference.model.names)
    assert [(c.follower, c.leader, c.multiplier) for c in scene.couplings] == [
        ("twin_ring", "arm_ring", -1.0)
    ]
    result = pinsettle.solve(scene, scene.set_start(arm_ring=0.3).q0())
    again = pinsettle.solve(reference, reference.set_start(arm_ring=0.3).q0())
    assert result.converged and np.array_equal(result.q, again.q)
    # The arm and its twin hang on either side: both straight down (+-pi/2 about y).
    assert result.joints["arm_ring"] == pytest.approx(math.pi / 2, abs=1e-9)
    assert result.joints["twin_ring"] == pytest.approx(-math.pi / 2, abs=1e-9)
    proc = run("solve", str(path), "--max-steps", "5", "--json")
    assert proc.returncode in (0, 1) and "error" not in proc.stderr, proc.stderr


def test_pybullet_diff_ring_is_read():
    data = required("pybullet_data", "PINSETTLE_REQUIRE_MODELS")
    path = Path(data.getDataPath()) / "differential" / "diff_ring.urdf"
    assert path.read_bytes().startswith(b"\n<?xml")  # what the test is about
    scene = pinsettle.load_scene(path)
    model = pinocchio.buildModelFromUrdf(str(path))
    assert list(scene.model.names) == list(model.names) and scene.model.nv == 5
    assert not scene.couplings


@pytest.mark.parametrize(
    "change, where",
    [
        (('name="diff_ring"', 'name="diff & ring"'), "line 2, column 19"),
        (("</robot>", "</robot>\n<extra/>"), "junk after document element"),
    ],
    ids=["ampersand", "text-after-the-root"],
)
def test_urdf_that_is_not_well_formed_xml_names_the_fault(tmp_path, change, where):
    # urdfdom reads past these; ElementTree, which reads the <mimic> tags, does not. The
    # message names the XML fault, not the file's <mimic> tags.
    path = tmp_path / "bad.urdf"
    path.write_text(DIFF_RING.replace(*change))
    line = one_line_error(run("solve", str(path)))
    assert "not well-formed XML" in line and where in line and "correct the file" in line
    assert "<mimic>" not in line


def test_urdf_faults_in_one_short_line_with_a_way_forward(tmp_path):
    # As pybullet_data's humanoid/humanoid.urdf: eight collision elements urdfdom cannot read
    # and a 'spherical' joint (PyBullet's own type): 704 characters before.
    links = "".join(
        f'<link name="l{k}"><collision><geometry><capsule length="0.1" radius="0.05"/>'
        f"</geometry></collision></link>"
        for k in range(8)
    )
    path = tmp_path / "humanoid.urdf"
    path.write_text(
        f'<robot name="h"><link name="base"/>{links}<joint name="chest" type="spherical">'
        '<parent link="base"/><child link="l0"/></joint></robot>'
    )
    line = one_line_error(run("solve", str(path)))
    assert len(line.replace(str(path), "")) < 300, line
    assert "Joint [chest] has no known type [spherical]" in line
    assert "change the joint's type to one of URDF's (revolute, continuous" in line
    assert "and 5 more" in line  # the collision faults merged into one


def test_urdf_with_xacro_left_in_says_to_expand_it(tmp_path):
    path = tmp_path / "husky.urdf"
    path.write_text(
        DIFF_RING.replace('<origin xyz="0 0 0.1"/>', '<origin xyz="$(optenv X 0) 0 0.1"/>', 1)
    )
    line = one_line_error(run("solve", str(path)))
    assert "expand it with xacro first" in line and len(line.replace(str(path), "")) < 300


def test_urdf_without_a_moving_joint_says_so(tmp_path):
    path = tmp_path / "box.urdf"
    path.write_text((ROBOTS / "free_body.urdf").read_text())
    line = one_line_error(run("solve", str(path)))
    assert "no joint moves" in line and "--floating" in line
    assert "locked" not in line  # nothing was locked


def test_unknown_joint_lists_a_few_names(tmp_path):
    line = one_line_error(run("solve", str(ROBOTS / "chain20.urdf"), "--start", "joint99=1"))
    assert "--start joint99=1: unknown joint 'joint99'" in line
    assert "and 12 more" in line and len(line.replace(str(ROBOTS), "")) < 300


def test_an_include_part_of_an_mjcf_file_says_to_solve_the_includer(tmp_path):
    path = tmp_path / "part.xml"
    path.write_text("<mujocoinclude><body name='b'/></mujocoinclude>")
    line = one_line_error(run("solve", str(path)))
    assert "solve the file that includes it" in line


def test_a_mimic_tag_that_names_no_joint_names_the_file(tmp_path):
    # As example-robot-data's alex_psyonic_hands.urdf: a <mimic joint="index_q1"> where the
    # joint is 'Left_index_q1'. The line said neither which file nor how to go on.
    path = tmp_path / "hand.urdf"
    path.write_text(DIFF_RING.replace('<mimic joint="arm_ring"', '<mimic joint="arm_rin"'))
    line = one_line_error(run("solve", str(path)))
    assert f"{path}: the <mimic> tag of joint 'twin_ring': leader: unknown joint 'arm_rin'" in line
    assert "did you mean 'arm_ring'?" in line and "mimic = false" in line


def test_an_unknown_scene_name_is_one_short_line():
    line = one_line_error(run("solve", "no_such_scene"))
    assert "unknown scene 'no_such_scene'" in line and "`pinsettle scenes` lists them" in line
    assert len(line) < 300, line

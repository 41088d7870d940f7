"""``pinsettle.hold`` and ``pinsettle.payload``: the efforts that hold a pose, the largest
payload it holds within the effort limits, and their commands.

The efforts are checked against Pinocchio's own generalized gravity (minus the springs'
efforts, written out here); the payload against a bisection on ``hold`` of the scene with the
payload added as a scene element (``Scene.add_payload``, the C++ point load), never with the
closed form that ``payload`` uses.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest

UR5_LIMITS = {  # the <limit effort> of example-robot-data's ur5_robot.urdf
    "shoulder_pan_joint": 150.0,
    "shoulder_lift_joint": 150.0,
    "elbow_joint": 150.0,
    "wrist_1_joint": 28.0,
    "wrist_2_joint": 28.0,
    "wrist_3_joint": 28.0,
}


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pinsettle", *args], capture_output=True, text=True, timeout=120
    )


def gravity(model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
    return pinocchio.computeGeneralizedGravity(model, model.createData(), q)


def assert_close(a: np.ndarray, b: np.ndarray, rel: float = 1e-12) -> None:
    scale = max(1.0, float(np.max(np.abs(b))))
    assert np.max(np.abs(np.asarray(a) - b)) <= rel * scale, (a, b)


def ur5_poses(count: int) -> list[np.ndarray]:
    model = pinsettle.load_scene("ur5").model
    rng = np.random.default_rng(7)
    return [np.zeros(model.nq)] + [rng.uniform(-np.pi, np.pi, model.nq) for _ in range(count - 1)]


def test_ur5_urdf_limits_are_those_listed():
    # The limits of the URDF file itself, read here with a plain XML parser.
    import xml.etree.ElementTree as ET

    root = ET.parse(pinsettle.robot_urdf("ur5")).getroot()
    from_file = {
        j.get("name"): float(j.find("limit").get("effort"))
        for j in root.iter("joint")
        if j.find("limit") is not None
    }
    assert from_file == UR5_LIMITS
    assert pinsettle.hold(pinsettle.load_scene("ur5")).effort_limits == UR5_LIMITS


@pytest.mark.parametrize("index", range(5))
def test_ur5_hold_is_pinocchio_gravity(index):
    scene = pinsettle.load_scene("ur5")
    q = ur5_poses(5)[index]
    result = pinsettle.hold(scene, q)
    g = gravity(scene.model, q)
    assert_close(result.tau, g)
    assert list(result.efforts) == list(UR5_LIMITS)
    assert_close(np.array(list(result.efforts.values())), g)
    over = [n for n, v in result.efforts.items() if abs(v) > UR5_LIMITS[n]]
    assert result.over_limit == over


def test_ur5_zero_pose_and_the_model_itself():
    # The bare model (no scene) at its neutral pose: the arm straight out, the shoulder and
    # elbow carry it, the wrists' axes leave them nothing that a 1e-10 N m floor would show.
    model = pinsettle.load_robot("ur5")
    result = pinsettle.hold(model)
    g = gravity(model, pinocchio.neutral(model))
    assert_close(result.tau, g)
    assert result.efforts["shoulder_lift_joint"] < -50  # holds the arm up against gravity
    assert result.over_limit == []


def test_joint_springs_are_taken_off():
    # A spring tau_s = -k (q - rest) does part of the work: the motor applies g - tau_s.
    scene = pinsettle.load_scene("ur5")
    scene.add_joint_spring("shoulder_lift_joint", 40.0, rest=0.3)
    scene.add_joint_spring("elbow_joint", 15.0, rest=-0.2)
    q = ur5_poses(3)[2]
    spring = np.zeros(6)
    spring[1] = -40.0 * (q[1] - 0.3)
    spring[2] = -15.0 * (q[2] + 0.2)
    assert_close(pinsettle.hold(scene, q).tau, gravity(scene.model, q) - spring)


def test_double_pendulum_springs_scene():
    scene = pinsettle.load_scene("double_pendulum_springs")
    q = scene.q0()
    spring = np.array([-2.0 * (q[0] - 0.5), -1.0 * (q[1] + 0.3)])
    result = pinsettle.hold(scene)
    assert_close(result.tau, gravity(scene.model, q) - spring)
    # its URDF's effort="0": no limit
    assert result.effort_limits == {"joint1": None, "joint2": None}
    assert result.over_limit == []


def test_locked_joint_is_listed_with_what_its_lock_holds():
    scene = pinsettle.load_scene("ur5")
    q = ur5_poses(2)[1]
    scene.set_start({name: q[k] for k, name in enumerate(UR5_LIMITS)})
    scene.lock("elbow_joint")
    assert_close(pinsettle.hold(scene, q).tau, gravity(scene.model, q))
    assert scene.locked == ["elbow_joint"]  # the scene is left as it was


def test_over_limit_is_flagged():
    scene = pinsettle.load_scene("ur5")
    scene.add_payload("tool0", 20.0)  # at the zero pose: 59 + 20 * 8.0 N m on the shoulder
    result = pinsettle.hold(scene)
    assert abs(result.efforts["shoulder_lift_joint"]) > 150.0
    assert result.over_limit == ["shoulder_lift_joint"]


@pytest.mark.parametrize(
    "scene_name, message",
    [
        ("go1_standing", "floating-base mechanism needs contact forces: not yet supported"),
        ("fourbar", "closed loops"),
        ("panda_fingers_locked", "couplings"),
        ("box_on_incline", "floating-base"),
    ],
)
def test_refused(scene_name, message):
    with pytest.raises(pinsettle.SceneError, match=message):
        pinsettle.hold(pinsettle.load_scene(scene_name))


def test_ground_contacts_are_refused():
    scene = pinsettle.load_scene("ur5")
    scene.add_ground((0.0, 0.0, -0.5)).add_contact("tool0")
    with pytest.raises(pinsettle.SceneError, match="ground contacts .*not yet supported"):
        pinsettle.hold(scene)
    with pytest.raises(pinsettle.SceneError, match="ground contacts"):
        pinsettle.payload(scene, None, "tool0")


def test_prismatic_joint_in_newtons():
    # A 2 kg block on a vertical slider 0.1 m up its 500 N/m spring: the motor carries its
    # weight (+z, against gravity) and the spring's pull back down, 2 g + 500 * 0.1 N.
    scene = pinsettle.load_scene("slider_spring")
    q = np.array([0.1])
    result = pinsettle.hold(scene, q)
    expected = 2.0 * np.linalg.norm(scene.gravity) + 500.0 * 0.1
    assert result.efforts["slider"] == pytest.approx(expected, rel=1e-12)
    assert_close(result.tau, gravity(scene.model, q) + 500.0 * q)
    assert result.effort_limits == {"slider": 1000.0}
    proc = run("hold", "slider_spring", "--start", "slider=0.1")
    assert proc.returncode == 0, proc.stderr
    assert f"{expected:.4g} N " in proc.stdout and "1000 N" in proc.stdout


# --- payload -----------------------------------------------------------------------------------


def within(scene: pinsettle.Scene, q: np.ndarray, rel: float = 0.0) -> bool:
    result = pinsettle.hold(scene, q)
    return all(
        limit is None or abs(result.efforts[n]) <= limit * (1 + rel)
        for n, limit in result.effort_limits.items()
    )


def with_payload(q: np.ndarray, frame: str, mass: float, offset) -> pinsettle.Scene:
    scene = pinsettle.load_scene("ur5")
    if mass > 0:
        scene.add_payload(frame, mass, offset)
    return scene


def bisect_mass(q: np.ndarray, frame: str, offset, hi: float = 500.0) -> float:
    lo = 0.0
    assert not within(with_payload(q, frame, hi, offset), q)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if within(with_payload(q, frame, mid, offset), q) else (lo, mid)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize(
    "index, frame, offset",
    [
        (0, "tool0", (0.0, 0.0, 0.0)),
        (1, "tool0", (0.0, 0.0, 0.1)),
        (2, "wrist_3_link", (0.05, -0.02, 0.1)),
        (3, "forearm_link", (0.0, 0.0, 0.2)),
    ],
)
def test_payload_against_bisection_on_hold(index, frame, offset):
    q = ur5_poses(4)[index]
    if not within(with_payload(q, frame, 0.0, offset), q):
        pytest.fail("pick poses that hold themselves")
    found = pinsettle.payload(pinsettle.load_scene("ur5"), q, frame, offset)
    assert found.mass == pytest.approx(bisect_mass(q, frame, offset), rel=1e-9)
    # at the mass every joint within its limit, at 1.001 times it the limiting joint over
    assert within(with_payload(q, frame, found.mass, offset), q, rel=1e-9)
    heavier = pinsettle.hold(with_payload(q, frame, 1.001 * found.mass, offset), q)
    assert found.limiting_joint in heavier.over_limit
    # the efforts it gives at the mass are those of the scene carrying it
    carried = pinsettle.hold(with_payload(q, frame, found.mass, offset), q)
    assert found.loaded is not None
    assert_close(found.loaded.tau, carried.tau, rel=1e-10)


def test_payload_of_a_pose_already_over_is_zero():
    scene = pinsettle.load_scene("ur5")
    scene.add_payload("tool0", 20.0)
    found = pinsettle.payload(scene, None, "tool0")
    assert found.mass == 0.0
    assert found.limiting_joint == "shoulder_lift_joint"
    assert found.hold.over_limit == ["shoulder_lift_joint"]


def test_payload_bad_frame():
    scene = pinsettle.load_scene("ur5")
    with pytest.raises(pinsettle.SceneError, match=r"frame: unknown frame 'tool9' \(did you"):
        pinsettle.payload(scene, None, "tool9")
    with pytest.raises(pinsettle.SceneError, match="fixed to the world"):
        pinsettle.payload(scene, None, "base_link")
    with pytest.raises(pinsettle.SceneError, match="offset must have 3 entries"):
        pinsettle.payload(scene, None, "tool0", (0.0, 0.1))


# --- the commands ------------------------------------------------------------------------------


def one_json(proc: subprocess.CompletedProcess) -> dict:
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1, proc.stdout + proc.stderr
    return json.loads(lines[0])


def test_cli_hold_json():
    proc = run("hold", "ur5", "--start", "shoulder_lift_joint=-1.57", "--json")
    assert proc.returncode == 0, proc.stderr
    out = one_json(proc)
    assert {"efforts", "effort_limits", "over_limit"} <= set(out)
    assert out["effort_limits"] == UR5_LIMITS and out["over_limit"] == []
    model = pinsettle.load_robot("ur5")
    q = np.zeros(6)
    q[1] = -1.57
    assert_close(np.array(list(out["efforts"].values())), gravity(model, q))


def test_cli_hold_text_lists_six_joints():
    proc = run("hold", "ur5", "--start", "shoulder_lift_joint=-1.57")
    assert proc.returncode == 0, proc.stderr
    for name, limit in UR5_LIMITS.items():
        assert any(
            line.startswith(name) and f"{limit:g} N m" in line for line in proc.stdout.splitlines()
        )
    assert "over limit: none" in proc.stdout


def test_cli_hold_over_limit_exits_1(tmp_path: Path):
    scene = tmp_path / "heavy.toml"
    scene.write_text(
        '[model]\nrobot = "ur5"\n\n[[payload]]\nframe = "tool0"\nmass = 20.0\n', encoding="utf-8"
    )
    proc = run("hold", str(scene), "--json")
    assert proc.returncode == 1, proc.stderr
    assert one_json(proc)["over_limit"] == ["shoulder_lift_joint"]


def test_cli_payload_json():
    proc = run("payload", "ur5", "--frame", "tool0", "--offset", "0", "0", "0.1", "--json")
    assert proc.returncode == 0, proc.stderr
    out = one_json(proc)
    found = pinsettle.payload(pinsettle.load_scene("ur5"), None, "tool0", (0, 0, 0.1))
    assert out["mass"] == pytest.approx(found.mass, rel=1e-12) and out["mass"] > 0
    assert out["limiting_joint"] == found.limiting_joint == "shoulder_lift_joint"


@pytest.mark.parametrize(
    "args, said",
    [
        (("payload", "ur5", "--frame", "tool9"), "--frame: unknown frame 'tool9'"),
        (("payload", "ur5", "--frame", "base_link"), "--frame: 'base_link' is fixed"),
        (("hold", "ur5", "--start", "elbow=1"), "--start elbow=1: unknown joint 'elbow'"),
        (("payload", "ur5", "--frame", "tool0", "--start", "x=1"), "--start x=1: unknown joint"),
        (("hold", "ur5", "--pose", "home"), "--pose home: unknown pose 'home'"),
        (("hold", "go1_standing"), "floating-base mechanism needs contact forces"),
        (("payload", "ur5", "--frame", "tool0", "--offset", "0", "a", "0"), "--offset"),
        (("payload", "ur5"), "--frame"),
    ],
)
def test_cli_bad_input_exits_2(args, said):
    proc = run(*args)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert said in proc.stderr
    assert "Traceback" not in proc.stderr


def test_worked_example_of_the_docs_is_what_the_commands_print(tmp_path: Path):
    # docs/loads.md quotes the table of `pinsettle hold` on its scene, and the payloads.
    page = (Path(__file__).parents[1] / "docs" / "loads.md").read_text(encoding="utf-8")
    scene_text = page.split("```toml\n", 1)[1].split("```", 1)[0]
    table = page.split("` prints:\n\n```\n", 1)[1].split("```", 1)[0]
    scene = tmp_path / "ur5_3kg.toml"
    scene.write_text(scene_text, encoding="utf-8")
    proc = run("hold", str(scene))
    assert proc.returncode == 0, proc.stderr
    assert table.strip() in proc.stdout
    words = " ".join(page.split())
    straight = pinsettle.payload(pinsettle.load_scene("ur5"), None, "tool0")
    assert f"gives {straight.mass:.2f} kg, limited by `{straight.limiting_joint}`" in words
    q = np.array([0.0, -1.5708, 1.5708, 0.0, 0.0, 0.0])
    bent = pinsettle.payload(pinsettle.load_scene("ur5"), q, "tool0")
    assert bent.limiting_joint == "elbow_joint"
    assert f"payload is {bent.mass:.2f} kg, limited by the elbow" in words


def test_cli_pose_and_robot_name():
    # z1 is a robot of example-robot-data, not a scene: its URDF, and its own SRDF's poses.
    proc = run("hold", "z1", "--pose", "arm_up", "--start", "joint1=0.4", "--json")
    assert proc.returncode == 0, proc.stderr
    out = one_json(proc)
    scene = pinsettle.Scene.from_robot("z1")
    scene.load_srdf(pinsettle._model_files.robot_srdf("z1"))
    scene.set_pose("arm_up").set_start(joint1=0.4)
    q = scene.q0()
    assert np.array(out["q"]) == pytest.approx(q, abs=0) and q[0] == 0.4
    assert q[1] != 0.0  # the pose moved more than the joint given
    assert_close(np.array(list(out["efforts"].values())), gravity(scene.model, q))


def test_payload_without_limits_is_unbounded():
    # The double pendulum's joints have no limit (effort="0"): nothing bounds the mass.
    found = pinsettle.payload(pinsettle.load_scene("double_pendulum_springs"), None, "link2")
    assert found.mass == np.inf and found.limiting_joint is None and found.loaded is None
    assert np.abs(found.per_kg).max() > 0  # the mass does load the joints
    proc = run("payload", "double_pendulum_springs", "--frame", "link2", "--json")
    assert proc.returncode == 0, proc.stderr
    out = one_json(proc)
    assert out["mass"] is None and out["limiting_joint"] is None

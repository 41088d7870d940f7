"""Helical and composite joints in real solves, and the SRDF poses of every robot pinsettle
reads an SRDF for, each judged independently.

- Helical joints (``JointModelHX``/``HY``/``HZ``, ``JointModelHelicalUnaligned``: a screw, the
  body turning by q and moving pitch * q along the axis), alone, in a chain, with a joint
  spring, a stop and a coupling: closed forms where there is one (a nut on a vertical screw
  rests where its spring holds its weight, m g pitch = k q), else the rest conditions
  recomputed with ``pinocchio.computeGeneralizedGravity`` and tests/scene_reference.py.
- Composite joints (``JointModelComposite``: several joints in one): a Cardan joint against
  the same mechanism built as two joints (Pinocchio's composite kinematics against its chain
  kinematics), a cylindrical joint held by a point spring, a composite inside a composite, a
  helical part, a joint load on a composite; what pinsettle refuses on one (a joint spring, a
  stop, a coupling, parts that repeat a motion) is refused in one line naming the joint.
- The verdicts are those of tests/verdict_reference.py (the stiffness differenced here).
- SRDF poses: every ``group_state`` of every robot in pinsettle's table of SRDFs
  (``_model_files.ROBOT_SRDF``), read again here with ElementTree, is the start a scene's
  ``[start] pose`` gives; released there, the robot (root fixed) converges to a rest the
  reference confirms.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pinocchio
import pinsettle
import pytest
from pinsettle._model_files import ROBOT_SRDF, robot_srdf
from scene_reference import Reference
from scipy.optimize import brentq
from verdict_reference import describe, gravity_force, scene_verdict, tree_verdict

ID = pinocchio.SE3.Identity()
G = 9.81
# A converged answer's residual, recomputed by the reference: round-off of the loads here.
MAX_RESIDUAL = 1e-11


def add_body(model: pinocchio.Model, joint: int, mass: float, lever) -> None:
    """A body of ``mass`` kg at ``lever`` (m) in the joint's frame, with a frame named after
    the joint plus '_body' for the scene's elements."""
    inertia = pinocchio.Inertia(mass, np.array(lever, float), mass * 0.01 * np.eye(3))
    model.appendBodyToJoint(joint, inertia, ID)
    name = model.names[joint] + "_body"
    model.addFrame(pinocchio.Frame(name, joint, 0, ID, pinocchio.FrameType.BODY))


def composite(*parts) -> pinocchio.JointModelComposite:
    """A composite joint of (joint model, placement) parts, in order."""
    joint = pinocchio.JointModelComposite()
    for model, placement in parts:
        joint.addJoint(model, placement)
    return joint


def pair(model: pinocchio.Model) -> tuple[pinsettle.Scene, Reference]:
    return pinsettle.Scene(model), Reference(model.copy())


def check_rest(scene, ref, result, couplings=()) -> None:
    """Converged at a rest of the reference's physics (residual at round-off, stops pushing),
    with the reference's verdict and smallest eigenvalue."""
    assert result.converged, result.summary()
    verdict = scene_verdict(ref, result.q, couplings)
    assert verdict.residual <= MAX_RESIDUAL, (verdict.residual, describe(verdict))
    assert verdict.decided, describe(verdict)
    verdict.check(result.stability, result.min_stiffness_eigenvalue)
    if not couplings:  # the stops' sides and reactions, recomputed
        contacts = ref.contacts(result.q)
        assert result.at_limit == {name: side for name, (side, _) in contacts.items()}
        for name, (_, reaction) in contacts.items():
            assert result.limit_reactions[name] == pytest.approx(reaction, rel=1e-9, abs=1e-12)


# --- helical joints ------------------------------------------------------------------------------


@pytest.mark.parametrize("pitch", [0.05, -0.2])
def test_a_nut_on_a_vertical_screw_rests_where_its_spring_holds_its_weight(pitch):
    # V = m g pitch q + k q^2 / 2: the rest is q* = -m g pitch / k, its stiffness k (the
    # weight's pull along the screw is the same at every turn).
    mass, stiffness = 1.5, 3.0
    model = pinocchio.Model()
    joint = model.addJoint(0, pinocchio.JointModelHZ(pitch), ID, "screw")
    add_body(model, joint, mass, [0.0, 0.0, 0.0])
    scene, ref = pair(model)
    scene.add_joint_spring("screw", stiffness, 0.0)
    ref.joint_springs.append(("screw", stiffness, 0.0))
    result = pinsettle.solve(scene, [0.4])
    check_rest(scene, ref, result)
    assert result.joints["screw"] == pytest.approx(-mass * G * pitch / stiffness, abs=1e-12)
    assert result.stability == "stable"
    assert result.min_stiffness_eigenvalue == pytest.approx(stiffness, rel=1e-9)


def test_a_screw_pendulum_hangs_straight_down():
    # A helical joint about a horizontal axis: the body turns as a pendulum and slides along the
    # axis, which changes nothing of its height: it hangs straight down (q = 0), at stiffness
    # m g l, as a hinge would.
    mass, arm = 2.0, 0.4
    model = pinocchio.Model()
    joint = model.addJoint(0, pinocchio.JointModelHX(0.05), ID, "screw")
    add_body(model, joint, mass, [0.0, 0.0, -arm])
    scene, ref = pair(model)
    result = pinsettle.solve(scene, [1.0])
    check_rest(scene, ref, result)
    assert abs(result.joints["screw"]) <= 1e-12
    assert result.min_stiffness_eigenvalue == pytest.approx(mass * G * arm, rel=1e-9)


def tilted_screw(upper: float) -> tuple[pinsettle.Scene, Reference]:
    """A screw about a tilted axis (pitch 0.03 m/rad), its body 0.2 m off the axis, a 2 N m/rad
    spring, stops at -0.3 and ``upper``."""
    model = pinocchio.Model()
    axis = np.array([0.6, 0.0, 0.8])
    joint = model.addJoint(0, pinocchio.JointModelHelicalUnaligned(axis, 0.03), ID, "screw")
    add_body(model, joint, 1.0, [0.2, 0.0, 0.0])
    scene, ref = pair(model)
    scene.add_joint_spring("screw", 2.0, 0.0)
    ref.joint_springs.append(("screw", 2.0, 0.0))
    scene.set_limit("screw", lower=-0.3, upper=upper)
    ref.limit_entries.append(("screw", -0.3, upper))
    return scene, ref


def test_a_tilted_screw_rests_at_the_root_of_its_force():
    scene, ref = tilted_screw(upper=0.3)
    result = pinsettle.solve(scene, [0.1])
    check_rest(scene, ref, result)
    root = brentq(lambda t: ref.force(np.array([t]))[0], -0.3, 0.3, xtol=1e-15)
    assert result.joints["screw"] == pytest.approx(root, abs=1e-12)
    assert result.at_limit == {}


def test_a_tilted_screw_presses_on_its_stop():
    # The same screw with its upper stop below the free rest's -0.080: it rests on the stop,
    # which pushes back with the force the reference finds there.
    scene, ref = tilted_screw(upper=-0.15)
    result = pinsettle.solve(scene, [-0.2])
    check_rest(scene, ref, result)
    assert result.at_limit == {"screw": "upper"} and result.joints["screw"] == -0.15
    assert result.limit_reactions["screw"] == pytest.approx(
        -ref.force(np.array([-0.15]))[0], rel=1e-12
    )


def test_an_arm_with_a_screw_wrist_and_a_coupling():
    # A shoulder (revolute), an elbow and a screw wrist (pitch -0.1 m/rad) whose turn follows
    # the elbow's (q_wrist = 0.5 q_elbow + 0.1), a spring on the elbow: a rest of the coupled
    # mechanism, checked on the motions the coupling allows.
    model = pinocchio.Model()
    shoulder = model.addJoint(0, pinocchio.JointModelRY(), ID, "shoulder")
    add_body(model, shoulder, 2.0, [0.0, 0.0, -0.3])
    down = pinocchio.SE3(np.eye(3), np.array([0.0, 0.0, -0.6]))
    elbow = model.addJoint(shoulder, pinocchio.JointModelRY(), down, "elbow")
    add_body(model, elbow, 1.0, [0.1, 0.0, -0.25])
    wrist = model.addJoint(elbow, pinocchio.JointModelHY(-0.1), down, "wrist")
    add_body(model, wrist, 0.5, [0.15, 0.05, -0.1])
    scene, ref = pair(model)
    scene.add_joint_spring("elbow", 5.0, 0.3)
    ref.joint_springs.append(("elbow", 5.0, 0.3))
    couplings = [("wrist", "elbow", 0.5, 0.1)]
    scene.add_coupling(*couplings[0])
    result = pinsettle.solve(scene, [0.5, -0.4, 0.0])
    check_rest(scene, ref, result, couplings)
    assert result.joints["wrist"] == pytest.approx(0.5 * result.joints["elbow"] + 0.1, abs=1e-12)


# --- composite joints ----------------------------------------------------------------------------


def cardan_models() -> tuple[pinocchio.Model, pinocchio.Model]:
    """A pendulum on a Cardan joint: as one composite (RX then RY) and as two joints (RX, then
    RY on a massless link at the same place)."""
    lever = [0.1, 0.05, -0.5]
    one = pinocchio.Model()
    joint = one.addJoint(
        0, composite((pinocchio.JointModelRX(), ID), (pinocchio.JointModelRY(), ID)), ID, "cardan"
    )
    add_body(one, joint, 2.0, lever)
    two = pinocchio.Model()
    first = two.addJoint(0, pinocchio.JointModelRX(), ID, "x")
    two.appendBodyToJoint(first, pinocchio.Inertia.Zero(), ID)
    second = two.addJoint(first, pinocchio.JointModelRY(), ID, "y")
    add_body(two, second, 2.0, lever)
    return one, two


def test_a_cardan_composite_rests_where_the_two_joint_chain_does():
    one, two = cardan_models()
    result = pinsettle.solve(one, [0.4, -0.3])
    scene, ref = pair(one)
    check_rest(scene, ref, result)
    # Pinocchio's chain kinematics agree that this is a rest, and the chain settles there too.
    assert (
        np.max(np.abs(pinocchio.computeGeneralizedGravity(two, two.createData(), result.q)))
        <= 1e-12
    )
    chain = pinsettle.solve(two, [0.4, -0.3])
    assert chain.converged and np.max(np.abs(chain.q - result.q)) <= 1e-12
    assert result.stability == chain.stability == "stable"
    assert result.min_stiffness_eigenvalue == pytest.approx(
        chain.min_stiffness_eigenvalue, rel=1e-6
    )


def test_a_cylindrical_composite_held_by_a_spring():
    # Slide along z and turn about it (PZ then RZ): the weight pulls it down for ever, unless
    # a point spring from its body to the world holds it.
    model = pinocchio.Model()
    joint = model.addJoint(
        0, composite((pinocchio.JointModelPZ(), ID), (pinocchio.JointModelRZ(), ID)), ID, "cylinder"
    )
    add_body(model, joint, 1.0, [0.3, 0.0, 0.0])
    falling = pinsettle.solve(model, [0.0, 1.0], max_steps=200_000)
    assert falling.status == "no_equilibrium", falling.summary()
    scene, ref = pair(model)
    a, b = ("cylinder_body", np.array([0.3, 0.0, 0.0])), ("universe", np.array([1.0, 0.5, 0.5]))
    scene.add_spring({"frame": a[0], "point": a[1]}, {"frame": b[0], "point": b[1]}, 50.0, 0.2)
    ref.springs.append((*a, *b, 50.0, 0.2))
    result = pinsettle.solve(scene)
    check_rest(scene, ref, result)
    assert result.stability == "stable"


@pytest.mark.parametrize("case", ["nested", "helical-part", "joint-load"])
def test_composites_rest_where_pinocchio_gravity_and_the_loads_vanish(case):
    model = pinocchio.Model()
    effort = None
    if case == "nested":  # (RZ then RX) then RY: the turn about the vertical is neutral
        inner = composite((pinocchio.JointModelRZ(), ID), (pinocchio.JointModelRX(), ID))
        joint = model.addJoint(0, composite((inner, ID), (pinocchio.JointModelRY(), ID)), ID, "c")
    elif case == "helical-part":  # a screw about x, then a hinge 0.2 m below it
        below = pinocchio.SE3(np.eye(3), np.array([0.0, 0.0, -0.2]))
        joint = model.addJoint(
            0,
            composite((pinocchio.JointModelHX(0.05), ID), (pinocchio.JointModelRY(), below)),
            ID,
            "c",
        )
    else:  # a Cardan joint pushed by a constant effort on each of its parts
        joint = model.addJoint(
            0, composite((pinocchio.JointModelRX(), ID), (pinocchio.JointModelRY(), ID)), ID, "c"
        )
        effort = np.array([0.5, -0.3])
    add_body(model, joint, 2.0, [0.1, 0.2, -0.4])
    scene, ref = pair(model)
    if effort is not None:
        scene.add_load("c", list(effort))
        ref.joint_loads.append(("c", effort))
    q0 = pinocchio.integrate(model, pinocchio.neutral(model), 0.4 * np.ones(model.nv))
    result = pinsettle.solve(scene, q0)
    check_rest(scene, ref, result)
    expected = "neutral" if case == "nested" else "stable"
    assert result.stability == expected
    # Without elements the reference is Pinocchio's gravity alone.
    if effort is None:
        verdict = tree_verdict(model, gravity_force(model), result.q)
        verdict.check(result.stability, result.min_stiffness_eigenvalue)


def test_what_a_composite_joint_cannot_take_is_refused_by_name():
    model, _ = cardan_models()
    scene = pinsettle.Scene(model)
    cases = [
        (lambda: scene.add_joint_spring("cardan", 1.0, 0.0), "joint spring needs a 1-DoF joint"),
        (lambda: scene.set_limit("cardan", lower=0.0), "a stop needs a 1-DoF joint"),
        (lambda: scene.add_coupling("cardan", "cardan"), "a coupling needs 1-DoF joints"),
        (lambda: scene.add_load("cardan", 1.0), "effort must be a list of 2 numbers"),
    ]
    for call, fragment in cases:
        with pytest.raises(pinsettle.SceneError) as error:
            call()
        message = str(error.value)
        assert "\n" not in message and fragment in message, message
        assert "'cardan'" in message or "effort" in message, message
        if "1-DoF" in message:
            assert "JointModelComposite with 2" in message, message


def test_a_composite_whose_parts_repeat_a_motion_is_refused_by_name():
    # A ball joint then a hinge about x: the hinge repeats one of the ball's turns, so one
    # combination of the joint's velocities moves nothing: no dynamics. Refused before any
    # step, in one line naming the joint.
    model = pinocchio.Model()
    joint = model.addJoint(
        0,
        composite((pinocchio.JointModelSpherical(), ID), (pinocchio.JointModelRX(), ID)),
        ID,
        "ball_and_hinge",
    )
    add_body(model, joint, 1.0, [0.1, 0.2, -0.4])
    with pytest.raises(ValueError) as error:
        pinsettle.solve(model)
    message = str(error.value)
    assert "\n" not in message
    assert "'ball_and_hinge'" in message and "singular" in message, message


# --- SRDF poses ----------------------------------------------------------------------------------


def srdf_poses(name: str) -> dict[str, dict[str, list[float]]]:
    """The group_state poses of a robot's SRDF, read with ElementTree: pose -> joint -> values."""
    root = ET.parse(robot_srdf(name)).getroot()
    return {
        state.get("name"): {
            joint.get("name"): [float(x) for x in joint.get("value").split()]
            for joint in state.iter("joint")
        }
        for state in root.iter("group_state")
    }


POSES = [(robot, pose) for robot in sorted(ROBOT_SRDF) for pose in sorted(srdf_poses(robot))]
# Measured: every pose converges in 6 to 173 steps. The Panda with its fingers coupled (the
# default for a robot's scene) once did not from its 'default' pose (max_steps after 1e6 steps,
# its arm drifting on two stops); it has converged (1297 steps) since an impact on a stop in a
# mechanism with couplings or loops takes the metric of the mass matrix.


def test_every_robot_of_the_table_has_its_srdf_and_most_have_poses():
    assert set(ROBOT_SRDF) >= {"talos", "panda", "ur5", "solo12", "anymal", "go1", "kinova"}
    for robot in ROBOT_SRDF:
        assert robot_srdf(robot).is_file(), robot
    assert len({robot for robot, _ in POSES}) == len(ROBOT_SRDF) - 1  # all but the UR5's
    assert len(POSES) >= 12


def test_a_robot_whose_srdf_has_no_pose_says_which_there_are(tmp_path):
    # The UR5's SRDF has groups but no group_state: asking for a pose names none known.
    assert srdf_poses("ur5") == {}
    toml = tmp_path / "ur5.toml"
    toml.write_text('[model]\nrobot = "ur5"\n[start]\npose = "home"\n', encoding="utf-8")
    with pytest.raises(pinsettle.SceneError) as error:
        pinsettle.load_scene(toml)
    message = str(error.value)
    assert "'home'" in message and "\n" not in message, message


@pytest.mark.parametrize(
    "robot, pose",
    POSES,
    ids=[f"{r}-{p}" for r, p in POSES],
)
def test_each_srdf_pose_starts_the_robot_and_it_settles_from_there(robot, pose, tmp_path):
    toml = tmp_path / f"{robot}.toml"
    toml.write_text(f'[model]\nrobot = "{robot}"\n[start]\npose = "{pose}"\n', encoding="utf-8")
    scene = pinsettle.load_scene(toml)
    model = scene.model
    # The start is the SRDF's pose, joint by joint (its free-flyer left out: the root is fixed).
    start = scene.joint_values(scene.q0())
    for joint, values in srdf_poses(robot)[pose].items():
        if not model.existJointName(joint):
            assert len(values) == 7, joint  # the free-flyer's pose, left out (a note says so)
            assert any(joint in note for note in scene.notes), (joint, scene.notes)
            continue
        got = start[joint]
        assert (got if isinstance(got, list) else [got]) == pytest.approx(values, abs=1e-15), joint
    couplings = [(c.follower, c.leader, c.multiplier, c.offset) for c in scene.couplings]
    result = pinsettle.solve(scene, max_steps=20_000)  # 100 times the slowest pose's steps
    ref = Reference(model.copy())
    assert result.converged, result.summary()
    verdict = scene_verdict(ref, result.q, couplings)
    scale = max(1.0, float(np.max(np.abs(ref.force(scene.q0())))))
    assert verdict.residual <= 1e-9 * scale, (verdict.residual, describe(verdict))
    verdict.check(result.stability, result.min_stiffness_eigenvalue)
    if not couplings:
        contacts = ref.contacts(result.q)
        assert result.at_limit == {name: side for name, (side, _) in contacts.items()}
    assert not math.isnan(result.residual)

"""Models whose inertias no rigid body has are refused wherever a model enters, with the body
named: a Python pinocchio.Model, a URDF (link by link, before fixed joints sum them), an MJCF
file, a scene file and the command line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest

ARM = """<robot name="arm">
  <link name="base"/>
  <link name="upper">
    <inertial><origin xyz="0 0 -0.25"/><mass value="{upper}"/>
      <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial>
  </link>
  <link name="tool">
    <inertial><origin xyz="0 0 0"/><mass value="{tool}"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/>
  </joint>
  <joint name="weld" type="fixed">
    <parent link="upper"/><child link="tool"/><origin xyz="0 0 -0.5"/>
  </joint>
</robot>
"""


def write_arm(tmp_path: Path, upper="1.0", tool="0.5", ixx="0.02") -> Path:
    path = tmp_path / "arm.urdf"
    path.write_text(ARM.format(upper=upper, tool=tool, ixx=ixx), encoding="utf-8")
    return path


def sound_model() -> pinocchio.Model:
    model = pinocchio.buildSampleModelManipulator()
    assert all(inertia.mass > 0 for inertia in model.inertias[1:])
    return model


@pytest.mark.parametrize(
    "spoil, words",
    [
        (lambda i: setattr(i, "mass", -2.0), ["mass -2 kg", "finite and >= 0"]),
        (lambda i: setattr(i, "mass", float("nan")), ["mass nan kg"]),
        (lambda i: setattr(i, "lever", np.array([0.0, np.inf, 0.0])), ["not finite"]),
        (
            lambda i: setattr(i, "inertia", np.diag([0.1, 0.1, -0.05])),
            ["principal moments", "positive semidefinite"],
        ),
    ],
)
def test_a_python_model_with_an_impossible_inertia_is_refused_naming_its_body(spoil, words):
    model = sound_model()
    inertia = model.inertias[3]
    spoil(inertia)
    model.inertias[3] = inertia
    body = next(
        f.name for f in model.frames if f.type == pinocchio.FrameType.BODY and f.parentJoint == 3
    )
    q = pinocchio.neutral(model)
    for call in (lambda: pinsettle.solve(model, q), lambda: pinsettle.Solver(model).solve(q)):
        with pytest.raises(ValueError) as error:
            call()
        message = str(error.value)
        assert f"'{body}'" in message and f"'{model.names[3]}'" in message, message
        for word in words:
            assert word in message, message


def test_a_sound_python_model_still_solves():
    model = sound_model()
    result = pinsettle.solve(model, pinocchio.neutral(model))
    assert result.status == "converged", result.reason


@pytest.mark.parametrize(
    "fields, words",
    [
        ({"upper": "-2"}, ["link 'upper'", "mass -2.0 kg"]),
        # A negative mass welded onto a heavier link: Pinocchio's sum (0.5 kg) hides it.
        ({"upper": "1.0", "tool": "-0.5"}, ["link 'tool'", "mass -0.5 kg"]),
        ({"ixx": "-0.5"}, ["link 'upper'", "positive semidefinite"]),
        # urdfdom refuses this one itself (not a float), naming the link too.
        ({"upper": "inf"}, ["upper", "mass"]),
    ],
)
def test_a_urdf_link_with_an_impossible_inertia_is_refused_naming_the_link(tmp_path, fields, words):
    path = write_arm(tmp_path, **fields)
    scene_file = tmp_path / "arm.toml"
    scene_file.write_text(f'[model]\nurdf = "{path.as_posix()}"\n', encoding="utf-8")
    for load in (lambda: pinsettle.load_urdf(path), lambda: pinsettle.load_scene(scene_file)):
        with pytest.raises(ValueError) as error:
            load()
        for word in words:
            assert word in str(error.value), str(error.value)
    run = subprocess.run(
        [sys.executable, "-m", "pinsettle", "solve", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 2, run.stdout + run.stderr
    assert words[0] in run.stderr and "Traceback" not in run.stderr, run.stderr


def test_the_sound_arm_loads_and_hangs_down(tmp_path):
    scene = pinsettle.load_scene(write_arm(tmp_path))
    result = pinsettle.solve(scene)
    assert result.status == "converged", result.reason
    assert abs(scene.residual(result.q)) < 1e-9


@pytest.mark.parametrize(
    "inertial, words",
    [
        ('mass="-1" diaginertia="0.1 0.1 0.1"', ["'link'", "mass", "-1"]),
        ('mass="1" diaginertia="0.1 -0.1 0.1"', ["'link'", "positive semidefinite"]),
    ],
)
def test_an_mjcf_body_with_an_impossible_inertia_is_refused_naming_the_body(
    tmp_path, inertial, words
):
    # Before MuJoCo's bounds would lift them (boundmass and boundinertia, 0 by default): both
    # were solved as another body, massless or with a zero moment.
    path = tmp_path / "arm.xml"
    path.write_text(
        f"""<mujoco><worldbody><body name="link" pos="0 0 1">
             <joint name="hinge" type="hinge" axis="0 1 0"/>
             <inertial pos="0 0 -0.5" {inertial}/>
           </body></worldbody></mujoco>""",
        encoding="utf-8",
    )
    with pytest.raises(ValueError) as error:
        pinsettle.solve(pinsettle.load_scene(path))
    for word in words:
        assert word in str(error.value), str(error.value)

"""The contacts of a model file: an MJCF file's floors and geoms by default (``contacts =
"none"``, ``--no-contacts`` leave them out), a URDF's collision shapes on a floor (``--floor``,
``[model] floor``). Each rest on a floor is checked by its contact forces: the floor carries
the weight to 1e-9, no gap below -1e-6 m, the box's centre half its height above the floor."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinsettle
import pytest

ROBOTS = Path(__file__).parents[1] / "robots"
MASS = 2.0  # kg
SIZE = (0.3, 0.2, 0.1)  # m

BOX_URDF = f"""<?xml version="1.0"?>
<robot name="crate">
  <link name="crate">
    <inertial>
      <mass value="{MASS}"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.025"/>
    </inertial>
    <collision><geometry><box size="{" ".join(str(x) for x in SIZE)}"/></geometry></collision>
  </link>
</robot>
"""


def solve_json(*args: str) -> dict:
    proc = subprocess.run(
        [sys.executable, "-m", "pinsettle", "solve", *args, "--json"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode in (0, 1), proc.stderr
    out: dict = json.loads(proc.stdout)
    return out


def assert_rests_on_the_floor(out: dict, weight: float, floor_z: float) -> None:
    assert out["status"] == "converged", out["reason"]
    contacts = out["contacts"]
    assert contacts and all(c["ground"] == "floor" for c in contacts)
    load = sum(c["normal_force"] * c["normal"][2] for c in contacts)
    assert abs(load - weight) <= 1e-9 * weight, (load, weight)
    assert min(c["gap"] for c in contacts) >= -1e-6
    assert all(abs(c["point"][2] - floor_z) <= 1e-6 for c in contacts)


@pytest.fixture
def box(tmp_path: Path) -> Path:
    path = tmp_path / "crate.urdf"
    path.write_text(BOX_URDF, encoding="utf-8")
    return path


def test_urdf_on_a_floor_under_it(box: Path) -> None:
    # Under its lowest collision point at the start (neutral: the centre at 0).
    out = solve_json(str(box), "--floating", "--floor")
    assert_rests_on_the_floor(out, MASS * 9.81, -SIZE[2] / 2)
    assert len(out["contacts"]) == 4  # the box's four bottom corners
    assert abs(out["joints"]["root_joint"][2]) < 1e-6
    # At a height: it falls onto it, its centre half its height above.
    out = solve_json(str(box), "--floating", "--floor", "-0.5", "--contacts", "collision")
    assert_rests_on_the_floor(out, MASS * 9.81, -0.5)
    assert abs(out["joints"]["root_joint"][2] - (-0.5 + SIZE[2] / 2)) < 1e-6


def test_urdf_floor_in_python_and_in_a_scene_file(box: Path, tmp_path: Path) -> None:
    scene = pinsettle.load_scene(box, floating=True, floor=-0.2)
    assert [g.name for g in scene.grounds] == ["floor"] and len(scene.contacts) == 8
    result = pinsettle.solve(scene)
    assert result.converged
    toml = tmp_path / "crate.toml"
    toml.write_text('[model]\nurdf = "crate.urdf"\nfloating = true\nfloor = -0.2\n')
    from_file = pinsettle.solve(pinsettle.load_scene(toml))
    assert np.abs(from_file.q - result.q).max() < 1e-12
    assert abs(result.q[2] - (-0.2 + SIZE[2] / 2)) < 1e-6
    # floor = true: under the lowest point at the start; a URDF without floor takes none.
    toml.write_text('[model]\nurdf = "crate.urdf"\nfloating = true\nfloor = true\n')
    assert pinsettle.load_scene(toml).grounds[0].point == (0.0, 0.0, -SIZE[2] / 2)
    toml.write_text('[model]\nurdf = "crate.urdf"\nfloating = true\n')
    assert not pinsettle.load_scene(toml).contacts
    # The floor sits under the start pose that [start] sets.
    toml.write_text(
        '[model]\nurdf = "crate.urdf"\nfloating = true\nfloor = true\n'
        "[start]\nroot_joint = [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0]\n"
    )
    assert pinsettle.load_scene(toml).grounds[0].point[2] == pytest.approx(1.0 - SIZE[2] / 2)


def test_mjcf_floor_by_default_in_a_scene_file(tmp_path: Path) -> None:
    # robots/mjcf_ant.toml says contacts = "collision"; without the key the same rest, with
    # contacts = "none" no floor: the ant falls.
    ant = ROBOTS / "mjcf_ant.xml"
    toml = tmp_path / "ant.toml"
    toml.write_text(f'[model]\nmjcf = "{ant}"\n')
    default = pinsettle.load_scene(toml)
    assert [g.name for g in default.grounds] == ["floor"] and len(default.contacts) == 25
    explicit = pinsettle.load_scene(ROBOTS / "mjcf_ant.toml")
    first, second = pinsettle.solve(default), pinsettle.solve(explicit)
    assert first.converged and np.abs(first.q - second.q).max() < 1e-12
    assert pinsettle.load_scene(ant).contacts == default.contacts  # the file alone too
    toml.write_text(f'[model]\nmjcf = "{ant}"\ncontacts = "none"\n')
    bare = pinsettle.load_scene(toml)
    assert not bare.grounds and not bare.contacts
    assert any("play no part" in note for note in bare.notes)
    assert pinsettle.solve(bare).status == "no_equilibrium"
    # [[ground]] tables replace the file's floors; the geoms are still the contacts.
    toml.write_text(
        f'[model]\nmjcf = "{ant}"\n[[ground]]\npoint = [0.0, 0.0, -0.1]\nname = "low"\n'
    )
    lowered = pinsettle.load_scene(toml)
    assert [g.name for g in lowered.grounds] == ["low"] and len(lowered.contacts) == 25
    # A floor replaces them too.
    low = pinsettle.load_scene(ant, floor=-0.3)
    assert [(g.name, g.point[2]) for g in low.grounds] == [("floor", -0.3)]


def test_mjcf_without_a_floor_takes_no_contacts(tmp_path: Path) -> None:
    path = tmp_path / "arm.xml"
    path.write_text(
        '<mujoco><worldbody><body name="link"><joint name="hinge" axis="0 1 0"/>'
        '<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02"/></body></worldbody></mujoco>'
    )
    scene = pinsettle.load_scene(path)
    assert not scene.contacts and not scene.grounds
    assert pinsettle.solve(scene).converged

"""Box grounds: a table, a turned block, a wall.

Each rest is checked with tests/contact_reference.py (its own gap and normal of a sphere on a
box, the balance recomputed with Pinocchio's Jacobians, the cones) and against closed forms.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinsettle
import pytest
from contact_reference import check_rest, read_listed_contacts
from contact_reference import scene_parts as parts

ROBOTS = Path(__file__).parents[1] / "robots"
G = 9.81
MASS = 1.0  # free_body.urdf and pendulum.urdf
CORNERS = [(x, y, -0.05) for x in (-0.1, 0.1) for y in (-0.05, 0.05)]
ALL_CORNERS = [(x, y, z) for x in (-0.1, 0.1) for y in (-0.05, 0.05) for z in (-0.05, 0.05)]


def assert_rest(scene: pinsettle.Scene, result: pinsettle.Result):
    assert result.status == "converged", result.reason
    planes, spheres = parts(scene)
    check = check_rest(scene.model, result.q, planes, spheres, result.contacts)
    assert check.balance <= 1e-9 * check.scale
    assert check.worst_cone <= 1e-9 * check.scale
    assert check.min_gap >= -1e-6 and check.worst_touch <= 1e-6
    return check


def body_on_a_block(theta: float, mu: float = 0.5, corners=CORNERS) -> pinsettle.Scene:
    """free_body.urdf (0.2 x 0.1 x 0.1 m) on `corners`, 2 cm above the top face of a 2 x 1 x
    0.2 m block centred at the origin, the block turned by theta (rad) about y, the body level
    with its face."""
    scene = pinsettle.load_scene(ROBOTS / "free_fall.toml")
    scene.add_ground(box=(2.0, 1.0, 0.2), rpy=(0.0, -theta, 0.0), friction=mu, name="block")
    for corner in corners:
        scene.add_contact("body", corner)
    up = np.array([-math.sin(theta), 0.0, math.cos(theta)])
    scene.set_start(
        root_joint=[
            *((0.1 + 0.05 + 0.02) * up),
            math.cos(-theta / 2),
            0.0,
            math.sin(-theta / 2),
            0.0,
        ]
    )
    return scene


def test_a_body_on_a_table_carries_a_quarter_of_its_weight_at_each_corner():
    scene = pinsettle.load_scene(ROBOTS / "free_fall.toml")
    # A table top 0.05 m thick, its top face at 0.425 m.
    scene.add_ground((0.1, -0.05, 0.4), box=(1.2, 0.6, 0.05), friction=0.5, name="table")
    for corner in CORNERS:
        scene.add_contact("body", corner)
    scene.set_start(root_joint=[0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0])
    result = pinsettle.solve(scene)
    check = assert_rest(scene, result)
    assert len(result.contacts) == 4
    for c in result.contacts:
        assert c.ground == "table"
        assert c.normal_force == pytest.approx(MASS * G / 4, rel=1e-9)
        assert c.normal == pytest.approx([0.0, 0.0, 1.0], abs=1e-12)
    assert check.total_normal == pytest.approx([0.0, 0.0, MASS * G], rel=1e-9)
    # Its centre 0.05 m above the table's top, level.
    assert result.q[2] == pytest.approx(0.425 + 0.05, abs=1e-6)
    assert result.stability == "stable"


@pytest.mark.parametrize("tan_theta", [0.2, 0.45])
def test_a_body_sticks_on_a_turned_block_no_steeper_than_the_friction_allows(tan_theta):
    theta = math.atan(tan_theta)
    scene = body_on_a_block(theta)
    result = pinsettle.solve(scene)
    check = assert_rest(scene, result)
    n = np.array([-math.sin(theta), 0.0, math.cos(theta)])
    up = np.array([math.cos(theta), 0.0, math.sin(theta)])
    assert check.total_normal == pytest.approx(MASS * G * math.cos(theta) * n, abs=1e-9)
    assert check.total_tangential == pytest.approx(MASS * G * math.sin(theta) * up, abs=1e-9)
    assert all(c.sticking for c in result.contacts)
    assert result.stability == "stable"


def test_a_body_slides_off_a_block_steeper_than_the_friction_allows_onto_the_floor():
    # tan(theta) = 0.55 > mu = 0.5: it slides down the face, off the block's lower end, and
    # lands on a floor 1 m below (tumbling: all eight corners can touch), where it rests on
    # one of its faces, clear of the block.
    scene = body_on_a_block(math.atan(0.55), corners=ALL_CORNERS)
    scene.add_ground((0.0, 0.0, -1.0), friction=0.5, name="floor")
    result = pinsettle.solve(scene)
    check = assert_rest(scene, result)
    assert {c.ground for c in result.contacts} == {"floor"}
    assert check.total_normal == pytest.approx([0.0, 0.0, MASS * G], rel=1e-9)
    # On a long face (its centre 0.05 m up) or an end (0.1 m up).
    height = result.q[2] + 1.0
    assert min(abs(height - 0.05), abs(height - 0.1)) <= 1e-6
    assert result.q[0] < 0.0  # it went down the slope
    assert result.stability == "stable"


def pendulum_at_a_wall(mu: float = 0.0) -> pinsettle.Scene:
    """pendulum.urdf (a 1 kg bob 1 m below a hinge about y) with a sphere of 0.05 m at its bob,
    released at 0.6 rad (the bob at x = -0.565 m) towards a block whose face x = -0.3 m stands
    in its way."""
    scene = pinsettle.load_scene(ROBOTS / "pendulum.toml")
    scene.add_ground((0.2, 0.0, -1.0), box=(1.0, 0.5, 0.5), friction=mu, name="wall")
    scene.add_contact("arm", (0.0, 0.0, -1.0), 0.05, name="bob")
    scene.set_start(hinge=0.6)
    return scene


def test_a_pendulum_rests_against_a_blocks_side_face():
    scene = pendulum_at_a_wall()
    result = pinsettle.solve(scene)
    assert_rest(scene, result)
    # The bob's sphere touches the face x = -0.3: -sin(theta) + 0.05 = -0.3.
    theta = math.asin(0.35)
    assert result.q[0] == pytest.approx(theta, abs=1e-6)
    (c,) = result.contacts
    assert c.normal == pytest.approx([-1.0, 0.0, 0.0], abs=1e-12)
    # The rod's tension and the bob's weight leave m g tan(theta) to the wall.
    assert c.normal_force == pytest.approx(MASS * G * math.tan(theta), rel=1e-6)
    assert result.stability == "stable"


def test_a_box_ground_in_a_scene_file_reads_as_the_scene_api(tmp_path):
    path = tmp_path / "table.toml"
    path.write_text(
        f'[model]\nurdf = "{ROBOTS / "free_body.urdf"}"\nfloating = true\n\n'
        "[start]\nroot_joint = [0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0]\n\n"
        '[[ground]]\nname = "table"\npoint = [0.0, 0.0, 0.4]\nbox = [1.2, 0.6, 0.05]\n'
        "rpy = [0.0, 0.0, 0.3]\nfriction = 0.6\n"
        + "".join(f'\n[[contact]]\nframe = "body"\npoint = {list(c)}\n' for c in CORNERS),
        encoding="utf-8",
    )
    scene = pinsettle.load_scene(path)
    (ground,) = scene.grounds
    assert ground.box == (1.2, 0.6, 0.05) and ground.rpy == (0.0, 0.0, 0.3)
    result = pinsettle.solve(scene)
    planes, spheres = read_listed_contacts(path)
    check = check_rest(scene.model, result.q, planes, spheres, result.contacts)
    assert result.status == "converged"
    assert check.balance <= 1e-9 * check.scale and check.min_gap >= -1e-6
    assert result.q[2] == pytest.approx(0.425 + 0.05, abs=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"box": (1.0, 0.0, 1.0)}, ["box", "> 0", "0.0"]),
        ({"box": (1.0, 1.0)}, ["box", "3 entries"]),
        ({"box": (1.0, 1.0, 1.0), "normal": (0, 0, 1)}, ["normal", "rpy", "box"]),
        ({"rpy": (0.0, 0.1, 0.0)}, ["rpy", "box"]),
        ({"box": (1.0, 1.0, 1.0), "rpy": (0.0, float("nan"), 0.0)}, ["rpy[1]", "finite"]),
    ],
)
def test_a_bad_box_ground_is_refused_naming_its_key(kwargs, words):
    scene = pinsettle.load_scene(ROBOTS / "free_fall.toml")
    with pytest.raises(pinsettle.SceneError) as error:
        scene.add_ground(**kwargs)
    for word in words:
        assert word in str(error.value)


def test_a_bad_box_in_a_scene_file_names_the_table(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(
        f'[model]\nurdf = "{ROBOTS / "free_body.urdf"}"\nfloating = true\n\n'
        '[[ground]]\nbox = [1.0, -1.0, 1.0]\n\n[[contact]]\nframe = "body"\n',
        encoding="utf-8",
    )
    with pytest.raises(pinsettle.SceneError, match=r"\[\[ground\]\] #1.*box"):
        pinsettle.load_scene(path)

"""An MJCF file's world box geoms as box grounds (Scene.add_collision_contacts, contacts =
"collision"): placed, sized and turned as MuJoCo compiles them, with the floors' friction rule,
a block resting on one in closed form and where MuJoCo's own damped settle puts it.

MuJoCo is the judge of the MJCF checks: they skip without it, except where
PINSETTLE_REQUIRE_MUJOCO=1 (CI), where its absence fails.
"""

from __future__ import annotations

import numpy as np
import pinocchio
import pinsettle
import pytest

G = 9.81


def write(tmp_path, world: str, bodies: str, name: str = "file.xml"):
    path = tmp_path / name
    path.write_text(
        f"<mujoco>\n  <worldbody>\n{world}\n{bodies}\n  </worldbody>\n</mujoco>\n",
        encoding="utf-8",
    )
    return path


BALL = '<body name="ball" pos="0 0 2"><freejoint/><geom name="ball" size="0.05"/></body>'


def collision_scene(path) -> pinsettle.Scene:
    scene = pinsettle.Scene.from_mjcf(path)
    scene.add_collision_contacts()
    return scene


# --- where a box ground is --------------------------------------------------------------------


PLACED = 'size="0.4 0.3 0.1" pos="0.5 -0.2 0.1"'


@pytest.mark.parametrize(
    "placement",
    [
        PLACED,
        f'{PLACED} euler="10 -20 35"',
        f'{PLACED} quat="0.9 0.1 -0.3 0.2"',
        f'{PLACED} axisangle="1 2 -0.5 40"',
        f'{PLACED} xyaxes="1 0.3 0 -0.2 1 0.4"',
        f'{PLACED} zaxis="0.2 -0.3 1"',
        'size="0.05" fromto="0 0 0.1  1 0.5 0.1"',  # a beam: 0.1 x 0.1, along the segment
    ],
)
def test_a_world_box_is_a_ground_placed_as_mujoco_compiles_it(tmp_path, mujoco, placement):
    box = f'<geom name="step" type="box" {placement}/>'
    path = write(tmp_path, box, BALL)
    (ground,) = collision_scene(path).grounds
    mj = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(mj)
    mujoco.mj_forward(mj, data)
    g = mj.geom("step").id
    # MuJoCo's sizes are half sizes; its orientation is float64 after compiling.
    assert ground.name == "step" and ground.box == pytest.approx(2 * mj.geom_size[g], abs=1e-12)
    assert ground.point == pytest.approx(data.geom_xpos[g], abs=1e-12)
    rotation = data.geom_xmat[g].reshape(3, 3)
    assert np.allclose(ground.rotation(), rotation, atol=1e-9)
    assert np.allclose(ground.normal, rotation[:, 2], atol=1e-9)
    assert ground.friction == 1.0  # MuJoCo's default, the ball's and the box's


def test_only_colliding_world_boxes_are_grounds(tmp_path):
    world = """
    <geom name="floor" type="plane" size="2 2 0.1"/>
    <geom name="marker" type="box" size="0.1 0.1 0.1" contype="0" conaffinity="0"/>
    <geom name="post" type="cylinder" size="0.05 0.5" pos="1 0 0.5"/>
    <geom name="table" type="box" size="0.5 0.5 0.2" pos="-1 0 0.2"/>"""
    scene = collision_scene(write(tmp_path, world, BALL))
    # The scenery box (collides with nothing) is left out; the cylinder is noted, as before.
    assert [(g.name, g.box) for g in scene.grounds] == [
        ("floor", None),
        ("table", pytest.approx((1.0, 1.0, 0.4))),
    ]
    assert any("world geoms post are not planes or boxes: not grounds" in n for n in scene.notes)
    assert not any("marker" in n for n in scene.notes)
    # Without contacts = "collision", both floors are noted and left out.
    plain = pinsettle.Scene.from_mjcf(write(tmp_path, world, BALL))
    assert not plain.grounds
    assert any("(plane and box geoms)" in n and "play no part" in n for n in plain.notes)


def test_a_geom_colliding_with_the_floor_but_not_the_box_is_an_error(tmp_path):
    world = """
    <geom name="floor" type="plane" size="2 2 0.1"/>
    <geom name="table" type="box" size="0.5 0.5 0.2" pos="-1 0 0.2" contype="2" conaffinity="2"/>"""
    scene = pinsettle.Scene.from_mjcf(write(tmp_path, world, BALL))
    message = "'ball': collides with floor floor but not with table"
    with pytest.raises(pinsettle.SceneError, match=message):
        scene.add_collision_contacts()


def test_floors_false_leaves_the_world_boxes_out(tmp_path):
    world = '<geom name="table" type="box" size="0.5 0.5 0.2" pos="0 0 0.2"/>'
    scene = pinsettle.Scene.from_mjcf(write(tmp_path, world, BALL))
    scene.add_ground()
    scene.add_collision_contacts(floors=False)
    assert [g.name for g in scene.grounds] == ["ground1"]


# --- a block on a table ---------------------------------------------------------------------

TOP = 0.4  # the table's top face (z)
HALF = (0.1, 0.05, 0.05)  # the block's half sides
TABLE_WORLD = f"""
    <geom name="floor" type="plane" size="3 3 0.1"/>
    <geom name="table" type="box" size="0.4 0.3 {TOP / 2}" pos="0.3 0.1 {TOP / 2}" euler="0 0 30"
          friction="0.6" priority="1"/>"""
TABLE_BODIES = f"""
    <body name="block" pos="0.3 0.1 0.5" euler="0 0 10">
      <freejoint name="block"/>
      <geom name="block" type="box" size="{HALF[0]} {HALF[1]} {HALF[2]}" mass="1"/>
    </body>
    <body name="ball" pos="-0.7 0 0.1">
      <freejoint name="ball"/>
      <geom name="ball" type="sphere" size="0.05" mass="0.5"/>
    </body>"""


def test_a_block_dropped_on_a_world_table_rests_on_its_top(tmp_path, mujoco):
    path = write(tmp_path, TABLE_WORLD, TABLE_BODIES)
    scene = collision_scene(path)
    floor, table = scene.grounds
    assert (floor.box, table.box) == (None, pytest.approx((0.8, 0.6, TOP)))
    assert table.friction == 0.6  # the table's priority: its friction, not the block's 1
    assert table.rpy == pytest.approx((0.0, 0.0, np.radians(30)), abs=1e-12)
    result = pinsettle.solve(scene)
    assert result.converged
    assert result.stability == "neutral"  # the ball rolls on the floor at no cost
    # The block's four lower corners on the table, the ball on the floor.
    on = {c.name: c.ground for c in result.contacts}
    assert sorted(on.values()) == ["floor", *["table"] * 4] and on["ball"] == "floor"
    for c in result.contacts:
        assert c.normal == pytest.approx((0.0, 0.0, 1.0), abs=1e-12)
    carried = {
        g: sum(c.normal_force for c in result.contacts if c.ground == g) for g in ("floor", "table")
    }
    assert carried["table"] == pytest.approx(1.0 * G, rel=1e-9)
    assert carried["floor"] == pytest.approx(0.5 * G, rel=1e-9)
    mass = pinocchio.computeTotalMass(scene.model)
    total = sum(np.asarray(c.normal) * c.normal_force for c in result.contacts)
    assert total == pytest.approx(-mass * scene.model.gravity.linear, rel=1e-9, abs=1e-9)
    # Closed form: the block's centre a half height above the table's top, level; the ball's
    # centre a radius above the floor.
    block, ball = scene.model.getJointId("block"), scene.model.getJointId("ball")
    block_q = result.q[scene.model.idx_qs[block] :][:7]
    ball_q = result.q[scene.model.idx_qs[ball] :][:7]
    assert block_q[2] == pytest.approx(TOP + HALF[2], abs=1e-6)
    assert ball_q[2] == pytest.approx(0.05, abs=1e-6)
    level = pinocchio.Quaternion(block_q[6], *block_q[3:6]).matrix()[:, 2]
    assert level == pytest.approx((0.0, 0.0, 1.0), abs=1e-6)
    # MuJoCo's damped settle of the same file: within its soft contacts' sinking of ours.
    mj = mujoco.MjModel.from_xml_path(str(path))
    mj.dof_damping[:] = 2.0
    data = mujoco.MjData(mj)
    while data.time < 4.0:
        mujoco.mj_step(mj, data)
    assert np.abs(data.qvel).max() < 1e-3
    table_id = mj.geom("table").id
    frictions = [
        float(data.contact[i].friction[0])
        for i in range(data.ncon)
        if table_id in (data.contact[i].geom1, data.contact[i].geom2)
    ]
    assert len(frictions) >= 4 and frictions == pytest.approx([0.6] * len(frictions))
    for joint, ours in ((block, block_q), (ball, ball_q)):
        adr = mj.jnt_qposadr[mj.joint(scene.model.names[joint]).id]
        assert np.abs(data.qpos[adr : adr + 3] - ours[:3]).max() < 3e-3

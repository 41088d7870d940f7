"""Payloads (``[[payload]]``, ``Scene.add_payload``): a mass's weight at a point of a frame.

Each rest is checked with Pinocchio outside pinsettle: the arm's gravity torque balanced by the
payload's weight m g at its point (its Jacobian from a frame added there) and the joint spring.
The sweep key ``payload.FRAME.mass`` addresses a [[payload]] table's mass.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest
from pinsettle._scene import Payload

ROBOTS = Path(__file__).parents[1] / "robots"
PLANAR = ROBOTS / "planar_3link.urdf"
STIFFNESS = 30.0  # N m/rad, on joint2 (rest 0)
OFFSET = (0.15, 0.0, -0.4)  # m, in link3's axes: beside the link, near its tip
MASS = 2.5  # kg

SCENE = f"""# A planar 3-link arm carrying a payload beside its last link
[model]
urdf = "{PLANAR}"

[start]
joint1 = 0.3

[[joint_spring]]
joint = "joint2"
stiffness = {STIFFNESS}

[[payload]]
frame = "link3"
mass = {MASS}
offset = [{", ".join(str(x) for x in OFFSET)}]
"""


def pinocchio_residual(
    q: np.ndarray, mass: float, offset: tuple[float, ...], gravity: np.ndarray | None = None
) -> tuple[float, float]:
    """max |g(q) - J_p(q)^T m g - tau_spring(q)| and the largest of its terms, with Pinocchio
    alone: the payload's point a frame of its own on link3, its world-aligned Jacobian."""
    model = pinocchio.buildModelFromUrdf(str(PLANAR))
    if gravity is not None:
        model.gravity = pinocchio.Motion(np.array(gravity, dtype=float), np.zeros(3))
    link = model.getFrameId("link3")
    parent = model.frames[link]
    at = parent.placement * pinocchio.SE3(np.eye(3), np.array(offset, dtype=float))
    point = model.addFrame(
        pinocchio.Frame("payload_point", parent.parentJoint, link, at, pinocchio.FrameType.OP_FRAME)
    )
    data = model.createData()
    g = pinocchio.computeGeneralizedGravity(model, data, q)
    pinocchio.computeJointJacobians(model, data, q)
    pinocchio.updateFramePlacements(model, data)
    jac = pinocchio.getFrameJacobian(model, data, point, pinocchio.LOCAL_WORLD_ALIGNED)[:3]
    weight = jac.T @ (mass * model.gravity.linear)
    spring = np.zeros(model.nv)
    spring[model.idx_vs[model.getJointId("joint2")]] = -STIFFNESS * q[1]
    residual = g - weight - spring
    # The scale: the terms, or at least the largest gravity torque the arm (3 kg, 1.5 m) and
    # the payload can exert (a rest hanging straight down has all its terms near zero).
    reach = 1.5 + float(np.linalg.norm(offset))
    most = float(np.linalg.norm(model.gravity.linear)) * (3.0 + mass) * reach
    scale = max(np.abs(g).max(), np.abs(weight).max(), np.abs(spring).max(), most)
    return float(np.abs(residual).max()), float(scale)


@pytest.fixture
def scene_file(tmp_path: Path) -> Path:
    path = tmp_path / "payload.toml"
    path.write_text(SCENE, encoding="utf-8")
    return path


def test_payload_at_an_offset_rests_where_pinocchio_balances_it(scene_file: Path) -> None:
    scene = pinsettle.load_scene(scene_file)
    assert scene.payloads == [Payload("link3", MASS, OFFSET)]
    result = pinsettle.solve(scene)
    assert result.converged and result.stability == "stable", result.summary()
    residual, scale = pinocchio_residual(result.q, MASS, OFFSET)
    assert residual < 1e-9 * scale, (residual, scale)
    assert abs(scene.residual(result.q)) < 1e-9 * scale
    # The payload and its offset matter: the rest without it, or at the frame's origin, is
    # another pose, which Pinocchio's balance with this payload refuses.
    for other in (pinsettle.Scene.from_urdf(PLANAR), pinsettle.load_scene(scene_file)):
        if not other.payloads:
            other.add_joint_spring("joint2", STIFFNESS)
        else:
            other.payloads = [Payload("link3", MASS, (0.0, 0.0, 0.0))]
        other.set_start(joint1=0.3)
        moved = pinsettle.solve(other)
        assert moved.converged
        assert np.abs(moved.q - result.q).max() > 1e-2
        assert pinocchio_residual(moved.q, MASS, OFFSET)[0] > 1e-3 * scale


def test_payload_weight_follows_the_gravity(scene_file: Path) -> None:
    scene = pinsettle.load_scene(scene_file)
    scene.gravity = [1.5, 0.0, -4.0]
    result = pinsettle.solve(scene)
    assert result.converged, result.summary()
    residual, scale = pinocchio_residual(result.q, MASS, OFFSET, np.array([1.5, 0.0, -4.0]))
    assert residual < 1e-9 * scale, (residual, scale)


def test_the_sweep_key_addresses_the_payload_table(scene_file: Path) -> None:
    pytest.importorskip("pandas")
    scene = pinsettle.load_scene(scene_file)
    masses = [0.5, 2.0, 6.0]
    df = pinsettle.sweep(scene, {"payload.link3.mass": masses}, progress=False)
    assert list(df["status"]) == ["converged"] * 3
    tips = []
    for mass, (_, row) in zip(masses, df.iterrows(), strict=True):
        q = np.array([row["joint1"], row["joint2"], row["joint3"]])
        residual, scale = pinocchio_residual(q, mass, OFFSET)  # the table's offset kept
        assert residual < 1e-9 * scale, (mass, residual, scale)
        tips.append(q)
    assert np.abs(tips[0] - tips[2]).max() > 1e-2  # a heavier payload moves the arm
    # Its offset by index, as a vector; the same table (one payload, none added).
    offsets = [(0.05, 0.0, -0.5), (-0.1, 0.0, -0.3)]
    df = pinsettle.sweep(scene, {"payload[0].offset": offsets}, progress=False)
    for offset, (_, row) in zip(offsets, df.iterrows(), strict=True):
        q = np.array([row["joint1"], row["joint2"], row["joint3"]])
        residual, scale = pinocchio_residual(q, MASS, offset)
        assert residual < 1e-9 * scale, (offset, residual, scale)


def test_sweep_key_errors_on_payloads(scene_file: Path) -> None:
    pytest.importorskip("pandas")
    scene = pinsettle.load_scene(scene_file)
    scene.add_payload("link3", 1.0)
    with pytest.raises(ValueError, match=r"2 \[\[payload\]\] tables.*payload\[0\]\.mass"):
        pinsettle.sweep(scene, {"payload.link3.mass": [1.0]}, progress=False)
    with pytest.raises(ValueError, match=r"payload\[2\].*past the scene's 2 \[\[payload\]\]"):
        pinsettle.sweep(scene, {"payload[2].mass": [1.0]}, progress=False)
    with pytest.raises(ValueError, match=r"payload\[0\] is a payload: unknown field 'weight'"):
        pinsettle.sweep(scene, {"payload[0].weight": [1.0]}, progress=False)
    df = pinsettle.sweep(scene, {"payload[0].mass": [-1.0]}, progress=False)
    assert df["error"].str.contains("payload\\[0\\].mass: the mass must be >= 0").all()


@pytest.mark.parametrize(
    ("call", "fragments"),
    [
        (lambda s: s.add_payload("link9", 1.0), ["frame: unknown frame 'link9'", "link3"]),
        (lambda s: s.add_payload("universe", 1.0), ["'universe' is fixed to the world"]),
        (lambda s: s.add_payload("base", 1.0), ["'base' is fixed to the world"]),
        (lambda s: s.add_payload("link3", 0.0), ["mass must be > 0 (kg), got 0.0"]),
        (lambda s: s.add_payload("link3", -2.0), ["mass must be > 0 (kg), got -2.0"]),
        (lambda s: s.add_payload("link3", float("inf")), ["mass must be finite"]),
        (lambda s: s.add_payload("link3", "2 kg"), ["mass must be a number", "'2 kg'"]),
        (lambda s: s.add_payload("link3", 1.0, (0.0, 1.0)), ["offset must have 3 entries"]),
    ],
)
def test_add_payload_names_the_mistake(call, fragments) -> None:
    scene = pinsettle.Scene.from_urdf(PLANAR)
    with pytest.raises(pinsettle.SceneError) as info:
        call(scene)
    for fragment in fragments:
        assert fragment in str(info.value), (fragment, str(info.value))
    assert not scene.payloads  # nothing bad was kept

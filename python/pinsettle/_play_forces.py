"""What holds a rest, drawn in the playback: point loads as arrows, the loops' closure points as
balls, the reactions of the stops a joint rests on at the end as arrows; and the legend that
says what each mark is (shown in the overlay).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio

from ._play_meshes import _frame_id
from ._play_timeline import FPS, Timeline
from ._scene import Scene
from ._scene_values import PointLoad
from ._solve import Result

#: The marks' colours (flat, unlit: the same on screen whatever the light).
LOAD_COLOR = 0xC00000
LOOP_COLOR = 0x7048E8
STOP_COLOR = 0x2B8A3E
#: The longest load arrow, and every stop-reaction arrow, as a share of the view's size.
ARROW_LENGTH = 0.3
_Y = np.array([0.0, 1.0, 0.0])  # meshcat's cylinders stand along y


@dataclass(frozen=True)
class _Sizes:
    """The marks' dimensions (m), from the size of the view."""

    arrow: float
    shaft: float
    head: float
    ball: float

    @classmethod
    def of(cls, size: float) -> _Sizes:
        return cls(ARROW_LENGTH * size, 0.008 * size, 0.022 * size, 0.018 * size)


def _hex(color: int) -> str:
    return f"#{color:06x}"


def arrow_matrix(tail: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """The placement of an arrow (drawn along +y from its tail, of unit length) from ``tail``
    along ``vector``, scaled to its length."""
    length = float(np.linalg.norm(vector))
    direction = vector / length if length > 0 else _Y
    m = np.eye(4)
    rotation = pinocchio.Quaternion.FromTwoVectors(_Y, direction).matrix()
    m[:3, :3] = rotation @ np.diag([1.0, max(length, 1e-9), 1.0])
    m[:3, 3] = tail
    return m


def _load_arrow(node: Any, color: int, sizes: _Sizes) -> None:
    """An arrow of unit length along +y (its shaft and head scale with it; the head's share is
    fixed) under ``node``."""
    import meshcat.geometry as mg

    material = mg.MeshBasicMaterial(color=color)
    shaft, head = node["shaft"], node["head"]
    shaft.set_object(mg.Cylinder(0.8, radius=sizes.shaft), material)
    shaft.set_transform(pinocchio.SE3(np.eye(3), np.array([0.0, 0.4, 0.0])).homogeneous)
    head.set_object(mg.Cylinder(0.2, radiusTop=0.0, radiusBottom=sizes.head), material)
    head.set_transform(pinocchio.SE3(np.eye(3), np.array([0.0, 0.9, 0.0])).homogeneous)


def _frame_points(
    model: pinocchio.Model, qs: np.ndarray, ends: list[tuple[str, tuple[float, float, float]]]
) -> np.ndarray:
    """World positions (keys, ends, 3) of the points ``(frame, point)`` at each configuration."""
    data = model.createData()
    frames = [_frame_id(model, frame) for frame, _ in ends]
    out = np.zeros((len(qs), len(ends), 3))
    for k, q in enumerate(qs):
        pinocchio.framesForwardKinematics(model, data, q)
        for e, (frame, (_, point)) in enumerate(zip(frames, ends, strict=True)):
            out[k, e] = data.oMf[frame].act(np.asarray(point, dtype=float))
    return out


def point_loads(scene: Scene) -> list[PointLoad]:
    return [load for load in scene.loads if isinstance(load, PointLoad)]


def _drawn_loads(scene: Scene) -> list[PointLoad]:
    return [
        load
        for load in scene.loads
        if isinstance(load, PointLoad) and np.linalg.norm(load.force) > 0
    ]


def draw_loads(viz: Any, scene: Scene, timeline: Timeline, sizes: _Sizes, tracks: Any) -> None:
    """Each point load: an arrow from its point along its (world-aligned) force, the largest
    ``sizes.arrow`` long, the others in proportion; following the point."""
    loads = _drawn_loads(scene)
    if not loads:
        return
    at = _frame_points(viz.model, timeline.q, [(load.frame, load.point) for load in loads])
    largest = max(float(np.linalg.norm(load.force)) for load in loads)
    for i, load in enumerate(loads):
        node = viz.viewer[f"forces/load_{i}"]
        _load_arrow(node, LOAD_COLOR, sizes)
        vector = sizes.arrow * np.asarray(load.force, dtype=float) / largest
        matrices = np.array([arrow_matrix(p, vector) for p in at[:, i]])
        node.set_transform(matrices[-1])
        tracks.poses(node.path, matrices)


def draw_loops(viz: Any, scene: Scene, timeline: Timeline, sizes: _Sizes, tracks: Any) -> None:
    """Each loop's two closure points: a ball at each (b's larger), following its body
    (together when the loop is closed)."""
    import meshcat.geometry as mg

    n = len(scene.loops)
    ends = [(loop.a_frame, loop.a_point) for loop in scene.loops]
    ends += [(loop.b_frame, loop.b_point) for loop in scene.loops]
    if not ends:
        return
    at = _frame_points(viz.model, timeline.q, ends)
    material = mg.MeshBasicMaterial(color=LOOP_COLOR)
    for e in range(len(ends)):
        node = viz.viewer[f"forces/loop_{e % n}_{'ab'[e // n]}"]
        node.set_object(mg.Sphere(sizes.ball * (1.0 if e < n else 1.4)), material)
        matrices = np.tile(np.eye(4), (len(at), 1, 1))
        matrices[:, :3, 3] = at[:, e]
        node.set_transform(matrices[-1])
        tracks.poses(node.path, matrices)


def _joint_axis(model: pinocchio.Model, q: np.ndarray, joint: int) -> tuple[np.ndarray, str]:
    """The world direction of a 1-DoF joint's motion and its unit of effort: the rotation axis
    of a revolute joint ('N m'), the direction of a prismatic one ('N')."""
    data = model.createData()
    pinocchio.computeJointJacobians(model, data, q)
    column = pinocchio.getJointJacobian(
        model, data, joint, pinocchio.ReferenceFrame.LOCAL_WORLD_ALIGNED
    )[:, model.idx_vs[joint]]
    if np.linalg.norm(column[3:]) > 1e-9:
        return column[3:] / np.linalg.norm(column[3:]), "N m"
    return column[:3] / np.linalg.norm(column[:3]), "N"


def stop_reactions(scene: Scene, result: Result) -> list[tuple[str, np.ndarray, np.ndarray, str]]:
    """Each stop a joint rests on at the end: the joint, where it is (world), the reaction as
    a vector along its axis (a torque about it by the right-hand rule, or a force), the unit."""
    model = scene.model
    data = model.createData()
    pinocchio.forwardKinematics(model, data, result.q)
    out = []
    for name, side in result.at_limit.items():
        joint = model.getJointId(name)
        axis, unit = _joint_axis(model, result.q, joint)
        sign = 1.0 if side == "lower" else -1.0  # a lower stop pushes q up, an upper one down
        reaction = sign * result.limit_reactions.get(name, 0.0) * axis
        out.append((name, data.oMi[joint].translation.copy(), reaction, unit))
    return out


def draw_stops(
    viz: Any, scene: Scene, result: Result, timeline: Timeline, sizes: _Sizes, tracks: Any
) -> None:
    """The stops' reactions at the end: an arrow ``sizes.arrow`` long at the joint along the
    reaction (its axis, signed), shown once the motion is over."""
    end = timeline.duration * FPS
    for i, (_, at, reaction, _) in enumerate(stop_reactions(scene, result)):
        node = viz.viewer[f"forces/stop_{i}"]
        _load_arrow(node, STOP_COLOR, sizes)
        norm = float(np.linalg.norm(reaction))
        vector = sizes.arrow * reaction / norm if norm > 0 else sizes.arrow * _Y
        node.set_transform(arrow_matrix(at, vector))
        if end > 0:  # hidden while it moves: a stop holds it only at the end
            tracks.visibility(node.path, [0.0, end - 1e-6, end], np.array([False, False, True]))


def draw_forces(
    viz: Any, scene: Scene, result: Result, timeline: Timeline, size: float, tracks: Any
) -> None:
    """Point loads, loop closure points and stop reactions drawn (see the draw_ functions),
    their dimensions from the view's ``size`` (m), their motion added to ``tracks``."""
    sizes = _Sizes.of(size)
    draw_loads(viz, scene, timeline, sizes, tracks)
    draw_loops(viz, scene, timeline, sizes, tracks)
    draw_stops(viz, scene, result, timeline, sizes, tracks)


def forces_legend(scene: Scene, result: Result) -> list[dict[str, str]]:
    """What each kind of mark drawn is: ``{"color", "text"}`` (for the overlay)."""
    legend = []
    loads = _drawn_loads(scene)
    if loads:
        forces = ", ".join(f"{np.linalg.norm(load.force):.3g} N on {load.frame}" for load in loads)
        legend.append((LOAD_COLOR, f"arrow: point load, length by force ({forces})"))
    if scene.loops:
        legend.append(
            (LOOP_COLOR, "balls: loop closure points (a small, b large), met when closed")
        )
    reactions = stop_reactions(scene, result)
    if reactions:
        held = ", ".join(f"{name} {np.linalg.norm(r):.3g} {unit}" for name, _, r, unit in reactions)
        legend.append(
            (
                STOP_COLOR,
                f"arrow at the end: stop reaction, a torque by the right-hand rule ({held})",
            )
        )
    return [{"color": _hex(color), "text": text} for color, text in legend]

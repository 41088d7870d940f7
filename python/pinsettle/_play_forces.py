"""What holds a rest, drawn in the playback: point loads as arrows, the loops' closure points as
balls, the reactions of the stops a joint rests on at the end as arrows; and the legend that
says what each mark is (shown in the overlay).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio

from ._memory import new_data
from ._play_meshes import _frame_id
from ._play_timeline import FPS, Timeline
from ._scene import Scene
from ._scene_values import JointLoad, PointLoad
from ._solve import Result

#: The marks' colours (flat, unlit: the same on screen whatever the light).
LOAD_COLOR = 0xC00000
LOOP_COLOR = 0x7048E8
STOP_COLOR = 0x2B8A3E
JOINT_SPRING_COLOR = 0xF08C00
#: The longest load arrow, and every stop-reaction arrow, as a share of the view's size.
ARROW_LENGTH = 0.3
_Y = np.array([0.0, 1.0, 0.0])  # meshcat's cylinders stand along y
_Z = np.array([0.0, 0.0, 1.0])  # the coil of _helix along z


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


def _load_arrow(node: Any, color: int, sizes: _Sizes, *, double: bool = False) -> None:
    """An arrow of unit length along +y under ``node`` (its shaft and heads scale with it);
    ``double``: a second head behind the first (a torque, by the right-hand rule)."""
    import meshcat.geometry as mg

    material = mg.MeshBasicMaterial(color=color)
    heads = (0.9, 0.72) if double else (0.9,)
    shaft = node["shaft"]
    shaft.set_object(mg.Cylinder(0.8, radius=sizes.shaft), material)
    shaft.set_transform(pinocchio.SE3(np.eye(3), np.array([0.0, 0.4, 0.0])).homogeneous)
    for h, y in enumerate(heads):
        head = node[f"head_{h}"]
        head.set_object(mg.Cylinder(0.2, radiusTop=0.0, radiusBottom=sizes.head), material)
        head.set_transform(pinocchio.SE3(np.eye(3), np.array([0.0, y, 0.0])).homogeneous)


def _frame_points(
    model: pinocchio.Model, qs: np.ndarray, ends: list[tuple[str, tuple[float, float, float]]]
) -> np.ndarray:
    """World positions (keys, ends, 3) of the points ``(frame, point)`` at each configuration."""
    data = new_data(model, "playback")
    frames = [_frame_id(model, frame) for frame, _ in ends]
    out = np.zeros((len(qs), len(ends), 3))
    for k, q in enumerate(qs):
        pinocchio.framesForwardKinematics(model, data, q)
        for e, (frame, (_, point)) in enumerate(zip(frames, ends, strict=True)):
            out[k, e] = data.oMf[frame].act(np.asarray(point, dtype=float))
    return out


@dataclass(frozen=True)
class _Mark:
    """One load drawn: a force (one head) or a torque (two heads, a moment vector by the
    right-hand rule), its tail and its vector (N or N m, world) at each keyframe."""

    torque: bool
    tails: np.ndarray  # (keys, 3)
    vectors: np.ndarray  # (keys, 3)
    label: str


def _joint_axes(model: pinocchio.Model, qs: np.ndarray, joint: int) -> tuple[np.ndarray, bool]:
    """The world direction of a 1-DoF joint's motion at each configuration, and whether it
    turns (a revolute joint: its axis) or slides (a prismatic one: its direction)."""
    data = new_data(model, "playback")
    columns = np.zeros((len(qs), 6))
    for k, q in enumerate(qs):
        pinocchio.computeJointJacobians(model, data, q)
        frame = pinocchio.ReferenceFrame.LOCAL_WORLD_ALIGNED
        jacobian = np.reshape(pinocchio.getJointJacobian(model, data, joint, frame), (6, -1))
        columns[k] = jacobian[:, model.idx_vs[joint]]  # (a model of nv = 1 gives a vector)
    turns = bool(np.linalg.norm(columns[-1, 3:]) > 1e-9)
    axes = columns[:, 3:] if turns else columns[:, :3]
    return axes / np.linalg.norm(axes, axis=1, keepdims=True), turns


def _joint_origins(model: pinocchio.Model, qs: np.ndarray, joint: int) -> np.ndarray:
    data = new_data(model, "playback")
    out = np.zeros((len(qs), 3))
    for k, q in enumerate(qs):
        pinocchio.forwardKinematics(model, data, q)
        out[k] = data.oMi[joint].translation
    return out


def _point_load_marks(model: pinocchio.Model, qs: np.ndarray, load: PointLoad) -> list[_Mark]:
    """A point load's force and torque (world-aligned, constant) at its point."""
    tails = _frame_points(model, qs, [(load.frame, load.point)])[:, 0]
    marks = []
    for torque, value, unit in ((False, load.force, "N"), (True, load.torque, "N m")):
        vector = np.asarray(value, dtype=float)
        if np.linalg.norm(vector) > 0:
            label = f"{np.linalg.norm(vector):.3g} {unit} on {load.frame}"
            marks.append(_Mark(torque, tails, np.tile(vector, (len(qs), 1)), label))
    return marks


def _joint_load_marks(model: pinocchio.Model, qs: np.ndarray, load: JointLoad) -> list[_Mark]:
    """A joint load on a 1-DoF joint: its effort along the joint's axis (a torque about a
    revolute joint's, a force along a prismatic one's), at the joint."""
    joint = model.getJointId(load.joint)
    if model.joints[joint].nv != 1 or not any(load.effort):
        return []
    axes, turns = _joint_axes(model, qs, joint)
    label = f"{abs(load.effort[0]):.3g} {'N m' if turns else 'N'} at {load.joint}"
    return [_Mark(turns, _joint_origins(model, qs, joint), load.effort[0] * axes, label)]


def load_marks(model: pinocchio.Model, scene: Scene, qs: np.ndarray) -> list[_Mark]:
    """Every load of ``scene`` drawn, at the configurations ``qs`` (see ``_Mark``)."""
    marks: list[_Mark] = []
    for load in scene.loads:
        if isinstance(load, PointLoad):
            marks += _point_load_marks(model, qs, load)
        else:
            marks += _joint_load_marks(model, qs, load)
    return marks


def _undrawn_loads(model: pinocchio.Model, scene: Scene) -> list[str]:
    """The joints whose loads are not drawn: joint loads on joints of several degrees of
    freedom (a free body's wrench has no one axis)."""
    return [
        load.joint
        for load in scene.loads
        if isinstance(load, JointLoad) and model.joints[model.getJointId(load.joint)].nv != 1
    ]


def draw_loads(viz: Any, scene: Scene, timeline: Timeline, sizes: _Sizes, tracks: Any) -> None:
    """Each load: an arrow from its point along its force (a double-headed one along its
    torque), the largest force and the largest torque ``sizes.arrow`` long, the others in
    proportion; following the body."""
    marks = load_marks(viz.model, scene, timeline.q)
    for i, mark in enumerate(marks):
        node = viz.viewer[f"forces/load_{i}"]
        _load_arrow(node, LOAD_COLOR, sizes, double=mark.torque)
        scale = sizes.arrow / _largest_norm(marks, mark.torque)
        matrices = np.array(
            [arrow_matrix(t, scale * v) for t, v in zip(mark.tails, mark.vectors, strict=True)]
        )
        node.set_transform(matrices[-1])
        tracks.poses(node.path, matrices)


def _largest_norm(marks: list[_Mark], torque: bool) -> float:
    return max(
        (float(np.linalg.norm(m.vectors, axis=1).max()) for m in marks if m.torque == torque),
        default=1.0,
    )


def draw_joint_springs(
    viz: Any, scene: Scene, timeline: Timeline, sizes: _Sizes, tracks: Any
) -> None:
    """Each joint spring: a short coil at its joint, along the joint's axis, following it."""
    import meshcat.geometry as mg

    from ._play_meshes import _helix, _normal_mesh_class

    length = 0.4 * sizes.arrow
    coil = 2.5 * sizes.head
    mesh = _normal_mesh_class()(*_helix(coil, 0.25 * sizes.shaft / 0.8, length, coils=5))
    material = mg.MeshBasicMaterial(color=JOINT_SPRING_COLOR)
    for i, spring in enumerate(scene.joint_springs):
        joint = viz.model.getJointId(spring.joint)
        axes, _ = _joint_axes(viz.model, timeline.q, joint)
        origins = _joint_origins(viz.model, timeline.q, joint)
        node = viz.viewer[f"forces/joint_spring_{i}"]
        node.set_object(mesh, material)
        matrices = np.zeros((len(origins), 4, 4))
        for k, (origin, axis) in enumerate(zip(origins, axes, strict=True)):
            m = np.eye(4)
            m[:3, :3] = pinocchio.Quaternion.FromTwoVectors(_Z, axis).matrix()
            m[:3, :3] = m[:3, :3] @ np.diag([1.0, 1.0, length])
            m[:3, 3] = origin - 0.5 * length * axis  # centred on the joint
            matrices[k] = m
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


def stop_reactions(scene: Scene, result: Result) -> list[tuple[str, np.ndarray, np.ndarray, str]]:
    """Each stop a joint rests on at the end: the joint, where it is (world), the reaction as
    a vector along its axis (a torque about it by the right-hand rule, or a force), the unit."""
    model = scene.model
    data = new_data(model, "playback")
    pinocchio.forwardKinematics(model, data, result.q)
    out = []
    for name, side in result.at_limit.items():
        joint = model.getJointId(name)
        axes, turns = _joint_axes(model, result.q[None, :], joint)
        axis, unit = axes[0], "N m" if turns else "N"
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


def mark_tips(scene: Scene, result: Result, size: float) -> np.ndarray:
    """Where the arrows of the loads and the stops' reactions end in the final pose (world),
    drawn for a view of ``size`` (m): for the camera to frame them too."""
    sizes = _Sizes.of(size)
    marks = load_marks(scene.model, scene, result.q[None, :])
    tips = [m.tails[0] + sizes.arrow * m.vectors[0] / _largest_norm(marks, m.torque) for m in marks]
    reactions = [(at, r) for _, at, r, _ in stop_reactions(scene, result)]
    for at, reaction in reactions + loop_reactions(scene, result):
        norm = float(np.linalg.norm(reaction))
        tips.append(at + sizes.arrow * (reaction / norm if norm > 0 else _Y))
    return np.reshape(tips, (-1, 3))


def loop_reactions(scene: Scene, result: Result) -> list[tuple[np.ndarray, np.ndarray]]:
    """At a rest, each loop's reaction: where its closure point a is (world) and the force the
    closure exerts on a's body there (N, world; b's body gets the opposite). The static force
    of the open tree, less the stops' reactions, is what the closures take: J^T force = f
    (least squares: a planar loop's out-of-plane force is indeterminate, reported as 0). None
    unless the solve converged."""
    if not scene.loops or not result.converged:
        return []
    from . import _core

    compiled = scene.compile(result.q)
    model, q = compiled.model, result.q[compiled.q_index]
    assert compiled.loops is not None  # the scene has loops
    stops = np.zeros(model.nv)
    for name, side in result.at_limit.items():
        sign = 1.0 if side == "lower" else -1.0  # as in stop_reactions
        stops[model.idx_vs[model.getJointId(name)]] = sign * result.limit_reactions[name]
    force = _core.static_force(model, q, compiled.elements) - stops
    jacobian = _core.loops(model, q, compiled.loops)["jacobian"]
    multipliers = np.linalg.lstsq(jacobian.T, force, rcond=None)[0]
    ends = [(loop.a_frame, loop.a_point) for loop in scene.loops]
    at = _frame_points(scene.model, result.q[None, :], ends)[0]
    out, row = [], 0
    for i, loop in enumerate(scene.loops):  # rows: 3 for a point loop, 6 for a frame loop
        out.append((at[i], multipliers[row : row + 3]))
        row += 3 if loop.kind == "point" else 6
    return out


def draw_loop_reactions(
    viz: Any, scene: Scene, result: Result, timeline: Timeline, sizes: _Sizes, tracks: Any
) -> None:
    """Each loop's reaction at rest: an arrow ``sizes.arrow`` long at closure point a along
    the force on a's body, shown once the motion is over."""
    end = timeline.duration * FPS
    for i, (at, force) in enumerate(loop_reactions(scene, result)):
        norm = float(np.linalg.norm(force))
        if norm == 0:
            continue
        node = viz.viewer[f"forces/loop_reaction_{i}"]
        _load_arrow(node, LOOP_COLOR, sizes)
        node.set_transform(arrow_matrix(at, sizes.arrow * force / norm))
        if end > 0:  # hidden while it moves: the reaction is that of the rest
            tracks.visibility(node.path, [0.0, end - 1e-6, end], np.array([False, False, True]))


def draw_forces(
    viz: Any, scene: Scene, result: Result, timeline: Timeline, size: float, tracks: Any
) -> None:
    """Loads, joint springs, loop closure points and stop reactions drawn (see the draw_ functions),
    their dimensions from the view's ``size`` (m), their motion added to ``tracks``."""
    sizes = _Sizes.of(size)
    draw_loads(viz, scene, timeline, sizes, tracks)
    draw_joint_springs(viz, scene, timeline, sizes, tracks)
    draw_loops(viz, scene, timeline, sizes, tracks)
    draw_stops(viz, scene, result, timeline, sizes, tracks)
    draw_loop_reactions(viz, scene, result, timeline, sizes, tracks)


def _loads_text(scene: Scene, result: Result) -> str:
    marks = load_marks(scene.model, scene, result.q[None, :])
    forces = ", ".join(m.label for m in marks if not m.torque)
    torques = ", ".join(m.label for m in marks if m.torque)
    undrawn = ", ".join(_undrawn_loads(scene.model, scene))
    parts = [
        f"forces {forces}" if forces else "",
        f"double head: torques {torques}" if torques else "",
        f"not drawn: the effort on {undrawn}" if undrawn else "",
    ]
    what = "; ".join(p for p in parts if p)
    return f"arrow: load, length by size ({what})" if what else ""


def _joint_springs_text(scene: Scene, result: Result) -> str:
    springs = ", ".join(f"{s.joint} k = {s.stiffness:.3g}" for s in scene.joint_springs)
    return f"coil on a joint's axis: joint spring ({springs})" if springs else ""


def _loops_text(scene: Scene, result: Result) -> str:
    if not scene.loops:
        return ""
    text = "balls: loop closure points (a small, b large), met when closed"
    forces = [float(np.linalg.norm(force)) for _, force in loop_reactions(scene, result)]
    if forces:
        values = ", ".join(f"loop {i} {f:.3g} N" for i, f in enumerate(forces, start=1))
        text += f"; arrow at the end: force on a ({values})"
    return text


def _stops_text(scene: Scene, result: Result) -> str:
    reactions = stop_reactions(scene, result)
    held = ", ".join(f"{name} {np.linalg.norm(r):.3g} {unit}" for name, _, r, unit in reactions)
    what = "arrow at the end: stop reaction, a torque by the right-hand rule or a force"
    return f"{what} ({held})" if held else ""


#: The legend's entries: the colour of a kind of mark, what says what it is (or ""), and the
#: paths of its marks (as ``draw_forces`` names them).
_LEGEND = (
    (LOAD_COLOR, _loads_text, "forces/load_*"),
    (JOINT_SPRING_COLOR, _joint_springs_text, "forces/joint_spring_*"),
    (LOOP_COLOR, _loops_text, "forces/loop_*"),
    (STOP_COLOR, _stops_text, "forces/stop_*"),
)


def forces_legend(scene: Scene, result: Result) -> list[dict[str, Any]]:
    """What each kind of mark drawn is: ``{"color", "text", "nodes"}`` (for the overlay; see
    ``_play_animation.legend``)."""
    texts = ((color, text(scene, result), nodes) for color, text, nodes in _LEGEND)
    return [
        {"color": _hex(color), "text": text, "nodes": [nodes]}
        for color, text, nodes in texts
        if text
    ]

"""The playback in meshcat: the mechanism, its springs and the event flashes loaded into the
viewer (the forces that hold it from ``_play_forces``, the grounds and contacts from
``_play_contacts``), the camera placed, and the animation of all of it made.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio

from ._play_forces import _hex, draw_forces, forces_legend, mark_tips
from ._play_meshes import _decompose, _frame_id, _helix, _local_corners, _normal_mesh_class
from ._play_timeline import FPS, Timeline, _pulse
from ._scene import Scene
from ._solve import Result

_SPRING_COLOR = 0xE8590C
_END_COLOR = 0x343A40
_EVENT_COLORS = {"damping": 0xFFB000, "push": 0x1C7ED6, "rollback": 0xE03131, "impact": 0xD6336C}


#: A link whose joint hits a stop is drawn in this colour for ``FLASH_SECONDS``.
_IMPACT_COLOR = (0.93, 0.16, 0.42, 1.0)
_IMPACT_HEX = int.from_bytes(bytes(int(255 * c) for c in _IMPACT_COLOR[:3]), "big")
_CAMERA_DIRECTION = np.array([0.45, -1.0, 0.35])  # from the mechanism towards the camera
_CAMERA_FOV = 40.0  # degrees, vertical


def _camera_fit(points: np.ndarray, top: float = 0.0) -> tuple[np.ndarray, float, float]:
    """Where the camera looks, how far from there it stands (looking along
    -_CAMERA_DIRECTION with the vertical field of view _CAMERA_FOV, in a view at least 4:3
    wide) so that every point is seen with a margin below the share ``top`` of the view's
    height (left to the overlay), and the size of the cloud (m)."""
    back = _CAMERA_DIRECTION / np.linalg.norm(_CAMERA_DIRECTION)
    right = np.cross(-back, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -back)
    points = points[np.all(np.isfinite(points), axis=1)]
    if not points.size:
        points = np.zeros((1, 3))
    low, high = points.min(axis=0), points.max(axis=0)
    size = max(float(np.linalg.norm(high - low)), 0.05)
    middle = (low + high) / 2
    x, y, z = (points - middle) @ right, (points - middle) @ up, (points - middle) @ back
    margin = 0.06 * size
    half_x, half_y = (x.max() - x.min()) / 2 + margin, (y.max() - y.min()) / 2 + margin
    half_y /= 1 - top  # the view's half height: the cloud fills all but the top
    target = (
        middle + right * (x.max() + x.min()) / 2 + up * ((y.max() + y.min()) / 2 + top * half_y)
    )
    tan = math.tan(math.radians(_CAMERA_FOV) / 2)
    distance = float(z.max()) + max(half_y / tan, half_x / (tan * 4 / 3), 0.05)
    return target, distance, size


@dataclass
class _Keyframes:
    """Where everything is at each keyframe: each shape's placement (with its mesh scale), the
    springs' two ends, the centre of mass and each joint's origin (world, m)."""

    placements: np.ndarray  # (keys, shapes, 4, 4)
    ends: np.ndarray  # (keys, springs, 2, 3)
    com: np.ndarray  # (keys, 3)
    joint_at: np.ndarray  # (keys, joints, 3)


def _keyframes(viz: Any, scene: Scene, timeline: Timeline, visual: Any) -> _Keyframes:
    model, data, geometry_data = viz.model, viz.data, viz.visual_data
    frames_a = [_frame_id(model, s.a_frame) for s in scene.springs]
    frames_b = [_frame_id(model, s.b_frame) for s in scene.springs]
    n_keys = timeline.times.size
    out = _Keyframes(
        np.zeros((n_keys, visual.ngeoms, 4, 4)),
        np.zeros((n_keys, len(scene.springs), 2, 3)),
        np.zeros((n_keys, 3)),
        np.zeros((n_keys, model.njoints, 3)),
    )
    for k, q in enumerate(timeline.q):
        pinocchio.forwardKinematics(model, data, q)
        pinocchio.updateFramePlacements(model, data)
        pinocchio.updateGeometryPlacements(model, data, visual, geometry_data)
        for g, obj in enumerate(visual.geometryObjects):
            scale = np.diag([*obj.meshScale, 1.0])
            out.placements[k, g] = geometry_data.oMg[g].homogeneous @ scale
        for s, spring in enumerate(scene.springs):
            out.ends[k, s, 0] = data.oMf[frames_a[s]].act(np.array(spring.a_point))
            out.ends[k, s, 1] = data.oMf[frames_b[s]].act(np.array(spring.b_point))
        out.com[k] = pinocchio.centerOfMass(model, data, q, False)
        out.joint_at[k] = [placement.translation for placement in data.oMi]
    return out


def _view(
    keys: _Keyframes, visual: Any, marks: np.ndarray | None = None, top: float = 0.0
) -> tuple[np.ndarray, float, float]:
    """The camera's target and distance, and the size of the view (m): everything the
    animation shows (``marks``: more points of the final pose, e.g. the arrows' tips), or the
    final pose alone after a runaway; below the share ``top`` of the view's height."""
    scales = np.array([obj.meshScale for obj in visual.geometryObjects]).reshape(-1, 1, 3)
    corners = _local_corners(visual)  # (ngeoms, 8, 3): each shape's bounding box
    placements = keys.placements
    shapes = np.einsum("kgij,gcj->kgci", placements[:, :, :3, :3] / scales, corners)
    shapes += placements[:, :, None, :3, 3]
    cloud = [shapes, keys.ends.reshape(-1, 3), keys.com]
    everything = np.concatenate([c.reshape(-1, 3) for c in cloud])
    last = np.concatenate([shapes[-1].reshape(-1, 3), keys.ends[-1].reshape(-1, 3), keys.com[-1:]])
    if marks is not None:
        everything, last = np.concatenate([everything, marks]), np.concatenate([last, marks])
    target, distance, size = _camera_fit(everything, top)
    if size > 20 * _camera_fit(last)[2]:
        # A runaway (a body falling for kilometres): a view of the whole path would show a
        # speck; frame the final pose, which the animation holds.
        target, distance, size = _camera_fit(last, top)
    return target, distance, size


def _place_camera(viz: Any, target: np.ndarray, distance: float) -> None:
    """The view's centre at the origin (meshcat's camera, with orbit controls, looks there),
    the camera at ``distance`` along _CAMERA_DIRECTION, on a plain background."""
    shift = np.eye(4)
    shift[:3, 3] = -target
    viz.viewer.set_transform(shift)  # /meshcat/pinsettle
    viz.viewer["/Grid"].set_property("visible", False)
    viz.viewer["/Axes"].set_property("visible", False)
    viz.setBackgroundColor(col_top=[0.99, 0.99, 1.0], col_bot=[0.80, 0.83, 0.87])
    camera = viz.viewer["/Cameras/default/rotated/<object>"]
    eye = distance * _CAMERA_DIRECTION / np.linalg.norm(_CAMERA_DIRECTION)
    camera.set_property("fov", _CAMERA_FOV)
    camera.set_property("far", max(100.0, 20 * distance))
    camera.set_property("position", [float(eye[0]), float(eye[2]), float(-eye[1])])


class _Tracks:
    """The animation being made, with the keyframe times (frames at ``FPS`` a second of
    playback) and the clips' rate (``Timeline.clip_fps``: frames per simulated second)."""

    def __init__(self, timeline: Timeline) -> None:
        from meshcat.animation import Animation

        self.fps = timeline.clip_fps
        self.animation = Animation(default_framerate=self.fps)
        self.key_frames = (timeline.times * FPS).tolist()

    def poses(self, path: Any, matrices: np.ndarray, frames: list[float] | None = None) -> None:
        """The node at ``path`` placed by ``matrices`` at the keyframes (or at ``frames``);
        the scale only where it changes."""
        from meshcat.animation import AnimationClip, AnimationTrack

        frames = self.key_frames if frames is None else frames
        tracks: dict[str, list[list[float]]] = {"position": [], "quaternion": [], "scale": []}
        for matrix in matrices:
            position, quaternion, scale = _decompose(matrix)
            tracks["position"].append(position)
            tracks["quaternion"].append(quaternion)
            tracks["scale"].append(scale)
        clip = AnimationClip(fps=self.fps)
        for name, jstype in (("position", "vector3"), ("quaternion", "quaternion")):
            clip.tracks[name] = AnimationTrack(name, jstype, list(frames), tracks[name])
        if not np.allclose(tracks["scale"], 1.0):
            clip.tracks["scale"] = AnimationTrack("scale", "vector3", list(frames), tracks["scale"])
        self.animation.clips[path] = clip

    def visibility(self, path: Any, frames: list[float], shown: np.ndarray) -> None:
        _add_visibility(self.animation, path, frames, shown, self.fps)


def legend(scene: Scene, result: Result, timeline: Timeline) -> list[dict[str, Any]]:
    """What each kind of mark drawn is (for the overlay): the springs', the flashes' (those
    shown at some frame), the forces', and the grounds' and contacts' for a scene with
    grounds. Each entry: its swatch ``color``, its ``text`` and the ``nodes`` it stands for
    (patterns of the marks' paths under the playback's root, as ``fnmatch`` reads them)."""
    entries = _springs_legend(scene) + _flashes_legend(scene, timeline)
    entries += forces_legend(scene, result)
    if scene.grounds:  # imported only for a scene that has them
        from ._play_contacts import contacts_legend

        entries += contacts_legend(scene, result)
    return entries


def _springs_legend(scene: Scene) -> list[dict[str, Any]]:
    if not scene.springs:
        return []
    values = [f"k = {spring.stiffness:.3g} N/m" for spring in scene.springs]
    if len(values) > 1:
        values = [f"{s}: {value}" for s, value in enumerate(values)]
    text = f"coil between two dark balls: spring ({', '.join(values)})"
    return [{"color": _hex(_SPRING_COLOR), "text": text, "nodes": ["springs/*"]}]


#: What a flash marks, by kind of event.
_FLASH_TEXTS = {
    "damping": "ball at the centre of mass, fading out: a damping event",
    "push": "ball at the centre of mass, fading out: a push off an unstable rest",
    "rollback": "ball at the centre of mass, fading out: a roll-back (step halved)",
}


def _flashes_legend(scene: Scene, timeline: Timeline) -> list[dict[str, Any]]:
    """The flashes that show at some frame: a ball per kind of event, and the links (or
    joints) that hit a stop."""
    entries = []
    for kind in _flash_levels(timeline):
        text = f"{_FLASH_TEXTS[kind]} ({timeline.events[kind].size}; gone on the final pose)"
        color = _hex(_EVENT_COLORS[kind])
        entries.append({"color": color, "text": text, "nodes": [f"events/{kind}"]})
    hit = [scene.model.names[j] for j, _ in _impact_flashes(timeline, scene.model.njoints)]
    if hit:
        joints = ", ".join(hit)
        text = f"link flashing pink-red (or a ball at its joint): a joint hit a stop ({joints})"
        nodes = ["events/impact_*", "pinocchio/visuals/*_impact"]
        entries.append({"color": _hex(_IMPACT_HEX), "text": text, "nodes": nodes})
    return entries


def _flash_levels(timeline: Timeline) -> dict[str, np.ndarray]:
    """Per kind of event flashed by a ball (damping, push, roll-back), its size at each frame
    of ``Timeline.frame_times`` (1 at an event, fading out, 0 on the final pose); the kinds
    that never show left out (an event at the run's last moment only)."""
    grid = timeline.frame_times()
    out = {}
    for kind, times in timeline.events.items():
        if kind == "impact":  # impacts flash the link that hit
            continue
        level = _pulse(grid, times, timeline.duration)
        if np.any(level > 0):
            out[kind] = level
    return out


def _impact_flashes(timeline: Timeline, njoints: int) -> list[tuple[int, np.ndarray]]:
    """Each joint that hits a stop (its index in the scene's model, of ``njoints``) and
    whether its flash shows at each frame of ``Timeline.frame_times``; those that never show
    left out."""
    grid = timeline.frame_times()
    out = []
    for joint in np.unique(timeline.impact_joints):
        at = timeline.events["impact"][timeline.impact_joints == joint]
        flashing = _pulse(grid, at, timeline.duration) > 0
        if 0 < joint < njoints and flashing.any():
            out.append((int(joint), flashing))
    return out


def _mark_tips(scene: Scene, result: Result, size: float) -> np.ndarray:
    """Where the arrows drawn at the end of the motion end (world), for the camera to frame."""
    tips = mark_tips(scene, result, size)
    if scene.grounds:
        from ._play_contacts import contact_tips

        tips = np.concatenate([tips, contact_tips(scene, result, size)])
    return tips


def build_animation(viz: Any, scene: Scene, timeline: Timeline, visual: Any, result: Result) -> Any:
    """Load the mechanism, its springs, the event flashes, the forces that hold it and its
    grounds and contacts into the viewer, place the camera, and make the animation
    (returned)."""
    viz.loadViewerModel(rootNodeName="pinocchio")
    keys = _keyframes(viz, scene, timeline, visual)
    # The top of the view is left to the overlay (its lines, 19 px each, of a 600 px view);
    # the forces' arrows are sized by the view, and framed too (the grounds' slabs are not).
    top = (20 + 19 * (3 + len(legend(scene, result, timeline)))) / 600
    target, distance, size = _view(keys, visual)
    target, distance, _ = _view(keys, visual, _mark_tips(scene, result, size), top)
    _place_camera(viz, target, distance)
    radius = size / 2
    tracks = _Tracks(timeline)
    for g, obj in enumerate(visual.geometryObjects):
        node = viz.viewer[viz.getViewerNodeName(obj, pinocchio.GeometryType.VISUAL)]
        tracks.poses(node.path, keys.placements[:, g])
    if scene.springs:
        _add_springs(viz.viewer, keys.ends, radius, tracks)
    _add_event_flashes(viz.viewer, timeline, keys.com, radius, tracks)
    _add_impact_flashes(viz, timeline, visual, keys, radius, tracks)
    draw_forces(viz, scene, result, timeline, size, tracks)
    if scene.grounds:
        from ._play_contacts import draw_contacts

        draw_contacts(viz, scene, result, timeline, size, keys.com[-1], tracks)
    viz.display(timeline.q[-1])  # the final pose, also where the animation ends
    return tracks.animation


def _coil_matrices(ends: np.ndarray) -> np.ndarray:
    """Per keyframe, the placement of a coil from end a to end b (stretched along its axis)."""
    ez = np.array([0.0, 0.0, 1.0])
    matrices = np.zeros((len(ends), 4, 4))
    for k, (a, b) in enumerate(ends):
        d = b - a
        length = float(np.linalg.norm(d))
        axis = d / length if length > 1e-9 else ez
        m = np.eye(4)
        m[:3, :3] = pinocchio.Quaternion.FromTwoVectors(ez, axis).matrix() @ np.diag(
            [1.0, 1.0, max(length, 1e-6)]
        )
        m[:3, 3] = a
        matrices[k] = m
    return matrices


def _add_springs(root: Any, ends: np.ndarray, radius: float, tracks: _Tracks) -> None:
    """Springs: a coil from end a to end b, stretched along its axis, and a ball at each end."""
    import meshcat.geometry as mg

    lengths = np.linalg.norm(ends[:, :, 1] - ends[:, :, 0], axis=2)
    nominal = float(np.median(lengths)) if lengths.size else 1.0
    coil = min(max(0.03 * radius, 0.01), 0.08)
    mesh = _normal_mesh_class()(*_helix(coil, 0.18 * coil, nominal))
    material = mg.MeshPhongMaterial(color=_SPRING_COLOR, shininess=40)
    ball = mg.Sphere(0.35 * coil)
    for s in range(ends.shape[1]):
        node = root[f"springs/{s}"]
        node.set_object(mesh, material)
        matrices = _coil_matrices(ends[:, s])
        node.set_transform(matrices[-1])
        tracks.poses(node.path, matrices)
        for e, end in enumerate("ab"):
            end_node = root[f"springs/{s}_{end}"]
            end_node.set_object(ball, mg.MeshPhongMaterial(color=_END_COLOR))
            at = np.tile(np.eye(4), (len(ends), 1, 1))
            at[:, :3, 3] = ends[:, s, e]
            end_node.set_transform(at[-1])
            if np.ptp(ends[:, s, e], axis=0).max() > 0:
                tracks.poses(end_node.path, at)


def _add_event_flashes(
    root: Any, timeline: Timeline, com: np.ndarray, radius: float, tracks: _Tracks
) -> None:
    """Event flashes: a translucent ball at the centre of mass that pops up at each event and
    fades out over ``FLASH_SECONDS``, hidden otherwise (and on the final pose)."""
    import meshcat.geometry as mg
    from meshcat.animation import AnimationClip, AnimationTrack

    grid = timeline.frame_times()
    grid_frames = (grid * FPS).tolist()
    tiny = 1e-3  # a scale of 0 makes a singular matrix in the viewer
    for kind, level in _flash_levels(timeline).items():
        node = root[f"events/{kind}"]
        node.set_object(
            mg.Sphere(0.12 * radius),
            mg.MeshPhongMaterial(color=_EVENT_COLORS[kind], opacity=0.45, transparent=True),
        )
        position = np.array([np.interp(grid, timeline.times, com[:, i]) for i in range(3)]).T
        static = np.diag([tiny, tiny, tiny, 1.0])
        static[:3, 3] = com[-1]
        node.set_transform(static)
        node.set_property("visible", False)
        clip = AnimationClip(fps=tracks.fps)
        clip.tracks["position"] = AnimationTrack(
            "position", "vector3", list(grid_frames), position.tolist()
        )
        sizes = np.maximum(level, tiny)
        clip.tracks["scale"] = AnimationTrack(
            "scale", "vector3", list(grid_frames), [[v, v, v] for v in sizes]
        )
        tracks.animation.clips[node.path] = clip
        tracks.visibility(node.path, grid_frames, level > 0)


def _add_impact_flashes(
    viz: Any, timeline: Timeline, visual: Any, keys: _Keyframes, radius: float, tracks: _Tracks
) -> None:
    """Impacts on a stop: the link the joint carries turns _IMPACT_COLOR for a moment (a copy
    of its shapes in that colour is shown in their place); a ball at a joint without shapes."""
    grid_frames = (timeline.frame_times() * FPS).tolist()
    for joint, flashing in _impact_flashes(timeline, viz.model.njoints):
        shapes = [g for g, obj in enumerate(visual.geometryObjects) if obj.parentJoint == joint]
        for g in shapes:
            obj = visual.geometryObjects[g]
            node = _load_flash_shape(viz, obj)
            node.set_transform(keys.placements[-1, g])
            node.set_property("visible", False)
            tracks.poses(node.path, keys.placements[:, g])
            tracks.visibility(node.path, grid_frames, flashing)
            shape = viz.viewer[viz.getViewerNodeName(obj, pinocchio.GeometryType.VISUAL)]
            tracks.visibility(shape.path, grid_frames, ~flashing)
        if not shapes:
            node = viz.viewer[f"events/impact_{joint}"]
            _add_joint_flash(node, timeline, keys.joint_at[:, joint], radius, tracks, flashing)


def _add_joint_flash(
    node: Any,
    timeline: Timeline,
    joint_at: np.ndarray,
    radius: float,
    tracks: _Tracks,
    flashing: np.ndarray,
) -> None:
    """A ball at a joint without shapes, following it, shown while ``flashing``."""
    import meshcat.geometry as mg

    grid = timeline.frame_times()
    grid_frames = (grid * FPS).tolist()
    node.set_object(mg.Sphere(0.05 * radius), mg.MeshPhongMaterial(color=_EVENT_COLORS["impact"]))
    at = np.tile(np.eye(4), (grid.size, 1, 1))
    at[:, :3, 3] = np.array([np.interp(grid, timeline.times, joint_at[:, i]) for i in range(3)]).T
    node.set_transform(at[-1])
    node.set_property("visible", False)
    tracks.poses(node.path, at, grid_frames)
    tracks.visibility(node.path, grid_frames, flashing)


def _load_flash_shape(viz: Any, obj: pinocchio.GeometryObject) -> Any:
    """A copy of the shape ``obj`` in _IMPACT_COLOR, loaded next to it; its meshcat node."""
    import meshcat.geometry as mg

    flash = obj.copy()
    flash.name = f"{obj.name}_impact"
    flash.meshColor = np.array(_IMPACT_COLOR)
    node = viz.viewer[viz.getViewerNodeName(flash, pinocchio.GeometryType.VISUAL)]
    if obj.meshPath.lower().endswith(".dae"):
        # As a bare geometry: pinocchio loads a DAE with the file's own materials.
        node.set_object(
            mg.DaeMeshGeometry.from_file(obj.meshPath), mg.MeshPhongMaterial(color=_IMPACT_HEX)
        )
    else:
        viz.loadViewerGeometryObject(flash, pinocchio.GeometryType.VISUAL)
    return node


def _add_visibility(
    animation: Any, path: Any, frames: list[float], shown: np.ndarray, fps: float
) -> None:
    """Show the node at ``path`` at the keyframes where ``shown`` holds, hide it elsewhere
    (a new clip at ``fps`` frames a second if the node has none)."""
    from meshcat.animation import AnimationClip, AnimationTrack

    clip = animation.clips.setdefault(path, AnimationClip(fps=fps))
    clip.tracks["visible"] = AnimationTrack(
        "visible", "boolean", list(frames), [bool(x) for x in shown]
    )

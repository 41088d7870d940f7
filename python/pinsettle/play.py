"""Watch a mechanism settle: playback of a solve in meshcat, and its energy plot.

``pinsettle.play(scene, result)`` draws the scene (its URDF's visual shapes and meshes, or a
stick figure when it has none), its springs following the motion, a flash at each damping
event, and plays the recorded trajectory with time scaled so that a long settle plays in a few
seconds; the final pose is held. ``plot_energy(result, path)`` draws both energy measures
against time with the damping events (PNG).

meshcat and matplotlib are an optional extra (``pip install 'pinsettle[viz]'``): they are
imported here, inside the functions, never by ``import pinsettle`` nor by a solve.
"""

from __future__ import annotations

import atexit
import base64
import json
import math
import os
import selectors
import subprocess
import sys
import time
import types
import webbrowser
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import numpy as np
import pinocchio

from ._scene import Scene, load_scene
from ._solve import Result, solve
from .robots import robots_dir
from .scenes import scene_path

if TYPE_CHECKING:  # for annotations only: pyzmq comes with meshcat, when playing
    import zmq

#: What ``play`` installs: the optional extra.
VIZ_INSTALL = "pip install 'pinsettle[viz]'"
#: A settle longer than this (simulated seconds) is sped up to play in about this long.
PLAYBACK_SECONDS = 6.0
#: Keyframes per second of playback (at most; fewer when the trace has fewer samples).
FPS = 30
#: The final pose is held this long at the end of the animation (s), then stays (clamped).
HOLD_SECONDS = 0.5
#: A damping event flashes for this long (s of playback).
FLASH_SECONDS = 0.25
#: Solver settings that record what playback needs (every step, at most 4096 samples kept:
#: the stride doubles when the buffer is full, so memory stays bounded on long runs).
TRACE_SETTINGS: dict[str, Any] = {
    "trace_every": 1,
    "trace_capacity": 4096,
    "trace_configurations": True,
}
#: Seconds to wait for the meshcat server to start or answer.
SERVER_TIMEOUT = 20.0

_DEFAULT_MESH_COLOR = (0.9, 0.9, 0.9, 1.0)  # what pinocchio gives a URDF shape without material
_LINK_COLORS = ((0.16, 0.42, 0.74, 1.0), (0.33, 0.60, 0.86, 1.0))
_BASE_COLOR = (0.35, 0.36, 0.38, 1.0)
#: An STL mesh without a URDF material (pinocchio's 0.9 grey would vanish on the background).
_MESH_GREY = (0.62, 0.64, 0.67, 1.0)
_SPRING_COLOR = 0xE8590C
_END_COLOR = 0x343A40
_EVENT_COLORS = {"damping": 0xFFB000, "push": 0x1C7ED6, "rollback": 0xE03131, "impact": 0xD6336C}
#: The kinds of velocity change a trace records (``Trace.event_kind``), in display order.
EVENT_KINDS = ("damping", "push", "rollback", "impact")
#: A link whose joint hits a stop is drawn in this colour for ``FLASH_SECONDS``.
_IMPACT_COLOR = (0.93, 0.16, 0.42, 1.0)
_CAMERA_DIRECTION = np.array([0.45, -1.0, 0.35])  # from the mechanism towards the camera
_CAMERA_FOV = 40.0  # degrees, vertical


class MissingDependencyError(ImportError):
    """meshcat or matplotlib is not installed; the message says what to install."""


def require(*modules: str) -> None:
    """Import ``modules`` (default: meshcat and matplotlib) or raise MissingDependencyError
    with a one-line message naming what to install."""
    import importlib

    missing = []
    for name in modules or ("meshcat", "matplotlib"):
        try:
            importlib.import_module(name)
        except ImportError:
            missing.append(name)
    if missing:
        raise MissingDependencyError(
            f"pinsettle play needs {' and '.join(missing)}, which "
            + ("is" if len(missing) == 1 else "are")
            + f" not installed: {VIZ_INSTALL}"
        )


# --- the timeline: which poses are shown when -------------------------------------------------


@overload
def check_speed(speed: None) -> None: ...
@overload
def check_speed(speed: float) -> float: ...
@overload
def check_speed(speed: object) -> float | None: ...


def check_speed(speed: Any) -> float | None:
    """``speed`` (simulated seconds per second of playback) checked: None (automatic) or a
    positive finite number."""
    if speed is None:
        return None
    if isinstance(speed, (bool, np.bool_)) or not isinstance(speed, (int, float, np.number)):
        raise TypeError(
            "speed must be a positive number (simulated seconds per second of playback) or "
            f"None, got {type(speed).__name__} {speed!r}"
        )
    value = float(speed)
    if not math.isfinite(value) or value <= 0:
        raise ValueError(
            "speed must be a positive finite number (simulated seconds per second of "
            f"playback), got {value}"
        )
    return value


def auto_speed(sim_time: float) -> float:
    """Real time, or faster for a settle longer than ``PLAYBACK_SECONDS``."""
    return max(1.0, sim_time / PLAYBACK_SECONDS) if math.isfinite(sim_time) else 1.0


@dataclass(frozen=True)
class Timeline:
    """What the animation shows: keyframe times (s of playback) and configurations (the last
    two are the final pose, held), the event times (s of playback) by kind (sorted), the speed
    and the length of the motion (s of playback, without the hold). ``impact_joints`` gives
    the joint (index in the scene's model) of each of ``events['impact']``."""

    times: np.ndarray
    q: np.ndarray
    speed: float
    duration: float
    sim_time: float
    events: dict[str, np.ndarray]
    impact_joints: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def end(self) -> float:
        """Length of the whole animation, hold included (s)."""
        return float(self.times[-1])

    def frame_times(self) -> np.ndarray:
        """A uniform grid at ``FPS`` over the whole animation (for the event flashes)."""
        n = int(math.ceil(self.end * FPS)) + 1
        return np.minimum(np.arange(n) / FPS, self.end)


def _trace_of(result: Result, nq: int) -> Any:
    if not isinstance(result, Result):
        raise TypeError(f"result must be a pinsettle.Result, got {type(result).__name__}")
    trace = result.trace
    if trace is None or trace.q is None:
        raise ValueError(
            "result has no recorded configurations to play: solve with trace_every=1 and "
            "trace_configurations=True (pinsettle.solve(scene, **pinsettle.play.TRACE_SETTINGS)),"
            " or call play(scene) without a result to solve with them"
        )
    if trace.q.ndim != 2 or trace.q.shape[1] != nq or result.q.shape != (nq,):
        raise ValueError(
            f"result does not belong to this scene: its configurations have "
            f"{trace.q.shape[-1]} entries, the scene's model has nq = {nq}"
        )
    return trace


def make_timeline(result: Result, nq: int, speed: float | None = None) -> Timeline:
    """Keyframes of the playback of ``result`` (see ``Timeline``): the trace's samples mapped
    to playback time (at most ``FPS`` a second), then the final pose, held."""
    trace = _trace_of(result, nq)
    speed = check_speed(speed)
    t = np.asarray(trace.time, dtype=float)
    q = np.asarray(trace.q, dtype=float)
    keep = np.isfinite(t) & np.all(np.isfinite(q), axis=1) & (t < result.sim_time)
    t, q = t[keep], q[keep]
    t0 = float(t[0]) if t.size else 0.0
    sim_time = max(float(result.sim_time) - t0, 0.0) if math.isfinite(result.sim_time) else 0.0
    if speed is None:
        speed = auto_speed(sim_time)
    duration = sim_time / speed
    play_t = (t - t0) / speed
    n_frames = int(math.ceil(duration * FPS)) + 1
    if play_t.size > n_frames:  # more samples than frames: the sample nearest each frame
        grid = np.arange(n_frames) / FPS
        idx = np.clip(np.searchsorted(play_t, grid), 0, play_t.size - 1)
        before = np.clip(idx - 1, 0, play_t.size - 1)
        nearer = np.abs(play_t[before] - grid) <= np.abs(play_t[idx] - grid)
        idx = np.unique(np.where(nearer, before, idx))
        play_t, q = play_t[idx], q[idx]
    final = np.asarray(result.q, dtype=float)[None, :]
    if play_t.size and duration - play_t[-1] < 1e-9:
        play_t, q = play_t[:-1], q[:-1]
    times = np.concatenate([play_t, [duration, duration + HOLD_SECONDS]])
    poses = np.concatenate([q, final, final])
    events: dict[str, np.ndarray] = {}
    kinds = np.asarray(trace.event_kind, dtype=object)
    event_t = (np.asarray(trace.event_time, dtype=float) - t0) / speed
    joints = np.asarray(trace.event_joint, dtype=np.int64)
    if joints.shape != kinds.shape:  # a trace without joints: no link to flash
        joints = np.full(kinds.shape, -1, dtype=np.int64)
    impact_joints = np.zeros(0, dtype=np.int64)
    for kind in EVENT_KINDS:
        chosen = (kinds == kind) & np.isfinite(event_t) if kinds.size else np.zeros(0, dtype=bool)
        order = np.argsort(event_t[chosen], kind="stable")
        events[kind] = event_t[chosen][order]
        if kind == "impact":
            impact_joints = joints[chosen][order]
    return Timeline(times, poses, speed, duration, sim_time, events, impact_joints)


def _pulse(grid: np.ndarray, times: np.ndarray) -> np.ndarray:
    """At each time of ``grid``, how strong the flash of the events at ``times`` is: 1 at an
    event, fading to 0 over ``FLASH_SECONDS`` (the strongest of those under way)."""
    if not times.size:
        return np.zeros(grid.shape)
    since = grid[:, None] - times[None, :]
    pulse = np.where((since >= 0) & (since < FLASH_SECONDS), 1 - since / FLASH_SECONDS, 0.0)
    return np.asarray(pulse.max(axis=1), dtype=float)


# --- geometry -------------------------------------------------------------------------------


def _visual_model(scene: Scene) -> pinocchio.GeometryModel | None:
    """The visual shapes and meshes of the scene's URDF (``package://`` resolved against
    example-robot-data and the URDF's folders), or None when it has none."""
    urdf = getattr(scene, "urdf", None)
    if urdf is None or not Path(urdf).is_file():
        return None
    package_dirs = [str(Path(urdf).resolve().parent), str(Path(urdf).resolve().parent.parent)]
    try:
        package_dirs.insert(0, str(robots_dir().parents[1]))  # .../share: example-robot-data/...
    except FileNotFoundError:
        pass
    try:
        geometry = pinocchio.buildGeomFromUrdf(
            scene.model, str(urdf), pinocchio.GeometryType.VISUAL, package_dirs=package_dirs
        )
    except (RuntimeError, ValueError) as error:
        raise ValueError(f"{urdf}: cannot load its visual geometry: {error}") from None
    if geometry.ngeoms == 0:
        return None
    for k, obj in enumerate(geometry.geometryObjects):
        if not np.allclose(obj.meshColor, _DEFAULT_MESH_COLOR):
            continue  # the URDF's <material> colour
        path = obj.meshPath.lower()
        if path.endswith(".stl"):
            # STL carries no colour (a DAE or OBJ brings its own materials): a lit grey.
            obj.meshColor = np.array(_MESH_GREY)
        elif not path.endswith((".dae", ".obj")):
            # URDF shapes without a material: the base dark, the links in alternating blues.
            color = _BASE_COLOR if obj.parentJoint == 0 else _LINK_COLORS[obj.parentJoint % 2]
            obj.meshColor = np.array(color)
        geometry.geometryObjects[k] = obj
    return geometry


def read_stl(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triangles of an STL file (binary or ASCII) as (vertices, faces, normals): three
    vertices per triangle, each with its triangle's unit normal computed from the vertices
    (counter-clockwise seen from outside, as STL orders them). The file's own normals are not
    used: many exporters write zeros there, which drew such meshes black."""
    data = Path(path).read_bytes()
    count = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
    if count >= 0 and len(data) == 84 + 50 * count:
        record = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("extra", "<u2")])
        triangles = np.frombuffer(data, dtype=record, count=count, offset=84)["vertices"]
    else:
        words = data.decode("ascii", errors="replace").split()
        try:
            values = [
                [float(x) for x in words[i + 1 : i + 4]]
                for i, word in enumerate(words)
                if word.lower() == "vertex"
            ]
        except ValueError as error:
            raise ValueError(f"{path}: not a readable STL file ({error})") from None
        if not values or len(values) % 3:
            raise ValueError(
                f"{path}: not a readable STL file (neither binary with {count} triangles in "
                f"{len(data)} bytes nor ASCII with whole facets)"
            )
        triangles = np.array(values).reshape(-1, 3, 3)
    triangles = np.asarray(triangles, dtype=float)
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    # A degenerate triangle draws nothing; any unit normal keeps the shader finite.
    normal = np.where(length > 0, normal / np.where(length > 0, length, 1.0), [0.0, 0.0, 1.0])
    vertices = triangles.reshape(-1, 3)
    faces = np.arange(vertices.shape[0]).reshape(-1, 3)
    return vertices, faces, np.repeat(normal, 3, axis=0)


def _stick_figure(model: pinocchio.Model) -> pinocchio.GeometryModel:
    """Shapes for a model without visuals: a rod from each joint to its children, a ball at
    each joint and at each body's centre of mass."""
    import coal

    data = model.createData()
    pinocchio.forwardKinematics(model, data, pinocchio.neutral(model))
    points = [data.oMi[j].translation for j in range(model.njoints)]
    points += [data.oMi[j].act(model.inertias[j].lever) for j in range(model.njoints)]
    size = float(np.ptp(np.array(points), axis=0).max()) if len(points) > 1 else 1.0
    size = size if size > 1e-6 else 1.0
    rod, ball = 0.012 * size, 0.03 * size
    geometry = pinocchio.GeometryModel()
    ez = np.array([0.0, 0.0, 1.0])
    for j in range(1, model.njoints):
        parent = model.parents[j]
        offset = model.jointPlacements[j].translation
        color = _LINK_COLORS[parent % 2] if parent else _BASE_COLOR
        length = float(np.linalg.norm(offset))
        if length > 1e-9:
            rotation = pinocchio.Quaternion.FromTwoVectors(ez, offset / length).matrix()
            placement = pinocchio.SE3(rotation, offset / 2)
            obj = pinocchio.GeometryObject(
                f"rod_{j}", parent, placement, coal.Cylinder(rod, length)
            )
            obj.meshColor = np.array(color)
            geometry.addGeometryObject(obj)
        obj = pinocchio.GeometryObject(
            f"joint_{j}", j, pinocchio.SE3.Identity(), coal.Sphere(1.5 * rod)
        )
        obj.meshColor = np.array(_BASE_COLOR)
        geometry.addGeometryObject(obj)
        if model.inertias[j].mass > 0:
            placement = pinocchio.SE3(np.eye(3), model.inertias[j].lever)
            obj = pinocchio.GeometryObject(f"mass_{j}", j, placement, coal.Sphere(ball))
            obj.meshColor = np.array(_LINK_COLORS[j % 2])
            geometry.addGeometryObject(obj)
    return geometry


def _local_corners(visual: pinocchio.GeometryModel) -> np.ndarray:
    """The 8 corners of each shape's bounding box in its own frame (a mesh's scale included,
    as pinocchio loads it); a point at the origin for a shape without one."""
    out = np.zeros((visual.ngeoms, 8, 3))
    signs = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=float)
    for g, obj in enumerate(visual.geometryObjects):
        try:
            obj.geometry.computeLocalAABB()
            low = np.array(obj.geometry.aabb_local.min_)
            high = np.array(obj.geometry.aabb_local.max_)
        except (AttributeError, RuntimeError):
            continue
        if np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(high >= low):
            out[g] = low + signs * (high - low)
    return out


def _camera_fit(points: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Where the camera looks, how far from there it stands (looking along
    -_CAMERA_DIRECTION with the vertical field of view _CAMERA_FOV, in a view at least 4:3
    wide) so that every point is seen with a margin, and the size of the cloud (m)."""
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
    target = middle + right * (x.max() + x.min()) / 2 + up * (y.max() + y.min()) / 2
    margin = 0.06 * size
    half_x, half_y = (x.max() - x.min()) / 2 + margin, (y.max() - y.min()) / 2 + margin
    tan = math.tan(math.radians(_CAMERA_FOV) / 2)
    distance = float(z.max()) + max(half_y / tan, half_x / (tan * 4 / 3), 0.05)
    return target, distance, size


def _frame_id(model: pinocchio.Model, name: str) -> int:
    body = [i for i, f in enumerate(model.frames) if f.name == name]
    bodies = [i for i in body if model.frames[i].type == pinocchio.FrameType.BODY]
    if not body:
        raise ValueError(f"frame '{name}' is not in the scene's model")
    return (bodies or body)[0]


def _decompose(matrix: np.ndarray) -> tuple[list[float], list[float], list[float]]:
    """Position, quaternion (x, y, z, w as three.js wants) and scale of a homogeneous matrix
    whose 3x3 part is a rotation times a diagonal scaling."""
    linear = matrix[:3, :3]
    scale = np.linalg.norm(linear, axis=0)
    scale = np.where(scale > 1e-12, scale, 1.0)
    rotation = linear / scale
    if np.linalg.det(rotation) < 0:
        scale[0], rotation[:, 0] = -scale[0], -rotation[:, 0]
    quat = pinocchio.Quaternion(rotation).normalized().coeffs()
    return matrix[:3, 3].tolist(), quat.tolist(), scale.tolist()


def _helix(
    coil_radius: float, wire_radius: float, nominal_length: float, coils: int = 9
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A coil spring along +z from z = 0 to z = 1 (vertices, faces, normals): stretched along
    z by the length of the spring; its wire looks round at ``nominal_length``."""
    per_coil, sides = 20, 6
    n = coils * per_coil + 1
    s = np.linspace(0.0, 1.0, n)
    theta = 2 * np.pi * coils * s
    phi = 2 * np.pi * np.arange(sides) / sides
    radial = np.stack([np.cos(theta), np.sin(theta), np.zeros(n)], axis=1)
    center = coil_radius * radial + np.stack([np.zeros(n), np.zeros(n), s], axis=1)
    ez = np.array([0.0, 0.0, 1.0])
    normals = np.cos(phi)[None, :, None] * radial[:, None, :] + np.sin(phi)[None, :, None] * ez
    offset = wire_radius * normals * np.array([1.0, 1.0, 1.0 / max(nominal_length, 1e-6)])
    vertices = (center[:, None, :] + offset).reshape(-1, 3)
    faces = []
    for i in range(n - 1):
        for k in range(sides):
            a, b = i * sides + k, i * sides + (k + 1) % sides
            c, d = a + sides, b + sides
            faces += [(a, c, b), (b, c, d)]
    return vertices, np.array(faces), normals.reshape(-1, 3)


@lru_cache(maxsize=1)
def _normal_mesh_class() -> type:
    import meshcat.geometry as mg

    class MeshWithNormals(mg.TriangularMeshGeometry):  # type: ignore[misc]  # meshcat: no types
        """meshcat's triangle mesh with vertex normals (for a lit material)."""

        __slots__ = ["normals"]

        def __init__(self, vertices: Any, faces: Any, normals: Any) -> None:
            super().__init__(vertices, faces)
            self.normals = np.asarray(normals, dtype=np.float32)

        def lower(self, object_data: Any) -> dict[str, Any]:
            data: dict[str, Any] = super().lower(object_data)
            data["data"]["attributes"]["normal"] = mg.pack_numpy_array(self.normals.T)
            return data

    return MeshWithNormals


# --- the window meshcat talks to: records every command, forwards them to a live server ----


class _LiveServer:
    """A meshcat server on 127.0.0.1 in a child process (pinsettle._meshcat_server)."""

    def __init__(self) -> None:
        command = [sys.executable, "-m", "pinsettle._meshcat_server", "--parent", str(os.getpid())]
        env = dict(os.environ)
        here = str(Path(__file__).resolve().parents[1])
        env["PYTHONPATH"] = os.pathsep.join([here, *filter(None, [env.get("PYTHONPATH")])])
        self.process = subprocess.Popen(
            command,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env,
            start_new_session=True,  # Ctrl-C in a terminal reaches us, and we close it
        )
        atexit.register(self.close)
        try:
            lines = self._read_lines(2)
        except Exception:
            self.close()
            raise
        self.zmq_url = lines[0].partition("=")[2]
        self.web_url = lines[1].partition("=")[2]

    def _read_lines(self, count: int) -> list[str]:
        assert self.process.stdout is not None
        deadline = time.monotonic() + SERVER_TIMEOUT
        buffer = b""
        with selectors.DefaultSelector() as selector:
            selector.register(self.process.stdout, selectors.EVENT_READ)
            while buffer.count(b"\n") < count:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise RuntimeError(
                        f"the meshcat server did not start within {SERVER_TIMEOUT:.0f} s"
                    )
                if selector.select(timeout=left):
                    chunk = os.read(self.process.stdout.fileno(), 4096)
                    if not chunk:
                        self.process.wait(timeout=5)
                        assert self.process.stderr is not None
                        errors = self.process.stderr.read().decode(errors="replace").strip()
                        last = errors.splitlines()[-1] if errors else "no message"
                        raise RuntimeError(
                            f"the meshcat server exited (status {self.process.returncode}): {last}"
                        )
                    buffer += chunk
        lines = buffer.decode().splitlines()[:count]
        if not (lines[0].startswith("zmq_url=") and lines[1].startswith("web_url=")):
            raise RuntimeError(f"unexpected output from the meshcat server: {lines!r}")
        return lines

    @property
    def running(self) -> bool:
        return self.process.poll() is None

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=5)
        for stream in (self.process.stdout, self.process.stderr):
            if stream is not None:
                stream.close()
        atexit.unregister(self.close)


class _Window:
    """What a ``meshcat.Visualizer`` sends its commands to: every command is kept in a scene
    tree, as meshcat's server keeps them, for the static HTML; with a live server, it is also
    sent there (with timeouts: nothing waits forever on a dead server)."""

    def __init__(self, server: _LiveServer | None = None) -> None:
        from meshcat.servers.tree import SceneTree

        self.tree = SceneTree()
        self.animation: bytes | None = None
        self.server = server
        self.web_url = server.web_url if server else None
        self.socket: zmq.Socket[bytes] | None = None
        if server is not None:
            import zmq

            self.socket = zmq.Context.instance().socket(zmq.REQ)
            timeout_ms = int(SERVER_TIMEOUT * 1000)
            self.socket.setsockopt(zmq.RCVTIMEO, timeout_ms)
            self.socket.setsockopt(zmq.SNDTIMEO, timeout_ms)
            self.socket.setsockopt(zmq.LINGER, 0)
            self.socket.connect(server.zmq_url)

    def send(self, command: Any) -> None:
        import umsgpack
        from meshcat.servers.tree import find_node

        data = command.lower()
        packed = umsgpack.packb(data)
        kind, path = data["type"], data["path"]
        node_path = [part for part in path.split("/") if part]
        if kind == "set_transform":
            find_node(self.tree, node_path).transform = packed
        elif kind == "set_object":
            node = find_node(self.tree, node_path)
            node.object, node.properties = packed, []
        elif kind == "set_property":
            find_node(self.tree, node_path).properties.append(packed)
        elif kind == "set_animation":
            self.animation = packed
        elif kind == "delete":
            if node_path:
                find_node(self.tree, node_path[:-1]).pop(node_path[-1], None)
            else:
                from meshcat.servers.tree import SceneTree

                self.tree = SceneTree()
        if self.socket is not None:
            import zmq

            try:
                self.socket.send_multipart([kind.encode(), path.encode(), packed])
                self.socket.recv()
            except zmq.Again:
                raise RuntimeError(
                    f"the meshcat server did not answer within {SERVER_TIMEOUT:.0f} s"
                ) from None

    def commands(self) -> list[bytes]:
        """The scene as packed commands, in the order meshcat's server replays them."""
        from meshcat.servers.tree import walk

        out: list[bytes] = []
        for node in walk(self.tree):
            if node.object is not None:
                out.append(node.object)
            out.extend(node.properties)
            if node.transform is not None:
                out.append(node.transform)
        return out

    def get_scene(self) -> str:
        """The static HTML (meshcat's viewer and the recorded commands, no overlay)."""
        return _html(self.commands(), self.animation, None)

    def open(self) -> _Window:
        if self.web_url:
            webbrowser.open(self.web_url, new=2)
        return self

    def wait(self) -> str:
        return "ok"

    def get_image(self) -> Any:
        raise NotImplementedError("pinsettle's playback window does not capture images")

    def close(self) -> None:
        if self.socket is not None:
            self.socket.close(linger=0)
            self.socket = None
        if self.server is not None:
            self.server.close()


# --- the static HTML ------------------------------------------------------------------------

_OVERLAY_CSS = """
body { margin: 0; }
#meshcat-pane { width: 100vw; height: 100vh; overflow: hidden; }
#pinsettle-overlay {
  position: fixed; left: 12px; top: 12px; padding: 8px 12px; border-radius: 6px;
  font: 13px/1.45 system-ui, sans-serif; color: #212529;
  background: rgba(255, 255, 255, 0.82); pointer-events: none;
  transition: background-color 0.15s;
}
#pinsettle-overlay.flash { background: rgba(255, 176, 0, 0.85); }
#pinsettle-overlay b { font-weight: 600; }
"""

_OVERLAY_JS = """
(function () {
  const info = JSON.parse(document.getElementById("pinsettle-info").textContent);
  const box = document.getElementById("pinsettle-overlay");
  const title = document.createElement("div");
  const clock = document.createElement("div");
  const counter = document.createElement("div");
  title.innerHTML = "<b></b> <span></span>";
  title.firstChild.textContent = info.scene;
  title.lastChild.textContent = info.status;
  box.append(title, clock, counter);
  function upto(times, t) {
    let lo = 0, hi = times.length;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (times[mid] <= t) lo = mid + 1; else hi = mid;
    }
    return lo;
  }
  let shown = -1;
  function tick() {
    const now = (viewer.animator && viewer.animator.time) || 0;
    const t = Math.min(now, info.duration);
    const held = now >= info.duration && info.duration > 0;
    clock.textContent = "t = " + (t * info.speed).toFixed(3) + " s simulated (x" +
      info.speed.toPrecision(3) + ")" + (held ? ", final pose held" : "");
    const parts = [];
    let total = 0;
    for (const kind of ["damping", "push", "rollback", "impact"]) {
      const times = info.events[kind];
      if (!times.length && kind !== "damping") continue;
      const k = upto(times, t);
      total += k;
      parts.push(kind + " events " + k + " / " + times.length);
    }
    counter.textContent = parts.join(", ");
    if (shown >= 0 && total > shown) {
      box.classList.add("flash");
      setTimeout(() => box.classList.remove("flash"), 120);
    }
    shown = total;
    requestAnimationFrame(tick);
  }
  tick();
})();
"""

# page.html#end opens on the final pose, paused (for a quick look, a screenshot or a test);
# page.html#t=1.5 on the frame 1.5 s into the playback, paused.
_END_JS = """
(function () {
  const animator = viewer.animator;
  const at = location.hash === "#end" ? animator.duration
    : location.hash.startsWith("#t=") ? parseFloat(location.hash.slice(3)) : NaN;
  if (isFinite(at)) {
    const t = Math.min(Math.max(at, 0), animator.duration);
    animator.playing = false;
    animator.seek(t);
    animator.time = t;
  }
})();
"""

_APPLY_JS = """
function pinsettle_apply(b64) {
  const text = atob(b64);
  const bytes = new Uint8Array(text.length);
  for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
  viewer.handle_command_bytearray(bytes);
}
"""


def _script_json(value: Any) -> str:
    """JSON safe inside a <script> element."""
    return json.dumps(value).replace("<", "\\u003c").replace(">", "\\u003e")


def _html(commands: list[bytes], animation: bytes | None, overlay: dict[str, Any] | None) -> str:
    """A self-contained page: meshcat's viewer (inline), the scene's commands applied in
    order, the animation in its own <script id="pinsettle-animation">, an optional overlay."""
    import meshcat

    viewer_js = (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text(
        encoding="utf-8"
    )
    encoded = [base64.b64encode(c).decode("ascii") for c in commands]
    parts = [
        '<!DOCTYPE html>\n<html>\n<head>\n<meta charset="utf-8">\n',
        "<title>pinsettle playback</title>\n",
        f'<style>{_OVERLAY_CSS}</style>\n</head>\n<body>\n<div id="meshcat-pane"></div>\n',
        f"<script>{viewer_js}</script>\n",
        '<script>\nvar viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));\n',
        _APPLY_JS,
        f"{_script_json(encoded)}.forEach(pinsettle_apply);\n</script>\n",
    ]
    if animation is not None:
        b64 = base64.b64encode(animation).decode("ascii")
        parts.append(f'<script id="pinsettle-animation">pinsettle_apply("{b64}");</script>\n')
        parts.append(f"<script>{_END_JS}</script>\n")
    if overlay is not None:
        parts.append('<div id="pinsettle-overlay"></div>\n')
        parts.append(
            f'<script type="application/json" id="pinsettle-info">{_script_json(overlay)}'
            "</script>\n"
        )
        parts.append(f"<script>{_OVERLAY_JS}</script>\n")
    parts.append("</body>\n</html>\n")
    return "".join(parts)


# --- building the scene in meshcat ----------------------------------------------------------


@lru_cache(maxsize=1)
def _visualizer_class() -> type:
    from pinocchio.visualize import MeshcatVisualizer

    class PlaybackVisualizer(MeshcatVisualizer):  # type: ignore[misc]  # pinocchio: no types
        """Pinocchio's ``MeshcatVisualizer`` holding one playback (see ``pinsettle.play``).

        ``url`` is the live page (None without a server), ``html()`` the self-contained
        static page, ``save_html(path)``, ``save_plot(path)`` the energy plot, ``replay()``
        starts the animation again, ``close()`` (or leaving a ``with`` block) stops the
        server. ``scene``, ``result`` and ``timeline`` are what is played.
        """

        scene: Scene
        result: Result
        timeline: Timeline
        window: _Window

        def loadMeshFromFile(self, geometry_object: Any) -> Any:  # noqa: N802  (pinocchio's)
            # STL: our own triangles with normals (meshcat's loader keeps the file's, often
            # zeros: a black mesh); DAE and OBJ as pinocchio loads them.
            if geometry_object.meshPath.lower().endswith(".stl"):
                return _normal_mesh_class()(*read_stl(geometry_object.meshPath))
            return super().loadMeshFromFile(geometry_object)

        @property
        def url(self) -> str | None:
            return self.window.web_url

        @property
        def speed(self) -> float:
            return self.timeline.speed

        @property
        def duration(self) -> float:
            """Length of the animation (s), the final hold included."""
            return self.timeline.end

        def html(self) -> str:
            return _html(self.window.commands(), self.window.animation, self._overlay())

        def save_html(self, path: str | Path) -> Path:
            path = Path(path)
            path.write_text(self.html(), encoding="utf-8")
            return path

        def save_plot(self, path: str | Path) -> Path:
            return plot_energy(self.result, path, title=self.scene.name)

        def replay(self) -> None:
            self.viewer.set_animation(self.animation, play=True, repetitions=1)

        def open(self) -> None:
            if self.url:
                webbrowser.open(self.url, new=2)

        def close(self) -> None:
            self.window.close()

        def __enter__(self) -> PlaybackVisualizer:
            return self

        def __exit__(self, *exc: object) -> None:
            self.close()

        def _overlay(self) -> dict[str, Any]:
            result = self.result
            status = f"{result.status}: {result.steps} steps, {result.peaks} damping events"
            return {
                "scene": self.scene.name,
                "status": status,
                "speed": self.timeline.speed,
                "duration": self.timeline.duration,
                "events": {k: v.tolist() for k, v in self.timeline.events.items()},
            }

    return PlaybackVisualizer


def _as_scene(scene: Any) -> Scene:
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, pinocchio.Model):
        return Scene(scene)
    if isinstance(scene, (str, os.PathLike)):
        return load_scene(scene_path(scene))
    raise TypeError(
        "scene must be a pinsettle.Scene, a pinocchio.Model, a scene file or a scene name, "
        f"got {type(scene).__name__}"
    )


def _build(viz: Any, scene: Scene, timeline: Timeline, visual: Any) -> Any:
    """Load the mechanism, its springs and the event flashes into the viewer, place the
    camera, and make the animation (returned)."""
    import meshcat.geometry as mg
    from meshcat.animation import Animation, AnimationClip, AnimationTrack

    model, data = viz.model, viz.data
    root = viz.viewer  # /meshcat/pinsettle
    viz.loadViewerModel(rootNodeName="pinocchio")

    # Where everything is at each keyframe.
    geometry_data = viz.visual_data
    frames = [_frame_id(model, s.a_frame) for s in scene.springs]
    frames_b = [_frame_id(model, s.b_frame) for s in scene.springs]
    n_keys = timeline.times.size
    placements = np.zeros((n_keys, visual.ngeoms, 4, 4))
    scales = np.array([obj.meshScale for obj in visual.geometryObjects]).reshape(-1, 1, 3)
    ends = np.zeros((n_keys, len(scene.springs), 2, 3))
    com = np.zeros((n_keys, 3))
    joint_at = np.zeros((n_keys, model.njoints, 3))
    for k, q in enumerate(timeline.q):
        pinocchio.forwardKinematics(model, data, q)
        pinocchio.updateFramePlacements(model, data)
        pinocchio.updateGeometryPlacements(model, data, visual, geometry_data)
        for g, obj in enumerate(visual.geometryObjects):
            placements[k, g] = geometry_data.oMg[g].homogeneous @ np.diag([*obj.meshScale, 1.0])
        for s, spring in enumerate(scene.springs):
            ends[k, s, 0] = data.oMf[frames[s]].act(np.array(spring.a_point))
            ends[k, s, 1] = data.oMf[frames_b[s]].act(np.array(spring.b_point))
        com[k] = pinocchio.centerOfMass(model, data, q, False)
        joint_at[k] = [placement.translation for placement in data.oMi]

    corners = _local_corners(visual)  # (ngeoms, 8, 3): each shape's bounding box
    cloud = [np.einsum("kgij,gcj->kgci", placements[:, :, :3, :3] / scales, corners)]
    cloud[0] += placements[:, :, None, :3, 3]
    cloud += [ends.reshape(-1, 3), com]
    everything = np.concatenate([c.reshape(-1, 3) for c in cloud])
    last = np.concatenate([cloud[0][-1].reshape(-1, 3), ends[-1].reshape(-1, 3), com[-1:]])
    target, distance, size = _camera_fit(everything)
    if size > 20 * _camera_fit(last)[2]:
        # A runaway (a body falling for kilometres): a view of the whole path would show a
        # speck; frame the final pose, which the animation holds.
        target, distance, size = _camera_fit(last)

    # The view's centre at the origin: meshcat's camera (orbit controls) looks there.
    shift = np.eye(4)
    shift[:3, 3] = -target
    root.set_transform(shift)
    viz.viewer["/Grid"].set_property("visible", False)
    viz.viewer["/Axes"].set_property("visible", False)
    viz.setBackgroundColor(col_top=[0.99, 0.99, 1.0], col_bot=[0.80, 0.83, 0.87])
    camera = viz.viewer["/Cameras/default/rotated/<object>"]
    eye = distance * _CAMERA_DIRECTION / np.linalg.norm(_CAMERA_DIRECTION)
    camera.set_property("fov", _CAMERA_FOV)
    camera.set_property("far", max(100.0, 20 * distance))
    radius = size / 2
    camera.set_property("position", [float(eye[0]), float(eye[2]), float(-eye[1])])

    animation = Animation(default_framerate=FPS)
    key_frames = (timeline.times * FPS).tolist()

    def add_pose_tracks(path: Any, matrices: np.ndarray, frames: list[float] | None = None) -> None:
        frames = key_frames if frames is None else frames
        tracks: dict[str, list[list[float]]] = {"position": [], "quaternion": [], "scale": []}
        for matrix in matrices:
            position, quaternion, scale = _decompose(matrix)
            tracks["position"].append(position)
            tracks["quaternion"].append(quaternion)
            tracks["scale"].append(scale)
        clip = AnimationClip(fps=FPS)
        for name, jstype in (("position", "vector3"), ("quaternion", "quaternion")):
            clip.tracks[name] = AnimationTrack(name, jstype, list(frames), tracks[name])
        if not np.allclose(tracks["scale"], 1.0):
            clip.tracks["scale"] = AnimationTrack("scale", "vector3", list(frames), tracks["scale"])
        animation.clips[path] = clip

    for g, obj in enumerate(visual.geometryObjects):
        node = viz.viewer[viz.getViewerNodeName(obj, pinocchio.GeometryType.VISUAL)]
        add_pose_tracks(node.path, placements[:, g])

    # Springs: a coil from end a to end b, stretched along its axis, and a ball at each end.
    if scene.springs:
        lengths = np.linalg.norm(ends[:, :, 1] - ends[:, :, 0], axis=2)
        nominal = float(np.median(lengths)) if lengths.size else 1.0
        coil = min(max(0.03 * radius, 0.01), 0.08)
        vertices, faces, normals = _helix(coil, 0.18 * coil, nominal)
        mesh = _normal_mesh_class()(vertices, faces, normals)
        material = mg.MeshPhongMaterial(color=_SPRING_COLOR, shininess=40)
        ball = mg.Sphere(0.35 * coil)
        ez = np.array([0.0, 0.0, 1.0])
        for s in range(len(scene.springs)):
            node = root[f"springs/{s}"]
            node.set_object(mesh, material)
            matrices = np.zeros((n_keys, 4, 4))
            for k in range(n_keys):
                a, b = ends[k, s]
                d = b - a
                length = float(np.linalg.norm(d))
                axis = d / length if length > 1e-9 else ez
                m = np.eye(4)
                m[:3, :3] = pinocchio.Quaternion.FromTwoVectors(ez, axis).matrix() @ np.diag(
                    [1.0, 1.0, max(length, 1e-6)]
                )
                m[:3, 3] = a
                matrices[k] = m
            node.set_transform(matrices[-1])
            add_pose_tracks(node.path, matrices)
            for e, end in enumerate("ab"):
                end_node = root[f"springs/{s}_{end}"]
                end_node.set_object(ball, mg.MeshPhongMaterial(color=_END_COLOR))
                at = np.tile(np.eye(4), (n_keys, 1, 1))
                at[:, :3, 3] = ends[:, s, e]
                end_node.set_transform(at[-1])
                if np.ptp(ends[:, s, e], axis=0).max() > 0:
                    add_pose_tracks(end_node.path, at)

    # Event flashes: a translucent ball at the centre of mass that pops up and fades.
    grid = timeline.frame_times()
    grid_frames = (grid * FPS).tolist()
    tiny = 1e-3
    for kind, times in timeline.events.items():
        if not times.size or kind == "impact":  # impacts flash the link that hit (below)
            continue
        level = np.maximum(_pulse(grid, times), tiny)
        node = root[f"events/{kind}"]
        node.set_object(
            mg.Sphere(0.12 * radius),
            mg.MeshPhongMaterial(color=_EVENT_COLORS[kind], opacity=0.45, transparent=True),
        )
        position = np.array([np.interp(grid, timeline.times, com[:, i]) for i in range(3)]).T
        static = np.diag([tiny, tiny, tiny, 1.0])
        static[:3, 3] = com[-1]
        node.set_transform(static)
        clip = AnimationClip(fps=FPS)
        clip.tracks["position"] = AnimationTrack(
            "position", "vector3", list(grid_frames), position.tolist()
        )
        clip.tracks["scale"] = AnimationTrack(
            "scale", "vector3", list(grid_frames), [[v, v, v] for v in level]
        )
        animation.clips[node.path] = clip

    # Impacts on a stop: the link the joint carries turns _IMPACT_COLOR for a moment (a copy
    # of its shapes in that colour is shown in their place); a ball at a joint without shapes.
    for joint in np.unique(timeline.impact_joints):
        if not 0 < joint < model.njoints:
            continue
        flashing = _pulse(grid, timeline.events["impact"][timeline.impact_joints == joint]) > 0
        shapes = [g for g, obj in enumerate(visual.geometryObjects) if obj.parentJoint == joint]
        for g in shapes:
            obj = visual.geometryObjects[g]
            node = _load_flash_shape(viz, obj)
            node.set_transform(placements[-1, g])
            node.set_property("visible", False)
            add_pose_tracks(node.path, placements[:, g])
            _add_visibility(animation, node.path, grid_frames, flashing)
            shape = viz.viewer[viz.getViewerNodeName(obj, pinocchio.GeometryType.VISUAL)]
            _add_visibility(animation, shape.path, grid_frames, ~flashing)
        if not shapes:
            node = root[f"events/impact_{joint}"]
            node.set_object(
                mg.Sphere(0.05 * radius), mg.MeshPhongMaterial(color=_EVENT_COLORS["impact"])
            )
            at = np.tile(np.eye(4), (grid.size, 1, 1))
            at[:, :3, 3] = np.array(
                [np.interp(grid, timeline.times, joint_at[:, joint, i]) for i in range(3)]
            ).T
            node.set_transform(at[-1])
            node.set_property("visible", False)
            add_pose_tracks(node.path, at, grid_frames)
            _add_visibility(animation, node.path, grid_frames, flashing)

    viz.display(timeline.q[-1])  # the final pose, also where the animation ends
    return animation


def _load_flash_shape(viz: Any, obj: pinocchio.GeometryObject) -> Any:
    """A copy of the shape ``obj`` in _IMPACT_COLOR, loaded next to it; its meshcat node."""
    import meshcat.geometry as mg

    flash = obj.copy()
    flash.name = f"{obj.name}_impact"
    flash.meshColor = np.array(_IMPACT_COLOR)
    node = viz.viewer[viz.getViewerNodeName(flash, pinocchio.GeometryType.VISUAL)]
    if obj.meshPath.lower().endswith(".dae"):
        # As a bare geometry: pinocchio loads a DAE with the file's own materials.
        color = int.from_bytes(bytes(int(255 * c) for c in _IMPACT_COLOR[:3]), "big")
        node.set_object(
            mg.DaeMeshGeometry.from_file(obj.meshPath), mg.MeshPhongMaterial(color=color)
        )
    else:
        viz.loadViewerGeometryObject(flash, pinocchio.GeometryType.VISUAL)
    return node


def _add_visibility(animation: Any, path: Any, frames: list[float], shown: np.ndarray) -> None:
    """Show the node at ``path`` at the keyframes where ``shown`` holds, hide it elsewhere."""
    from meshcat.animation import AnimationClip, AnimationTrack

    clip = animation.clips.setdefault(path, AnimationClip(fps=FPS))
    clip.tracks["visible"] = AnimationTrack(
        "visible", "boolean", list(frames), [bool(x) for x in shown]
    )


def play(
    scene: Any,
    result: Result | None = None,
    *,
    speed: float | None = None,
    html: str | Path | None = None,
    plot: str | Path | None = None,
    live: bool = True,
    open_browser: bool = False,
) -> Any:
    """Play the settling motion of ``scene`` in meshcat; return the visualizer.

    Args:
        scene: a ``pinsettle.Scene`` (its URDF's shapes and meshes are drawn; a stick figure
            when it has none), a scene file or library name, or a ``pinocchio.Model``.
        result: a ``Result`` of ``solve(scene, ...)`` with a trace of configurations
            (``trace_configurations=True``, e.g. ``**TRACE_SETTINGS``); None to solve here
            with the scene's settings and ``TRACE_SETTINGS``.
        speed: simulated seconds per second of playback; None: real time, or faster so that a
            settle longer than ``PLAYBACK_SECONDS`` plays in about that long.
        html: also write the self-contained static page (no server needed to view it).
        plot: also write the energy plot (PNG; see ``plot_energy``).
        live: start a meshcat server on 127.0.0.1 (the returned visualizer's ``url``; stop it
            with ``close()`` or a ``with`` block; it also stops when this process exits).
        open_browser: open the live page (or, without a server, the HTML file) in a browser.

    Returns:
        A ``pinocchio.visualize.MeshcatVisualizer`` (``PlaybackVisualizer``) with ``url``,
        ``html()``, ``save_html()``, ``save_plot()``, ``replay()`` and ``close()``.

    Raises:
        MissingDependencyError (an ImportError): meshcat or matplotlib is missing.
        TypeError, ValueError: a bad argument (named in the message), or a result without a
            trace of configurations.
    """
    require()
    scene = _as_scene(scene)
    speed = check_speed(speed)
    if result is None:
        result = solve(scene, **TRACE_SETTINGS)
    timeline = make_timeline(result, scene.model.nq, speed)
    visual = _visual_model(scene) or _stick_figure(scene.model)

    import meshcat

    server = _LiveServer() if live else None
    window = _Window(server)
    try:
        viz = _visualizer_class()(scene.model, None, visual)
        viz.window = window
        viz.scene, viz.result, viz.timeline = scene, result, timeline
        viz.initViewer(viewer=meshcat.Visualizer(window=window)["pinsettle"])
        viz.animation = _build(viz, scene, timeline, visual)
        viz.viewer.set_animation(viz.animation, play=True, repetitions=1)
        if html is not None:
            viz.save_html(html)
        if plot is not None:
            viz.save_plot(plot)
    except BaseException:
        window.close()
        raise
    if open_browser:
        if viz.url:
            viz.open()
        elif html is not None:
            webbrowser.open(Path(html).resolve().as_uri(), new=2)
    return viz


# --- the energy plot ------------------------------------------------------------------------


def plot_energy(result: Result, path: str | Path, *, title: str | None = None) -> Path:
    """Both energy measures of ``result.trace`` against simulated time on a log scale, with
    the damping events (and pushes, roll-backs) marked, saved as PNG at ``path``."""
    require("matplotlib")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not isinstance(result, Result):
        raise TypeError(f"result must be a pinsettle.Result, got {type(result).__name__}")
    trace = result.trace
    if trace is None:
        raise ValueError("result has no trace: solve with trace_every=1 (or more) to plot it")
    path = Path(path)
    fig = Figure(figsize=(8.0, 4.2), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    t = np.asarray(trace.time, dtype=float)

    def positive(values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, dtype=float)
        return np.where(np.isfinite(values) & (values > 0), values, np.nan)

    ax.plot(
        t,
        positive(trace.kinetic_energy),
        lw=1.4,
        color="#1864ab",
        label="exact  Σ ½m|v|² + ½ωᵀIω  (J)",
    )
    ax.plot(
        t,
        positive(trace.simplified_kinetic_energy),
        lw=1.1,
        color="#e8590c",
        label="simplified  Σ |v|² + |ω|²  (m²/s², rad²/s²)",
    )
    ax.set_yscale("log")
    kinds = np.asarray(trace.event_kind, dtype=object)
    event_t = np.asarray(trace.event_time, dtype=float)
    styles = {
        "damping": ("#f59f00", 0.35),
        "push": ("#1c7ed6", 0.9),
        "rollback": ("#e03131", 0.9),
        "impact": ("#d6336c", 0.8),
    }
    for kind, (color, alpha) in styles.items():
        times = event_t[kinds == kind] if kinds.size else np.zeros(0)
        if times.size:
            ax.vlines(
                times,
                0,
                1,
                transform=ax.get_xaxis_transform(),
                colors=color,
                alpha=alpha,
                lw=0.7,
                label=f"{kind} events ({times.size}{_impact_names(result, kind)})",
            )
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("kinetic energy")
    heading = f"{title}: " if title else ""
    ax.set_title(
        f"{heading}{result.status}, {result.steps} steps, {result.peaks} damping events",
        fontsize=11,
    )
    ax.grid(True, which="major", alpha=0.3)
    if t.size:
        ax.set_xlim(float(t[0]), float(max(t[-1], result.sim_time)))
    ax.legend(fontsize=8, loc="upper right", framealpha=0.9)
    fig.savefig(path, format="png")
    return path


def _impact_names(result: Result, kind: str) -> str:
    """For the legend of impacts: which joints hit a stop (at most three named)."""
    trace = result.trace
    if kind != "impact" or trace is None or len(trace.event_joint) != len(trace.event_kind):
        return ""
    names = list(result.joints)  # the model's joints 1, 2, ... in order
    hit = sorted(
        {int(j) for j, k in zip(trace.event_joint, trace.event_kind, strict=True) if k == kind}
    )
    named = [names[j - 1] for j in hit if 0 < j <= len(names)]
    if not named:
        return ""
    more = f" and {len(named) - 3} more" if len(named) > 3 else ""
    return ": " + ", ".join(named[:3]) + more


# ``import pinsettle.play`` binds the module to ``pinsettle.play``: make the module callable, so
# that ``pinsettle.play(scene, result)`` works whichever of the two the name holds.
class _CallableModule(types.ModuleType):
    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return play(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule

"""The cases of a sweep: its keys (the scene values it varies), the scene's variants, and
the ``Runner`` that solves cases and makes their rows, the same on local threads and on a Dask
worker (``_sweep`` plans and runs, ``_sweep_cluster`` sends the cases to a cluster)."""

from __future__ import annotations

import dataclasses
import importlib
import math
import re
import signal
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio

from . import _core
from ._checks import unknown_key_message
from ._scene import JointLoad, PointLoad, Scene, SceneError, _body_frame
from ._settings import make_settings
from ._solve import Result
from ._solver import Solver

#: A pandas.DataFrame (pandas is optional: no static import here).
DataFrame = Any

#: Two rests closer than this (rad or m, the largest difference of a joint, angles modulo 2 pi)
#: are the same rest: ``distinct_rests``' default and the least move that can be a jump.
REST_TOLERANCE = 1e-3

SWEEP_EXTRA = "pip install 'pinsettle[sweep]'"


class MissingDependencyError(ImportError):
    """An optional package the sweep needs is missing; the message says what to install."""


def pandas() -> Any:
    """The pandas module, or an ImportError that says what to install."""
    try:
        return importlib.import_module("pandas")
    except ImportError:
        raise MissingDependencyError(
            f"pinsettle.sweep needs pandas for its table: {SWEEP_EXTRA}"
        ) from None


# --- vary keys -------------------------------------------------------------------------------

_ELEMENT_FIELDS = {
    "joint_spring": ("stiffness", "rest", "damping"),
    "spring": ("stiffness", "rest_length", "damping"),
    "load": ("effort", "force", "torque", "point"),
    "payload": ("mass", "offset"),
}
_KEY_FORMS = (
    "start.JOINT",
    "joint_spring[i].stiffness|rest|damping",
    "spring[i].stiffness|rest_length|damping",
    "load[i].effort|force|torque|point",
    "payload[i].mass|offset",
    "gravity",
    "payload.FRAME.mass",
)
_ELEMENT_RE = re.compile(r"^(joint_spring|spring|load|payload)\[(-?\d+)\]\.(\w+)$")


@dataclass(frozen=True)
class Key:
    """A scene value a sweep varies, resolved against the scene.

    ``kind`` is 'start', 'joint_spring', 'spring', 'load', 'payload' (a [[payload]]),
    'gravity' or 'frame_payload' (``payload.FRAME.mass`` on a frame without a [[payload]]);
    ``index`` the element's index (force elements, payloads), ``name`` the joint (start) or
    frame (frame_payload), ``field`` the element's field. ``size`` is the number of entries
    of a value (1: a number); ``direction`` the unit vector a number scales on a vector value
    (None: numbers are not allowed there, or the value is a number anyway).
    """

    text: str
    kind: str
    index: int = -1
    name: str = ""
    field: str = ""
    size: int = 1
    direction: tuple[float, ...] | None = None


def _elements(scene: Scene, kind: str) -> list[Any]:
    lists: dict[str, list[Any]] = {
        "joint_spring": scene.joint_springs,
        "spring": scene.springs,
        "load": scene.loads,
        "payload": scene.payloads,
    }
    return lists[kind]


def _unit(vector: Sequence[float]) -> tuple[float, ...] | None:
    norm = math.sqrt(sum(x * x for x in vector))
    return None if norm == 0.0 else tuple(x / norm for x in vector)


def _start_key(text: str, model: pinocchio.Model) -> Key:
    """The key ``start.JOINT``: the joint's start value."""
    joint = text[len("start.") :]
    joints = list(model.names)[1:]
    if joint not in joints:
        raise ValueError(f"vary key '{text}': " + unknown_key_message("joint", joint, joints))
    j = model.getJointId(joint)
    size = 1 if model.nvs[j] == 1 else int(model.nqs[j])
    return Key(text, "start", name=joint, size=size)


def _payload_key(text: str, scene: Scene) -> Key:
    """The key ``payload.FRAME.mass``: the mass of the scene's [[payload]] on the frame, or,
    without one, a payload at the frame's origin (a frame that moves)."""
    frame = text[len("payload.") : -len(".mass")]
    model = scene.model
    frames = list(dict.fromkeys(f.name for f in model.frames))
    if frame not in frames:
        raise ValueError(f"vary key '{text}': " + unknown_key_message("frame", frame, frames))
    tables = [k for k, p in enumerate(scene.payloads) if p.frame == frame]
    if len(tables) > 1:
        raise ValueError(
            f"vary key '{text}': frame '{frame}' has {len(tables)} [[payload]] tables; name "
            f"one by its index: " + " or ".join(f"payload[{k}].mass" for k in tables)
        )
    if tables:
        return Key(text, "payload", tables[0], field="mass")
    if model.frames[_body_frame(model, frame)].parentJoint == 0:
        raise ValueError(
            f"vary key '{text}': frame '{frame}' is fixed to the world: a mass there does nothing"
        )
    return Key(text, "frame_payload", name=frame, field="mass")


def _element_fields(kind: str, element: Any) -> tuple[tuple[str, ...], str]:
    """The fields a sweep may vary on a force element, and what the element is (in words)."""
    if kind != "load":
        what = {"joint_spring": "a joint spring", "spring": "a spring", "payload": "a payload"}
        return _ELEMENT_FIELDS[kind], what[kind]
    if isinstance(element, JointLoad):
        return ("effort",), "a joint load"
    return ("force", "torque", "point"), "a load at a frame"


def _element_key(text: str, scene: Scene) -> Key:
    """The key ``KIND[i].FIELD``: a field of a force element by its index."""
    match = _ELEMENT_RE.match(text)
    if match is None:
        raise ValueError(
            f"unknown vary key '{text}'; the keys are {', '.join(_KEY_FORMS)} (i: the element's "
            "index, from 0, in the order of the scene file)"
        )
    kind, index, field = match.group(1), int(match.group(2)), match.group(3)
    items = _elements(scene, kind)
    if not 0 <= index < len(items):
        have = f"{len(items)} [[{kind}]] element" + ("s" if len(items) != 1 else "")
        valid = f" ({kind}[0] to {kind}[{len(items) - 1}])" if items else ""
        raise ValueError(f"vary key '{text}': index {index} is past the scene's {have}{valid}")
    fields, what = _element_fields(kind, items[index])
    if field not in fields:
        raise ValueError(
            f"vary key '{text}': {kind}[{index}] is {what}: "
            + unknown_key_message("field", field, list(fields))
        )
    value = getattr(items[index], field)
    if isinstance(value, tuple):
        return Key(text, kind, index, field=field, size=len(value), direction=_unit(value))
    return Key(text, kind, index, field=field)


def parse_key(text: Any, scene: Scene) -> Key:
    """The ``vary`` key ``text`` resolved against ``scene``.

    Raises:
        ValueError: an unknown form, field, joint or frame (with a close match), an element
            index past the scene's elements, a payload on a frame fixed to the world.
    """
    if not isinstance(text, str):
        raise TypeError(f"vary keys must be strings, got {type(text).__name__} {text!r}")
    if text == "gravity":
        return Key(text, "gravity", size=3, direction=_unit(scene.gravity.tolist()))
    if text.startswith("start."):
        return _start_key(text, scene.model)
    if text.startswith("payload.") and text.endswith(".mass") and len(text) > 13:
        return _payload_key(text, scene)
    return _element_key(text, scene)


def _number(value: Any, where: str) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
        raise TypeError(f"{where} must be a number, got {type(value).__name__} {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"{where} must be finite, got {x}")
    return x


def _key_value(key: Key, value: Any, at: str) -> float | tuple[float, ...]:
    """One value of a key (``at``: where it is, for the errors), checked."""
    if isinstance(value, (Sequence, np.ndarray)) and not isinstance(value, str):
        if key.size == 1:
            raise TypeError(f"{at} must be a number, got {value!r}")
        if len(value) != key.size:
            raise ValueError(f"{at} must have {key.size} entries, got {len(value)}")
        return tuple(_number(x, f"{at}[{i}]") for i, x in enumerate(value))
    x = _number(value, at)
    if key.size > 1 and key.kind == "start":
        raise TypeError(
            f"{at}: joint '{key.name}' has {key.size} configuration entries: give lists "
            f"of {key.size} numbers, got {value!r}"
        )
    if key.size > 1 and key.direction is None:
        raise ValueError(
            f"{at}: the scene's {key.text} is zero, so a number (a magnitude along it) "
            f"has no direction: give vectors of {key.size} numbers"
        )
    return x


def key_values(key: Key, values: Any) -> list[float | tuple[float, ...]]:
    """The values a key takes, checked: numbers, or vectors of ``key.size`` numbers for a
    vector value (a number there scales the scene's own vector, ``key.direction``).

    Raises:
        TypeError, ValueError: not a list, empty, a value of the wrong type or size, numbers
            mixed with vectors, a number where the scene's vector is zero; naming the key.
    """
    where = f"vary['{key.text}']"
    if isinstance(values, (str, bytes, Mapping)) or not isinstance(values, (Iterable, np.ndarray)):
        raise TypeError(f"{where} must be a list of values, got {type(values).__name__}")
    items = list(values)
    if not items:
        raise ValueError(f"{where} has no values (a range needs N >= 1)")
    out = [_key_value(key, value, f"{where}[{k}]") for k, value in enumerate(items)]
    if len({isinstance(x, tuple) for x in out}) > 1:
        raise TypeError(f"{where}: give all numbers or all vectors, not both")
    return out


def _vector_value(key: Key, value: float | tuple[float, ...]) -> tuple[float, ...]:
    if isinstance(value, tuple):
        return value
    assert key.direction is not None  # key_values allows a number only with a direction
    return tuple(value * x for x in key.direction)


def value_columns(key: Key, value: float | tuple[float, ...]) -> dict[str, float]:
    """A key's value as table columns: ``key`` for a number, ``key[k]`` for a vector."""
    if isinstance(value, tuple):
        return {f"{key.text}[{k}]": x for k, x in enumerate(value)}
    return {key.text: value}


# --- scenes as data, and their variants ---------------------------------------------------------


def scene_data(scene: Scene) -> dict[str, Any]:
    """Everything a sweep needs to rebuild ``scene`` elsewhere: the model (``pinocchio.Model``
    pickles), the elements, locked joints, stops and settings; plain, picklable data."""
    return {
        "model": pinocchio.Model(scene.model),
        "name": scene.name,
        "description": scene.description,
        "path": None if scene.path is None else str(scene.path),
        "urdf": None if scene.urdf is None else str(scene.urdf),
        "mjcf": None if scene.mjcf is None else str(scene.mjcf),
        "srdf": [str(path) for path in scene.srdf],
        "notes": list(scene.notes),
        "limits": scene.limits,
        "settings": scene.settings.to_dict(),
        "joint_springs": list(scene.joint_springs),
        "springs": list(scene.springs),
        "loads": list(scene.loads),
        "payloads": list(scene.payloads),
        "loops": list(scene.loops),
        "couplings": list(scene.couplings),
        "locked": list(scene.locked),
        "joint_limits": list(scene.joint_limits),
        "grounds": list(scene.grounds),
        "contacts": list(scene.contacts),
        "q0": scene.q0(),
    }


def _add_payload(scene: Scene, frame: str, mass: float, offset: Any) -> None:
    """A payload of a case: none for a mass of 0 (a sweep may start from no payload)."""
    if mass < 0:
        raise SceneError(f"the mass must be >= 0 (kg), got {mass}")
    if mass > 0:
        scene.add_payload(frame, mass, offset)


Changes = tuple[tuple[int, Any], ...]


@dataclass
class _Sorted:
    """A case's changes by what they change: fields of force elements by (kind, index), the
    gravity, payloads; each with the key that changes it."""

    fields: dict[tuple[str, int], dict[str, tuple[Key, Any]]]
    gravity: tuple[Key, tuple[float, ...]] | None
    payloads: list[tuple[Key, float]]

    def element(self, kind: str, k: int, element: Any) -> tuple[Key | None, dict[str, Any]]:
        """The fields of element ``k`` of ``kind`` with the changed ones in place, and the key
        of its first changed field (None: none changed)."""
        values = dataclasses.asdict(element)
        changed = self.fields.get((kind, k), {})
        for name, (_, value) in changed.items():
            values[name] = value
        first = next(iter(changed.values()))[0] if changed else None
        return first, values


def _sort_changes(keys: Sequence[Key], changes: Changes) -> _Sorted:
    """``changes`` ((key index, value), ...) sorted by what they change, vectors in full."""
    out = _Sorted({}, None, [])
    for index, value in changes:
        key = keys[index]
        if key.kind == "gravity":
            out.gravity = (key, _vector_value(key, value))
        elif key.kind == "frame_payload":
            out.payloads.append((key, value))
        elif key.kind in _ELEMENT_FIELDS:
            fixed = _vector_value(key, value) if key.size > 1 else value
            out.fields.setdefault((key.kind, key.index), {})[key.field] = (key, fixed)
    return out


def _at(key: Key | None, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
    """``fn(*args, **kwargs)``; the SceneError it raises names ``key``, the value that caused
    it (None: a value of the scene's own, the error as it is)."""
    try:
        fn(*args, **kwargs)
    except SceneError as error:
        if key is None:
            raise
        raise SceneError(f"{key.text}: {error}") from None


def _scene_of(data: Mapping[str, Any], changed: _Sorted) -> Scene:
    """The scene of ``data`` with its model, files, notes and gravity; no elements yet."""
    model = pinocchio.Model(data["model"])
    scene = Scene(
        model,
        settings=data["settings"],
        name=data["name"],
        description=data["description"],
        limits=data["limits"],
    )
    scene.path = None if data["path"] is None else Path(data["path"])
    scene.urdf = None if data["urdf"] is None else Path(data["urdf"])
    scene.mjcf = None if data["mjcf"] is None else Path(data["mjcf"])
    scene.srdf = [Path(path) for path in data["srdf"]]
    scene.notes = list(data["notes"])
    if changed.gravity is not None:
        _at(changed.gravity[0], setattr, scene, "gravity", changed.gravity[1])
    return scene


def _add_load(
    scene: Scene, load: JointLoad | PointLoad, key: Key | None, v: dict[str, Any]
) -> None:
    if isinstance(load, JointLoad):
        effort = v["effort"] if isinstance(v["effort"], tuple) else (v["effort"],)
        _at(key, scene.add_load, v["joint"], effort[0] if len(effort) == 1 else effort)
        return
    _at(
        key,
        scene.add_load,
        frame=v["frame"],
        point=v["point"],
        force=v["force"],
        torque=v["torque"],
    )


def _add_force_elements(scene: Scene, data: Mapping[str, Any], changed: _Sorted) -> None:
    """The payloads, joint springs, springs and loads of ``data``, with the changed fields
    (payloads first: a bad mass is named before the other elements' values)."""
    for k, payload in enumerate(data["payloads"]):
        key, v = changed.element("payload", k, payload)
        _at(key, _add_payload, scene, v["frame"], v["mass"], v["offset"])
    for key, mass in changed.payloads:  # payload.FRAME.mass on a frame without a [[payload]]
        _at(key, _add_payload, scene, key.name, mass, (0.0, 0.0, 0.0))
    for k, s in enumerate(data["joint_springs"]):
        key, v = changed.element("joint_spring", k, s)
        _at(key, scene.add_joint_spring, v["joint"], v["stiffness"], v["rest"], v["damping"])
    for k, s in enumerate(data["springs"]):
        key, v = changed.element("spring", k, s)
        a = {"frame": v["a_frame"], "point": v["a_point"]}
        b = {"frame": v["b_frame"], "point": v["b_point"]}
        _at(key, scene.add_spring, a, b, v["stiffness"], v["rest_length"], v["damping"])
    for k, load in enumerate(data["loads"]):
        key, v = changed.element("load", k, load)
        _add_load(scene, load, key, v)


def _add_constraints(scene: Scene, data: Mapping[str, Any]) -> None:
    """The loops, couplings, locked joints, stops and contacts of ``data`` (a sweep changes
    none)."""
    for loop in data["loops"]:
        scene.add_loop((loop.a_frame, loop.a_point), (loop.b_frame, loop.b_point), loop.kind)
    for c in data["couplings"]:
        scene.add_coupling(c.follower, c.leader, c.multiplier, c.offset)
    if data["locked"]:
        scene.lock(*data["locked"])
    for limit in data["joint_limits"]:
        scene.set_limit(limit.joint, limit.lower, limit.upper)
    for g in data["grounds"]:
        if g.box is None:
            scene.add_ground(g.point, g.normal, g.friction, g.name)
        else:  # a box is turned by its rpy, not by a normal
            scene.add_ground(g.point, None, g.friction, g.name, box=g.box, rpy=g.rpy)
    for c in data["contacts"]:
        scene.add_contact(c.frame, c.point, c.radius, c.name)


def build_scene(data: Mapping[str, Any], keys: Sequence[Key], changes: Changes) -> Scene:
    """The scene of ``data`` with the values of ``changes`` ((key index, value), ...) in place
    of its own, built through the public Scene API (so every value is checked as there).

    Raises:
        SceneError: a value the scene refuses (a negative stiffness or mass), naming the key.
    """
    changed = _sort_changes(keys, changes)
    scene = _scene_of(data, changed)
    _add_force_elements(scene, data, changed)
    _add_constraints(scene, data)
    scene.compile()  # every element resolved now, once, not in each solve
    return scene


def start_q(model: pinocchio.Model, q: np.ndarray, key: Key, value: Any) -> np.ndarray:
    """``q`` with the joint of a start key set to ``value`` (an angle for a continuous joint)."""
    j = model.getJointId(key.name)
    iq, nq = model.idx_qs[j], model.nqs[j]
    out: np.ndarray = np.array(q, dtype=float)
    if isinstance(value, tuple):
        out[iq : iq + nq] = value
    elif nq == 2:
        out[iq : iq + 2] = (math.cos(value), math.sin(value))
    else:
        out[iq] = value
    return out


# --- joints in the table ------------------------------------------------------------------------

_ANGLE_JOINTS: tuple[str, ...] = ("RX", "RY", "RZ", "RevoluteUnaligned", "RUBX", "RUBY", "RUBZ")
_ANGLE_JOINTS += ("RevoluteUnboundedUnaligned", "SphericalZYX", "Universal", "Ellipsoid")
_LENGTH_JOINTS = ("PX", "PY", "PZ", "PrismaticUnaligned", "Translation")


def joint_kind(model: pinocchio.Model, j: int) -> str:
    """How a joint's values are compared: 'angle' (each modulo 2 pi), 'length', 'quaternion'
    (spherical), 'free' (translation and quaternion), 'planar' (x, y, cos, sin) or 'plain'
    (helical and other joints: entry by entry)."""
    kind = str(model.joints[j].shortname()).removeprefix("JointModel")
    if kind in _ANGLE_JOINTS:
        return "angle"
    if kind in _LENGTH_JOINTS:
        return "length"
    return {"Spherical": "quaternion", "FreeFlyer": "free", "Planar": "planar"}.get(kind, "plain")


@dataclass(frozen=True)
class JointColumns:
    """A free joint in the table: its kind and its columns (one for a 1-DoF joint, the angle
    of a continuous joint; one per configuration entry, ``name[k]``, otherwise)."""

    name: str
    kind: str
    columns: tuple[str, ...]


def joint_columns(scene: Scene, taken: Iterable[str] = ()) -> list[JointColumns]:
    """The free (unlocked) joints' columns; a joint whose name is already a column gets
    ``joint.NAME``."""
    model = scene.model
    reserved = set(taken) | set(OUTPUT_COLUMNS)
    out = []
    for j in range(1, model.njoints):
        name = str(model.names[j])
        if name in scene.locked:
            continue
        base = f"joint.{name}" if name in reserved else name
        if model.nvs[j] == 1:
            columns: tuple[str, ...] = (base,)
        else:
            columns = tuple(f"{base}[{k}]" for k in range(model.nqs[j]))
        out.append(JointColumns(name, joint_kind(model, j), columns))
    return out


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.abs((x + np.pi) % (2 * np.pi) - np.pi)


def _rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    dot = abs(float(np.dot(a, b))) / (np.linalg.norm(a) * np.linalg.norm(b))
    return 2.0 * math.acos(min(1.0, dot))


def segment_distance(kind: str, a: np.ndarray, b: np.ndarray) -> float:
    """The largest difference between two values of a joint (its table columns), angles
    modulo 2 pi, rotations by their angle."""
    if kind == "angle":
        return float(np.max(_wrap(a - b)))
    if kind == "quaternion":
        return _rotation_angle(a, b)
    if kind == "free":
        return max(float(np.max(np.abs(a[:3] - b[:3]))), _rotation_angle(a[3:], b[3:]))
    if kind == "planar":
        turn = math.atan2(a[3], a[2]) - math.atan2(b[3], b[2])
        return max(float(np.max(np.abs(a[:2] - b[:2]))), float(_wrap(np.array(turn))))
    return float(np.max(np.abs(a - b)))


def rest_distance(
    joints: Sequence[JointColumns], a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray
) -> float:
    """The distance of two rests given as the values of ``joints``' columns, in order."""
    out, k = 0.0, 0
    xa, xb = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    for joint in joints:
        n = len(joint.columns)
        out = max(out, segment_distance(joint.kind, xa[k : k + n], xb[k : k + n]))
        k += n
    return out


def joint_row(model: pinocchio.Model, joints: Sequence[JointColumns], q: np.ndarray) -> list[float]:
    """The values of ``joints``' columns at the full configuration q."""
    out: list[float] = []
    for joint in joints:
        j = model.getJointId(joint.name)
        iq, nq = model.idx_qs[j], model.nqs[j]
        if model.nvs[j] == 1 and nq == 2:
            out.append(math.atan2(q[iq + 1], q[iq]))
        else:
            out.extend(float(x) for x in q[iq : iq + nq])
    return out


def q_from_row(
    model: pinocchio.Model, joints: Sequence[JointColumns], values: Sequence[float], q: np.ndarray
) -> np.ndarray:
    """The full configuration ``q`` (locked joints' values kept) with ``joints`` set to the
    values of their columns (the inverse of ``joint_row``)."""
    out = np.array(q, dtype=float)
    k = 0
    for joint in joints:
        j = model.getJointId(joint.name)
        iq, nq = model.idx_qs[j], model.nqs[j]
        if model.nvs[j] == 1 and nq == 2:
            out[iq : iq + 2] = (math.cos(values[k]), math.sin(values[k]))
            k += 1
        else:
            out[iq : iq + nq] = values[k : k + nq]
            k += nq
    return out


# --- running cases ------------------------------------------------------------------------------

#: The columns each case fills, in table order (joint columns go after 'status'; 'at_limit'
#: only where the scene has stops, 'jump' only with continuation).
OUTPUT_COLUMNS = (
    "status",
    "residual",
    "stability",
    "min_stiffness_eigenvalue",
    "at_limit",
    "steps",
    "wall_time",
    "jump",
    "error",
)


@dataclass(frozen=True)
class Spec:
    """One case to run: its number, the scene values it changes and its start (None inside a
    continuation branch after its first case: the previous rest)."""

    case: int
    changes: Changes
    q0: np.ndarray | None


@dataclass(frozen=True)
class Task:
    """Cases run together by one worker: independent cases, or a continuation branch (each
    case starts from the previous rest). ``previous`` continues a branch begun earlier (a
    resumed sweep): its last rest and the changes it was found with."""

    specs: tuple[Spec, ...]
    branch: bool = False
    previous: tuple[Changes, np.ndarray] | None = None


class Runner:
    """Runs the cases of one sweep: the scene's variants (built once each, kept in a small
    cache shared by the threads), one solve per case, one row of outputs per case."""

    CACHE = 64

    def __init__(
        self,
        data: Mapping[str, Any],
        keys: Sequence[Key],
        settings: Mapping[str, Any],
        limits: bool | None,
        continuation: bool,
    ) -> None:
        self.data = data
        self.keys = list(keys)
        self.settings = make_settings(settings, {})
        self.limits = limits
        self.continuation = continuation
        self._variants: OrderedDict[Changes, Scene | SceneError] = OrderedDict()
        self._lock = threading.Lock()
        self._local = threading.local()  # each thread's solvers
        base = self.variant(())
        assert isinstance(base, Scene)
        self.base = base
        self.joints = joint_columns(base, [k.text for k in self.keys])
        compiled = base.compile()
        stops = compiled.stops_for(base.limits if limits is None else limits)
        self.has_stops = bool(
            stops is not None and _core.joint_stops(compiled.model, stops)["stops"]
        )

    def variant(self, changes: Changes) -> Scene | SceneError:
        """The scene with ``changes``, or the error that refuses them (kept too)."""
        with self._lock:  # built under the lock: the GIL serialises it anyway
            if changes in self._variants:
                self._variants.move_to_end(changes)
                return self._variants[changes]
            try:
                scene: Scene | SceneError = build_scene(self.data, self.keys, changes)
            except SceneError as error:
                scene = error
            self._variants[changes] = scene
            if len(self._variants) > self.CACHE:
                self._variants.popitem(last=False)
            return scene

    def solve(
        self, changes: Changes, q0: np.ndarray, callback: Callable[[], bool] | None
    ) -> Result | Exception:
        scene = self.variant(changes)
        if isinstance(scene, Exception):
            return scene
        try:
            return self.solver(changes, scene).solve(q0, callback=callback)
        except Exception as error:  # a case's bad value: recorded, the sweep goes on
            return error

    def solver(self, changes: Changes, scene: Scene) -> Solver:
        """This thread's solver of the scene with ``changes``: made once and kept (the last
        ``CACHE``), as a solver runs one solve at a time and each worker thread needs its own."""
        solvers: OrderedDict[Changes, Solver] | None = getattr(self._local, "solvers", None)
        if solvers is None:
            solvers = self._local.solvers = OrderedDict()
        if changes in solvers:
            solvers.move_to_end(changes)
            return solvers[changes]
        made = solvers[changes] = Solver(scene, self.settings, limits=self.limits)
        if len(solvers) > self.CACHE:
            solvers.popitem(last=False)
        return made

    def outputs(self, result: Result | Exception) -> dict[str, Any]:
        """A case's columns: its outcome, joint values by name, or its error."""
        row: dict[str, Any] = {}
        if isinstance(result, Exception):
            message = str(result) or type(result).__name__
            row.update(status="error", residual=math.nan, stability="")
            row.update(min_stiffness_eigenvalue=math.nan, steps=None, wall_time=math.nan)
            row.update({c: math.nan for joint in self.joints for c in joint.columns})
            plain = isinstance(result, ValueError) or type(result).__name__ == "CaseError"
            row["error"] = message if plain else f"{type(result).__name__}: {message}"
        else:
            values = joint_row(self.base.model, self.joints, result.q)
            columns = [c for joint in self.joints for c in joint.columns]
            row.update(status=result.status, residual=result.residual)
            row.update(stability=result.stability)
            row.update(min_stiffness_eigenvalue=result.min_stiffness_eigenvalue)
            row.update(steps=result.steps, wall_time=result.wall_time, error="")
            row.update(dict(zip(columns, values, strict=True)))
        if self.has_stops:
            at = {} if isinstance(result, Exception) else result.at_limit
            row["at_limit"] = ",".join(f"{name}:{side}" for name, side in at.items())
        return row

    def jumped(self, previous: tuple[Changes, np.ndarray], changes: Changes, q: np.ndarray) -> bool:
        """Whether the rest ``q`` (found with ``changes``) is off the branch of the previous
        rest: released from ``q`` with the previous values, the mechanism does not go back
        (it stays over half as far from the previous rest as ``q`` is)."""
        before_changes, before = previous
        step = rest_distance(
            self.joints,
            joint_row(self.base.model, self.joints, before),
            joint_row(self.base.model, self.joints, q),
        )
        if step <= REST_TOLERANCE:
            return False
        back = self.solve(before_changes, q, None)
        if isinstance(back, Exception) or not back.converged:
            return True
        gap = rest_distance(
            self.joints,
            joint_row(self.base.model, self.joints, before),
            joint_row(self.base.model, self.joints, back.q),
        )
        return gap > 0.5 * step

    def run(
        self,
        task: Task,
        stop: Callable[[], bool] = lambda: False,
        callback: Callable[[], bool] | None = None,
    ) -> list[tuple[int, dict[str, Any]]]:
        """The rows of a task's cases, (case, outputs), in order. ``stop`` is asked between
        cases (a stopped task returns the cases done); ``callback`` is passed to each solve
        (returning True aborts it)."""
        rows: list[tuple[int, dict[str, Any]]] = []
        if not task.branch:
            for spec in task.specs:
                if stop():
                    break
                assert spec.q0 is not None
                result = self.solve(spec.changes, spec.q0, callback)
                rows.append((spec.case, self.outputs(result)))
            return rows
        previous = task.previous
        start = previous[1] if previous is not None else task.specs[0].q0
        assert start is not None
        for spec in task.specs:
            if stop():
                break
            result = self.solve(spec.changes, start, callback)
            row = self.outputs(result)
            row["jump"] = None
            if isinstance(result, Result) and result.converged:
                if previous is not None:
                    row["jump"] = self.jumped(previous, spec.changes, result.q)
                previous, start = (spec.changes, result.q), result.q
            rows.append((spec.case, row))
        return rows


# --- Ctrl-C --------------------------------------------------------------------------------------


Collect = Callable[[list[tuple[int, dict[str, Any]]]], None]


class Interrupts:
    """Ctrl-C during a sweep, counted instead of raised: the first stops new cases, the second
    aborts those in flight. A KeyboardInterrupt raised in the middle of collecting rows could
    lose or repeat some; a count cannot. Only the main thread receives signals: elsewhere this
    counts nothing and Ctrl-C is the caller's."""

    def __init__(self) -> None:
        self.count = 0
        self._installed = False
        self._previous: Any = None

    def __enter__(self) -> Interrupts:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
            self._installed = True
        return self

    def _handle(self, signum: int, frame: object) -> None:
        self.count += 1

    def __exit__(self, *exc: object) -> None:
        if self._installed:
            # None: a handler not set from Python; the default is the closest to it.
            previous = signal.SIG_DFL if self._previous is None else self._previous
            signal.signal(signal.SIGINT, previous)

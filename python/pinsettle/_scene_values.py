"""The parts of a scene that need no scene: its error, its elements by name, value checks
with messages that name the parameter, joint values by name, and joint stops.

``_scene`` (the ``Scene`` and what the solver sees of it) and ``_scene_schema`` (the scene
file) build on these.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio

from . import _core


class SceneError(ValueError):
    """A scene that cannot be built: the message names the file, the key and what was wrong."""


# --- force elements, by name (resolved against the model when a scene is solved) -----------


@dataclass(frozen=True)
class JointSpring:
    """tau = -stiffness (q - rest) - damping qdot on a 1-DoF joint."""

    joint: str
    stiffness: float
    rest: float = 0.0
    damping: float = 0.0


@dataclass(frozen=True)
class Spring:
    """A straight spring-damper from ``a_point`` of ``a_frame`` to ``b_point`` of ``b_frame``."""

    a_frame: str
    a_point: tuple[float, float, float]
    b_frame: str
    b_point: tuple[float, float, float]
    stiffness: float
    rest_length: float = 0.0
    damping: float = 0.0


@dataclass(frozen=True)
class JointLoad:
    """A constant effort on a joint (N m or N; one entry per degree of freedom)."""

    joint: str
    effort: tuple[float, ...]


@dataclass(frozen=True)
class PointLoad:
    """A constant world-aligned force (N) and torque (N m) at a point (m) of a frame."""

    frame: str
    point: tuple[float, float, float]
    force: tuple[float, float, float]
    torque: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Payload:
    """A payload: a point mass (kg) at ``offset`` (m, in the frame's axes) from a frame's
    origin. Its weight, mass times gravity, hangs there: a point load (``load``)."""

    frame: str
    mass: float
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def load(self, gravity: Sequence[float]) -> PointLoad:
        """The payload's weight under ``gravity`` (m/s^2, world axes) as a point load."""
        weight = tuple(self.mass * float(g) for g in gravity)
        return PointLoad(self.frame, self.offset, weight)  # type: ignore[arg-type]


@dataclass(frozen=True)
class Loop:
    """A loop closure: ``a_point`` of ``a_frame`` and ``b_point`` of ``b_frame`` coincide
    (``kind`` 'point': a spherical joint, a pin joint in a plane) or the two frames, moved to
    those points, coincide (``kind`` 'frame': a weld)."""

    a_frame: str
    a_point: tuple[float, float, float]
    b_frame: str
    b_point: tuple[float, float, float]
    kind: str = "point"


LOOP_KINDS = ("point", "frame")


@dataclass(frozen=True)
class Ground:
    """A ground plane through ``point`` with unit ``normal`` (out of the ground, world, m), and
    its Coulomb friction coefficient; or, with ``box`` (its full size along its own axes, m), a
    box centred at ``point``, turned by ``rpy`` (roll, pitch, yaw, rad, as a URDF origin), whose
    ``normal`` is then its top face's (its own z axis in the world)."""

    name: str
    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    friction: float
    box: tuple[float, float, float] | None = None
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def rotation(self) -> np.ndarray:
        """The box's axes in the world (3 x 3, its columns; the identity for a plane)."""
        return np.asarray(pinocchio.rpy.rpyToMatrix(*self.rpy))


@dataclass(frozen=True)
class ContactPoint:
    """A point of a body that can touch the ground: the centre ``point`` (in ``frame``, m) of a
    sphere of ``radius`` (m; 0 for a point)."""

    name: str
    frame: str
    point: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class Coupling:
    """A joint coupling (a URDF ``<mimic>`` tag, a mimic joint): q[follower] = multiplier *
    q[leader] + offset, two 1-DoF joints (rad or m)."""

    follower: str
    leader: str
    multiplier: float = 1.0
    offset: float = 0.0

    def text(self) -> str:
        return f"'{self.follower}' = {self.multiplier:g} * '{self.leader}' + {self.offset:g}"


def has_mimic_joints(model: pinocchio.Model) -> bool:
    """Whether a model holds mimic joints (``pinocchio.buildModelFromUrdf(path, mimic=True)``):
    a follower has no velocity of its own but one in the extended space (a test of 0.5 us where
    a look at every joint's type took 8 us on the UR5, 0.6% of its solve)."""
    return bool(model.nv != model.nvExtended or len(model.mimicking_joints) > 0)


@dataclass(frozen=True)
class JointLimit:
    """Stops of a 1-DoF joint set by ``Scene.set_limit`` (``[[limit]]``), rad or m. A side left
    None is the model's own limit on that side while the scene's ``limits`` is on (none when it
    is off, or when the model has no usable limit there); -inf / +inf: no stop on that side."""

    joint: str
    lower: float | None = None
    upper: float | None = None


_INF = math.inf


# --- value checks with messages that name the parameter --------------------------------------


def _number(value: Any, name: str, *, nonnegative: bool = False) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
        raise SceneError(f"{name} must be a number, got {type(value).__name__} {value!r}")
    try:
        x = float(value)
    except OverflowError:
        raise SceneError(f"{name} is too large for a float: {value}") from None
    if not math.isfinite(x):
        raise SceneError(f"{name} must be finite, got {x}")
    if nonnegative and x < 0:
        raise SceneError(f"{name} must be >= 0, got {x}")
    return x


def _vector(value: Any, name: str, size: int) -> tuple[float, ...]:
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, (Sequence, np.ndarray)):
        raise SceneError(
            f"{name} must be a list of {size} numbers, got {type(value).__name__} {value!r}"
        )
    if len(value) != size:
        raise SceneError(f"{name} must have {size} entries, got {len(value)}: {list(value)!r}")
    return tuple(_number(x, f"{name}[{k}]") for k, x in enumerate(value))


def _close(name: str, known: Sequence[str], kind: str) -> str:
    close = difflib.get_close_matches(name, known, n=1)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    # A hand or a humanoid has 30 to 90 joints and more frames: the first few, then a count.
    shown = ", ".join(known[:8]) + (f" and {len(known) - 8} more" if len(known) > 8 else "")
    return f"unknown {kind} '{name}'{hint}; {kind}s: {shown}"


def _joint_kind(model: pinocchio.Model, j: int) -> str:
    return str(model.joints[j].shortname())


# --- per-joint values by name ------------------------------------------------------------------
#
# Everywhere a joint's value is given or shown by name (set_start, [start], --start, set_pose,
# Result.joints, the JSON's "joints") a quaternion is written w first, (w, x, y, z), as MuJoCo's
# qpos: a free-flyer is (x, y, z, qw, qx, qy, qz), a spherical (ball) joint (qw, qx, qy, qz).
# Pinocchio's configuration q (Result.q, q0) keeps its own order, (x, y, z, w).

#: A quaternion given by name may be off unit norm by this much (values typed to 4 digits,
#: 0.7071 for cos 45 degrees): it is normalised. Further off it is an error.
UNIT_NORM_SLACK = 1e-3

#: What the value of a joint given as a list holds, for messages.
_LAYOUTS = {
    "JointModelFreeFlyer": "a free joint's value is x, y, z, qw, qx, qy, qz (m, then a unit "
    "quaternion w first)",
    "JointModelSpherical": "a ball joint's value is qw, qx, qy, qz (a unit quaternion, w first)",
    "JointModelPlanar": "a planar joint's value is x, y, cos, sin (m, then a unit cos/sin pair)",
}


def _unit_parts(model: pinocchio.Model, j: int) -> list[tuple[int, int]]:
    """(offset, size) in joint j's configuration segment of each part that has unit norm: a
    quaternion (4 entries, Pinocchio's x, y, z, w) or a cos/sin pair (2)."""
    base = int(model.idx_qs[j])

    def parts(joint: Any) -> list[tuple[int, int]]:
        kind = str(joint.shortname())
        at = int(joint.idx_q) - base
        if kind == "JointModelFreeFlyer":
            return [(at + 3, 4)]
        if kind == "JointModelSpherical":
            return [(at, 4)]
        if kind == "JointModelPlanar":
            return [(at + 2, 2)]
        if kind == "JointModelComposite":
            return [p for part in joint.extract().joints for p in parts(part)]
        if joint.nq == 2 and joint.nv == 1:  # a continuous joint's (cos, sin)
            return [(at, 2)]
        return []

    return parts(model.joints[j])


def named_value(model: pinocchio.Model, j: int, segment: Any) -> float | list[float]:
    """Joint j's value by name from its configuration segment (Pinocchio's order): a number
    (rad or m) for a 1-DoF joint (the angle of a continuous one), else a list with each
    quaternion w first."""
    x = [float(v) for v in segment]
    if model.nvs[j] == 1 and len(x) == 2:
        return math.atan2(x[1], x[0])
    if len(x) == 1:
        return x[0]
    for at, size in _unit_parts(model, j):
        if size == 4:
            x[at : at + 4] = [x[at + 3], *x[at : at + 3]]
    return x


def _show(values: Any) -> str:
    return ", ".join(f"{v:g}" for v in values)


def _is_angle_pair(model: pinocchio.Model, j: int) -> bool:
    """A continuous (unbounded revolute) joint: one DoF stored as (cos, sin)."""
    return bool(model.nvs[j] == 1 and model.nqs[j] == 2)


def _bound(value: Any, name: str, none: float) -> float:
    """A stop position (rad or m): a number, or ``none`` (-inf for a lower stop, +inf for an
    upper one) for no stop on that side."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)):
        raise SceneError(
            f"{name} must be a number (rad or m), got {type(value).__name__} {value!r}"
        )
    try:
        x = float(value)
    except OverflowError:
        raise SceneError(f"{name} is too large for a float: {value}") from None
    if math.isnan(x):
        raise SceneError(f"{name} must be a number (rad or m), got nan")
    if math.isinf(x) and x != none:
        raise SceneError(f"{name} must be finite, or {none} for no stop on that side, got {x}")
    return x


def model_stops(model: pinocchio.Model) -> dict[str, tuple[float, float]]:
    """The stops a model's own position limits make, by joint name: (lower, upper), rad or m,
    -inf / +inf where a side has none (the rules of ``pinsettle::JointStops``: 1-DoF joints with
    one coordinate; equal limits, non-finite or huge ones are no stop)."""
    return {
        name: (lower, upper)
        for name, _, _, lower, upper in _core.joint_stops(model, (True, []))["stops"]
    }


def _effective_stop(
    limit: JointLimit, own: Mapping[str, tuple[float, float]]
) -> tuple[float, float]:
    """The (lower, upper) stops of a ``set_limit`` entry: a side left None takes the model's
    own stop from ``own`` (empty when the scene's limits are off), else none (-inf / +inf).

    Raises:
        SceneError: lower > upper, saying which side is the model's.
    """
    model_lower, model_upper = own.get(limit.joint, (-_INF, _INF))
    lower = model_lower if limit.lower is None else limit.lower
    upper = model_upper if limit.upper is None else limit.upper
    if lower > upper:

        def origin(side: str, given: float | None) -> str:
            return "" if given is not None else f" (the model's own {side} limit)"

        raise SceneError(
            f"joint '{limit.joint}': lower {lower:g}{origin('lower', limit.lower)} > upper "
            f"{upper:g}{origin('upper', limit.upper)}"
        )
    return lower, upper


def joint_values(model: pinocchio.Model, q: np.ndarray) -> dict[str, float | list[float]]:
    """Joint values by name (``named_value``): a number for a 1-DoF joint (the angle of a
    continuous joint), a list for a multi-DoF joint, each quaternion w first."""
    return JointReader(model).values(q)


class JointReader:
    """``joint_values`` for one model, its joints read once (in one call to the core: each of
    the model's vectors, names, idx_qs, ..., is a copy made on every access from Python, 45 us
    a call on the UR5 when read per joint, 2 us from these lists)."""

    def __init__(self, model: pinocchio.Model) -> None:
        self.model = model
        names, idx_qs, nqs, _ = _core.joint_layout(model)
        # (name, index in q) of the 1-DoF joints of one entry, (name, joint, start, end) of
        # the others
        self.simple: list[tuple[str, int]] = []
        self.other: list[tuple[str, int, int, int]] = []
        for j, nq in enumerate(nqs[1:], start=1):
            if nq == 1:
                self.simple.append((names[j], idx_qs[j]))
            else:
                self.other.append((names[j], j, idx_qs[j], idx_qs[j] + nq))
        self.order = names[1:]

    def fields(self) -> list[tuple[str, int, int, list[int]]]:
        """How the core reads each joint's value (``_core.Solver``'s ``joints``): (name, index
        in q, kind, offsets): kind 0 the number q[i], 1 a continuous joint's angle, 2 the list
        of q[i + offset] (the offsets put each quaternion w first)."""
        out: list[tuple[str, int, int, list[int]]] = []
        for name, j, start, end in self.other:
            layout = named_value(self.model, j, np.arange(end - start, dtype=float))
            if isinstance(layout, float):  # a continuous joint's (cos, sin)
                out.append((name, start, 1, []))
            else:
                out.append((name, start, 2, [int(k) for k in layout]))
        out += [(name, i, 0, []) for name, i in self.simple]
        order = {name: k for k, name in enumerate(self.order)}
        return sorted(out, key=lambda field: order[field[0]])

    def values(self, q: np.ndarray) -> dict[str, float | list[float]]:
        values = q.tolist()
        out: dict[str, float | list[float]] = {name: values[i] for name, i in self.simple}
        for name, j, start, end in self.other:
            out[name] = named_value(self.model, j, q[start:end])
        if self.other:  # in the model's order, as before
            out = {name: out[name] for name in self.order}
        return out

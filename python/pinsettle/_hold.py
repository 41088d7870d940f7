"""What a pose asks of its motors: the joint efforts that hold a mechanism still at q
(``hold``) and the largest payload a frame can carry there within the effort limits
(``payload``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio

from ._checks import as_vector
from ._memory import new_data
from ._scene import Scene, SceneError, _body_frame
from ._scene_values import _vector
from ._solve import effort_kinds, effort_unit


@dataclass(frozen=True)
class Hold:
    """The efforts that hold a mechanism still at ``q`` (full configuration).

    ``tau`` (dim model.nv, N m or N): the effort each joint's motor applies, gravity minus the
    scene's springs, loads and payloads (Pinocchio's rnea(q, 0, 0) with those forces taken
    off); ``efforts`` the same by joint name (a list for a multi-DoF joint). ``effort_limits``:
    each joint's limit (the model's ``effortLimit``, a URDF's ``<limit effort>``), None where
    the model gives none (not finite, or not above 0). ``over_limit``: the joints whose effort
    exceeds its limit in magnitude, in joint order.
    """

    q: np.ndarray
    tau: np.ndarray
    efforts: dict[str, float | list[float]]
    effort_limits: dict[str, float | list[float] | None]
    over_limit: list[str]

    def to_dict(self) -> dict[str, Any]:
        return {
            "efforts": self.efforts,
            "effort_limits": self.effort_limits,
            "over_limit": self.over_limit,
            "q": [float(x) for x in self.q],
        }


@dataclass(frozen=True)
class PayloadCapacity:
    """The largest payload ``mass`` (kg) at ``offset`` (m, in the frame's axes) from the origin
    of ``frame`` that the pose holds with every joint within its effort limit, and the joint
    whose limit sets it (``limiting_joint``; None when no limit bounds it: ``mass`` is then
    inf). ``per_kg`` (dim model.nv, N m/kg or N/kg): what each kilogram adds to the efforts
    (``per_kg_by_joint`` by name);
    ``hold`` the efforts without the payload, ``loaded`` those with ``mass`` at the point (None
    when mass is inf). A pose that cannot hold even the bare mechanism has mass 0 and its
    limiting joint the one furthest over its limit (``hold.over_limit`` lists them all)."""

    frame: str
    offset: tuple[float, float, float]
    mass: float
    limiting_joint: str | None
    per_kg: np.ndarray
    per_kg_by_joint: dict[str, float | list[float]]
    hold: Hold
    loaded: Hold | None

    def to_dict(self) -> dict[str, Any]:
        finite = math.isfinite(self.mass)
        return {
            "frame": self.frame,
            "offset": list(self.offset),
            "mass": self.mass if finite else None,
            "limiting_joint": self.limiting_joint,
            "per_kg": self.per_kg_by_joint,
            "efforts_unloaded": self.hold.efforts,
            "efforts_at_mass": None if self.loaded is None else self.loaded.efforts,
            "effort_limits": self.hold.effort_limits,
            "over_limit_unloaded": self.hold.over_limit,
        }


def _as_scene(scene_or_model: Any) -> Scene:
    if isinstance(scene_or_model, Scene):
        return scene_or_model
    if isinstance(scene_or_model, pinocchio.Model):
        return Scene(scene_or_model)
    raise TypeError(
        "scene_or_model must be a pinsettle.Scene or a pinocchio.Model, got "
        f"{type(scene_or_model).__name__}"
    )


def _refuse_unsupported(scene: Scene) -> None:
    """What the efforts of a fixed tree cannot answer: a floating body (contact forces carry
    it), contacts, loops and couplings (their reactions share the load)."""
    model = scene.model
    free = [
        str(model.names[j])
        for j in range(1, model.njoints)
        if model.joints[j].shortname() == "JointModelFreeFlyer"
    ]
    if free:
        raise SceneError(
            f"hold of a floating-base mechanism needs contact forces: not yet supported "
            f"(free joint{'s' if len(free) > 1 else ''}: {', '.join(free)})"
        )
    reasons = [
        (scene.contacts, "ground contacts (their forces share the load; --no-contacts)"),
        (scene.loops, "closed loops (their reactions share the load)"),
        (scene.couplings, "joint couplings or mimic joints (one motor drives several joints)"),
    ]
    for items, what in reasons:
        if items:
            raise SceneError(f"hold of a mechanism with {what}: not yet supported")


def _by_joint(model: pinocchio.Model, x: Sequence[Any] | np.ndarray) -> dict[str, Any]:
    """A vector over velocities (dim nv) by joint name: a number for a 1-DoF joint, a list for
    a multi-DoF one."""
    out: dict[str, Any] = {}
    for j in range(1, model.njoints):
        iv, nv = model.idx_vs[j], model.nvs[j]
        part = [None if v is None else float(v) for v in x[iv : iv + nv]]
        out[str(model.names[j])] = part[0] if nv == 1 else part
    return out


def effort_limits(model: pinocchio.Model) -> np.ndarray:
    """Each velocity's effort limit (N m or N), nan where the model gives none (a limit that
    is not finite or not above 0)."""
    limits = np.array(model.effortLimit, dtype=float)
    limits[~(np.isfinite(limits) & (limits > 0))] = np.nan
    return limits


def _full_static_force(scene: Scene, q: np.ndarray) -> np.ndarray:
    """The scene's static force on every joint, locked ones included: a lock is a brake, and
    what it holds is that joint's effort as well."""
    if not scene.locked:
        return np.asarray(scene.static_force(q), dtype=float)
    locked = scene.locked
    scene.locked = []
    scene._changed()
    try:
        return np.asarray(scene.static_force(q), dtype=float)
    finally:
        scene.locked = locked
        scene._changed()


def _make_hold(model: pinocchio.Model, q: np.ndarray, tau: np.ndarray) -> Hold:
    limits = effort_limits(model)
    over = np.abs(tau) > limits  # nan compares False: no limit, never over
    names = [
        str(model.names[j])
        for j in range(1, model.njoints)
        if over[model.idx_vs[j] : model.idx_vs[j] + model.nvs[j]].any()
    ]
    shown = [None if np.isnan(x) else float(x) for x in limits]
    return Hold(q.copy(), tau, _by_joint(model, tau), _by_joint(model, shown), names)


def _start(scene: Scene, q: Any) -> np.ndarray:
    if q is None:
        return scene.q0()
    return as_vector(q, "q", scene.model.nq, "model.nq")


def hold(scene_or_model: Any, q: Any = None) -> Hold:
    """The joint efforts that hold a mechanism still at ``q`` (full configuration, Pinocchio's
    order; None: the scene's start, a model's neutral): gravity minus the scene's springs,
    loads and payloads, the effort each motor applies (``pinocchio.rnea(q, 0, 0)`` for a bare
    model), with each joint's effort limit and the joints over it. Locked joints are listed
    too (what their lock holds). Joint stops play no part (the efforts hold the pose off
    them).

    Raises:
        SceneError: a floating base, ground contacts, loops or couplings (not yet supported).
        TypeError, ValueError: a q of the wrong size or kind.
    """
    scene = _as_scene(scene_or_model)
    _refuse_unsupported(scene)
    qv = _start(scene, q)
    return _make_hold(scene.model, qv, _full_static_force(scene, qv))


def _point_jacobian(model: pinocchio.Model, q: np.ndarray, frame: int, offset: np.ndarray) -> Any:
    """The world-axes Jacobian (3 x nv) of the point at ``offset`` (frame axes) of a frame."""
    data = new_data(model, "the payload's Jacobian")
    pinocchio.computeJointJacobians(model, data, q)
    pinocchio.updateFramePlacements(model, data)
    jac = pinocchio.getFrameJacobian(model, data, frame, pinocchio.LOCAL_WORLD_ALIGNED)
    r = data.oMf[frame].rotation @ offset  # from the frame's origin to the point, world axes
    return jac[:3] - pinocchio.skew(r) @ jac[3:]


def _largest_mass(tau0: np.ndarray, per_kg: np.ndarray, limits: np.ndarray) -> tuple[float, int]:
    """The largest m >= 0 with |tau0 + m per_kg| <= limits (nan: no limit) and the index that
    sets it (-1: none bounds it); 0 and the worst index when m = 0 is already over."""
    ratio = np.where(np.isnan(limits), 0.0, np.abs(tau0) / np.where(np.isnan(limits), 1, limits))
    if (ratio > 1).any():
        return 0.0, int(np.argmax(ratio))
    bounds = np.full(tau0.shape, np.inf)
    for k in np.flatnonzero(~np.isnan(limits) & (per_kg != 0)):
        # tau0 + m a reaches +L when a > 0, -L when a < 0
        bounds[k] = (limits[k] - np.sign(per_kg[k]) * tau0[k]) / abs(per_kg[k])
    if not np.isfinite(bounds).any():
        return math.inf, -1
    i = int(np.argmin(bounds))
    return float(max(bounds[i], 0.0)), i


def _joint_of_velocity(model: pinocchio.Model, index: int) -> str:
    for j in range(1, model.njoints):
        if model.idx_vs[j] <= index < model.idx_vs[j] + model.nvs[j]:
            return str(model.names[j])
    raise IndexError(index)


def payload(
    scene_or_model: Any, q: Any = None, frame: Any = None, offset: Any = (0.0, 0.0, 0.0)
) -> PayloadCapacity:
    """The largest mass (kg) at ``offset`` (m, in the axes of ``frame``) from the origin of
    ``frame`` that the mechanism holds at ``q`` (as for ``hold``) with every joint within its
    effort limit, and the joint that limits it. The efforts are affine in the mass:
    tau(m) = tau0 - m J^T g, J the point's world-axes Jacobian, g the scene's gravity.

    Raises:
        SceneError: an unknown frame (with a close match), one fixed to the world; as ``hold``.
    """
    return payload_at(_as_scene(scene_or_model), q, frame, offset)


def payload_at(
    scene: Scene, q: Any, frame: Any, offset: Any, names: tuple[str, str] = ("frame", "offset")
) -> PayloadCapacity:
    """``payload`` on a scene, errors naming the frame and offset as ``names`` (the command
    line's flags)."""
    base = hold(scene, q)
    model = scene.model
    name = scene._frame_name(frame, names[0])
    frame_id = _body_frame(model, name)
    if model.frames[frame_id].parentJoint == 0:
        raise SceneError(
            f"{names[0]}: '{name}' is fixed to the world: a payload there hangs on nothing that "
            "moves"
        )
    at = np.array(_vector(offset, names[1], 3), dtype=float)
    per_kg = -_point_jacobian(model, base.q, frame_id, at).T @ scene.gravity
    mass, index = _largest_mass(base.tau, per_kg, effort_limits(model))
    loaded = None
    if math.isfinite(mass):
        loaded = _make_hold(model, base.q, base.tau + mass * per_kg)
    limiting = None if index < 0 else _joint_of_velocity(model, index)
    triple = (float(at[0]), float(at[1]), float(at[2]))
    return PayloadCapacity(
        name, triple, mass, limiting, per_kg, _by_joint(model, per_kg), base, loaded
    )


def _table(model: pinocchio.Model, columns: Sequence[tuple[str, np.ndarray, str]]) -> list[str]:
    """One line per joint velocity: its name, then each column (head, values, what follows
    the unit) in that joint's unit (N m, or N for a joint that only slides), '-' for nan (no
    limit)."""
    width = max([len(str(n)) for n in list(model.names)[1:]] + [5]) + 2
    lines = [f"{'joint':<{width}}" + "".join(f"{h:>18}" for h, _, _ in columns)]
    for j in range(1, model.njoints):
        unit = effort_unit(effort_kinds_of_joint(model, j))
        for k in range(model.nvs[j]):
            iv = model.idx_vs[j] + k
            name = str(model.names[j]) + (f"[{k}]" if model.nvs[j] > 1 else "")
            cells = [
                "-" if np.isnan(c[iv]) else f"{c[iv]:.4g} {unit}{per}" for _, c, per in columns
            ]
            lines.append(f"{name:<{width}}" + "".join(f"{c:>18}" for c in cells))
    return lines


def effort_kinds_of_joint(model: pinocchio.Model, j: int) -> set[str]:
    """The units of one joint's efforts (``effort_kinds`` of the joint alone)."""
    others = [str(n) for i, n in enumerate(model.names) if i not in (0, j)]
    return effort_kinds(model, without=others)


def hold_summary(model: pinocchio.Model, result: Hold) -> str:
    """The efforts, limits and the share of each limit used, one joint a line."""
    limits = effort_limits(model)
    share = 100 * np.abs(result.tau) / limits
    lines = _table(model, [("effort", result.tau, ""), ("limit", limits, "")])
    lines = [
        line + ("" if i == 0 else "  -" if np.isnan(share[i - 1]) else f"  {share[i - 1]:.1f}%")
        for i, line in enumerate(lines)
    ]
    lines[0] += "  of limit"
    over = ", ".join(result.over_limit) if result.over_limit else "none"
    return "\n".join([*lines, f"over limit: {over}"])


def payload_summary(model: pinocchio.Model, result: PayloadCapacity) -> str:
    """The mass, the joint that limits it and the efforts with and without it."""
    offset = ", ".join(f"{x:g}" for x in result.offset)
    at = f"{result.frame}" + (f" (offset {offset} m)" if any(result.offset) else "")
    if not math.isfinite(result.mass):
        head = f"payload at {at}: no effort limit bounds it (no joint with a limit carries it)"
    elif result.hold.over_limit:
        head = (
            f"payload at {at}: 0 kg, the pose cannot hold itself: over limit already "
            f"{', '.join(result.hold.over_limit)}"
        )
    else:
        head = f"payload at {at}: {result.mass:.4g} kg, limited by {result.limiting_joint}"
    loaded = np.full(model.nv, np.nan) if result.loaded is None else result.loaded.tau
    columns = [
        ("per kg", result.per_kg, "/kg"),
        ("unloaded", result.hold.tau, ""),
        ("at the mass", loaded, ""),
        ("limit", effort_limits(model), ""),
    ]
    return "\n".join([head, *_table(model, columns)])

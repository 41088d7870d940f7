"""A scene as the solver sees it (``Scene.compile``): the reduced model (locked joints removed)
and the force elements, loops, couplings and stops resolved to its indices, as the C++ core
takes them. What a scene is made of is checked against the model here once more, as a whole:
an element on a locked joint, a spring or loop with both ends on one body.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Protocol

import numpy as np
import pinocchio

from . import _core
from ._scene_values import (
    ContactPoint,
    Coupling,
    Ground,
    JointLimit,
    JointLoad,
    JointSpring,
    Loop,
    Payload,
    PointLoad,
    SceneError,
    Spring,
    _effective_stop,
    model_stops,
)


class SceneParts(Protocol):
    """What compiling needs of a ``Scene``."""

    model: pinocchio.Model
    locked: list[str]
    joint_springs: list[JointSpring]
    springs: list[Spring]
    loads: list[JointLoad | PointLoad]
    payloads: list[Payload]
    loops: list[Loop]
    couplings: list[Coupling]
    joint_limits: list[JointLimit]
    grounds: list[Ground]
    contacts: list[ContactPoint]

    @property
    def limits(self) -> bool: ...


def _check_not_locked(scene: SceneParts) -> None:
    """A joint spring, load or stop on a locked joint would do nothing: an error."""
    for kind, items in (
        ("joint_spring", scene.joint_springs),
        ("load", scene.loads),
        ("limit", scene.joint_limits),
    ):
        for k, item in enumerate(items, start=1):
            joint = getattr(item, "joint", None)
            if joint in scene.locked:
                raise SceneError(
                    f"[[{kind}]] #{k} on joint '{joint}': the joint is locked, so "
                    + ("its stops would" if kind == "limit" else "it would")
                    + " do nothing"
                )


def _reduced_model(full: pinocchio.Model, locked_ids: list[int], q_ref: np.ndarray) -> Any:
    """The model without its locked joints (held at their value in q_ref).

    Raises:
        SceneError: no joint is left to move.
    """
    model = pinocchio.buildReducedModel(full, sorted(locked_ids), q_ref) if locked_ids else full
    if model.nv == 0:
        raise SceneError(
            "every joint is locked: nothing to settle"
            if locked_ids
            else "no joint moves (the model's joints are all fixed): nothing to settle; "
            "a free-flyer on the root (--floating, [model] floating = true) lets it fall"
        )
    return model


def _segments(starts: Any, sizes: Any, joints: list[int]) -> np.ndarray:
    """The indices of the joints' segments (of q or v), in order."""
    return np.concatenate([np.arange(starts[j], starts[j] + sizes[j]) for j in joints]).astype(int)


def _point_loads(scene: SceneParts) -> list[PointLoad]:
    """The point loads of a scene: its loads at frames, then its payloads' weights under the
    model's gravity."""
    gravity = scene.model.gravity.linear
    return [load for load in scene.loads if isinstance(load, PointLoad)] + [
        payload.load(gravity) for payload in scene.payloads
    ]


class _Compiled:
    """A scene as the solver sees it: the reduced model and index-resolved elements."""

    def __init__(self, scene: SceneParts, q_ref: np.ndarray) -> None:
        full = scene.model
        _check_not_locked(scene)
        locked_ids = [full.getJointId(name) for name in scene.locked]
        model = _reduced_model(full, locked_ids, q_ref)
        self.model = model
        kept = [j for j in range(1, full.njoints) if j not in locked_ids]
        # Reduced coordinates are the kept joints' segments, in the same order.
        self.q_index = _segments(full.idx_qs, full.nqs, kept)
        self.v_index = _segments(full.idx_vs, full.nvs, kept)
        assert self.q_index.size == model.nq and self.v_index.size == model.nv
        self.q_ref = np.array(q_ref, dtype=float)
        once_locked = ", once the locked joints are removed" if locked_ids else ""
        for k, s in enumerate(scene.springs, start=1):
            self._check_two_bodies(f"[[spring]] #{k}", s, once_locked, "exerts no net effort")
        # No elements: the solver runs the bare core.
        self.elements = self._elements(scene)
        for k, loop in enumerate(scene.loops, start=1):
            self._check_two_bodies(f"[[loop]] #{k}", loop, once_locked, "holds nothing")
        #: Loop closures and joint couplings as the C++ core takes them; None for a tree
        #: (plain ABA).
        self.loops: list[tuple[Any, ...]] | None = (
            self._loops(scene) + self._couplings(scene) or None
        )
        # Joint stops: the model's own (the reduced model keeps the position limits of the
        # joints it keeps) and those set by name, resolved when the limits setting is known.
        self._own_stops = model_stops(model)
        self._set_stops = [(int(model.getJointId(lim.joint)), lim) for lim in scene.joint_limits]
        #: The stops as the C++ core takes them with the scene's own setting (None: no stop).
        self.stops = self.stops_for(scene.limits)
        #: Ground planes and contact points as the C++ core takes them (None: none).
        self.contacts = self._contacts(scene)
        try:
            _core.static_force(model, pinocchio.neutral(model), self.elements)
        except ValueError as error:  # anything the C++ checks catch that the above did not
            raise SceneError(str(error)) from None

    def _frame(self, name: str) -> int:
        """A frame of the reduced model by name, a body's first."""
        for kind in (pinocchio.FrameType.BODY, None):
            for i, f in enumerate(self.model.frames):
                if f.name == name and (kind is None or f.type == kind):
                    return i
        raise SceneError(f"frame '{name}' is missing from the reduced model")

    def _check_two_bodies(self, where: str, ends: Spring | Loop, once: str, why: str) -> None:
        """A spring or loop with both ends on one rigid body is an error of the scene."""
        frames = self.model.frames
        ja = frames[self._frame(ends.a_frame)].parentJoint
        jb = frames[self._frame(ends.b_frame)].parentJoint
        if ja == jb:
            body = "the world" if ja == 0 else f"the body of joint '{self.model.names[ja]}'"
            kind = "spring" if isinstance(ends, Spring) else "loop"
            raise SceneError(
                f"{where}: both ends ('{ends.a_frame}' and '{ends.b_frame}') are on the "
                f"same rigid body ({body}{once}); such a {kind} {why}"
            )

    def _elements(self, scene: SceneParts) -> dict[str, list[tuple[Any, ...]]] | None:
        """The force elements as the C++ core takes them (None: there is none)."""
        model, frame = self.model, self._frame
        spec: dict[str, list[tuple[Any, ...]]] = {
            "joint_springs": [
                (model.getJointId(s.joint), s.stiffness, s.rest, s.damping)
                for s in scene.joint_springs
            ],
            "springs": [
                (frame(s.a_frame), np.array(s.a_point), frame(s.b_frame), np.array(s.b_point))
                + (s.stiffness, s.rest_length, s.damping)
                for s in scene.springs
            ],
            "joint_loads": [
                (model.getJointId(load.joint), np.array(load.effort))
                for load in scene.loads
                if isinstance(load, JointLoad)
            ],
            "point_loads": [
                (frame(load.frame), np.array(load.point), np.array(load.force))
                + (np.array(load.torque),)
                for load in _point_loads(scene)
            ],
        }
        return spec if any(spec.values()) else None

    def _contacts(self, scene: SceneParts) -> tuple[list[Any], list[Any], list[Any]] | None:
        """Ground planes, ground boxes (centre, axes, half sizes) and contact points for
        ``_core``: each point in its joint's frame."""
        if not scene.grounds and not scene.contacts:
            return None
        if not scene.grounds or not scene.contacts:
            missing = "[[ground]]" if not scene.grounds else "[[contact]]"
            raise SceneError(
                f"contacts need both a ground and points that touch it; no {missing} given"
            )
        planes = [
            (g.name, np.array(g.point), np.array(g.normal), g.friction)
            for g in scene.grounds
            if g.box is None
        ]
        boxes = [
            (g.name, np.array(g.point), g.rotation(), 0.5 * np.array(g.box), g.friction)
            for g in scene.grounds
            if g.box is not None
        ]
        points = []
        for c in scene.contacts:
            frame = self.model.frames[self._frame(c.frame)]
            if frame.parentJoint == 0:
                raise SceneError(
                    f"contact '{c.name}': frame '{c.frame}' is on the world once the locked "
                    "joints are removed; a contact needs a body that moves"
                )
            position = frame.placement.act(np.array(c.point, dtype=float))
            points.append((c.name, int(frame.parentJoint), position, c.radius))
        return planes, boxes, points

    def _loops(self, scene: SceneParts) -> list[tuple[Any, ...]]:
        frame = self._frame
        return [
            (frame(loop.a_frame), np.array(loop.a_point), frame(loop.b_frame))
            + (np.array(loop.b_point), loop.kind)
            + (f"[[loop]] #{k} ('{loop.a_frame}' to '{loop.b_frame}')",)
            for k, loop in enumerate(scene.loops, start=1)
        ]

    def _couplings(self, scene: SceneParts) -> list[tuple[Any, ...]]:
        """The couplings as the core takes them; one of two locked joints is an error, both
        locked are held at their start values (nothing to couple)."""
        out: list[tuple[Any, ...]] = []
        for c in scene.couplings:
            locked = [joint for joint in (c.follower, c.leader) if joint in scene.locked]
            if len(locked) == 2:
                continue
            if locked:
                raise SceneError(
                    f"coupling {c.text()}: joint '{locked[0]}' is locked and the other is not; "
                    "lock both or neither"
                )
            ids = (self.model.getJointId(c.follower), self.model.getJointId(c.leader))
            out.append(("coupling", *ids, c.multiplier, c.offset, f"coupling {c.text()}"))
        return out

    def stops_for(self, limits: bool) -> tuple[bool, list[tuple[int, float, float]]] | None:
        """The joint stops for ``_core``: (take the model's limits, [(joint index in the reduced
        model, lower, upper), ...]), or None when there is none to apply (limits off and no
        stop set).

        Raises:
            SceneError: a stop set whose range is empty once its sides are resolved.
        """
        if not limits and not self._set_stops:
            return None
        own = self._own_stops if limits else {}
        return (limits, [(j, *_effective_stop(lim, own)) for j, lim in self._set_stops])

    def unset_equal_limits(self, equal: Iterable[str]) -> list[str]:
        """Of the joints whose equal model limits the core took as no stop (``equal``, as
        ``_core.Solver.equal_limits`` lists them), those that no stop set on the scene
        overrides."""
        set_by_name = {lim.joint for _, lim in self._set_stops}
        return [str(name) for name in equal if name not in set_by_name]

    def full_q(self, q: np.ndarray) -> np.ndarray:
        out: np.ndarray = self.q_ref.copy()
        out[self.q_index] = q
        return out

    def full_v(self, v: np.ndarray, nv: int) -> np.ndarray:
        out = np.zeros(nv)
        out[self.v_index] = v
        return out

"""Scenes: a mechanism with its force elements, locked joints, gravity and start pose.

A scene is built in code (``Scene(model)``, ``add_joint_spring``, ``add_spring``, ``add_load``,
``lock``, ``set_limit``) or read from a TOML file (``load_scene``). Names are resolved and every
value is checked when it is added, so that a mistake is reported where it is made.

A scene file is read in two steps: ``_scene_schema`` checks its tables against their declared
keys and kinds, then ``_build_scene`` builds the scene through the same methods as code does.
What the solver sees of a scene (``Scene.compile``) is made in ``_scene_compile``.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio

from . import _core
from ._checks import as_flag, as_vector, unknown_key_message
from ._collision_contacts import (
    HULL_POINTS,
    Collision,
    _frame_joint,
    geometry_collision,
    moves_after_locking,
    take_contacts,
    urdf_geometry,
)
from ._mjcf import MjcfError, MjcfModel, load_mjcf
from ._mjcf_contacts import MjcfCollision
from ._model_files import file_kind, load_srdf_poses, robot_srdf
from ._scene_compile import _Compiled
from ._scene_schema import ModelTable, SceneFile, read_scene_file
from ._scene_values import (
    _INF,
    _LAYOUTS,
    LOOP_KINDS,
    UNIT_NORM_SLACK,
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
    _bound,
    _close,
    _effective_stop,
    _is_angle_pair,
    _joint_kind,
    _number,
    _show,
    _unit_parts,
    _vector,
    has_mimic_joints,
    joint_values,
    model_stops,
    named_value,
)
from ._settings import Settings, make_settings
from ._urdf_mimic import urdf_mimic_tags
from .robots import build_robot_model, build_urdf_model, robot_urdf
from .scenes import scene_path

__all__ = [
    "LOOP_KINDS",
    "UNIT_NORM_SLACK",
    "Coupling",
    "JointLimit",
    "JointLoad",
    "JointSpring",
    "Loop",
    "Payload",
    "PointLoad",
    "Scene",
    "SceneError",
    "Spring",
    "has_mimic_joints",
    "joint_values",
    "load_scene",
    "model_stops",
    "named_value",
]

#: The Coulomb friction of a ground when none is given (add_ground, add_floor, [[ground]]).
DEFAULT_FRICTION = 0.5

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


# --- the scene --------------------------------------------------------------------------------


def _take_mimic(
    model: pinocchio.Model,
) -> tuple[pinocchio.Model, list[Coupling], pinocchio.Model | None, list[str]]:
    """The model a scene solves, its couplings, the model given when it had mimic joints (else
    None) and the scene's note on them."""
    if not has_mimic_joints(model):
        return model, [], None, []
    given = pinocchio.Model(model)
    model, couplings = _release_mimic(model)
    notes = ["mimic joints honoured as couplings: " + "; ".join(c.text() for c in couplings)]
    return model, couplings, given, notes


def _release_mimic(model: pinocchio.Model) -> tuple[pinocchio.Model, list[Coupling]]:
    """A model with mimic joints as one without (each follower an ordinary joint of its own
    type and axis, without position limits) and the couplings that hold the followers."""
    released, couplings = _core.release_mimic(model)
    return released, [
        Coupling(str(released.names[follower]), str(released.names[leader]), float(m), float(o))
        for follower, leader, m, o in couplings
    ]


class Scene:
    """A mechanism to settle: a ``pinocchio.Model`` plus gravity, start pose, locked joints,
    springs, loads, payloads, loops, joint stops and ground contacts.

    The scene owns a copy of the model (gravity is set on it). Joint names are the model's
    joint names; frame names are its frame names (URDF link names); ``"universe"`` is the
    world. ``pinsettle.solve(scene)`` settles it; results are in the full configuration.
    ``limits`` (default True): the model's position limits are joint stops (a URDF's
    ``<limit lower upper>`` of revolute and prismatic joints); ``set_limit`` adds or overrides
    the stops of a joint either way.
    """

    def __init__(
        self,
        model: pinocchio.Model,
        *,
        gravity: Any = None,
        settings: Settings | Mapping[str, Any] | None = None,
        name: str = "scene",
        description: str = "",
        limits: bool = True,
    ) -> None:
        if not isinstance(model, pinocchio.Model):
            raise TypeError(f"model must be a pinocchio.Model, got {type(model).__name__}")
        self._limits = True
        #: Joint couplings (``add_coupling``, a URDF's ``<mimic>`` tags, mimic joints).
        self.couplings: list[Coupling]
        #: The model given, when it has mimic joints (``pinocchio.buildModelFromUrdf(path,
        #: mimic=True)``); ``model`` is then that model with each follower made an ordinary
        #: joint (of its own type and axis, without position limits) and coupled back in
        #: ``couplings``. None otherwise.
        self.mimic_model: pinocchio.Model | None
        model, self.couplings, self.mimic_model, notes = _take_mimic(model)
        self.model = pinocchio.Model(model)
        self.name = name
        self.description = description
        self.path: Path | None = None
        #: The URDF the model was built from, if any (its visual shapes are drawn by
        #: ``pinsettle.play``; solving never loads them).
        self.urdf: Path | None = None
        #: The MJCF file the model was built from, if any.
        self.mjcf: Path | None = None
        #: The SRDF files whose poses were read (``load_srdf``).
        self.srdf: list[Path] = []
        #: What the model file said that the scene leaves out (an MJCF file's damping,
        #: actuators, ...), one line each; ``pinsettle solve`` prints them.
        self.notes: list[str] = notes
        self._pose_notes: dict[str, str] = {}
        #: Joint springs whose rest a pose sets: pose -> (index in joint_springs, rest).
        self._pose_springs: dict[str, list[tuple[int, float]]] = {}
        self.settings = make_settings(settings, {})
        self.joint_springs: list[JointSpring] = []
        self.springs: list[Spring] = []
        self.loads: list[JointLoad | PointLoad] = []
        self.payloads: list[Payload] = []  # add_payload, [[payload]]: weights at points
        #: Loop closures of the tree (``add_loop``, ``[[loop]]``).
        self.loops: list[Loop] = []
        self.locked: list[str] = []
        #: Stops added or overridden by ``set_limit`` (``[[limit]]``), one per joint.
        self.joint_limits: list[JointLimit] = []
        #: Ground planes (``add_ground``, ``[[ground]]``) and the points of bodies that touch
        #: them (``add_contact``, ``[[contact]]``).
        self.grounds: list[Ground] = []
        self.contacts: list[ContactPoint] = []
        #: An MJCF file's floors and geoms (``add_collision_contacts``); None for other models.
        self._mjcf_collision: MjcfCollision | None = None
        self._start: dict[str, Any] = {}
        if gravity is not None:
            self.gravity = gravity
        self._compiled: _Compiled | None = None
        self.limits = limits

    # -- construction -------------------------------------------------------------------------

    @classmethod
    def from_urdf(
        cls, path: str | Path, *, floating: bool = False, mimic: bool | None = None, **kwargs: Any
    ) -> Scene:
        """A scene of the mechanism in a URDF file (meshes are not loaded). ``mimic``: its
        ``<mimic>`` tags are joint couplings (True, the default when it has any) or ignored as
        ``pinocchio.buildModelFromUrdf`` does by default (False, each joint then moves on its
        own); a line of ``notes`` says which."""
        scene = cls(build_urdf_model(path, floating=floating), **kwargs)
        scene.urdf = Path(path)
        scene.apply_urdf_mimic(Path(path), mimic)
        return scene

    @classmethod
    def from_robot(
        cls, name: str, *, floating: bool = False, mimic: bool | None = None, **kwargs: Any
    ) -> Scene:
        """A scene of a robot shipped by example-robot-data (see ``pinsettle.robot_names()``);
        ``mimic`` as for ``from_urdf``."""
        scene = cls(build_robot_model(name, floating=floating), **kwargs)
        scene.urdf = robot_urdf(name)
        scene.apply_urdf_mimic(scene.urdf, mimic)
        return scene

    def apply_urdf_mimic(self, path: Path, mimic: bool | None) -> None:
        """Couple the joints of the URDF's ``<mimic>`` tags (``mimic`` True or None) or leave
        them free (False); a line of ``notes`` says which. Nothing happens without tags.

        Raises:
            SceneError: ``mimic`` not a bool or None; a tag naming a joint the model lacks or one
                that cannot be coupled (the message names the tag's joint).
        """
        if mimic is not None and not isinstance(mimic, (bool, np.bool_)):
            raise SceneError(f"mimic must be true or false, got {mimic!r}")
        try:
            tags = urdf_mimic_tags(path)
        except ValueError as error:
            raise SceneError(str(error)) from None
        if not tags:
            return
        if mimic is not None and not mimic:
            self.notes.append(
                "URDF <mimic> tags ignored (mimic = false, pinocchio.buildModelFromUrdf's "
                "default): " + ", ".join(f"'{tag.follower}'" for tag in tags) + " move"
                f"{'s' if len(tags) == 1 else ''} on "
                f"{'its' if len(tags) == 1 else 'their'} own, uncoupled"
            )
            return
        for tag in tags:
            try:
                self.add_coupling(tag.follower, tag.leader, tag.multiplier, tag.offset)
            except SceneError as error:
                raise SceneError(
                    f"{path}: the <mimic> tag of joint '{tag.follower}': {error}; correct the "
                    "tag, or leave the tags out ([model] mimic = false, mimic=False)"
                ) from None
        self.notes.append(
            "URDF <mimic> tags honoured as joint couplings (mimic = true): "
            + "; ".join(c.text() for c in self.couplings[-len(tags) :])
        )

    @classmethod
    def from_mjcf(
        cls,
        path: str | Path,
        *,
        floating: bool = False,
        free_objects: str = "keep",
        actuator_springs: bool = False,
        **kwargs: Any,
    ) -> Scene:
        """A scene of a MuJoCo MJCF file: its bodies and joints, gravity (``<option
        gravity>``), joint ranges as stops, joint springs (``stiffness``, ``springref``),
        ``connect`` and ``weld`` equalities as loops, its reference pose ``qpos0`` as the
        start and its keyframes as poses (``set_pose``). What it says that has no force at rest
        (damping, actuators, ...) is listed in ``notes``; what would change the rest and cannot
        be honoured is an error naming the element. A body with a ``<freejoint>`` floats, as
        in MuJoCo; ``floating``: a free-flyer added to the root body of a file that has none.
        ``free_objects``: free objects beside the mechanism (bodies whose only joint is their
        free joint) stay free and fall ('keep') or are fixed where the file places them
        ('lock'). ``actuator_springs``: each position actuator on a hinge or slide joint is a
        joint spring (stiffness kp) towards its control: 0, or the ctrl of the keyframe
        ``set_pose`` starts from.

        Raises:
            FileNotFoundError: no such file, or an included file or asset missing.
            SceneError: the file cannot be read or honoured (the message names the element).
        """
        try:
            mjcf = load_mjcf(
                path,
                floating=floating,
                free_objects=free_objects,
                actuator_springs=bool(as_flag(actuator_springs, "actuator_springs")),
            )
        except MjcfError as error:
            raise SceneError(str(error)) from None
        scene = cls(mjcf.model, **kwargs)
        scene.mjcf = Path(path)
        scene._take_mjcf(mjcf)
        return scene

    def _take_mjcf(self, mjcf: MjcfModel) -> None:
        """What an MJCF file says beside its model: notes, joint and actuator springs, loops
        (its equalities) and the start (its qpos0)."""
        self.notes = list(mjcf.notes)
        self._mjcf_collision = mjcf.collision
        for joint, stiffness, rest in mjcf.joint_springs:
            self.add_joint_spring(joint, stiffness, rest)
        first = len(self.joint_springs)
        for joint, stiffness, rest in mjcf.actuator_springs:
            self.add_joint_spring(joint, stiffness, rest)
        # A pose moves the actuator springs' rests to its keyframe's ctrl (set_pose).
        self._pose_springs = {
            pose: [(first + k, rest) for k, rest in enumerate(rests)]
            for pose, rests in mjcf.actuator_rests.items()
        }
        for frame_a, point_a, frame_b, point_b, kind in mjcf.loops:
            self.add_loop((frame_a, point_a), (frame_b, point_b), kind)
        # The reader gives a multi-DoF joint's start as its configuration entries in
        # Pinocchio's order (a quaternion w last): set_start takes the by-name order.
        model = self.model
        self.set_start(
            {
                joint: named_value(model, model.getJointId(joint), value)
                if isinstance(value, list)
                else value
                for joint, value in mjcf.start.items()
            }
        )

    @property
    def poses(self) -> list[str]:
        """Names of the model's named poses: an SRDF's (``load_srdf``), an MJCF file's
        keyframes and its ``qpos0``."""
        return sorted(entry.key() for entry in self.model.referenceConfigurations)

    def load_srdf(self, path: str | Path) -> Scene:
        """Read the named poses (``group_state``) of an SRDF file for ``set_pose``, with
        Pinocchio's ``loadReferenceConfigurations``; the rest of the SRDF
        (``disable_collisions``, groups) plays no part.

        Raises:
            FileNotFoundError: no such file.
            SceneError: a pose names a joint the model does not have, or a value is not numbers
                or has the wrong count.
        """
        try:
            self._pose_notes.update(load_srdf_poses(self.model, path))
        except ValueError as error:
            raise SceneError(str(error)) from None
        self.srdf.append(Path(path))
        return self

    def set_pose(self, name: str) -> Scene:
        """Start every joint at a named pose (see ``poses``); ``set_start`` afterwards
        overrides single joints.

        Raises:
            SceneError: an unknown pose, with the known ones.
        """
        if not isinstance(name, str):
            raise SceneError(f"pose must be a pose name (str), got {name!r}")
        known = self.poses
        if name not in known:
            where = (
                f" (SRDF: {', '.join(str(p) for p in self.srdf)})"
                if self.srdf
                else " (the model has no SRDF: [model] srdf, Scene.load_srdf)"
            )
            raise SceneError(
                _close(name, known, "pose") + where
                if known
                else f"unknown pose '{name}': the model has no named poses{where}"
            )
        model = self.model
        q = pinocchio.normalize(model, self.model.referenceConfigurations[name])
        # Each joint's value in the by-name convention (quaternions w first), as set_start
        # takes it: a pose is a start like any other.
        self.set_start(
            {
                model.names[j]: named_value(
                    model, j, q[model.idx_qs[j] : model.idx_qs[j] + model.nqs[j]]
                )
                for j in range(1, model.njoints)
            }
        )
        for index, rest in self._pose_springs.get(name, []):
            self.joint_springs[index] = replace(self.joint_springs[index], rest=rest)
            self._changed()
        if name in self._pose_notes and self._pose_notes[name] not in self.notes:
            self.notes.append(self._pose_notes[name])
        return self

    @property
    def gravity(self) -> np.ndarray:
        """Gravity acceleration (m/s^2, world axes)."""
        return np.array(self.model.gravity.linear)

    @gravity.setter
    def gravity(self, value: Any) -> None:
        g = np.array(_vector(value, "gravity", 3))
        self.model.gravity = pinocchio.Motion(g, np.zeros(3))
        self._compiled = None

    @property
    def limits(self) -> bool:
        """Whether the model's own position limits are joint stops (``[model] limits``)."""
        return self._limits

    @limits.setter
    def limits(self, value: Any) -> None:
        if not isinstance(value, (bool, np.bool_)):
            raise SceneError(f"limits must be True or False, got {value!r}")
        self._limits = bool(value)
        self._compiled = None

    def _joint_id(self, joint: Any, name: str) -> int:
        if not isinstance(joint, str):
            raise SceneError(f"{name} must be a joint name (str), got {type(joint).__name__}")
        known = list(self.model.names)[1:]
        if joint not in known:
            raise SceneError(f"{name}: " + _close(joint, known, "joint"))
        return int(self.model.getJointId(joint))

    def _frame_name(self, frame: Any, name: str) -> str:
        if not isinstance(frame, str):
            raise SceneError(f"{name} must be a frame name (str), got {type(frame).__name__}")
        known = list(dict.fromkeys(f.name for f in self.model.frames))
        if frame not in known:
            raise SceneError(f"{name}: " + _close(frame, known, "frame"))
        return frame

    def _changed(self) -> None:
        self._compiled = None

    def set_start(self, values: Mapping[str, Any] | None = None, **kwargs: Any) -> Scene:
        """Start values by joint name: a number (rad or m) for a 1-DoF joint (the angle of a
        continuous one), a list for a multi-DoF joint, each quaternion w first as in MuJoCo's
        qpos: a free-flyer (x, y, z, qw, qx, qy, qz), a spherical joint (qw, qx, qy, qz). A
        quaternion within 1e-3 of unit norm is normalised. Joints not named start at neutral.

        Raises:
            SceneError: an unknown joint, a value of the wrong kind or count, a quaternion or
                cos/sin pair far from unit norm (the message names the joint).
        """
        for joint, value in {**(values or {}), **kwargs}.items():
            self._set_joint_start(joint, value, f"start '{joint}'")
        self._changed()
        return self

    def _set_joint_start(self, joint: Any, value: Any, where: str) -> None:
        """One joint's start by name; errors begin with ``where`` (the key the user wrote)."""
        j = self._joint_id(joint, where)
        self._start[joint] = self._joint_start(j, value, where)
        self._changed()

    @property
    def start(self) -> dict[str, Any]:
        """The start values set, by joint name, as ``set_start`` takes them: a number for a
        1-DoF joint, an array (quaternions w first) for a multi-DoF joint."""
        out: dict[str, Any] = {}
        for joint, segment in self._start.items():
            value = named_value(self.model, self.model.getJointId(joint), segment)
            out[joint] = np.array(value) if isinstance(value, list) else value
        return out

    def _joint_start(self, j: int, value: Any, name: str) -> np.ndarray:
        """Joint j's configuration segment (Pinocchio's order) from its value by name."""
        model = self.model
        nq = model.nqs[j]
        kind = _joint_kind(model, j)
        layout = _LAYOUTS.get(kind)
        is_list = isinstance(value, (Sequence, np.ndarray)) and not isinstance(value, str)
        if model.nvs[j] == 1:
            if is_list:
                raise SceneError(
                    f"{name}: joint '{model.names[j]}' ({kind}) has one degree of freedom: give "
                    f"one number (rad or m), got {value!r}"
                )
            x = _number(value, name)
            return np.array([math.cos(x), math.sin(x)]) if nq == 2 else np.array([x])
        if not is_list:
            raise SceneError(
                f"{name}: joint '{model.names[j]}' ({kind}) has {nq} configuration entries: "
                f"give a list of {nq} numbers, got {value!r}" + (f"; {layout}" if layout else "")
            )
        if layout and not isinstance(value, (bytes, Mapping)) and len(value) != nq:
            raise SceneError(
                f"{name}: joint '{model.names[j]}' must have {nq} entries, got {len(value)}: "
                f"{list(value)!r}; {layout}"
            )
        segment = np.array(_vector(value, name, nq))
        for at, size in _unit_parts(model, j):
            segment[at : at + size] = self._unit_part(j, segment[at : at + size], name, layout)
        return segment

    def _unit_part(self, j: int, part: np.ndarray, name: str, layout: str | None) -> np.ndarray:
        """A quaternion (w first, as given; returned w last, as in Pinocchio's q) or a cos/sin
        pair of joint j, normalised.

        Raises:
            SceneError: off unit norm by more than ``UNIT_NORM_SLACK``.
        """
        norm = math.hypot(*part)  # scaled: numpy's dot overflows (and warns) past 1e154
        if abs(norm - 1.0) > UNIT_NORM_SLACK:
            if part.size == 4:
                raise SceneError(
                    f"{name}: the quaternion (qw, qx, qy, qz) = ({_show(part)}) has norm "
                    f"{norm:.6g}; give a unit quaternion, w first (1, 0, 0, 0: no rotation)"
                )
            raise SceneError(
                f"{name}: the cos/sin pair ({_show(part)}) of joint '{self.model.names[j]}' has "
                f"norm {norm:.6g}; give a unit pair (1, 0: angle 0)"
                + (f"; {layout}" if layout else "")
            )
        unit = part / norm
        return unit[[1, 2, 3, 0]] if part.size == 4 else unit

    def lock(self, *joints: str) -> Scene:
        """Hold joints at their start value and leave them out of the solve."""
        for joint in joints:
            self._joint_id(joint, "locked joint")
            if joint not in self.locked:
                self.locked.append(joint)
        self._changed()
        return self

    def set_limit(self, joint: str, lower: Any = None, upper: Any = None) -> Scene:
        """Add or override the stops of a 1-DoF joint (revolute, prismatic, helical): ``lower``
        and ``upper`` in rad or m. A side left None keeps the model's own limit on that side
        while ``limits`` is on (none when it is off); ``-math.inf`` / ``math.inf`` is no stop on
        that side. A second call for the same joint replaces the first.

        Raises:
            SceneError: an unknown joint (with a close match), a joint that cannot have a stop
                (continuous, multi-DoF, mimic), neither side given, a bound that is not a
                number or NaN, lower > upper (also against the model's limit kept on a side).
        """
        j = self._joint_id(joint, "joint")
        model = self.model
        kind = _joint_kind(model, j)
        if _is_angle_pair(model, j):
            raise SceneError(
                f"joint '{joint}' is a continuous joint ({kind}): a continuous joint has no stops"
            )
        if model.nvs[j] != 1 or model.nqs[j] != 1:
            raise SceneError(
                f"joint '{joint}' is a {kind} with {model.nvs[j]} degrees of freedom; a stop "
                "needs a 1-DoF joint with one coordinate (revolute, prismatic, helical)"
            )
        if "Mimic" in kind:
            raise SceneError(
                f"joint '{joint}' ({kind}) mimics another joint: it has no motion of its own to "
                "stop"
            )
        if lower is None and upper is None:
            raise SceneError(f"joint '{joint}': give 'lower', 'upper' or both (rad or m)")
        limit = JointLimit(
            joint,
            None if lower is None else _bound(lower, "lower", -_INF),
            None if upper is None else _bound(upper, "upper", _INF),
        )
        _effective_stop(limit, model_stops(model) if self.limits else {})  # an empty range
        self.joint_limits = [lim for lim in self.joint_limits if lim.joint != joint] + [limit]
        self._changed()
        return self

    def add_joint_spring(
        self, joint: str, stiffness: float, rest: float = 0.0, damping: float = 0.0
    ) -> Scene:
        """A spring-damper tau = -stiffness (q - rest) - damping qdot on a 1-DoF joint
        (stiffness in N m/rad or N/m; for a continuous joint q - rest is wrapped to
        [-pi, pi])."""
        j = self._joint_id(joint, "joint")
        if self.model.nvs[j] != 1:
            raise SceneError(
                f"joint: '{joint}' is a {_joint_kind(self.model, j)} with {self.model.nvs[j]} "
                "degrees of freedom; a joint spring needs a 1-DoF joint (revolute, continuous, "
                "prismatic)"
            )
        self.joint_springs.append(
            JointSpring(
                joint,
                _number(stiffness, "stiffness", nonnegative=True),
                _number(rest, "rest"),
                _number(damping, "damping", nonnegative=True),
            )
        )
        self._changed()
        return self

    def _end(self, end: Any, name: str) -> tuple[str, tuple[float, float, float]]:
        if isinstance(end, str):
            return self._frame_name(end, name), (0.0, 0.0, 0.0)
        if isinstance(end, Mapping):
            unknown = [k for k in end if k not in ("frame", "point")]
            if unknown:
                raise SceneError(
                    f"{name}: " + unknown_key_message("key", unknown[0], ["frame", "point"])
                )
            if "frame" not in end:
                raise SceneError(f"{name}: missing key 'frame'")
            frame = self._frame_name(end["frame"], f"{name}.frame")
            point = _vector(end.get("point", (0.0, 0.0, 0.0)), f"{name}.point", 3)
            return frame, point  # type: ignore[return-value]
        if isinstance(end, Sequence) and len(end) == 2:
            frame = self._frame_name(end[0], f"{name} frame")
            return frame, _vector(end[1], f"{name} point", 3)  # type: ignore[return-value]
        raise SceneError(
            f"{name} must be a frame name, (frame, point) or {{frame, point}}, got {end!r}"
        )

    def add_spring(
        self,
        a: Any,
        b: Any,
        stiffness: float,
        rest_length: float = 0.0,
        damping: float = 0.0,
    ) -> Scene:
        """A straight spring-damper between two points, each given as a frame name, a
        ``(frame, point)`` pair or ``{"frame": ..., "point": [x, y, z]}`` (point in the frame,
        m; ``"universe"`` is the world). Tension: stiffness (|d| - rest_length) plus damping
        times the rate of change of the length (N/m, m, N s/m)."""
        a_frame, a_point = self._end(a, "a")
        b_frame, b_point = self._end(b, "b")
        self.springs.append(
            Spring(
                a_frame,
                a_point,
                b_frame,
                b_point,
                _number(stiffness, "stiffness", nonnegative=True),
                _number(rest_length, "rest_length", nonnegative=True),
                _number(damping, "damping", nonnegative=True),
            )
        )
        self._changed()
        return self

    def add_load(
        self,
        joint: str | None = None,
        effort: Any = None,
        *,
        frame: str | None = None,
        point: Any = (0.0, 0.0, 0.0),
        force: Any = (0.0, 0.0, 0.0),
        torque: Any = (0.0, 0.0, 0.0),
    ) -> Scene:
        """A constant load: ``add_load(joint, effort)`` (N m or N; a list for a multi-DoF
        joint) or ``add_load(frame=..., point=..., force=..., torque=...)`` (world-aligned N
        and N m at a point of the frame, m)."""
        if (joint is None) == (frame is None):
            raise SceneError("a load needs either 'joint' (with 'effort') or 'frame', not both")
        if joint is not None:
            j = self._joint_id(joint, "joint")
            if effort is None:
                raise SceneError(f"load on joint '{joint}': missing 'effort'")
            nv = self.model.nvs[j]
            value: tuple[float, ...]
            if nv == 1:
                value = (_number(effort, "effort"),)
            else:
                value = _vector(effort, "effort", nv)
            self.loads.append(JointLoad(joint, value))
        else:
            if effort is not None:
                raise SceneError(
                    "'effort' belongs to a joint load; a load at a frame takes force and torque"
                )
            name = self._frame_name(frame, "frame")
            if name == "universe":
                raise SceneError("frame: a load on 'universe' (the world) does nothing")
            self.loads.append(
                PointLoad(
                    name,
                    _vector(point, "point", 3),  # type: ignore[arg-type]
                    _vector(force, "force", 3),  # type: ignore[arg-type]
                    _vector(torque, "torque", 3),  # type: ignore[arg-type]
                )
            )
        self._changed()
        return self

    def add_payload(self, frame: str, mass: Any, offset: Any = (0.0, 0.0, 0.0)) -> Scene:
        """A payload of ``mass`` (kg) at ``offset`` (m, in the frame's axes) from the origin of
        ``frame``: its weight, mass times the scene's gravity, hangs at that point, a point
        load that follows the gravity (``scene.gravity``) when it changes.

        Raises:
            SceneError: an unknown frame (with a close match), a frame fixed to the world, a
                mass that is not a finite number > 0, an offset that is not 3 finite numbers.
        """
        name = self._frame_name(frame, "frame")
        if self.model.frames[_body_frame(self.model, name)].parentJoint == 0:
            raise SceneError(
                f"frame: '{name}' is fixed to the world: a payload there hangs on nothing that "
                "moves"
            )
        kg = _number(mass, "mass")
        if not kg > 0:
            raise SceneError(f"mass must be > 0 (kg), got {kg}")
        self.payloads.append(Payload(name, kg, _vector(offset, "offset", 3)))  # type: ignore[arg-type]
        self._changed()
        return self

    def add_coupling(
        self, follower: str, leader: str, multiplier: Any = 1.0, offset: Any = 0.0
    ) -> Scene:
        """Couple two 1-DoF joints (revolute, prismatic, helical), as a URDF ``<mimic>`` tag
        does: q[follower] = multiplier * q[leader] + offset (rad or m). The solver holds it as
        a constraint (as it holds loops): the follower moves with its leader, and its effort
        (gravity, springs, loads, a stop) acts on the leader through the coupling. The start
        sets the follower from its leader unless ``set_start`` names it.

        Raises:
            SceneError: an unknown joint, one with other than one coordinate and one velocity,
                the same joint twice, a follower coupled already, a multiplier or offset that is
                not a finite number.
        """
        ids = []
        for joint, role in ((follower, "follower"), (leader, "leader")):
            j = self._joint_id(joint, role)
            if self.model.nqs[j] != 1 or self.model.nvs[j] != 1:
                raise SceneError(
                    f"{role} '{joint}' is a {_joint_kind(self.model, j)} with "
                    f"{self.model.nqs[j]} configuration entries and {self.model.nvs[j]} "
                    "velocities; a coupling needs 1-DoF joints with one of each (revolute, "
                    "prismatic, helical)"
                )
            ids.append(j)
        if ids[0] == ids[1]:
            raise SceneError(f"joint '{follower}' cannot follow itself")
        if any(c.follower == follower for c in self.couplings):
            raise SceneError(f"joint '{follower}' follows another joint already")
        coupling = Coupling(
            follower, leader, _number(multiplier, "multiplier"), _number(offset, "offset")
        )
        self.couplings.append(coupling)
        self._changed()
        return self

    def add_loop(self, a: Any, b: Any, kind: str = "point") -> Scene:
        """Close a loop of the tree: the point ``a`` and the point ``b`` (each a frame name, a
        ``(frame, point)`` pair or ``{"frame": ..., "point": [x, y, z]}``, point in the frame,
        m) are held together. ``kind`` 'point' makes the two points coincide (a spherical joint;
        in a plane, a pin joint); 'frame' makes the two frames, moved to their points, coincide
        (a weld). A planar loop closed by a 3-D point constraint is fine: redundant equations are
        dropped. The solver assembles the loops from the start configuration first."""
        a_frame, a_point = self._end(a, "a")
        b_frame, b_point = self._end(b, "b")
        if not isinstance(kind, str) or kind not in LOOP_KINDS:
            raise SceneError(f"kind must be 'point' or 'frame', got {kind!r}")
        self.loops.append(Loop(a_frame, a_point, b_frame, b_point, kind))
        self._changed()
        return self

    def add_ground(
        self,
        point: Any = (0.0, 0.0, 0.0),
        normal: Any = None,
        friction: Any = DEFAULT_FRICTION,
        name: str | None = None,
        *,
        box: Any = None,
        rpy: Any = None,
    ) -> Scene:
        """A ground plane through ``point`` with ``normal`` pointing out of it (world, m; the
        normal need not be of unit length; default +z), and its Coulomb friction coefficient
        (>= 0). The contact points (``add_contact``) rest on it: unilateral, inelastic, a contact
        sticks while its tangential force stays within ``friction`` times its normal force.

        With ``box`` (its full size along its own x, y and z axes, m, each > 0) the ground is a
        box centred at ``point`` and turned by ``rpy`` (roll, pitch, yaw, rad; default level): a
        table, a step, a block. Its faces, edges and corners all hold: a contact touches the
        box where it is closest to it, along the normal of that face (or edge, or corner).

        Raises:
            SceneError: a point, normal, size or rpy that is not 3 finite numbers, a normal of
                zero length, a normal given with a box or an rpy without one, a size that is not
                > 0, a negative friction, a name given twice.
        """
        name = f"ground{len(self.grounds) + 1}" if name is None else name
        if not isinstance(name, str) or any(g.name == name for g in self.grounds):
            raise SceneError(f"name must be a new ground's name (str), got {name!r}")
        centre = _vector(point, "point", 3)
        mu = _number(friction, "friction", nonnegative=True)
        ground = (
            _plane_ground(name, centre, normal, mu, rpy)
            if box is None
            else _box_ground(name, centre, box, mu, normal, rpy)
        )
        self.grounds.append(ground)
        self._changed()
        return self

    def add_contact(
        self, frame: str, point: Any = (0.0, 0.0, 0.0), radius: Any = 0.0, name: str | None = None
    ) -> Scene:
        """A point of a body that can touch the ground (``add_ground``): the centre ``point``
        (in ``frame``, m) of a sphere of ``radius`` (m; 0, the default, for a point). Named
        ``name``, else after the frame (with a number when the frame has several).

        Raises:
            SceneError: an unknown frame, a frame on the world, a point that is not 3 finite
                numbers, a negative radius, a name given twice.
        """
        frame = self._frame_name(frame, "frame")
        j = self.model.frames[_body_frame(self.model, frame)].parentJoint
        if j == 0:
            raise SceneError(f"frame: '{frame}' is fixed to the world; a contact needs a body")
        if name is None:
            same = sum(1 for c in self.contacts if c.frame == frame)
            name = frame if same == 0 else f"{frame}#{same + 1}"
        if not isinstance(name, str) or any(c.name == name for c in self.contacts):
            raise SceneError(f"name must be a new contact's name (str), got {name!r}")
        self.contacts.append(
            ContactPoint(
                name,
                frame,
                _vector(point, "point", 3),  # type: ignore[arg-type]
                _number(radius, "radius", nonnegative=True),
            )
        )
        self._changed()
        return self

    def add_collision_contacts(
        self,
        *,
        hull_points: Any = HULL_POINTS,
        exclude: Sequence[str] = (),
        geometry: pinocchio.GeometryModel | None = None,
        floors: Any = True,
    ) -> Scene:
        """Contact points from the model's own collision geometry (``[model] contacts =
        "collision"``): a sphere gives a sphere at its centre, a capsule the spheres at its two
        ends, a box its 8 corners, a cylinder 8 points on each rim circle, a mesh the vertices
        of its convex hull (at most ``hull_points``: a hull with more is thinned to that many,
        those that keep its extent in every direction best; a note says by how much). Each
        is fixed to the shape's body, named after the shape (``name#1``, ``name#2``, ... for
        several). Shapes on bodies fixed to the world (or held there by locked joints) are left
        out; ``exclude``: names of shapes or frames (bodies) to leave out.

        The shapes come from ``geometry`` (a ``pinocchio.GeometryModel`` built on the scene's
        model) if given, else from the model file: a URDF's ``<collision>`` elements, or the
        geoms of an MJCF file that MuJoCo would collide with its floors (``contype``,
        ``conaffinity``, ``<contact>``); ``floors``: an MJCF file's plane and box geoms become
        grounds too. The grounds' friction is theirs (``add_ground``); ``notes`` say what was taken.

        Raises:
            SceneError: no collision geometry, or none on a moving body; a shape of another
                kind (cone, height field, ...) or a size that is not positive (the
                message names the shape); an unknown name in ``exclude``; a contact name taken.
        """
        count = _hull_points(hull_points)
        _check_exclude(exclude)
        take_floors = as_flag(floors, "floors")
        collision, where = self._collision(geometry, exclude)
        self._add_shapes(collision, where, count, exclude)
        if self._mjcf_collision is not None and geometry is None:
            floor_notes = self._take_floors(collision, bool(take_floors))  # it edits notes
            self.notes += floor_notes
        return self

    def _add_shapes(
        self, collision: Collision, where: str, count: int, exclude: Sequence[str]
    ) -> None:
        """The contact points of ``collision``'s shapes on moving bodies, and its notes."""
        _check_excluded(collision, exclude)
        made, notes = take_contacts(collision, self.model, self.locked, count, where)
        taken = {c.name for c in self.contacts}
        for name, _, _, _ in made.contacts:
            if name in taken:
                raise SceneError(f"collision contacts: the contact name '{name}' is taken already")
            taken.add(name)
        for frame in dict.fromkeys(frame for _, frame, _, _ in made.contacts):
            self._frame_name(frame, "frame")  # add_contact's checks, once per frame
        self.contacts += [ContactPoint(*contact) for contact in made.contacts]
        self._changed()
        self.notes += notes

    def add_floor(
        self, height: Any = None, friction: Any = DEFAULT_FRICTION, name: str = "floor"
    ) -> Scene:
        """A level ground plane (normal +z) at ``height`` (m), or, when None, just under the
        scene's lowest contact point at its start pose (a sphere's lowest point): the
        mechanism starts touching it. Its Coulomb ``friction`` as for ``add_ground``.

        Raises:
            SceneError: the scene has no contact points yet (``add_collision_contacts``,
                ``add_contact``), a height that is not a finite number, a name taken.
        """
        if not self.contacts:
            raise SceneError(
                "a floor needs contact points to rest on it, and the scene has none: take the "
                "model's collision shapes first (add_collision_contacts, [model] contacts = "
                '"collision", --contacts collision) or add points (add_contact, [[contact]])'
            )
        z = self._lowest_contact() if height is None else _number(height, "floor height")
        return self.add_ground((0.0, 0.0, z), (0.0, 0.0, 1.0), friction, name)

    def _lowest_contact(self) -> float:
        """The lowest world z of the contacts' spheres at the start (locked joints there)."""
        model = self.model
        data = model.createData()
        pinocchio.framesForwardKinematics(model, data, self.q0())
        lowest = math.inf
        for c in self.contacts:
            placement = data.oMf[_body_frame(model, c.frame)]
            lowest = min(lowest, float(placement.act(np.array(c.point))[2]) - c.radius)
        return lowest

    def _take_floors(self, collision: Collision, take: bool) -> list[str]:
        """An MJCF file's floors as grounds (``take``), or a note that they are not."""
        assert self._mjcf_collision is not None
        self.notes = [n for n in self.notes if n != self._mjcf_collision.floor_note()]
        if not take:
            return (
                [
                    "the file's floors are not grounds (floors = False: [[ground]] tables or a "
                    "floor given): the scene's grounds replace them"
                ]
                if collision.grounds
                else []
            )
        for g in collision.grounds:
            self.add_ground(g.point, g.normal, g.friction, g.name, box=g.box, rpy=g.rpy)
        return []

    def _collision(
        self, geometry: pinocchio.GeometryModel | None, exclude: Sequence[str]
    ) -> tuple[Collision, str]:
        """The collision shapes of ``geometry``, else of the model file, and their source."""
        if geometry is not None:
            if not isinstance(geometry, pinocchio.GeometryModel):
                raise SceneError(
                    f"geometry must be a pinocchio.GeometryModel, got {type(geometry).__name__}"
                )
            return geometry_collision(self.model, geometry, "geometry", exclude), "geometry"
        if self._mjcf_collision is not None:
            try:
                return self._mjcf_collision.collision(self.model, exclude), str(self.mjcf)
            except MjcfError as error:
                raise SceneError(str(error)) from None
        if self.urdf is not None:
            shapes = urdf_geometry(self.model, self.urdf)
            return geometry_collision(self.model, shapes, str(self.urdf), exclude), str(self.urdf)
        raise SceneError(
            "the scene has no model file to take collision geometry from (a Scene of a "
            "pinocchio.Model): give geometry=pinocchio.GeometryModel, or points with add_contact"
        )

    def assemble(self, q: Any = None) -> tuple[np.ndarray, float]:
        """The configuration q (the start by default, full model) moved onto the loops, and how
        far it moved (max |difference|, rad or m), as the solver does before it starts.

        Raises:
            SceneError: the loops cannot be assembled from there (the message names the loop).
        """
        q = self.q0() if q is None else as_vector(q, "q", self.model.nq, "model.nq")
        compiled = self.compile(q)
        if not compiled.loops:
            return q.copy(), 0.0
        try:
            reduced, moved = _core.assemble_loops(
                compiled.model, q[compiled.q_index], compiled.loops
            )
        except ValueError as error:
            raise SceneError(str(error)) from None
        return compiled.full_q(reduced), float(moved)

    def mobility(self, q: Any = None) -> int:
        """Degrees of freedom at the full configuration q (the assembled start by default):
        the free joints' nv less the independent loop equations."""
        q = self.assemble(q)[0]
        compiled = self.compile(q)
        if not compiled.loops:
            return int(compiled.model.nv)
        basis = _core.loops(compiled.model, q[compiled.q_index], compiled.loops)["basis"]
        return int(basis.shape[1])

    # -- what the solver sees -----------------------------------------------------------------

    def q0(self) -> np.ndarray:
        """The start configuration of the full model (dim model.nq)."""
        q: np.ndarray = pinocchio.neutral(self.model)
        for joint, value in self._start.items():
            j = self.model.getJointId(joint)
            q[self.model.idx_qs[j] : self.model.idx_qs[j] + self.model.nqs[j]] = value
        # a follower not named starts where its leader puts it
        self._set_followers(q, self.model.idx_qs, with_offset=True, keep=self._start)
        return q

    # -- a model with mimic joints, in its own coordinates ------------------------------------

    def _mimic_indices(self) -> tuple[np.ndarray, np.ndarray]:
        """Where the coordinates of ``mimic_model`` sit in those of ``model``: every joint's
        segment but the followers'."""
        model = self.model
        followers = {model.getJointId(c.follower) for c in self.couplings}
        kept = [j for j in range(1, model.njoints) if j not in followers]
        q_index = [np.arange(model.idx_qs[j], model.idx_qs[j] + model.nqs[j]) for j in kept]
        v_index = [np.arange(model.idx_vs[j], model.idx_vs[j] + model.nvs[j]) for j in kept]
        return (
            np.concatenate(q_index or [np.zeros(0)]).astype(int),
            np.concatenate(v_index or [np.zeros(0)]).astype(int),
        )

    def _set_followers(self, x: np.ndarray, index: Any, with_offset: bool, keep: Any = ()) -> None:
        """Each coupling's follower coordinate in x (a configuration with ``model.idx_qs`` and
        the offset, or a velocity with ``model.idx_vs``) set from its leader's, in coupling
        order; followers named in keep are left as they are."""
        for c in self.couplings:
            if c.follower in keep:
                continue
            leader = x[index[self.model.getJointId(c.leader)]]
            x[index[self.model.getJointId(c.follower)]] = c.multiplier * leader + (
                c.offset if with_offset else 0.0
            )

    def from_mimic_q(self, q: Any) -> np.ndarray:
        """A configuration of ``mimic_model`` (the model given, with mimic joints) as one of
        ``model``: each follower set from its leader."""
        assert self.mimic_model is not None
        q = as_vector(q, "q", self.mimic_model.nq, "model.nq")
        out = np.zeros(self.model.nq)
        out[self._mimic_indices()[0]] = q
        self._set_followers(out, self.model.idx_qs, with_offset=True)
        return out

    def from_mimic_v(self, v: Any) -> np.ndarray:
        """A velocity of ``mimic_model`` as one of ``model`` (each follower's from its
        leader's)."""
        assert self.mimic_model is not None
        v = as_vector(v, "v", self.mimic_model.nv, "model.nv")
        out = np.zeros(self.model.nv)
        out[self._mimic_indices()[1]] = v
        self._set_followers(out, self.model.idx_vs, with_offset=False)
        return out

    def to_mimic_q(self, q: np.ndarray) -> np.ndarray:
        """A configuration of ``model`` as one of ``mimic_model`` (the followers left out)."""
        return np.asarray(q)[..., self._mimic_indices()[0]]

    def to_mimic_v(self, v: np.ndarray) -> np.ndarray:
        """A velocity (or rows of a matrix over velocities) of ``model`` in the coordinates of
        ``mimic_model`` (the followers' rows left out)."""
        return np.asarray(v)[self._mimic_indices()[1], ...]

    def to_mimic_force(self, tau: np.ndarray) -> np.ndarray:
        """A generalized force of ``model`` (dim model.nv) as one of ``mimic_model``: each
        follower's effort added to its leader's times the multiplier (the chain rule, as
        Pinocchio's rnea on a model with mimic joints)."""
        out = np.array(tau, dtype=float)
        for c in self.couplings:
            iv_leader = self.model.idx_vs[self.model.getJointId(c.leader)]
            out[iv_leader] += (
                c.multiplier * out[self.model.idx_vs[self.model.getJointId(c.follower)]]
            )
        reduced: np.ndarray = out[self._mimic_indices()[1]]
        return reduced

    @property
    def has_elements(self) -> bool:
        return bool(self.joint_springs or self.springs or self.loads or self.payloads)

    def compile(self, q_locked: np.ndarray | None = None) -> _Compiled:
        """The reduced model (locked joints removed at their value in ``q_locked``, the start
        configuration by default) and the force elements resolved to its indices."""
        if q_locked is not None and self.locked:  # the locked values come from q_locked
            return _Compiled(self, q_locked)
        if self._compiled is None:
            self._compiled = _Compiled(self, self.q0())
        return self._compiled

    def joint_values(self, q: Any) -> dict[str, float | list[float]]:
        """Joint values by name from a full configuration: a number (rad or m) for a 1-DoF
        joint (the angle of a continuous one), a list for a multi-DoF joint."""
        return joint_values(self.model, q)

    def static_force(self, q: Any) -> np.ndarray:
        """Net static generalized force on the free (unlocked) joints at the full
        configuration q: gravity minus springs and loads (dim of the reduced model's nv). With
        loops, its component along the motions the loops allow at q (the constraint reactions
        take the rest): zero at an equilibrium of the closed mechanism."""
        q = as_vector(q, "q", self.model.nq, "model.nq")
        compiled = self.compile(q)
        return _core.static_force(
            compiled.model, q[compiled.q_index], compiled.elements, compiled.loops
        )

    def loop_error(self, q: Any) -> np.ndarray:
        """The loops' constraint errors at the full configuration q, stacked (3 per point loop:
        p_a - p_b in world axes, m; 6 per frame loop: that and the rotation vector of
        R_a R_b^T, rad); empty without loops."""
        q = as_vector(q, "q", self.model.nq, "model.nq")
        compiled = self.compile(q)
        if not compiled.loops:
            return np.zeros(0)
        return _core.loops(compiled.model, q[compiled.q_index], compiled.loops)["error"]

    def residual(self, q: Any, *, limits: bool | None = None) -> float:
        """The residual the solver reports at the full configuration q (N m or N): max
        |static_force(q)|, or with joint stops the largest violation of the conditions of a rest
        against them (|force| on a joint off its stops; on a joint at its lower stop
        max(0, -force), at its upper stop max(0, force): a stop only pushes). ``limits``: as
        for ``pinsettle.solve`` (None: the scene's own setting)."""
        q = as_vector(q, "q", self.model.nq, "model.nq")
        compiled = self.compile(q)
        force = self.static_force(q)
        stops = compiled.stops_for(self.limits if limits is None else as_flag(limits, "limits"))
        if stops is None or not force.size:
            return float(np.max(np.abs(force))) if force.size else 0.0
        violation = np.abs(force)
        qr = q[compiled.q_index]
        for _, iq, iv, lower, upper in _core.joint_stops(compiled.model, stops)["stops"]:
            if qr[iq] <= lower:
                violation[iv] = max(0.0, -force[iv])
            elif qr[iq] >= upper:
                violation[iv] = max(0.0, force[iv])
        return float(np.max(violation))

    def __repr__(self) -> str:
        parts = [f"'{self.name}'", f"nq={self.model.nq}"]
        for label, items in (
            ("locked", self.locked),
            ("joint_springs", self.joint_springs),
            ("springs", self.springs),
            ("loads", self.loads),
            ("payloads", self.payloads),
            ("loops", self.loops),
            ("couplings", self.couplings),
            ("stops set", self.joint_limits),
            ("grounds", self.grounds),
            ("contacts", self.contacts),
        ):
            if items:
                parts.append(f"{len(items)} {label}")
        if not self.limits:
            parts.append("model limits off")
        return f"Scene({', '.join(parts)})"


def _plane_ground(name: str, point: Any, normal: Any, friction: float, rpy: Any) -> Ground:
    """A plane ground (Scene.add_ground without a box): its normal made of unit length."""
    if rpy is not None:
        raise SceneError(
            f"rpy turns a box ground; a plane is turned by its normal, got rpy={rpy!r} without box"
        )
    normal_v = _vector((0.0, 0.0, 1.0) if normal is None else normal, "normal", 3)
    length = math.sqrt(sum(x * x for x in normal_v))
    if not length > 1e-12:
        raise SceneError(f"normal must have a non-zero length, got {list(normal_v)}")
    unit = tuple(x / length for x in normal_v)
    return Ground(name, point, unit, friction)  # type: ignore[arg-type]


def _box_ground(name: str, centre: Any, box: Any, friction: float, normal: Any, rpy: Any) -> Ground:
    """A box ground (Scene.add_ground with a box): its sizes > 0, its top face's normal."""
    if normal is not None:
        raise SceneError(
            f"normal is a plane's; a box ground is turned by rpy, got normal={normal!r} with box"
        )
    size = _vector(box, "box", 3)
    if not all(x > 0 for x in size):
        raise SceneError(f"box must be 3 sizes > 0 (m), got {list(size)}")
    angles = _vector((0.0, 0.0, 0.0) if rpy is None else rpy, "rpy", 3)
    up = tuple(float(x) for x in pinocchio.rpy.rpyToMatrix(*angles)[:, 2])
    return Ground(name, centre, up, friction, size, angles)  # type: ignore[arg-type]


# --- the scene file ----------------------------------------------------------------------------


def load_scene(
    path: str | Path,
    *,
    floating: bool | None = None,
    free_objects: str | None = None,
    actuator_springs: bool | None = None,
    contacts: str | None = None,
    floor: Any = None,
) -> Scene:
    """Read a scene: a scene file (TOML; the format is documented in the README), a scene of
    the library by name (``pinsettle.scene_names()``), or a model file as a scene with only
    ``[model]``: a URDF or a MuJoCo MJCF file, told apart by content (the root as the file
    has it: fixed, or free by an MJCF ``<freejoint>``; ``floating`` adds a free-flyer where
    there is none). ``free_objects`` ('keep' or 'lock') and ``actuator_springs``: an MJCF
    file's free objects and position actuators, as in ``Scene.from_mjcf``.

    Contacts of a model file, as ``[model] contacts`` and ``floor`` of a scene file say them:
    an MJCF file's floors and the geoms MuJoCo collides with them are taken by default, as
    MuJoCo does (``contacts="none"`` leaves them out); ``contacts="collision"`` takes a URDF's
    collision shapes, which rest on ``floor``: True, a level plane under the lowest of them
    at the start pose, or a height z (m); a floor replaces an MJCF file's own.

    Raises:
        FileNotFoundError: no such file or scene name.
        SceneError (a ValueError): a syntax error (with its line), an unknown key, name or
            robot, a value of the wrong type, shape or sign; the message names the file and key.
            A file that is neither a scene, a URDF nor an MJCF file: each parser's reason.
    """
    path = scene_path(path)
    try:
        kind = file_kind(path)
    except ValueError as error:
        raise SceneError(str(error)) from None
    if kind != "scene":
        scene = _scene_from_model_file(path, kind, bool(floating), free_objects, actuator_springs)
        _model_file_contacts(scene, path, kind, contacts, floor)
        return scene
    _model_file_options_only(
        path,
        floating=floating,
        contacts=contacts,
        floor=floor,
        free_objects=free_objects,
        actuator_springs=actuator_springs,
    )
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"{path}: TOML syntax error: {error}") from None
    except UnicodeDecodeError as error:
        raise SceneError(f"{path}: not a UTF-8 text file ({error})") from None
    try:
        return _scene_from_dict(data, path)
    except SceneError as error:
        raise SceneError(f"{path}: {error}") from None


def _check_exclude(exclude: Any) -> None:
    """``exclude`` of ``add_collision_contacts``: a list of names (not one string)."""
    if isinstance(exclude, str) or not all(isinstance(n, str) for n in exclude):
        raise SceneError(f"exclude must be a list of shape or frame names, got {exclude!r}")


def _body_frame(model: pinocchio.Model, name: str) -> int:
    """A frame by name, a body's first (as the compiled scene resolves names)."""
    if model.existFrame(name, pinocchio.FrameType.BODY):
        return int(model.getFrameId(name, pinocchio.FrameType.BODY))
    return int(model.getFrameId(name))


def _model_file_options_only(path: Path, **options: Any) -> None:
    """A scene file says its model's options in [model]: load_scene's are for model files."""
    for key, value in options.items():
        if value is None:
            continue
        files = "an MJCF file" if key in ("free_objects", "actuator_springs") else "a model file"
        raise SceneError(
            f"{path}: {key} applies to {files}"
            + (" (URDF, MJCF)" if files == "a model file" else "")
            + f"; a scene file says it in [model] {key}"
        )


def _hull_points(value: Any) -> int:
    """``hull_points``, checked: an integer >= 4 (a solid's fewest vertices)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 4:
        raise SceneError(f"hull_points must be an integer >= 4, got {value!r}")
    return int(value)


def _check_loops(scene: Scene, where: str) -> None:
    """Elements resolved now, not at the first solve; a start the loops cannot be closed from,
    or loops that lock everything, are errors of the file."""
    scene.compile()
    if not scene.loops:
        return
    q = scene.assemble()[0]
    if scene.mobility(q) == 0:
        raise SceneError(
            f"{where}: the loops leave the mechanism no degree of freedom (every joint "
            "motion would open a loop): it is a structure, with nothing to settle"
        )


def _scene_from_model_file(
    path: Path,
    kind: str,
    floating: bool,
    free_objects: str | None = None,
    actuator_springs: bool | None = None,
) -> Scene:
    """A URDF or MJCF file as a scene with only [model]."""
    if kind == "urdf" and free_objects is not None:
        raise SceneError(
            f"{path}: free_objects applies to an MJCF file's free objects; a URDF has one root"
        )
    if kind == "urdf" and actuator_springs is not None:
        raise SceneError(f"{path}: actuator_springs applies to an MJCF file's actuators")
    try:
        if kind == "urdf":
            scene = Scene.from_urdf(path, floating=floating)
        else:
            scene = Scene.from_mjcf(
                path,
                floating=floating,
                free_objects=free_objects or "keep",
                actuator_springs=bool(actuator_springs),
            )
    except SceneError:
        raise
    except ValueError as error:  # load_urdf's reasons name the file already
        raise SceneError(str(error)) from None
    scene.name = path.stem
    scene.description = f"{'URDF' if kind == 'urdf' else 'MJCF'} file" + (
        ", free-flyer root" if floating else ""
    )
    scene.path = path
    try:
        _check_loops(scene, "<equality>")
    except SceneError as error:
        raise SceneError(f"{path}: {error}") from None
    return scene


def _model_file_contacts(
    scene: Scene, path: Path, kind: str, contacts: str | None, floor: Any
) -> None:
    """A model file's contacts (``load_scene``'s ``contacts`` and ``floor``); errors name the
    file. A URDF's collision shapes need a floor to rest on."""
    has_floor = floor is not None and floor is not False
    if kind == "urdf" and contacts == "collision" and not has_floor:
        raise SceneError(
            f"{path}: contacts 'collision' takes the URDF's collision shapes, but a URDF has no "
            "ground for them: add a floor (floor=True, --floor: a plane under the model; or "
            "floor=Z, --floor Z), or write a scene file with [[ground]] tables"
        )
    try:
        take_model_contacts(scene, contacts, floor)
        scene.compile()
    except SceneError as error:
        message = str(error)
        raise SceneError(message if str(path) in message else f"{path}: {message}") from None


def _description(path: Path) -> str:
    """The scene's one-line description: its first comment line."""
    try:
        for line in path.read_text(encoding="utf-8").splitlines():
            stripped = line.strip()
            if stripped.startswith("#"):
                return stripped.lstrip("#").strip()
            if stripped:
                break
    except (OSError, UnicodeDecodeError):
        pass
    return ""


def _scene_from_dict(data: Mapping[str, Any], path: Path) -> Scene:
    """The scene of a parsed scene file: checked against the schema first, then built."""
    return _build_scene(read_scene_file(data), path)


def _build_scene(file: SceneFile, path: Path) -> Scene:
    """The scene of a checked scene file; errors name the table (the caller adds the file)."""
    scene = _model_scene(file.model, path)
    _apply_model_options(scene, file.model, path)
    _apply_start(scene, file.model, file.start)
    _add_elements(scene, file)
    _add_collision_contacts(scene, file)
    scene.settings = file.settings
    _check_loops(scene, "[[loop]]")
    return scene


def _at(where: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``fn(*args, **kwargs)``, its SceneError prefixed with ``where`` (the file's table)."""
    try:
        return fn(*args, **kwargs)
    except SceneError as error:
        raise SceneError(f"{where}: {error}") from None


def _urdf_scene(m: ModelTable, path: Path) -> tuple[Scene, Path | None]:
    assert m.urdf is not None
    urdf_path = path.parent / m.urdf
    try:
        model = build_urdf_model(urdf_path, floating=m.floating)
    except (FileNotFoundError, ValueError) as error:
        raise SceneError(f"[model] urdf: {error}") from None
    return Scene(model), urdf_path


def _mjcf_scene(m: ModelTable, path: Path) -> tuple[Scene, Path | None]:
    assert m.mjcf is not None
    try:
        scene = Scene.from_mjcf(
            path.parent / m.mjcf,
            floating=m.floating,
            free_objects=m.free_objects,
            actuator_springs=m.actuator_springs,
        )
    except (FileNotFoundError, SceneError) as error:
        raise SceneError(f"[model] mjcf: {error}") from None
    return scene, None


def _robot_scene(m: ModelTable, path: Path) -> tuple[Scene, Path | None]:
    assert m.robot is not None
    try:
        model = build_robot_model(m.robot, floating=m.floating)
        urdf_path = robot_urdf(m.robot)
    except (KeyError, ValueError, FileNotFoundError) as error:
        message = error.args[0] if error.args else str(error)
        raise SceneError(f"[model] robot: {message}") from None
    return Scene(model), urdf_path


#: How each source of [model] makes the scene (and which URDF it has, for <mimic> and playback).
_SOURCES: dict[str, Callable[[ModelTable, Path], tuple[Scene, Path | None]]] = {
    "urdf": _urdf_scene,
    "robot": _robot_scene,
    "mjcf": _mjcf_scene,
}


def _model_scene(m: ModelTable, path: Path) -> Scene:
    """The scene of [model]'s one source, named after the file."""
    source = next(name for name in ModelTable.SOURCES if getattr(m, name) is not None)
    scene, urdf_path = _SOURCES[source](m, path)
    scene.name, scene.description = path.stem, _description(path)
    scene.limits = m.limits
    scene.path = path
    scene.urdf = urdf_path
    return scene


def _apply_model_options(scene: Scene, m: ModelTable, path: Path) -> None:
    """[model]'s mimic, srdf, gravity and locked, in that order."""
    if scene.urdf is not None:
        _at("[model] mimic", scene.apply_urdf_mimic, scene.urdf, m.mimic)
    if m.srdf is not None:
        try:
            scene.load_srdf(path.parent / m.srdf)
        except (FileNotFoundError, SceneError) as error:
            raise SceneError(f"[model] srdf: {error}") from None
    if m.gravity is not None:
        _at("[model]", setattr, scene, "gravity", m.gravity)
    _at("[model] locked", scene.lock, *m.locked)


def _apply_start(scene: Scene, m: ModelTable, start: Mapping[str, Any]) -> None:
    """[start]: a named pose (``pose``, unless the model has a joint of that name; a robot's
    own SRDF is read for it when the file names none), then joint values by name."""
    if "pose" in start and not scene.model.existJointName("pose"):
        pose = start["pose"]
        if m.srdf is None and m.robot is not None:
            own = robot_srdf(m.robot)
            if own is not None and isinstance(pose, str) and pose not in scene.poses:
                _at("[model] robot's SRDF", scene.load_srdf, own)
        _at("[start] pose", scene.set_pose, pose)
        start = {joint: value for joint, value in start.items() if joint != "pose"}
    for joint, value in start.items():
        _at("[start]", scene.set_start, {joint: value})


def _add_elements(scene: Scene, file: SceneFile) -> None:
    """The arrays of tables, each entry through the Scene method it stands for."""
    for k, s in enumerate(file.joint_springs, start=1):
        _at(
            f"[[joint_spring]] #{k}",
            scene.add_joint_spring,
            s.joint,
            s.stiffness,
            s.rest,
            s.damping,
        )
    for k, sp in enumerate(file.springs, start=1):
        where = f"[[spring]] #{k}"
        _at(where, scene.add_spring, sp.a, sp.b, sp.stiffness, sp.rest_length, sp.damping)
    for k, load in enumerate(file.loads, start=1):
        if load.joint is not None:
            _at(f"[[load]] #{k}", scene.add_load, load.joint, load.effort)
        else:
            _at(
                f"[[load]] #{k}",
                scene.add_load,
                frame=load.frame,
                point=load.point,
                force=load.force,
                torque=load.torque,
            )
    for k, p in enumerate(file.payloads, start=1):
        _at(f"[[payload]] #{k}", scene.add_payload, p.frame, p.mass, p.offset)
    for k, loop in enumerate(file.loops, start=1):
        _at(f"[[loop]] #{k}", scene.add_loop, loop.a, loop.b, loop.kind)
    for k, limit in enumerate(file.limits, start=1):
        _at(f"[[limit]] #{k}", scene.set_limit, limit.joint, limit.lower, limit.upper)
    for k, g in enumerate(file.grounds, start=1):
        _at(
            f"[[ground]] #{k}",
            scene.add_ground,
            g.point,
            g.normal,
            g.friction,
            g.name,
            box=g.box,
            rpy=g.rpy,
        )
    for k, c in enumerate(file.contacts, start=1):
        _at(f"[[contact]] #{k}", scene.add_contact, c.frame, c.point, c.radius, c.name)


def _add_collision_contacts(scene: Scene, file: SceneFile) -> None:
    """[model] contacts and floor: the model's collision shapes as contacts (an MJCF file's
    by default) and its floors as grounds unless the scene gives [[ground]] tables or a
    floor."""
    m = file.model
    _at(
        "[model] contacts",
        take_model_contacts,
        scene,
        m.contacts,
        m.floor,
        grounds=bool(file.grounds),
        hull_points=m.hull_points,
        exclude=m.contacts_exclude,
    )


#: The way out of an MJCF file's contacts, for the errors of contacts taken by default.
_NO_CONTACTS = (
    'or leave the file\'s contacts out: [model] contacts = "none" (--no-contacts, contacts="none")'
)


def take_model_contacts(
    scene: Scene,
    contacts: str | None,
    floor: Any = None,
    *,
    grounds: bool = False,
    hull_points: Any = HULL_POINTS,
    exclude: Sequence[str] = (),
) -> None:
    """The contacts a scene file's [model] (or ``load_scene``'s options) asks for.

    ``contacts``: 'collision' (the model's collision shapes, ``add_collision_contacts``),
    'none', or None: an MJCF file's floors and the geoms MuJoCo collides with them, as MuJoCo
    does, where the file has floors (or ``grounds``: the scene gives grounds of its own, which
    replace the file's floors) and they touch a moving geom; nothing for other models.
    ``floor``: None or False (no floor), True (a level plane under the lowest contact point at
    the start) or a height (m); it takes the collision shapes unless contacts is 'none', which
    is then an error.
    """
    if contacts not in (None, "collision", "none"):
        raise SceneError(f"contacts must be 'collision', 'none' or None, got {contacts!r}")
    has_floor = floor is not None and floor is not False
    if has_floor and not (floor is True or isinstance(floor, (int, float, np.number))):
        raise SceneError(
            f"floor must be True (under the lowest contact point), a height (m) or None, "
            f"got {floor!r}"
        )
    if contacts == "none":
        if has_floor:
            raise SceneError(
                "a floor needs contact points, and contacts 'none' leaves them out: give one "
                "or the other"
            )
        return
    if contacts is None and not has_floor:
        _take_mjcf_contacts(scene, grounds, hull_points, exclude)
        return
    scene.add_collision_contacts(
        hull_points=hull_points, exclude=exclude, floors=not grounds and not has_floor
    )
    if has_floor:
        scene.add_floor(None if floor is True else floor)


def _take_mjcf_contacts(
    scene: Scene, grounds: bool, hull_points: Any, exclude: Sequence[str]
) -> None:
    """An MJCF file's contacts by default: its floors and the geoms MuJoCo collides with them,
    where it has floors (or the scene grounds) and they touch a moving geom; else a note."""
    mjcf = scene._mjcf_collision
    if mjcf is None or not (mjcf.floors or grounds):
        return  # nothing to rest on: the file solves as it did without contacts
    count = _hull_points(hull_points)
    _check_exclude(exclude)
    try:
        collision, where = scene._collision(None, exclude)
    except SceneError as error:
        raise SceneError(f"{error}; {_NO_CONTACTS}") from None
    _check_excluded(collision, exclude)
    if not mjcf.enabled:
        scene.notes += collision.notes
        return
    if not any(_moves(scene, shape.frame) for shape in collision.shapes):
        scene.notes.append(
            "the file's floors touch no geom of a moving body: no contacts (contype, "
            "conaffinity, <contact>)"
        )
        return
    try:
        scene._add_shapes(collision, where, count, exclude)
    except SceneError as error:
        raise SceneError(f"{error}; {_NO_CONTACTS}") from None
    floor_notes = scene._take_floors(collision, not grounds)  # it edits notes
    scene.notes += floor_notes


def _moves(scene: Scene, frame: str) -> bool:
    """Whether a frame's body moves with the scene's locked joints held."""
    return moves_after_locking(scene.model, _frame_joint(scene.model, frame), scene.locked)


def _check_excluded(collision: Collision, exclude: Sequence[str]) -> None:
    """Each name of ``exclude`` is a shape or frame of the source."""
    for name in exclude:
        if name not in collision.names:
            raise SceneError("exclude: " + _close(name, collision.names, "shape or frame"))

"""The scene file's schema: one dataclass per TOML table, read by one generic loader.

Each table is declared once, as a dataclass: its keys are the fields (in the order that
unknown-key messages list them and the loader checks them), with their defaults; ``key()``
adds what a given value must be (``expect``, the words of the error message, and ``check``)
and which other key it goes with. ``read_table`` checks a TOML table against its declaration
and gives the dataclass; ``read_scene_file`` reads every table of a scene file into a
``SceneFile``. Nothing here looks at the model: joint and frame names, numbers and shapes are
checked when the scene is built (``_scene``), with the same ``where`` in front.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, TypeVar

from ._checks import unknown_key_message
from ._scene_values import SceneError
from ._settings import SETTING_TYPES, Settings, make_settings, set_setting

_MISSING: Any = dataclasses.MISSING
_T = TypeVar("_T")


def key(
    default: Any = _MISSING,
    *,
    expect: str | None = None,
    check: Callable[[Any], bool] | None = None,
    needs: str | None = None,
    clashes: str | None = None,
    purpose: str = "",
) -> Any:
    """A key of a table: its default (none: the key is required), ``expect`` / ``check``: what
    a given value must be, ``needs`` / ``clashes``: a key it is only for, or never with (the
    message then says what it ``is for``, ``purpose``)."""
    meta = {
        "expect": expect,
        "check": check,
        "needs": needs,
        "clashes": clashes,
        "purpose": purpose,
    }
    if isinstance(default, list):
        return field(default_factory=lambda: list(default), metadata=meta)
    return field(default=default, metadata=meta)


def _is_bool(value: Any) -> bool:
    return isinstance(value, bool)


def _is_str(value: Any) -> bool:
    return isinstance(value, str)


def _is_list(value: Any) -> bool:
    return isinstance(value, list)


def _is_table(value: Any) -> bool:
    return isinstance(value, dict)


def _keep_or_lock(value: Any) -> bool:
    return value in ("keep", "lock")


def _contacts_kind(value: Any) -> bool:
    return value in ("collision", "none")


def _floor_kind(value: Any) -> bool:
    if isinstance(value, bool):
        return True
    return isinstance(value, (int, float)) and math.isfinite(value)


_FLAG: dict[str, Any] = {"expect": "true or false", "check": _is_bool}
_PATH: dict[str, Any] = {"expect": "a path (str)", "check": _is_str}
_END: dict[str, Any] = {
    "expect": "an inline table { frame = ..., point = [x, y, z] }",
    "check": _is_table,
}


def _label(where: str, name: str, entry: bool) -> str:
    """How a message names a key: ``[model] urdf`` in a table, ``[[spring]] #2: a`` in an
    entry of an array of tables."""
    return f"{where}: {name}" if entry else f"{where} {name}"


def read_table(cls: type[_T], table: Mapping[str, Any], where: str, *, entry: bool = False) -> _T:
    """``table`` as the dataclass ``cls`` that declares it: unknown keys, missing required
    keys, values of the wrong kind and keys given without the key they are for are errors
    that begin with ``where``. A declaration may add checks of its own: ``check_keys`` (a
    classmethod: which keys go together), run before the values are looked at, and ``check``,
    run on the table read."""
    fields = dataclasses.fields(cls)  # type: ignore[arg-type]
    known = [f.name for f in fields]
    for name in table:
        if name not in known:
            raise SceneError(f"{where}: " + unknown_key_message("key", name, known))
    check_keys = getattr(cls, "check_keys", None)
    if check_keys is not None:  # which keys go together, before their values
        check_keys(table, where)
    for f in fields:
        required = f.default is _MISSING and f.default_factory is _MISSING
        if f.name not in table:
            if required:
                raise SceneError(f"{where}: missing key '{f.name}'")
            continue
        _check_value(f.metadata, table, f.name, _label(where, f.name, entry))
    out = cls(**table)
    check = getattr(out, "check", None)
    if check is not None:
        check(table, where)
    return out


def _check_value(meta: Mapping[str, Any], table: Mapping[str, Any], name: str, label: str) -> None:
    """One given key's value and company, as its declaration says."""
    value = table[name]
    if meta["check"] is not None and not meta["check"](value):
        raise SceneError(f"{label} must be {meta['expect']}, got {value!r}")
    if meta["clashes"] is not None and meta["clashes"] in table:
        raise SceneError(f"{label} is for {meta['purpose']}")
    if meta["needs"] is not None and meta["needs"] not in table:
        raise SceneError(f"{label} is for {meta['purpose']}")


# --- the tables -------------------------------------------------------------------------------


@dataclass(frozen=True)
class ModelTable:
    """``[model]``: the mechanism (exactly one of urdf, robot, mjcf) and how to take it."""

    urdf: str | None = key(None, **_PATH)
    robot: str | None = key(None, expect="a name (str)", check=_is_str)
    mjcf: str | None = key(None, **_PATH)
    srdf: str | None = key(None, **_PATH)
    floating: bool = key(False, **_FLAG)
    locked: list[Any] = key([], expect="a list of joint names", check=_is_list)
    gravity: Any = key(None)  # checked by Scene.gravity
    limits: bool = key(True, **_FLAG)
    mimic: bool | None = key(
        None,
        **_FLAG,
        clashes="mjcf",
        purpose="a URDF's <mimic> tags ('urdf' or 'robot'); an MJCF file couples joints with "
        "<equality><joint>",
    )
    free_objects: str = key(
        "keep",
        expect="'keep' (free objects fall) or 'lock' (fixed where the file places them)",
        check=_keep_or_lock,
        needs="mjcf",
        purpose="an MJCF file's free objects ('mjcf')",
    )
    actuator_springs: bool = key(
        False, **_FLAG, needs="mjcf", purpose="an MJCF file's actuators ('mjcf')"
    )
    contacts: str | None = key(
        None,
        expect="'collision' (contact points from the model's collision geometry) or 'none'",
        check=_contacts_kind,
    )
    floor: Any = key(
        None,
        expect="true (a level plane under the model's lowest contact point at its start), a "
        "height z (m) or false",
        check=_floor_kind,
    )
    hull_points: Any = key(16)  # checked by Scene.add_collision_contacts
    contacts_exclude: list[Any] = key([], expect="a list of shape or frame names", check=_is_list)

    SOURCES: ClassVar[tuple[str, ...]] = ("urdf", "robot", "mjcf")

    @classmethod
    def check_keys(cls, table: Mapping[str, Any], where: str) -> None:
        sources = [name for name in cls.SOURCES if name in table]
        if len(sources) != 1:
            raise SceneError(
                f"{where} needs exactly one of 'urdf' (a file), 'robot' (an example-robot-data "
                "name) or 'mjcf' (a MuJoCo MJCF file), got "
                + ("neither" if not sources else "all three" if len(sources) == 3 else "both")
                + (f" ({' and '.join(sources)})" if sources else "")
            )

    def takes_contacts(self) -> bool:
        """Whether the model's collision shapes are contacts: ``contacts = "collision"``, a
        ``floor``, or an MJCF file without a ``contacts`` key (MuJoCo collides its geoms)."""
        if self.contacts is not None:
            return self.contacts == "collision"
        return self.has_floor or self.mjcf is not None

    @property
    def has_floor(self) -> bool:
        """Whether ``floor`` asks for a floor (``false`` does not; a height 0 does)."""
        return self.floor is not None and self.floor is not False

    def check(self, table: Mapping[str, Any], where: str) -> None:
        if self.has_floor and self.contacts == "none":
            raise SceneError(
                f'{where} floor needs contact points, and contacts = "none" leaves them out: '
                'drop one (contacts = "collision" takes the collision shapes)'
            )
        for name, what in (
            ("hull_points", "the most points of a mesh's hull"),
            ("contacts_exclude", "shapes or frames left out"),
        ):
            if name in table and not self.takes_contacts():
                raise SceneError(
                    f"{where} {name} is for contacts from the model's collision shapes ({what}): "
                    'contacts = "collision", a floor, or an MJCF file without contacts = "none"'
                )


@dataclass(frozen=True)
class JointSpringEntry:
    """``[[joint_spring]]``: ``Scene.add_joint_spring``."""

    joint: Any = key()
    stiffness: Any = key()
    rest: Any = key(0.0)
    damping: Any = key(0.0)


@dataclass(frozen=True)
class SpringEntry:
    """``[[spring]]``: ``Scene.add_spring`` between two ends ``{ frame, point }``."""

    a: dict[str, Any] = key(**_END)
    b: dict[str, Any] = key(**_END)
    stiffness: Any = key()
    rest_length: Any = key(0.0)
    damping: Any = key(0.0)


_JOINT_LOAD_ONLY = ("frame", "point", "force", "torque")


@dataclass(frozen=True)
class LoadEntry:
    """``[[load]]``: on a joint (``joint``, ``effort``) or at a point of a frame (``frame``,
    ``point``, ``force``, ``torque``): ``Scene.add_load``."""

    joint: Any = key(None)
    effort: Any = key(None)
    frame: Any = key(None)
    point: Any = key((0.0, 0.0, 0.0))
    force: Any = key(None)
    torque: Any = key((0.0, 0.0, 0.0))

    def check(self, table: Mapping[str, Any], where: str) -> None:
        if "joint" in table:
            extra = [name for name in _JOINT_LOAD_ONLY if name in table]
            if extra:
                raise SceneError(
                    f"{where}: a joint load takes 'joint' and 'effort' only, got also '{extra[0]}'"
                )
            needed = "effort"
        elif "frame" in table:
            if "effort" in table:
                raise SceneError(f"{where}: 'effort' belongs to a joint load, not a frame load")
            needed = "force"
        else:
            raise SceneError(f"{where}: needs 'joint' (with 'effort') or 'frame' (with 'force')")
        if needed not in table:
            raise SceneError(f"{where}: missing key '{needed}'")


@dataclass(frozen=True)
class PayloadEntry:
    """``[[payload]]``: ``Scene.add_payload``, a mass's weight at a point of a frame."""

    frame: Any = key()
    mass: Any = key()
    offset: Any = key((0.0, 0.0, 0.0))


@dataclass(frozen=True)
class LoopEntry:
    """``[[loop]]``: ``Scene.add_loop``."""

    a: dict[str, Any] = key(**_END)
    b: dict[str, Any] = key(**_END)
    kind: Any = key("point")


@dataclass(frozen=True)
class LimitEntry:
    """``[[limit]]``: ``Scene.set_limit``, one per joint."""

    joint: Any = key()
    lower: Any = key(None)
    upper: Any = key(None)

    def check(self, table: Mapping[str, Any], where: str) -> None:
        if "lower" not in table and "upper" not in table:
            raise SceneError(f"{where}: give 'lower', 'upper' or both (rad or m), got neither")


@dataclass(frozen=True)
class GroundEntry:
    """``[[ground]]``: ``Scene.add_ground``."""

    point: Any = key((0.0, 0.0, 0.0))
    normal: Any = key(None)
    friction: Any = key(0.5)
    name: Any = key(None)
    box: Any = key(None)
    rpy: Any = key(None)


@dataclass(frozen=True)
class ContactEntry:
    """``[[contact]]``: ``Scene.add_contact``."""

    frame: Any = key()
    point: Any = key((0.0, 0.0, 0.0))
    radius: Any = key(0.0)
    name: Any = key(None)


@dataclass(frozen=True)
class SceneFile:
    """A scene file, read: each table as declared above (``start``: joint values by name, and
    ``pose``), the solver settings checked."""

    model: ModelTable
    start: dict[str, Any]
    joint_springs: list[JointSpringEntry]
    springs: list[SpringEntry]
    loads: list[LoadEntry]
    payloads: list[PayloadEntry]
    loops: list[LoopEntry]
    limits: list[LimitEntry]
    grounds: list[GroundEntry]
    contacts: list[ContactEntry]
    settings: Settings


#: The arrays of tables: TOML key, declaration, field of ``SceneFile``.
_ARRAYS: tuple[tuple[str, type[Any], str], ...] = (
    ("joint_spring", JointSpringEntry, "joint_springs"),
    ("spring", SpringEntry, "springs"),
    ("load", LoadEntry, "loads"),
    ("payload", PayloadEntry, "payloads"),
    ("loop", LoopEntry, "loops"),
    ("limit", LimitEntry, "limits"),
    ("ground", GroundEntry, "grounds"),
    ("contact", ContactEntry, "contacts"),
)
_TOP_KEYS = ["model", "start", *[name for name, _, _ in _ARRAYS], "solver"]


def read_scene_file(data: Mapping[str, Any]) -> SceneFile:
    """A parsed scene file (TOML) checked against the schema; errors name the table and key."""
    for name in data:
        if name not in _TOP_KEYS:
            raise SceneError("top level: " + unknown_key_message("key", name, _TOP_KEYS))
    if "model" not in data:
        raise SceneError("missing table [model] (with 'urdf' or 'robot')")
    model = read_table(ModelTable, _table(data, "model"), "[model]")
    start = _table(data, "start")
    arrays = {
        attribute: [
            read_table(cls, entry, f"[[{name}]] #{k}", entry=True)
            for k, entry in enumerate(_tables(data, name), start=1)
        ]
        for name, cls, attribute in _ARRAYS
    }
    _one_limit_per_joint(arrays["limits"])
    return SceneFile(
        model=model,
        start=start,
        settings=_settings(_table(data, "solver")),
        **arrays,
    )


def _table(data: Mapping[str, Any], name: str) -> dict[str, Any]:
    value = data.get(name, {})
    if not isinstance(value, dict):
        raise SceneError(f"[{name}] must be a table ([{name}]), got {type(value).__name__}")
    return value


def _tables(data: Mapping[str, Any], name: str) -> list[dict[str, Any]]:
    value = data.get(name, [])
    if not isinstance(value, list) or not all(isinstance(x, dict) for x in value):
        raise SceneError(f"'{name}' must be an array of tables ([[{name}]]), got {value!r}")
    return value


def _one_limit_per_joint(limits: list[LimitEntry]) -> None:
    first: dict[str, int] = {}
    for k, limit in enumerate(limits, start=1):
        if isinstance(limit.joint, str) and limit.joint in first:
            raise SceneError(
                f"[[limit]] #{k}: joint '{limit.joint}' has its stops in [[limit]] "
                f"#{first[limit.joint]} already (one [[limit]] per joint)"
            )
        if isinstance(limit.joint, str):
            first[limit.joint] = k


def _settings(solver: Mapping[str, Any]) -> Settings:
    """``[solver]``: the settings of ``pinsettle.solve``, each checked, then together."""
    settings = make_settings(None, {})
    for name, value in solver.items():
        if name not in SETTING_TYPES:
            raise SceneError("[solver]: " + unknown_key_message("key", name, list(SETTING_TYPES)))
        try:
            set_setting(settings, name, value)
        except (TypeError, ValueError) as error:
            raise SceneError(f"[solver]: {error}") from None
    try:
        settings.check()
    except ValueError as error:
        raise SceneError(f"[solver]: {error}") from None
    return settings

"""Solver settings: ``Settings`` and the checks of their fields.

It imports only the C++ core and ``_checks``, so that scenes (which carry settings) and the
solve can both use it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from . import _core
from ._checks import unknown_key_message

#: Every setting as the core declares it (``_core.Settings.fields()``: name, kind, what a
#: value must be, help, default, whether the command line has a flag), in the core's order.
SETTING_FIELDS: list[dict[str, Any]] = _core.Settings.fields()

#: The Python type each kind of setting takes, as messages and type stubs say it.
_KIND_TYPES = {
    "number": ("float", "float"),
    "integer": ("int", "int"),
    "switch": ("bool", "bool"),
    "auto_number": ("float or 'auto'", "float | str"),
    "auto_switch": ("bool or 'auto'", "bool | str"),
    "choice": ("str", "str"),
}


def _type_text(field: dict[str, Any]) -> str:
    if field["kind"] == "choice":  # the names it takes, as Python writes them
        return "str (" + str(field["expected"]).replace('"', "'") + ")"
    return _KIND_TYPES[field["kind"]][0]


#: Settings keys with the Python type each one takes (used for clear messages).
SETTING_TYPES: dict[str, str] = {f["name"]: _type_text(f) for f in SETTING_FIELDS}


def settings_stub() -> str:
    """The type stub of ``_core.Settings``'s fields (``_core.pyi`` holds it; a test keeps the
    two equal)."""
    return "".join(f"    {f['name']}: {_KIND_TYPES[f['kind']][1]}\n" for f in SETTING_FIELDS)


def _fields_doc() -> str:
    lines = []
    for f in SETTING_FIELDS:
        lines.append(f"``{f['name']}`` ({SETTING_TYPES[f['name']]}, default {f['default']!r}):")
        lines.append(f"    {f['help']}")
    return "\n    ".join(lines)


class Settings(_core.Settings):
    """Solver settings, inputs only: the solver never writes them back.

    ``Settings(kt=0.3, dt=5e-4)`` sets fields by name; an unknown name or a value of the wrong
    type raises ``TypeError``, a value out of range raises ``ValueError`` when solving (or on
    ``check()``), naming the field and its allowed range.

    The fields (each declared once, in the core: ``_core.Settings.fields()``), what each
    takes, its default and what it does are listed below; ``effective_dt_safety`` and
    ``effective_dt_growth`` give the values 'auto' stands for. docs/settings.md says how the
    defaults were measured.
    """

    def __init__(self, **fields: Any) -> None:
        super().__init__()
        for key, value in fields.items():
            set_setting(self, key, value)

    def replace(self, **fields: Any) -> Settings:
        """A copy with some fields changed."""
        return make_settings(self, fields)

    def _copy(self) -> Settings:
        """A copy, made by the core's copy constructor (1.4 us; ``replace()`` sets each field
        through its checks, 20 us): a kept Solver gives each Result settings of its own."""
        out = Settings.__new__(Settings)
        _core.Settings.__init__(out, self)
        return out

    def to_dict(self) -> dict[str, Any]:
        return {key: getattr(self, key) for key in SETTING_TYPES}

    def __repr__(self) -> str:
        body = ", ".join(f"{k}={v!r}" for k, v in self.to_dict().items())
        return f"Settings({body})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, _core.Settings):
            return NotImplemented
        return all(getattr(self, k) == getattr(other, k) for k in SETTING_TYPES)

    __hash__ = None  # type: ignore[assignment]


Settings.__doc__ = f"{(Settings.__doc__ or '').rstrip()}\n\n    {_fields_doc()}\n"


def _is_of_kind(kind: str, value: Any) -> bool:
    """Whether value has the Python type a setting of ``kind`` (SETTING_TYPES) takes; the
    range is the core's to check ('fast' for dt, 'on' for a bool or 'auto': its messages)."""
    is_bool = isinstance(value, (bool, np.bool_))
    number = isinstance(value, (int, float, np.integer, np.floating)) and not is_bool
    return {
        "float": number,
        "float or 'auto'": number or isinstance(value, str),
        "int": isinstance(value, (int, np.integer)) and not is_bool,
        "bool": is_bool,
        "bool or 'auto'": is_bool or isinstance(value, str),
    }.get(kind, isinstance(value, str))


def set_setting(settings: _core.Settings, key: str, value: Any) -> None:
    """Set one field with a message that names it when the key or the type is wrong."""
    if key not in SETTING_TYPES:
        raise TypeError(unknown_key_message("setting", key, list(SETTING_TYPES)))
    kind = SETTING_TYPES[key]
    # The type by hand before the C++ property sees it: pybind11 raises RuntimeError, not
    # TypeError, for some values it cannot convert (None for dt).
    if not _is_of_kind(kind, value):
        raise TypeError(f"setting '{key}' expects {kind}, got {type(value).__name__} {value!r}")
    if kind == "int" and not -(2**63) <= value < 2**63:
        raise ValueError(f"setting '{key}' must fit in a 64-bit integer, got {value}")
    if kind.startswith("float") and isinstance(value, (int, np.integer)):
        value = float(value)
    if isinstance(value, np.bool_):
        value = bool(value)
    try:
        setattr(settings, key, value)
    except (TypeError, RuntimeError):
        raise TypeError(
            f"setting '{key}' expects {SETTING_TYPES[key]}, got {type(value).__name__} {value!r}"
        ) from None


def make_settings(settings: Any, overrides: Mapping[str, Any]) -> Settings:
    """The settings of a solve: a copy of ``settings`` (None, Settings or a dict) with
    ``overrides`` applied."""
    if settings is None:
        out = Settings()
    elif isinstance(settings, _core.Settings):
        out = Settings(**{k: getattr(settings, k) for k in SETTING_TYPES})
    elif isinstance(settings, Mapping):
        out = Settings(**settings)
    else:
        raise TypeError(
            f"settings must be a pinsettle.Settings, a dict or None, got {type(settings).__name__}"
        )
    for key, value in overrides.items():
        set_setting(out, key, value)
    return out

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

#: Settings keys with the Python type each one takes (used for clear messages).
SETTING_TYPES: dict[str, str] = {
    "dt": "float or 'auto'",
    "dt_safety": "float or 'auto'",
    "kt": "float",
    "err": "float",
    "ds": "int",
    "max_e": "float",
    "max_steps": "int",
    "max_time": "float",
    "energy": "str ('exact' or 'simplified')",
    "backtrack": "bool",
    "polish": "bool",
    "newton_takeover": "bool",
    "scale_stiff_modes": "bool",
    "scale_joint_inertia": "bool",
    "dt_growth": "float or 'auto'",
    "trace_every": "int",
    "trace_capacity": "int",
    "trace_configurations": "bool",
    "check_every": "int",
}


class Settings(_core.Settings):
    """Solver settings, inputs only: the solver never writes them back.

    ``Settings(kt=0.3, dt=5e-4)`` sets fields by name; an unknown name or a value of the wrong
    type raises ``TypeError``, a value out of range raises ``ValueError`` when solving (or on
    ``check()``), naming the field and its allowed range.

    Fields: ``dt`` time step (s), or 'auto' (the default: ``dt_safety`` times the stability
    limit 2 / omega_max of the mechanism linearised where it is, re-estimated as it moves);
    ``dt_safety`` in (0, 1], or 'auto' (the default: 0.3 with ``backtrack`` and the exact
    energy, 0.2 otherwise, measured; ``effective_dt_safety`` gives the value in use);
    ``dt_growth`` >= 1, or 'auto' (the default: 2.5 with ``backtrack``, the exact energy and
    ``scale_stiff_modes``, 1 otherwise, measured): the largest factor the automatic step grows
    to between damping events, 5 % a step, never past the stability limit
    (``effective_dt_growth``);
    ``scale_stiff_modes`` (with 'auto': modes over 100x faster than the rest, or 30x faster
    than the slowest, get a larger effective mass, equilibria unchanged, where the longer step
    pays for the costlier one);
    ``scale_joint_inertia`` (off by default; with 'auto' and the exact energy, on a tree: each
    joint gets a fictitious inertia that brings its own rate, stiffness or pull over inertia,
    down towards the slowest joint's, re-chosen at each estimate; equilibria and stability
    unchanged, ``Result.scaled_joints`` counts the joints given one);
    ``polish`` (Newton steps after convergence); ``newton_takeover`` (on by default; with
    ``polish``: at a damping event, at most once every max(1, nv^2 / 4) steps, the polish's
    Newton from where the mechanism stands; a rest it reaches at round-off within the polish's
    reach and 0.1 (rad or m), stable or neutral as where it started, ends the run); ``kt``
    velocity scale at each energy peak, in [0, 1); ``err`` relative peak threshold; ``ds``
    stopping window (steps); ``max_e`` bound on the sum of the last ``ds`` energy samples (J for
    the exact measure); ``max_steps``; ``max_time`` (s); ``energy`` ('exact' or 'simplified');
    ``backtrack`` (back up to the interpolated peak before damping; on by default);
    ``trace_every`` (0: no trace); ``trace_capacity``; ``trace_configurations`` (record q in the
    trace, for playback); ``check_every`` (steps between checks of the clock and Ctrl-C).
    """

    def __init__(self, **fields: Any) -> None:
        super().__init__()
        for key, value in fields.items():
            set_setting(self, key, value)

    def replace(self, **fields: Any) -> Settings:
        """A copy with some fields changed."""
        return make_settings(self, fields)

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


def set_setting(settings: _core.Settings, key: str, value: Any) -> None:
    """Set one field with a message that names it when the key or the type is wrong."""
    if key not in SETTING_TYPES:
        raise TypeError(unknown_key_message("setting", key, list(SETTING_TYPES)))
    kind = SETTING_TYPES[key]
    is_bool = isinstance(value, (bool, np.bool_))
    if is_bool != (kind == "bool"):
        raise TypeError(f"setting '{key}' expects {kind}, got {type(value).__name__} {value!r}")
    if kind == "int" and isinstance(value, (int, np.integer)) and not -(2**63) <= value < 2**63:
        raise ValueError(f"setting '{key}' must fit in a 64-bit integer, got {value}")
    # The type by hand before the C++ property sees it: pybind11 raises RuntimeError, not
    # TypeError, for some values it cannot convert (None for dt).
    number = isinstance(value, (int, float, np.integer, np.floating)) and not is_bool
    expected = {
        "float": number,
        "float or 'auto'": number or isinstance(value, str),  # 'fast': the C++ range message
        "int": isinstance(value, (int, np.integer)) and not is_bool,
        "bool": is_bool,
    }.get(kind, isinstance(value, str))
    if not expected:
        raise TypeError(f"setting '{key}' expects {kind}, got {type(value).__name__} {value!r}")
    if kind.startswith("float") and isinstance(value, (int, np.integer)):
        value = float(value)
    if is_bool:
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

"""Argument checks whose messages name what was wrong, shared by every module of the package.

It imports nothing of the package, so that any module can use it without an import circle.
"""

from __future__ import annotations

import difflib
from typing import Any

import numpy as np


def unknown_key_message(kind: str, key: str, known: list[str]) -> str:
    close = difflib.get_close_matches(key, known, n=1)
    hint = f" (did you mean '{close[0]}'?)" if close else ""
    return f"unknown {kind} '{key}'{hint}; known {kind}s: {', '.join(known)}"


def as_vector(value: Any, name: str, size: int, size_name: str) -> np.ndarray:
    if isinstance(value, (str, bytes)) or np.iscomplexobj(value):
        raise TypeError(
            f"{name} must be a 1-D array of {size_name} = {size} real numbers, "
            f"got {type(value).__name__}"
        )
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(
            f"{name} must be a 1-D array of {size_name} = {size} real numbers, "
            f"got {type(value).__name__} {value!r}"
        ) from None
    if arr.ndim != 1 or arr.shape[0] != size:
        raise ValueError(f"{name} must have shape ({size},) ({size_name}), got {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] is {arr[bad[0]]}; every entry must be finite")
    return arr


def as_flag(value: Any, name: str) -> bool:
    """A True/False argument (numpy booleans too); anything else is a TypeError naming it."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {type(value).__name__} {value!r}")
    return bool(value)


def negative_moments(tensor: np.ndarray) -> np.ndarray | None:
    """The principal moments of a finite rotational inertia (kg m^2) when it is not positive
    semidefinite (its smallest below -1e-9 of its largest), else None. Scaled to its largest
    entry first: a moment of 1e308 overflows the sum of its halves."""
    scale = float(np.abs(tensor).max())
    if scale == 0.0:
        return None
    moments = np.linalg.eigvalsh(0.5 * (tensor / scale + tensor.T / scale)) * scale
    return moments if moments[0] < -1e-9 * max(np.abs(moments).max(), 1e-12) else None

"""A ``pinocchio.Data`` made only where it fits in the memory the machine has available."""

from __future__ import annotations

from typing import Any

from . import _core


def new_data(model: Any, what: str) -> Any:
    """``model.createData()``, checked first against the memory the machine has available: a
    MemoryError that says how much, instead of the kernel's OOM killer (Pinocchio 4.1 zeroes
    four nv^3 tensors in every Data; its Python binding copies the Data it returns, so the peak
    is two)."""
    _core.check_data_memory(model, 2, what)
    return model.createData()

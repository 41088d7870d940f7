"""Type stubs of the C++ extension pinsettle._core (see pinsettle._solve for the public API)."""

from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
import pinocchio

class Settings:
    dt: float | str
    dt_safety: float
    kt: float
    err: float
    ds: int
    max_e: float
    max_steps: int
    max_time: float
    energy: str
    backtrack: bool
    polish: bool
    scale_stiff_modes: bool
    trace_every: int
    trace_capacity: int
    trace_configurations: bool
    check_every: int
    def __init__(self, other: Settings | None = ...) -> None: ...
    def check(self) -> None: ...

def solve(
    model: pinocchio.Model,
    q0: npt.NDArray[np.float64],
    v0: npt.NDArray[np.float64],
    settings: Settings,
    callback: Callable[[], bool] | None = ...,
    elements: dict[str, list[tuple[Any, ...]]] | None = ...,
    loops: list[tuple[Any, ...]] | None = ...,
) -> dict[str, Any]: ...
def kinetic_energies(
    model: pinocchio.Model, q: npt.NDArray[np.float64], v: npt.NDArray[np.float64]
) -> tuple[float, float]: ...
def static_force(
    model: pinocchio.Model,
    q: npt.NDArray[np.float64],
    elements: dict[str, list[tuple[Any, ...]]] | None = ...,
    loops: list[tuple[Any, ...]] | None = ...,
) -> npt.NDArray[np.float64]: ...
def stiffness(
    model: pinocchio.Model,
    q: npt.NDArray[np.float64],
    elements: dict[str, list[tuple[Any, ...]]] | None = ...,
    loops: list[tuple[Any, ...]] | None = ...,
) -> dict[str, Any]: ...
def time_scale(
    model: pinocchio.Model,
    q: npt.NDArray[np.float64],
    elements: dict[str, list[tuple[Any, ...]]] | None = ...,
    scale_stiff_modes: bool = ...,
    loops: list[tuple[Any, ...]] | None = ...,
) -> dict[str, float]: ...
def loops(
    model: pinocchio.Model, q: npt.NDArray[np.float64], loops: list[tuple[Any, ...]]
) -> dict[str, Any]: ...
def assemble_loops(
    model: pinocchio.Model, q: npt.NDArray[np.float64], loops: list[tuple[Any, ...]] | None
) -> tuple[npt.NDArray[np.float64], float]: ...

"""Type stubs of the C++ extension pinsettle._core (see pinsettle._solve for the public API)."""

from collections.abc import Callable
from typing import Any, TypedDict, type_check_only

import numpy as np
import numpy.typing as npt
import pinocchio

# The force elements and loop closures as pinsettle._scene._Compiled resolves them: tuples of
# indices, points (arrays) and numbers, by kind ('joint_springs', 'springs', 'joint_loads',
# 'point_loads').
_Elements = dict[str, list[tuple[Any, ...]]]
_Loops = list[tuple[Any, ...]]
# Joint stops: (take the model's position limits, [(joint index, lower, upper), ...]).
_Stops = tuple[bool, list[tuple[int, float, float]]]
# Ground contacts: (planes (name, point, normal, friction), boxes (name, centre, axes, half
# sizes, friction), points (name, joint index, centre in the joint's frame, radius)).
_Contacts = tuple[
    list[tuple[str, npt.ArrayLike, npt.ArrayLike, float]],
    list[tuple[str, npt.ArrayLike, npt.ArrayLike, npt.ArrayLike, float]],
    list[tuple[str, int, npt.ArrayLike, float]],
]

class Settings:
    dt: float | str
    dt_safety: float | str
    dt_growth: float | str
    kt: float
    err: float
    ds: int
    max_e: float
    max_steps: int
    max_time: float
    energy: str
    backtrack: bool
    polish: bool
    newton_takeover: bool
    scale_stiff_modes: bool
    scale_joint_inertia: bool | str
    trace_every: int
    trace_capacity: int
    trace_configurations: bool
    check_every: int
    @property
    def effective_dt_safety(self) -> float: ...
    @property
    def effective_dt_growth(self) -> float: ...
    def __init__(self, other: Settings | None = ...) -> None: ...
    def check(self) -> None: ...
    @staticmethod
    def fields() -> list[dict[str, Any]]: ...

# The dicts the functions return (plain dicts at run time: these names exist only here).
@type_check_only
class _Stiffness(TypedDict):
    stiffness_matrix: npt.NDArray[np.float64]
    verdict: str
    min_eigenvalue: float
    neutral_directions: int
    tolerance: float
    eigenvalues: npt.NDArray[np.float64]
    softest_direction: npt.NDArray[np.float64]
    basis: npt.NDArray[np.float64]

@type_check_only
class _StopStiffness(_Stiffness, total=False):
    # Present when stops are given.
    stop_contacts: list[tuple[str, str, float]]
    stop_residual: float

@type_check_only
class _JointStops(TypedDict):
    stops: list[tuple[str, int, int, float, float]]
    equal_limits: list[str]
    unapplied_limits: list[str]

@type_check_only
class _TimeScale(TypedDict):
    omega_max: float
    omega_unscaled: float
    scaled_modes: int
    damping_rate: float
    critical_step: float

@type_check_only
class _LoopState(TypedDict):
    error: npt.NDArray[np.float64]
    jacobian: npt.NDArray[np.float64]
    rank: int
    basis: npt.NDArray[np.float64]

# What solve's progress callable is given every settings.check_every steps.
@type_check_only
class _Progress(TypedDict):
    steps: int
    sim_time: float
    kinetic_energy: float
    peaks: int
    residual: float  # nan before the first assessment
    wall_time: float

class Solver:
    """A kinetic-damping solver for one model and what the scene adds to it, reusable."""

    def __init__(
        self,
        model: pinocchio.Model,
        elements: _Elements | None = ...,
        loops: _Loops | None = ...,
        stops: _Stops | None = ...,
        joints: list[tuple[str, int, int, list[int]]] | None = ...,
        contacts: _Contacts | None = ...,
    ) -> None: ...
    def solve(
        self,
        q0: npt.ArrayLike,
        v0: npt.ArrayLike,
        settings: Settings,
        callback: Callable[[], bool] | None = ...,
        progress: Callable[[_Progress], object] | None = ...,
    ) -> dict[str, Any]: ...
    @property
    def model(self) -> pinocchio.Model: ...
    @property
    def equal_limits(self) -> tuple[str, ...]: ...
    @property
    def unapplied_limits(self) -> tuple[str, ...]: ...

def check_data_memory(model: pinocchio.Model, count: int, what: str) -> None: ...
def data_memory(model: pinocchio.Model) -> int: ...

class MemoryLimitError(MemoryError): ...

def joint_layout(
    model: pinocchio.Model,
) -> tuple[list[str], list[int], list[int], list[int]]: ...
def joint_stops(model: pinocchio.Model, stops: _Stops | None) -> _JointStops: ...
def kinetic_energies(
    model: pinocchio.Model, q: npt.ArrayLike, v: npt.ArrayLike
) -> tuple[float, float]: ...
def static_force(
    model: pinocchio.Model,
    q: npt.ArrayLike,
    elements: _Elements | None = ...,
    loops: _Loops | None = ...,
) -> npt.NDArray[np.float64]: ...
def stiffness(
    model: pinocchio.Model,
    q: npt.ArrayLike,
    elements: _Elements | None = ...,
    loops: _Loops | None = ...,
    stops: _Stops | None = ...,
) -> _StopStiffness: ...
def time_scale(
    model: pinocchio.Model,
    q: npt.ArrayLike,
    elements: _Elements | None = ...,
    scale_stiff_modes: bool = ...,
    loops: _Loops | None = ...,
) -> _TimeScale: ...
def loops(model: pinocchio.Model, q: npt.ArrayLike, loops: _Loops) -> _LoopState: ...
def release_mimic(
    model: pinocchio.Model,
) -> tuple[pinocchio.Model, list[tuple[int, int, float, float]]]: ...
def assemble_loops(
    model: pinocchio.Model, q: npt.ArrayLike, loops: _Loops | None
) -> tuple[npt.NDArray[np.float64], float]: ...

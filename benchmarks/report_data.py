"""What the benchmark report measures and writes: its constants and the records of its
measurements. benchmarks/report.py fills them in, benchmarks/report_writer.py turns them into
figures and text; both import this module, and the writer never imports report.py.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinsettle
from scene_statics import Statics

#: Residual levels of the summary, relative to the scene's force scale.
RESIDUAL_LEVELS = (1e-6, 1e-10)
#: Distance levels (rad or m) of the energy-measure comparison.
DISTANCE_LEVELS = (1e-3, 1e-6, 1e-9)
KTS = (0.0, 0.25, 0.5, 0.75, 0.9)
ERRS = (0.0, 1e-12, 1e-8, 1e-4, 1e-2)
DSS = (10, 30, 100, 300, 1000)
MAX_ES = (1e-8, 1e-12, 1e-16, 1e-20, 1e-24)
CHAIN_LENGTHS = (5, 10, 20, 50, 100, 200)
#: The bound of the stopping rule in the runs whose curves are plotted: far below every level,
#: so that the curve shows how the error falls, down to round-off.
DEEP_MAX_E = 1e-26
#: The baselines run until their residual is below this fraction of the force scale.
BASELINE_TARGET = 1e-13
#: Largest number of samples kept per curve (the solver's trace decimates beyond it).
CURVE_SAMPLES = 4096
MAX_STEPS = 3_000_000
#: Kinetic-damping runs on a scene take at most this many times the steps of the run that found
#: its reference equilibrium (and at least STEP_BUDGET_MIN).
STEP_BUDGET_FACTOR = 10
STEP_BUDGET_MIN = 20_000
#: ... except in the fixed-against-automatic-dt sweep, whose runs get at least this many
#: seconds' worth of steps (at the reference run's time per step).
DT_SWEEP_SECONDS = 2.0
#: Budget of one baseline run: steps and wall clock (s).
BASELINE_MAX_STEPS = 4_000_000
BASELINE_MAX_TIME = 5.0
#: ... and of the runs with other coefficients than the rule's (no curve).
BASELINE_SIDE_TIME = 2.0
#: Timed repeats stop once they took this long in all (s): long runs are timed fewer times.
REPEAT_BUDGET = 2.0
#: Viscous damping coefficients tried besides the rule's c, as multiples of it.
DAMPING_FACTORS = (0.25, 4.0)
DT_SAFETY = pinsettle.Settings().dt_safety


# --- the records of the measurements ----------------------------------------------------------


@dataclass
class BenchScene:
    name: str
    scene: pinsettle.Scene
    description: str
    urdf: Path | None = None  # for step_cost, when the model is a URDF of its own


@dataclass
class Reference:
    """The exact equilibrium q* of a scene: kinetic damping with polish=True and a tiny max_e,
    Newton-refined to round-off, checked stable (or neutral) and checked by an independent
    finite-difference Newton step."""

    q: np.ndarray
    residual: float  # relative
    stability: str
    neutral_directions: int
    min_eigenvalue: float
    fd_step: float  # size of the independent Newton step from q* (rad or m)
    steps: int  # of the kinetic-damping run that found it
    seconds_per_step: float  # of that run
    constraint_error: float = 0.0  # largest loop error of q (m), Statics.loop_error

    @property
    def step_budget(self) -> int:
        """The most steps any kinetic-damping run on the scene may take: a setting that stops
        it from converging (a large err) or a bound below round-off (a tiny max_e with the
        simplified measure) ends at that many steps, with status max_steps."""
        return max(STEP_BUDGET_MIN, STEP_BUDGET_FACTOR * self.steps)


@dataclass
class Landing:
    """Where a run comes to rest: its final pose Newton-refined to round-off (None when the run
    ended too far from any equilibrium for that), the stability there and its distance from
    the scene's reference q*."""

    q: np.ndarray | None
    stability: str
    from_reference: float  # rad or m; nan when q is None


@dataclass
class Curve:
    """The error along a run: step index, relative residual and distance of each sample."""

    steps: np.ndarray
    residual: np.ndarray
    distance: np.ndarray


def stays_below(values: np.ndarray, level: float) -> int | None:
    """Index of the first sample from which every value is <= level; None if the last is not."""
    above = np.flatnonzero(~(values <= level))
    if above.size == 0:
        return 0
    if above[-1] == values.size - 1:
        return None
    return int(above[-1]) + 1


@dataclass
class Run:
    """One method on one scene: the outcome, the timed repeats and (optionally) the curve."""

    scene: str
    method: str  # "kd", "viscous", "fire", "newton"
    label: str
    settings: dict
    status: str
    steps: int
    seconds: list[float]  # wall time of each timed repeat (s)
    residual: float  # relative, at the end
    distance: float  # from the landing pose (or the reference when none), at the end
    stability: str  # of the landing pose
    landing: Landing
    peaks: int = 0
    curve: Curve | None = None
    extra: dict = field(default_factory=dict)

    @property
    def time(self) -> float:
        return statistics.median(self.seconds)

    @property
    def per_step(self) -> float:
        return self.time / self.steps if self.steps else math.nan

    def reach(self, quantity: str, level: float) -> tuple[float, float] | None:
        """(steps, seconds) from which the residual or distance stays <= level; seconds map
        steps by the run's measured time per step."""
        if self.curve is None:
            return None
        values = getattr(self.curve, quantity)
        k = stays_below(values, level)
        if k is None:
            return None
        steps = float(self.curve.steps[k])
        return steps, steps * self.per_step


@dataclass
class Damping:
    """The two viscous baselines' coefficients: joint dampers c (every joint) and the
    mass-proportional rate c, both damping the slowest mode critically."""

    omega: float  # slowest mode (rad/s)
    joint: float  # N m s/rad (or N s/m): 2 omega / |phi|^2
    mass: float  # 1/s: 2 omega


BASELINE_LABELS = {
    "viscous": "viscous (joint dampers)",
    "mass_damping": "viscous (mass-proportional)",
    "fire": "FIRE",
}


@dataclass
class Config:
    scenes: Sequence[str]
    chain_lengths: Sequence[int]
    repeats: int  # timed repeats of the main runs
    sweep_repeats: int
    kts: Sequence[float] = KTS
    errs: Sequence[float] = ERRS
    dss: Sequence[int] = DSS
    max_es: Sequence[float] = MAX_ES
    damping_factors: Sequence[float] = DAMPING_FACTORS
    step_cost_steps: int = 20000
    step_cost_repeats: int = 11


@dataclass
class SceneData:
    bench: BenchScene
    statics: Statics
    ref: Reference
    description: str = ""
    force_scale: float = math.nan
    nv: int = 0
    loops: int = 0  # loop closures
    mobility: int = 0  # degrees of freedom (nv less the independent loop equations)
    runs: dict[str, Run] = field(default_factory=dict)  # main runs by key
    damping: Damping | None = None
    # The viscous baselines with other coefficients: (method, factor of the rule's c) -> run.
    damping_sweep: dict[tuple[str, float], Run] = field(default_factory=dict)
    sweeps: dict[str, list[Run]] = field(default_factory=dict)


@dataclass
class Results:
    config: Config
    scenes: dict[str, SceneData] = field(default_factory=dict)
    step_cost: dict[str, dict] = field(default_factory=dict)
    # benchmarks/loop_step_cost per scene with loops.
    loop_step_cost: dict[str, dict] = field(default_factory=dict)
    scaling: list[dict] = field(default_factory=list)
    machine: dict = field(default_factory=dict)
    seconds: float = 0.0

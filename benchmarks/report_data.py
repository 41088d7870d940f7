"""What the benchmark report measures and writes: its constants and the records of its
measurements. benchmarks/report.py fills them in, the report_* modules (report_writer.py says
which does what) turn them into figures and text; none of those imports report.py.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinsettle
from independent import CachedReference
from scene_statics import Statics

#: The report's sections (``report.py --sections``), in the report's order.
SECTIONS = ("scenes", "cost", "overhead", "scaling", "gallery", "contact")

#: A record as the C++ programs print it (JSON) or a measurement gathers it: settings, a
#: profile, a gallery row.
Record = dict[str, Any]
#: Residual levels of the summary, relative to the scene's force scale.
RESIDUAL_LEVELS = (1e-6, 1e-10)
#: Distance levels (rad or m) of the energy-measure comparison.
DISTANCE_LEVELS = (1e-3, 1e-6, 1e-9)
KTS = (0.0, 0.25, 0.5, 0.75, 0.9)
ERRS = (0.0, 1e-12, 1e-8, 1e-4, 1e-2)
DSS = (10, 30, 100, 300, 1000)
MAX_ES = (1e-4, 1e-6, 1e-8, 1e-12, 1e-16, 1e-20)
#: Chain lengths of the scaling section, and the longest that also gets a run to round-off
#: (its curve) and the whole step-cost table.
CHAIN_LENGTHS = (5, 10, 20, 50, 100, 200, 300, 400, 1000)
DEEP_CHAIN_MAX = 200
#: Wall-clock budget of one solve of the scaling section (s): the 1,000-link chain is not run
#: to its end.
SCALING_MAX_TIME = 150.0
#: The bound of the stopping rule in the runs whose curves are plotted: far below every level,
#: so that the curve shows how the error falls, down to round-off.
DEEP_MAX_E = 1e-26
#: The settings of those runs: the damping's own run down to round-off (Newton's takeover at a
#: damping event, on by default, would end it where the default run ends).
DEEP = {"max_e": DEEP_MAX_E, "newton_takeover": False}
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
#: Timed solves per method and round of the interleaved timing (fewer once they took half a
#: second).
INTERLEAVE_REPEATS = 7
# pinsettle's solves of a gallery robot take well under a millisecond to a few: a median of 3,
# timed from Python, was moved 2-3x by one slow call (ur3 160 us in one run, 438 in the next).
GALLERY_KD_REPEATS = 21
DT_SAFETY = pinsettle.Settings().effective_dt_safety

# --- the baselines: their rules and the sweeps of their own parameters ----------------------

#: The damped baselines, by the key of their runs; each also runs as "<key>_n", finished by the
#: solver's own Newton (its guarded takeover and polish, as the default solve), and "newton_tr" is
#: Newton's method from the start with a trust region on the potential energy.
DAMPED_LABELS = {
    "viscous": "viscous (joint dampers)",
    "mass_damping": "viscous (mass-proportional)",
    "adr": "adaptive DR",
    "fire": "FIRE",
    "fire2": "FIRE 2.0",
}
NEWTON_SUFFIX = "_n"
NEWTON_TR = "newton_tr"
BASELINE_LABELS = {
    **DAMPED_LABELS,
    **{f"{k}{NEWTON_SUFFIX}": f"{v} + Newton" for k, v in DAMPED_LABELS.items()},
    NEWTON_TR: "Newton, trust region",
}
BASELINES = tuple(BASELINE_LABELS)


def baseline_method(family: str) -> tuple[str, bool]:
    """The C++ method of a baseline family (benchmarks/baselines.cpp) and whether the solver's
    Newton finishes it."""
    if family == NEWTON_TR:
        return "newton", False
    if family.endswith(NEWTON_SUFFIX):
        return family[: -len(NEWTON_SUFFIX)], True
    return family, False


#: Each baseline's rule setting: the viscous ones at KD's own step safety and the c that damps
#: the softest mode at the start critically; FIRE and FIRE 2.0 with dt_max twice the stability
#: limit (dt0 = dt_max / 10, the classic ratio), mixing in joint coordinates; Newton from a
#: first radius of 0.1 rad (the solver's takeover reach).
_DAMPED_RULES: dict[str, Record] = {
    "viscous": {"dt_safety": DT_SAFETY, "damping_factor": 1.0},
    "mass_damping": {"dt_safety": DT_SAFETY, "damping_factor": 1.0},
    "adr": {"dt_safety": DT_SAFETY, "damping_factor": 1.0},
    "fire": {"dt_max": 2.0, "metric": "euclid"},
    "fire2": {"dt_max": 2.0, "metric": "euclid"},
}
BASELINE_RULES: dict[str, Record] = {
    family: dict(_DAMPED_RULES[baseline_method(family)[0]])
    if family != NEWTON_TR
    else {"radius": 0.1}
    for family in BASELINES
}
#: The sweeps' first grids: step safety and c (as a multiple of the rule's) of the viscous
#: baselines; FIRE's dt_max (a multiple of the stability limit) and the metric of its velocity
#: mixing; Newton's first radius (rad or m). A best on an edge of what was tried extends the grid
#: past it (SWEEP_EXTENSIONS), until the best lies inside or the runs past it fail.
VISCOUS_SAFETIES = tuple(sorted({0.2, DT_SAFETY, 0.5, 0.8, 0.9}))  # the rule among them
DAMPING_FACTORS = (0.0625, 0.25, 1.0, 4.0)
FIRE_DT_MAXES = (0.5, 1.0, 1.5, 2.0)
FIRE_METRICS = ("euclid", "mass")
NEWTON_RADII = (0.01, 0.1, 1.0)
#: How a grid grows past an edge: the next value above the largest (x up) or below the smallest
#: (x down), per numeric setting; at most this many extensions per setting.
SWEEP_GROWTH = {
    "dt_safety": (1.25, 0.5),
    "damping_factor": (4.0, 0.25),
    "dt_max": (2.0, 0.5),
    "radius": (10.0, 0.1),
}
SWEEP_EXTENSIONS = 4
#: Budget of one sweep run (s); it stops at the residual LEVEL.
SWEEP_MAX_TIME = 2.0
#: Scenes reported apart from the baselines' comparison: a test of KD's stiff-mode scaling,
#: which the baselines do not have.
APART = ("stiff_spring",)

# --- the robot gallery and MuJoCo ------------------------------------------------------------

#: MuJoCo's damped settle as its users run it: joint damping (N m s/rad or N s/m on every
#: degree of freedom) and time step (s).
MUJOCO_DAMPING = 1.0
MUJOCO_TIMESTEP = 1e-3
#: MuJoCo has settled once max |qvel| <= MUJOCO_QVEL and max |qacc| <= MUJOCO_QACC at every
#: check (every MUJOCO_CHUNK steps) for MUJOCO_QUIET seconds of simulated time in a row.
MUJOCO_QVEL = 1e-4
MUJOCO_QACC = 1e-3
MUJOCO_QUIET = 0.5
MUJOCO_CHUNK = 10
#: Simulated-time budget of MuJoCo's settle (s).
MUJOCO_MAX_SIM = 600.0
#: KD's budget on a gallery robot (s of wall clock).
GALLERY_MAX_TIME = 60.0


# --- the records of the measurements ----------------------------------------------------------


@dataclass
class BenchScene:
    name: str
    scene: pinsettle.Scene
    description: str
    reference: CachedReference  # the same scene written independently (tests/scene_reference)
    urdf: Path | None = None  # for step_cost, when the model is a URDF of its own


@dataclass
class Reference:
    """The exact equilibrium q* of a scene: kinetic damping with polish=True and a tiny max_e,
    refined to round-off by Newton's method on the independent physics
    (benchmarks/independent.py), its stability from the eigenvalues of that physics'
    finite-difference stiffness, and checked by one more such Newton step."""

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
    settings: Record
    status: str
    steps: int
    seconds: list[float]  # wall time of each timed repeat (s)
    residual: float  # relative, at the end
    distance: float  # from the landing pose (or the reference when none), at the end
    stability: str  # of the landing pose
    landing: Landing
    peaks: int = 0
    curve: Curve | None = None
    extra: Record = field(default_factory=dict)
    #: Set-up (s, median) before the first step, part of ``seconds``: charged in full to the
    #: time to a level (0: unknown, spread over the steps).
    setup: float = 0.0

    @property
    def time(self) -> float:
        return statistics.median(self.seconds)

    @property
    def per_step(self) -> float:
        """Time per step (s) after the set-up: (time - setup) / steps."""
        return (self.time - self.setup) / self.steps if self.steps else math.nan

    def reach(self, quantity: str, level: float) -> tuple[float, float] | None:
        """(steps, seconds) from which the residual or distance stays <= level; seconds are
        the set-up plus the steps at the run's measured time per step."""
        if self.curve is None:
            return None
        values = getattr(self.curve, quantity)
        k = stays_below(values, level)
        if k is None:
            return None
        steps = float(self.curve.steps[k])
        return steps, self.setup + steps * self.per_step


@dataclass
class SweepPoint:
    """One baseline run of a sweep, stopped at the residual LEVEL (or its budget)."""

    settings: Record
    status: str
    steps: int
    seconds: float  # set-up and loop, median of the repeats (s)
    setup: float  # s
    halvings: int
    retries: list[str]
    resets: int
    dt: float  # the (initial) step used (s)

    @property
    def time_to(self) -> float | None:
        return self.seconds if self.status == "converged" else None


def setting_label(family: str, settings: Record) -> str:
    if family == NEWTON_TR:
        return f"radius {settings['radius']:g}"
    if baseline_method(family)[0] in ("fire", "fire2"):
        return f"dt_max {settings['dt_max']:g} x limit, {settings['metric']}"
    return f"safety {settings['dt_safety']:g}, {settings['damping_factor']:g} c"


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
    safeties: Sequence[float] = VISCOUS_SAFETIES
    damping_factors: Sequence[float] = DAMPING_FACTORS
    fire_dt_maxes: Sequence[float] = FIRE_DT_MAXES
    fire_metrics: Sequence[str] = FIRE_METRICS
    newton_radii: Sequence[float] = NEWTON_RADII
    #: Rounds of the interleaved timing of every method's best (spread over the rounds).
    interleave_rounds: int = 3
    #: Extensions of a sweep's grid past an edge, per setting and direction.
    sweep_extensions: int = SWEEP_EXTENSIONS
    step_cost_steps: int = 20000
    step_cost_repeats: int = 11
    #: Models of the step cost (robots of example-robot-data or robots/*.urdf by name).
    cost_models: Sequence[str] = ("ur5", "panda", "pendulum", "chain20")
    #: Scenes of the overhead split (goal 4 of issue 20).
    overhead_scenes: Sequence[str] = ("ur5", "chain20", "chain100")
    scaling_max_time: float = SCALING_MAX_TIME
    deep_chain_max: int = DEEP_CHAIN_MAX
    #: Robots of the gallery (None: every robot pinsettle lists).
    robots: Sequence[str] | None = None
    mujoco_max_sim: float = MUJOCO_MAX_SIM
    gallery_repeats: int = 3
    #: The contact part's small sweep (benchmarks/contact_drop.py's QUICK) instead of its full.
    contact_quick: bool = False

    def sweep(self, family: str) -> list[Record]:
        """The first grid a baseline is swept on (the rule included)."""
        if family == NEWTON_TR:
            return [{"radius": r} for r in self.newton_radii]
        if baseline_method(family)[0] in ("fire", "fire2"):
            return [
                {"dt_max": m, "metric": g} for g in self.fire_metrics for m in self.fire_dt_maxes
            ]
        return [
            {"dt_safety": s, "damping_factor": f}
            for f in self.damping_factors
            for s in self.safeties
        ]


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
    # The baselines' sweeps of their own parameters: family -> runs to the residual LEVEL.
    baseline_sweep: dict[str, list[SweepPoint]] = field(default_factory=dict)
    # Every method's best timed again in interleaved rounds: key (kd_default or a baseline
    # family) -> each round's median time (s; NaN where it did not converge).
    interleaved: dict[str, list[float]] = field(default_factory=dict)
    sweeps: dict[str, list[Run]] = field(default_factory=dict)
    # benchmarks/kd_profile on the scene (trees): the solver's set-up and overheads.
    profile: Record | None = None
    apart: bool = False  # reported apart from the baselines' comparison (APART)
    bench_name: str = ""  # its name in the report (set by the writer)


@dataclass
class Results:
    config: Config
    scenes: dict[str, SceneData] = field(default_factory=dict)
    step_cost: dict[str, Record] = field(default_factory=dict)
    # benchmarks/loop_step_cost per scene with loops.
    loop_step_cost: dict[str, Record] = field(default_factory=dict)
    scaling: list[Record] = field(default_factory=list)
    # benchmarks/kd_profile on the overhead scenes (goal 4 of issue 20).
    overhead: dict[str, Record] = field(default_factory=dict)
    # The robot gallery: one record per robot, root fixed; and the floating-base robots.
    gallery: list[Record] = field(default_factory=list)
    floating: list[Record] = field(default_factory=list)
    mujoco: Record = field(default_factory=dict)  # version, or why it is not there
    # The contact part (benchmarks/contact_drop.py's measure): go1 on a floor against MuJoCo.
    contact: Record = field(default_factory=dict)
    machine: Record = field(default_factory=dict)
    seconds: float = 0.0
    sections: Sequence[str] = ()  # the sections measured in this run
    section_seconds: dict[str, float] = field(default_factory=dict)

"""An outside check of docs/benchmarks.md's "MuJoCo at its best, per robot" (written by
benchmarks/mujoco_best.py): a search of its own for MuJoCo's fastest settle of each robot, which
shares nothing with that script but the gallery's model loading and rest judge, and then times the
section's recorded best against its own, interleaved, in one process.

- The robots: those whose row in the section has a best setting (not "no valid rest reached");
  the section's setting, level and step count are read from its table.
- The model: the gallery's stripped URDF in MuJoCo (``gallery.load_mujoco``; root fixed, its
  limits kept, from qpos = 0), its timestep, integrator, damping and constraint solver
  tolerance (``opt.tolerance``) set by the setting: damping either the same c on every degree of
  freedom (kind "uniform") or c_i = a M_ii(q0) (kind "mass"; M from ``mj_fullM`` at the start).
  A setting printed without a tolerance is at MuJoCo's default, 1e-8.
- The residual (the same rule as the section's, written anew): qpos with qvel = 0,
  ``mj_forward`` (its constraint solve to convergence: solver tolerance 0), r = max |M qacc|
  (``mj_mulM``) over the force scale max |qfrc_bias| at qpos0 with qvel = 0 (1 if 0). It is
  checked after EVERY step, so a run's step count is exact: the first step where r <= the level
  (1e-10, or the section's level for that robot if looser). A run diverges when qpos or qvel is
  not finite or MuJoCo counts a bad qacc, qvel or qpos (``data.warning``); it stops at MAX_STEPS
  steps, at RUN_WALL s of wall time, or, once a valid best of S steps is known, at CUT * S steps
  (such a run can no longer be the fastest).
- A valid rest: ``gallery.rest_check`` of the configuration where the level is reached: at most
  OUTSIDE_TOL beyond a limit and not unstable (the section's acceptance).
- The search, per robot, BUDGET runs at most (``--budget``): the parameters are x = (log
  timestep, log damping value, log solver tolerance) for each of the six families (integrator
  Euler, implicitfast, implicit) x (kind uniform, mass), over the timestep range TIMESTEP_RANGE,
  the damping ranges DAMPING_RANGES and the tolerance range TOLERANCE_RANGE (on a soft limit a
  step solves the constraint forces only to the solver's tolerance, and at MuJoCo's default,
  1e-8, the residual may never settle below 1e-10; where no limit is touched it plays no
  part). A seeded scrambled Halton sample in three dimensions (SAMPLE_SHARE of the budget,
  spread evenly over the families, each family its own sequence; the budget raised from 250 to
  300 for the third dimension), then scipy's bounded Nelder-Mead from the best
  sample of each family, the best families first (the first STARTS share the rest of the
  budget); the TRANSFER best settings are then tried with the other integrators, and Nelder-Mead
  restarts from the best point found (the nearest miss if none is valid) with a halved simplex
  while the budget lasts and the restarts improve. Objective: the steps to the level at a valid
  rest times the integrator's cost of a step relative to Euler's (timed once per robot, at the
  default tolerance: the tolerance's own cost shows in the finalists' timing); a run
  that does not reach it costs MAX_STEPS times 1 to 2 (more the further its last residual is from
  the level), one at an invalid rest 2 to 3 (more the further beyond a limit), one that diverges
  3 to 4 (more the sooner).
- The outside best: of the valid runs, the FINALISTS with the fewest weighted steps and the
  fewest-step run of each integrator, each timed (median of TIME_REPEATS); the fastest.
- The comparison: a setting's time is the wall time of ``mj_step(model, data, nstep=steps)``
  from a fresh reset (no checks), after one run not counted, median of TIME_REPEATS runs or
  more for a short run (TIME_SPAN of runs, at most TIME_MAX_REPEATS); the section's best (its
  setting and step count as printed) and the outside best are timed alternately for ROUNDS
  rounds, and the medians over the rounds compared: ratio = section / outside, agreement when
  ratio <= AGREE and the section's setting replays: run again from the start, checked at every
  step, it must reach its level at a valid rest within its step count.

    cd benchmarks && python mujoco_outside.py [--robots ur5,panda] [--budget 250] [--write]

``--write`` puts the section (a delimited block) into docs/benchmarks.md right after the
section it checks.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import math
import re
import statistics
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import mujoco
import numpy as np
import pinocchio
import pinsettle
from gallery import load_mujoco, mujoco_q, rest_check
from independent import CachedReference
from scipy.optimize import minimize
from scipy.stats import qmc

DOC = Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md"
BEGIN = "<!-- mujoco:outside (written by benchmarks/mujoco_outside.py) -->"
END = "<!-- /mujoco:outside -->"
AFTER = "<!-- /mujoco:best -->"
CHECKED_BEGIN = "<!-- mujoco:best"  # the section checked, read only

LEVEL = 1e-10
INTEGRATORS = ("Euler", "implicitfast", "implicit")
KINDS = ("uniform", "mass")
Family = tuple[str, str]  # (integrator, kind)
FAMILIES = tuple((integrator, kind) for integrator in INTEGRATORS for kind in KINDS)
TIMESTEP_RANGE = (2e-4, 10.0)  # s
TOLERANCE_RANGE = (1e-12, 1e-6)  # MuJoCo's constraint solver tolerance, opt.tolerance
MUJOCO_TOLERANCE = 1e-8  # MuJoCo's default, for a setting printed without one
DAMPING_RANGES = {"uniform": (1e-3, 1e3), "mass": (1e-2, 1e3)}  # N m s/rad (or N s/m); 1/s
BUDGET = 300  # runs per robot (250 before the tolerance became a third parameter)
SAMPLE_SHARE = 0.4  # of the budget, for the quasi-random sample
STARTS = 4  # Nelder-Mead starts sharing the rest of the budget
SIMPLEX = math.log(2.0)  # the initial simplex's edge, in log units
MAX_STEPS = 20_000
RUN_WALL = 1.0  # s of wall time per run (checks included): a safety net
CUT = 5  # a run stops at CUT times the best valid step count so far
TRANSFER = 3  # the best valid settings tried with the other integrators
WEIGHT_STEPS = 500  # steps timed for each integrator's cost of a step
OUTSIDE_TOL = 1e-2  # rad or m beyond a limit: the section's acceptance
FINALISTS = 3
TIME_REPEATS = 5
TIME_SPAN = 5e-3  # s of runs timed at least, for a short run
TIME_MAX_REPEATS = 201
ROUNDS = 3
AGREE = 1.5
SEED = 20261128
BAD = ("mjWARN_BADQACC", "mjWARN_BADQVEL", "mjWARN_BADQPOS")
NUMBER = r"[0-9]+(?:\.[0-9]*)?(?:[eE][+-]?[0-9]+)?"
SETTING_FORM = re.compile(
    rf"^(?P<ms>{NUMBER}) ms, (?P<integrator>{'|'.join(INTEGRATORS)}), "
    rf"(?:c = (?P<c>{NUMBER})|a = (?P<a>{NUMBER})/s)(?:, tol (?P<tol>{NUMBER}))?$"
)


class Setting(NamedTuple):
    timestep: float  # s
    integrator: str
    kind: str  # "uniform" or "mass"
    value: float  # c (uniform) or a (mass, 1/s)
    tolerance: float = MUJOCO_TOLERANCE  # the constraint solver's, opt.tolerance

    def label(self) -> str:
        damping = f"c = {self.value:.6g}" if self.kind == "uniform" else f"a = {self.value:.6g}/s"
        return (
            f"{self.timestep * 1e3:.6g} ms, {self.integrator}, {damping}, tol {self.tolerance:.3g}"
        )


class Recorded(NamedTuple):
    """A row of the section checked: its best setting, level, step count and time."""

    robot: str
    setting: Setting
    level: float
    steps: int
    ms: float


class Run(NamedTuple):
    status: str  # reached, invalid, diverged, budget, wall, cut
    steps: int
    residual: float
    qpos: np.ndarray | None  # where the level was reached
    outside: float = 0.0  # how far that rest is beyond a limit (rad or m)


# --- the section checked ----------------------------------------------------------------------


def parse_setting(text: str) -> Setting:
    """A setting as the section prints it: '458.502 ms, Euler, a = 2.12132/s, tol 1e-10' (mass
    kind) or '1 ms, Euler, c = 0.1, tol 1e-08' (uniform kind); without ', tol ...' the solver
    tolerance is MuJoCo's default (1e-8)."""
    match = SETTING_FORM.match(text.strip())
    if match is None:
        raise ValueError(
            f"not a MuJoCo setting: {text!r} (expected '<timestep> ms, <integrator>, c = <c>' "
            f"or '... a = <a>/s', then optionally ', tol <tolerance>', the integrator one of "
            f"{', '.join(INTEGRATORS)})"
        )
    timestep = float(match["ms"]) * 1e-3
    kind, value = ("uniform", match["c"]) if match["c"] is not None else ("mass", match["a"])
    tolerance = MUJOCO_TOLERANCE if match["tol"] is None else float(match["tol"])
    if timestep <= 0 or float(value) <= 0:
        raise ValueError(f"not a MuJoCo setting: {text!r} (timestep and damping must be > 0)")
    return Setting(timestep, match["integrator"], kind, float(value), tolerance)


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def checked_table(text: str) -> list[str]:
    """The table lines (header first) of the section checked in the document's text."""
    if CHECKED_BEGIN not in text or AFTER not in text:
        raise ValueError(f"no section {CHECKED_BEGIN} ... {AFTER} in the document")
    block = text.split(CHECKED_BEGIN, 1)[1].split(AFTER, 1)[0]
    lines = block.splitlines()
    head = next((k for k, line in enumerate(lines) if line.startswith("| robot |")), None)
    if head is None:
        raise ValueError("the section has no table starting '| robot |'")
    table = [lines[head]]
    for line in lines[head + 2 :]:
        if not line.startswith("|"):
            break
        table.append(line)
    return table


def parse_section(text: str) -> list[Recorded]:
    """The rows of the section with a best setting (the others say 'no valid rest reached')."""
    table = checked_table(text)
    header = _cells(table[0])
    wanted = ("robot", "MuJoCo best setting", "level", "steps", "MuJoCo (ms)")
    missing = [name for name in wanted if name not in header]
    if missing:
        raise ValueError(f"the section's table has no column {', '.join(missing)}")
    col = {name: header.index(name) for name in wanted}
    rows = []
    for line in table[1:]:
        cells = _cells(line)
        if cells[col["MuJoCo best setting"]].startswith("no valid rest"):
            continue
        rows.append(
            Recorded(
                robot=cells[col["robot"]],
                setting=parse_setting(cells[col["MuJoCo best setting"]]),
                level=float(cells[col["level"]]),
                steps=int(cells[col["steps"]]),
                ms=float(cells[col["MuJoCo (ms)"]].split("±")[0]),  # "0.364 ± 21%"
            )
        )
    return rows


# --- MuJoCo -----------------------------------------------------------------------------------


def mass_diagonal(m: Any) -> np.ndarray:
    """diag M(qpos0), from mj_fullM."""
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    return np.array(np.diag(full))


def force_scale(m: Any) -> float:
    """max |qfrc_bias| at qpos0 with qvel = 0 (1 if 0)."""
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    scale = float(np.max(np.abs(d.qfrc_bias), initial=0.0))
    return scale if scale > 0 else 1.0


def static_residual(
    m: Any, scratch: Any, qpos: np.ndarray, scale: float, force: np.ndarray | None = None
) -> float:
    """max |M qacc| at qpos with qvel = 0 (the net generalized force at rest there, the limits'
    constraint forces included), over ``scale``. ``scratch`` is an MjData of ``m``. The
    constraint solve runs to convergence for the check (solver tolerance 0): at the default
    1e-8 it may stop before its first iteration and read qacc = 0 exactly on a limit."""
    scratch.qpos[:] = qpos
    scratch.qvel[:] = 0.0
    opt = m.opt
    kept = opt.tolerance, opt.ls_tolerance, opt.iterations
    opt.tolerance, opt.ls_tolerance, opt.iterations = 0.0, 1e-12, 100
    try:
        mujoco.mj_forward(m, scratch)
    finally:
        opt.tolerance, opt.ls_tolerance, opt.iterations = kept
    out = np.zeros(m.nv) if force is None else force
    mujoco.mj_mulM(m, scratch, out, scratch.qacc)
    return max(map(abs, out.tolist()), default=0.0) / scale


def integrator_of(name: str) -> Any:
    return getattr(mujoco.mjtIntegrator, f"mjINT_{name.upper()}")


class Bench:
    """A robot's MuJoCo model (the gallery's), with what a setting and the residual need."""

    def __init__(self, urdf: Path) -> None:
        loaded, why, _ = load_mujoco(urdf)
        if loaded is None:
            raise RuntimeError(f"MuJoCo cannot load {urdf}: {why}")
        model: Any = loaded
        self.model = model
        self.diag = mass_diagonal(model)
        self.scale = force_scale(model)
        self.scratch = mujoco.MjData(model)
        self.force = np.zeros(model.nv)
        self.bad = [int(getattr(mujoco.mjtWarning, name)) for name in BAD]

    def configure(self, setting: Setting) -> None:
        m = self.model
        m.opt.timestep = setting.timestep
        m.opt.integrator = integrator_of(setting.integrator)
        m.opt.tolerance = setting.tolerance
        m.dof_damping[:] = setting.value if setting.kind == "uniform" else setting.value * self.diag

    def residual(self, qpos: np.ndarray) -> float:
        return static_residual(self.model, self.scratch, qpos, self.scale, self.force)

    def diverged(self, d: Any) -> bool:
        if any(d.warning[k].number > 0 for k in self.bad):
            return True
        return not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all())


def settle(bench: Bench, setting: Setting, level: float, cap: int = MAX_STEPS) -> Run:
    """One run from the start, the residual checked after every step, to the first step at
    ``level`` (status 'reached'), or divergence, or ``cap`` steps ('budget' at MAX_STEPS, else
    'cut'), or RUN_WALL s of wall time."""
    bench.configure(setting)
    m = bench.model
    d = mujoco.MjData(m)
    residual = math.inf
    deadline = time.perf_counter() + RUN_WALL
    with warnings_off_the_log():  # a setting of the search may diverge: d.warning counts it
        for step in range(1, cap + 1):
            mujoco.mj_step(m, d)
            if bench.diverged(d):
                return Run("diverged", step, math.inf, None)
            residual = bench.residual(d.qpos)
            if residual <= level:
                return Run("reached", step, residual, d.qpos.copy())
            if time.perf_counter() > deadline:
                return Run("wall", step, residual, None)
    return Run("budget" if cap >= MAX_STEPS else "cut", cap, residual, None)


def replay(bench: Bench, setting: Setting, steps: int, level: float) -> dict[str, Any]:
    """The setting from the start for ``steps`` steps, checked after every one: the first step
    at ``level`` (None if none), and the residual and configuration at the end."""
    bench.configure(setting)
    d = mujoco.MjData(bench.model)
    first = None
    for step in range(1, steps + 1):
        mujoco.mj_step(bench.model, d)
        if first is None and bench.residual(d.qpos) <= level:
            first = step
    return {"first": first, "end": bench.residual(d.qpos), "qpos": d.qpos.copy()}


def time_once(m: Any, d: Any, steps: int) -> float:
    mujoco.mj_resetData(m, d)
    began = time.perf_counter()
    mujoco.mj_step(m, d, nstep=steps)
    return time.perf_counter() - began


def timed(bench: Bench, setting: Setting, steps: int, repeats: int = TIME_REPEATS) -> float:
    """Median wall time (s) of ``steps`` steps from a fresh reset in one mj_step call, after one
    run not counted; at least ``repeats`` runs, more for a short run (TIME_SPAN of runs, at most
    TIME_MAX_REPEATS): five runs of one step (3 us) on a fresh MjData read the same setting 1.5
    times apart."""
    bench.configure(setting)
    d = mujoco.MjData(bench.model)
    once = time_once(bench.model, d, steps)
    count = min(max(repeats, math.ceil(TIME_SPAN / max(once, 1e-9))), TIME_MAX_REPEATS)
    return statistics.median(time_once(bench.model, d, steps) for _ in range(count))


# --- the rest judge ---------------------------------------------------------------------------


class Judge:
    """The gallery's independent rest check, on Pinocchio's model of the same URDF."""

    def __init__(self, urdf: Path) -> None:
        self.ref = CachedReference(pinocchio.buildModelFromUrdf(str(urdf)))

    def check(self, bench: Bench, qpos: np.ndarray) -> dict[str, Any]:
        return rest_check(self.ref, mujoco_q(bench.model, qpos, self.ref.full))

    def valid(self, bench: Bench, qpos: np.ndarray) -> bool:
        return acceptable(self.check(bench, qpos))


def acceptable(check: dict[str, Any]) -> bool:
    """The section's acceptance of a rest: at most OUTSIDE_TOL beyond a limit, not unstable."""
    return bool(check["outside"] <= OUTSIDE_TOL and check["stability"] != "unstable")


# --- the search -------------------------------------------------------------------------------


class Exhausted(Exception):
    """The run budget is spent."""


def bounds(kind: str) -> list[tuple[float, float]]:
    low, high = DAMPING_RANGES[kind]
    return [
        (math.log(TIMESTEP_RANGE[0]), math.log(TIMESTEP_RANGE[1])),
        (math.log(low), math.log(high)),
        (math.log(TOLERANCE_RANGE[0]), math.log(TOLERANCE_RANGE[1])),
    ]


def setting_at(family: Family, x: np.ndarray) -> Setting:
    """The setting at x = (log timestep, log damping, log tolerance), clipped to the bounds."""
    timestep, value, tolerance = (
        math.exp(min(max(float(v), low), high))
        for v, (low, high) in zip(x, bounds(family[1]), strict=True)
    )
    return Setting(timestep, family[0], family[1], value, tolerance)


def cost(run: Run, level: float) -> float:
    """The objective of a run: its steps if it reached the level at a valid rest, else a
    penalty above MAX_STEPS, graded so that a local search can tell the better failures: one
    that stops short costs MAX_STEPS times 1 to 2 (by the decades its last residual is above
    the level), one at an invalid rest 2 to 3 (by how far it is beyond a limit), one that
    diverges 3 to 4 (the sooner, the more)."""
    if run.status == "reached":
        return float(run.steps)
    if run.status == "invalid":
        return MAX_STEPS * (2.0 + min(math.log10(1.0 + run.outside / OUTSIDE_TOL), 1.0))
    if run.status == "diverged":
        return MAX_STEPS * (4.0 - math.log(max(run.steps, 1)) / math.log(MAX_STEPS))
    decades = math.log10(run.residual / level) if math.isfinite(run.residual) else 20.0
    return MAX_STEPS * (1.0 + min(max(decades, 0.0), 20.0) / 20.0)


@dataclass
class Search:
    """The runs of one robot's search, cached, within a budget."""

    bench: Bench
    judge: Judge
    level: float
    budget: int
    weights: dict[str, float] = field(default_factory=lambda: dict.fromkeys(INTEGRATORS, 1.0))
    runs: list[tuple[Setting, Run]] = field(default_factory=list)
    cache: dict[Setting, float] = field(default_factory=dict)

    def best_steps(self) -> int | None:
        steps = [run.steps for _, run in self.runs if run.status == "reached"]
        return min(steps) if steps else None

    def weighted(self, setting: Setting, run: Run) -> float:
        """A valid run's steps times its integrator's cost of a step (Euler's = 1)."""
        return run.steps * self.weights[setting.integrator]

    def evaluate(self, setting: Setting) -> float:
        if setting in self.cache:
            return self.cache[setting]
        if len(self.runs) >= self.budget:
            raise Exhausted
        best = self.best_steps()
        cap = MAX_STEPS if best is None else min(MAX_STEPS, CUT * best)
        run = settle(self.bench, setting, self.level, cap)
        if run.qpos is not None:
            check = self.judge.check(self.bench, run.qpos)
            if not acceptable(check):
                run = run._replace(status="invalid", outside=float(check["outside"]))
        self.runs.append((setting, run))
        value = cost(run, self.level)
        self.cache[setting] = self.weighted(setting, run) if run.status == "reached" else value
        return self.cache[setting]

    def remaining(self) -> int:
        return self.budget - len(self.runs)


def sample(search: Search, per_family: int, seed: int) -> dict[Family, tuple[float, Setting]]:
    """A scrambled Halton sample of the parameters (log-uniform over the ranges) for every
    family, each its own (seeded in turn), the families taken in turn; the best of each."""
    units = [
        qmc.Halton(d=3, scramble=True, seed=seed + 7919 * k).random(per_family)
        for k in range(len(FAMILIES))
    ]
    best: dict[Family, tuple[float, Setting]] = {}
    for i in range(per_family):
        for family, unit in zip(FAMILIES, units, strict=True):
            low, high = np.array(bounds(family[1])).T
            setting = setting_at(family, low + unit[i] * (high - low))
            value = search.evaluate(setting)
            if family not in best or value < best[family][0]:
                best[family] = (value, setting)
    return best


def simplex(x0: np.ndarray, kind: str, edge: float) -> np.ndarray:
    """x0 and a step of ``edge`` along each axis, towards the inside of the bounds."""
    points = [x0]
    for axis, (low, high) in enumerate(bounds(kind)):
        x = x0.copy()
        x[axis] = x0[axis] + edge if x0[axis] + edge <= high else x0[axis] - edge
        x[axis] = max(x[axis], low)
        points.append(x)
    return np.array(points)


def polish(search: Search, start: Setting, maxfev: int, edge: float = SIMPLEX) -> None:
    """Bounded Nelder-Mead from ``start`` in its family (at most ``maxfev`` evaluations)."""
    family = (start.integrator, start.kind)
    x0 = np.array([math.log(start.timestep), math.log(start.value), math.log(start.tolerance)])
    try:
        minimize(
            lambda x: search.evaluate(setting_at(family, x)),
            x0,
            method="Nelder-Mead",
            bounds=bounds(start.kind),
            options={
                "maxfev": max(maxfev, 3),
                "initial_simplex": simplex(x0, start.kind, edge),
                "xatol": 0.01,
                "fatol": 0.5,
            },
        )
    except Exhausted:
        pass


def best_valid(search: Search) -> tuple[Setting, Run] | None:
    """The valid run with the fewest steps weighted by the integrators' costs of a step."""
    reached = [(s, r) for s, r in search.runs if r.status == "reached"]
    return min(reached, key=lambda x: search.weighted(*x)) if reached else None


def transfer(search: Search, count: int = TRANSFER) -> None:
    """The ``count`` best valid settings again with each other integrator (the same timestep
    and damping): a family's optimum can be another's too, and its steps cheaper there."""
    reached = sorted(
        ((s, r) for s, r in search.runs if r.status == "reached"),
        key=lambda x: search.weighted(*x),
    )
    for setting, _ in reached[:count]:
        for integrator in INTEGRATORS:
            search.evaluate(setting._replace(integrator=integrator))


def local(search: Search, starts: list[Setting]) -> None:
    """Nelder-Mead from each start, the first STARTS sharing the budget left; the best
    settings tried with the other integrators; then restarts from the best point (the nearest
    miss if none is valid) with a halved simplex while they improve and the budget lasts."""
    for k, start in enumerate(starts):
        if search.remaining() <= 0:
            return
        polish(search, start, (search.remaining() - TRANSFER * 2) // max(STARTS - k, 1))
    try:
        transfer(search)
    except Exhausted:
        return
    edge = SIMPLEX / 2
    while search.remaining() > 0:
        best = min(search.cache, key=search.cache.__getitem__)  # valid or, if none, nearest
        before = search.cache[best]
        polish(search, best, search.remaining(), edge)
        if min(search.cache.values()) >= before:
            return
        edge /= 2


def step_costs(bench: Bench) -> dict[str, float]:
    """Each integrator's wall time of a step relative to Euler's, on a middling setting
    (WEIGHT_STEPS steps from the start, median of TIME_REPEATS, after a warm-up round)."""
    seconds: dict[str, float] = {}
    for _ in range(2):
        for integrator in INTEGRATORS:
            setting = Setting(0.01, integrator, "mass", 1.0)
            seconds[integrator] = timed(bench, setting, WEIGHT_STEPS)
    return {integrator: t / seconds["Euler"] for integrator, t in seconds.items()}


def search_robot(bench: Bench, judge: Judge, level: float, budget: int, seed: int) -> Search:
    search = Search(bench, judge, level, budget, step_costs(bench))
    per_family = max(int(budget * SAMPLE_SHARE) // len(FAMILIES), 1)
    try:
        best = sample(search, per_family, seed)
    except Exhausted:
        return search
    ranked = sorted(best.values(), key=lambda x: x[0])
    local(search, [setting for _, setting in ranked])
    return search


def finalists(search: Search) -> list[tuple[Setting, int]]:
    """The valid runs with the fewest weighted steps, and each integrator's fewest."""
    reached = sorted(
        ((s, r) for s, r in search.runs if r.status == "reached"),
        key=lambda x: search.weighted(*x),
    )
    chosen = reached[:FINALISTS]
    for integrator in INTEGRATORS:
        chosen += [x for x in reached if x[0].integrator == integrator][:1]
    return list(dict.fromkeys((s, r.steps) for s, r in chosen))


def outside_best(search: Search) -> tuple[Setting, int] | None:
    """The fastest of the finalists by a median of TIME_REPEATS."""
    timings = [(timed(search.bench, s, steps), s, steps) for s, steps in finalists(search)]
    if not timings:
        return None
    _, setting, steps = min(timings, key=lambda x: x[0])
    return setting, steps


# --- the comparison ---------------------------------------------------------------------------


def interleaved(
    first: Callable[[], float], second: Callable[[], float], rounds: int = ROUNDS
) -> tuple[float, float]:
    """Medians over ``rounds`` rounds of two timings taken alternately (which goes first
    alternates too)."""
    a: list[float] = []
    b: list[float] = []
    for k in range(rounds):
        if k % 2 == 0:
            a.append(first())
            b.append(second())
        else:
            b.append(second())
            a.append(first())
    return statistics.median(a), statistics.median(b)


def measure(recorded: Recorded, budget: int, seed: int) -> dict[str, Any]:
    """One robot, MuJoCo's warnings (bad states, counted in data.warning) kept off the log."""
    with warnings_off_the_log():
        return compare(recorded, budget, seed)


@contextlib.contextmanager
def warnings_off_the_log() -> Iterator[None]:
    """MuJoCo's warnings (a diverging setting's bad states, which ``data.warning`` counts and
    ``Bench.diverged`` reads) dropped: by default MuJoCo appends each to MUJOCO_LOG.TXT in the
    working directory, a file left in the user's folder (or the checkout, by the tests)."""
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda text: None)
    try:
        yield
    finally:
        mujoco.set_mju_user_warning(previous)


def compare(recorded: Recorded, budget: int, seed: int) -> dict[str, Any]:
    """One robot: the search, the section's setting replayed, both timed."""
    urdf = pinsettle.robot_urdf(recorded.robot)
    judge = Judge(urdf)
    mine, theirs = Bench(urdf), Bench(urdf)
    level = max(recorded.level, LEVEL)
    began = time.perf_counter()
    search = search_robot(mine, judge, level, budget, seed)
    replayed = replay(theirs, recorded.setting, recorded.steps, recorded.level)
    replayed["valid"] = judge.valid(theirs, replayed.pop("qpos"))
    row: dict[str, Any] = {
        "recorded": recorded,
        "level": level,
        "runs": len(search.runs),
        "statuses": Counter(run.status for _, run in search.runs),
        "replayed": replayed,
        "best": outside_best(search),
    }
    if row["best"] is not None:
        setting, steps = row["best"]
        row["section_s"], row["outside_s"] = interleaved(
            lambda: timed(theirs, recorded.setting, recorded.steps),
            lambda: timed(mine, setting, steps),
        )
    else:
        row["section_s"] = timed(theirs, recorded.setting, recorded.steps)
    row["seconds"] = time.perf_counter() - began
    return row


# --- the section ------------------------------------------------------------------------------


def ratio(row: dict[str, Any]) -> float | None:
    return row["section_s"] / row["outside_s"] if "outside_s" in row else None


def replays(row: dict[str, Any]) -> bool:
    """The section's setting, run again from the start, reaches its level at a valid rest
    within its steps."""
    replayed = row["replayed"]
    return replayed["first"] is not None and bool(replayed["valid"])


def agrees(row: dict[str, Any]) -> bool:
    """The section's best replays and is within AGREE times of the outside best (or the
    outside search found none)."""
    value = ratio(row)
    return replays(row) and (value is None or value <= AGREE)


def miss(row: dict[str, Any]) -> str:
    value = ratio(row)
    why = [] if value is None or value <= AGREE else [f"{value:.2f}"]
    why += [] if replays(row) else ["its setting does not replay"]
    return f"{row['recorded'].robot} ({', '.join(why)})"


def table_row(row: dict[str, Any]) -> str:
    rec: Recorded = row["recorded"]
    steps = f"{rec.steps}" if rec.level <= LEVEL else f"{rec.steps} (to {rec.level:g})"
    if row["best"] is None:
        outside, its_steps, outside_ms, r = f"none reached {row['level']:g}", "", "", ""
    else:
        outside, its_steps = row["best"][0].label(), f"{row['best'][1]}"
        outside_ms, r = f"{row['outside_s'] * 1e3:.3g}", f"{ratio(row):.2f}"
    return (
        f"| {rec.robot} | {rec.setting.label()} | {steps} | {outside} | {its_steps} | "
        f"{row['runs']} | {row['section_s'] * 1e3:.3g} | {outside_ms} | {r} | "
        f"{'yes' if agrees(row) else '**no**'} |"
    )


HEADER = (
    "| robot | section's setting | its steps | outside setting | its steps | runs made | "
    "section time (ms) | outside time (ms) | section / outside | within 1.5 |\n"
    "|---|---|---|---|---|---|---|---|---|---|"
)


def prose(budget: int) -> str:
    (t_low, t_high) = TIMESTEP_RANGE
    u_low, u_high = DAMPING_RANGES["uniform"]
    a_low, a_high = DAMPING_RANGES["mass"]
    tol_low, tol_high = TOLERANCE_RANGE
    return (
        "An independent search for MuJoCo's fastest settle of each robot that has a best above "
        "(the same model: the gallery's stripped URDF, root fixed, limits kept, from qpos = 0), "
        "sharing nothing with `mujoco_best.py` but the gallery's loading and rest check. Per "
        f"robot at most {budget} runs: over the integrators {', '.join(INTEGRATORS)} and both "
        f"damping kinds (the same c in [{u_low:g}, {u_high:g}] on every degree of freedom, or "
        f"c_i = a M_ii(q0) with a in [{a_low:g}, {a_high:g}] 1/s), the timestep in "
        f"[{t_low * 1e3:g} ms, {t_high:g} s] and MuJoCo's constraint solver tolerance "
        f"(`opt.tolerance`, 'tol' in the table) in [{tol_low:g}, {tol_high:g}] (on a soft "
        "limit a step solves the constraint forces only to it, and at MuJoCo's default, 1e-8, "
        "the residual may wander near 1e-10 and never settle below; off the limits it plays no "
        "part), a scrambled Halton sample in log scale "
        f"({SAMPLE_SHARE:.0%} of the runs), then bounded Nelder-Mead in (log timestep, log "
        "damping, log tolerance) from the best sample of each of the six families, the best "
        "settings tried "
        "with the other integrators, then restarts from the best point; the objective is the "
        "steps to the level at a valid rest weighted by the integrator's cost of a step "
        "(failures penalized, graded by how near they came). The "
        "residual, written anew to the same rule: max |M qacc| (`mj_mulM`) after `mj_forward` "
        "at qpos with qvel = 0 (its constraint solve to convergence, solver tolerance 0), over "
        "max |qfrc_bias| at the start; it is checked after every "
        f"step (so step counts are exact, not rounded up to a check every 10), runs capped at "
        f"{MAX_STEPS} steps, {RUN_WALL:g} s, or {CUT} times the fewest steps found so far; the "
        "fastest of the fewest-step finalists by timing; a valid rest is within "
        f"{OUTSIDE_TOL:g} rad or m "
        "of the limits and not unstable by the gallery's check. The level is 1e-10, or the "
        "section's for a robot whose best stops at a looser one. Timing, in one process: "
        "`mj_step(model, data, nstep)` from a fresh reset, no checks, after one run not "
        f"counted, median of {TIME_REPEATS} runs, or as many as fill {TIME_SPAN * 1e3:g} ms "
        f"(at most {TIME_MAX_REPEATS}) for a short run; the section's best (its setting and "
        f"steps as printed) and the outside best alternately, {ROUNDS} rounds, median of the "
        "rounds."
    )


def first_step(row: dict[str, Any]) -> str:
    first = row["replayed"]["first"]
    return f"none by {row['recorded'].steps}" if first is None else f"{first}"


def closing(rows: list[dict[str, Any]]) -> list[str]:
    misses = [row for row in rows if not agrees(row)]
    named = "; ".join(miss(row) for row in misses)
    lines = [
        f"The section's best replays and is within {AGREE:g} times of the outside best on "
        f"{len(rows) - len(misses)} of {len(rows)} robots"
        + (f"; not on {named}." if misses else ".")
    ]
    none = [row["recorded"].robot for row in rows if row["best"] is None]
    if none:
        lines.append(
            f"The outside search reached no valid rest on: {', '.join(none)}; there the "
            "agreement is the section's replay alone (no faster setting was found, nor any "
            "to compare with)."
        )
    bad = [row for row in rows if not replays(row)]
    firsts = ", ".join(f"{row['recorded'].robot} {first_step(row)}" for row in rows)
    if bad:
        names = ", ".join(row["recorded"].robot for row in bad)
        lines.append(
            f"Run again from the start, the section's setting does NOT reach its level "
            f"at a valid rest within its steps on: {names}."
        )
    lines.append(
        "Run again from the start with a check after every step, the section's setting first "
        f"reaches its level at step: {firsts}."
    )
    return lines


def section(rows: list[dict[str, Any]], seconds: float, budget: int) -> str:
    date = datetime.date.today().isoformat()
    body = [
        BEGIN,
        "### An outside check of MuJoCo's best",
        "",
        f"*Measured on {date} by `benchmarks/mujoco_outside.py` (MuJoCo {mujoco.__version__}) "
        f"in {seconds / 60:.1f} min.*",
        "",
        prose(budget),
        "",
        HEADER,
        *[table_row(row) for row in rows],
        "",
    ]
    for line in closing(rows):
        body += [line, ""]
    return "\n".join(body[:-1] + [END]) + "\n"


def put_block(text: str, path: Path = DOC) -> None:
    """The block in place of the old one, or right after the section checked; the rest of the
    file kept byte for byte."""
    old = path.read_text(encoding="utf-8")
    block = text.rstrip("\n")
    if BEGIN in old:
        head, rest = old.split(BEGIN, 1)
        if END not in rest:
            raise ValueError(f"{path}: {BEGIN} without {END}")
        new = head + block + rest.split(END, 1)[1]
    elif AFTER in old:
        head, tail = old.split(AFTER, 1)
        new = head + AFTER + "\n\n" + block + (tail if tail.startswith("\n") else "\n" + tail)
    else:
        raise ValueError(f"{path} has no line {AFTER} to put the block after")
    path.write_text(new, encoding="utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", help="a comma-separated subset (default: the section's)")
    parser.add_argument("--budget", type=int, default=BUDGET, help="runs per robot")
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--write", action="store_true", help=f"put the section into {DOC}")
    args = parser.parse_args()
    recorded = {row.robot: row for row in parse_section(DOC.read_text(encoding="utf-8"))}
    names = args.robots.split(",") if args.robots else list(recorded)
    unknown = [name for name in names if name not in recorded]
    if unknown:
        parser.error(f"no best in the section for: {', '.join(unknown)}")
    began = time.perf_counter()
    rows = []
    for name in names:
        rows.append(measure(recorded[name], args.budget, args.seed))
        print(
            f"{name}: {time.perf_counter() - began:.0f} s {dict(rows[-1]['statuses'])}",
            file=sys.stderr,
            flush=True,
        )
    text = section(rows, time.perf_counter() - began, args.budget)
    print(text)
    if args.write:
        put_block(text)
        print(f"wrote the section into {DOC}", file=sys.stderr)


if __name__ == "__main__":
    main()

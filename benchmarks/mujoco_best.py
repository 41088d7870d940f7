"""MuJoCo at its best on each robot of the gallery: the damped settle of benchmarks/gallery.py
(the same stripped URDF, root fixed, its limits kept, from qpos = 0) swept over its step, its
integrator and its damping, stopped by the same rule as pinsettle's (the static residual), and
set against pinsettle's default solve of the same robot, warm and in a fresh process.

- The sweep: timestep in TIMESTEPS; integrator in INTEGRATORS; damping either the same c on
  every degree of freedom (UNIFORM, N m s/rad or N s/m) or c_i = a M_ii(q0) (MASS, 1/s; M the
  joint-space mass matrix at the start, from ``mj_fullM``); MuJoCo's constraint solver
  tolerance ``opt.tolerance`` at its default (1e-8) and, for the integrators in
  TIGHT_INTEGRATORS, also at TIGHT (1e-10). Why: on a soft joint limit a step solves the
  constraint forces only to the solver's tolerance, and at the default the static residual
  wanders near 1e-10, so reaching it is a lucky dip (a panda, 29.5 ms Euler a = 0.771/s:
  10990 steps at 1e-8, 7300 at 1e-9, 7290 at 1e-10, 7230 at 1e-12; talos_left_arm, 200 ms
  Euler a = 0.0424/s: 10290, 2340, 2320, 2320; xarm7 and baxter alike at all four). So 1e-9 is
  nearly tight enough and 1e-12 gains nothing: the grid takes the default and 1e-10. Only
  Euler's grid is doubled (Euler was the best integrator on 10 of the 11 robots settled before
  the tolerance was swept, and the outside check's on 8 of 10; the whole grid doubled would not
  fit the run time): the local search swaps the tolerance as one of its moves, for every
  integrator. A run that never has a constraint row
  (``MjData.maxuse_efc`` = 0: no limit touched) is the same at any tolerance, step for step,
  so its twin at the other tolerance is not run again but copied (and not counted twice).
- The stopping rule: every CHUNK steps, qpos is copied to a scratch MjData with qvel = 0 and
  ``mj_forward`` gives qacc; r = max |M qacc| (``mj_mulM``) is the net generalized force at rest
  there, the limits' constraint forces included. Relative to the force scale at the start
  (max |qfrc_bias| at qpos = 0, qvel = 0; 1 if 0). A run records the first step where it is
  <= each of LEVELS and ends at the last, or at the budget (MAX_STEPS steps or RUN_WALL s of
  wall time, whichever first), or when MuJoCo finds its state bad. No bound on the simulated
  time: at the largest steps it cut runs of 400 steps short.
- The best: among the settings that reach the tightest level any reaches, the fastest to it,
  timed as gallery.py times MuJoCo: the same number of steps again from the start in one
  ``mj_step(model, data, nstep)`` call (no checks), median of TIME_REPEATS.
- pinsettle: ``pinsettle.solve(model)`` with the default settings (root fixed), the wall time of
  the call warm and the first call in a fresh process (median of FIRST_PROCESSES processes).
  MuJoCo's best and pinsettle's warm call are timed alternately, ROUNDS rounds (``interleaved``).

    cd benchmarks && python mujoco_best.py [--robots ur5,panda] [--write]

``--write`` puts the section (a delimited block) into docs/benchmarks.md right after the
gallery; benchmarks/report.py keeps it there when it regenerates the file.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import statistics
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import mujoco
import numpy as np
import pinocchio
import pinsettle
from gallery import distance, load_mujoco, mujoco_q, rest_check
from independent import CachedReference
from python_overhead import fresh_process
from report_format import half_spread
from sweep_throughput import DOC, write

BEGIN = "<!-- mujoco:best (written by benchmarks/mujoco_best.py) -->"
END = "<!-- /mujoco:best -->"
AFTER = "<!-- /report:gallery -->"

DEFAULT_TOLERANCE = 1e-8  # MuJoCo's default opt.tolerance
TIGHT = 1e-10  # the tight solver tolerance (1e-9 nearly as good, 1e-12 no better: measured)
TOLERANCES = (DEFAULT_TOLERANCE, TIGHT)
TIGHT_INTEGRATORS = ("Euler",)  # the integrators whose grid is swept at TIGHT too
TIMESTEPS = (1e-3, 2e-3, 5e-3, 10e-3, 20e-3, 50e-3, 100e-3, 200e-3, 500e-3, 1.0, 2.0, 5.0)
INTEGRATOR_NAMES = ("Euler", "implicitfast", "implicit")
UNIFORM = (0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0)
MASS = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)
GRIDS = {"uniform": UNIFORM, "mass": MASS}
LEVELS = (1e-6, 1e-8, 1e-10)
CHUNK = 10
MAX_STEPS = 20_000  # lowered from 200k to keep the default run near 10 minutes on one core
RUN_WALL = 0.5  # s of wall time per setting (detection, checks included): a safety net
TIME_REPEATS = 5
TIME_CANDIDATES = 3  # the fastest by one timing, timed again TIME_REPEATS times
ROUNDS = 3  # MuJoCo's best and pinsettle's warm solve timed alternately, this many rounds
ROUND_REPEATS = 7  # pinsettle's warm calls a round (MuJoCo's: TIME_REPEATS)
FIRST_PROCESSES = 5
GOAL_WARM, GOAL_FIRST = 100.0, 30.0  # times faster than MuJoCo at its best
# A rest further than this beyond a limit (rad or m) is not the same answer: MuJoCo's limits are
# soft, and at large steps they soften with the step (an ur5 at 1 ms rests 3e-3 inside).
OUTSIDE_TOL = 1e-2
CHECK_ITERATIONS = 100  # the check's constraint solve, to convergence (one Newton step at rest)

_FIRST = """
import json, sys, time
import pinsettle
model = pinsettle.load_robot(sys.argv[1], floating=False)
start = time.perf_counter()
pinsettle.solve(model)
print(json.dumps({"first": time.perf_counter() - start}))
"""


class Setting(NamedTuple):
    timestep: float
    integrator: str
    kind: str  # "uniform" or "mass"
    value: float
    tolerance: float = DEFAULT_TOLERANCE  # the constraint solver's, m.opt.tolerance

    def label(self) -> str:
        damping = f"c = {self.value:.10g}" if self.kind == "uniform" else f"a = {self.value:.10g}/s"
        return (
            f"{self.timestep * 1e3:.10g} ms, {self.integrator}, {damping}, tol {self.tolerance:g}"
        )

    def twin(self) -> Setting:
        """The same setting at the other tolerance of TOLERANCES."""
        other = TIGHT if self.tolerance == DEFAULT_TOLERANCE else DEFAULT_TOLERANCE
        return self._replace(tolerance=other)


def sweep_settings() -> list[Setting]:
    """The grid: every setting at the default tolerance, then TIGHT_INTEGRATORS' at TIGHT."""
    grid = [
        Setting(dt, integrator, kind, value)
        for dt in TIMESTEPS
        for integrator in INTEGRATOR_NAMES
        for kind, values in GRIDS.items()
        for value in values
    ]
    return grid + [s.twin() for s in grid if s.integrator in TIGHT_INTEGRATORS]


# --- MuJoCo -----------------------------------------------------------------------------------


def mass_diagonal(m: Any) -> np.ndarray:
    """diag M(q0), from mj_fullM at qpos0."""
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    diag: np.ndarray = np.diag(full).copy()
    return diag


def force_scale(m: Any) -> float:
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    scale = float(np.max(np.abs(d.qfrc_bias), initial=0.0))
    return scale if scale > 0 else 1.0


def configure(m: Any, setting: Setting, diag: np.ndarray) -> None:
    m.opt.timestep = setting.timestep
    m.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{setting.integrator.upper()}")
    m.opt.tolerance = setting.tolerance
    if setting.kind == "uniform":
        m.dof_damping[:] = setting.value
    else:
        m.dof_damping[:] = setting.value * diag


class Checker:
    """The static residual of a configuration, relative to the force scale, with the constraint
    forces solved to convergence: at MuJoCo's default solver tolerance (1e-8) a rest on a limit
    can read qacc = 0 exactly where the solver accepts its start (no iteration), between checks
    of 5e-9 (talos_left_arm), which let a run stop at a lucky step. The solver's settings are
    changed for the check only (the run steps at the setting's tolerance, MuJoCo's other
    defaults); the residual depends on the configured timestep, through the softness of the
    limits."""

    def __init__(self, m: Any, scale: float) -> None:
        self.m, self.scale = m, scale
        self.scratch = mujoco.MjData(m)
        self.force = np.zeros(m.nv)

    def __call__(self, qpos: np.ndarray) -> float:
        s, opt = self.scratch, self.m.opt
        s.qpos[:] = qpos
        s.qvel[:] = 0.0
        kept = opt.tolerance, opt.ls_tolerance, opt.iterations
        opt.tolerance, opt.ls_tolerance, opt.iterations = 0.0, 1e-12, CHECK_ITERATIONS
        try:
            mujoco.mj_forward(self.m, s)
        finally:
            opt.tolerance, opt.ls_tolerance, opt.iterations = kept
        mujoco.mj_mulM(self.m, s, self.force, s.qacc)
        return float(np.max(np.abs(self.force), initial=0.0)) / self.scale


def bad_state(d: Any) -> bool:
    warnings = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL)
    if any(d.warning[int(w)].number > 0 for w in warnings):
        return True
    return not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel)))


def run(m: Any, check: Checker, max_steps: int = MAX_STEPS) -> dict[str, Any]:
    """One setting (already configured) from qpos = 0: the first step at each level, and
    whether a constraint row was ever made (``maxuse_efc``: if not, the tolerance played no
    part)."""
    d = mujoco.MjData(m)
    first: dict[float, int] = {}
    steps, status, residual = 0, "budget", float("inf")
    deadline = time.perf_counter() + RUN_WALL
    while steps < max_steps:
        mujoco.mj_step(m, d, nstep=CHUNK)
        steps += CHUNK
        if bad_state(d):
            status = "diverged"
            break
        residual = check(d.qpos)
        for level in LEVELS:
            if residual <= level and level not in first:
                first[level] = steps
        if LEVELS[-1] in first:
            status = "reached"
            break
        if time.perf_counter() > deadline:
            status = "wall"
            break
    return {
        "status": status,
        "steps": steps,
        "first": first,
        "residual": residual,
        "constrained": d.maxuse_efc > 0,
    }


def copied(twin: Setting, r: dict[str, Any]) -> dict[str, Any] | None:
    """A run of ``twin``'s twin at the other tolerance, if ``twin``'s run ``r`` never had a
    constraint row (so the tolerance played no part): ``r``, marked as a copy of ``twin``."""
    return None if r["constrained"] else r | {"twin": twin}


def time_steps(m: Any, steps: int, repeats: int) -> tuple[list[float], np.ndarray]:
    """Wall times of ``steps`` steps from the start in one call, and where they end."""
    d = mujoco.MjData(m)
    seconds: list[float] = []
    qpos: np.ndarray | None = None
    for _ in range(repeats):
        mujoco.mj_resetData(m, d)
        began = time.perf_counter()
        mujoco.mj_step(m, d, nstep=steps)
        seconds.append(time.perf_counter() - began)
        if qpos is not None and not np.array_equal(d.qpos, qpos):
            raise RuntimeError("MuJoCo's timed run took another path")
        qpos = d.qpos.copy()
    assert qpos is not None
    return seconds, qpos


def sweep(m: Any) -> tuple[list[tuple[Setting, dict[str, Any]]], float]:
    """Every setting's run, and the force scale."""
    diag = mass_diagonal(m)
    check = Checker(m, force_scale(m))
    runs: list[tuple[Setting, dict[str, Any]]] = []
    seen: dict[Setting, dict[str, Any]] = {}
    for setting in sweep_settings():
        r = copied(setting.twin(), seen[setting.twin()]) if setting.twin() in seen else None
        if r is None:
            configure(m, setting, diag)
            r = run(m, check)
        seen[setting] = r
        runs.append((setting, r))
    return runs, check.scale


#: The local search after the grid: factors on the timestep and the damping (log steps),
#: largest first; at most REFINE_EVALS runs from each family's best (integrator and kind).
REFINE_FACTORS = (2.0**0.5, 2.0**0.25, 2.0**0.125, 2.0**0.0625)
REFINE_EVALS = 60
#: Then SCATTER settings drawn around each of the SCATTER_CENTRES best, log-uniform within
#: SCATTER_SPAN in the step and the damping, any integrator and tolerance (seeded: the same draws
#: each run).
SCATTER, SCATTER_CENTRES, SCATTER_SPAN, SCATTER_SEED = 30, 3, 2.0**0.5, 20261128
CUT = 5  # a local run stops at CUT times the fewest steps found so far
WEIGHT_STEPS = 500  # steps timed for each integrator's cost of a step


def step_costs(m: Any, diag: np.ndarray) -> dict[str, float]:
    """Each integrator's cost of a step relative to Euler's on this robot (WEIGHT_STEPS steps
    from the start at 10 ms, mass-proportional damping 1/s; medians of TIME_REPEATS): an
    implicit step can cost twice an Euler step, so the fewest steps need not be the fastest.
    At the default solver tolerance only: where a limit is active a step at TIGHT cost within
    5% of one at the default (panda, talos_left_arm, xarm7, baxter at their best settings), less
    than this weight's own spread, so the tolerance gets no weight of its own; the best is
    chosen by wall time in the end (timed_best), the tighter solve's cost included."""
    costs = {}
    for name in INTEGRATOR_NAMES:
        configure(m, Setting(10e-3, name, "mass", 1.0), diag)
        costs[name] = statistics.median(time_steps(m, WEIGHT_STEPS, TIME_REPEATS)[0])
    return {name: costs[name] / costs["Euler"] for name in INTEGRATOR_NAMES}


class LocalRuns:
    """The local search's runs on one robot: each setting run once (capped at CUT times the
    fewest steps found), scored at ``level``: its exact steps times its integrator's cost of a
    step if it reaches the level at a valid rest, else infinity."""

    def __init__(
        self,
        m: Any,
        runs: list[tuple[Setting, dict[str, Any]]],
        check: Checker,
        valid: Callable[[np.ndarray], bool],
    ) -> None:
        self.m, self.check, self.valid = m, check, valid
        self.diag = mass_diagonal(m)
        self.weight = step_costs(m, self.diag)
        self.made: list[tuple[Setting, dict[str, Any]]] = []
        self.seen = {setting: r for setting, r in runs}
        self.scored: dict[Setting, float] = {}
        self.fewest = MAX_STEPS
        self.level = LEVELS[-1]
        self.runs_made = 0  # the runs made (copies not counted)

    def cost(self, setting: Setting) -> float:
        if setting in self.scored:
            return self.scored[setting]
        m, level = self.m, self.level
        twin = setting.twin()
        if setting not in self.seen and twin in self.seen:
            copy = copied(twin, self.seen[twin])
            if copy is not None:
                self.seen[setting] = copy
                self.made.append((setting, copy))  # not counted: no run made
        if setting not in self.seen:
            configure(m, setting, self.diag)
            self.seen[setting] = run(m, self.check, min(MAX_STEPS, CUT * self.fewest))
            self.made.append((setting, self.seen[setting]))
            self.runs_made += 1
        r = self.seen[setting]
        self.scored[setting] = math.inf
        if level in r["first"]:
            configure(m, setting, self.diag)
            steps, qpos = exact_first(m, self.check, r["first"][level], level)
            if self.valid(qpos):
                self.scored[setting] = float(steps * self.weight[setting.integrator])
                self.fewest = min(self.fewest, steps)
        return self.scored[setting]

    def starts(self, runs: list[tuple[Setting, dict[str, Any]]]) -> list[Setting]:
        """The fastest grid point of each family (integrator and kind of damping) at the
        tightest level a grid point reaches at a valid rest (``level`` is left at it)."""
        for self.level in reversed(LEVELS):
            self.scored.clear()
            found = []
            for name in INTEGRATOR_NAMES:
                for kind in GRIDS:
                    family = [s for s, _ in runs if s.integrator == name and s.kind == kind]
                    reached = sorted(
                        (self.seen[s]["first"][self.level], s)
                        for s in family
                        if self.level in self.seen[s]["first"]
                    )
                    start = next((s for _, s in reached if self.cost(s) < math.inf), None)
                    if start is not None:
                        found.append(start)
            if found:
                return found
        return []


def refine(
    m: Any,
    runs: list[tuple[Setting, dict[str, Any]]],
    check: Checker,
    valid: Callable[[np.ndarray], bool],
) -> list[tuple[Setting, dict[str, Any]]]:
    """A local search after the grid, to the tightest level a grid point reaches at a valid
    rest: a pattern search from the fastest grid point of each family (integrator and kind of
    damping), the timestep, the damping or both multiplied or divided by a factor, or the
    integrator or the solver tolerance swapped, moving to the best neighbour while one is
    faster, then a smaller factor; then settings scattered around the best found (scatter).
    Faster: the exact steps (exact_first) times the integrator's cost of a step (step_costs;
    a step costs the same whatever its length, damping and tolerance). The steps to rest are
    a rugged function of the step and the damping where a limit is touched (with the check at
    MuJoCo's default solver tolerance, a panda settled in 1200 steps at one point, in 710 at
    11% longer steps with 18% less damping, and not within 20000 steps between them), so a
    pattern search alone stopped at local minima up to twice as slow as a wider search found.
    Returns the runs it made."""
    local = LocalRuns(m, runs, check, valid)
    for start in sorted(local.starts(runs), key=local.cost):
        descend(start, local.cost, local.runs_made + REFINE_EVALS, lambda: local.runs_made)
    scatter(local.scored, local.cost)
    return local.made


def scatter(scored: dict[Setting, float], cost: Callable[[Setting], float]) -> None:
    """SCATTER settings drawn around each of the SCATTER_CENTRES best scored so far (distinct
    in step and damping), then a pattern search from the best of all with the two smallest
    factors."""
    rng = np.random.default_rng(SCATTER_SEED)
    ranked = sorted((c, s) for s, c in scored.items() if c < math.inf)
    centres: list[Setting] = []
    for _, s in ranked:
        if all((s.timestep, s.value) != (c.timestep, c.value) for c in centres):
            centres.append(s)
        if len(centres) == SCATTER_CENTRES:
            break
    for centre in centres:
        for _ in range(SCATTER):
            fh, fc = SCATTER_SPAN ** rng.uniform(-1.0, 1.0, size=2)
            name = INTEGRATOR_NAMES[int(rng.integers(len(INTEGRATOR_NAMES)))]
            tol = TOLERANCES[int(rng.integers(len(TOLERANCES)))]
            cost(Setting(centre.timestep * fh, name, centre.kind, centre.value * fc, tol))
    if centres:
        best = min(scored, key=lambda s: scored[s])
        count = [0]

        def counted(setting: Setting) -> float:
            count[0] += setting not in scored
            return cost(setting)

        for factor in REFINE_FACTORS[-2:]:
            best = step_down(best, counted, factor, lambda: count[0] < REFINE_EVALS)


def neighbours(here: Setting, factor: float) -> list[Setting]:
    """The settings a factor away in the timestep, the damping or both (the best damping moves
    with the step), and the same step and damping with another integrator (often as many
    steps, and an Euler step is the cheapest), and at the other solver tolerance."""
    out = []
    for fh in (factor, 1.0, 1.0 / factor):
        for fc in (factor, 1.0, 1.0 / factor):
            if (fh, fc) != (1.0, 1.0):
                out.append(here._replace(timestep=here.timestep * fh, value=here.value * fc))
    out += [here._replace(integrator=n) for n in INTEGRATOR_NAMES if n != here.integrator]
    return [*out, here.twin()]


def step_down(
    here: Setting, cost: Callable[[Setting], float], factor: float, going: Callable[[], bool]
) -> Setting:
    """Moves to the best neighbour at ``factor`` while one is faster and ``going()``."""
    best = cost(here)
    while going():
        scored = min(((cost(s), s) for s in neighbours(here, factor)), key=lambda x: x[0])
        if not scored[0] < best:
            break
        best, here = scored
    return here


def descend(
    start: Setting, cost: Callable[[Setting], float], until: int, made: Callable[[], int]
) -> None:
    """The pattern search's moves from ``start`` while the runs made stay below ``until``."""
    here = start
    for factor in REFINE_FACTORS:
        here = step_down(here, cost, factor, lambda: made() < until)


def exact_first(m: Any, check: Checker, steps: int, level: float) -> tuple[int, np.ndarray]:
    """The first step at ``level`` of a run (``m`` configured) whose check every CHUNK steps
    first found it at ``steps``, and the configuration there: the last CHUNK steps again one at
    a time."""
    d = mujoco.MjData(m)
    before = max(steps - CHUNK, 0)
    if before:
        mujoco.mj_step(m, d, nstep=before)
    for step in range(before + 1, steps + 1):
        mujoco.mj_step(m, d)
        if step == steps or check(d.qpos) <= level:
            return step, d.qpos.copy()
    return steps, d.qpos.copy()  # steps = 0: the start


def best_run(
    m: Any,
    runs: list[tuple[Setting, dict[str, Any]]],
    valid: Callable[[np.ndarray], bool],
    check: Checker,
) -> dict[str, Any] | None:
    """The fastest setting whose end is a valid rest (``valid``: inside the limits, not
    unstable), at the tightest level such a setting reaches (None if none does); each run's
    steps to it exact (exact_first), not a multiple of CHUNK."""
    diag = mass_diagonal(m)
    for level in reversed(LEVELS):
        once = []
        for setting, r in runs:
            if level in r["first"] and "twin" not in r:  # a copy is its twin's run
                configure(m, setting, diag)
                steps = exact_first(m, check, r["first"][level], level)[0]
                seconds, qpos = time_steps(m, steps, 1)
                once.append((seconds[0], setting, steps, qpos))
        fine = [x for x in once if valid(x[3])]
        if fine:
            return timed_best(m, fine, diag) | {"level": level, "invalid": len(once) - len(fine)}
    return None


def timed_best(
    m: Any, once: list[tuple[float, Setting, int, np.ndarray]], diag: np.ndarray
) -> dict[str, Any]:
    """Of settings timed once, the fastest by a median of TIME_REPEATS: the fastest by one
    timing and the fewest steps are timed again (one timing can be an outlier)."""
    candidates = sorted(once, key=lambda x: x[0])[:TIME_CANDIDATES]
    candidates += sorted(once, key=lambda x: x[2])[:TIME_CANDIDATES]
    timed = []
    for _, setting, steps, _ in {(x[1], x[2]): x for x in candidates}.values():
        configure(m, setting, diag)
        seconds, qpos = time_steps(m, steps, TIME_REPEATS)
        timed.append((statistics.median(seconds), setting, steps, qpos))
    seconds_best, setting, steps, qpos = min(timed, key=lambda x: x[0])
    configure(m, setting, diag)  # left as the best, for the rest check
    return {
        "setting": setting,
        "steps": steps,
        "sim_time": steps * setting.timestep,
        "seconds": seconds_best,
        "qpos": qpos,
    }


def edges(setting: Setting) -> list[str]:
    out = []
    if not TIMESTEPS[0] < setting.timestep < TIMESTEPS[-1]:
        out.append(f"timestep {setting.timestep * 1e3:g} ms")
    grid = GRIDS[setting.kind]
    if not grid[0] < setting.value < grid[-1]:
        out.append(f"{'c' if setting.kind == 'uniform' else 'a'} = {setting.value:g}")
    return out


# --- pinsettle ----------------------------------------------------------------------------------


def pinsettle_round(model: pinocchio.Model) -> tuple[float, float, pinsettle.Result]:
    """One round of pinsettle's warm solve: the medians of ROUND_REPEATS calls' wall time and
    of their C++ runs' own (``Result.wall_time``), and the last result."""
    seconds, inside = [], []
    for _ in range(ROUND_REPEATS):
        began = time.perf_counter()
        result = pinsettle.solve(model)
        seconds.append(time.perf_counter() - began)
        inside.append(result.wall_time)
    return statistics.median(seconds), statistics.median(inside), result


def interleaved(m: Any, steps: int | None, model: pinocchio.Model) -> dict[str, Any]:
    """MuJoCo's best (``m`` configured to it, ``steps`` of it; None: none) and pinsettle's warm
    solve timed in ROUNDS alternating rounds, the first of each round swapped every round (after
    a warm-up of each): the medians of the rounds, and half their spread over the median."""
    pinsettle.solve(model)
    if steps is not None:
        time_steps(m, steps, 1)
    mj: list[float] = []
    kd: list[tuple[float, float, pinsettle.Result]] = []
    for k in range(ROUNDS):
        order = [False, True] if k % 2 == 0 else [True, False]
        for is_mujoco in order:
            if not is_mujoco:
                kd.append(pinsettle_round(model))
            elif steps is not None:
                mj.append(statistics.median(time_steps(m, steps, TIME_REPEATS)[0]))
    warm = [x[0] for x in kd]
    return {
        "warm": statistics.median(warm),
        "warm_spread": half_spread(warm),
        "cpp": statistics.median(x[1] for x in kd),
        "result": kd[-1][2],
        "mujoco": statistics.median(mj) if mj else None,
        "mujoco_spread": half_spread(mj) if mj else None,
    }


def pinsettle_first(name: str) -> float:
    firsts = []
    for _ in range(FIRST_PROCESSES):
        firsts.append(float(fresh_process(_FIRST, name)["first"]))
    return statistics.median(firsts)


# --- one robot ----------------------------------------------------------------------------------


def level_counts(runs: list[tuple[Setting, dict[str, Any]]]) -> dict[float, int]:
    return {level: sum(level in r["first"] for _, r in runs) for level in LEVELS}


def mujoco_side(urdf: Path, ref: CachedReference) -> dict[str, Any]:
    m, why, _ = load_mujoco(urdf)
    if m is None:
        return {"error": why}

    def valid(qpos: np.ndarray) -> bool:
        """A rest inside the limits (to OUTSIDE_TOL: MuJoCo's are soft) and not unstable."""
        check = rest_check(ref, mujoco_q(m, qpos, ref.full))
        return bool(check["outside"] <= OUTSIDE_TOL and check["stability"] != "unstable")

    began = time.perf_counter()
    runs, scale = sweep(m)
    check = Checker(m, scale)
    refined = refine(m, runs, check, valid)
    best = best_run(m, runs + refined, valid, check)
    return {
        "model": m,
        "scale": scale,
        "best": best,
        "counts": level_counts(runs),
        "settings": len(runs),
        "refined": len(refined),
        "statuses": {s: sum(r["status"] == s for _, r in runs) for s in ("wall", "diverged")},
        "sweep_seconds": time.perf_counter() - began,
    }


def measure(name: str) -> dict[str, Any]:
    urdf = pinsettle.robot_urdf(name)
    model = pinsettle.load_robot(name, floating=False)
    row: dict[str, Any] = {"name": name, "nv": model.nv}
    ref = CachedReference(pinocchio.buildModelFromUrdf(str(urdf)))
    mj = mujoco_side(urdf, ref)
    if "error" in mj:
        return row | {"error": mj["error"]}
    best = mj["best"]
    timed = interleaved(mj["model"], None if best is None else best["steps"], model)
    result = timed["result"]
    kd = rest_check(ref, result.q)
    row |= {
        "warm": timed["warm"],
        "warm_spread": timed["warm_spread"],
        "cpp": timed["cpp"],
        "first": pinsettle_first(name),
        "kd_status": result.status,
        "kd_steps": result.steps,
        "kd_newton": result.polish_iterations,
        "kd_dt": result.dt,
        "kd_relative": kd["residual"] / mj["scale"],
        "kd_verdict": kd["stability"],
    }
    row |= {k: mj[k] for k in ("counts", "settings", "statuses", "sweep_seconds", "best")}
    if best is not None:
        q = mujoco_q(mj["model"], best.pop("qpos"), ref.full)
        check = rest_check(ref, q)
        best |= {
            "seconds": timed["mujoco"],
            "spread": timed["mujoco_spread"],
            "damping_per_step": damping_per_step(best["setting"], mass_diagonal(mj["model"])),
            "relative": check["residual"] / mj["scale"],
            "verdict": check["stability"],
            "distance": distance(ref.full, result.q, q),
            "outside": float(check["outside"]),
            "edges": edges(best["setting"]),
        }
    return row


def damping_per_step(setting: Setting, diag: np.ndarray) -> float:
    """h c_i / M_ii, the damping a step applies against the inertia (median over the degrees
    of freedom; h a for the mass-proportional kind)."""
    if setting.kind == "mass":
        return setting.timestep * setting.value
    return float(np.median(setting.timestep * setting.value / diag))


# --- the section --------------------------------------------------------------------------------


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.3g}"


def _pct(fraction: float) -> str:
    return f"{fraction * 100:.0f}%"


def table_row(row: dict[str, Any]) -> str:
    counts = "/".join(str(row["counts"][level]) for level in LEVELS)
    kd = f"{_ms(row['warm'])} ± {_pct(row['warm_spread'])} | {_ms(row['first'])} | "
    kd += f"{row['kd_relative']:.0e}"
    kd += f" ({row['kd_verdict']})"
    best = row["best"]
    if best is None:
        none = f"no valid rest reached {LEVELS[0]:g} | | | | | {counts}"
        return f"| {row['name']} | {row['nv']} | {none} | {kd} | | | | |"
    s = best["setting"]
    return (
        f"| {row['name']} | {row['nv']} | {s.label()} | {best['level']:.0e} | "
        f"{best['steps']} | {best['sim_time']:.3g} | "
        f"{_ms(best['seconds'])} ± {_pct(best['spread'])} | {counts} | {kd} | "
        f"{best['seconds'] / row['warm']:.2g} | {best['seconds'] / row['first']:.2g} | "
        f"{best['relative']:.0e}, {best['verdict']}, {best['distance']:.1e}, "
        f"{best['outside']:.1e} | {best['invalid']} |"
    )


def comparable(row: dict[str, Any]) -> bool:
    """Both reach the level and MuJoCo's rest is not unstable."""
    best = row.get("best")
    return bool(
        best is not None
        and best["level"] == LEVELS[-1]
        and row["kd_relative"] <= LEVELS[-1]
        and best["verdict"] != "unstable"
    )


def summary(rows: list[dict[str, Any]]) -> list[str]:
    both = [r for r in rows if "error" not in r and comparable(r)]
    lines = []
    if both:
        warm = statistics.median(r["best"]["seconds"] / r["warm"] for r in both)
        first = statistics.median(r["best"]["seconds"] / r["first"] for r in both)
        lines.append(
            f"Over the {len(both)} robots where both reach {LEVELS[-1]:g} and MuJoCo's rest is "
            f"not unstable, the median of MuJoCo's best time over pinsettle's warm call is "
            f"{warm:.2g}, over pinsettle's first call in a process {first:.2g}."
        )
        lines.append(goal_line(both))
        lines.append("\n".join([WHY, "", *(why_line(r) for r in both)]))
    return lines + flags(rows)


def goal_line(both: list[dict[str, Any]]) -> str:
    """The goal of at least GOAL_WARM times faster warm and GOAL_FIRST times on the first
    call, on every robot both settle: met or by how much not."""
    short = [
        f"{r['name']} ({r['best']['seconds'] / r['warm']:.2g}, "
        f"{r['best']['seconds'] / r['first']:.2g})"
        for r in both
        if r["best"]["seconds"] / r["warm"] < GOAL_WARM
        or r["best"]["seconds"] / r["first"] < GOAL_FIRST
    ]
    verdict = "met" if not short else "**not met** on " + "; ".join(short)
    return (
        f"The goal, at least {GOAL_WARM:g} times faster than MuJoCo at its best warm and "
        f"{GOAL_FIRST:g} times on the first call in a process, on every robot both bring to "
        f"{LEVELS[-1]:g} (MuJoCo's best over pinsettle's warm and first times in brackets): "
        f"{verdict}."
    )


WHY = (
    "Why, per robot. MuJoCo's integrators (Euler, implicitfast and implicit alike) take the joint"
    " damping D implicitly: a step is v <- (M + hD)^-1 (M v + h f(q)), q <- q + h v, with f the "
    "static force (gravity and the limits). That is a momentum (heavy-ball) descent on the "
    "potential energy, its momentum about 1/(1 + h c/M): the implicit damping keeps it stable at "
    "steps far longer than the motion's own time scale, and the sweep tunes its step and momentum"
    " per robot, which is why the best settings run at tenths of a second a step and settle in "
    "tens of steps where the motion is simple. pinsettle's damped steps follow the motion (each "
    "step within the stability limit of its fastest mode, which it estimates) until Newton takes "
    "over near the rest. Per robot, MuJoCo's steps and their cost against pinsettle's (its C++ "
    "run divided by its steps: the step estimates, Newton and the final stability verdict "
    "included) and the Python layer's time:"
)


def why_line(row: dict[str, Any]) -> str:
    """One robot's reasons, in numbers: MuJoCo's steps, step length (against pinsettle's) and
    momentum, and pinsettle's steps, Newton iterations, C++ and Python times."""
    best, us = row["best"], 1e6
    s, hd = best["setting"], best["damping_per_step"]
    ratio = best["seconds"] / row["warm"]
    steps = max(row["kd_steps"], 1)
    return (
        f"- **{row['name']}** (MuJoCo's best over pinsettle warm {ratio:.2g}, first "
        f"{best['seconds'] / row['first']:.2g}): MuJoCo takes {best['steps']} steps of "
        f"{best['seconds'] / best['steps'] * us:.3g} us, h = {s.timestep * 1e3:.3g} ms "
        f"({s.timestep / row['kd_dt']:.2g} times pinsettle's final step), h c/M = {hd:.2g} "
        f"(momentum about {1 / (1 + hd):.2g}). pinsettle takes {row['kd_steps']} steps and "
        f"{row['kd_newton']} Newton iterations: {row['cpp'] * us:.3g} us in C++ "
        f"({row['cpp'] / steps * us:.3g} us a step, all included) and "
        f"{(row['warm'] - row['cpp']) * us:.3g} us in Python; its first call in a process takes "
        f"{row['first'] / row['warm']:.2g} times the warm one. {goal_gap(ratio)}"
    )


def goal_gap(ratio: float) -> str:
    if ratio >= GOAL_WARM:
        return "The warm goal is met."
    return f"The warm goal needs pinsettle {GOAL_WARM / ratio:.3g} times faster than today."


def flags(rows: list[dict[str, Any]]) -> list[str]:
    """The edge flags and the robots MuJoCo brings to no level's end."""
    flagged = [
        f"{r['name']} ({', '.join(r['best']['edges'])})"
        for r in rows
        if r.get("best") and r["best"]["edges"]
    ]
    lines = [
        "Best settings on an edge of the grid: " + ("; ".join(flagged) if flagged else "none") + "."
    ]
    missing = [
        r["name"]
        for r in rows
        if "error" not in r and (r["best"] is None or r["best"]["level"] != LEVELS[-1])
    ]
    if missing:
        lines.append(f"No setting brings MuJoCo to {LEVELS[-1]:g} on: {', '.join(missing)}.")
    return lines


def tolerance_prose() -> str:
    """The prose's sentences on the solver tolerance."""
    tight = ", ".join(TIGHT_INTEGRATORS)
    return (
        f"MuJoCo's constraint solver tolerance (`opt.tolerance`, 'tol' in the table) at its "
        f"default {DEFAULT_TOLERANCE:g}, and for {tight} also at {TIGHT:g}. On a soft joint "
        "limit a step solves the constraint forces only to that tolerance, and at the default "
        "the static residual wanders near 1e-10: reaching it is a lucky dip that does not "
        "replay (a panda at 29.5 ms Euler a = 0.771/s took 10990 steps at 1e-8, 7300 at 1e-9, "
        "7290 at 1e-10 and 7230 at 1e-12; talos_left_arm at 200 ms Euler a = 0.0424/s 10290, "
        f"2340, 2320 and 2320), so the grid takes the default and {TIGHT:g}, and only {tight}'s "
        "twice (the best integrator on 10 of the 11 robots settled before the tolerance was "
        "swept; all of it twice would not fit the run time): the local search swaps the "
        "tolerance as one of its moves. A run that never makes a constraint row (`maxuse_efc` "
        "= 0, no limit touched) is the same at either tolerance, step for step, and is not run "
        "twice. A step at the tight tolerance on a limit cost within 5% of one at the default "
        "(measured on four robots), so the search weighs the steps by the integrator only; the "
        "best is timed, the tighter solve included."
    )


def prose() -> list[str]:
    steps = ", ".join(f"{dt * 1e3:g}" for dt in TIMESTEPS)
    return [
        f"MuJoCo's damped settle of each robot (the gallery's stripped URDF, root fixed, its "
        f"limits kept, from qpos = 0) swept over {len(sweep_settings())} settings: timestep "
        f"in {{{steps}}} ms; integrator {', '.join(INTEGRATOR_NAMES)}; damping either the same "
        f"c in {{{', '.join(f'{c:g}' for c in UNIFORM)}}} on every degree of freedom or "
        f"c_i = a M_ii(q0) with a in {{{', '.join(f'{a:g}' for a in MASS)}}} 1/s (M_ii from "
        "`mj_fullM` at the start); "
        + tolerance_prose()
        + " Then a local search to the tightest level a grid point "
        "reaches at a valid rest. First a pattern search from the fastest grid point of each "
        "family (integrator and kind of damping): the timestep, the damping or both "
        f"multiplied or divided by {', then '.join(f'{f:.3g}' for f in REFINE_FACTORS)}, or "
        "the integrator or the solver tolerance swapped, moving while a neighbour is faster "
        "(its exact steps times the integrator's cost of a step on that robot, timed over "
        f"{WEIGHT_STEPS} steps: an implicit step can cost twice an Euler one), at most "
        f"{REFINE_EVALS} runs from each. "
        f"Then {SCATTER} settings drawn around each of the {SCATTER_CENTRES} best found "
        f"(log-uniform within {SCATTER_SPAN:.3g} times in the step and the damping, any "
        "integrator and tolerance, a fixed seed) and the pattern search again from the best "
        "with the two "
        f"smallest factors. A local run stops at {CUT} times the fewest steps found. The "
        "steps to rest are a rugged function of the setting where a limit is touched (a "
        "panda's fewest, 710 steps with the check at MuJoCo's default solver tolerance, had "
        "neighbours 9% away that took 1.4 to 1.6 times as many, ended outside a limit or "
        "never settled), so the search samples around its best rather than trusting one "
        "descent.",
        "",
        f"Stopping rule, the same as pinsettle's: every {CHUNK} steps the configuration is "
        "copied to a scratch MjData with qvel = 0, `mj_forward` gives qacc (its constraint "
        "solve run to convergence for the check, solver tolerance 0: at MuJoCo's default, "
        "1e-8, a rest on a limit can read qacc = 0 exactly where the solver accepts its "
        "start, between checks of 5e-9), and the residual is "
        "max |M qacc| (`mj_mulM`), the net generalized force at rest there with the limits' "
        "constraint forces included, over the force scale max |qfrc_bias| at the start. A run "
        f"records the first check at {', '.join(f'{x:g}' for x in LEVELS)} (for the best "
        f"candidates then the exact step: the last {CHUNK} steps again, checked one at a time) "
        "and ends at the "
        f"last, or at {MAX_STEPS} steps (to keep the run near a "
        f"quarter of an hour on one core) or {RUN_WALL:g} s of wall time, whichever "
        "comes first. The best setting is the fastest to the tightest level that a setting "
        "ending at a valid rest reaches (inside the limits to "
        f"{OUTSIDE_TOL:g} rad or m, MuJoCo's being soft and softening with the step, and not "
        "unstable by the independent check: a rest beyond the limits or on a saddle is another "
        "answer; the settings left out for that are counted in the last column): the same "
        "steps again from the start in one `mj_step(model, data, nstep)` "
        f"call, no checks, median of {TIME_REPEATS} (the {TIME_CANDIDATES} fastest by one "
        f"timing and the {TIME_CANDIDATES} with the fewest steps timed again). "
        "pinsettle: `pinsettle.solve(model)` with the default settings, the wall time of the "
        "call, warm and first in a fresh process (median of "
        f"{FIRST_PROCESSES}); its residual is recomputed independently (Pinocchio's gravity "
        "and the stops' reactions) over the same scale. The times in the table, MuJoCo's best "
        f"and pinsettle's warm call, are timed alternately in {ROUNDS} rounds after a warm-up "
        f"of each (a round: the median of {TIME_REPEATS} MuJoCo runs and of {ROUND_REPEATS} "
        "pinsettle calls; which goes first swaps every round): the median of the rounds, ± "
        "half their spread over it.",
    ]


HEADER = (
    "| robot | nv | MuJoCo best setting | level | steps | simulated (s) | MuJoCo (ms) "
    f"| settings reaching {'/'.join(f'{x:g}' for x in LEVELS)} | pinsettle warm (ms) "
    "| pinsettle first (ms) | pinsettle residual (verdict) | MuJoCo / warm | MuJoCo / first "
    "| MuJoCo rest: residual, verdict, distance, outside | settings left out at the level |"
)


def section(rows: list[dict[str, Any]], seconds: float) -> str:
    lines = [
        BEGIN,
        "## MuJoCo at its best, per robot",
        "",
        f"*Measured on {datetime.date.today().isoformat()} by `benchmarks/mujoco_best.py` "
        f"(MuJoCo {mujoco.__version__}) in {seconds / 60:.1f} min; 1-minute load average "
        f"{os.getloadavg()[0]:.2f} at the end.*",
        "",
        *prose(),
        "",
        HEADER,
        "|" + "---|" * HEADER.count(" | ") + "---|",
        *[table_row(r) for r in rows if "error" not in r],
        "",
        "Residuals are relative to the force scale; distance is max |q_MuJoCo - q_pinsettle| "
        "(rad or m); outside is how far MuJoCo's rest lies beyond a limit (its limits are soft; "
        "rad or m); the verdicts are the gallery's independent stiffness check.",
        "",
        *"\n\n".join(summary(rows)).splitlines(),
    ]
    skipped = [f"{r['name']} ({r['error']})" for r in rows if "error" in r]
    if skipped:
        lines += ["", "Not loaded by MuJoCo: " + "; ".join(skipped) + "."]
    return "\n".join([*lines, END]) + "\n"


def put(text: str, path: Path, after: str) -> None:
    """The block in place of the old one in ``path``, or the first time right after the line
    ``after`` (at the end without it)."""
    old = path.read_text(encoding="utf-8")
    if BEGIN in old or after not in old:
        write(text, path, BEGIN, END)
        return
    head, tail = old.split(after, 1)
    path.write_text(f"{head}{after}\n\n{text.rstrip()}\n{tail}", encoding="utf-8")


README = DOC.parents[1] / "README.md"
README_AFTER = "<!-- /bench:summary -->"


def readme_block(doc: Path = DOC) -> str:
    """The README's paragraph on MuJoCo at its best: the medians and the goal's verdict of the
    section in ``doc`` (one source for both)."""
    text = doc.read_text(encoding="utf-8")
    block = text.split(BEGIN, 1)[1].split(END, 1)[0]
    kept = [line for line in block.splitlines() if line.startswith(("Over the", "The goal"))]
    body = " ".join(kept).replace("(MuJoCo's best over", "(its best over")
    paragraph = (
        "**MuJoCo at its best**, per robot (timestep, integrator, damping and constraint solver "
        "tolerance swept, stopped at "
        "the same static residual as pinsettle, at a valid rest: [docs/benchmarks.md]"
        f"(docs/benchmarks.md#mujoco-at-its-best-per-robot)): {body}"
    )
    wrapped = textwrap.fill(paragraph, width=100, break_long_words=False, break_on_hyphens=False)
    return f"{BEGIN}\n{wrapped}\n{END}\n"


def robots() -> list[str]:
    """The gallery's robots (all, root fixed) that MuJoCo loads."""
    names = []
    for name in pinsettle.robot_names():
        if load_mujoco(pinsettle.robot_urdf(name))[0] is not None:
            names.append(name)
    return names


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", help="a comma-separated subset (default: all)")
    parser.add_argument(
        "--write", action="store_true", help=f"put the section into {DOC} and the README"
    )
    parser.add_argument(
        "--readme", action="store_true", help=f"only the README's paragraph, from {DOC}"
    )
    args = parser.parse_args()
    if args.readme:
        put(readme_block(), README, README_AFTER)
        return
    names = args.robots.split(",") if args.robots else robots()
    began = time.perf_counter()
    rows = []
    for name in names:
        rows.append(measure(name))
        ended = rows[-1].get("statuses", {})  # runs cut by the wall cap, or diverged
        print(f"{name}: {time.perf_counter() - began:.0f} s {ended}", file=sys.stderr, flush=True)
    text = section(rows, time.perf_counter() - began)
    print(text)
    if args.write:
        put(text, DOC, AFTER)
        put(readme_block(), README, README_AFTER)
        print(f"wrote the section into {DOC} and {README}", file=sys.stderr)


if __name__ == "__main__":
    main()

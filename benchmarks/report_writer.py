"""The figures and the text of the benchmark report (benchmarks/report.py measures).

Everything written here is computed from the measurements: the conclusions too, by the rules
stated next to them.
"""

from __future__ import annotations

import dataclasses
import math
import re
import statistics
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinsettle
import report_data as D

#: Values below this are drawn at it on the log axes (exact zeros happen at round-off).
FLOOR = 1e-17
LEVEL = D.RESIDUAL_LEVELS[-1]  # the level the conclusions compare at
#: The solver's default settings, which the texts quote (they may change).
DEFAULTS = pinsettle.Settings()


# --- formatting ---------------------------------------------------------------------------------


def fmt_time(seconds: float | None) -> str:
    if seconds is None or not math.isfinite(seconds):
        return "-"
    if seconds >= 1.0:
        return f"{seconds:.2f} s"
    if seconds >= 1e-3:
        return f"{seconds * 1e3:.3g} ms"
    return f"{seconds * 1e6:.3g} us"


def fmt_spread(values: Sequence[float], scale: float = 1.0) -> str:
    """Median (min-max) of values times scale, in a time unit."""
    vals = [v * scale for v in values]
    med = statistics.median(vals)
    if len(vals) == 1:
        return f"{fmt_time(med)} (1 run)"
    lo, hi = min(vals), max(vals)
    unit, factor = ("s", 1.0) if med >= 1 else ("ms", 1e3) if med >= 1e-3 else ("us", 1e6)
    return f"{med * factor:.3g} {unit} ({lo * factor:.3g}-{hi * factor:.3g})"


def fmt_steps(steps: float | None) -> str:
    return "-" if steps is None else f"{int(steps):,}"


def plural(n: int, word: str) -> str:
    return f"{n:,} {word}" + ("" if n == 1 else "s")


def fmt_e(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.1e}"


def reach(run: D.Run, quantity: str, level: float) -> tuple[float, float] | None:
    return run.reach(quantity, level)


def reach_cell(run: D.Run, quantity: str, level: float, spread: bool = True) -> tuple[str, str]:
    """(steps, time) cells for the step from which the error stays below level."""
    hit = run.reach(quantity, level)
    if hit is None:
        return "not reached", "-"
    steps, _ = hit
    if run.method == "newton":
        return f"{int(steps)} it.", fmt_time(run.extra["times"][int(steps)]) + " (Python)"
    # The set-up in full, then the steps at each repeat's time per step after it.
    times = [run.setup + steps * (s - run.setup) / run.steps for s in run.seconds]
    return fmt_steps(steps), fmt_spread(times) if spread else fmt_time(hit[1])


def outcome_time(run: D.Run) -> str:
    """Time to the level, or what happened instead (the status, the residual left)."""
    t = time_to(run)
    if t is not None:
        return fmt_time(t)
    return f"not reached ({run.status} at {run.steps:,} steps, residual {fmt_e(run.residual)})"


def outcome_steps_time(run: D.Run) -> str:
    hit = run.reach("residual", LEVEL)
    if hit is not None:
        return f"{fmt_steps(hit[0])}, {fmt_time(hit[1])}"
    return f"not reached ({run.status} at {run.steps:,} steps, residual {fmt_e(run.residual)})"


def peaks_to(run: D.Run, level: float = LEVEL) -> str:
    """Damping events before the residual stays below level."""
    steps = steps_to(run, level)
    if steps is None:
        return "-"
    return f"{int(np.sum(run.extra['damping_steps'] < steps)):,}"


def landed(run: D.Run) -> str:
    if run.landing.q is None:
        return "no rest"
    return run.landing.stability


def geomean(values: Sequence[float]) -> float:
    values = [v for v in values if v is not None and math.isfinite(v) and v > 0]
    return math.exp(statistics.fmean(math.log(v) for v in values)) if values else math.nan


def time_to(run: D.Run, level: float = LEVEL) -> float | None:
    hit = run.reach("residual", level)
    return None if hit is None else hit[1]


def steps_to(run: D.Run, level: float = LEVEL) -> float | None:
    hit = run.reach("residual", level)
    return None if hit is None else hit[0]


BASELINES = D.BASELINES


def loop_scenes(results: D.Results) -> list[str]:
    """The scenes with closed loops, in the report's order."""
    return [name for name, d in results.scenes.items() if d.loops]


def trees_only(results: D.Results) -> str:
    """The sentence that says why the loop scenes have no baselines ('' when there are none)."""
    names = loop_scenes(results)
    if not names:
        return ""
    return (
        "baselines run on trees only: "
        + ", ".join(f"`{n}`" for n in names)
        + (" closes" if len(names) == 1 else " close")
        + " kinematic loops, which the baselines' unconstrained `pinocchio::aba` cannot hold"
    )


def kd_runs(d: D.SceneData) -> list[D.Run]:
    """Every kinetic-damping run on a scene: the main runs and the sweeps'."""
    runs = [r for r in d.runs.values() if r.method == "kd"]
    return runs + [r for sweep in d.sweeps.values() for r in sweep if r.method == "kd"]


def worst_constraint_error(d: D.SceneData) -> float:
    """Largest final loop error (m) over every KD run on the scene, as measured by the report
    and as reported by the solver."""
    return max(
        float(max(r.extra["constraint_error"], r.extra["solver_constraint_error"]))
        for r in kd_runs(d)
    )


def loop_cost_ratio(results: D.Results, name: str, key: str = "exact") -> float:
    """The solver's step on a scene with loops over a bare ``pinocchio::constraintDynamics`` +
    ``integrate`` step (benchmarks/loop_step_cost, medians); nan when not measured."""
    cost = results.loop_step_cost.get(name)
    if cost is None:
        return math.nan
    c = cost["ns_per_step"]
    return float(statistics.median(c[key]) / statistics.median(c["bare"]))


# --- figures -----------------------------------------------------------------------------------

STYLE: dict[str, dict[str, Any]] = {
    "kd_exact": dict(color="C0", ls="-", lw=2, label="KD, exact energy"),
    "kd_simplified": dict(color="C0", ls="--", label="KD, simplified energy"),
    "viscous_rule": dict(color="C1", ls="-", label="viscous, joint dampers (rule)"),
    "viscous_best": dict(color="C1", ls="--", label="viscous, joint dampers (best)"),
    "mass_damping_rule": dict(color="C2", ls="-", label="viscous, mass-proportional (rule)"),
    "mass_damping_best": dict(color="C2", ls="--", label="viscous, mass-proportional (best)"),
    "fire_rule": dict(color="C3", ls="-", label="FIRE (rule)"),
    "fire_best": dict(color="C3", ls="--", label="FIRE (best)"),
    "fire2_rule": dict(color="C6", ls="-", label="FIRE 2.0 (rule)"),
    "fire2_best": dict(color="C6", ls="--", label="FIRE 2.0 (best)"),
    "newton": dict(color="C4", ls=":", marker="o", ms=3, label="Newton (Python)"),
    "newton_ls": dict(color="C5", ls=":", marker="s", ms=3, label="Newton + line search (Python)"),
}


def scene_figure(d: D.SceneData, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 8), sharey="row")
    for key, run in d.runs.items():
        if run.curve is None or key not in STYLE:
            continue
        if key.endswith("_best") and run is d.runs.get(key[: -len("_best")] + "_rule"):
            continue  # the rule was the best: drawn once
        c = run.curve
        style = STYLE[key]
        for row, quantity in enumerate(("distance", "residual")):
            y = np.maximum(getattr(c, quantity), FLOOR)
            if run.method == "newton":
                t = np.array(run.extra["times"])
                axes[row, 0].plot(t[1:], y[1:], **style)
                continue
            keep = c.steps > 0
            axes[row, 0].plot(run.setup + c.steps[keep] * run.per_step, y[keep], **style)
            axes[row, 1].plot(c.steps[keep], y[keep], **style)
    for ax in axes.flat:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, which="major", alpha=0.3)
    for ax in axes[1]:
        for level in D.RESIDUAL_LEVELS:
            ax.axhline(level, color="grey", lw=0.8, ls=":")
    axes[0, 0].set_ylim(FLOOR / 2, 1e2)
    axes[1, 0].set_ylim(FLOOR / 2, 1e2)
    axes[0, 0].set_ylabel("distance max|q - q*| (rad or m)")
    axes[1, 0].set_ylabel("residual / force scale")
    axes[1, 0].set_xlabel("wall time (s): set-up + steps x measured time per step")
    axes[1, 1].set_xlabel(
        "steps (constrained-dynamics evaluations)" if d.loops else "steps (ABA evaluations)"
    )
    axes[0, 0].set_title("against wall time")
    axes[0, 1].set_title("against steps")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    title = f"{d.bench_name}: {d.description}"
    if d.loops:
        title += f"\n(closed loops, mobility {d.mobility}: the baselines run on trees only)"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.09, 1, 1))
    fig.savefig(path, dpi=90)
    plt.close(fig)


def scene_color(k: int) -> str | tuple[float, ...]:
    """The k-th scene's colour in the figures with a line per scene: the ten of matplotlib's
    cycle, then the light shades of tab20 (C10 would be C0 again)."""
    if k < 10:
        return f"C{k}"
    import matplotlib

    return matplotlib.colormaps["tab20"]((2 * (k - 10) + 1) % 20)


def kt_figure(results: D.Results, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    for k, (name, d) in enumerate(results.scenes.items()):
        runs = d.sweeps["kt"]
        times = {(r.settings["energy"], r.settings["kt"]): time_to(r) for r in runs}
        best = min((t for t in times.values() if t is not None), default=None)
        if best is None:
            continue
        for energy, ls in (("exact", "-"), ("simplified", "--")):
            x = [kt for kt in results.config.kts]
            y = [np.nan if (t := times[(energy, kt)]) is None else t / best for kt in x]
            ax.plot(
                x,
                y,
                ls=ls,
                marker="s" if d.loops else "o",
                ms=3,
                color=scene_color(k),
                label=name if energy == "exact" else None,
            )
    ax.set_yscale("log")
    ax.set_xlabel("kt")
    ax.set_ylabel(f"time to residual {LEVEL:g} / the scene's best")
    ax.set_title("kt sweep: exact energy solid, simplified dashed (missing: not reached)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def max_e_figure(results: D.Results, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    for k, (name, d) in enumerate(results.scenes.items()):
        runs = [r for r in d.sweeps["max_e"] if r.settings.get("energy") == "exact"]
        x = [r.settings["max_e"] for r in runs]
        y = [max(r.distance, FLOOR) for r in runs]
        marker = "s" if d.loops else "o"
        ax.plot(x, y, marker=marker, ms=3, color=scene_color(k), label=name)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("max_e (J, exact energy)")
    ax.set_ylabel("final distance max|q - q*| (rad or m)")
    ax.set_title("What the stopping rule leaves: final error against max_e")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def scaling_figure(results: D.Results, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = measured_chains(results)
    n = np.array([row["n"] for row in rows], dtype=float)
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(14, 4.5))
    per_step = [solve_time(row) / max(solve_steps(row), 1) for row in rows]
    bare = [row["profile"]["median"]["bare_step"] for row in rows]
    a.plot(n, per_step, marker="^", label="KD, whole solve / steps")
    a.plot(n, bare, marker="o", label="bare aba + integrate")
    a.plot(n, bare[0] * n / n[0], color="grey", ls=":", label="O(n) from the first")
    a.set_ylabel("time per step (s)")
    a.legend(fontsize=8)
    done = [row["profile"]["status"] == "converged" for row in rows]
    b.plot(n, [solve_steps(row) for row in rows], marker="o", label="steps (defaults)")
    for k, ok in enumerate(done):
        if not ok:
            status, steps = rows[k]["profile"]["status"], solve_steps(rows[k])
            b.annotate(status, (n[k], steps), fontsize=7)
    b.set_ylabel("steps")
    b.legend(fontsize=8)
    times = [solve_time(row) for row in rows]
    c.plot(n, times, marker="s", label="solve time (defaults)")
    c.plot(n, times[0] * (n / n[0]) ** 2, color="grey", ls=":", label="n^2 from the first")
    for k, ok in enumerate(done):
        if not ok:
            c.annotate(rows[k]["profile"]["status"], (n[k], times[k]), fontsize=7)
    c.set_ylabel("wall time (s)")
    c.legend(fontsize=8)
    for ax in (a, b, c):
        ax.set_xlabel("chain length (joints)")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(True, alpha=0.3)
    fig.suptitle(
        "Chains of robots/make_chain.py (0.1 m, 0.1 kg links) released horizontal, default "
        f"settings (max_time {results.config.scaling_max_time:g} s)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


# --- the text ----------------------------------------------------------------------------------


def table(header: Sequence[str], rows: Sequence[Sequence[str]], right: Sequence[int] = ()) -> str:
    align = ["---:" if k in right else "---" for k in range(len(header))]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def header(results: D.Results) -> str:
    m = results.machine
    return f"""# Benchmarks: error against run time

Generated by `python benchmarks/report.py` (every part; about {fmt_minutes(results)} on this
machine), or part by part with `--sections {",".join(D.SECTIONS)}` (comma-separated; each part
below is replaced alone and says when it was measured; `--quick` makes a tiny run elsewhere).
Machine: {m["cpu"]}, {m["cores"]} cores, Python {m["python"]}, Pinocchio {m["pinocchio"]},
pinsettle {m["pinsettle"]}. **The machine was shared with other jobs while measuring**:
absolute times are noisy, so methods are compared by ratios within one run and by medians of
repeats. Do not edit by hand: every number below is measured by that command.

"""


#: How the scenes part measures, a template filled by summary_rules (every number in it is
#: a setting of the report or of the solver, quoted where it is set).
SUMMARY_RULES = """### How it is measured

**Mechanics.** The scenes are solved without joint stops (`limits = false`): the baselines have
none, so that every method solves the same problem. Stops are measured in the step cost and the
robot gallery below.

**Error.** For a configuration q, the *distance* `max |q - q*|` over the free joints (rad or m;
revolute angles compared modulo 2 pi) and the *residual* `max |tau_static(q)|` (gravity minus
springs and loads) divided by the scene's *force scale*, `max |tau_static(q0)|` at the start.
The static force, the stiffness and its verdict are the **independent physics** of
`benchmarks/independent.py`: the test reference `tests/scene_reference.py` (forces from
Pinocchio's generalized gravity, frames and Jacobians), the stiffness by central differences of
that force, the verdict from its eigenvalues; nothing of pinsettle's static force, stiffness or
verdict. q* is the exact equilibrium the run comes to rest at: its final pose refined by Newton's
method on that physics to round-off (least squares, so that neutral directions are left alone).
For a scene with isolated equilibria that is the scene's reference equilibrium (the tables say
how far from it each run landed); the UR5 and the Panda rest on a family of equilibria (a base
turning about the vertical, wrist turns), and each run is measured against the member it comes
to. The reference q* of a scene is kinetic damping with `polish=True` and
`max_e = {deep_max_e:g}`, refined the same way, checked stable or neutral by the independent
stiffness, and checked by one more independent Newton step (`check step` below: its size).

**Curves and time.** Kinetic damping (KD) runs with the default settings (kt = {kt:g},
`dt = "auto"`, `err`, `ds`, `polish = {polish}`) but `max_e = {deep_max_e:g}` and
`newton_takeover = False`, so that the damping alone goes on down to round-off and the curve
shows how its error falls (up to where the default run stops, at its stopping rule or where
Newton takes over at a damping event, its trajectory is the same); the default run itself is in
its own table, and the sweeps of `err`, `ds` and `max_e` are of the default settings. On trees the
default run is timed in C++ as the baselines are (`benchmarks/kd_profile.cpp`: a fresh solver
each repeat after one untimed solve, as `benchmarks/baselines.cpp` makes a fresh workspace for
each run; checked to take the same steps and Newton iterations as `pinsettle.solve`), and KD's
time to a level is that run's when its polish gets there before the curve does: timed from
Python, between calls that leave the caches to the interpreter, a microsecond-long solve takes
longer (the default run's table gives both). The curve comes
from a run with `trace_every = 1` and `trace_configurations = True` (at most
{curve_samples} samples: the trace halves its samples when full); its trajectory is checked
identical to the timed runs', which trace nothing. **Time to a level is the set-up plus the steps
to it at the run's measured time per step**, for every method alike: KD's set-up (its checks and
first step estimate, from the call of `solve` to the end of that estimate) is measured by
`benchmarks/kd_profile.cpp` on the same scene and charged in full, the rest of the solve's
`wall_time` (medians of up to {repeats} repeats, fewer for runs over
{repeat_budget:g} s) is spread over its steps (the estimates along the way and the final
stability check included); each baseline's set-up (its step and damping from the start) is timed
by the baseline program and charged in full too. "Time to a level" is the time from which the
error stays below it to the end of the run (a swing through q* does not count). Every KD run on
a scene is limited to {step_budget_factor} times the steps of the run that found the scene's
reference (at least {step_budget_min:,}; the dt sweep's runs to at least
{dt_sweep_seconds:g} s): a setting that keeps it from converging ends there, `max_steps`.

**Baselines**, on the same Pinocchio dynamics, C++ (`benchmarks/baselines.cpp`, built against
the installed package: `pinocchio::aba` in the world convention as KD's step,
`pinsettle::ForceElements`, timed inside the program
like the solver's `wall_time`), semi-implicit Euler. **Each gets what KD gets: the start, never
q\\*.** Its set-up linearises the mechanism at the start as KD's first step estimate does (M,
K = `pinsettle::computeStiffnessMatrix`, the static force; the explicit stability limit
`2 / omega_max` of `pinsettle::computeTimeScale` without stiff-mode scaling, which they do not
have):

- *viscous, joint dampers*: `a = ABA(q, v, tau - c v)`, the same c on every joint: what users of
  physics simulators do to let a robot settle. Rule: c damps the softest mode of the start's
  linearisation critically (`K phi = lambda M phi`, phi M-normalised, the smallest `|lambda|`
  above 1e-6 `omega_max^2`, `omega = sqrt|lambda|`; without one, `omega = omega_max`, as on a
  chain held horizontal, which has no stiffness there and moves only by the pull of gravity):
  `c = 2 omega / |phi|^2` (`|phi|^2 = nv / trace(M)` without a mode).
- *viscous, mass-proportional*: `a = ABA(q, v, tau) - c v` (damping `c M v`), dynamic
  relaxation's classic form: every mode decays at the rate c / 2. Rule: `c = 2 omega`.
- Their step: a safety factor (rule: {dt_safety:g}, KD's default `dt_safety`) times the
  stability limit of semi-implicit Euler with the damping, `4 / (r + sqrt(r^2 + 4
  omega_max^2))`, r = c max eig(M^-1) (joint dampers) or c (mass-proportional).
- *FIRE* (Bitzek et al., 2006), classic parameters (N_min 5, f_inc 1.1, f_dec 0.5, alpha_start
  0.1, f_alpha 0.99), power `P = F . v` with `F = -tau_static(q)` (one extra RNEA per step).
  Rule: dt_max twice the stability limit, dt0 = dt_max / 10, mixing
  `v <- (1 - alpha) v + alpha |v| F / |F|` in joint coordinates.
- *FIRE 2.0* (Guénolé et al., 2020, written from the paper's description): semi-implicit Euler
  with the mixing after the velocity update, N_delay 20 steps before the step grows and none of
  the first 20 steps shrinks it, alpha_start 0.25, dt_min = 0.02 dt0, half a step back
  (`q -= dt v / 2`) at P <= 0 before the velocity is zeroed, a stop after 2,000 uphill steps in a
  row. Rule as for FIRE.
- FIRE's mixing in the **mass-matrix metric** (sweep): `v <- (1 - alpha) v + alpha |v|_M d /
  |d|_M`, `d = M^-1 F` (one more ABA at zero velocity), `|v|_M^2 = v^T M v`.
- **Their sweeps**: the viscous ones over step safety {safeties} and c
  times {damping_factors} the rule's; FIRE and FIRE 2.0 over dt_max
  {fire_dt_maxes} times the stability limit, each in both metrics. A
  sweep run stops at a residual of {level:g} of the force scale (checked every 16 steps; FIRE has
  it every step) or after {sweep_max_time:g} s; *best* is the setting with the shortest time to
  that level on the scene (an oracle choice per scene, which favours the baselines), run again
  with its curve. The rule and the best run until the residual is below {baseline_target:g} of
  the force scale or {baseline_max_steps:,} steps or {baseline_max_time:g} s.
- A run that blows up (a non-finite value or a residual 1e6 times the start's) or stalls (FIRE:
  1,000 velocity resets without the residual falling tenfold; FIRE 2.0 also its 2,000 uphill
  steps in a row) is started again with every step halved, up to 6 times.
- `stiff_spring` (a 1e7 N/m spring next to a 10 kg pendulum) is a test of KD's stiff-mode
  scaling, which the baselines do not have: it is reported apart, out of the comparison's
  medians.
- *Newton* from the same start, in Python (its wall time is **not** comparable with the C++
  loops'; it is quoted per iteration for orientation): the stiffness matrix of
  `pinsettle.assess_stability` as Jacobian, least squares (rank cut 1e-10), full steps;
  *Newton + line search* halves a step until `|tau_static|_2` falls. At most 50 iterations; where
  it lands is judged with the independent stiffness.

**Closed loops** (scenes with `[[loop]]`: {loop_names}). The solver runs Pinocchio's constrained
dynamics and keeps the pose on the loops; the report measures the closed mechanism the same way,
with its own projections (Gauss-Newton on the loop errors of the independent reference). Its
start is the scene's start moved onto the loops, and the force scale is taken there. The residual
is the static force projected onto the motions the loops allow (the null space of the loops'
Jacobian: zero at an equilibrium of the closed mechanism; the loops' reactions take the rest).
Newton's step, for the references and the landings, is the reduced one, differenced along those
motions, each side moved back onto the loops. The distance is `max |q - q*|` over the free joints
as for a tree. The final constraint error of every KD run (the largest loop error, m) is measured
here from Pinocchio's frame placements and compared with the solver's
`Result.constraint_error`. The C++ baselines run unconstrained ABA and cannot close a loop: the
baselines run on trees only.

"""


def summary_rules(results: D.Results) -> str:
    config = results.config
    s = pinsettle.Settings()
    return SUMMARY_RULES.format(
        loop_names=", ".join(f"`{n}`" for n in loop_scenes(results)) or "none here",
        kt=s.kt,
        polish=s.polish,
        level=LEVEL,
        repeats=config.repeats,
        safeties=fmt_list(config.safeties),
        damping_factors=fmt_list(config.damping_factors),
        fire_dt_maxes=fmt_list(config.fire_dt_maxes),
        baseline_max_steps=D.BASELINE_MAX_STEPS,
        baseline_max_time=D.BASELINE_MAX_TIME,
        baseline_target=D.BASELINE_TARGET,
        curve_samples=D.CURVE_SAMPLES,
        deep_max_e=D.DEEP_MAX_E,
        dt_safety=D.DT_SAFETY,
        dt_sweep_seconds=D.DT_SWEEP_SECONDS,
        repeat_budget=D.REPEAT_BUDGET,
        step_budget_factor=D.STEP_BUDGET_FACTOR,
        step_budget_min=D.STEP_BUDGET_MIN,
        sweep_max_time=D.SWEEP_MAX_TIME,
    )


def scenes_table(results: D.Results) -> str:
    rows = []
    for name, d in results.scenes.items():
        ref = d.ref
        neutral = f", {ref.neutral_directions} neutral" if ref.neutral_directions else ""
        rows.append(
            [
                f"`{name}`",
                d.description,
                str(d.nv),
                str(d.loops) if d.loops else "-",
                str(d.mobility),
                f"{d.force_scale:.3g}",
                f"{ref.stability}{neutral} (min eig. {ref.min_eigenvalue:.3g})",
                fmt_e(ref.residual),
                fmt_e(ref.fd_step),
            ]
        )
    return "### Scenes\n\n" + table(
        [
            "scene",
            "what",
            "nv",
            "loops",
            "mobility",
            "force scale (N m or N)",
            "q*",
            "residual of q*",
            "check step (rad or m)",
        ],
        rows,
        right=(2, 3, 4, 5, 7, 8),
    )


METHOD_ORDER = (
    "kd_exact",
    "kd_simplified",
    *(f"{f}_{kind}" for f in D.BASELINES for kind in ("rule", "best")),
    "newton",
    "newton_ls",
)


def summary_table(results: D.Results) -> str:
    rows = []
    for name, d in results.scenes.items():
        for key in METHOD_ORDER:
            if key not in d.runs:
                continue
            run = d.runs[key]
            if key.endswith("_best") and run is d.runs.get(key[: -len("_best")] + "_rule"):
                continue  # the rule was the best
            cells = [f"`{name}`" if key == "kd_exact" else "", run.label]
            for level in D.RESIDUAL_LEVELS:
                cells += list(reach_cell(run, "residual", level))
            far = run.landing.from_reference
            where = landed(run)
            if run.landing.q is not None and far > 1e-6:
                where += f", {far:.2g} from the reference q*"
            cells += [
                run.status,
                fmt_e(run.distance) if run.landing.q is not None else "-",
                fmt_e(run.residual),
                fmt_e(run.extra["constraint_error"]) if d.loops else "-",
                where,
            ]
            rows.append(cells)
    lv = [f"{x:g}" for x in D.RESIDUAL_LEVELS]
    return (
        "### Summary\n\n"
        "Steps and wall time from which the relative residual stays below "
        f"{lv[0]} and {lv[1]} (median over the repeats, min-max in brackets); the run's end: "
        "status, distance from its rest q*, residual, and where it rests (the stability of q*). "
        "KD runs use `max_e = "
        f"{D.DEEP_MAX_E:g}` here (see above); a baseline's best row is left out when its rule "
        "was its best; Newton's times are Python's. For the scenes with closed loops, the final "
        "constraint error (largest loop error, m) and the reduced Newton; "
        + (trees_only(results) or "the baselines run on trees only")
        + ".\n\n"
        + table(
            [
                "scene",
                "method",
                f"steps to {lv[0]}",
                f"time to {lv[0]}",
                f"steps to {lv[1]}",
                f"time to {lv[1]}",
                "status",
                "final distance",
                "final residual",
                "constraint error (m)",
                "rests",
            ],
            rows,
            right=(2, 3, 4, 5, 7, 8, 9),
        )
    )


def _pairs(d: D.SceneData, kts: Sequence[float]) -> list[tuple[float, D.Run, D.Run]]:
    by = {(r.settings["energy"], r.settings["kt"]): r for r in d.sweeps["kt"]}
    return [(kt, by[("exact", kt)], by[("simplified", kt)]) for kt in kts]


def energy_tally(results: D.Results, kts: Sequence[float]) -> D.Record:
    """Steps to the level, simplified against exact, over the scenes and the given kt."""
    ratios, fewer, more, equal, missing = [], 0, 0, 0, []
    for name, d in results.scenes.items():
        for kt, e, s in _pairs(d, kts):
            a, b = steps_to(e), steps_to(s)
            if a is None or b is None:
                which = (
                    "both" if a is None and b is None else "exact" if a is None else "simplified"
                )
                missing.append(f"{name} kt={kt:g} ({which})")
                continue
            ratios.append(b / a)
            fewer += b < a
            more += b > a
            equal += b == a
    return {
        "ratios": ratios,
        "fewer": fewer,
        "more": more,
        "equal": equal,
        "missing": missing,
        "geomean": geomean(ratios),
    }


def cost_ratio(results: D.Results, name: str = "ur5") -> float:
    cost = results.step_cost.get(name)
    if not cost:
        return math.nan
    c = cost["ns_per_step"]
    return float(statistics.median(c["simplified"]) / statistics.median(c["exact"]))


def kt_scores(results: D.Results, energy: str) -> dict[float, list[float]]:
    """For each kt: steps to the level over the scene's best kt, per scene (inf: not reached)."""
    score: dict[float, list[float]] = {kt: [] for kt in results.config.kts}
    for d in results.scenes.values():
        steps = {
            r.settings["kt"]: steps_to(r) for r in d.sweeps["kt"] if r.settings["energy"] == energy
        }
        best = min((x for x in steps.values() if x is not None), default=None)
        for kt in results.config.kts:
            x = steps.get(kt)
            score[kt].append(math.inf if x is None or best is None else max(x, 1) / max(best, 1))
    return score


def best_kt(score: dict[float, list[float]]) -> float:
    def key(kt: float) -> tuple[int, float]:
        ratios = score[kt]
        return (sum(not math.isfinite(x) for x in ratios), geomean(ratios))

    return min(score, key=key)


#: The energy measures' verdict, by how the steps' and a step's ratios combine (simplified /
#: exact, within 5 % either way counts as a tie).
ENERGY_VERDICTS = {
    "exact": "**choose the exact measure** (the default): the simplified one is slower",
    "simplified": "the simplified measure is faster on these scenes",
    "tie": "the two are within 5 % of each other; the exact measure (the default) has units (J), "
    "so that its `max_e` means the same on every mechanism",
}


def energy_verdict(ratio: float) -> str:
    """The verdict for a time ratio simplified / exact (steps times cost per step)."""
    if ratio > 1.05:
        return ENERGY_VERDICTS["exact"]
    if ratio < 1 / 1.05:
        return ENERGY_VERDICTS["simplified"]
    return ENERGY_VERDICTS["tie"]


def energy_bullet(results: D.Results) -> list[str]:
    """Energy measure: steps (deterministic) over every scene and kt pair, and the cost per
    step."""
    t = energy_tally(results, results.config.kts)
    g, c = t["geomean"], cost_ratio(results)
    missing = f" Not reached: {', '.join(t['missing'])}." if t["missing"] else ""
    return [
        f"- **Energy measure**: over {len(t['ratios'])} scene and kt pairs of the kt sweep, the "
        f"simplified measure needed fewer steps to a residual of {LEVEL:g} in {t['fewer']}, more "
        f"in {t['more']} and as many in {t['equal']}; geometric mean of the step ratios "
        f"simplified / exact: {g:.2f}. One step with the simplified measure driving costs {c:.3f} "
        "times one with the exact measure (step_cost, UR5, medians of interleaved repeats): both "
        "are computed every step from the body velocities ABA produced, whichever drives the "
        f"detector. So {energy_verdict(g * c)}." + missing
    ]


def kt_score_text(kt: float, ratios: list[float]) -> str:
    bad = sum(not math.isfinite(x) for x in ratios)
    finite = [x for x in ratios if math.isfinite(x)]
    return f"kt = {kt:g}: {geomean(finite):.2f}" + (f" ({bad} not reached)" if bad else "")


def kt_bullets(results: D.Results) -> list[str]:
    """kt, by steps (the same loop: time follows steps), for each energy measure."""
    out = []
    for energy in ("exact", "simplified"):
        score = kt_scores(results, energy)
        chosen = best_kt(score)
        default = (
            " (the default)." if chosen == DEFAULTS.kt else f" (the default is {DEFAULTS.kt:g})."
        )
        out.append(
            f"- **kt** ({energy} energy): steps to a residual of {LEVEL:g} over the scene's "
            f"fewest, geometric mean over the {len(results.scenes)} scenes: "
            + "; ".join(kt_score_text(kt, ratios) for kt, ratios in score.items())
            + f". Best: **kt = {chosen:g}**"
            + default
        )
    return out


def baseline_bullets(
    results: D.Results, over_kd: str = "KD's with the default settings"
) -> list[str]:
    """The baselines, by time (their steps cost differently): at their rule and at their best,
    over KD's time (``over_kd`` names it)."""
    names = compared(results)
    out = []
    for family in BASELINES if names else ():
        best = {n: ratio_to_kd(results.scenes[n], f"{family}_best") for n in names}
        rule = {n: ratio_to_kd(results.scenes[n], f"{family}_rule") for n in names}
        out.append(
            f"- **{D.BASELINE_LABELS[family]}** (same dynamics, C++, the start only), its time to "
            f"a residual of {LEVEL:g} over {over_kd}: at its rule "
            f"{median_with_failures(rule)}; at its best {median_with_failures(best)}."
        )
    return out


def trees_only_bullet(results: D.Results) -> list[str]:
    if not loop_scenes(results):
        return []
    return [f"- The {trees_only(results)} (see Closed loops below)."]


def root_kind(run: D.Run) -> str:
    """Where a Newton run ended, in words: a stable root, no root, ..."""
    if run.landing.q is None:
        return "no root"
    kind = f"{'an' if run.stability[0] in 'aeiou' else 'a'} {run.stability} root"
    if run.landing.from_reference > 1e-6:
        kind += " other than the reference q*"
    return kind


def newton_bullets(results: D.Results) -> list[str]:
    out = []
    for key in ("newton", "newton_ls"):
        kinds: dict[str, list[str]] = {}
        for name, d in results.scenes.items():
            kinds.setdefault(root_kind(d.runs[key]), []).append(name)
        label = list(results.scenes.values())[-1].runs[key].label
        out.append(
            f"- **{label}** from the same start: "
            + "; ".join(f"{kind} on {', '.join(names)}" for kind, names in kinds.items())
            + "."
        )
    return out


def max_e_slope(d: D.SceneData) -> float | None:
    """The final distance's power of max_e on one scene (exact energy; log-log least squares)."""
    runs = [r for r in d.sweeps["max_e"] if r.settings.get("energy") == "exact"]
    x = [math.log(r.settings["max_e"]) for r in runs if r.distance > 0]
    y = [math.log(r.distance) for r in runs if r.distance > 0]
    return float(np.polyfit(x, y, 1)[0]) if len(x) >= 2 else None


def max_e_bullet(results: D.Results) -> list[str]:
    slopes = [p for p in map(max_e_slope, results.scenes.values()) if p is not None]
    if not slopes:
        return []
    return [
        f"- **max_e** (exact energy) sets the accuracy: the final distance goes as max_e^p "
        f"with p from {min(slopes):.2f} to {max(slopes):.2f} over the scenes (median "
        f"{statistics.median(slopes):.2f}; least squares, log-log), at a cost of steps "
        "(table below). With the simplified measure `max_e` has no unit of energy, so the "
        "same number stops at another accuracy on each mechanism."
    ]


def err_bullet(results: D.Results) -> list[str]:
    stalled: dict[float, list[str]] = {}
    for name, d in results.scenes.items():
        for r in d.sweeps["err"]:
            if r.status != "converged":
                stalled.setdefault(r.settings["err"], []).append(name)
    if not stalled:
        return []
    return [
        "- **err**: "
        + "; ".join(
            f"err = {err:g} kept {', '.join(names)} from converging"
            for err, names in stalled.items()
        )
        + " (a peak counts only when the energy rises and falls by more than err times "
        "itself within one step; a slow swing sampled by many steps does not, and goes "
        "undamped); the other values converged on every scene."
    ]


def backtrack_ratio(d: D.SceneData) -> float | None:
    """Steps to the level with backtracking over without (exact energy); None if one missed."""
    runs = {
        r.settings["backtrack"]: r for r in d.sweeps["backtrack"] if r.settings["energy"] == "exact"
    }
    a, b = steps_to(runs[False]), steps_to(runs[True])
    return b / a if a and b else None


def backtrack_bullet(results: D.Results) -> list[str]:
    on_off = [x for x in map(backtrack_ratio, results.scenes.values()) if x is not None]
    if not on_off:
        return []
    return [
        f"- **Backtracking** (exact energy): steps to a residual of {LEVEL:g} on / off, "
        f"geometric mean {geomean(on_off):.2f} (from {min(on_off):.2f} to {max(on_off):.2f}; "
        f"fewer on {sum(x < 1 for x in on_off)} of {len(on_off)} scenes)."
    ]


def dt_bullet(results: D.Results) -> list[str]:
    scenes = results.scenes
    failed: dict[str, list[str]] = {}
    for name, d in scenes.items():
        for r in d.sweeps["dt"]:
            if steps_to(r) is None:
                failed.setdefault(r.label, []).append(name)
    if not failed:
        return []
    auto = sum(steps_to(d.sweeps["dt"][0]) is not None for d in scenes.values())
    return [
        f"- **Time step**: a residual of {LEVEL:g} was not reached with "
        + "; ".join(f"`{label}` on {', '.join(names)}" for label, names in failed.items())
        + f"; with the automatic step (the default) on {auto} of the {len(scenes)} scenes."
    ]


def stiff_mode_bullets(results: D.Results) -> list[str]:
    """What the stiff-mode scaling does (the baselines have none)."""
    out = []
    for name, d in results.scenes.items():
        scaled = d.runs["kd_exact"].extra.get("scaled_modes", 0)
        if not scaled:
            continue
        runs = {r.label: r for r in d.sweeps["dt"]}
        out.append(
            f"- On `{name}` the automatic step slowed {scaled} stiff mode"
            + ("s" if scaled > 1 else "")
            + f" (added inertia). Steps and time to a residual of {LEVEL:g} with it: "
            + outcome_steps_time(runs["auto"])
            + "; without it (`scale_stiff_modes = False`): "
            + outcome_steps_time(runs["auto, unscaled"])
            + ". The baselines have no such scaling: their step is set by the stiff mode."
        )
    return out


def rests_bullet(results: D.Results) -> list[str]:
    scenes = results.scenes
    kd_ok = [
        name
        for name, d in scenes.items()
        if all(d.runs[k].stability in ("stable", "neutral") for k in ("kd_exact", "kd_simplified"))
    ]
    return [
        f"- KD came to a stable or neutral rest on {len(kd_ok)} of the {len(scenes)} scenes with "
        "both energy measures."
    ]


def conclusions(results: D.Results) -> str:
    # The bullets of "In short", in their order: each a list of lines (empty: not measured).
    bullets = (
        energy_bullet,
        kt_bullets,
        baseline_bullets,
        trees_only_bullet,
        newton_bullets,
        max_e_bullet,
        err_bullet,
        backtrack_bullet,
        dt_bullet,
        stiff_mode_bullets,
        closed_loops_short,
        rests_bullet,
    )
    out = ["### In short\n"]
    for bullet in bullets:
        out += bullet(results)
    return "\n".join(out) + "\n\n"


def closed_loops_short(results: D.Results) -> list[str]:
    """The "Closed loops" paragraph of the short section: steps and time to the level on each
    loop scene, the constraint error at the end, the cost of a step against a bare constrained
    step."""
    names = loop_scenes(results)
    if not names:
        return []
    parts, worst = [], 0.0
    for name in names:
        d = results.scenes[name]
        run = d.runs["kd_exact"]
        hit = run.reach("residual", LEVEL)
        reached = (
            f"{fmt_steps(hit[0])} steps, {fmt_time(hit[1])}"
            if hit is not None
            else f"not reached ({run.status}, residual {fmt_e(run.residual)})"
        )
        ratio = loop_cost_ratio(results, name)
        cost = (
            f"; a step costs {ratio:.2f} times a bare `pinocchio::constraintDynamics` + "
            "`integrate` step"
            if math.isfinite(ratio)
            else ""
        )
        parts.append(
            f"`{name}` ({d.loops} loop{'s' if d.loops != 1 else ''}, nv {d.nv}, mobility "
            f"{d.mobility}): {reached}, final constraint error "
            f"{fmt_e(run.extra['constraint_error'])} m{cost}"
        )
        worst = max(worst, worst_constraint_error(d))
    bound = 1e-10
    verdict = "below" if worst < bound else "**above**"
    return [
        f"- **Closed loops**: kinetic damping (exact energy, default kt = "
        f"{pinsettle.Settings().kt:g}) to a residual of "
        f"{LEVEL:g} (projected onto the motions the loops allow): "
        + "; ".join(parts)
        + f". The largest final constraint error over every KD run on these scenes (main runs "
        f"and sweeps) is {fmt_e(worst)} m, {verdict} {bound:g} m. The solver's step adds to "
        "Pinocchio's constrained dynamics the projections of q onto the loops and of v onto the "
        "motions they allow (`benchmarks/loop_step_cost.cpp`, medians of interleaved repeats; "
        "the bare step holds the loops with Baumgarte's correction instead). Newton from the "
        "start is the reduced Newton (see How it is measured)."
    ]


def closed_loops_section(results: D.Results) -> str:
    names = loop_scenes(results)
    if not names:
        return ""
    rows = []
    for name in names:
        d = results.scenes[name]
        for key in ("kd_exact", "kd_simplified"):
            run = d.runs[key]
            rows.append(
                [
                    f"`{name}`" if key == "kd_exact" else "",
                    f"{d.loops}, {d.mobility}" if key == "kd_exact" else "",
                    f"{d.statics.assembly_distance:.3g}" if key == "kd_exact" else "",
                    run.label,
                    *reach_cell(run, "residual", LEVEL),
                    fmt_e(run.extra["constraint_error"]),
                    fmt_e(run.extra["solver_constraint_error"]),
                    fmt_e(run.extra["constraint_error_along"]),
                    fmt_time(run.per_step),
                    fmt_e(worst_constraint_error(d)) if key == "kd_exact" else "",
                ]
            )
    return (
        "### Closed loops\n\n"
        "The scenes with `[[loop]]`: loop closures and mobility (degrees of freedom), how far "
        "the start moved to close the loops (rad or m), and for kinetic damping "
        f"(`max_e = {D.DEEP_MAX_E:g}`) the steps and time to a residual of {LEVEL:g}, the final "
        "constraint error (largest loop error of the final q, m) measured here from Pinocchio's "
        "frame placements and as the solver reports it (`Result.constraint_error`), the largest "
        "over the traced run's samples, the time per step (whole solve / steps: the solve's "
        "set-up included, the assembly of the start, the step estimates, the final stability "
        "check) and the largest final constraint error over every KD run on the scene (these "
        "and all the sweeps'). The "
        + trees_only(results)
        + "; Newton from the start is the reduced Newton (summary above, baselines section).\n\n"
        + table(
            [
                "scene",
                "loops, mobility",
                "start moved",
                "method",
                f"steps to {LEVEL:g}",
                f"time to {LEVEL:g}",
                "constraint error",
                "solver's",
                "largest along the run",
                "time per step",
                "largest over every KD run",
            ],
            rows,
            right=(2, 4, 5, 6, 7, 8, 9, 10),
        )
        + "\n"
        + loop_cost_table(results)
    )


def loop_cost_table(results: D.Results) -> str:
    """benchmarks/loop_step_cost: the solver's step on each loop scene against a bare
    constrained step, with the open tree's bare ABA step for scale."""
    names = [n for n in loop_scenes(results) if n in results.loop_step_cost]
    if not names:
        return ""
    rows = []
    for name in names:
        cost = results.loop_step_cost[name]
        c = cost["ns_per_step"]
        cells = [
            fmt_spread([x * 1e-9 for x in c[key]])
            + f", **{loop_cost_ratio(results, name, key):.2f}**"
            for key in ("bare_tree", "exact", "simplified")
        ]
        rows.append(
            [
                f"`{name}`",
                f"{cost['nv']}, {cost['rows']}",
                fmt_spread([x * 1e-9 for x in c["bare"]]),
                *cells,
                f"{cost['settled_steps']:,}",
                fmt_e(cost["constraint_error"]),
            ]
        )
    first = results.loop_step_cost[names[0]]
    return (
        "\nThe cost of one step (`benchmarks/loop_step_cost.cpp`, in the same run, "
        f"{first['steps']:,} steps, {len(first['ns_per_step']['bare'])} interleaved repeats): a "
        "bare `pinocchio::constraintDynamics` + `pinocchio::integrate` step with the solver's "
        "constraint models and proximal settings, holding the loops with Baumgarte's correction "
        "(Pinocchio's corrector gains) instead of projections, against the solver's step "
        "(constrained dynamics, both energy measures, peak detection, integration, the "
        "projections of q onto the loops and of v onto the motions they allow), and a bare "
        "`pinocchio::aba` step on the open tree (the loops cut) for scale; median (min-max) and "
        "in bold the ratio of the medians to the bare constrained step. Every run starts at rest "
        "on the loops at the scene's start under gravity alone; the solver runs with kt = 0.99 "
        "and `max_e = 0` (it never stops early: the steps it took are in the table, and its "
        "constraint error at the end).\n\n"
        + table(
            [
                "scene",
                "nv, loop equations",
                "bare constraintDynamics",
                "bare aba, open tree",
                "pinsettle (exact)",
                "pinsettle (simplified)",
                "solver's steps",
                "constraint error (m)",
            ],
            rows,
            right=(2, 3, 4, 5, 6, 7),
        )
        + "\n"
    )


def figures_section(results: D.Results, figures: str) -> str:
    parts = [
        "### Error against wall time and against steps\n\n"
        "One figure per scene: distance (top) and relative residual (bottom) against wall time "
        "(left: steps times the run's measured time per step; Newton: Python's elapsed time per "
        "iteration) and against steps (right: ABA evaluations; constrained-dynamics evaluations on "
        "the scenes with closed loops, whose figures have no baselines). Dotted lines: the "
        f"residual levels of the summary. Values below {FLOOR:g} are drawn at {FLOOR:g}.\n"
    ]
    for name in results.scenes:
        parts.append(f"![{name}]({figures}/{name}.png)\n")
    return "\n".join(parts) + "\n"


def energy_section(results: D.Results) -> str:
    rows = []
    for name, d in results.scenes.items():
        e, s = d.runs["kd_exact"], d.runs["kd_simplified"]
        cells = [f"`{name}`"]
        cells.append(f"{e.time / e.steps * 1e9:.0f} / {s.time / s.steps * 1e9:.0f}")
        cells.append(f"{peaks_to(e)} / {peaks_to(s)}")
        for level in D.DISTANCE_LEVELS:
            a, b = e.reach("distance", level), s.reach("distance", level)
            cells.append(f"{fmt_steps(a and a[0])} / {fmt_steps(b and b[0])}")
        for level in D.RESIDUAL_LEVELS:
            a, b = e.reach("residual", level), s.reach("residual", level)
            cells.append(f"{fmt_steps(a and a[0])} / {fmt_steps(b and b[0])}")
        cells.append(f"{fmt_time(time_to(e))} / {fmt_time(time_to(s))}")
        rows.append(cells)
    head = ["scene", "ns per step", f"peaks before residual {LEVEL:g}"]
    head += [f"steps to distance {x:g}" for x in D.DISTANCE_LEVELS]
    head += [f"steps to residual {x:g}" for x in D.RESIDUAL_LEVELS]
    head += [f"time to residual {LEVEL:g}"]
    text = (
        "### Exact against simplified energy\n\n"
        "The peak detector's signal: the exact kinetic energy `sum 1/2 m v^2 + 1/2 w^T I w` (J) "
        "against the simplified `sum v^2 + w^2`. Each cell is exact / simplified, kt = "
        f"{DEFAULTS.kt:g} (the default), "
        f"`max_e = {D.DEEP_MAX_E:g}` (in each measure's own unit; the levels are reached long "
        "before either stops). Time per step is the whole solve's `wall_time / steps` (median of "
        "the repeats), estimates of the automatic step and stability checks included.\n\n"
        + table(head, rows, right=tuple(range(1, len(head))))
    )
    # Across kt, by steps (the cost per step is the same).
    rows = []
    for kt in results.config.kts:
        t = energy_tally(results, [kt])
        rows.append(
            [
                f"{kt:g}",
                str(t["fewer"]),
                str(t["more"]),
                str(t["equal"]),
                str(len(t["missing"])),
                f"{t['geomean']:.2f}",
            ]
        )
    text += (
        f"\nAcross the kt sweep, steps to a residual of {LEVEL:g}: the scenes where the "
        "simplified measure needed fewer, more or as many steps as the exact one, those where one "
        "of the two did not get there, and the geometric mean of the step ratios simplified / "
        "exact:\n\n"
        + table(
            ["kt", "fewer", "more", "as many", "not reached", "ratio"],
            rows,
            right=(1, 2, 3, 4, 5),
        )
    )
    return text + "\n"


def kt_section(results: D.Results, figures: str) -> str:
    kts = results.config.kts
    rows = []
    for name, d in results.scenes.items():
        by = {(r.settings["energy"], r.settings["kt"]): r for r in d.sweeps["kt"]}
        cells = [f"`{name}`"]
        for kt in kts:
            e, s = by[("exact", kt)], by[("simplified", kt)]
            cells.append(f"{outcome_time(e)} / {outcome_time(s)}")
        rows.append(cells)
    return (
        "### kt\n\n"
        f"Time to a residual of {LEVEL:g} (exact / simplified energy; `max_e = "
        f"{D.DEEP_MAX_E:g}`, other settings default; median of the repeats):\n\n"
        + table(
            ["scene", *[f"kt = {kt:g}" for kt in kts]], rows, right=tuple(range(1, len(kts) + 1))
        )
        + f"\n![kt sweep]({figures}/kt.png)\n\n"
    )


def stopping_section(results: D.Results, figures: str) -> str:
    text = (
        "### The stopping rule: err, ds, max_e\n\n"
        f"Each setting varied alone, the others at their defaults (kt = {DEFAULTS.kt:g}, "
        f"{DEFAULTS.energy} energy, `max_e = {DEFAULTS.max_e:g}`, `ds = {DEFAULTS.ds}`, "
        f"`err = {DEFAULTS.err:g}`, `polish = {DEFAULTS.polish}`). Each cell: final distance "
        "from the rest "
        "the run ends near (rad or m), steps, time (median of the repeats); the status when not "
        "converged.\n\n"
    )
    names = list(results.scenes)
    for key, label in (("err", "err"), ("ds", "ds"), ("max_e", "max_e")):
        rows = []
        runs_by_value: dict[tuple[str, float], dict[str, D.Run]] = {}
        for name in names:
            for r in results.scenes[name].sweeps[key]:
                by = (r.settings.get("energy", "exact"), r.settings[key])
                runs_by_value.setdefault(by, {})[name] = r
        for (energy, value), runs in runs_by_value.items():
            cells = [f"{value:g}" + (f" ({energy})" if key == "max_e" else "")]
            for name in names:
                r = runs[name]
                status = "" if r.status == "converged" else f" **{r.status}**"
                cells.append(f"{fmt_e(r.distance)}, {r.steps:,}, {fmt_time(r.time)}{status}")
            rows.append(cells)
        text += f"**{label}**\n\n" + table([label, *[f"`{n}`" for n in names]], rows) + "\n"
    text += (
        "With the simplified measure `max_e` is in m^2/s^2 + rad^2/s^2, not J: the same number "
        "stops at another accuracy on each mechanism.\n\n"
        f"![max_e sweep]({figures}/max_e.png)\n\n"
    )
    return text


def backtrack_section(results: D.Results) -> str:
    rows = []
    for name, d in results.scenes.items():
        for energy in ("exact", "simplified"):
            runs = {
                r.settings["backtrack"]: r
                for r in d.sweeps["backtrack"]
                if r.settings["energy"] == energy
            }
            cells = [f"`{name}`" if energy == "exact" else "", energy]
            for flag in (False, True):
                r = runs[flag]
                cells += [fmt_steps(steps_to(r)), fmt_time(time_to(r)), f"{r.peaks:,}"]
            rows.append(cells)
    return (
        "### Peak backtracking\n\n"
        "`backtrack = True` moves the configuration back to the parabola-interpolated peak "
        f"before damping. Steps and time to a residual of {LEVEL:g}, and the peaks (damping "
        f"events) of the whole run (`max_e = {D.DEEP_MAX_E:g}`):\n\n"
        + table(
            [
                "scene",
                "energy",
                "off: steps",
                "off: time",
                "off: peaks",
                "on: steps",
                "on: time",
                "on: peaks",
            ],
            rows,
            right=(2, 3, 4, 5, 6, 7),
        )
        + "\n"
    )


def dt_section(results: D.Results) -> str:
    labels = [r.label for r in next(iter(results.scenes.values())).sweeps["dt"]]
    rows = []
    for name, d in results.scenes.items():
        cells = [f"`{name}`"]
        for r in d.sweeps["dt"]:
            halvings = r.extra.get("dt_reductions", 0)
            cells.append(outcome_steps_time(r) + (f", {halvings} halvings" if halvings else ""))
        rows.append(cells)
    return (
        "### Fixed against automatic dt\n\n"
        f"Steps and time to a residual of {LEVEL:g} (exact energy, kt = {DEFAULTS.kt:g}, "
        f"`max_e = {D.DEEP_MAX_E:g}`): `auto` (the default: re-estimated as the mechanism moves, "
        "stiff modes slowed), `auto, unscaled` (`scale_stiff_modes = False`), `fixed, start` "
        "(`dt` fixed at the automatic step's first estimate, stiff modes slowed: the step "
        "at the start; a fixed step has no scaling, no re-estimates and no bound on the turn per "
        "step) and a quarter of it. `halvings`: the divergence guard's step halvings.\n\n"
        + table(["scene", *labels], rows)
        + "\n"
    )


def baselines_section(results: D.Results) -> str:
    return comparison_section(results) + newton_section(results)


COST_ROWS = (
    ("bare", "bare aba + integrate"),
    ("exact", "KD step, exact energy"),
    ("simplified", "KD step, simplified energy"),
    ("no_elements", "a scene without elements"),
    ("joint_springs", "a joint spring on every joint"),
    ("point_spring", "one point spring"),
    ("stops", "the model's joint stops"),
)


def cost_section(results: D.Results) -> str:
    names = list(results.step_cost)
    rows = []
    for key, label in COST_ROWS:
        cells = [label]
        for name in names:
            c = results.step_cost[name]["ns_per_step"]
            if not c.get(key):
                cells.append("-")
                continue
            t = [x * 1e-9 for x in c[key]]
            ratio = cost_median(results, name, key) / cost_median(results, name, "bare")
            cells.append(fmt_spread(t) + ("" if key == "bare" else f", **{ratio:.2f}**"))
        rows.append(cells)
    rows.append(
        ["stops / no stops"]
        + [
            f"**{stops_ratio(results, n):.2f}** "
            f"({plural(results.step_cost[n]['stop_count'], 'stop')}, "
            f"{results.step_cost[n]['stop_contacts']} resting at the end)"
            for n in names
        ]
    )
    info = ", ".join(
        f"{n} (nv = {results.step_cost[n]['nv']}, {results.step_cost[n]['steps']:,} steps, "
        f"{len(results.step_cost[n]['ns_per_step']['bare'])} repeats)"
        for n in names
    )
    limit = [
        f"{n} {stops_ratio(results, n):.2f}" for n in ("ur5", "panda") if n in results.step_cost
    ]
    verdict = ""
    if limit:
        worst = max(stops_ratio(results, n) for n in ("ur5", "panda") if n in results.step_cost)
        verdict = (
            f"\n\n**Joint stops** (issue 18: a step with stops at most 1.1 times today's step on "
            f"the UR5 and the Panda): {', '.join(limit)}: "
            + ("met." if worst <= 1.1 else "**not met**.")
            + " The run with stops starts as the others and comes to rest against some of them "
            "(the joints resting at the end in the last row); the run without stops passes "
            "through them."
        )
    return (
        "`benchmarks/step_cost.cpp`, in the same run: time per step of a bare `pinocchio::aba` "
        "(world convention, as the solver's step) + `pinocchio::integrate` step against the "
        "solver's step on the same model (ABA, both energy measures, peak detection, stopping "
        "rule, integration, the automatic step's re-estimates), repeats interleaved, median "
        "(min-max) and in bold the ratio of the medians to the bare step; the last row is the "
        "step with the model's position limits as "
        "joint stops (`JointStops`) over the same step without them. Every run starts at rest "
        "0.3 rad from neutral in every joint; the solver runs with kt = 0.99 and `max_e = 0`, so "
        "that it damps at every peak but never stops and its velocity never reaches subnormal "
        f"numbers (see the file's header). Models: {info}."
        + verdict
        + "\n\n"
        + table(["", *names], rows, right=tuple(range(1, len(names) + 1)))
        + "\n"
        + loop_cost_table(results)
    )


def solve_time(row: D.Record) -> float:
    """A scaling chain's default solve, timed whole with its polish (median of the repeats; the
    profile's parts are timed in the same solve without it)."""
    return float(row["profile"]["median"]["polish_wall"])


def solve_steps(row: D.Record) -> int:
    """The steps of a scaling chain's default solve (solve_time's): with Newton's takeover they
    may be fewer than the profile's plain solve took."""
    p = row["profile"]
    return int(p.get("polish_steps", p["steps"]))


def measured_chains(results: D.Results) -> list[D.Record]:
    """The chains of the scaling section that pinsettle took (not refused)."""
    return [row for row in results.scaling if "refused" not in row]


def refused_chains(results: D.Results) -> list[D.Record]:
    """The chains of the scaling section that pinsettle refused (their rows hold its message)."""
    return [row for row in results.scaling if "refused" in row]


def unfinished_chains(results: D.Results) -> str:
    """The chains of the scaling section that did not converge in time and those pinsettle
    refused, in words ('' when every chain converged)."""
    refused = [row["n"] for row in refused_chains(results)]
    unconverged = [
        row["n"]
        for row in measured_chains(results)
        if row.get("profile", {}).get("status") != "converged"
    ]
    parts = []
    if unconverged:
        parts.append(
            f"{', '.join(map(str, unconverged))} links did not converge within "
            f"{results.config.scaling_max_time:g} s"
        )
    if refused:
        parts.append(f"{', '.join(map(str, refused))} links were refused")
    return "; ".join(parts)


def refusals(results: D.Results) -> str:
    refused = refused_chains(results)
    if not refused:
        return ""
    return (
        ", ".join(f"{row['n']}" for row in refused)
        + " links: pinsettle refuses the model: "
        + str(refused[0]["refused"]).strip().splitlines()[-1]
        + "\n\n"
    )


def pair_slope(a: D.Record, b: D.Record) -> float:
    """The exponent of the solve time between two chain lengths."""
    return slope([a["n"], b["n"]], [solve_time(a), solve_time(b)])


def scaling_row(row: D.Record) -> list[str]:
    """One chain length's row of the scaling table."""
    if "refused" in row:
        return [str(row["n"]), "**refused**", *["-"] * 11]
    p = row["profile"]
    m = p["median"]
    wall, steps = solve_time(row), max(solve_steps(row), 1)
    deep = row.get("deep")
    return [
        str(row["n"]),
        f"{p['status']}",
        f"{solve_steps(row):,}",
        fmt_time(wall),
        fmt_time(wall / steps),
        fmt_time(m["bare_step"]),
        f"{wall / steps / m['bare_step']:.2f}",
        f"{fmt_time(m['setup'])} ({m['setup'] / m['wall']:.0%})",
        f"{p['estimate_count']}: {m['estimates'] / m['wall']:.0%}",
        f"{p['assessment_count']}: {m['assessments'] / m['wall']:.0%}",
        fmt_e(row["residual"]),
        fmt_steps(steps_to(deep)) if deep else "-",
        fmt_time(time_to(deep)) if deep else "-",
    ]


def converged_chains(results: D.Results) -> list[D.Record]:
    """The chains whose default solve converged: the ones the growth is fitted over."""
    return [r for r in measured_chains(results) if r["profile"]["status"] == "converged"]


def scaling_fits(results: D.Results) -> str:
    """The growth of steps, step and time over the converged lengths, and goal 5's verdict."""
    done = converged_chains(results)
    if len(done) < 2:
        return ""
    n = [r["n"] for r in done]
    wall = [solve_time(r) for r in done]
    steps = [solve_steps(r) for r in done]
    per = [w / s for w, s in zip(wall, steps, strict=True)]
    bare = [r["profile"]["median"]["bare_step"] for r in done]
    fits = (
        f"Least-squares fits (log-log) over the converged lengths ({n[0]} to {n[-1]}): steps "
        f"grow as n^{slope(n, steps):.2f}, time per step as n^{slope(n, per):.2f} (the bare "
        f"step as n^{slope(n, bare):.2f}: ABA is O(n)), time as n^{slope(n, wall):.2f}. "
    )
    pairs = [(a, b) for a, b in zip(done, done[1:], strict=False) if b["n"] >= 2 * a["n"]]
    local = [f"{a['n']} to {b['n']}: n^{pair_slope(a, b):.2f}" for a, b in pairs]
    if local:
        fits += "Between neighbours, time grows as " + ", ".join(local) + ". "
    verdict = slope(n, wall) <= 2.0 and all(pair_slope(a, b) <= 2.0 for a, b in pairs)
    unfinished = unfinished_chains(results)
    return (
        fits
        + "**Goal 5 of issue 20** (time no faster than n^2 over 5 to 1,000 links, a step O(n)): "
        + ("met over the converged lengths" if verdict else "**not met**")
        + (f"; {unfinished} (**not met** there)" if unfinished else "")
        + ".\n\n"
    )


SCALING_COLUMNS = (
    "links",
    "status",
    "steps",
    "time",
    "per step",
    "bare step",
    "ratio",
    "set-up",
    "estimates",
    "assessments",
    "final residual",
    f"steps to {LEVEL:g}",
    f"time to {LEVEL:g}",
)


def scaling_section(results: D.Results, figures: str) -> str:
    config = results.config
    return (
        "Chains of `robots/make_chain.py` (0.1 m, 0.1 kg links) released horizontal, default "
        f"settings within `max_time = {config.scaling_max_time:g}` s, profiled by "
        "`benchmarks/kd_profile.cpp` (one run past "
        f"{config.deep_chain_max} links, else the median of up to "
        f"{config.sweep_repeats}): status, steps and wall time of the default solve (the "
        "polish and Newton's takeover included), time per step, a bare `aba` + `integrate` step "
        "and the ratio, the set-up, the step estimates and stability assessments (count: share "
        "of the solve's time with `polish = False`, the damping's own run), the final residual "
        "(relative, independent physics); up to "
        f"{config.deep_chain_max} links also the steps and time to a "
        f"residual of {LEVEL:g} (`max_e = {D.DEEP_MAX_E:g}`, `newton_takeover = False`).\n\n"
        + table(
            SCALING_COLUMNS,
            [scaling_row(row) for row in results.scaling],
            right=(0, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12),
        )
        + "\n"
        + refusals(results)
        + scaling_fits(results)
        + joint_inertia_table(results)
        + f"![scaling]({figures}/scaling.png)\n\n"
    )


def joint_inertia_table(results: D.Results) -> str:
    """The same chains with scale_joint_inertia on (an option, off by default), beside the
    default run."""
    rows = []
    for row in results.scaling:
        ji = row.get("joint_inertia")
        if ji is None:
            continue
        default = solve_time(row)
        rows.append(
            [
                str(row["n"]),
                ji["status"],
                f"{ji['steps']:,}",
                f"{row['profile']['steps']:,}",
                fmt_time(ji["seconds"]),
                f"{ji['seconds'] / default:.2f}",
                str(ji["scaled_joints"]),
                fmt_e(ji["residual"]),
                fmt_e(ji["distance"]),
            ]
        )
    if not rows:
        return ""
    return (
        "The same chains with `scale_joint_inertia = True` (off by default: a fictitious inertia "
        "per joint that brings its rate down towards the slowest joint's, docs/method.md), timed "
        "from Python (`pinsettle.solve`'s wall time, median of the same repeats): status, steps "
        "and the default run's, time and its ratio to the default run's above, the joints given "
        "an inertia, the final residual (relative) and the distance to straight down (rad).\n\n"
        + table(
            [
                "links",
                "status",
                "steps",
                "default steps",
                "time",
                "ratio",
                "joints",
                "final residual",
                "distance",
            ],
            rows,
            right=(0, 2, 3, 4, 5, 6, 7, 8),
        )
        + "\n"
    )


def write(results: D.Results, output: Path) -> None:
    """The parts measured in this run into output/benchmarks.md (the others kept) and their
    figures into output/benchmarks/; figures no part refers to any more are removed."""
    figures = "benchmarks"
    fig_dir = output / figures
    fig_dir.mkdir(parents=True, exist_ok=True)
    new = parts(results, fig_dir, figures)
    new["header"] = header(results)
    path = output / "benchmarks.md"
    existing = path.read_text(encoding="utf-8") if path.exists() else ""
    text = merge(existing, new)
    path.write_text(text, encoding="utf-8")
    for png in fig_dir.glob("*.png"):
        if f"({figures}/{png.name})" not in text:
            png.unlink()


# --- the README's summary ----------------------------------------------------------------------


def kd_key() -> str:
    """The main KD run: the default energy measure (its other settings are the defaults but
    max_e, see How it is measured)."""
    return f"kd_{pinsettle.Settings().energy}"


def compared(results: D.Results) -> list[str]:
    """The scenes of the baselines' comparison: trees, not reported apart."""
    return [n for n, d in results.scenes.items() if d.baseline_sweep and not d.apart]


def apart_scenes(results: D.Results) -> list[str]:
    return [n for n, d in results.scenes.items() if d.baseline_sweep and d.apart]


def kd_reach(d: D.SceneData) -> tuple[float, int] | None:
    """KD's time (s) and steps to the level with the default settings: from the curve of the run
    that goes on to round-off (the same trajectory as the default run up to where that stops), or
    the whole default run when it ends below the level sooner (its polish, after the trajectory,
    gets there)."""
    hit = d.runs[kd_key()].reach("residual", LEVEL)
    default = d.runs.get("kd_default")
    if default is not None and default.residual <= LEVEL and (hit is None or default.time < hit[1]):
        return default.time, default.steps
    return None if hit is None else (hit[1], int(hit[0]))


def kd_time(d: D.SceneData) -> float | None:
    """KD's time to the level with the default settings (kd_reach)."""
    reach = kd_reach(d)
    return None if reach is None else reach[0]


def ratio_to_kd(d: D.SceneData, key: str) -> float | None:
    """A baseline's time to the level over KD's (defaults); None when either did not get
    there."""
    tb, tk = time_to(d.runs[key]), kd_time(d)
    return None if tb is None or tk is None else tb / tk


def median_with_failures(values: dict[str, float | None]) -> str:
    """'median x over n scenes; k not reached (names)'."""
    ok = [v for v in values.values() if v is not None]
    failed = [n for n, v in values.items() if v is None]
    scenes = "scene" if len(ok) == 1 else "scenes"
    text = f"{statistics.median(ok):.2g} over {len(ok)} {scenes}" if ok else "no scene reached"
    if ok and len(ok) > 1:
        text += f" ({min(ok):.2g} to {max(ok):.2g})"
    return text + (f"; **{len(failed)} not reached** ({', '.join(failed)})" if failed else "")


def gallery_figure(results: D.Results, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = results.gallery
    fig, ax = plt.subplots(figsize=(11, 4.8))
    x = np.arange(len(rows))
    kd = [statistics.median(r["seconds"]) for r in rows]
    mj = [
        statistics.median(r["mujoco"]["seconds"])
        if r["mujoco"].get("status") == "settled"
        else np.nan
        for r in rows
    ]
    ax.bar(x - 0.2, kd, width=0.4, label="pinsettle, default settings", color="C0")
    ax.bar(
        x + 0.2,
        mj,
        width=0.4,
        label="MuJoCo, damped settle (missing: not loaded or not settled)",
        color="C1",
    )
    ax.set_xticks(x, [r["name"] for r in rows], rotation=60, ha="right", fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("wall time (s)")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("The robot gallery: root fixed, released from neutral")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def fmt_minutes(results: D.Results) -> str:
    if set(results.sections) == set(D.SECTIONS):
        return f"{results.seconds / 60:.1f} minutes"
    return "the sum of the parts' times below"


def stamp(results: D.Results, section: str) -> str:
    """The line that opens a part: when and how long it was measured, and the machine's load."""
    m = results.machine
    return (
        f"*Measured on {m['date']} (`--sections {section}`: "
        f"{results.section_seconds.get(section, 0.0):.0f} s); 1-minute load average "
        f"{m['load_start'][0]:.2f} before the run and {m['load_end'][0]:.2f} at its end, its "
        "own single-threaded process included.*\n\n"
    )


def fmt_list(values: Sequence[float]) -> str:
    return ", ".join(f"{v:g}" for v in values)


def defaults_section(results: D.Results) -> str:
    """Where the default settings stop (goal 2 of issue 20)."""
    s = pinsettle.Settings()
    rows = []
    for name, d in results.scenes.items():
        run = d.runs.get("kd_default")
        if run is None:
            continue
        rows.append(
            [
                f"`{name}`",
                run.status,
                f"{run.steps:,}",
                fmt_spread(run.seconds),
                fmt_spread(run.extra["python_seconds"]) if "python_seconds" in run.extra else "-",
                fmt_e(run.residual),
                "yes" if run.residual <= LEVEL else "**no**",
                str(run.extra.get("polish_iterations", 0)),
                landed(run),
            ]
        )
    return (
        "### The default settings\n\n"
        f"`pinsettle.solve(scene)` with nothing changed (kt = {s.kt:g}, `dt_safety = "
        f"{s.dt_safety}` ({s.effective_dt_safety:g}), `dt_growth = {s.dt_growth}` "
        f"({s.effective_dt_growth:g}), `backtrack = {s.backtrack}`, "
        f"`max_e = {s.max_e:g}`, "
        f"`polish = {s.polish}`, `energy = {s.energy}`): status, steps, wall time (median, "
        "min-max; on trees timed in C++ as the baselines are, `benchmarks/kd_profile.cpp`, and "
        "from Python too, `pinsettle.solve`'s own `wall_time`; with loops from Python only), the "
        "final residual relative to the force scale (independent physics), whether "
        f"it is at most {LEVEL:g} (goal 2 of issue 20), the polish's Newton iterations and where "
        "it rests.\n\n"
        + table(
            [
                "scene",
                "status",
                "steps",
                "time",
                "from Python",
                "final residual",
                f"<= {LEVEL:g}",
                "polish iterations",
                "rests",
            ],
            rows,
            right=(2, 3, 4, 5, 7),
        )
        + "\n"
    )


def baseline_cell(d: D.SceneData, key: str) -> str:
    """A baseline run's cell: its time over KD's in bold (its own in brackets), or why not."""
    run = d.runs[key]
    r = ratio_to_kd(d, key)
    t = time_to(run)
    if r is not None:
        return f"**{r:.2g}** ({fmt_time(t)})"
    return f"not reached ({run.status})" if t is None else f"({fmt_time(t)})"


def comparison_row(d: D.SceneData, name: str) -> list[str]:
    tk = kd_time(d)
    cells = [f"`{name}`", fmt_time(tk) if tk is not None else outcome_time(d.runs[kd_key()])]
    for family in BASELINES:
        cells += [baseline_cell(d, f"{family}_{kind}") for kind in ("rule", "best")]
    return cells


def comparison_bullet(results: D.Results, names: list[str], family: str) -> str:
    """One baseline family over KD, at its rule and at its best, and where its best wins."""
    rule = {n: ratio_to_kd(results.scenes[n], f"{family}_rule") for n in names}
    best = {n: ratio_to_kd(results.scenes[n], f"{family}_best") for n in names}
    sooner = [n for n, r in best.items() if r is not None and r < 1]
    wins = (
        f". Faster than KD at its best on {len(sooner)} of {len(names)}: " + ", ".join(sooner)
        if sooner
        else ". KD is faster on every scene it reached"
    )
    return (
        f"- **{D.BASELINE_LABELS[family]}**, its time over KD's: at its rule "
        f"{median_with_failures(rule)}; at its best {median_with_failures(best)}" + wins + "."
    )


def comparison_section(results: D.Results) -> str:
    """The baselines at their rule and at their best against KD's defaults, per scene."""
    names = compared(results)
    if not names:
        return ""
    head = ["scene", f"KD (defaults): time to {LEVEL:g}"]
    for family in BASELINES:
        head += [f"{D.BASELINE_LABELS[family]}: rule", "best"]
    rows = [comparison_row(results.scenes[name], name) for name in names]
    apart = apart_scenes(results)
    return (
        "### Baselines at their rule and at their best\n\n"
        f"Time to a residual of {LEVEL:g} of each baseline over KD's with the default settings "
        "(KD: the curve of the run that goes on to round-off, or the whole default run when it "
        "ends below the level, its polish included, whichever is sooner), per scene (in bold; "
        "below 1: the baseline is faster; its time in brackets), at its rule "
        "setting and at its best over its sweep (settings in the next table). Tree scenes"
        + (f", `{'`, `'.join(apart)}` apart (below)" if apart else "")
        + ".\n\n"
        + table(head, rows, right=tuple(range(1, len(head))))
        + "\n"
        + "\n".join(comparison_bullet(results, names, family) for family in BASELINES)
        + "\n\n"
        + settings_table(results)
        + sweep_tables(results)
        + apart_section(results)
    )


def settings_table(results: D.Results) -> str:
    rows = []
    for name, d in results.scenes.items():
        if not d.baseline_sweep:
            continue
        for family in BASELINES:
            rule, best = d.runs[f"{family}_rule"], d.runs[f"{family}_best"]
            e = rule.extra
            fire = family in ("fire", "fire2")
            coeffs = (
                f"dt0 {e['dt']:.3g}, dt_max {e['dt_max']:.3g}"
                if fire
                else f"dt {e['dt']:.3g}, c {e['damping']:.3g} (omega {e['omega_rule']:.3g})"
            )
            retried = f"{e['halvings']} ({', '.join(e['retries'])})" if e["halvings"] else "0"
            best_label = (
                "the rule"
                if best is rule
                else D.setting_label(family, best.settings)
                if time_to(best) is not None or best.status == "converged"
                else "-"
            )
            rows.append(
                [
                    f"`{name}`" if family == BASELINES[0] else "",
                    D.BASELINE_LABELS[family],
                    f"{e['limit']:.3g}",
                    coeffs,
                    f"{e['resets']:,}" if fire else "-",
                    retried,
                    best_label,
                ]
            )
    return (
        "The rule runs: the explicit stability limit at the start (s), their steps and "
        "coefficients (s; N m s/rad or 1/s; omega of the softest mode at the start, rad/s), "
        "FIRE's velocity resets, the retries with the steps halved (and why), and the setting "
        "that was best on the scene:\n\n"
        + table(
            ["scene", "baseline", "limit", "rule: steps and c", "resets", "retries", "best"],
            rows,
            right=(2, 4, 5),
        )
        + "\n"
    )


def sweep_tables(results: D.Results) -> str:
    text = (
        f"Each baseline's sweep: time to a residual of {LEVEL:g} (set-up and loop, median of "
        f"{results.config.sweep_repeats} repeats) or why not (`max_steps`, `time_limit` after "
        f"{D.SWEEP_MAX_TIME:g} s, `diverged`, `stalled`, after the retries); "
        "`h` counts the retries with every step halved; the rule's cell in bold.\n\n"
    )
    for family in BASELINES:
        settings = results.config.sweep(family)
        rows = []
        for name, d in results.scenes.items():
            points = d.baseline_sweep.get(family)
            if not points:
                continue
            cells = [f"`{name}`"]
            for p in points:
                cell = fmt_time(p.time_to) if p.time_to is not None else p.status
                if p.halvings:
                    cell += f", {p.halvings} h"
                if p.settings == D.BASELINE_RULES[family]:
                    cell = f"**{cell}**"
                cells.append(cell)
            rows.append(cells)
        text += (
            f"**{D.BASELINE_LABELS[family]}**\n\n"
            + table(
                ["scene", *[D.setting_label(family, s) for s in settings]],
                rows,
                right=tuple(range(1, len(settings) + 1)),
            )
            + "\n"
        )
    return text


def apart_section(results: D.Results) -> str:
    parts = []
    for name in apart_scenes(results):
        d = results.scenes[name]
        dt = {r.label: r for r in d.sweeps.get("dt", [])}
        cells = [f"KD (defaults): {outcome_steps_time(d.runs[kd_key()])}"]
        default = d.runs.get("kd_default")
        if default is not None:
            cells.append(
                f"the default run, polish included: {default.steps:,} steps, "
                f"{fmt_time(default.time)}, residual {fmt_e(default.residual)}"
            )
        if "auto, unscaled" in dt:
            cells.append(
                f"KD without stiff-mode scaling: {outcome_steps_time(dt['auto, unscaled'])}"
            )
        for family in BASELINES:
            for kind in ("rule", "best"):
                run = d.runs[f"{family}_{kind}"]
                if kind == "best" and run is d.runs[f"{family}_rule"]:
                    continue
                cells.append(f"{run.label}: {outcome_steps_time(run)}")
        parts.append(
            f"**`{name}`, apart** (a test of KD's stiff-mode scaling; "
            f"{d.runs[kd_key()].extra.get('scaled_modes', 0)} mode(s) slowed): steps and time "
            f"to a residual of {LEVEL:g}: " + "; ".join(cells) + ".\n"
        )
    return "\n".join(parts) + ("\n" if parts else "")


def newton_section(results: D.Results) -> str:
    rows = []
    for name, d in results.scenes.items():
        for key in ("newton", "newton_ls"):
            r = d.runs[key]
            rows.append(
                [
                    f"`{name}`" if key == "newton" else "",
                    r.label,
                    f"{r.steps}",
                    fmt_e(r.residual),
                    landed(r),
                    fmt_e(r.extra["min_eigenvalue"]) if r.landing.q is not None else "-",
                    fmt_e(r.distance) if r.landing.q is not None else "-",
                    f"{r.extra['largest_angle']:.3g}",
                    fmt_time(r.time),
                ]
            )
    return (
        "### Newton from the start\n\n"
        "Iterations, the residual it ends with, where it lands (a root: its stability and "
        "smallest stiffness eigenvalue by the independent physics, its distance from the "
        "reference q*), the largest entry of q in absolute value (rad or m: a step off to 1e15 "
        "rad means the stiffness matrix was near singular at the start) and Python's wall time. "
        "On the scenes with closed loops it is the reduced Newton, each step moved back onto the "
        "loops.\n\n"
        + table(
            [
                "scene",
                "method",
                "iterations",
                "residual",
                "lands",
                "min eig.",
                "distance from q*",
                "largest entry of q",
                "time (Python)",
            ],
            rows,
            right=(2, 3, 5, 6, 7, 8),
        )
        + "\n"
    )


def cost_median(results: D.Results, name: str, key: str) -> float:
    c = results.step_cost[name]["ns_per_step"]
    return statistics.median(c[key]) if c.get(key) else math.nan


def stops_ratio(results: D.Results, name: str) -> float:
    """A step with the model's joint stops over the same step without (step_cost medians)."""
    return cost_median(results, name, "stops") / cost_median(results, name, "exact")


#: The scenes of goal 4 of issue 20.
GOAL4_SCENES = ("ur5", "chain20", "chain100")


def overhead_rows(results: D.Results) -> list[D.Record]:
    """The overhead split per scene, as fractions of the solve's wall time (medians): of the
    plain solve (polish off), and of the default solve (its set-up, estimates, assessments and
    Newton's stiffness matrices; Newton's static-force evaluations, O(n) each, are left out)."""
    out = []
    for name, p in results.overhead.items():
        m = p["median"]
        wall = m["wall"]
        parts = {
            "setup": m["setup"],
            "estimates": m["estimates"],
            "assessments": m["assessments"],
        }
        overhead = sum(parts.values())
        # The default solve's own parts: with Newton's takeover it is not the plain run plus a
        # polish, but a run that Newton may end at a damping event.
        default_parts = (
            m["polish_setup"]
            + m["polish_estimates"]
            + m["polish_assessments"]
            + m["polish_stiffness"]
        )
        fraction_polish = default_parts / m["polish_wall"]
        out.append(
            {
                "name": name,
                "nv": p["nv"],
                "steps": p["steps"],
                "status": p["status"],
                "wall": wall,
                "parts": parts,
                "estimate_count": p["estimate_count"],
                "assessment_count": p["assessment_count"],
                "polish_iterations": p.get("polish_iterations", 0),
                "fraction": overhead / wall,
                "fraction_polish": fraction_polish,
                "default_wall": m["polish_wall"],
                "default_steps": p["polish_steps"],
                "bare": m["bare_step"] * p["steps"],
            }
        )
    return out


def goal4_verdict(rows: list[D.Record]) -> str:
    """Goal 4's shares (the damping's own run, polish off, and the default solve), met or not,
    and why not where the default solve's Newton is what passes the bound."""
    text = ", ".join(
        f"{r['name']} {r['fraction']:.1%} ({r['fraction_polish']:.1%} in the default solve)"
        for r in rows
    )
    worst = max(max(r["fraction"], r["fraction_polish"]) for r in rows)
    if worst <= 0.25:
        return text + ": met."
    newton = [r for r in rows if r["fraction"] <= 0.25 < r["fraction_polish"]]
    why = "".join(
        f" Why, on {r['name']} ({r['fraction_polish']:.2%}): the default solve's Newton (its "
        "tries at damping events and the polish) counts as overhead, and it replaces steps: "
        f"{r['default_steps']:,} steps and "
        f"{fmt_time(r['default_wall'])} against {r['steps']:,} steps and "
        f"{fmt_time(r['wall'])} with `polish = False`."
        for r in newton
    )
    return text + ": **not met**." + why


def overhead_row(r: D.Record) -> list[str]:
    w = r["wall"]
    p = r["parts"]
    return [
        f"`{r['name']}`",
        str(r["nv"]),
        f"{r['steps']:,} ({r['status']})",
        fmt_time(w),
        f"{fmt_time(p['setup'])} ({p['setup'] / w:.0%})",
        f"{r['estimate_count']}: {fmt_time(p['estimates'])} ({p['estimates'] / w:.0%})",
        f"{r['assessment_count']}: {fmt_time(p['assessments'])} ({p['assessments'] / w:.0%})",
        f"**{r['fraction']:.0%}**",
        f"{fmt_time(r['bare'])} ({r['bare'] / w:.0%})",
        f"{r['default_steps']:,}, {fmt_time(r['default_wall'])}, {r['polish_iterations']} it.",
        f"**{r['fraction_polish']:.0%}**",
    ]


OVERHEAD_COLUMNS = (
    "scene",
    "nv",
    "steps",
    "solve",
    "set-up",
    "estimates",
    "assessments",
    "overhead",
    "bare steps",
    "default solve",
    "its overhead",
)

OVERHEAD_INTRO = (
    "`benchmarks/kd_profile.cpp`: the solve with the default settings but `polish = False` "
    "(the default is `polish = {polish}`) timed whole (`wall_time`) and in its parts, by "
    "wrapping the library's "
    "`computeTimeScale` (step estimates), `assessStability` (rest checks and the final "
    "verdict) and `computeStiffnessMatrix` (the polish's Newton steps) at link time (`ld "
    "--wrap`: the solver's code is unchanged, each call timed, nested calls counted once): "
    "the *set-up* (from the call of `solve` to the end of the first step estimate: the checks "
    "and the first estimate), the later *step estimates* (count: time), the *stability "
    "assessments* (count: time), their sum as a fraction of the solve, the bare steps "
    "(the solve's steps times a bare `aba` + `integrate` step) for scale, and the *default "
    "solve* (`polish = True`, and with it Newton's takeover at damping events, which may "
    "end the run before the plain one ends: its steps, wall time and Newton iterations) "
    "with the same parts and the time of its stiffness matrices (Newton's) as a fraction of "
    "it; Newton's static-force evaluations, O(n) each, are left out. Medians of repeats "
    "(the default solves made one after the other, after the plain ones)."
)


def overhead_section(results: D.Results) -> str:
    goal = [r for r in overhead_rows(results) if r["name"] in GOAL4_SCENES]
    verdict = ""
    if goal:
        verdict = (
            "\n\n**Goal 4 of issue 20** (set-up, step estimates, stability assessments and polish "
            "at most 25% of a solve on the UR5, chain20 and chain100): " + goal4_verdict(goal)
        )
    rows = [overhead_row(r) for r in overhead_rows(results)]
    return (
        OVERHEAD_INTRO.format(polish=pinsettle.Settings().polish)
        + verdict
        + "\n\n"
        + table(OVERHEAD_COLUMNS, rows, right=tuple(range(1, 11)))
        + "\n"
    )


def slope(x: Sequence[float], y: Sequence[float]) -> float:
    """Least-squares exponent of y against x (log-log)."""
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def mujoco_ratio(row: D.Record) -> float | None:
    """MuJoCo's wall time over KD's on a robot both settle; None otherwise."""
    mj = row["mujoco"]
    if mj.get("status") != "settled" or row["status"] != "converged":
        return None
    return float(statistics.median(mj["seconds"]) / statistics.median(row["seconds"]))


MUJOCO_MEASURED = ("settled", "not settled", "diverged")


def mujoco_cells(mj: D.Record, scale: float) -> list[str]:
    """The MuJoCo columns of a gallery row ('-' where it did not run)."""
    if mj.get("status") not in MUJOCO_MEASURED:
        return [mj.get("status", "-"), "-", "-", "-", "-", "-", "-"]
    return [
        mj["status"],
        f"{mj['sim_time']:g} s",
        fmt_time(statistics.median(mj["seconds"]))
        + ("" if mj["status"] == "settled" else " (the budget, checks included)"),
        fmt_e(mj["residual"] / scale if scale > 0 else mj["residual"]),
        f"{max(mj['outside'], 0.0):.1e}",
        mj["stability"] if mj["stability"] != "unstable" else "**unstable**",
        f"{mj['distance']:.2g}",
    ]


def gallery_row(r: D.Record) -> list[str]:
    scale = r["force_scale"]
    rel = r["residual"] / scale if scale > 0 else math.nan
    ratio = mujoco_ratio(r)
    return [
        f"`{r['name']}`",
        str(r["nv"]),
        r["status"],
        f"{r['steps']:,}",
        fmt_time(statistics.median(r["seconds"])),
        ", ".join(f"{j} ({side})" for j, side in r["contacts"].items()) or "-",
        f"{r['stability']} ({r['verdict']})",
        fmt_e(rel if scale > 0 else r["residual"]),
        "yes" if r["outside"] <= 0 else f"**no** ({r['outside']:.1e})",
        *mujoco_cells(r["mujoco"], scale),
        f"**{ratio:.0f}**" if ratio is not None else "-",
    ]


GALLERY_COLUMNS = (
    "robot",
    "nv",
    "status",
    "steps",
    "time",
    "on a stop",
    "stability",
    "residual",
    "inside limits",
    "MuJoCo",
    "simulated",
    "MuJoCo time",
    "MuJoCo residual",
    "past a limit",
    "MuJoCo rests",
    "distance",
    "MuJoCo / KD",
)


def gallery_intro(results: D.Results) -> str:
    return (
        "Every robot `pinsettle robots` lists, root fixed (`floating = false`), released at rest "
        "from neutral with the default settings (`pinsettle.solve(model)`, joint stops from the "
        "URDF: issue 18), side by side with MuJoCo's damped settle of the same URDF in the same "
        f"run (MuJoCo {results.mujoco.get('version', '-')}). pinsettle: status, steps, wall "
        f"time (median of up to {D.GALLERY_KD_REPEATS} repeats), the joints resting on a stop and "
        "its stability verdict "
        "(in brackets the independent one); then **independently** (tests/scene_reference.py's "
        "physics and stops, Pinocchio's generalized gravity): the residual of a rest against "
        "the stops relative to the force scale at the start (absolute, N m, where that is 0), "
        "and whether every joint is inside its limits. MuJoCo: `benchmarks/gallery.py` strips "
        "the URDF's visual and collision elements (no meshes, no contacts) and its `<mimic>` "
        "tags (MuJoCo would couple those joints; pinsettle's model of the robot moves them "
        "freely, as `pinocchio.buildModelFromUrdf` does by default: the Panda's and Baxter's "
        "fingers, Talos' grippers), sets joint damping "
        f"{D.MUJOCO_DAMPING:g} on every degree of freedom and a "
        f"{D.MUJOCO_TIMESTEP * 1e3:g} ms step as its users do, keeps its URDF limits (MuJoCo "
        "honours them; equal limits are none, as in pinsettle) and steps from qpos = 0 "
        "(pinsettle's neutral; MuJoCo's soft limits push a start outside them back). "
        f"**Settled**: max |qvel| <= {D.MUJOCO_QVEL:g} (rad/s or m/s) and max |qacc| <= "
        f"{D.MUJOCO_QACC:g} at every check (every {D.MUJOCO_CHUNK} steps) for "
        f"{D.MUJOCO_QUIET:g} s of simulated time in a row, within "
        f"{results.config.mujoco_max_sim:g} s simulated. Its time is that of stepping the same "
        "number of steps again in one `mj_step(model, data, nstep)` call (no checks, no Python in "
        "between: MuJoCo is charged its steps alone; median of the repeats). Its pose is checked "
        "by the same independent physics: residual (relative), how far its worst joint is past a "
        "limit (rad or m; soft limits let a joint in a little), the stability of its rest (the "
        "independent stiffness restricted to the joints off their stops: MuJoCo's criterion "
        "also accepts a balance on a saddle) and its distance from pinsettle's rest (max |dq|, "
        "rad or m: near 0 for the same rest; a robot with neutral directions, such as a base "
        "turning freely, may come to another rest of the same family). Last column: MuJoCo's "
        "time over pinsettle's.\n\n"
    )


def mujoco_both(results: D.Results) -> dict[str, float]:
    """MuJoCo's time over pinsettle's, on the robots both settle."""
    ratios = {r["name"]: mujoco_ratio(r) for r in results.gallery}
    return {n: x for n, x in ratios.items() if x is not None}


def settled_inside(results: D.Results) -> list[str]:
    """The robots pinsettle settled inside their limits, not on an unstable rest."""
    return [
        r["name"]
        for r in results.gallery
        if r["status"] == "converged" and r["outside"] <= 0 and r["stability"] != "unstable"
    ]


def saddle_note(results: D.Results, both: dict[str, float]) -> str:
    """Where MuJoCo stopped on a saddle, and its ratio without those robots."""
    unstable = mujoco_saddle_stops(results.gallery, both)
    if not unstable:
        return ""
    text = (
        f" MuJoCo's settle ends on an unstable rest (a saddle its damped motion did not "
        f"leave) on {', '.join(unstable)}: there pinsettle pushes off and goes on to a "
        "stable rest, so the two times are of different answers."
    )
    fair = [both[n] for n in both if n not in unstable]
    if fair:
        text += (
            f" Without them, MuJoCo took {statistics.median(fair):.0f} times pinsettle's "
            f"time (median over {len(fair)}; {min(fair):.1f} to {max(fair):.0f})."
        )
    return text


def goal3_paragraph(both: dict[str, float]) -> str:
    if not both:
        return ""
    values = sorted(both.values())
    below = [f"{n} ({x:.1f})" for n, x in both.items() if x < 100]
    met = not below and statistics.median(values) >= 300
    return (
        f"\n\n**Goal 3 of issue 20** (at least 100 times faster than MuJoCo on every robot "
        f"both settle, median at least 300 times): over the {len(both)} robots both settle, "
        f"MuJoCo took {statistics.median(values):.0f} times pinsettle's time (median; "
        f"{values[0]:.1f} to {values[-1]:.0f})"
        + (f"; below 100 on {', '.join(below)}" if below else "")
        + (": met." if met else ": **not met**.")
    )


def floating_table(results: D.Results) -> str:
    if not results.floating:
        return ""
    rows = [
        [
            f"`{r['name']}`",
            str(r["nv"]),
            r["status"],
            f"{r['steps']:,}",
            fmt_spread(r["seconds"]),
            r["reason"] or "-",
        ]
        for r in results.floating
    ]
    return (
        "The floating-base robots with their free-flyer (`floating = true`), default "
        "settings: they fall (no ground), and the solver should say `no_equilibrium` "
        "quickly.\n\n"
        + table(["robot", "nv", "status", "steps", "time", "reason"], rows, right=(1, 3, 4))
        + "\n"
    )


def gallery_section(results: D.Results, figures: str) -> str:
    rows = [gallery_row(r) for r in results.gallery]
    failed = [
        f"`{r['name']}`: {r['mujoco']['reason']}"
        for r in results.gallery
        if r["mujoco"].get("status") == "cannot load"
    ]
    both = mujoco_both(results)
    text = (
        gallery_intro(results)
        + table(GALLERY_COLUMNS, rows, right=(1, 3, 4, 7, 10, 11, 12, 13, 15, 16))
        + "\n"
        f"pinsettle converged inside the limits (independent check) and not on an unstable rest "
        f"on {len(settled_inside(results))} of {len(results.gallery)} robots."
    )
    if failed:
        text += " MuJoCo cannot load " + "; ".join(failed) + "."
    text += saddle_note(results, both) + goal3_paragraph(both)
    return text + f"\n\n![gallery]({figures}/gallery.png)\n\n" + floating_table(results)


def fastest_baseline(d: D.SceneData, family: str) -> tuple[float, int | None, int] | None:
    """A baseline at its best: the shortest time to LEVEL (s) among its rule run, the run at the
    sweep's best setting and the sweep's own runs (each timed in its own repeats; a full run may
    be slower than its sweep point when it stalled past the level and was retried with the steps
    halved), with that run's velocity resets (None for the viscous baselines) and its steps to
    the level; None when none got there."""
    fire = family.startswith("fire")
    found: list[tuple[float, int | None, int]] = []
    for run in (d.runs[f"{family}_rule"], d.runs[f"{family}_best"]):
        hit = run.reach("residual", LEVEL)  # (steps, time)
        if hit is not None:
            found.append((hit[1], run.extra.get("resets") if fire else None, int(hit[0])))
    found += [
        (p.seconds, p.resets if fire else None, p.steps)
        for p in d.baseline_sweep.get(family, [])
        if p.time_to is not None
    ]
    return min(found, key=lambda item: item[0], default=None)


#: A behind scene (of more than one degree of freedom) whose KD run damps more often than once
#: in this many steps, or whose set-up is more than this share of KD's time, gets the matching
#: reason in the goal 1 line.
FREQUENT_DAMPING = 15
SETUP_HEAVY = 0.2


def goal1_reasons(
    frequent: list[str],
    setup_heavy: list[str],
    single: list[tuple[str, str, int, float, int, float]],
) -> str:
    """Why KD is behind where goal 1 is not met, in plain words, from what was measured.
    ``single``: the one-degree-of-freedom scenes behind, each (name, the faster baseline, its
    steps and time to the level, KD's steps and time to the level)."""
    text = ""
    if single:
        fewer = all(steps_b <= steps_k for _, _, steps_b, _, steps_k, _ in single)
        text += (
            f" Why, on {', '.join(n for n, *_ in single)} (one degree of freedom): "
            + "; ".join(
                f"{n}: {label} {steps_b:,} steps in {fmt_time(t_b)} "
                f"({fmt_time(t_b / steps_b)} a step, set-up included), KD {steps_k:,} in "
                f"{fmt_time(t_k)} ({fmt_time(t_k / steps_k)})"
                for n, label, steps_b, t_b, steps_k, t_k in single
            )
            + ". A single mode has no slower swing for KD's stops to save, and a damper tuned to "
            "it (its sweep's best) brings it down "
            + ("in as few steps or fewer" if fewer else "in about as many steps")
            + "; each KD step also computes both energies, tests for a peak and controls the "
            "step."
        )
    if frequent:
        text += (
            f" Why, on {', '.join(frequent)}: KD damps every few steps there, and each damping "
            "event (kt = 0) stops the slow swing of the whole mechanism together with the fast "
            "modes whose energy peaked, so the motion starts again from rest; viscous damping "
            "removes energy without stopping the motion, and FIRE mixes its velocity toward "
            "the force, which keeps its power positive for longer between resets."
        )
    if setup_heavy:
        text += (
            f" Why, on {', '.join(setup_heavy)}: the whole run takes microseconds, and KD's "
            "set-up (the checks of the model and the start, the first estimate of the "
            "stability limit and of the stiff modes) is a large share of it."
        )
    return text


def goal3_reasons(gallery: list[D.Record], both: dict[str, float]) -> str:
    """Why pinsettle is less than 100 times faster than MuJoCo on a robot, from what was
    measured: MuJoCo stopped on a saddle (another answer), or pinsettle's run is a few steps
    against MuJoCo's shortest settle (the still window it must pass)."""
    rows = {r["name"]: r for r in gallery if r["name"] in both and both[r["name"]] < 100}
    unstable = mujoco_saddle_stops(gallery, both)
    saddle = [n for n in rows if n in unstable]
    short = [n for n in rows if n not in saddle]
    text = ""
    if saddle:
        fair = [x for n, x in both.items() if n not in unstable]
        text += (
            f" Why, on {', '.join(saddle)}: MuJoCo's settle ends on a saddle it did not leave and "
            "pinsettle goes on to a stable rest, so the two times are of different answers"
            + (
                f" (over the {len(fair)} robots where both come to a rest that is not unstable "
                f"the median is {statistics.median(fair):.0f})"
                if fair
                else ""
            )
            + "."
        )
    if short:
        text += (
            f" Why, on {', '.join(short)}: "
            + "; ".join(
                f"pinsettle's whole run is {rows[n]['steps']:,} steps in "
                f"{fmt_time(statistics.median(rows[n]['seconds']))}, and MuJoCo's is the "
                f"{rows[n]['mujoco']['sim_time']:g} s it simulates to see the robot stay still"
                for n in short
            )
            + "."
        )
    return text


def mujoco_saddle_stops(gallery: list[D.Record], both: dict[str, float]) -> list[str]:
    """The robots both settle (``both``) where MuJoCo's settle ended on an unstable rest."""
    return [
        r["name"]
        for r in gallery
        if r["name"] in both and r["mujoco"].get("stability") == "unstable"
    ]


def goal5_reasons(
    results: D.Results, n: list[int], steps: list[int], per: list[float], wall: list[float]
) -> str:
    """Why the chains' time grows faster than n^2, or why the longest are missing, from what
    was measured: the growth of the steps and of a step, and the solver's own refusal."""
    text = ""
    if slope(n, wall) > 2:
        text += (
            f" Why: the steps grow as n^{slope(n, steps):.2f} (a longer chain's slowest swing "
            f"takes more of them) and a step as n^{slope(n, per):.2f}."
        )
    refused = refused_chains(results)
    if refused:
        text += (
            f" {', '.join(str(row['n']) for row in refused)} links are refused: "
            + refused[0]["refused"].strip().splitlines()[-1]
            + "."
        )
    return text + joint_inertia_growth(results)


def joint_inertia_growth(results: D.Results) -> str:
    """What the option scale_joint_inertia does to the same chains' growth, where all of them
    converged with it, and why it is not the default."""
    rows = [r for r in results.scaling if r.get("joint_inertia") is not None]
    if len(rows) < 2 or any(r["joint_inertia"]["status"] != "converged" for r in rows):
        return ""
    n = [r["n"] for r in rows]
    steps = [r["joint_inertia"]["steps"] for r in rows]
    seconds = [r["joint_inertia"]["seconds"] for r in rows]
    return (
        f" With `scale_joint_inertia = True` the same chains ({n[0]} to {n[-1]} links) take "
        f"{min(steps):,} to {max(steps):,} steps and their time grows as "
        f"n^{slope(n, seconds):.2f} (the Scaling part); the option is not the default because "
        "some robots lose with it and a run with no equilibrium is not always called one "
        "(docs/method.md, Fictitious joint inertia)."
    )


@dataclasses.dataclass
class Behind:
    """The scenes where KD is slower than a baseline at its best, for goal 1's line: one entry
    each, and the scenes each reason of goal1_reasons applies to."""

    entries: list[str] = dataclasses.field(default_factory=list)
    frequent: list[str] = dataclasses.field(default_factory=list)
    setup_heavy: list[str] = dataclasses.field(default_factory=list)
    single: list[tuple[str, str, int, float, int, float]] = dataclasses.field(default_factory=list)


def behind_entry(
    name: str, label: str, t_b: float, t_k: float, kd: D.Run, resets: int | None
) -> str:
    """'name (baseline time against KD's; how often KD damps; its set-up's share)'."""
    every = kd.steps / kd.peaks if kd.peaks else math.inf
    reset = f" ({kd.peaks:,} times), {label} resets {resets:,} times" if resets is not None else ""
    return (
        f"{name} ({label} {fmt_time(t_b)} against KD's {fmt_time(t_k)}; KD damps once every "
        f"{every:.0f} steps" + reset + f"; KD's set-up {fmt_time(kd.setup)} is "
        f"{kd.setup / t_k:.0%} of its time)"
    )


def note_behind(behind: Behind, name: str, d: D.SceneData) -> None:
    """Add the scene to ``behind`` where KD did not reach the level or a baseline was faster."""
    reach = kd_reach(d)
    if reach is None:
        behind.entries.append(f"{name} (KD did not reach it)")
        return
    tk, steps_k = reach
    bests = {f: b for f in BASELINES if (b := fastest_baseline(d, f)) is not None}
    faster = {f: b[0] for f, b in bests.items() if b[0] < tk}
    if not faster:
        return
    f = min(faster, key=lambda family: faster[family])
    kd = d.runs[kd_key()]
    label = D.BASELINE_LABELS[f]
    behind.entries.append(behind_entry(name, label, faster[f], tk, kd, bests[f][1]))
    every = kd.steps / kd.peaks if kd.peaks else math.inf
    if every < FREQUENT_DAMPING and d.nv > 1:  # one mode: no slow swing to stop
        behind.frequent.append(name)
    if d.nv == 1 and steps_k:
        behind.single.append((name, label, bests[f][2], faster[f], steps_k, tk))
    if kd.setup / tk > SETUP_HEAVY:  # of the time the line gives, set-up included
        behind.setup_heavy.append(name)


def fire_rule_failures(results: D.Results) -> str:
    """Where FIRE at its rule did not reach the level, and how many of those KD settled."""
    scenes = results.scenes
    fails = [
        n for n, d in scenes.items() if d.baseline_sweep and time_to(d.runs["fire_rule"]) is None
    ]
    if not fails:
        return ". FIRE at its rule fails none"
    kd_ok = [n for n in fails if kd_time(scenes[n]) is not None]
    return f". FIRE at its rule fails {', '.join(fails)}; KD settles {len(kd_ok)} of them"


def goal1_lines(results: D.Results) -> list[str]:
    names = compared(results)
    if not names:
        return []
    behind = Behind()
    for name in names:
        note_behind(behind, name, results.scenes[name])
    done = len(names) - len(behind.entries)
    verdict = (
        f"met on {done} of {len(names)}; **not met** on " + "; ".join(behind.entries)
        if behind.entries
        else f"met on all {len(names)}"
    )
    return [
        f"- **Goal 1** (KD with the default settings at least as fast to a residual of "
        f"{LEVEL:g} as every baseline at its best, on every tree scene; a baseline's best is "
        "its fastest run to that level: its rule, a point of its sweep or the sweep's best "
        "setting run in full): "
        + verdict
        + fire_rule_failures(results)
        + " (the whole comparison, per scene, in the Scenes part)."
        + goal1_reasons(behind.frequent, behind.setup_heavy, behind.single)
    ]


def goal2_lines(results: D.Results) -> list[str]:
    if not compared(results):
        return []
    defaults = [
        (n, d.runs["kd_default"]) for n, d in results.scenes.items() if "kd_default" in d.runs
    ]
    worse = [f"{n} ({fmt_e(r.residual)})" for n, r in defaults if not r.residual <= LEVEL]
    verdict = (
        f"**not met** on {len(worse)} of {len(defaults)} scenes: " + ", ".join(worse)
        if worse
        else f"met on all {len(defaults)} scenes"
    )
    return [
        f"- **Goal 2** (the default run ends at a relative residual of at most {LEVEL:g}): "
        + verdict
        + "."
    ]


def goal3_lines(results: D.Results) -> list[str]:
    both = mujoco_both(results)
    if not both:
        return []
    median = statistics.median(both.values())
    below = [f"{n} ({x:.1f})" for n, x in both.items() if x < 100]
    return [
        f"- **Goal 3** (at least 100 times faster than MuJoCo's damped settle on every "
        f"robot both settle, median at least 300): median {median:.0f} over {len(both)} robots"
        + (f"; below 100: {', '.join(below)}" if below else "")
        + (": met." if not below and median >= 300 else ": **not met**.")
        + goal3_reasons(results.gallery, both)
    ]


def goal4_rows(results: D.Results) -> list[D.Record]:
    """The overhead rows goal 4 names (a quick run: the scenes it has)."""
    rows = [r for r in overhead_rows(results) if r["name"] in GOAL4_SCENES]
    return rows or overhead_rows(results)


def goal4_lines(results: D.Results) -> list[str]:
    rows = goal4_rows(results)
    if not rows:
        return []
    return [
        "- **Goal 4** (set-up, step estimates, stability assessments and polish at most 25% "
        "of a solve on the UR5, chain20, chain100): " + goal4_verdict(rows)
    ]


@dataclasses.dataclass
class ChainGrowth:
    """The converged chains' lengths and, for each, the default solve's time, steps and time
    per step: what goal 5 and the README's chains line fit."""

    n: list[int]
    wall: list[float]
    steps: list[int]
    per: list[float]

    @classmethod
    def of(cls, results: D.Results) -> ChainGrowth | None:
        done = converged_chains(results)
        if len(done) < 2:
            return None
        wall = [solve_time(r) for r in done]
        per = [w / max(solve_steps(r), 1) for w, r in zip(wall, done, strict=True)]
        return cls([r["n"] for r in done], wall, [solve_steps(r) for r in done], per)

    def text(self) -> str:
        return (
            f"time grows as n^{slope(self.n, self.wall):.2f} and a step as "
            f"n^{slope(self.n, self.per):.2f} over {self.n[0]} to {self.n[-1]} links"
        )


def goal5_lines(results: D.Results) -> list[str]:
    growth = ChainGrowth.of(results)
    if growth is None:
        return []
    unfinished = unfinished_chains(results)
    if unfinished:
        verdict = f"; {unfinished}: **not met**."
    else:
        verdict = ": met." if slope(growth.n, growth.wall) <= 2 else ": **not met**."
    return [
        "- **Goal 5** (time no faster than n^2 from 5 to 1,000 links, a step O(n)): "
        + growth.text()
        + verdict
        + goal5_reasons(results, growth.n, growth.steps, growth.per, growth.wall)
    ]


def stop_ratios(results: D.Results) -> dict[str, float]:
    """A step with joint stops over one without, on the UR5 and the Panda (where measured)."""
    return {n: stops_ratio(results, n) for n in ("ur5", "panda") if n in results.step_cost}


def step_cost_goal_lines(results: D.Results) -> list[str]:
    ratios = stop_ratios(results)
    if not ratios:
        return []
    return [
        "- **Issue 18, step cost** (a step with joint stops at most 1.1 times one "
        "without, UR5 and Panda): "
        + ", ".join(f"{n} {x:.2f}" for n, x in ratios.items())
        + (": met." if max(ratios.values()) <= 1.1 else ": **not met**.")
    ]


def gallery_tally(results: D.Results) -> str:
    """'k of n robots converge inside their limits ...; floating bases: ...'."""
    falls = [f"{r['name']} {r['status']} in {fmt_time(r['median'])}" for r in results.floating]
    return (
        f"{len(settled_inside(results))} of {len(results.gallery)} robots converge inside "
        "their limits with the default settings (independent check)"
        + (f"; floating bases: {', '.join(falls)}" if falls else "")
    )


def gallery_goal_lines(results: D.Results) -> list[str]:
    if not results.gallery:
        return []
    return [f"- **Issue 18, gallery**: {gallery_tally(results)}."]


#: The goals of issues 18 and 20, in the Goals part's order: each a function of the results
#: giving its line (none when this run did not measure it).
GOALS = (
    goal1_lines,
    goal2_lines,
    goal3_lines,
    goal4_lines,
    goal5_lines,
    step_cost_goal_lines,
    gallery_goal_lines,
)


def goals_section(results: D.Results) -> str:
    """The goals of issues 18 and 20, each measured in this run: met or not, in plain words."""
    lines = [line for goal in GOALS for line in goal(results)]
    return (
        "## Goals\n\n"
        "The figures issues 18 and 20 ask for, as measured in this run (details in the parts "
        "below).\n\n" + "\n".join(lines) + "\n\n"
    )


REGION_TITLES = {
    "scenes": "Scenes: error against run time, KD against the baselines",
    "cost": "Cost of one step",
    "overhead": "Where a solve's time goes",
    "scaling": "Scaling with chain length",
    "gallery": "The robot gallery, and MuJoCo",
}


def scenes_part(results: D.Results, figures: str) -> str:
    return (
        conclusions(results)
        + summary_rules(results)
        + scenes_table(results)
        + "\n"
        + defaults_section(results)
        + baselines_section(results)
        + summary_table(results)
        + "\n"
        + figures_section(results, figures)
        + closed_loops_section(results)
        + energy_section(results)
        + kt_section(results, figures)
        + stopping_section(results, figures)
        + backtrack_section(results)
        + dt_section(results)
    )


def parts(results: D.Results, fig_dir: Path, figures: str) -> dict[str, str]:
    """The report's parts measured in this run (their figures written), by region name."""
    out: dict[str, str] = {}
    if "scenes" in results.sections:
        for name, d in results.scenes.items():
            d.bench_name = name
            scene_figure(d, fig_dir / f"{name}.png")
        kt_figure(results, fig_dir / "kt.png")
        max_e_figure(results, fig_dir / "max_e.png")
        out["scenes"] = scenes_part(results, figures)
    if "cost" in results.sections:
        out["cost"] = cost_section(results)
    if "overhead" in results.sections:
        out["overhead"] = overhead_section(results)
    if "scaling" in results.sections:
        scaling_figure(results, fig_dir / "scaling.png")
        out["scaling"] = scaling_section(results, figures)
    if "gallery" in results.sections:
        gallery_figure(results, fig_dir / "gallery.png")
        out["gallery"] = gallery_section(results, figures)
    for name in list(out):
        out[name] = f"## {REGION_TITLES[name]}\n\n" + stamp(results, name) + out[name]
    if set(results.sections) == set(D.SECTIONS):
        out["goals"] = goals_section(results)
    return out


REGIONS = ("header", "goals", *D.SECTIONS)


_OPEN = re.compile(r"^<!-- ([\w.:-]+)(?: [^>]*)? -->$")


def region(name: str, text: str) -> str:
    return (
        f"<!-- report:{name} (written by benchmarks/report.py; do not edit) -->\n"
        f"{text.rstrip()}\n<!-- /report:{name} -->\n"
    )


def split_regions(text: str) -> tuple[dict[str, str], list[tuple[str | None, str]]]:
    """The report's regions of an existing file (name -> whole block) and every other
    delimited block (``<!-- NAME ... -->`` ... ``<!-- /NAME -->``, e.g. a section another tool
    writes), each with the report region it follows (None: before any). Text outside any block
    is dropped: the file is generated."""
    ours: dict[str, str] = {}
    foreign: list[tuple[str | None, str]] = []
    lines = text.splitlines(keepends=True)
    last: str | None = None
    k = 0
    while k < len(lines):
        m = _OPEN.match(lines[k].strip())
        if not m or m.group(1).startswith("/"):
            k += 1
            continue
        name = m.group(1)
        close = f"<!-- /{name} -->"
        end = next((j for j in range(k + 1, len(lines)) if lines[j].strip() == close), None)
        if end is None:
            k += 1
            continue
        block = "".join(lines[k : end + 1])
        if name.startswith("report:"):
            last = name[len("report:") :]
            ours[last] = block
        else:
            foreign.append((last, block))
        k = end + 1
    return ours, foreign


def merge(existing: str, new: dict[str, str]) -> str:
    """The report with the new regions in place of the old ones, the regions not measured now
    kept, and the other delimited blocks kept after the region they followed (at the end when
    they followed none)."""
    ours, foreign = split_regions(existing)
    blocks = []
    for name in REGIONS:
        if name in new:
            blocks.append(region(name, new[name]))
        elif name in ours:
            blocks.append(ours[name])
        blocks += [block for anchor, block in foreign if anchor == name]
    # Blocks that followed no region of the report (a file written before the regions) or one
    # it no longer has: at the end.
    blocks += [block for anchor, block in foreign if anchor is None or anchor not in REGIONS]
    return "\n".join(block.rstrip("\n") + "\n" for block in blocks)


README_BEGIN = "<!-- bench:summary (written by benchmarks/report.py) -->"
README_END = "<!-- /bench:summary -->"


def step_cost_line(results: D.Results) -> list[str]:
    """One step over a bare step, per model and per kind of element, and the stops' cost."""
    names = list(results.step_cost)
    if not names:
        return []

    def ratio(name: str, key: str) -> float:
        return cost_median(results, name, key) / cost_median(results, name, "bare")

    def span(key: str) -> str:
        values = [ratio(n, key) for n in names]
        return f"{min(values):.2f}-{max(values):.2f}"

    costs = ", ".join(f"{n} {ratio(n, 'exact'):.2f}" for n in names)
    stops = ", ".join(f"{n} {stops_ratio(results, n):.2f}" for n in names)
    return [
        f"- **One step** costs {costs} times a bare `pinocchio::aba` + `pinocchio::integrate` "
        f"step on the same model (median of interleaved repeats; `benchmarks/step_cost.cpp`). A "
        f"scene without elements: {span('no_elements')}; a joint spring on every joint: "
        f"{span('joint_springs')}; one point spring: {span('point_spring')} (a forward-kinematics "
        f"pass per step to place its ends); the model's joint stops over no stops: {stops}."
    ]


def energy_line(results: D.Results) -> list[str]:
    t = energy_tally(results, results.config.kts)
    return [
        f"- **Exact or simplified energy**: per step, simplified / exact "
        f"{cost_ratio(results):.3f} (UR5); over {len(t['ratios'])} scene and kt pairs, "
        f"{t['geomean']:.2f} times the steps to a residual of {LEVEL:g} (geometric mean; fewer "
        f"in {t['fewer']}, more in {t['more']}, as many in {t['equal']})."
    ]


def kt_line(results: D.Results) -> list[str]:
    score = kt_scores(results, "exact")
    means = ", ".join(
        f"{kt:g}: {geomean([x for x in r if math.isfinite(x)]):.2f}" for kt, r in score.items()
    )
    return [
        f"- **kt**: the fewest steps to a residual of {LEVEL:g} came with kt = "
        f"{best_kt(score):g} (geometric mean over the scenes of the steps over each scene's "
        f"fewest: {means})."
    ]


def readme_baseline_lines(results: D.Results) -> list[str]:
    lines = baseline_bullets(results, over_kd="KD's defaults")
    if loop_scenes(results):
        lines.append(f"- The {trees_only(results)}.")
    return lines


def mujoco_line(results: D.Results) -> list[str]:
    both = mujoco_both(results)
    if not both:
        return []
    values = sorted(both.values())
    return [
        f"- **MuJoCo**: its damped settle of the same URDF took {statistics.median(values):.0f} "
        f"times pinsettle's time (median over the {len(values)} robots both settle; "
        f"{values[0]:.1f} to {values[-1]:.0f})." + saddle_note(results, both)
    ]


def gallery_line(results: D.Results) -> list[str]:
    if not results.gallery:
        return []
    return [f"- **Robot gallery**: {gallery_tally(results)}."]


def overhead_line(results: D.Results) -> list[str]:
    rows = goal4_rows(results)
    if not rows:
        return []
    shares = ", ".join(
        f"{r['name']} {r['fraction']:.1%} ({r['fraction_polish']:.1%} in the default solve)"
        for r in rows
    )
    return [
        "- **Where a solve's time goes**: the set-up, step estimates, stability assessments and "
        f"(in the default solve) the polish's Newton take {shares} of a solve's time "
        "(`benchmarks/kd_profile.cpp`)."
    ]


def chains_line(results: D.Results) -> list[str]:
    growth = ChainGrowth.of(results)
    if growth is None:
        return []
    unfinished = unfinished_chains(results)
    return ["- **Chains**: " + growth.text() + (f"; {unfinished}" if unfinished else "") + "."]


#: The README's speed section, in its order: what was measured, without the goals (those are
#: in the report's Goals part). Each a function of the results giving its lines.
README_LINES = (
    step_cost_line,
    energy_line,
    kt_line,
    readme_baseline_lines,
    mujoco_line,
    gallery_line,
    overhead_line,
    chains_line,
)


def wrap(line: str) -> str:
    """A README line wrapped at 100 characters, a bullet's continuation indented."""
    if not line or line.startswith("<!--"):
        return line
    return textwrap.fill(line, 100, subsequent_indent="  " if line.startswith("- ") else "")


def readme_block(results: D.Results) -> str:
    """The README's speed section: the main ratios of the report, as measured."""
    m = results.machine
    lines = [
        README_BEGIN,
        f"Measured by `python benchmarks/report.py` on this project's {m['cores']}-core machine "
        f"({m['date']}, shared with other jobs: ratios within one run, medians of repeats); the "
        "whole report, with plots of error against wall time and steps for each scene and the "
        "goals this project set itself, is [docs/benchmarks.md](docs/benchmarks.md).",
        "",
    ]
    lines += [line for part in README_LINES for line in part(results)]
    lines.append(README_END)
    return "\n".join(wrap(line) for line in lines)


def update_readme(results: D.Results, readme: Path) -> bool:
    """Replace the block between the markers; False when the README has none."""
    text = readme.read_text(encoding="utf-8")
    start, end = text.find(README_BEGIN), text.find(README_END)
    if start < 0 or end < 0:
        return False
    text = text[:start] + readme_block(results) + text[end + len(README_END) :]
    readme.write_text(text, encoding="utf-8")
    return True

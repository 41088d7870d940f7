"""The figures and the text of the benchmark report (benchmarks/report.py measures).

Everything written here is computed from the measurements: the conclusions too, by the rules
stated next to them.
"""

from __future__ import annotations

import math
import statistics
import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pinsettle
import report_data as D

#: Values below this are drawn at it on the log axes (exact zeros happen at round-off).
FLOOR = 1e-17
LEVEL = D.RESIDUAL_LEVELS[-1]  # the level the conclusions compare at


# --- formatting ---------------------------------------------------------------------------------


def fmt_time(seconds: float) -> str:
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


def fmt_e(x: float) -> str:
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
    per_step = [s / run.steps for s in run.seconds]
    return fmt_steps(steps), fmt_spread(per_step, steps) if spread else fmt_time(
        steps * run.per_step
    )


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


BASELINES = ("viscous", "mass_damping", "fire")


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
        max(r.extra["constraint_error"], r.extra["solver_constraint_error"]) for r in kd_runs(d)
    )


def loop_cost_ratio(results: D.Results, name: str, key: str = "exact") -> float:
    """The solver's step on a scene with loops over a bare ``pinocchio::constraintDynamics`` +
    ``integrate`` step (benchmarks/loop_step_cost, medians); nan when not measured."""
    cost = results.loop_step_cost.get(name)
    if cost is None:
        return math.nan
    c = cost["ns_per_step"]
    return statistics.median(c[key]) / statistics.median(c["bare"])


# --- figures -----------------------------------------------------------------------------------

STYLE = {
    "kd_exact": dict(color="C0", ls="-", label="KD, exact energy"),
    "kd_simplified": dict(color="C0", ls="--", label="KD, simplified energy"),
    "viscous": dict(color="C1", ls="-", label="viscous, joint dampers"),
    "mass_damping": dict(color="C2", ls="-", label="viscous, mass-proportional"),
    "fire": dict(color="C3", ls="-", label="FIRE"),
    "newton": dict(color="C4", ls=":", marker="o", ms=3, label="Newton (Python)"),
    "newton_ls": dict(color="C5", ls=":", marker="s", ms=3, label="Newton + line search (Python)"),
}


def scene_figure(d: D.SceneData, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharey="row")
    for key, run in d.runs.items():
        if run.curve is None:
            continue
        c = run.curve
        style = STYLE[key]
        for row, quantity in enumerate(("distance", "residual")):
            y = np.maximum(getattr(c, quantity), FLOOR)
            if run.method == "newton":
                t = np.array(run.extra["times"])
                axes[row, 0].plot(t[1:], y[1:], **style)
                continue
            keep = c.steps > 0
            axes[row, 0].plot(c.steps[keep] * run.per_step, y[keep], **style)
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
    axes[1, 0].set_xlabel("wall time (s): steps x measured time per step")
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
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(path, dpi=90)
    plt.close(fig)


def scene_color(k: int):
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
            y = [
                times[(energy, kt)] / best if times[(energy, kt)] is not None else np.nan
                for kt in x
            ]
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

    rows = results.scaling
    n = [row["n"] for row in rows]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.5))
    bare = [statistics.median(row["cost"]["ns_per_step"]["bare"]) * 1e-9 for row in rows]
    kd = [statistics.median(row["cost"]["ns_per_step"]["exact"]) * 1e-9 for row in rows]
    real = [row["runs"][0].per_step for row in rows]
    a.plot(n, bare, marker="o", label="bare aba + integrate (step_cost)")
    a.plot(n, kd, marker="s", label="KD step (step_cost)")
    a.plot(n, real, marker="^", label="KD, whole solve / steps")
    a.set_xlabel("chain length (joints)")
    a.set_ylabel("time per step (s)")
    a.set_xscale("log")
    a.set_yscale("log")
    a.grid(True, alpha=0.3)
    a.legend(fontsize=8)
    b.plot(n, [row["runs"][0].steps for row in rows], marker="o", label="converged (defaults)")
    b.plot(
        n,
        [steps_to(row["runs"][1]) or np.nan for row in rows],
        marker="s",
        label=f"to residual {LEVEL:g} (max_e = {D.DEEP_MAX_E:g})",
    )
    b.set_xlabel("chain length (joints)")
    b.set_ylabel("steps")
    b.set_xscale("log")
    b.set_yscale("log")
    b.grid(True, alpha=0.3)
    b.legend(fontsize=8)
    fig.suptitle("Chains of robots/make_chain.py (0.1 m, 0.1 kg links) released horizontal")
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
    load = (
        f"1-minute load average {m['load_start'][0]:.2f} before the run and "
        f"{m['load_end'][0]:.2f} at its end (its own process, single-threaded, included)"
    )
    return f"""# Benchmarks: error against run time

Generated by `python benchmarks/report.py` on {m["date"]}: {m["cpu"]}, {m["cores"]} cores,
Python {m["python"]}, Pinocchio {m["pinocchio"]}, pinsettle {m["pinsettle"]}; {load}. The
measurements took {results.seconds:.0f} s. Do not edit by hand: every number below is measured
by that command.

"""


def summary_rules(results: D.Results) -> str:
    names = ", ".join(f"`{n}`" for n in loop_scenes(results)) or "none here"
    return f"""## How it is measured

**Error.** For a configuration q, the *distance* `max |q - q*|` over the free joints (rad or m;
revolute angles compared modulo 2 pi) and the *residual* `max |tau_static(q)|`
(`Scene.static_force`: gravity minus springs and loads) divided by the scene's *force scale*,
`max |tau_static(q0)|` at the start. q* is the exact equilibrium the run comes to rest at: its
final pose refined by Newton's method to round-off (the stiffness matrix of
`pinsettle.assess_stability`, least squares so that neutral directions are left alone). For a
scene with isolated equilibria that is the scene's reference equilibrium (the tables say how far
from it each run landed); the UR5 and the Panda rest on a family of equilibria (a base turning
about the vertical, wrist turns), and each run is measured against the member it comes to.
The reference q* of a scene is kinetic damping with `polish=True` and `max_e = {D.DEEP_MAX_E:g}`,
Newton-refined, checked stable or neutral, and checked independently by one Newton step with a
central-difference Jacobian of the static force (`check step` below: the size of that step).

**Curves and time.** Kinetic damping (KD) runs with the default settings (kt = 0.5,
`dt = "auto"`, `err`, `ds`) but `max_e = {D.DEEP_MAX_E:g}`, so that the run goes on down to
round-off and the curve shows how the error falls; the stopping rule's own trade-off is the
`max_e` sweep below. The curve comes from a run with `trace_every = 1` and
`trace_configurations = True` (at most {D.CURVE_SAMPLES} samples: the trace halves its samples
when full); its trajectory is checked identical to the timed runs', which trace nothing. **Steps
are mapped to wall time by the run's measured time per step** (`wall_time / steps` of the timed
runs, the median of up to 5 repeats, fewer for runs over {D.REPEAT_BUDGET:g} s; the spread
quoted is min-max over the repeats). KD's time per step is the whole solve's: its set-up (the
first estimate of the automatic step), the step estimates along the way and the final stability
check are in it; the baselines' loops have no set-up. "Time to a level" is the time from which
the error stays below it to the end of the run (a swing through q* does not count). Every KD run
on a scene is limited to {D.STEP_BUDGET_FACTOR} times the steps of the run that found the
scene's reference (at least {D.STEP_BUDGET_MIN:,}; the dt sweep's runs to at least
{D.DT_SWEEP_SECONDS:g} s): a setting that keeps it from converging ends there, `max_steps`.

**Baselines**, on the same Pinocchio dynamics, C++ (`benchmarks/baselines.cpp`, built against
the installed package: `pinocchio::aba`, `pinsettle::ForceElements`, the static force as
`pinsettle::computeStaticForce` computes it, timed inside the loop like the solver's
`wall_time`), semi-implicit Euler, until the residual is below {D.BASELINE_TARGET:g} of the force
scale (checked every 64 steps; FIRE has it every step) or {D.BASELINE_MAX_STEPS:,} steps or
{D.BASELINE_MAX_TIME:g} s:

- *viscous, joint dampers*: `a = ABA(q, v, tau - c v)`, the same c on every joint: what users of
  physics simulators do to let a robot settle. c damps the slowest mode of the mechanism
  linearised at q* critically: with `K phi = omega^2 M phi` (phi M-normalised, neutral
  directions skipped) its modal damping is `c |phi|^2`, so `c = 2 omega / |phi|^2`.
- *viscous, mass-proportional*: `a = ABA(q, v, tau) - c v` (damping `c M v`), dynamic
  relaxation's classic form: every mode decays at the rate c / 2; `c = 2 omega` damps the slowest
  critically.
- *FIRE* (Bitzek et al., 2006) with its classic parameters: N_min 5, f_inc 1.1, f_dec 0.5,
  alpha_start 0.1, f_alpha 0.99, dt_max 10 dt0 (with dt0 below, {10 * D.DT_SAFETY:g} times the
  stability limit: FIRE counts on its resets there); power `P = F . v` with `F = -tau_static(q)`
  (one extra RNEA per step), velocity mixing `v <- (1 - alpha) v + alpha |v| F / |F|` in joint
  coordinates.
- Their step: dt_safety ({D.DT_SAFETY:g}, the solver's default) times the stability limit of
  semi-implicit Euler with the damping, `4 / (r + sqrt(r^2 + 4 omega_max^2))`, r the fastest decay
  rate the damping gives (c times the largest eigenvalue of M^-1 for joint dampers, c for
  mass-proportional damping, 0 for FIRE, whose dt0 it is), the worse of the start and q*, without
  stiff-mode scaling (they have none). A run that blows up is started again with half the step.
  Other coefficients than the rule's are tried in the baselines section.
- *Newton* from the same start, in Python (its wall time is **not** comparable with the C++
  loops'; it is quoted per iteration for orientation): the stiffness matrix of
  `pinsettle.assess_stability` as Jacobian, least squares (rank cut 1e-10), full steps;
  *Newton + line search* halves a step until `|tau_static|_2` falls. At most 50 iterations; where
  it lands is judged with `pinsettle.assess_stability`.

**Closed loops** (scenes with `[[loop]]`: {names}). The solver runs
Pinocchio's constrained dynamics and keeps the pose on the loops; the report measures the closed
mechanism the same way. Its start is the scene's start moved onto the loops (`Scene.assemble`,
as the solver does first), and the force scale is taken there. The residual is the static force
projected onto the motions the loops allow (`Scene.static_force`: zero at an equilibrium of the
closed mechanism; the loops' reactions take the rest). Newton's step, for the references, the
landings and Newton from the start, is the reduced one, `dq = B lstsq(K_r, -B^T f)` with K_r and
its basis B from `pinsettle.assess_stability`, followed by moving the pose back onto the loops;
the check step differentiates the projected force along B. The distance is `max |q - q*|` over
the free joints as for a tree. The final constraint error of every KD run (the largest loop
error, m) is measured here from Pinocchio's frame placements and compared with the solver's
`Result.constraint_error`. The C++ baselines run unconstrained ABA and cannot close a loop: the
baselines run on trees only.

"""


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
    return "## Scenes\n\n" + table(
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
    "viscous",
    "mass_damping",
    "fire",
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
        "## Summary\n\n"
        "Steps and wall time from which the relative residual stays below "
        f"{lv[0]} and {lv[1]} (median over the repeats, min-max in brackets); the run's end: "
        "status, distance from its rest q*, residual, and where it rests (the stability of q*). "
        "KD runs use `max_e = "
        f"{D.DEEP_MAX_E:g}` here (see above); Newton's times are Python's. For the scenes with "
        "closed loops, the final constraint error (largest loop error, m) and the reduced "
        "Newton; "
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


def energy_tally(results: D.Results, kts: Sequence[float]) -> dict:
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
    return statistics.median(c["simplified"]) / statistics.median(c["exact"])


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


def conclusions(results: D.Results) -> str:
    scenes = results.scenes
    out = ["## In short\n"]
    # Energy measure: steps (deterministic) over every scene and kt pair, and the cost per step.
    t = energy_tally(results, results.config.kts)
    g, c = t["geomean"], cost_ratio(results)
    if g * c > 1.05:
        verdict = "**choose the exact measure** (the default): the simplified one is slower"
    elif g * c < 1 / 1.05:
        verdict = "the simplified measure is faster on these scenes"
    else:
        verdict = (
            "the two are within 5 % of each other; the exact measure (the default) has units (J), "
            "so that its `max_e` means the same on every mechanism"
        )
    out.append(
        f"- **Energy measure**: over {len(t['ratios'])} scene and kt pairs of the kt sweep, the "
        f"simplified measure needed fewer steps to a residual of {LEVEL:g} in {t['fewer']}, more "
        f"in {t['more']} and as many in {t['equal']}; geometric mean of the step ratios "
        f"simplified / exact: {g:.2f}. One step with the simplified measure driving costs {c:.3f} "
        "times one with the exact measure (step_cost, UR5, medians of interleaved repeats): both "
        "are computed every step from the body velocities ABA produced, whichever drives the "
        f"detector. So {verdict}."
        + (f" Not reached: {', '.join(t['missing'])}." if t["missing"] else "")
    )
    # kt, by steps (the same loop: time follows steps).
    for energy in ("exact", "simplified"):
        score = kt_scores(results, energy)
        chosen = best_kt(score)
        parts = []
        for kt, ratios in score.items():
            bad = sum(not math.isfinite(x) for x in ratios)
            finite = [x for x in ratios if math.isfinite(x)]
            parts.append(
                f"kt = {kt:g}: {geomean(finite):.2f}" + (f" ({bad} not reached)" if bad else "")
            )
        out.append(
            f"- **kt** ({energy} energy): steps to a residual of {LEVEL:g} over the scene's "
            f"fewest, geometric mean over the {len(scenes)} scenes: "
            + "; ".join(parts)
            + f". Best: **kt = {chosen:g}**"
            + (" (the default)." if chosen == 0.5 else " (the default is 0.5).")
        )
    # Baselines, by time (their steps cost differently).
    for key in BASELINES:
        ratios, faster, slower, never = [], [], [], []
        for name, d in scenes.items():
            if key not in d.runs:
                continue
            tk, tb = time_to(d.runs["kd_exact"]), time_to(d.runs[key])
            if tb is None or tk is None:
                never.append(name)
                continue
            ratios.append(tb / tk)
            (faster if tk < tb else slower).append(name)
        label = D.BASELINE_LABELS[key]
        text = f"- **{label}** against KD (exact energy), time to a residual of {LEVEL:g}: "
        if ratios:
            text += (
                f"KD sooner on {len(faster)} scenes, later on {len(slower)}"
                + (f" ({', '.join(slower)})" if slower else "")
                + f"; {label} took {statistics.median(ratios):.2g} times KD's time (median; "
                f"from {min(ratios):.2g} to {max(ratios):.2g})"
            )
        if never:
            text += ("; " if ratios else "") + f"not reached on {', '.join(never)}"
        if key != "fire":
            factors = results.config.damping_factors
            text += (
                " (its c comes from the slowest mode at the answer q*, which a user would not "
                "have"
                + (
                    f"; {' and '.join(f'{x:g}' for x in factors)} times c are in the baselines "
                    "section)"
                    if factors
                    else ")"
                )
            )
        out.append(text + ".")
    if loop_scenes(results):
        out.append(f"- The {trees_only(results)} (see Closed loops below).")
    for key in ("newton", "newton_ls"):
        kinds: dict[str, list[str]] = {}
        for name, d in scenes.items():
            run = d.runs[key]
            kind = (
                f"{'an' if run.stability[0] in 'aeiou' else 'a'} {run.stability} root"
                if run.landing.q is not None
                else "no root"
            )
            if run.landing.q is not None and run.landing.from_reference > 1e-6:
                kind += " other than the reference q*"
            kinds.setdefault(kind, []).append(name)
        label = d.runs[key].label
        out.append(
            f"- **{label}** from the same start: "
            + "; ".join(f"{kind} on {', '.join(names)}" for kind, names in kinds.items())
            + "."
        )
    # The stopping rule and the other settings.
    slopes = []
    for d in scenes.values():
        runs = [r for r in d.sweeps["max_e"] if r.settings.get("energy") == "exact"]
        x = [math.log(r.settings["max_e"]) for r in runs if r.distance > 0]
        y = [math.log(r.distance) for r in runs if r.distance > 0]
        if len(x) >= 2:
            slopes.append(float(np.polyfit(x, y, 1)[0]))
    if slopes:
        out.append(
            f"- **max_e** (exact energy) sets the accuracy: the final distance goes as max_e^p "
            f"with p from {min(slopes):.2f} to {max(slopes):.2f} over the scenes (median "
            f"{statistics.median(slopes):.2f}; least squares, log-log), at a cost of steps "
            "(table below). With the simplified measure `max_e` has no unit of energy, so the "
            "same number stops at another accuracy on each mechanism."
        )
    stalled: dict[float, list[str]] = {}
    for name, d in scenes.items():
        for r in d.sweeps["err"]:
            if r.status != "converged":
                stalled.setdefault(r.settings["err"], []).append(name)
    if stalled:
        out.append(
            "- **err**: "
            + "; ".join(
                f"err = {err:g} kept {', '.join(names)} from converging"
                for err, names in stalled.items()
            )
            + " (a peak counts only when the energy rises and falls by more than err times "
            "itself within one step; a slow swing sampled by many steps does not, and goes "
            "undamped); the other values converged on every scene."
        )
    on_off = []
    for d in scenes.values():
        runs = {
            r.settings["backtrack"]: r
            for r in d.sweeps["backtrack"]
            if r.settings["energy"] == "exact"
        }
        a, b = steps_to(runs[False]), steps_to(runs[True])
        if a and b:
            on_off.append(b / a)
    if on_off:
        out.append(
            f"- **Backtracking** (exact energy): steps to a residual of {LEVEL:g} on / off, "
            f"geometric mean {geomean(on_off):.2f} (from {min(on_off):.2f} to {max(on_off):.2f}; "
            f"fewer on {sum(x < 1 for x in on_off)} of {len(on_off)} scenes)."
        )
    failed = {}
    for name, d in scenes.items():
        for r in d.sweeps["dt"]:
            if steps_to(r) is None:
                failed.setdefault(r.label, []).append(name)
    if failed:
        out.append(
            f"- **Time step**: a residual of {LEVEL:g} was not reached with "
            + "; ".join(f"`{label}` on {', '.join(names)}" for label, names in failed.items())
            + "; with the automatic step (the default) on "
            + f"{sum(steps_to(d.sweeps['dt'][0]) is not None for d in scenes.values())} of the "
            f"{len(scenes)} scenes."
        )
    # What the stiff-mode scaling does (the baselines have none).
    for name, d in scenes.items():
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
    out += closed_loops_short(results)
    kd_ok = [
        name
        for name, d in scenes.items()
        if all(d.runs[k].stability in ("stable", "neutral") for k in ("kd_exact", "kd_simplified"))
    ]
    out.append(
        f"- KD came to a stable or neutral rest on {len(kd_ok)} of the {len(scenes)} scenes with "
        "both energy measures."
    )
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
        "## Closed loops\n\n"
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
        "## Error against wall time and against steps\n\n"
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
        cells.append(f"{e.per_step * 1e9:.0f} / {s.per_step * 1e9:.0f}")
        cells.append(f"{peaks_to(e)} / {peaks_to(s)}")
        for level in D.DISTANCE_LEVELS:
            a, b = e.reach("distance", level), s.reach("distance", level)
            cells.append(f"{fmt_steps(a and a[0])} / {fmt_steps(b and b[0])}")
        for level in D.RESIDUAL_LEVELS:
            a, b = e.reach("residual", level), s.reach("residual", level)
            cells.append(f"{fmt_steps(a and a[0])} / {fmt_steps(b and b[0])}")
        a, b = time_to(e), time_to(s)
        cells.append(f"{fmt_time(a)} / {fmt_time(b)}")
        rows.append(cells)
    head = ["scene", "ns per step", f"peaks before residual {LEVEL:g}"]
    head += [f"steps to distance {x:g}" for x in D.DISTANCE_LEVELS]
    head += [f"steps to residual {x:g}" for x in D.RESIDUAL_LEVELS]
    head += [f"time to residual {LEVEL:g}"]
    text = (
        "## Exact against simplified energy\n\n"
        "The peak detector's signal: the exact kinetic energy `sum 1/2 m v^2 + 1/2 w^T I w` (J) "
        "against the simplified `sum v^2 + w^2`. Each cell is exact / simplified, kt = 0.5, "
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
        "## kt\n\n"
        f"Time to a residual of {LEVEL:g} (exact / simplified energy; `max_e = "
        f"{D.DEEP_MAX_E:g}`, other settings default; median of the repeats):\n\n"
        + table(
            ["scene", *[f"kt = {kt:g}" for kt in kts]], rows, right=tuple(range(1, len(kts) + 1))
        )
        + f"\n![kt sweep]({figures}/kt.png)\n\n"
    )


def stopping_section(results: D.Results, figures: str) -> str:
    text = (
        "## The stopping rule: err, ds, max_e\n\n"
        "Each setting varied alone, the others at their defaults (kt = 0.5, exact energy, "
        "`max_e = 1e-12`, `ds = 100`, `err = 1e-12`). Each cell: final distance from the rest "
        "the run ends near (rad or m), steps, time (median of the repeats); the status when not "
        "converged.\n\n"
    )
    names = list(results.scenes)
    for key, label in (("err", "err"), ("ds", "ds"), ("max_e", "max_e")):
        rows = []
        runs_by_value: dict = {}
        for name in names:
            for r in results.scenes[name].sweeps[key]:
                value = (r.settings.get("energy", "exact"), r.settings[key])
                runs_by_value.setdefault(value, {})[name] = r
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
        "## Peak backtracking\n\n"
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
        "## Fixed against automatic dt\n\n"
        f"Steps and time to a residual of {LEVEL:g} (exact energy, kt = 0.5, "
        f"`max_e = {D.DEEP_MAX_E:g}`): `auto` (the default: re-estimated as the mechanism moves, "
        "stiff modes slowed), `auto, unscaled` (`scale_stiff_modes = False`), `fixed, start` "
        "(`dt` fixed at the automatic step's first estimate, stiff modes slowed: the step "
        "at the start; a fixed step has no scaling, no re-estimates and no bound on the turn per "
        "step) and a quarter of it. `halvings`: the divergence guard's step halvings.\n\n"
        + table(["scene", *labels], rows)
        + "\n"
    )


def baselines_section(results: D.Results) -> str:
    rows = []
    for name, d in results.scenes.items():
        if d.damping is None:  # closed loops: no baselines
            continue
        damping = d.damping
        v, m, f = d.runs["viscous"], d.runs["mass_damping"], d.runs["fire"]
        rows.append(
            [
                f"`{name}`",
                f"{damping.omega:.3g}",
                f"{damping.joint:.3g}",
                f"{v.settings['dt']:.3g}"
                + (f" ({v.extra['halvings']} halvings)" if v.extra["halvings"] else ""),
                f"{damping.mass:.3g}",
                f"{m.settings['dt']:.3g}"
                + (f" ({m.extra['halvings']} halvings)" if m.extra["halvings"] else ""),
                f"{f.settings['dt']:.3g}"
                + (f" ({f.extra['halvings']} halvings)" if f.extra["halvings"] else ""),
                f"{f.extra['resets']:,}",
            ]
        )
    text = (
        "## Baselines\n\n"
        "The coefficients and steps of the rules above: the slowest mode's frequency omega "
        "(rad/s), the joint dampers' c (N m s/rad) and their step (s), the mass-proportional c "
        "(1/s) and its step, FIRE's dt0 and its velocity resets (P <= 0)."
        + (f" The {trees_only(results)}." if loop_scenes(results) else "")
        + "\n\n"
        + table(
            [
                "scene",
                "omega",
                "joint c",
                "joint dt",
                "mass c",
                "mass dt",
                "FIRE dt0",
                "FIRE resets",
            ],
            rows,
            right=tuple(range(1, 8)),
        )
    )
    if any(d.damping_sweep for d in results.scenes.values()):
        factors = results.config.damping_factors
        rows = []
        for name, d in results.scenes.items():
            if d.damping is None:
                continue
            for method in ("viscous", "mass_damping"):
                main = d.runs[method]
                cells = [f"`{name}`" if method == "viscous" else "", D.BASELINE_LABELS[method]]
                for factor in (*factors[:1], 1.0, *factors[1:]):
                    r = main if factor == 1.0 else d.damping_sweep[(method, factor)]
                    status = "" if r.status == "converged" else f" **{r.status}**"
                    cells.append(f"{r.steps:,}, {fmt_time(r.time)}{status}")
                rows.append(cells)
        text += (
            f"\nThe damping coefficient against the rule's c: steps and time to the baselines' "
            f"target (residual {D.BASELINE_TARGET:g} of the force scale), or the status when "
            f"the run stopped first (budget {D.BASELINE_SIDE_TIME:g} s off the rule):\n\n"
            + table(
                ["scene", "method", *[f"{x:g} c" for x in (*factors[:1], 1.0, *factors[1:])]],
                rows,
                right=(2, 3, 4),
            )
        )
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
    text += (
        "\nNewton from the start: iterations, the residual it ends with, where it lands (a root: "
        "its stability and smallest stiffness eigenvalue, its distance from the reference q*), "
        "the largest entry of q in absolute value (rad or m: a step off to 1e15 rad means the "
        "stiffness matrix was near singular at the start) and Python's wall time. On the scenes "
        "with closed loops it is the reduced Newton, each step moved back onto the loops.\n\n"
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
    )
    return text + "\n"


COST_ROWS = (
    ("bare", "bare aba + integrate"),
    ("exact", "KD step, exact energy"),
    ("simplified", "KD step, simplified energy"),
    ("no_elements", "a scene without elements"),
    ("joint_springs", "a joint spring on every joint"),
    ("point_spring", "one point spring"),
)


def cost_section(results: D.Results) -> str:
    names = list(results.step_cost)
    rows = []
    for key, label in COST_ROWS:
        cells = [label]
        for name in names:
            c = results.step_cost[name]["ns_per_step"]
            t = [x * 1e-9 for x in c[key]]
            ratio = statistics.median(c[key]) / statistics.median(c["bare"])
            cells.append(fmt_spread(t) + ("" if key == "bare" else f", **{ratio:.2f}**"))
        rows.append(cells)
    info = ", ".join(
        f"{n} (nv = {results.step_cost[n]['nv']}, {results.step_cost[n]['steps']:,} steps, "
        f"{len(results.step_cost[n]['ns_per_step']['bare'])} repeats)"
        for n in names
    )
    return (
        "## Cost of one step\n\n"
        "`benchmarks/step_cost.cpp`, in the same run: time per step of a bare `pinocchio::aba` + "
        "`pinocchio::integrate` step against the solver's step on the same model (ABA, both "
        "energy measures, peak detection, stopping rule, integration, the automatic step's "
        "re-estimates), repeats interleaved, median (min-max) and in bold the ratio of the "
        "medians to the bare step. Every run starts at rest 0.3 rad from neutral in every joint; "
        "the solver runs with kt = 0.99 and `max_e = 0`, so that it damps at every peak but "
        "never stops and its velocity never reaches subnormal numbers (see the file's header). "
        f"Models: {info}."
        + (
            " Trees only: the cost of a step with closed loops, against a bare "
            "`pinocchio::constraintDynamics` step, is in the Closed loops section."
            if loop_scenes(results)
            else ""
        )
        + "\n\n"
        + table(["", *names], rows, right=tuple(range(1, len(names) + 1)))
        + "\n"
    )


def scaling_section(results: D.Results, figures: str) -> str:
    rows = []
    for row in results.scaling:
        default, deep = row["runs"]
        c = row["cost"]["ns_per_step"]
        bare = statistics.median(c["bare"])
        kd = statistics.median(c["exact"])
        rows.append(
            [
                str(row["n"]),
                f"{bare / 1e3:.3g} us",
                f"{kd / 1e3:.3g} us ({kd / bare:.2f})",
                fmt_spread([s / default.steps for s in default.seconds]),
                f"{default.steps:,}",
                fmt_spread(default.seconds),
                fmt_e(default.distance),
                fmt_steps(steps_to(deep)),
                fmt_time(time_to(deep)),
            ]
        )
    n = np.log([row["n"] for row in results.scaling])
    fits = ""
    if len(n) >= 3:
        slope = {
            what: float(np.polyfit(n, np.log(values), 1)[0])
            for what, values in (
                ("steps", [row["runs"][0].steps for row in results.scaling]),
                ("per step", [row["runs"][0].per_step for row in results.scaling]),
                ("time", [row["runs"][0].time for row in results.scaling]),
            )
        }
        fits = (
            f"Least-squares fits over the lengths (log-log): the default solve's steps grow as "
            f"n^{slope['steps']:.2f}, its time per step as n^{slope['per step']:.2f} (ABA is "
            f"O(n)), its time as n^{slope['time']:.2f}.\n\n"
        )
    return (
        "## Scaling with chain length\n\n"
        "Chains of `robots/make_chain.py` (0.1 m, 0.1 kg links) released horizontal, exact "
        "energy, kt = 0.5. Per step: the bare step and the solver's step of `step_cost` (ratio in "
        "brackets), and the whole default solve's `wall_time / steps`. Then the default solve "
        "(`max_e = 1e-12`): steps, time, final distance; and with "
        f"`max_e = {D.DEEP_MAX_E:g}`: steps and time to a residual of {LEVEL:g}.\n\n"
        + table(
            [
                "links",
                "bare step",
                "KD step (ratio)",
                "KD solve / steps",
                "steps (defaults)",
                "time (defaults)",
                "final distance",
                f"steps to {LEVEL:g}",
                f"time to {LEVEL:g}",
            ],
            rows,
            right=tuple(range(0, 9)),
        )
        + "\n"
        + fits
        + f"![scaling]({figures}/scaling.png)\n\n"
    )


def write(results: D.Results, output: Path) -> None:
    """output/benchmarks.md and output/benchmarks/*.png."""
    figures = "benchmarks"
    fig_dir = output / figures
    fig_dir.mkdir(parents=True, exist_ok=True)
    for old in fig_dir.glob("*.png"):
        old.unlink()
    for name, d in results.scenes.items():
        d.bench_name = name
        scene_figure(d, fig_dir / f"{name}.png")
    kt_figure(results, fig_dir / "kt.png")
    max_e_figure(results, fig_dir / "max_e.png")
    scaling_figure(results, fig_dir / "scaling.png")
    text = (
        header(results)
        + conclusions(results)
        + summary_rules(results)
        + scenes_table(results)
        + "\n"
        + summary_table(results)
        + "\n"
        + figures_section(results, figures)
        + closed_loops_section(results)
        + energy_section(results)
        + kt_section(results, figures)
        + stopping_section(results, figures)
        + backtrack_section(results)
        + dt_section(results)
        + baselines_section(results)
        + cost_section(results)
        + scaling_section(results, figures)
    )
    (output / "benchmarks.md").write_text(text, encoding="utf-8")


# --- the README's summary ----------------------------------------------------------------------

README_BEGIN = "<!-- bench:summary (written by benchmarks/report.py) -->"
README_END = "<!-- /bench:summary -->"


def readme_block(results: D.Results) -> str:
    """The README's speed section: the main ratios of the report, as measured."""
    m = results.machine
    names = list(results.step_cost)

    def ratio(name: str, key: str) -> float:
        c = results.step_cost[name]["ns_per_step"]
        return statistics.median(c[key]) / statistics.median(c["bare"])

    def span(key: str) -> str:
        values = [ratio(n, key) for n in names]
        return f"{min(values):.2f}-{max(values):.2f}"

    costs = ", ".join(f"{n} {ratio(n, 'exact'):.2f}" for n in names)
    t = energy_tally(results, results.config.kts)
    score = kt_scores(results, "exact")
    chosen = best_kt(score)
    lines = [
        README_BEGIN,
        f"Measured by `python benchmarks/report.py` on this project's {m['cores']}-core machine "
        f"({m['date']}); the whole report, with plots of error against wall time and steps for "
        f"each scene, is [docs/benchmarks.md](docs/benchmarks.md).",
        "",
        f"- **One step** costs {costs} times a bare `pinocchio::aba` + `pinocchio::integrate` "
        f"step on the same model (median of interleaved repeats; `benchmarks/step_cost.cpp`). A "
        f"scene without elements: {span('no_elements')}; a joint spring on every joint: "
        f"{span('joint_springs')}; one point spring: {span('point_spring')} (a forward-kinematics "
        "pass per step to place its ends).",
        f"- **Exact or simplified energy**: per step, simplified / exact "
        f"{cost_ratio(results):.3f} (UR5); over {len(t['ratios'])} scene and kt pairs, "
        f"{t['geomean']:.2f} times the steps to a residual of {LEVEL:g} (geometric mean; fewer "
        f"in {t['fewer']}, more in {t['more']}, as many in {t['equal']}).",
        f"- **kt**: the fewest steps to a residual of {LEVEL:g} came with kt = {chosen:g} "
        f"(geometric mean over the scenes of the steps over each scene's fewest: "
        + ", ".join(
            f"{kt:g}: {geomean([x for x in r if math.isfinite(x)]):.2f}" for kt, r in score.items()
        )
        + ").",
    ]
    for key in BASELINES:
        ratios, never = [], []
        for name, d in results.scenes.items():
            if key not in d.runs:
                continue
            tk, tb = time_to(d.runs["kd_exact"]), time_to(d.runs[key])
            if tb is None or tk is None:
                never.append(name)
            else:
                ratios.append(tb / tk)
        label = D.BASELINE_LABELS[key]
        text = f"- **{label}** (same dynamics, C++" + (
            ", c from the slowest mode at the answer): " if key != "fire" else "): "
        )
        if ratios:
            text += (
                f"{statistics.median(ratios):.2g} times KD's time to a residual of {LEVEL:g} "
                f"(median over {len(ratios)} scenes, {min(ratios):.2g} to {max(ratios):.2g})"
            )
        if never:
            text += ("; " if ratios else "") + f"not reached on {', '.join(never)}"
        lines.append(text + ".")
    if loop_scenes(results):
        lines.append(f"- The {trees_only(results)}.")
    kinds = {}
    for name, d in results.scenes.items():
        run = d.runs["newton_ls"]
        kind = f"{run.stability} root" if run.landing.q is not None else "no root"
        kinds.setdefault(kind, []).append(name)
    settled = [
        name
        for name, d in results.scenes.items()
        if all(d.runs[k].stability in ("stable", "neutral") for k in ("kd_exact", "kd_simplified"))
    ]
    lines.append(
        "- **Newton with a line search** from the same start: "
        + "; ".join(f"{kind} on {', '.join(v)}" for kind, v in kinds.items())
        + f"; kinetic damping rests stable or neutral on {len(settled)} of the "
        f"{len(results.scenes)} scenes."
    )
    names = loop_scenes(results)
    if names:
        parts = []
        for name in names:
            d = results.scenes[name]
            hit = d.runs["kd_exact"].reach("residual", LEVEL)
            ratio = loop_cost_ratio(results, name)
            parts.append(
                f"{name} "
                + (f"{fmt_steps(hit[0])} steps, {fmt_time(hit[1])}" if hit else "not reached")
                + (f" (a step: {ratio:.2f})" if math.isfinite(ratio) else "")
            )
        worst = max(worst_constraint_error(results.scenes[n]) for n in names)
        lines.append(
            f"- **Closed loops** (constrained dynamics, projections onto the loops): to a "
            f"residual of {LEVEL:g} along the allowed motions, "
            + "; ".join(parts)
            + f"; final constraint error at most {fmt_e(worst)} m over every KD run. A step "
            "costs, in brackets, that many times a bare `pinocchio::constraintDynamics` + "
            "`integrate` step (`benchmarks/loop_step_cost.cpp`)."
        )
    lines.append(README_END)
    wrapped = []
    for line in lines:
        bullet = line.startswith("- ")
        wrapped.append(
            textwrap.fill(line, 100, subsequent_indent="  " if bullet else "")
            if line and not line.startswith("<!--")
            else line
        )
    return "\n".join(wrapped)


def update_readme(results: D.Results, readme: Path) -> bool:
    """Replace the block between the markers; False when the README has none."""
    text = readme.read_text(encoding="utf-8")
    start, end = text.find(README_BEGIN), text.find(README_END)
    if start < 0 or end < 0:
        return False
    text = text[:start] + readme_block(results) + text[end + len(README_END) :]
    readme.write_text(text, encoding="utf-8")
    return True

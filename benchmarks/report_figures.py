"""The figures of the benchmark report (matplotlib, written as PNG)."""

from __future__ import annotations

import statistics
from pathlib import Path
from typing import Any

import numpy as np
import report_data as D
from report_measures import LEVEL, measured_chains, solve_steps, solve_time, time_to

#: Values below this are drawn at it on the log axes (exact zeros happen at round-off).
FLOOR = 1e-17


#: The damped baselines' plain runs, by run key.
_DAMPED_STYLE: dict[str, dict[str, Any]] = {
    "viscous_rule": dict(color="C1", ls="-", label="viscous, joint dampers (rule)"),
    "viscous_best": dict(color="C1", ls="--", label="viscous, joint dampers (best)"),
    "mass_damping_rule": dict(color="C2", ls="-", label="viscous, mass-proportional (rule)"),
    "mass_damping_best": dict(color="C2", ls="--", label="viscous, mass-proportional (best)"),
    "adr_rule": dict(color="C7", ls="-", label="adaptive DR (rule)"),
    "adr_best": dict(color="C7", ls="--", label="adaptive DR (best)"),
    "fire_rule": dict(color="C3", ls="-", label="FIRE (rule)"),
    "fire_best": dict(color="C3", ls="--", label="FIRE (best)"),
    "fire2_rule": dict(color="C6", ls="-", label="FIRE 2.0 (rule)"),
    "fire2_best": dict(color="C6", ls="--", label="FIRE 2.0 (best)"),
}
STYLE: dict[str, dict[str, Any]] = {
    "kd_exact": dict(color="C0", ls="-", lw=2, label="KD, exact energy"),
    "kd_simplified": dict(color="C0", ls="--", label="KD, simplified energy"),
    **_DAMPED_STYLE,
    # The same finished by the solver's Newton: their colour, dotted.
    **{
        f"{family}{D.NEWTON_SUFFIX}_{kind}": dict(
            _DAMPED_STYLE[f"{family}_{kind}"],
            ls=":" if kind == "rule" else "-.",
            label=_DAMPED_STYLE[f"{family}_{kind}"]["label"].replace(
                f" ({kind})", f" + Newton ({kind})"
            ),
        )
        for family in D.DAMPED_LABELS
        for kind in ("rule", "best")
    },
    "newton_tr_rule": dict(
        color="C8", ls="-", marker="^", ms=3, label="Newton, trust region (rule)"
    ),
    "newton_tr_best": dict(
        color="C8", ls="--", marker="^", ms=3, label="Newton, trust region (best)"
    ),
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


def gallery_figure(results: D.Results, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = results.gallery
    fig, ax = plt.subplots(figsize=(11, 4.8))
    x = np.arange(len(rows))
    kd = [statistics.median(r["seconds"]) for r in rows]
    # pinsettle's time only: MuJoCo runs here at one setting, to compare the answers, and its
    # time at that setting is no measure of its speed (that is MuJoCo at its best, per robot).
    ax.bar(x, kd, width=0.6, label="pinsettle, default settings", color="C0")
    ax.set_xticks(x, [r["name"] for r in rows], rotation=60, ha="right", fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("wall time (s)")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("The robot gallery: pinsettle's solve, root fixed, released from neutral")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)

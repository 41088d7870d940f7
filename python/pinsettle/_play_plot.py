"""The energy plot of a solve: both kinetic energy measures against time, with its events."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ._play_extra import require
from ._solve import Result

#: The energy measures: field of the trace, line width, colour, legend.
_MEASURES = (
    ("kinetic_energy", 1.4, "#1864ab", "exact  Σ ½m|v|² + ½ωᵀIω  (J)"),
    ("simplified_kinetic_energy", 1.1, "#e8590c", "simplified  Σ |v|² + |ω|²  (m²/s², rad²/s²)"),
)
#: The events marked: kind, colour, opacity of its vertical lines.
_EVENT_STYLES = (
    ("damping", "#f59f00", 0.35),
    ("push", "#1c7ed6", 0.9),
    ("rollback", "#e03131", 0.9),
    ("impact", "#d6336c", 0.8),
)


def plot_energy(result: Result, path: str | Path, *, title: str | None = None) -> Path:
    """Both energy measures of ``result.trace`` against simulated time on a log scale, with
    the damping events (and pushes, roll-backs) marked, saved as PNG at ``path``."""
    require("matplotlib")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not isinstance(result, Result):
        raise TypeError(f"result must be a pinsettle.Result, got {type(result).__name__}")
    trace = result.trace
    if trace is None:
        raise ValueError("result has no trace: solve with trace_every=1 (or more) to plot it")
    path = Path(path)
    fig = Figure(figsize=(8.0, 4.2), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    t = np.asarray(trace.time, dtype=float)
    for name, width, color, label in _MEASURES:
        ax.plot(t, _positive(getattr(trace, name)), lw=width, color=color, label=label)
    ax.set_yscale("log")
    _mark_events(ax, result)
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("kinetic energy")
    heading = f"{title}: " if title else ""
    ax.set_title(
        f"{heading}{result.status}, {result.steps} steps, {result.peaks} damping events",
        fontsize=11,
    )
    ax.grid(True, which="major", alpha=0.3)
    ax.set_xlim(*_time_range(t, result))
    # Below the axes, never on the curves (they fill the axes wherever the run went).
    fig.legend(loc="outside lower center", ncols=2, fontsize=8, frameon=False)
    fig.savefig(path, format="png")
    return path


def _time_range(t: np.ndarray, result: Result) -> tuple[float, float]:
    """The time axis: the trace's first sample to the end of the run; a run of one sample or
    none (a free body refused before its first step) gets one time step (or 1 ms) of axis, not
    an empty range."""
    low = float(t[0]) if t.size and np.isfinite(t[0]) else 0.0
    end = max(float(t[-1]) if t.size else low, float(result.sim_time))
    if not np.isfinite(end) or end <= low:
        step = float(result.dt)
        end = low + (step if np.isfinite(step) and step > 0 else 1e-3)
    return low, end


def _positive(values: Any) -> np.ndarray:
    """The values a log scale can show; NaN (a gap) for the others."""
    values = np.asarray(values, dtype=float)
    return np.where(np.isfinite(values) & (values > 0), values, np.nan)


def _mark_events(ax: Any, result: Result) -> None:
    """A vertical line at each event of the trace, a colour per kind."""
    assert result.trace is not None
    kinds = np.asarray(result.trace.event_kind, dtype=object)
    event_t = np.asarray(result.trace.event_time, dtype=float)
    for kind, color, alpha in _EVENT_STYLES:
        times = event_t[kinds == kind] if kinds.size else np.zeros(0)
        if times.size:
            ax.vlines(
                times,
                0,
                1,
                transform=ax.get_xaxis_transform(),
                colors=color,
                alpha=alpha,
                lw=0.7,
                label=f"{kind} events ({times.size}{_impact_names(result, kind)})",
            )


def _impact_names(result: Result, kind: str) -> str:
    """For the legend of impacts: which joints hit a stop (at most three named)."""
    trace = result.trace
    if kind != "impact" or trace is None or len(trace.event_joint) != len(trace.event_kind):
        return ""
    names = list(result.joints)  # the model's joints 1, 2, ... in order
    hit = sorted(
        {int(j) for j, k in zip(trace.event_joint, trace.event_kind, strict=True) if k == kind}
    )
    named = [names[j - 1] for j in hit if 0 < j <= len(names)]
    if not named:
        return ""
    more = f" and {len(named) - 3} more" if len(named) > 3 else ""
    return ": " + ", ".join(named[:3]) + more

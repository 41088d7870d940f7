"""The continuation figure of the README: the bistable pendulum's rest angle against its spring's
rest length, both branches and the jump (docs/sweep_bistable_fold.png).

The scene is robots/bistable_pendulum.toml with a constant 0.5 N m on its hinge: without it the
two tilted rests are mirror images and grow out of the hanging one continuously (a symmetric
pitchfork, no jump anywhere); the torque favours the positive side, so the negative branch ends
at a fold. Two sweeps with continuation (``pinsettle.sweep``, each case released from the
previous rest): down from L0 = 2.2 m on the negative branch (it jumps at the fold), and up from
L0 = 1.0 m (it follows the positive branch throughout). The lines are the equilibria of the
closed form V = -m g l cos t + 1/2 k (d - L0)^2 - tau t, found by bisection, nothing of
pinsettle's; the fold is where the negative stable branch meets the unstable one.

    python benchmarks/sweep_fold.py [--out docs/sweep_bistable_fold.png]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pinsettle
from scipy.optimize import brentq

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.axes import Axes

ROOT = Path(__file__).resolve().parents[1]
M, G, L, H, K, TAU = 1.0, 9.81, 1.0, 2.0, 40.0, 0.5
LOW, HIGH, N = 1.0, 2.2, 49


def torque(t: float, rest_length: float) -> float:
    """dV/dt: zero at an equilibrium."""
    d = math.sqrt(L * L + H * H - 2 * L * H * math.cos(t))
    return math.sin(t) * (M * G * L + K * (d - rest_length) * L * H / d) - TAU


def equilibria(rest_length: float) -> list[tuple[float, bool]]:
    """Every equilibrium angle in (-pi, pi) and whether it is stable (dV/dt rising through it)."""
    grid = np.linspace(-math.pi + 1e-9, math.pi - 1e-9, 4001)
    values = [torque(t, rest_length) for t in grid]
    out = []
    for a, b, fa, fb in zip(grid[:-1], grid[1:], values[:-1], values[1:], strict=True):
        if (fa < 0) != (fb < 0):
            out.append((brentq(torque, a, b, args=(rest_length,), xtol=1e-14), fa < 0))
    return out


def fold() -> float:
    """The rest length below which the negative stable branch is gone (bisection)."""

    def has_negative(rest_length: float) -> bool:
        return any(t < 0 and stable for t, stable in equilibria(rest_length))

    low, high = LOW, HIGH
    while high - low > 1e-10:
        middle = 0.5 * (low + high)
        low, high = (middle, high) if not has_negative(middle) else (low, middle)
    return 0.5 * (low + high)


def scene() -> pinsettle.Scene:
    out = pinsettle.load_scene(pinsettle.scene_path("bistable_pendulum"))
    out.add_load("hinge", TAU)
    return out


def continuation() -> tuple[pd.DataFrame, pd.DataFrame, int]:
    """The two sweeps (down from HIGH started on the negative side, up from LOW) and the case
    where the sweep down jumps (checked: the only jump of either)."""
    lengths = np.linspace(HIGH, LOW, N)
    down = pinsettle.sweep(scene(), {"spring[0].rest_length": lengths}, [[-1.0]], progress=False)
    up = pinsettle.sweep(scene(), {"spring[0].rest_length": lengths[::-1]}, [[0.0]], progress=False)
    jumps = down[down["jump"].fillna(False)]
    assert len(jumps) == 1 and not up["jump"].fillna(False).any()
    return down, up, jumps.index[0]


def draw_closed_form(ax: Axes) -> None:
    """The hanging-side equilibria (the one near pi is the top, a maximum, left out)."""
    dense = np.linspace(LOW, HIGH, 400)
    points = [(x, t, s) for x in dense for t, s in equilibria(x) if abs(t) < 2.5]
    for stable, style, label in (
        (True, "o", "stable equilibria (closed form)"),
        (False, "x", "unstable equilibria (closed form)"),
    ):
        xs = [x for x, _, s in points if s == stable]
        ts = [t for _, t, s in points if s == stable]
        ax.plot(xs, ts, style, ms=1.5, color="0.5" if stable else "0.65", label=label)


def draw_down(ax: Axes, down: pd.DataFrame, jump: int) -> tuple[float, float, float, float]:
    """The sweep down, in two pieces joined by an arrow at its jump; the jump's two ends
    (rest lengths x0, x1 and angles t0, t1)."""
    x, t = down["spring[0].rest_length"], down["hinge"]
    ax.plot(
        x[:jump],
        t[:jump],
        "v-",
        color="C3",
        ms=5,
        lw=1,
        label="sweep down from L0 = 2.2 m, started at -1 rad",
    )
    ax.plot(x[jump:], t[jump:], "v-", color="C3", ms=5, lw=1)
    x0, x1 = x[jump - 1], x[jump]
    t0, t1 = t[jump - 1], t[jump]
    ax.annotate(
        "",
        xy=(x1, t1),
        xytext=(x0, t0),
        arrowprops={"arrowstyle": "->", "color": "C3", "lw": 1.5, "ls": "--"},
    )
    ax.text(x1 + 0.02, 0.5 * (t0 + t1), f"jump (case {jump})", color="C3", va="center")
    return x0, x1, t0, t1


def draw_up_and_fold(ax: Axes, up: pd.DataFrame, where: float) -> None:
    ax.plot(
        up["spring[0].rest_length"],
        up["hinge"],
        "^",
        color="C0",
        ms=4,
        mfc="none",
        label="sweep up from L0 = 1.0 m, started at 0 rad",
    )
    ax.axvline(where, color="k", lw=0.8, ls=":")
    ax.set_ylim(-1.5, 1.6)
    ax.text(where, 1.5, f" fold (closed form) L0 = {where:.4f} m", va="top")
    ax.set_xlabel("spring rest length L0 (m)")
    ax.set_ylabel("rest angle of the hinge (rad)")
    ax.set_title("Bistable pendulum, 0.5 N m on its hinge: continuation over the rest length")
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, 0.93), fontsize=8)
    ax.grid(alpha=0.3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "sweep_bistable_fold.png")
    args = parser.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    down, up, jump = continuation()
    where = fold()
    fig, ax = plt.subplots(figsize=(8, 5), dpi=120)
    draw_closed_form(ax)
    x0, x1, t0, t1 = draw_down(ax, down, jump)
    draw_up_and_fold(ax, up, where)
    fig.tight_layout()
    fig.savefig(args.out)
    print(f"fold (closed form)       L0 = {where:.6f} m")
    print(
        f"jump between             L0 = {x0:.4f} m (hinge {t0:.6f}) and {x1:.4f} m (hinge {t1:.6f})"
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

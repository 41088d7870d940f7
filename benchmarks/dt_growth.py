"""Measure how far the automatic step may grow between damping events (``dt_growth``).

Every robot of ``pinsettle robots`` (root fixed, its stops on), chains of robots/make_chain.py
(5 to 100 links, released horizontal, no stops) and every scene of the library are solved with
the default settings but ``dt_growth``; for each value the table gives the steps over those with
``dt_growth = 1`` (the step fixed between estimates: geometric mean, and the runs that took more
than 10 % more), the total wall time of one solve each, and the runs whose status or stability
changed. docs/method.md quotes the table.

    python benchmarks/dt_growth.py            # print the section (about a minute)
    python benchmarks/dt_growth.py --write    # and put it into docs/benchmarks.md

The section is a delimited block that benchmarks/report.py keeps when it regenerates the rest.
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
from sweep_throughput import write

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "robots"))
from make_chain import chain_urdf  # noqa: E402  (robots/make_chain.py)

GROWTHS = [1.0, 1.5, 2.0, 2.5, 3.0, 4.0]
CHAINS = [5, 10, 20, 50, 100]
BEGIN = "<!-- step:growth (written by benchmarks/dt_growth.py) -->"
END = "<!-- /step:growth -->"
SHOWN = ("chain20", "chain100", "so_arm100", "kinova", "ur5", "xarm7", "pendulum_upright")


def problems() -> list[tuple[str, Callable[..., pinsettle.Result]]]:
    out: list[tuple[str, Callable[..., pinsettle.Result]]] = []
    for name in pinsettle.robot_names():
        model = pinsettle.load_robot(name, floating=False)
        out.append((name, lambda m=model, **kw: pinsettle.solve(m, **kw)))
    for n in CHAINS:
        model = pinocchio.buildModelFromXML(chain_urdf(n))
        q0 = np.zeros(model.nq)
        q0[0] = np.pi / 2
        out.append(
            (f"chain{n}", lambda m=model, q=q0, **kw: pinsettle.solve(m, q, limits=False, **kw))
        )
    for name in pinsettle.scene_names():
        scene = pinsettle.load_scene(pinsettle.scene_path(name))
        out.append((name, lambda s=scene, **kw: pinsettle.solve(s, **kw)))
    return out


def section(runs: dict[float, dict[str, pinsettle.Result]]) -> str:
    base = runs[1.0]
    load = os.getloadavg()[0]
    lines = [
        BEGIN,
        "## The step's growth between damping events",
        "",
        f"Measured by `python benchmarks/dt_growth.py --write` ({datetime.date.today()}, "
        f"1-minute load average {load:.2f} at its end). Every robot of `pinsettle robots` (root "
        f"fixed, stops on), chains of {', '.join(map(str, CHAINS))} links (released horizontal) "
        f"and every library scene, {len(base)} runs, solved with the default settings but "
        '`dt_growth` (the default `"auto"` is 2.5 with backtracking, the exact energy and '
        "stiff-mode scaling); "
        "steps over those with the step fixed between estimates (`dt_growth = 1`), the runs that "
        "took over 10 % more, the total time of one solve each, and any change of status or "
        "stability. Why 2.5 and what lost: docs/method.md (Step growth between damping events).",
        "",
        "| dt_growth | steps over dt_growth = 1 (geometric mean) | over 10 % more steps "
        "| total time (ms) | status or stability changed |",
        "| ---: | ---: | --- | ---: | --- |",
    ]
    for g in GROWTHS:
        ratios = [runs[g][k].steps / base[k].steps for k in base]
        more = [k for k in base if runs[g][k].steps > 1.1 * base[k].steps]
        changed = [
            k
            for k in base
            if (runs[g][k].status, runs[g][k].stability) != (base[k].status, base[k].stability)
        ]
        total = 1e3 * sum(r.wall_time for r in runs[g].values())
        geo = math.exp(sum(math.log(x) for x in ratios) / len(ratios))
        lines.append(
            f"| {g:g} | {geo:.3f} | {', '.join(more) or '-'} | {total:.0f} "
            f"| {', '.join(changed) or '-'} |"
        )
    lines += ["", "Steps with a fixed step and with the default growth (2.5):", ""]
    lines += [f"- `{k}`: {base[k].steps:,} -> {runs[2.5][k].steps:,}" for k in SHOWN]
    return "\n".join(lines + [END]) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="put it into docs/benchmarks.md")
    args = parser.parse_args()
    runs: dict[float, dict[str, pinsettle.Result]] = {g: {} for g in GROWTHS}
    for name, solve in problems():
        for g in GROWTHS:
            runs[g][name] = solve(dt_growth=g)
    text = section(runs)
    print(text)
    if args.write:
        write(text, begin=BEGIN, end=END)


if __name__ == "__main__":
    main()

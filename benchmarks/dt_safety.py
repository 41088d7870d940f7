"""Measure the safety factor c of the automatic time step (dt = c * critical step).

For every scene of the library that has an equilibrium and every kt in {0, 0.5, 0.9}, solve
with dt='auto' for a range of c and report how many runs converge to a rest that is not
unstable (stable, neutral, or marginal: a rest on contacts within 1 % of sliding, as go1 with
its motors off may come to) and the steps they take. The default c is the one with every run
converged and the fewest steps in total (docs/robustness.md quotes this table).
Run: python benchmarks/dt_safety.py
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import pinsettle

FACTORS = [0.02, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 1.0]
KTS = [0.0, 0.5, 0.9]
NO_EQUILIBRIUM = {"torque_disk", "free_fall", "overloaded_pendulum"}


def measure(factors: list[float], max_steps: int) -> list[dict[str, Any]]:
    rows = []
    scenes = [s for s in pinsettle.scene_names() if s not in NO_EQUILIBRIUM]
    for c in factors:
        runs = []
        start = time.perf_counter()
        for name in scenes:
            scene = pinsettle.load_scene(pinsettle.scene_path(name))
            for kt in KTS:
                r = pinsettle.solve(
                    scene, dt="auto", dt_safety=c, kt=kt, max_steps=max_steps, max_time=60.0
                )
                ok = r.converged and r.stability in ("stable", "neutral", "marginal")
                runs.append((name, kt, ok, r.steps, r.dt_reductions, r.residual))
        rows.append(
            {
                "c": c,
                "converged": sum(run[2] for run in runs),
                "runs": len(runs),
                "total_steps": sum(run[3] for run in runs),
                "median_steps": statistics.median(run[3] for run in runs),
                "reductions": sum(run[4] for run in runs),
                "failed": [f"{run[0]} kt={run[1]}" for run in runs if not run[2]],
                "seconds": time.perf_counter() - start,
            }
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--max-steps", type=int, default=2_000_000)
    args = parser.parse_args()
    print("| c | converged | total steps | median steps | step halvings | failed |")
    print("| --- | --- | --- | --- | --- | --- |")
    for row in measure(FACTORS, args.max_steps):
        print(
            f"| {row['c']} | {row['converged']}/{row['runs']} | {row['total_steps']:,} "
            f"| {row['median_steps']:,.0f} | {row['reductions']} | {', '.join(row['failed'])} |",
            flush=True,
        )


if __name__ == "__main__":
    main()

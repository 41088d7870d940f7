"""What the Python layer adds to a solve: the time of a warm solve outside the C++ run, and the
first solve in a process against the next, on the UR5 (example-robot-data's URDF, the model's
limits as stops, default settings).

- Warm: ``pinsettle.Solver(model)`` made once, then ``solver.solve()`` called again and again;
  and ``pinsettle.solve(model)``, which makes a Solver for each call. The Python overhead of a
  call is its wall time (``time.perf_counter`` around the call) less the C++ run's own
  (``Result.wall_time``, timed inside ``pinsettle::Solver::solve``). Blocks of calls of the
  two kinds alternate; the median over the calls of each kind is kept.
- First: fresh processes, each importing pinsettle and loading the model (not timed), then
  timing its first solve and the next ones. The median over the processes of first / next.

Targets (issue 41): the overhead of a warm ``Solver.solve`` at most 10% of the C++ run; the
first solve in a process at most 1.5 times the next one.

    python benchmarks/python_overhead.py            # print the section
    python benchmarks/python_overhead.py --write     # and put it into docs/benchmarks.md

The section is a delimited block (``<!-- python:overhead ... -->``) that benchmarks/report.py
keeps when it regenerates the rest of the file.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import subprocess
import sys
import time
from typing import Any

import pinsettle
from sweep_throughput import DOC, write

BEGIN = "<!-- python:overhead (written by benchmarks/python_overhead.py) -->"
END = "<!-- /python:overhead -->"
ROBOT = "ur5"
MAX_OVERHEAD = 0.10  # of the C++ run
MAX_FIRST_RATIO = 1.5
WARM_UP_SECONDS = 1.0

# One fresh process: its first solves, timed (kind: "solve" for pinsettle.solve, "solver"
# for a Solver made before the clock starts).
_FIRST = """
import json, sys, time
import pinsettle
model = pinsettle.load_robot(sys.argv[1])
kind, calls = sys.argv[2], int(sys.argv[3])
solver = pinsettle.Solver(model) if kind == "solver" else None
walls, cores = [], []
for _ in range(calls):
    start = time.perf_counter()
    result = solver.solve() if solver is not None else pinsettle.solve(model)
    walls.append(time.perf_counter() - start)
    cores.append(result.wall_time)
print(json.dumps({"walls": walls, "cores": cores}))
"""

# A bare Pinocchio call in a fresh process, for reference: its first and next times.
_PINOCCHIO_FIRST = """
import json, sys, time
import numpy as np
import pinocchio
import pinsettle
model = pinsettle.load_robot(sys.argv[1])
data = model.createData()
q, zero = pinocchio.neutral(model), np.zeros(model.nv)
walls = []
for _ in range(3):
    start = time.perf_counter()
    pinocchio.aba(model, data, q, zero, zero)
    walls.append(time.perf_counter() - start)
print(json.dumps({"walls": walls}))
"""


def fresh_process(script: str, *args: str) -> dict[str, Any]:
    """The JSON object ``script`` prints last, run with ``args`` in a fresh Python process."""
    done = subprocess.run(
        [sys.executable, "-c", script, *args], capture_output=True, text=True, check=True
    )
    record: dict[str, Any] = json.loads(done.stdout.splitlines()[-1])
    return record


def warm(repeats: int, calls: int) -> dict[str, dict[str, float]]:
    """Median wall time, C++ run and overhead (s) of warm ``Solver.solve`` and
    ``pinsettle.solve`` calls, in alternating blocks."""
    model = pinsettle.load_robot(ROBOT)
    solver = pinsettle.Solver(model)
    runs: dict[str, Any] = {"solver": solver.solve, "solve": lambda: pinsettle.solve(model)}
    walls: dict[str, list[float]] = {kind: [] for kind in runs}
    cores: dict[str, list[float]] = {kind: [] for kind in runs}
    # Warmed up for a second of calls: the processor's clock and caches settle (the first
    # blocks after an idle spell ran 1.6 times slower, the overhead 2.2 times).
    end = time.perf_counter() + WARM_UP_SECONDS
    while time.perf_counter() < end:
        for run in runs.values():
            run()
    for _ in range(repeats):
        for kind, run in runs.items():
            for _ in range(calls):
                start = time.perf_counter()
                result = run()
                walls[kind].append(time.perf_counter() - start)
                cores[kind].append(result.wall_time)
    out = {}
    for kind in runs:
        overhead = [w - c for w, c in zip(walls[kind], cores[kind], strict=True)]
        out[kind] = {
            "wall": statistics.median(walls[kind]),
            "core": statistics.median(cores[kind]),
            "overhead": statistics.median(overhead),
        }
    return out


def first(processes: int, calls: int = 21) -> dict[str, dict[str, float]]:
    """Median over fresh processes of the first solve's wall time, the next one's, the median
    of the 20 after, and the ratios."""
    out = {}
    for kind in ("solve", "solver"):
        firsts, seconds, laters, core_first, core_next = [], [], [], [], []
        for _ in range(processes):
            record = fresh_process(_FIRST, ROBOT, kind, str(calls))
            walls, cores = record["walls"], record["cores"]
            core_first.append(cores[0])
            core_next.append(cores[1])
            firsts.append(walls[0])
            seconds.append(walls[1])
            laters.append(statistics.median(walls[2:]))
        out[kind] = {
            "first": statistics.median(firsts),
            "next": statistics.median(seconds),
            "later": statistics.median(laters),
            "ratio": statistics.median(f / s for f, s in zip(firsts, seconds, strict=True)),
            "ratio_later": statistics.median(f / s for f, s in zip(firsts, laters, strict=True)),
            "core_first": statistics.median(core_first),
            "core_next": statistics.median(core_next),
            "core_ratio": statistics.median(
                f / s for f, s in zip(core_first, core_next, strict=True)
            ),
        }
    out["aba"] = pinocchio_first(processes)
    return out


def pinocchio_first(processes: int) -> dict[str, float]:
    """Median over fresh processes of Pinocchio's ``aba`` on the model, its first call and the
    next, and their ratio: what a first call costs on this machine without pinsettle."""
    firsts, seconds = [], []
    for _ in range(processes):
        walls = fresh_process(_PINOCCHIO_FIRST, ROBOT)["walls"]
        firsts.append(walls[0])
        seconds.append(walls[1])
    return {
        "first": statistics.median(firsts),
        "next": statistics.median(seconds),
        "ratio": statistics.median(f / s for f, s in zip(firsts, seconds, strict=True)),
    }


US = 1e6  # us per s


def warm_lines(hot: dict[str, dict[str, float]]) -> list[str]:
    """The warm calls' table and what it means."""
    lines = [
        f"On the {ROBOT.upper()} (limits as stops, default settings). A warm solve's Python "
        "overhead is its wall time less the C++ run's own (`Result.wall_time`): medians over "
        "alternating blocks of calls.",
        "",
        "| call | wall | C++ run | Python overhead | share of the C++ run |",
        "|---|---|---|---|---|",
    ]
    labels = {"solver": "`solver.solve()` (a `Solver` kept)", "solve": "`pinsettle.solve(model)`"}
    for kind, label in labels.items():
        h = hot[kind]
        lines.append(
            f"| {label} | {h['wall'] * US:.1f} us | {h['core'] * US:.1f} us | "
            f"{h['overhead'] * US:.1f} us | {h['overhead'] / h['core']:.1%} |"
        )
    return lines + [
        "",
        "`pinsettle.solve` makes a `Solver` for each call (the model's stops and joints read, "
        "Pinocchio's data allocated): keep a `Solver` to solve one mechanism many times "
        "(`pinsettle.sweep` keeps one per scene variant and worker thread).",
    ]


def first_lines(cold: dict[str, dict[str, float]]) -> list[str]:
    """The first calls' table, and how much of the first call's extra time is the C++ run's."""
    lines = [
        "The first solve in a fresh process against the next ones (medians over the "
        "processes; importing pinsettle and loading the model not timed):",
        "",
        "| call | first | next | first / next | median of the 20 after | first / those |",
        "|---|---|---|---|---|---|",
    ]
    for kind, label in (("solve", "`pinsettle.solve(model)`"), ("solver", "`solver.solve()`")):
        c = cold[kind]
        lines.append(
            f"| {label} | {c['first'] * US:.0f} us | {c['next'] * US:.0f} us | "
            f"{c['ratio']:.2f} | {c['later'] * US:.0f} us | {c['ratio_later']:.2f} |"
        )
    c, a = cold["solve"], cold["aba"]
    return lines + [
        "",
        f"The C++ run itself is slower the first time in a process: {c['core_first'] * US:.0f} us "
        f"against {c['core_next'] * US:.0f} us the next time (`Result.wall_time`), "
        f"{(c['core_first'] - c['core_next']) * US:.0f} us of the first call's "
        f"{(c['first'] - c['next']) * US:.0f} us more: its code and data are not yet in the "
        "processor's caches (a second mechanism's first solve in the same process runs at the "
        "warm speed). What the Python layer did only once (finding numpy's C API, reading a "
        "model's joints one vector at a time) is done at import or in one call now.",
        "",
        "The target is below what a first call costs on this machine: the C++ run alone is "
        f"{c['core_ratio']:.2f} "
        "times its next run (median over the processes), above the 1.5 target before any "
        "Python is counted, and a bare Pinocchio call is slower still the first time: "
        f"`pinocchio.aba` on the {ROBOT.upper()} takes {a['first'] * US:.0f} us in a fresh "
        f"process and {a['next'] * US:.1f} us the next time ({a['ratio']:.0f} times). The "
        "first call's extra time is not extra work: counted in instructions "
        "(`valgrind --tool=callgrind`), the first and the second C++ run are the same, and "
        "with every page of pinsettle's and Pinocchio's code touched before the first solve "
        "(no page faults left in it; measured once, in three processes) the first run was "
        "still 1.7 to 2.1 times the next. Only running "
        "a solve before the user's (a warm-up at import) would meet the target, and that "
        "would move the time, not save it.",
    ]


def section(hot: dict[str, dict[str, float]], cold: dict[str, dict[str, float]]) -> str:
    share = hot["solver"]["overhead"] / hot["solver"]["core"]
    ratio = cold["solve"]["ratio"]
    verdict = "met" if share <= MAX_OVERHEAD else "**not met**"
    first_verdict = "met" if ratio <= MAX_FIRST_RATIO else "**not met**"
    lines = [
        BEGIN,
        "## The Python layer's cost",
        "",
        f"*Measured on {datetime.date.today().isoformat()} by `benchmarks/python_overhead.py`; "
        f"1-minute load average {os.getloadavg()[0]:.2f} at the end.*",
        "",
        *warm_lines(hot),
        "",
        *first_lines(cold),
        "",
        f"Targets: a warm `Solver.solve`'s overhead at most {MAX_OVERHEAD:.0%} of the C++ run: "
        f"{share:.1%}, {verdict}; the first `pinsettle.solve` in a process at most "
        f"{MAX_FIRST_RATIO} times the next: {ratio:.2f}, {first_verdict}.",
        END,
    ]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=11)
    parser.add_argument("--processes", type=int, default=11)
    parser.add_argument("--quick", action="store_true", help="a tiny run, to try it")
    parser.add_argument("--write", action="store_true", help=f"put the section into {DOC}")
    args = parser.parse_args()
    hot = warm(2 if args.quick else args.repeats, 20 if args.quick else 200)
    cold = first(2 if args.quick else args.processes, 5 if args.quick else 21)
    text = section(hot, cold)
    print(text)
    if args.write:
        write(text, DOC, BEGIN, END)
        print(f"wrote the section into {DOC}")


if __name__ == "__main__":
    main()

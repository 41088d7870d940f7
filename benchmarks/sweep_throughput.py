"""Throughput of sweeps (issue 17): solves per second on the UR5 and the bistable pendulum by a
plain Python loop over ``pinsettle.solve``, by ``pinsettle.sweep`` on 1 and 2 local threads, and
on a ``dask.distributed.LocalCluster`` of 2 worker processes; the Dask path's overhead per case.

The same cases everywhere: random starts drawn once (uniform inside the joints' stops) and passed
to every run as an array. Runs are interleaved, each timed whole (the sweep's planning, table
and, for Dask, sending the scene included; starting the cluster not), and the median of the
repeats kept. Every sweep's table is checked against the loop's results, to the bit (wall times
aside), before anything is reported.

    python benchmarks/sweep_throughput.py            # print the section
    python benchmarks/sweep_throughput.py --write    # and put it into docs/benchmarks.md
    python benchmarks/sweep_throughput.py --quick    # a tiny run, to try it

The section is a delimited block (``<!-- sweep:throughput ... -->``) that benchmarks/report.py
keeps when it regenerates the rest of the file.
"""

from __future__ import annotations

import argparse
import datetime
import os
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
import pinsettle
from pinsettle import _sweep

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "benchmarks.md"
BEGIN = "<!-- sweep:throughput (written by benchmarks/sweep_throughput.py) -->"
END = "<!-- /sweep:throughput -->"
SCENES = {"ur5": 300, "bistable_pendulum": 3000}
SEED = 17


def starts_of(scene: pinsettle.Scene, n: int) -> np.ndarray:
    return np.array(_sweep.random_starts(scene, None, n, SEED))


def loop(scene: pinsettle.Scene, starts: np.ndarray) -> list[pinsettle.Result]:
    return [pinsettle.solve(scene, q) for q in starts]


def check(df: Any, results: list[pinsettle.Result], names: list[str], what: str) -> None:
    """A sweep's rows are the loop's results, to the bit."""
    for (_, row), result in zip(df.iterrows(), results, strict=True):
        same = (
            row["status"] == result.status
            and row["steps"] == result.steps
            and row["residual"] == result.residual
            and all(row[name] == result.joints[name] for name in names)
        )
        if not same:
            raise AssertionError(
                f"{what}: case {row['case']} differs from pinsettle.solve: {row.to_dict()} "
                f"against {result.status}, {result.steps} steps, residual {result.residual!r}, "
                f"{result.joints}"
            )


def runs(scene: pinsettle.Scene, starts: np.ndarray, client: Any) -> dict[str, Any]:
    """The ways of solving the same cases, by name."""

    def sweep(**kwargs: Any) -> Any:
        return pinsettle.sweep(scene, starts=kwargs.pop("starts", starts), progress=False, **kwargs)

    return {
        "loop": lambda: loop(scene, starts),
        "sweep1": lambda: sweep(workers=1),
        "sweep2": lambda: sweep(workers=2),
        "dask": lambda: sweep(client=client),
        "dask1": lambda: sweep(client=client, chunk_size=1),
        "dask_one": lambda: sweep(client=client, starts=starts[:1]),
    }


def measure_scene(name: str, n: int, client: Any, repeats: int) -> dict[str, Any]:
    scene = pinsettle.load_scene(pinsettle.scene_path(name))
    starts = starts_of(scene, n)
    names = [scene.model.names[j] for j in range(1, scene.model.njoints)]
    ways = runs(scene, starts, client)
    times: dict[str, list[float]] = {key: [] for key in ways}
    solver: list[float] = []  # the loop's mean solver time per case, each repeat
    for run in ways.values():  # a warm-up of each (imports, the workers' first scene)
        run()
    results = loop(scene, starts)
    for _ in range(repeats):
        for key, run in ways.items():
            started = time.perf_counter()
            value = run()
            times[key].append(time.perf_counter() - started)
            if key.startswith("dask"):
                # The cluster forgets the tasks and its workers settle after the run: not on
                # the next run's clock.
                time.sleep(1.0)
            if key == "loop":
                solver.append(float(np.mean([r.wall_time for r in value])))
            else:
                check(value, results[: len(value)], names, f"{name} {key}")
    return {
        "cases": n,
        "solver": statistics.median(solver),
        "median": {key: statistics.median(t) for key, t in times.items()},
        "converged": sum(r.converged for r in results),
    }


def measure(repeats: int, scale: float) -> dict[str, Any]:
    import distributed

    cluster = distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=":0",
    )
    client = distributed.Client(cluster, set_as_default=False)
    out: dict[str, Any] = {"scenes": {}, "load_before": os.getloadavg()[0]}
    try:
        for name, n in SCENES.items():
            out["scenes"][name] = measure_scene(name, max(4, int(n * scale)), client, repeats)
    finally:
        client.close()
        cluster.close()
    out["load_after"] = os.getloadavg()[0]
    out["repeats"] = repeats
    return out


THROUGHPUT_INTRO = (
    "Measured by `python benchmarks/sweep_throughput.py --write` on this project's 2-core "
    "machine ({today}; load average {load_before:.1f} before, "
    "{load_after:.1f} after, this run's own two workers included{busy}). Random starts inside the "
    "stops, drawn once and passed to every run as an array, solved by a plain Python loop "
    "over `pinsettle.solve`, by `pinsettle.sweep` on 1 and 2 local threads, and by "
    "`pinsettle.sweep(client=...)` on a `dask.distributed.LocalCluster` of 2 worker "
    "processes with 1 thread each (127.0.0.1; default chunks, then one case per task). "
    "Median of {repeats} interleaved repeats, each timed whole (planning, the "
    "table and sending the scene included, starting the cluster not), all in one process "
    "with the Dask client connected (its thread shares the GIL). Every table was checked "
    "against the loop's results to the bit (wall times aside)."
)
#: Said in the intro when the machine was busy before the run.
BUSY = (
    ": other work was running, so the ratios below are uncertain to tens of percent; "
    "run it again on an idle machine"
)

THROUGHPUT_HEADER = [
    "| scene | cases | solver time per case | GIL released | loop over `solve` | "
    "sweep, 1 thread | sweep, 2 threads | Dask, 2 processes | Dask, 1 case per task |",
    "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
]


def gil_share(item: dict[str, Any]) -> float:
    """The share of a case's time spent in the C++ solve (the GIL released) in the loop."""
    return float(min(1.0, item["solver"] / (item["median"]["loop"] / item["cases"])))


def throughput_row(name: str, item: dict[str, Any]) -> str:
    n, median = item["cases"], item["median"]

    def cell(key: str) -> str:
        rate = n / median[key]
        return f"{rate:,.0f} /s ({median['loop'] / median[key]:.2f}x)"

    return (
        f"| {name} | {n} | {item['solver'] * 1e3:.3f} ms | {100 * gil_share(item):.0f}% | "
        f"{cell('loop')} | {cell('sweep1')} | {cell('sweep2')} | {cell('dask')} | "
        f"{cell('dask1')} |"
    )


def two_thread_bound(name: str, item: dict[str, Any]) -> str:
    """How much faster two threads can be than one with the scene's share released."""
    share = gil_share(item)
    return f"{name} {1 / ((1 - share) + share / 2):.2f}x"


def dask_overheads(name: str, item: dict[str, Any]) -> list[str]:
    """Worker time a case costs on the cluster beyond what it costs on one local thread."""
    n, median = item["cases"], item["median"]
    lines = []
    for key, how in (("dask", "default chunks"), ("dask1", "one case per task")):
        overhead = (2 * median[key] - median["sweep1"]) / n
        lines.append(
            f"- {name}, {how}: {overhead * 1e3:+.3f} ms per case "
            f"({median[key] / n * 1e3:.3f} ms of wall time per case)"
        )
    return lines


def section(data: dict[str, Any]) -> str:
    scenes = data["scenes"]
    intro = THROUGHPUT_INTRO.format(
        today=datetime.date.today().isoformat(),
        load_before=data["load_before"],
        load_after=data["load_after"],
        busy=BUSY if data["load_before"] > 1.0 else "",
        repeats=data["repeats"],
    )
    lines = [BEGIN, "## Sweeps: throughput", "", intro, "", *THROUGHPUT_HEADER]
    lines += [throughput_row(name, item) for name, item in scenes.items()]
    bounds = [two_thread_bound(name, item) for name, item in scenes.items()]
    lines += [
        "",
        "Solves per second (the loop's time over each run's in brackets). The solver time is "
        "the C++ loop's own (`Result.wall_time`, mean over the cases of the loop, median over "
        "the repeats), run with the GIL released; its share of the loop's time per case is the "
        "next column, the rest is Python (settings, the "
        "scene's specs, the result and its joint names), which threads run one at a time. "
        "With a share p released, two threads can be at most 1 / ((1 - p) + p / 2) times as "
        "fast as one: " + ", ".join(bounds) + " here; the load of the machine takes the rest.",
        "",
        "Overhead of the Dask path per case: worker-seconds per case on the cluster (its wall "
        "time times its 2 workers, over the cases) less the time per case of the sweep on one "
        "local thread:",
        "",
    ]
    lines += [line for name, item in scenes.items() for line in dask_overheads(name, item)]
    one = ", ".join(
        f"{name} {item['median']['dask_one'] * 1e3:.0f} ms" for name, item in scenes.items()
    )
    lines += [
        "",
        "A sweep of one case on the cluster (the scene sent to both workers, one task there "
        f"and back): {one}.",
        "",
        "On one machine the cluster only adds cost (pickling, the scheduler's round trips); it "
        "pays when the cases outnumber one machine's cores. Locally the threads share one "
        "Python interpreter: the C++ solves run in parallel with the GIL released, the Python "
        "around each solve does not.",
        END,
    ]
    return "\n".join(lines) + "\n"


def write(text: str, path: Path = DOC, begin: str = BEGIN, end: str = END) -> None:
    """Put the section (delimited by begin and end) into the file: in place of the old one, or
    at the end."""
    old = path.read_text(encoding="utf-8")
    if begin in old and end in old:
        head, rest = old.split(begin, 1)
        tail = rest.split(end, 1)[1]
        new = head + text.rstrip("\n") + tail
    else:
        new = old.rstrip("\n") + "\n\n" + text
    path.write_text(new, encoding="utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="tiny sizes, 1 repeat")
    parser.add_argument("--write", action="store_true", help=f"put the section into {DOC}")
    args = parser.parse_args()
    data = measure(1 if args.quick else args.repeats, 0.02 if args.quick else 1.0)
    text = section(data)
    print(text)
    if args.write:
        write(text)
        print(f"wrote the section into {DOC}")


if __name__ == "__main__":
    main()

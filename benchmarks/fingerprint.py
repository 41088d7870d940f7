"""Fingerprints of whole solves: steps, events and the final state to the last bit.

A refactoring of the step loop must not change a single trajectory. Run this before and after
and compare the two files:

    python benchmarks/fingerprint.py --out before.json      # on the old build
    python benchmarks/fingerprint.py --out after.json       # on the new build
    python benchmarks/fingerprint.py --compare before.json after.json

Covered: every scene of robots/ with its own settings and with each setting that changes the
loop's path (kt 0 and 0.9, backtracking, the simplified measure, a fixed step, polish, tracing),
every run of the stress suite (benchmarks/stress.py), and every robot of example-robot-data
with its root fixed, released from neutral with the default settings. A run's fingerprint is
its status, its counters and the exact bytes of its final q, v and residual.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pinsettle

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import stress  # noqa: E402  (benchmarks/stress.py)

# Settings that take the loop down each of its branches, on top of a scene's own.
VARIANTS: dict[str, dict[str, Any]] = {
    "default": {},
    "kt0": {"kt": 0.0},
    "kt0.9": {"kt": 0.9},
    "backtrack": {"backtrack": True},
    "simplified": {"energy": "simplified"},
    "fixed_dt": {"dt": 1e-3},
    "fixed_dt_too_large": {"dt": 0.2},  # the divergence guard rolls back and halves
    "full_stability_limit": {"dt_safety": 1.0},
    "polish": {"polish": True},
    "trace": {"trace_every": 3, "trace_capacity": 64, "trace_configurations": True},
    "no_stiff_scaling": {"scale_stiff_modes": False},
}
COUNTERS = (
    "status",
    "steps",
    "peaks",
    "pushes",
    "dt_estimates",
    "dt_reductions",
    "scaled_modes",
    "polish_iterations",
    "polished",
    "stability",
    "neutral_directions",
)


def _digest(*arrays: object) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(np.asarray(a, dtype=np.float64)).tobytes())
    return h.hexdigest()[:16]


def fingerprint(result: pinsettle.Result) -> dict[str, Any]:
    out = {name: getattr(result, name) for name in COUNTERS}
    out["state"] = _digest(result.q, result.v, [result.residual, result.sim_time, result.dt])
    out["energies"] = _digest([result.kinetic_energy, result.simplified_kinetic_energy])
    trace = result.trace
    if trace is not None:
        out["trace"] = _digest(
            trace.step,
            trace.time,
            trace.kinetic_energy,
            trace.simplified_kinetic_energy,
            [trace.stride],
            trace.q if trace.q is not None else [],
            trace.event_step,
            trace.event_time,
        )
        out["events"] = hashlib.sha256(",".join(trace.event_kind).encode()).hexdigest()[:16]
    out["reason"] = result.reason
    return out


def _runs() -> dict[str, dict[str, Any]]:
    runs: dict[str, dict[str, Any]] = {}
    for path in sorted((HERE.parent / "robots").glob("*.toml")):
        name = path.stem
        scene = pinsettle.load_scene(path)
        for variant, overrides in VARIANTS.items():
            runs[f"scene {name} {variant}"] = fingerprint(
                pinsettle.solve(scene, max_steps=200_000, **overrides)
            )
    for case, energy, kt in stress.runs():
        _, scene, q0 = case.build()
        result = pinsettle.solve(scene, q0, energy=energy, kt=kt, **case.settings)
        runs[f"stress {case.name} {energy} kt{kt:g}"] = fingerprint(result)
    for name in pinsettle.robot_names():
        model = pinsettle.load_robot(name, floating=False)
        runs[f"robot {name}"] = fingerprint(pinsettle.solve(model))
    return runs


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="write the fingerprints here (JSON)")
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("BEFORE", "AFTER"))
    args = parser.parse_args()
    if args.compare:
        before, after = (json.loads(p.read_text()) for p in args.compare)
        differ = [k for k in sorted(set(before) | set(after)) if before.get(k) != after.get(k)]
        for key in differ:
            print(f"differs: {key}\n  before {before.get(key)}\n  after  {after.get(key)}")
        print(f"{len(before)} runs before, {len(after)} after, {len(differ)} differ")
        return 1 if differ else 0
    start = time.perf_counter()
    runs = _runs()
    text = json.dumps(runs, indent=1, sort_keys=True)
    if args.out:
        args.out.write_text(text + "\n")
    else:
        print(text)
    print(f"{len(runs)} runs in {time.perf_counter() - start:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Time the README's first command as a new user runs it, phase by phase.

Each run: a fresh clone of this repository (or --repo), a fresh virtual environment and an empty
pip cache, then `pip install . && pinsettle demo ur5` in the clone, every output line stamped
with the time since the start. pip runs verbose (PIP_VERBOSE=1, to see the phases) and
scikit-build-core builds in a kept folder (SKBUILD_BUILD_DIR), whose .ninja_log gives each
translation unit's compile time; neither changes what is done. Prints the phases, the
translation units and the totals (median of the runs):

    python benchmarks/install_time.py --runs 3
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

COMMAND = "pip install . && pinsettle demo ur5"

# (phase name, regular expression of the line that starts it), in order. The build's own output
# comes from scikit-build-core and CMake (pip -v shows it).
MARKS = [
    ("build requirements (isolated env)", r"Installing build dependencies: started"),
    ("backend's requirements hook", r"Getting requirements to build wheel: started"),
    ("metadata", r"Preparing metadata .*: started"),
    ("run-time requirements: resolve", r"Preparing metadata .*: finished"),
    ("cmake configure", r"Building wheel for pinsettle .*: started"),
    # ninja prints a step when it ends: the compile starts when CMake's generation ends.
    ("compile + link (ninja)", r"Build files have been written to"),
    ("make wheel", r"\*\*\* Installing project into wheel"),
    ("install wheel + run-time requirements", r"Building wheel for pinsettle .*: finished"),
    ("pip's exit (removes its temporary folders)", r"^Successfully installed"),
]


def _stamp_lines(cmd: str, cwd: Path, env: dict[str, str], log: Path) -> list[tuple[float, str]]:
    """Run cmd in a shell; every output line with its time (s) since the start."""
    start = time.monotonic()
    lines: list[tuple[float, str]] = []
    with (
        log.open("w") as out,
        subprocess.Popen(
            ["bash", "-c", cmd],
            cwd=cwd,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        ) as proc,
    ):
        assert proc.stdout is not None
        for line in proc.stdout:
            t = time.monotonic() - start
            lines.append((t, line.rstrip("\n")))
            out.write(f"{t:8.2f} {line}")
        code = proc.wait()
    lines.append((time.monotonic() - start, f"[exit {code}]"))
    if code != 0:
        sys.exit(f"{cmd!r} failed ({code}); output in {log}")
    return lines


def _phases(lines: list[tuple[float, str]]) -> dict[str, float]:
    """Seconds per phase: from the first line matching a phase's mark to the next phase's."""
    starts: list[tuple[str, float]] = [("start (clone done, pip starting)", 0.0)]
    for name, pattern in MARKS:
        regex = re.compile(pattern)
        after = starts[-1][1]
        hit = next((t for t, line in lines if t >= after and regex.search(line)), None)
        if hit is not None:
            starts.append((name, hit))
    total = lines[-1][0]
    out: dict[str, float] = {}
    for (name, t0), (_, t1) in zip(starts, [*starts[1:], ("end", total)], strict=True):
        out[name] = round(t1 - t0, 1)
    out["total"] = round(total, 1)
    return out


def _ninja_times(build_dir: Path) -> dict[str, float]:
    """Seconds per ninja output (object file, library, module), from .ninja_log."""
    log = build_dir / ".ninja_log"
    times: dict[str, float] = {}
    if not log.exists():
        return times
    for line in log.read_text().splitlines()[1:]:
        start, end, _, output, _ = line.split("\t")
        name = re.sub(r"^(core/)?CMakeFiles/[^/]+\.dir/", "", output)
        times[name] = round((int(end) - int(start)) / 1000.0, 1)
    return times


def one_run(repo: Path, ref: str, work: Path, python: str) -> dict[str, object]:
    """A fresh clone, venv and pip cache under work; the command timed."""
    src, venv, cache, build = work / "src", work / "venv", work / "pip-cache", work / "build"
    subprocess.run(["git", "clone", "--quiet", str(repo), str(src)], check=True)
    subprocess.run(["git", "-C", str(src), "checkout", "--quiet", ref], check=True)
    subprocess.run([python, "-m", "venv", str(venv)], check=True)
    cache.mkdir()
    drop = ("PIP_CACHE_DIR", "PIP_NO_CACHE_DIR", "PIP_VERBOSE", "SKBUILD_")
    env = {k: v for k, v in os.environ.items() if not k.startswith(drop)}
    env.update(
        PATH=f"{venv / 'bin'}:{env['PATH']}",
        VIRTUAL_ENV=str(venv),
        PIP_CACHE_DIR=str(cache),
        PIP_VERBOSE="1",
        SKBUILD_BUILD_DIR=str(build),
    )
    env.pop("PYTHONHOME", None)
    # The README's command, its two halves timed apart (`a && b` runs b once a has exited).
    install, demo = COMMAND.split(" && ")
    lines = _stamp_lines(install, src, env, work / "output.log")
    phases = _phases(lines)
    demo_lines = _stamp_lines(demo, src, env, work / "demo.log")
    install_total = phases.pop("total")
    phases["demo"] = round(demo_lines[-1][0], 1)
    phases["total"] = round(install_total + phases["demo"], 1)
    return {"phases": phases, "ninja": _ninja_times(build), "log": str(work / "output.log")}


def _print_run(i: int, run: dict[str, object]) -> None:
    phases = run["phases"]
    ninja = run["ninja"]
    assert isinstance(phases, dict) and isinstance(ninja, dict)
    print(f"\nrun {i + 1} (output: {run['log']})")
    for name, secs in phases.items():
        print(f"  {name:<36} {secs:7.1f} s")
    print("  ninja steps (s; ninja runs as many jobs as cores + 2):")
    for name, secs in sorted(ninja.items(), key=lambda kv: -kv[1]):
        print(f"    {name:<50} {secs:7.1f}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    here = Path(__file__).resolve().parent.parent
    parser.add_argument("--repo", type=Path, default=here, help="repository to clone")
    parser.add_argument("--ref", default="HEAD", help="commit or branch to check out")
    parser.add_argument("--runs", type=int, default=1)
    parser.add_argument("--python", default="python3", help="interpreter of the venvs")
    parser.add_argument("--work", type=Path, help="keep each run's folders under this one")
    parser.add_argument("--json", type=Path, help="write the runs' numbers here")
    args = parser.parse_args()
    load = os.getloadavg()
    print(f"`{COMMAND}` at {args.ref}; load average before: {load[0]:.2f} {load[1]:.2f}")
    runs = []
    for i in range(args.runs):
        if args.work:
            work = args.work / f"run{i + 1}"
            shutil.rmtree(work, ignore_errors=True)
            work.mkdir(parents=True)
        else:
            work = Path(tempfile.mkdtemp(prefix="pinsettle-install-"))
        run = one_run(args.repo, args.ref, work, args.python)
        run["load_after"] = os.getloadavg()
        runs.append(run)
        _print_run(i, run)
        if not args.work:
            shutil.rmtree(work / "venv")
    totals = [float(r["phases"]["total"]) for r in runs]  # type: ignore[index]
    print(f"\ntotal: {', '.join(f'{t:.1f}' for t in totals)} s; median {statistics.median(totals)}")
    if args.json:
        args.json.write_text(json.dumps(runs, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Error against run time: the benchmark report.

``python benchmarks/report.py`` regenerates docs/benchmarks.md and its figures under
docs/benchmarks/ (a progress bar on stderr) and the speed section of README.md (between its
``bench:summary`` markers); ``--quick`` makes a tiny run into build/bench-quick instead, and
``--sections gallery,cost`` measures only those sections and replaces only their parts of the
report (each part sits between ``report:NAME`` markers; any other delimited part of the file,
such as a section another tool writes, is kept as it is). The sections:

- ``scenes``: for each scene of the benchmark set, how the error falls with the steps taken and
  with wall time, for kinetic damping (both energy measures as the peak detector's signal) and
  for baselines on the same Pinocchio dynamics: viscous damping (joint dampers and
  mass-proportional), FIRE and FIRE 2.0 (C++, benchmarks/baselines.cpp, built here with CMake
  against the installed package), each at its rule setting and at its best over a sweep of its
  own parameters, and Newton's method from the same start (the baselines on trees only: they
  run unconstrained ABA, which cannot hold a closed loop). Then the sweeps of KD's settings (kt,
  err, ds, max_e, backtracking, fixed against automatic dt).
- ``cost``: the cost of one step against a bare ``pinocchio::aba`` + ``integrate`` step
  (benchmarks/step_cost.cpp: force elements, joint stops; with closed loops against a bare
  ``pinocchio::constraintDynamics`` + ``integrate`` step, benchmarks/loop_step_cost.cpp).
- ``overhead``: where a solve's time goes (benchmarks/kd_profile.cpp): set-up, step estimates,
  stability assessments, polish.
- ``scaling``: chains of 5 to 1,000 links.
- ``gallery``: every robot of example-robot-data, root fixed, with the default settings, side by
  side with MuJoCo's damped settle of the same URDF (``pip install ".[bench]"``), and the
  floating-base robots falling.
- ``contact``: go1 dropped on a floor (the scenes go1_standing and go1_motors_off) against
  MuJoCo at its best over its time step, integrator and damping, and the cost of a step on the
  contacts (benchmarks/contact_drop.py; it needs no C++ program).

The error of a configuration q is measured two ways:

- distance: ``max |q - q*|`` over the free joints (rad or m; revolute angles compared modulo
  2 pi), q* the exact equilibrium the run comes to rest at (see ``landing``);
- residual: ``max |tau_static(q)|`` divided by the scene's force scale, ``max |tau_static(q0)|``
  at the start, with the static force of the independent physics (benchmarks/independent.py:
  tests/scene_reference.py's, nothing of pinsettle's).

The scenes are solved without joint stops (``limits = false``): the baselines have none, and the
comparison is of the methods on the same mechanics. Stops are measured in the ``cost`` and
``gallery`` sections.

Scenes with closed loops (``[[loop]]``) are measured on the closed mechanism: their start is
moved onto the loops first, the static force is the one projected onto the motions the loops
allow, Newton steps are taken in those motions and every step is moved back onto the loops, and
the KD runs' final loop error is measured here with Pinocchio's frame placements.

Every number in the report is computed by this script; nothing is typed in by hand.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from datetime import date
from functools import partial
from pathlib import Path
from typing import TextIO, cast

import numpy as np
import pinocchio
import pinsettle

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "robots"))
sys.path.insert(0, str(HERE))
import contact_drop  # noqa: E402  (benchmarks/contact_drop.py: go1 on a floor and MuJoCo)
import gallery  # noqa: E402  (benchmarks/gallery.py: the robots and MuJoCo)
import report_readme  # noqa: E402  (benchmarks/report_readme.py: the README's speed section)
import report_writer  # noqa: E402  (benchmarks/report_writer.py: the report's text)
import stress  # noqa: E402  (benchmarks/stress.py: the heavy-and-light model)
from independent import CachedReference  # noqa: E402  (benchmarks/independent.py)
from make_chain import chain_urdf  # noqa: E402  (robots/make_chain.py)
from report_data import (  # noqa: E402  (benchmarks/report_data.py: constants and records)
    APART,
    BASELINE_LABELS,
    BASELINE_MAX_STEPS,
    BASELINE_MAX_TIME,
    BASELINE_RULES,
    BASELINE_TARGET,
    BASELINES,
    CHAIN_LENGTHS,
    CURVE_SAMPLES,
    DEEP,
    DEEP_MAX_E,
    DT_SAFETY,
    DT_SWEEP_SECONDS,
    INTERLEAVE_REPEATS,
    MAX_STEPS,
    REPEAT_BUDGET,
    RESIDUAL_LEVELS,
    SECTIONS,
    SWEEP_GROWTH,
    SWEEP_MAX_TIME,
    BenchScene,
    Config,
    Curve,
    Landing,
    Record,
    Reference,
    Results,
    Run,
    SceneData,
    SweepPoint,
    baseline_method,
    setting_label,
)
from scene_statics import Statics  # noqa: E402  (benchmarks/scene_statics.py)

LEVEL = RESIDUAL_LEVELS[-1]

# --- scenes ---------------------------------------------------------------------------------


def _library(name: str) -> BenchScene:
    """A scene of robots/, without joint stops (the baselines have none)."""
    path = ROOT / "robots" / f"{name}.toml"
    scene = pinsettle.load_scene(path)
    scene.limits = False
    # from_toml builds its own class (tests/scene_reference.py types it as the base class).
    reference = cast(CachedReference, CachedReference.from_toml(path))
    reference.limits = False
    return BenchScene(name, scene, scene.description, reference)


def chain_scene(links: int) -> BenchScene:
    """The chain of robots/make_chain.py (0.1 m, 0.1 kg links) released horizontal."""
    scene = pinsettle.Scene(
        pinocchio.buildModelFromXML(chain_urdf(links)), name=f"chain{links}", limits=False
    )
    scene.set_start(joint1=math.pi / 2)
    reference = CachedReference(
        pinocchio.buildModelFromXML(chain_urdf(links)), start={"joint1": math.pi / 2}, limits=False
    )
    return BenchScene(
        f"chain{links}",
        scene,
        f"{links}-link chain (robots/make_chain.py) released horizontal",
        reference,
    )


STIFFNESS = 1e7  # N/m, the stiff-spring scene


def stiff_scene() -> BenchScene:
    """benchmarks/stress.py's 10 kg pendulum carrying a 10 g slider, on a 1e7 N/m spring."""
    scene = pinsettle.Scene(
        stress.heavy_and_light(pinocchio.JointModelPZ()), name="stiff_spring", limits=False
    )
    scene.add_joint_spring("light", stiffness=STIFFNESS)
    scene.set_start(j0=0.8)
    reference = CachedReference(
        stress.heavy_and_light(pinocchio.JointModelPZ()),
        joint_springs=[("light", STIFFNESS, 0.0)],
        start={"j0": 0.8},
        limits=False,
    )
    return BenchScene(
        "stiff_spring",
        scene,
        f"10 kg, 1 m pendulum carrying a 10 g slider on a {STIFFNESS:.0e} N/m joint spring "
        "(benchmarks/stress.py's heavy_and_light), released at 0.8 rad",
        reference,
    )


SCENE_NAMES = (
    "pendulum",
    "double_pendulum_springs",
    "bistable_pendulum",
    "ur5",
    "panda_fingers_locked",
    "chain20",
    "chain100",
    "stiff_spring",
    "fourbar",
    "slider_crank",
    "parallel_gripper",
)


def make_scene(name: str) -> BenchScene:
    if name.startswith("chain") and name[5:].isdigit() and name != "chain20":
        return chain_scene(int(name[5:]))
    if name == "stiff_spring":
        return stiff_scene()
    return _library(name)


# --- the static force, distances and exact equilibria ----------------------------------------


def newton(
    statics: Statics, q: np.ndarray, iterations: int = 30, tolerance: float = 1e-16
) -> tuple[np.ndarray, list[float], int]:
    """Newton's method on the independent static force from q, with its finite-difference
    stiffness (``Statics.newton_step``: least squares with a rank cut, so neutral directions are
    left alone; with loops along the motions they allow, each step moved back onto the loops),
    full steps, until the residual stops falling or is <= tolerance (relative: round-off).
    Returns the last pose, the relative residual after each iteration (the start first) and the
    iterations taken."""
    residuals = [statics.residual(q)]
    taken = 0
    for _ in range(iterations):
        if not residuals[-1] > tolerance:
            break
        trial = statics.step(q, statics.newton_step(q))
        r = statics.residual(trial) if np.all(np.isfinite(trial)) else math.inf
        if not np.all(np.isfinite(trial)) or not r < residuals[-1]:
            break
        q = trial
        residuals.append(r)
        taken += 1
    return q, residuals, taken


def newton_from_start(
    statics: Statics, q: np.ndarray, line_search: bool, iterations: int = 50
) -> tuple[np.ndarray, list[float], list[float], list[np.ndarray]]:
    """Newton's method as a user runs it from the start, with the stiffness matrix of
    ``pinsettle.assess_stability`` as Jacobian (``Statics.solver_newton_step``; with loops the
    reduced Newton, every step moved back onto the loops): full steps, or with ``line_search``
    halved until |tau_static|_2 falls (Armijo, 1e-4), until the residual is <= 1e-14 of the
    force scale, a step fails or 50 iterations. Returns the end pose, the relative residual and
    the elapsed wall time (s) at the start and after each iteration, and the poses."""
    start = time.perf_counter()
    residuals, times, poses = [statics.residual(q)], [0.0], [q]
    for _ in range(iterations):
        if not residuals[-1] > 1e-14:
            break
        f = statics.force(q)
        dq = statics.solver_newton_step(q, f)
        a, norm = 1.0, np.linalg.norm(f)
        trial = statics.step(q, dq)
        while line_search and not (
            np.all(np.isfinite(trial))
            and np.linalg.norm(statics.force(trial)) <= (1 - 1e-4 * a) * norm
        ):
            a *= 0.5
            if a < 1e-10:
                break
            trial = statics.step(q, a * dq)
        if not np.all(np.isfinite(trial)) or a < 1e-10:
            break
        q = trial
        residuals.append(statics.residual(q))
        times.append(time.perf_counter() - start)
        poses.append(q)
    return q, residuals, times, poses


def reference(statics: Statics) -> Reference:
    """q*: kinetic damping with polish and a tiny max_e, refined by Newton on the independent
    physics, its verdict from that physics' stiffness, checked by one more Newton step."""
    r = pinsettle.solve(statics.scene, polish=True, max_e=DEEP_MAX_E, max_steps=MAX_STEPS)
    if not r.converged:
        raise RuntimeError(f"{statics.scene.name}: no reference ({r.status})")
    q, _, _ = newton(statics, r.q)
    verdict, neutral, min_eig = statics.verdict(q)
    if verdict not in ("stable", "neutral"):
        raise RuntimeError(f"{statics.scene.name}: the reference is {verdict}")
    return Reference(
        q,
        statics.residual(q),
        verdict,
        neutral,
        min_eig,
        float(np.max(np.abs(statics.newton_step(q)))),
        r.steps,
        r.wall_time / r.steps,
        statics.loop_error(q),
    )


def landing(statics: Statics, ref: Reference, q_final: np.ndarray) -> Landing:
    if not np.all(np.isfinite(q_final)) or not statics.residual(q_final) <= 1e-4:
        return Landing(None, "-", math.nan)
    q, _, _ = newton(statics, q_final)
    if not statics.residual(q) <= 1e-12:
        return Landing(None, "-", math.nan)
    return Landing(q, statics.verdict(q)[0], statics.distance(ref.q, q))


# --- runs and their curves --------------------------------------------------------------------


def curve_of(statics: Statics, target: np.ndarray, steps: np.ndarray, rows: np.ndarray) -> Curve:
    residual = np.array([statics.residual(row) for row in rows])
    return Curve(np.asarray(steps, dtype=float), residual, statics.distances(target, rows))


def _target(ref: Reference, land: Landing) -> np.ndarray:
    return land.q if land.q is not None else ref.q


def timed_solves(scene: pinsettle.Scene, settings: Record, repeats: int) -> list[pinsettle.Result]:
    """Up to ``repeats`` solves (no more once they took REPEAT_BUDGET in all)."""
    timed = [pinsettle.solve(scene, **settings)]
    while len(timed) < repeats and sum(r.wall_time for r in timed) < REPEAT_BUDGET:
        timed.append(pinsettle.solve(scene, **settings))
    return timed


@dataclasses.dataclass
class Traced:
    """What the traced run of a KD solve adds: the error curve, the steps of its damping events
    and the largest loop error over its samples (nan on a tree)."""

    curve: Curve | None = None
    damping: list[int] = dataclasses.field(default_factory=list)
    along: float = math.nan


def traced_run(
    statics: Statics, settings: Record, result: pinsettle.Result, target: np.ndarray
) -> Traced:
    """The same solve again with every step's configuration traced: the same trajectory (the
    solver is deterministic; checked), sampled into the error curve."""
    traced = pinsettle.solve(
        statics.scene,
        **settings,
        trace_every=1,
        trace_configurations=True,
        trace_capacity=CURVE_SAMPLES,
    )
    if traced.steps != result.steps or not np.array_equal(traced.q, result.q):
        raise RuntimeError(f"{statics.scene.name}: the traced run took another path")
    t = traced.trace
    if t is None or t.q is None:  # trace_every = 1 with configurations: never
        raise RuntimeError(f"{statics.scene.name}: the traced run has no trace")
    steps = np.append(t.step, traced.steps)
    rows = np.vstack([t.q, traced.q[None, :]])
    along = max(statics.loop_error(row) for row in rows) if statics.loops else math.nan
    damping = [
        step for step, kind in zip(t.event_step, t.event_kind, strict=True) if kind == "damping"
    ]
    return Traced(curve_of(statics, target, steps, rows), damping, along)


def kd_extra(statics: Statics, result: pinsettle.Result, traced: Traced) -> Record:
    """A KD run's extra record: its step control, damping events and loop errors."""
    return {
        "dt": result.dt,
        "dt_estimates": result.dt_estimates,
        "dt_reductions": result.dt_reductions,
        "scaled_modes": result.scaled_modes,
        "polish_iterations": result.polish_iterations,
        "damping_steps": np.array(traced.damping),  # steps of the damping events (traced run)
        # Largest loop error (m) of the final q, measured here (Statics.loop_error) and by
        # the solver (Result.constraint_error), and over the traced run's samples.
        "constraint_error": statics.loop_error(result.q),
        "solver_constraint_error": result.constraint_error,
        "constraint_error_along": traced.along,
    }


def run_kd(
    statics: Statics,
    ref: Reference,
    settings: Record,
    repeats: int,
    curve: bool = True,
    label: str = "",
    setup: float = 0.0,
) -> Run:
    """Kinetic damping: up to ``repeats`` timed solves (wall_time is measured inside the C++
    loop), and with ``curve`` one more with a trace of every step's configuration (the same
    trajectory: the solver is deterministic, checked). At most the scene's step budget.
    ``setup``: the solver's set-up on the scene (s, benchmarks/kd_profile), charged in full to
    the time to a level."""
    settings = {"max_steps": ref.step_budget, **settings}
    timed = timed_solves(statics.scene, settings, repeats)
    result = timed[-1]
    land = landing(statics, ref, result.q)
    target = _target(ref, land)
    traced = traced_run(statics, settings, result, target) if curve else Traced()
    energy = settings.get("energy", pinsettle.Settings().energy)
    return Run(
        statics.scene.name,
        "kd",
        label or f"KD {energy}",
        settings,
        result.status,
        result.steps,
        [r.wall_time for r in timed],
        statics.residual(result.q),
        statics.distance(target, result.q),
        land.stability,
        land,
        peaks=result.peaks,
        curve=traced.curve,
        extra=kd_extra(statics, result, traced),
        setup=min(setup, min(r.wall_time for r in timed)),
    )


# --- the C++ programs ---------------------------------------------------------------------------


def build_programs(build_dir: Path, log: Callable[[str], None]) -> Path:
    """Configure and build benchmarks/ (step_cost, loop_step_cost, baselines, kd_profile)
    against the installed package."""
    cmake = shutil.which("cmake", path=str(Path(sys.executable).parent)) or shutil.which("cmake")
    if cmake is None:
        raise RuntimeError("cmake is not installed (pip install cmake ninja)")
    generator = (
        ["-G", "Ninja"] if shutil.which("ninja", path=str(Path(sys.executable).parent)) else []
    )
    build_dir.mkdir(parents=True, exist_ok=True)
    if not (build_dir / "CMakeCache.txt").exists():
        log("configuring the C++ benchmarks")
        # The real path: next to an installed package's cmake folder sits Pinocchio's prefix.
        cmake_dir = Path(pinsettle.get_cmake_dir()).resolve()
        subprocess.run(
            [
                cmake,
                "-S",
                str(HERE),
                "-B",
                str(build_dir),
                *generator,
                "-DCMAKE_BUILD_TYPE=Release",
                f"-DCMAKE_PREFIX_PATH={cmake_dir}",
            ],
            check=True,
            capture_output=True,
            text=True,
        )
    # The installed headers keep their own dates, so a changed library would not make the
    # objects compiled against the old headers stale: rebuild them all when the library changed.
    library = next(Path(pinsettle.get_cmake_dir()).resolve().parents[1].glob("libpinsettle.*"))
    stamp = build_dir / "pinsettle-library.stamp"
    seen = f"{library.stat().st_mtime_ns} {library.stat().st_size}"
    if stamp.exists() and stamp.read_text() != seen:
        log("the installed pinsettle library changed: rebuilding the C++ benchmarks")
        subprocess.run(
            [cmake, "--build", str(build_dir), "--target", "clean"], check=True, capture_output=True
        )
    log("building the C++ benchmarks (a few minutes the first time)")
    proc = subprocess.run(
        [cmake, "--build", str(build_dir), "--parallel", str(os.cpu_count() or 2)],
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"building benchmarks/ failed:\n{proc.stdout}\n{proc.stderr}")
    stamp.write_text(seen)
    return build_dir


def _spec_lines(statics: Statics) -> list[str]:
    lines = []
    spec = statics.elements or {}
    for joint, k, rest, d in spec.get("joint_springs", []):
        lines.append(f"joint_spring {joint} {k!r} {rest!r} {d!r}")
    for fa, pa, fb, pb, k, rest, d in spec.get("springs", []):
        a = " ".join(repr(float(x)) for x in pa)
        b = " ".join(repr(float(x)) for x in pb)
        lines.append(f"point_spring {fa} {a} {fb} {b} {k!r} {rest!r} {d!r}")
    for joint, effort in spec.get("joint_loads", []):
        e = " ".join(repr(float(x)) for x in np.atleast_1d(effort))
        lines.append(f"joint_load {joint} {np.atleast_1d(effort).size} {e}")
    for frame, point, force, torque in spec.get("point_loads", []):
        values = " ".join(repr(float(x)) for x in [*point, *force, *torque])
        lines.append(f"point_load {frame} {values}")
    return lines


def write_spec(statics: Statics, work: Path, tag: str, lines: Sequence[str]) -> Path:
    """The spec file of benchmarks/spec.hpp for the scene: its model (saved once), its start,
    its elements and the given lines."""
    name = statics.scene.name
    model_path = work / f"{name}.model.bin"
    if not model_path.exists():
        statics.model.saveToBinary(str(model_path))
    q0 = statics.q0[statics.compiled.q_index]
    spec = work / f"{name}.{tag}.spec"
    spec.write_text(
        "\n".join(
            [
                f"model {model_path}",
                f"q0 {q0.size} " + " ".join(repr(float(x)) for x in q0),
                *lines,
                *_spec_lines(statics),
            ]
        )
        + "\n"
    )
    return spec


def last_json(stdout: str) -> Record:
    """The record a C++ program prints as its last line (JSON)."""
    record: Record = json.loads(stdout.strip().splitlines()[-1])
    return record


def run_program(program: Path, spec: Path) -> Record:
    proc = subprocess.run([str(program), str(spec)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{program.name} {spec} failed: {proc.stderr}")
    return last_json(proc.stdout)


def _settings_lines(family: str, settings: Record) -> list[str]:
    method, newton = baseline_method(family)
    return [
        f"method {method}",
        *(["newton 1"] if newton else []),
        *(f"{key} {value}" for key, value in settings.items()),
    ]


def _tag(family: str, settings: Record) -> str:
    return family + "".join(f".{k}{v}" for k, v in settings.items())


#: What a baseline's run keeps of its program's record (benchmarks/baselines.cpp).
RUN_EXTRA = (
    *("dt", "dt_max", "dt_end", "limit", "damping", "omega_rule", "resets", "halvings"),
    *("retries", "newton_tries", "newton_iterations", "by_newton"),
)


def run_baseline(
    program: Path,
    statics: Statics,
    ref: Reference,
    family: str,
    settings: Record,
    repeats: int,
    work: Path,
    label: str,
) -> Run:
    """A baseline in C++ (benchmarks/baselines.cpp) down to BASELINE_TARGET, timed, then again
    recording its curve. Its set-up (the step and damping from the start) is timed by the
    program and charged to the time to a level."""
    tag = _tag(family, settings)
    samples = work / f"{statics.scene.name}.{tag}.samples"
    spec = write_spec(
        statics,
        work,
        tag,
        [
            *_settings_lines(family, settings),
            f"target {BASELINE_TARGET * statics.force_scale!r}",
            "check_every 16",
            f"max_steps {BASELINE_MAX_STEPS}",
            f"max_time {BASELINE_MAX_TIME}",
            f"repeats {repeats}",
            f"repeat_budget {REPEAT_BUDGET}",
            f"max_samples {CURVE_SAMPLES}",
            f"samples {samples}",
        ],
    )
    out = run_program(program, spec)
    q_final = statics.compiled.full_q(np.array(out["q"]))
    land = landing(statics, ref, q_final)
    target = _target(ref, land)
    data = np.fromfile(samples, dtype=np.float64).reshape(-1, statics.model.nq + 1)
    rows = np.array([statics.compiled.full_q(row) for row in data[:, 1:]])
    setup = statistics.median(out["setup_times"])
    return Run(
        statics.scene.name,
        family,
        label,
        dict(settings),
        out["status"],
        int(out["steps"]),
        _totals(out),
        statics.residual(q_final),
        statics.distance(target, q_final),
        land.stability,
        land,
        curve=curve_of(statics, target, data[:, 0], rows),
        extra={key: out[key] for key in RUN_EXTRA},
        setup=setup,
    )


def _totals(out: Record) -> list[float]:
    """Each timed run's set-up and loop (s), from a baselines record."""
    return [s + loop for s, loop in zip(out["setup_times"], out["wall_times"], strict=True)]


def sweep_point(
    program: Path,
    statics: Statics,
    family: str,
    settings: Record,
    work: Path,
    repeats: int,
    repeat_budget: float = REPEAT_BUDGET / 2,
) -> SweepPoint:
    """A baseline with the given settings, stopped at the residual LEVEL (time to it: its
    set-up and loop, median of the repeats, no more once they took ``repeat_budget`` s)."""
    spec = write_spec(
        statics,
        work,
        "sweep." + _tag(family, settings),
        [
            *_settings_lines(family, settings),
            f"target {LEVEL * statics.force_scale!r}",
            "check_every 16",
            f"max_steps {BASELINE_MAX_STEPS}",
            f"max_time {SWEEP_MAX_TIME}",
            f"repeats {repeats}",
            f"repeat_budget {repeat_budget}",
        ],
    )
    out = run_program(program, spec)
    return SweepPoint(
        dict(settings),
        out["status"],
        int(out["steps"]),
        statistics.median(_totals(out)),
        statistics.median(out["setup_times"]),
        out["halvings"],
        out["retries"],
        out["resets"],
        out["dt"],
    )


def run_kd_profile(
    program: Path,
    statics: Statics,
    work: Path,
    repeats: int,
    polish: bool,
    max_time: float = 60.0,
) -> Record:
    """benchmarks/kd_profile on the scene: the default solve's set-up, estimates, assessments
    (and with ``polish`` the polished solve), medians of the repeats in ``median``."""
    spec = write_spec(
        statics,
        work,
        "profile",
        [
            "method kd",
            f"polish {int(polish)}",
            f"repeats {repeats}",
            f"repeat_budget {REPEAT_BUDGET}",
            f"max_time {max_time}",
        ],
    )
    out = run_program(program, spec)
    keys = ["wall", "setup", "estimates", "assessments", "bare_step"]
    if polish:
        keys += [
            "polish_wall",
            "polish_setup",
            "polish_estimates",
            "polish_assessments",
            "polish_stiffness",
        ]
    out["median"] = {key: statistics.median(out[key]) for key in keys}
    return out


def time_in_cpp(run: Run, profile: Record) -> None:
    """The default run's times from benchmarks/kd_profile's polished solves (C++, a fresh solver
    each repeat, as benchmarks/baselines.cpp times each baseline run); those from
    ``pinsettle.solve`` are kept in ``extra["python_seconds"]``. The two must be the same run."""
    if profile["polish_steps"] != run.steps or profile["polish_iterations"] != run.extra.get(
        "polish_iterations"
    ):
        raise RuntimeError(
            f"{run.scene}: kd_profile's default solve took {profile['polish_steps']} steps and "
            f"{profile['polish_iterations']} Newton iterations, pinsettle.solve {run.steps} and "
            f"{run.extra.get('polish_iterations')}: not the same run"
        )
    run.extra["python_seconds"] = run.seconds
    run.seconds = list(profile["polish_wall"])


def run_newton(statics: Statics, ref: Reference, line_search: bool) -> Run:
    """Newton from the start (Python: its wall time is not comparable with the C++ loops')."""
    q, residuals, times, poses = newton_from_start(statics, statics.q0.copy(), line_search)
    finite = bool(np.all(np.isfinite(q)))
    root = finite and residuals[-1] <= 1e-10
    verdict, _, min_eig = statics.verdict(q) if root else ("-", 0, math.nan)
    distance = statics.distance(ref.q, q) if finite else math.nan
    dist = np.array([statics.distance(ref.q, p) for p in poses])
    return Run(
        statics.scene.name,
        "newton",
        "Newton + line search" if line_search else "Newton",
        {"line_search": line_search},
        "root" if root else "no root",
        len(residuals) - 1,
        [times[-1]],
        residuals[-1],
        distance,
        verdict,
        Landing(q if root else None, verdict, distance),
        curve=Curve(np.arange(len(residuals), dtype=float), np.array(residuals), dist),
        extra={
            "times": times,
            "min_eigenvalue": min_eig,
            "largest_angle": float(np.max(np.abs(q))) if finite else math.inf,
            "constraint_error": statics.loop_error(q),  # 0 for a tree
        },
    )


def run_step_cost(
    program: Path, urdf: Path, steps: int, repeats: int, only: str | None = None
) -> Record:
    args = [str(program), str(urdf), str(steps), str(repeats), "--json"]
    if only:
        args += ["--only", only]
    proc = subprocess.run(args, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"step_cost {urdf} failed: {proc.stderr}")
    return last_json(proc.stdout)


def run_loop_step_cost(program: Path, scene: pinsettle.Scene, steps: int, repeats: int) -> Record:
    """benchmarks/loop_step_cost on a scene with loops: its URDF, its loops by frame name and
    its start (the program moves it onto the loops as the solver does); gravity alone."""
    if scene.locked or scene.urdf is None:  # the program builds the whole URDF's model
        raise RuntimeError(f"loop_step_cost: {scene.name} needs a URDF and no locked joints")
    args = [str(program), str(scene.urdf), str(steps), str(repeats), "--json"]
    args += ["--q0", ",".join(repr(float(x)) for x in scene.q0())]
    for loop in scene.loops:
        fields = [loop.a_frame, *map(repr, map(float, loop.a_point))]
        fields += [loop.b_frame, *map(repr, map(float, loop.b_point)), loop.kind]
        args += ["--loop", ",".join(fields)]
    proc = subprocess.run(args, capture_output=True, text=True)
    if proc.returncode != 0 or proc.stderr.strip():
        raise RuntimeError(f"loop_step_cost {scene.name} failed: {proc.stderr}")
    return last_json(proc.stdout)


def cost_urdf(name: str) -> Path:
    """A model of the step cost by name: a robot of example-robot-data or robots/NAME.urdf."""
    local = ROOT / "robots" / f"{name}.urdf"
    return local if local.exists() else pinsettle.robot_urdf(name)


# --- the plan ---------------------------------------------------------------------------------


class Progress:
    """A progress bar on stderr: done/total, elapsed time and what runs now."""

    def __init__(self, total: int, stream: TextIO = sys.stderr) -> None:
        self.total, self.done, self.start, self.stream = total, 0, time.perf_counter(), stream
        self.tty = stream.isatty()

    def show(self, label: str) -> None:
        width = 30
        filled = int(width * self.done / max(self.total, 1))
        bar = "#" * filled + "." * (width - filled)
        elapsed = time.perf_counter() - self.start
        line = f"[{bar}] {self.done}/{self.total} {elapsed:6.0f} s  {label}"
        if self.tty:
            self.stream.write("\r" + line[:120].ljust(120))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def advance(self) -> None:
        self.done += 1

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")
        self.stream.flush()


FULL = Config(SCENE_NAMES, CHAIN_LENGTHS, repeats=5, sweep_repeats=3)
QUICK = Config(
    ("pendulum", "fourbar"),
    (5, 10, 1000),  # 1,000 links: refused where its 32 GB Data does not fit (or max_time)
    repeats=1,
    sweep_repeats=1,
    kts=(0.0, 0.5),
    errs=(1e-12, 1e-4),
    dss=(30, 100),
    max_es=(1e-6, 1e-12),
    safeties=(DT_SAFETY, 0.8),
    damping_factors=(1.0,),
    fire_dt_maxes=(1.0, 2.0),
    newton_radii=(0.1, 1.0),
    interleave_rounds=2,
    sweep_extensions=1,
    step_cost_steps=2000,
    step_cost_repeats=3,
    cost_models=("ur5", "pendulum"),
    overhead_scenes=("pendulum",),
    scaling_max_time=10.0,
    deep_chain_max=10,
    robots=("ur5", "double_pendulum", "finger_edu", "solo12"),
    mujoco_max_sim=60.0,
    gallery_repeats=1,
    contact_quick=True,
)

Task = tuple[str, Callable[[], None]]


@dataclasses.dataclass
class SceneJob:
    """What the scenes section's tasks share: the configuration, the results they fill, the C++
    programs, a work folder and the scenes (built once)."""

    config: Config
    results: Results
    programs: Path
    work: Path
    benches: dict[str, BenchScene]


def kd_setup(d: SceneData) -> float:
    """The solver's set-up on a scene (benchmarks/kd_profile; 0 on a scene with loops)."""
    return d.profile["median"]["setup"] if d.profile else 0.0


def scene_setup(job: SceneJob, name: str) -> None:
    """The scene's reference equilibrium and, on a tree, the solver's set-up and the default
    solve timed in C++."""
    bench = job.benches[name]
    statics = Statics(bench.scene, bench.reference)
    d = SceneData(
        bench,
        statics,
        reference(statics),
        bench.description,
        statics.force_scale,
        statics.model.nv,
        len(bench.scene.loops),
        statics.mobility,
    )
    d.apart = name in APART
    if not d.loops:
        program = job.programs / "kd_profile"
        d.profile = run_kd_profile(program, statics, job.work, job.config.repeats, True)
    job.results.scenes[name] = d


def scene_main_runs(job: SceneJob, name: str) -> None:
    d = job.results.scenes[name]
    s, ref, reps = d.statics, d.ref, job.config.repeats
    for energy in ("exact", "simplified"):
        d.runs[f"kd_{energy}"] = run_kd(s, ref, {"energy": energy, **DEEP}, reps, setup=kd_setup(d))
    # The default settings, nothing changed: where they stop (goal 2 of issue 20).
    d.runs["kd_default"] = run_kd(
        s, ref, {}, reps, curve=False, label="KD defaults", setup=kd_setup(d)
    )
    if d.profile:
        time_in_cpp(d.runs["kd_default"], d.profile)


def scene_newton(job: SceneJob, name: str) -> None:
    d = job.results.scenes[name]
    d.runs["newton"] = run_newton(d.statics, d.ref, line_search=False)
    d.runs["newton_ls"] = run_newton(d.statics, d.ref, line_search=True)


def scene_baseline(job: SceneJob, name: str, family: str) -> None:
    """A baseline at its rule, its sweep, and its best setting run in full (the rule's run
    again when that was the best)."""
    d = job.results.scenes[name]
    s, ref, reps = d.statics, d.ref, job.config.repeats
    baselines, work = job.programs / "baselines", job.work
    rule = BASELINE_RULES[family]
    label = BASELINE_LABELS[family]
    d.runs[f"{family}_rule"] = run_baseline(
        baselines, s, ref, family, rule, reps, work, f"{label}, rule"
    )
    points = sweep_inside(
        lambda settings: sweep_point(
            baselines, s, family, settings, work, job.config.sweep_repeats
        ),
        job.config.sweep(family),
        job.config.sweep_extensions,
    )
    d.baseline_sweep[family] = points
    best = fastest(points)
    if best is None or best.settings == rule:
        d.runs[f"{family}_best"] = d.runs[f"{family}_rule"]
        return
    d.runs[f"{family}_best"] = run_baseline(
        baselines,
        s,
        ref,
        family,
        best.settings,
        reps,
        work,
        f"{label}, best ({setting_label(family, best.settings)})",
    )


def fastest(points: Sequence[SweepPoint]) -> SweepPoint | None:
    done = [p for p in points if p.time_to is not None]
    return min(done, key=lambda p: p.seconds, default=None)


def _beyond(points: Sequence[SweepPoint], best: SweepPoint, key: str) -> list[float]:
    """The next values of a numeric setting past the edge of what was tried where the best
    sits (none where it is inside)."""
    values = sorted({p.settings[key] for p in points})
    up, down = SWEEP_GROWTH[key]
    value = best.settings[key]
    if len(values) < 2 or value not in (values[0], values[-1]):
        return []
    return [value * up] if value == values[-1] else [value * down]


def _grown(points: Sequence[SweepPoint], best: SweepPoint, key: str) -> list[Record]:
    """The next value of ``key`` past the edge where the best sits (none where it is inside)
    with every value tried of the other settings (the grid stays a product), in the settings'
    order, less what was tried."""
    beyond = _beyond(points, best, key)
    values = {
        k: beyond if k == key else list(dict.fromkeys(p.settings[k] for p in points))
        for k in best.settings
    }
    tried = [p.settings for p in points]
    grid = [dict(zip(values, combo, strict=True)) for combo in itertools.product(*values.values())]
    return [g for g in grid if beyond and g not in tried]


def sweep_inside(
    run: Callable[[Record], SweepPoint], grid: Sequence[Record], extensions: int
) -> list[SweepPoint]:
    """A sweep on ``grid``, grown past an edge while the best sits on it: the next value of
    that setting (SWEEP_GROWTH) with each value of the others tried, at most ``extensions``
    times per setting. It ends with the best inside, or on an edge past which every run failed
    or the extensions ran out (the report flags that edge)."""
    points = [run(settings) for settings in grid]
    grown = dict.fromkeys(SWEEP_GROWTH, 0)
    while (best := fastest(points)) is not None:
        # One setting at a time, so that the next grows with the values this one added.
        growable = (k for k in best.settings if k in SWEEP_GROWTH and grown[k] < extensions)
        key, more = next(((k, m) for k in growable if (m := _grown(points, best, k))), (None, []))
        if key is None:
            break
        grown[key] += 1
        points += [run(settings) for settings in more]
    return points


def _interleaved_baseline(run: Callable[[], SweepPoint]) -> float:
    t = run().time_to
    return math.nan if t is None else t


def _interleaved_kd(program: Path, statics: Statics, work: Path) -> float:
    profile = run_kd_profile(program, statics, work, INTERLEAVE_REPEATS, True)
    return float(profile["median"]["polish_wall"])


def scene_interleaved(job: SceneJob, name: str) -> None:
    """The default solve and every baseline at its best, each run to the residual LEVEL
    (baselines) or to its end (the default solve: its polish and takeover take it to round-off,
    so its time to the LEVEL is at most that), timed again in ``interleave_rounds`` rounds, each
    round in another order (rotated), INTERLEAVE_REPEATS solves a method and round: each
    round's median, in ``d.interleaved``."""
    d = job.results.scenes[name]
    s, work = d.statics, job.work
    runs: dict[str, Callable[[], float]] = {
        "kd_default": partial(_interleaved_kd, job.programs / "kd_profile", s, work)
    }
    for family in BASELINES:
        best = fastest(d.baseline_sweep.get(family, []))
        if best is None:
            continue
        program = job.programs / "baselines"
        runs[family] = partial(
            _interleaved_baseline,
            partial(sweep_point, program, s, family, best.settings, work, INTERLEAVE_REPEATS, 0.5),
        )
    keys = list(runs)
    d.interleaved = {key: [] for key in keys}
    for r in range(job.config.interleave_rounds):
        shift = r % len(keys)
        for key in keys[shift:] + keys[:shift]:
            d.interleaved[key].append(runs[key]())


def scene_kt_sweep(job: SceneJob, name: str) -> None:
    d = job.results.scenes[name]
    d.sweeps["kt"] = [
        run_kd(
            d.statics,
            d.ref,
            {"energy": e, "kt": kt, **DEEP},
            job.config.sweep_repeats,
            setup=kd_setup(d),
        )
        for e in ("exact", "simplified")
        for kt in job.config.kts
    ]


def scene_stop_sweeps(job: SceneJob, name: str) -> None:
    d = job.results.scenes[name]
    s, ref, sreps, config = d.statics, d.ref, job.config.sweep_repeats, job.config
    d.sweeps["err"] = [run_kd(s, ref, {"err": x}, sreps, curve=False) for x in config.errs]
    d.sweeps["ds"] = [run_kd(s, ref, {"ds": x}, sreps, curve=False) for x in config.dss]
    d.sweeps["max_e"] = [
        run_kd(s, ref, {"max_e": x, "energy": e}, sreps, curve=False)
        for e in ("exact", "simplified")
        for x in config.max_es
    ]


def dt_sweep(d: SceneData, sreps: int) -> list[Run]:
    """The automatic step (with and without stiff-mode scaling) against fixed steps."""
    s, ref, setup = d.statics, d.ref, kd_setup(d)
    start_dt = DT_SAFETY * s.time_scale(s.q0, True)["critical_step"]
    # At least DT_SWEEP_SECONDS each: an unscaled stiff mode needs many small steps.
    budget = {
        **DEEP,
        "max_steps": max(ref.step_budget, int(DT_SWEEP_SECONDS / ref.seconds_per_step)),
    }
    unscaled = {**budget, "scale_stiff_modes": False}
    return [
        run_kd(s, ref, budget, sreps, label="auto", setup=setup),
        run_kd(s, ref, unscaled, sreps, label="auto, unscaled", setup=setup),
        run_kd(s, ref, {**budget, "dt": start_dt}, sreps, label="fixed, start"),
        run_kd(s, ref, {**budget, "dt": start_dt / 4}, sreps, label="fixed, start / 4"),
    ]


def scene_other_sweeps(job: SceneJob, name: str) -> None:
    d = job.results.scenes[name]
    sreps = job.config.sweep_repeats
    d.sweeps["backtrack"] = [
        run_kd(
            d.statics,
            d.ref,
            {**DEEP, "energy": e, "backtrack": b},
            sreps,
            setup=kd_setup(d),
        )
        for e in ("exact", "simplified")
        for b in (False, True)
    ]
    d.sweeps["dt"] = dt_sweep(d, sreps)


def scene_tasks(config: Config, results: Results, programs: Path, work: Path) -> list[Task]:
    """The scenes section: references, KD, the baselines and their sweeps, Newton, KD's
    sweeps."""
    benches = {name: make_scene(name) for name in config.scenes}  # built once
    job = SceneJob(config, results, programs, work, benches)
    tasks: list[Task] = []
    for name in config.scenes:
        tasks += [
            (
                f"{name}: reference equilibrium, the solver's set-up",
                partial(scene_setup, job, name),
            ),
            (
                f"{name}: kinetic damping, both energy measures, defaults",
                partial(scene_main_runs, job, name),
            ),
            (f"{name}: Newton from the start", partial(scene_newton, job, name)),
        ]
        if not benches[name].scene.loops:  # the C++ baselines run unconstrained ABA
            tasks += [
                (
                    f"{name}: {BASELINE_LABELS[family]}, its rule and its sweep",
                    partial(scene_baseline, job, name, family),
                )
                for family in BASELINES
            ]
            tasks.append(
                (
                    f"{name}: every method's best, interleaved timing",
                    partial(scene_interleaved, job, name),
                )
            )
        tasks += [
            (f"{name}: kt sweep", partial(scene_kt_sweep, job, name)),
            (f"{name}: err, ds and max_e sweeps", partial(scene_stop_sweeps, job, name)),
            (
                f"{name}: backtracking, fixed against automatic dt",
                partial(scene_other_sweeps, job, name),
            ),
        ]
    return tasks


def cost_tasks(config: Config, results: Results, programs: Path) -> list[Task]:
    """The cost of one step: step_cost (elements, stops) and loop_step_cost."""
    tasks: list[Task] = []
    for name in config.cost_models:

        def cost(name: str = name) -> None:
            results.step_cost[name] = run_step_cost(
                programs / "step_cost",
                cost_urdf(name),
                config.step_cost_steps,
                config.step_cost_repeats,
            )

        tasks.append((f"step cost: {name}", cost))
    for name in config.scenes:
        if not _library_has_loops(name):
            continue

        def loop_cost(name: str = name) -> None:
            results.loop_step_cost[name] = run_loop_step_cost(
                programs / "loop_step_cost",
                make_scene(name).scene,
                config.step_cost_steps,
                config.step_cost_repeats,
            )

        tasks.append((f"step cost: {name} (closed loops)", loop_cost))
    return tasks


def _library_has_loops(name: str) -> bool:
    path = ROOT / "robots" / f"{name}.toml"
    return path.exists() and bool(pinsettle.load_scene(path).loops)


def overhead_tasks(config: Config, results: Results, programs: Path, work: Path) -> list[Task]:
    tasks: list[Task] = []
    for name in config.overhead_scenes:

        def overhead(name: str = name) -> None:
            bench = make_scene(name)
            statics = Statics(bench.scene, bench.reference)
            results.overhead[name] = run_kd_profile(
                programs / "kd_profile", statics, work, max(config.repeats, 3), True
            ) | {"nv": statics.model.nv}

        tasks.append((f"overhead: {name}", overhead))
    return tasks


def joint_inertia_run(
    scene: pinsettle.Scene, statics: Statics, q_star: np.ndarray, repeats: int, config: Config
) -> Record:
    """The chain's solve with scale_joint_inertia off (the default, 'auto', gives it from 20
    links) and its default solve, both from Python, each on a Solver kept for its repeats and
    the two alternated (the same way for both: a ratio of 1 where they are the same run):
    the off run's status, steps, median wall time, joints given an inertia (none), final
    residual (relative, independent physics) and distance to straight down, and the default
    run's median wall time."""
    off = pinsettle.Solver(scene, scale_joint_inertia=False, max_time=config.scaling_max_time)
    default = pinsettle.Solver(scene, max_time=config.scaling_max_time)
    runs, default_runs = [], []
    for _ in range(repeats):
        runs.append(off.solve())
        default_runs.append(default.solve())
    r = runs[-1]
    return {
        "status": r.status,
        "steps": r.steps,
        "seconds": statistics.median(x.wall_time for x in runs),
        "default_seconds": statistics.median(x.wall_time for x in default_runs),
        "scaled_joints": r.scaled_joints,
        "residual": statics.residual(r.q),
        "distance": statics.distance(q_star, r.q),
    }


def chain_statics(n: int, bench: BenchScene) -> tuple[Statics, np.ndarray, float, str]:
    """A chain's statics and its rest hanging straight down (checked stable, with its residual
    and verdict)."""
    statics = Statics(bench.scene, bench.reference)
    q_star = pinocchio.neutral(statics.full)  # hanging straight down, checked below
    residual = statics.residual(q_star)
    verdict = statics.verdict(q_star)[0]
    if not (residual <= 1e-14 and verdict == "stable"):
        raise RuntimeError(f"chain{n}: straight down is not a stable rest ({verdict})")
    return statics, q_star, residual, verdict


def scale_chain(config: Config, results: Results, programs: Path, work: Path, n: int) -> None:
    """One chain length of the scaling section (a row of results.scaling)."""
    bench = chain_scene(n)
    try:
        statics, q_star, residual, verdict = chain_statics(n, bench)
    except (ValueError, MemoryError) as e:  # refused: its Data would not fit in memory
        results.scaling.append({"n": n, "refused": str(e)})
        return
    long_chain = n > config.deep_chain_max
    repeats = 1 if long_chain else config.sweep_repeats
    # The default solve, polish included: the stopping rule leaves the last digits to it.
    profile = run_kd_profile(
        programs / "kd_profile", statics, work, repeats, True, max_time=config.scaling_max_time
    )
    q_final = statics.compiled.full_q(np.array(profile["polish_q"]))
    row = {
        "n": n,
        "profile": profile,
        "residual": statics.residual(q_final),
        "distance": statics.distance(q_star, q_final),
    }
    row["no_joint_inertia"] = joint_inertia_run(bench.scene, statics, q_star, repeats, config)
    if not long_chain:
        ref = Reference(q_star, residual, verdict, 0, math.nan, 0.0, profile["steps"], 0.0)
        row["deep"] = run_kd(
            statics,
            ref,
            {**DEEP, "max_time": config.scaling_max_time},
            1,
            label="deep",
            setup=profile["median"]["setup"],
        )
    path = work / f"chain{n}.urdf"
    path.write_text(chain_urdf(n))
    steps = max(200, min(config.step_cost_steps, config.step_cost_steps * 20 // n))
    only = "bare" if long_chain else "bare,exact"
    row["cost"] = run_step_cost(programs / "step_cost", path, steps, 3, only=only)
    results.scaling.append(row)


def scaling_tasks(config: Config, results: Results, programs: Path, work: Path) -> list[Task]:
    """Chains of config.chain_lengths: the default solve profiled (benchmarks/kd_profile, within
    config.scaling_max_time; timed whole with its polish, in parts without), the bare step, and up
    to config.deep_chain_max links a run to round-off and the whole step cost."""
    return [
        (f"scaling: chain of {n}", partial(scale_chain, config, results, programs, work, n))
        for n in config.chain_lengths
    ]


def gallery_tasks(config: Config, results: Results) -> list[Task]:
    tasks: list[Task] = []
    names = list(config.robots) if config.robots is not None else pinsettle.robot_names()
    results.mujoco = gallery.mujoco_info()

    for name in names:

        def robot(name: str = name) -> None:
            results.gallery.append(
                gallery.measure_robot(
                    name,
                    repeats=config.gallery_repeats,
                    mujoco_max_sim=config.mujoco_max_sim,
                )
            )

        tasks.append((f"gallery: {name}", robot))
    for name in names:
        if not gallery.is_floating(name):
            continue

        def falling(name: str = name) -> None:
            results.floating.append(gallery.measure_floating(name, config.gallery_repeats))

        tasks.append((f"gallery: {name} with a floating base", falling))
    return tasks


def contact_tasks(config: Config, results: Results) -> list[Task]:
    """go1 on a floor against MuJoCo, one task per scene."""
    sweep = contact_drop.QUICK if config.contact_quick else contact_drop.FULL
    results.contact = contact_drop.empty_record(sweep)

    def scene(name: str) -> None:
        results.contact["scenes"].append(contact_drop.measure_scene(name, sweep))

    return [(f"contact: {name}", partial(scene, name)) for name in sweep.scenes]


def plan(
    config: Config, results: Results, programs: Path, work: Path, sections: Sequence[str]
) -> list[tuple[str, str, Callable[[], None]]]:
    """The tasks, as (section, label, callable), run in order under the progress bar."""
    tasks: list[tuple[str, str, Callable[[], None]]] = []
    makers = {
        "scenes": lambda: scene_tasks(config, results, programs, work),
        "cost": lambda: cost_tasks(config, results, programs),
        "overhead": lambda: overhead_tasks(config, results, programs, work),
        "scaling": lambda: scaling_tasks(config, results, programs, work),
        "gallery": lambda: gallery_tasks(config, results),
        "contact": lambda: contact_tasks(config, results),
    }
    for section in SECTIONS:
        if section in sections:
            tasks += [(section, label, task) for label, task in makers[section]()]
    return tasks


# --- machine ---------------------------------------------------------------------------------


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.machine()


def machine() -> Record:
    return {
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "pinocchio": pinocchio.__version__,
        "pinsettle": pinsettle.__version__,
        "date": date.today().isoformat(),
        "load_start": os.getloadavg(),
    }


# --- main --------------------------------------------------------------------------------------


def generate(
    config: Config,
    output: Path,
    build_dir: Path,
    quiet: bool = False,
    update_readme: bool = False,
    sections: Sequence[str] = SECTIONS,
) -> Results:
    """Measure the given sections and write their parts of output/benchmarks.md (the others
    kept) and their figures in output/benchmarks/; with ``update_readme`` and every section, also
    the README's speed section (between its bench:summary markers)."""

    def log(msg: str) -> None:
        if not quiet:
            print(msg, file=sys.stderr, flush=True)

    results = Results(config, machine=machine(), sections=tuple(sections))
    # The gallery and the contact part run no C++ program of benchmarks/.
    needs_programs = bool(set(sections) - {"gallery", "contact"})
    programs = build_programs(build_dir, log) if needs_programs else build_dir
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="pinsettle-bench-") as tmp:
        tasks = plan(config, results, programs, Path(tmp), sections)
        progress = Progress(len(tasks), stream=open(os.devnull, "w") if quiet else sys.stderr)
        for section, label, task in tasks:
            progress.show(label)
            began = time.perf_counter()
            task()
            results.section_seconds[section] = (
                results.section_seconds.get(section, 0.0) + time.perf_counter() - began
            )
            progress.advance()
        progress.show("writing the report")
        progress.close()
    results.machine["load_end"] = os.getloadavg()
    results.seconds = time.perf_counter() - start
    report_writer.write(results, output)
    if (
        update_readme
        and set(sections) == set(SECTIONS)
        and report_readme.update_readme(results, ROOT / "README.md")
    ):
        log("updated the speed section of README.md")
    log(f"wrote {output / 'benchmarks.md'} and {output / 'benchmarks'}/")
    return results


def parse_sections(text: str) -> tuple[str, ...]:
    names = tuple(s.strip() for s in text.split(",") if s.strip())
    unknown = [s for s in names if s not in SECTIONS]
    if unknown or not names:
        raise argparse.ArgumentTypeError(
            f"--sections takes a comma-separated list of {', '.join(SECTIONS)}; got {text!r}"
        )
    return names


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a tiny run (few scenes, robots and repeats) into build/bench-quick unless "
        "--output is given",
    )
    parser.add_argument(
        "--sections",
        type=parse_sections,
        default=SECTIONS,
        help=f"measure only these sections (comma-separated: {', '.join(SECTIONS)}) and replace "
        "only their parts of the report",
    )
    parser.add_argument(
        "--output", type=Path, help="folder of benchmarks.md and benchmarks/ (default: docs)"
    )
    parser.add_argument(
        "--build-dir",
        type=Path,
        default=ROOT / "build" / "benchmarks",
        help="CMake build folder of the C++ benchmarks (default: build/benchmarks)",
    )
    parser.add_argument(
        "--no-readme",
        action="store_true",
        help="leave README.md alone (a full run into docs/ rewrites its speed section)",
    )
    args = parser.parse_args(argv)
    config = QUICK if args.quick else FULL
    output = args.output or (ROOT / "build" / "bench-quick" if args.quick else ROOT / "docs")
    # The README quotes the committed report: only a full run into docs/ rewrites its numbers.
    readme = not args.quick and output.resolve() == (ROOT / "docs").resolve()
    generate(
        config,
        output,
        args.build_dir,
        update_readme=readme and not args.no_readme,
        sections=args.sections,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

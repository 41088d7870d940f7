"""Error against run time: the benchmark report.

``python benchmarks/report.py`` regenerates docs/benchmarks.md and its figures under
docs/benchmarks/ (a progress bar on stderr) and the speed section of README.md (between its
``bench:summary`` markers); ``--quick`` makes a tiny run into build/bench-quick instead.

For each scene of the benchmark set it measures how the error falls with the steps taken and
with wall time, for kinetic damping (both energy measures as the peak detector's signal) and
for baselines on the same Pinocchio dynamics: plain viscous damping and FIRE (C++,
benchmarks/baselines.cpp, built here with CMake against the installed package) and Newton's
method from the same start (the baselines on trees only: they run unconstrained ABA, which
cannot hold a closed loop). Then the sweeps of the settings (kt, err, ds, max_e, backtracking,
fixed against automatic dt), the cost of one step against a bare ``pinocchio::aba`` +
``integrate`` step (benchmarks/step_cost.cpp; with closed loops against a bare
``pinocchio::constraintDynamics`` + ``integrate`` step, benchmarks/loop_step_cost.cpp) and the
scaling with chain length.

The error of a configuration q is measured two ways:

- distance: ``max |q - q*|`` over the free joints (rad or m; revolute angles compared modulo
  2 pi), q* the exact equilibrium the run comes to rest at (see ``landing``);
- residual: ``max |tau_static(q)|`` (``Scene.static_force``) divided by the scene's force scale,
  ``max |tau_static(q0)|`` at the start.

Scenes with closed loops (``[[loop]]``) are measured on the closed mechanism: their start is
moved onto the loops first (``Scene.assemble``, as the solver does), the static force is the one
projected onto the motions the loops allow (what ``Scene.static_force`` returns for them), Newton
steps are taken in the reduced coordinates of ``pinsettle.assess_stability`` (``basis``) and
every step is moved back onto the loops, and the KD runs' final loop error is measured here with
Pinocchio's frame placements.

Every number in the report is computed by this script; nothing is typed in by hand.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from datetime import date
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT / "robots"))
sys.path.insert(0, str(HERE))
import report_writer  # noqa: E402  (benchmarks/report_writer.py: figures and markdown)
import stress  # noqa: E402  (benchmarks/stress.py: the heavy-and-light model)
from make_chain import chain_urdf  # noqa: E402  (robots/make_chain.py)
from report_data import (  # noqa: E402  (benchmarks/report_data.py: constants and records)
    BASELINE_LABELS,
    BASELINE_MAX_STEPS,
    BASELINE_MAX_TIME,
    BASELINE_SIDE_TIME,
    BASELINE_TARGET,
    CHAIN_LENGTHS,
    CURVE_SAMPLES,
    DEEP_MAX_E,
    DT_SAFETY,
    DT_SWEEP_SECONDS,
    MAX_STEPS,
    REPEAT_BUDGET,
    BenchScene,
    Config,
    Curve,
    Damping,
    Landing,
    Reference,
    Results,
    Run,
    SceneData,
)
from scene_statics import Statics  # noqa: E402  (benchmarks/scene_statics.py)

# --- scenes ---------------------------------------------------------------------------------


def _library(name: str) -> BenchScene:
    path = ROOT / "robots" / f"{name}.toml"
    scene = pinsettle.load_scene(path)
    return BenchScene(name, scene, scene.description)


def chain_scene(links: int) -> BenchScene:
    """The chain of robots/make_chain.py (0.1 m, 0.1 kg links) released horizontal."""
    model = pinocchio.buildModelFromXML(chain_urdf(links))
    scene = pinsettle.Scene(model, name=f"chain{links}")
    scene.set_start(joint1=math.pi / 2)
    return BenchScene(
        f"chain{links}",
        scene,
        f"{links}-link chain (robots/make_chain.py) released horizontal",
    )


STIFFNESS = 1e7  # N/m, the stiff-spring scene


def stiff_scene() -> BenchScene:
    """benchmarks/stress.py's 10 kg pendulum carrying a 10 g slider, on a 1e7 N/m spring."""
    model = stress.heavy_and_light(pinocchio.JointModelPZ())
    scene = pinsettle.Scene(model, name="stiff_spring")
    scene.add_joint_spring("light", stiffness=STIFFNESS)
    scene.set_start(j0=0.8)
    return BenchScene(
        "stiff_spring",
        scene,
        f"10 kg, 1 m pendulum carrying a 10 g slider on a {STIFFNESS:.0e} N/m joint spring "
        "(benchmarks/stress.py's heavy_and_light), released at 0.8 rad",
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
    if name == "chain100":
        return chain_scene(100)
    if name == "stiff_spring":
        return stiff_scene()
    return _library(name)


# --- the static force, distances and exact equilibria ----------------------------------------


def newton(
    statics: Statics, q: np.ndarray, iterations: int = 30, tolerance: float = 1e-16
) -> tuple[np.ndarray, list[float], int]:
    """Newton's method on the static force from q with the stiffness matrix of
    ``pinsettle.assess_stability`` (least squares with a rank cut, so neutral directions are
    left alone; with loops in the reduced coordinates, each step moved back onto the loops:
    ``Statics.newton_step``), full steps, until the residual stops falling or is <= tolerance
    (relative: round-off).
    Returns the last pose, the relative residual after each iteration (the start first) and the
    iterations taken."""
    residuals = [statics.residual(q)]
    taken = 0
    for _ in range(iterations):
        if not residuals[-1] > tolerance:
            break
        dq = statics.newton_step(q)
        trial = statics.step(q, dq)
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
    ``pinsettle.assess_stability`` as Jacobian (least squares with a rank cut 1e-10; with loops
    the reduced Newton of ``Statics.newton_step``, the start and every step moved onto the
    loops): full steps,
    or with ``line_search`` halved until |tau_static|_2 falls (Armijo, 1e-4), until the residual
    is <= 1e-14 of the force scale, a step fails or 50 iterations. Returns the end pose, the
    relative residual and the elapsed wall time (s) at the start and after each iteration, and
    the poses."""
    start = time.perf_counter()
    residuals, times, poses = [statics.residual(q)], [0.0], [q]
    for _ in range(iterations):
        if not residuals[-1] > 1e-14:
            break
        f = statics.force(q)
        dq = statics.newton_step(q, f)
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


def fd_newton_step(statics: Statics, q: np.ndarray, h: float = 1e-6) -> float:
    """Size (max norm, rad or m) of one Newton step from q with a central-difference Jacobian
    of the static force: nothing of pinsettle's stiffness code. Tiny at a root. With loops the
    differences are taken along the basis B of the motions they allow (each side moved back
    onto the loops) and the step solves B^T J y = -B^T f, dq = B y."""
    B = statics.basis(q)
    J = np.empty((statics.model.nv, B.shape[1]))
    for i in range(B.shape[1]):
        e = h * B[:, i]
        J[:, i] = (statics.force(statics.step(q, e)) - statics.force(statics.step(q, -e))) / (2 * h)
    step = B @ np.linalg.lstsq(B.T @ J, -(B.T @ statics.force(q)), rcond=1e-8)[0]
    return float(np.max(np.abs(step)))


def reference(statics: Statics) -> Reference:
    r = pinsettle.solve(statics.scene, polish=True, max_e=DEEP_MAX_E, max_steps=MAX_STEPS)
    if not r.converged or r.stability not in ("stable", "neutral"):
        raise RuntimeError(f"{statics.scene.name}: no stable reference ({r.status}, {r.stability})")
    q, _, _ = newton(statics, r.q)
    report = statics.stiffness(q)
    if report.verdict not in ("stable", "neutral"):
        raise RuntimeError(f"{statics.scene.name}: the reference is {report.verdict}")
    return Reference(
        q,
        statics.residual(q),
        report.verdict,
        report.neutral_directions,
        report.min_eigenvalue,
        fd_newton_step(statics, q),
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
    return Landing(q, statics.stiffness(q).verdict, statics.distance(ref.q, q))


# --- runs and their curves --------------------------------------------------------------------


def curve_of(statics: Statics, target: np.ndarray, steps: np.ndarray, rows: np.ndarray) -> Curve:
    residual = np.array([statics.residual(row) for row in rows])
    return Curve(np.asarray(steps, dtype=float), residual, statics.distances(target, rows))


def _target(statics: Statics, ref: Reference, land: Landing) -> np.ndarray:
    return land.q if land.q is not None else ref.q


def run_kd(
    statics: Statics,
    ref: Reference,
    settings: dict,
    repeats: int,
    curve: bool = True,
    label: str = "",
) -> Run:
    """Kinetic damping: up to ``repeats`` timed solves (wall_time is measured inside the C++
    loop; no more once they took REPEAT_BUDGET in all), and with ``curve`` one more with a trace
    of every step's configuration (the same trajectory: the solver is deterministic, checked).
    At most the scene's step budget."""
    settings = {"max_steps": ref.step_budget, **settings}
    timed = [pinsettle.solve(statics.scene, **settings)]
    while len(timed) < repeats and sum(r.wall_time for r in timed) < REPEAT_BUDGET:
        timed.append(pinsettle.solve(statics.scene, **settings))
    result = timed[-1]
    land = landing(statics, ref, result.q)
    target = _target(statics, ref, land)
    c, damping, along = None, [], math.nan
    if curve:
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
        steps = np.append(t.step, traced.steps)
        rows = np.vstack([t.q, traced.q[None, :]])
        c = curve_of(statics, target, steps, rows)
        if statics.loops:
            along = max(statics.loop_error(row) for row in rows)
        damping = [
            step for step, kind in zip(t.event_step, t.event_kind, strict=True) if kind == "damping"
        ]
    energy = settings.get("energy", "exact")
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
        curve=c,
        extra={
            "dt": result.dt,
            "dt_reductions": result.dt_reductions,
            "scaled_modes": result.scaled_modes,
            "damping_steps": np.array(damping),  # steps of the damping events (traced run)
            # Largest loop error (m) of the final q, measured here (Statics.loop_error) and by
            # the solver (Result.constraint_error), and over the traced run's samples.
            "constraint_error": statics.loop_error(result.q),
            "solver_constraint_error": result.constraint_error,
            "constraint_error_along": along,
        },
    )


# --- the C++ programs ---------------------------------------------------------------------------


def build_programs(build_dir: Path, log: Callable[[str], None]) -> Path:
    """Configure and build benchmarks/ (step_cost, loop_step_cost, baselines) against the
    installed package."""
    cmake = shutil.which("cmake", path=str(Path(sys.executable).parent)) or shutil.which("cmake")
    if cmake is None:
        raise RuntimeError("cmake is not installed (pip install cmake ninja)")
    generator = (
        ["-G", "Ninja"] if shutil.which("ninja", path=str(Path(sys.executable).parent)) else []
    )
    build_dir.mkdir(parents=True, exist_ok=True)
    if not (build_dir / "CMakeCache.txt").exists():
        log("configuring the C++ benchmarks")
        subprocess.run(
            [
                cmake,
                "-S",
                str(HERE),
                "-B",
                str(build_dir),
                *generator,
                "-DCMAKE_BUILD_TYPE=Release",
                f"-DCMAKE_PREFIX_PATH={pinsettle.get_cmake_dir()}",
            ],
            check=True,
            capture_output=True,
            text=True,
        )
    log("building the C++ benchmarks (about a minute the first time)")
    proc = subprocess.run(
        [cmake, "--build", str(build_dir), "--parallel", str(os.cpu_count() or 2)],
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"building benchmarks/ failed:\n{proc.stdout}\n{proc.stderr}")
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


def baseline_dt(statics: Statics, ref: Reference, rate: Callable[[np.ndarray], float]) -> float:
    """dt_safety times the stability limit of semi-implicit Euler with a damping rate,
    4 / (rate + sqrt(rate^2 + 4 omega_max^2)) (2 / omega_max undamped), the worse of the start
    and q*; omega_max without stiff-mode scaling (the baselines have none)."""
    steps = []
    for q in (statics.q0, ref.q):
        omega = statics.time_scale(q)["omega_unscaled"]
        r = rate(q)
        steps.append(4.0 / (r + math.sqrt(r * r + 4.0 * omega * omega)))
    return DT_SAFETY * min(steps)


def slowest_mode(statics: Statics, ref: Reference) -> tuple[float, np.ndarray]:
    """Frequency (rad/s) and M-normalised shape of the slowest mode of the mechanism linearised
    at q* (generalized eigenproblem K phi = omega^2 M phi; neutral directions skipped)."""
    from scipy.linalg import eigh

    report = statics.stiffness(ref.q)
    K = report.stiffness_matrix
    M = statics.mass_matrix(ref.q)
    w2, phi = eigh(0.5 * (K + K.T), M)
    k = int(np.flatnonzero(w2 > report.tolerance / np.max(np.diag(M)))[0])
    return math.sqrt(w2[k]), phi[:, k]


def damping_rule(statics: Statics, ref: Reference) -> Damping:
    omega, phi = slowest_mode(statics, ref)
    return Damping(omega, 2.0 * omega / float(phi @ phi), 2.0 * omega)


def damping_rate(statics: Statics, method: str, c: float) -> Callable[[np.ndarray], float]:
    """The fastest decay rate the damping gives (1/s): c times the largest eigenvalue of M^-1
    for joint dampers, c for mass-proportional damping, 0 for FIRE."""
    if method == "viscous":
        return lambda q: (
            c * float(np.max(np.linalg.eigvalsh(np.linalg.inv(statics.mass_matrix(q)))))
        )
    if method == "mass_damping":
        return lambda q: c
    return lambda q: 0.0


def run_baseline(
    program: Path,
    statics: Statics,
    ref: Reference,
    method: str,
    repeats: int,
    work: Path,
    damping: float = 0.0,
    label: str = "",
    curve: bool = True,
    max_time: float = BASELINE_MAX_TIME,
) -> Run:
    """Viscous damping or FIRE in C++ (benchmarks/baselines.cpp), with the step of
    ``baseline_dt`` (halved by the program when a run blows up: ``extra['halvings']``)."""
    dt = baseline_dt(statics, ref, damping_rate(statics, method, damping))
    model_path = work / f"{statics.scene.name}.model.bin"
    if not model_path.exists():
        statics.model.saveToBinary(str(model_path))
    q0 = statics.q0[statics.compiled.q_index]
    samples = work / f"{statics.scene.name}.{method}.samples"
    lines = [
        f"model {model_path}",
        f"q0 {q0.size} " + " ".join(repr(float(x)) for x in q0),
        f"method {method}",
        f"dt {dt!r}",
        f"damping {damping!r}",
        f"target {BASELINE_TARGET * statics.force_scale!r}",
        "check_every 64",
        f"max_steps {BASELINE_MAX_STEPS}",
        f"max_time {max_time}",
        f"repeats {repeats}",
        f"repeat_budget {REPEAT_BUDGET}",
        f"max_samples {CURVE_SAMPLES}",
        *([f"samples {samples}"] if curve else []),
        *_spec_lines(statics),
    ]
    spec = work / f"{statics.scene.name}.{method}.spec"
    spec.write_text("\n".join(lines) + "\n")
    proc = subprocess.run([str(program), str(spec)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"baselines {spec} failed: {proc.stderr}")
    out = json.loads(proc.stdout)
    q_final = statics.compiled.full_q(np.array(out["q"]))
    land = landing(statics, ref, q_final)
    target = _target(statics, ref, land)
    c = None
    if curve:
        data = np.fromfile(samples, dtype=np.float64).reshape(-1, statics.model.nq + 1)
        rows = np.array([statics.compiled.full_q(row) for row in data[:, 1:]])
        c = curve_of(statics, target, data[:, 0], rows)
    return Run(
        statics.scene.name,
        method,
        label or BASELINE_LABELS[method],
        {"dt": out["dt"], "damping": damping},
        out["status"],
        int(out["steps"]),
        list(out["wall_times"]),
        statics.residual(q_final),
        statics.distance(target, q_final),
        land.stability,
        land,
        curve=c,
        extra={"dt_end": out["dt_end"], "resets": out["resets"], "halvings": out["halvings"]},
    )


def run_newton(statics: Statics, ref: Reference, line_search: bool) -> Run:
    """Newton from the start (Python: its wall time is not comparable with the C++ loops')."""
    q, residuals, times, poses = newton_from_start(statics, statics.q0.copy(), line_search)
    finite = bool(np.all(np.isfinite(q)))
    root = finite and residuals[-1] <= 1e-10
    report = statics.stiffness(q) if root else None
    stability = report.verdict if report is not None else "-"
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
        stability,
        Landing(q if root else None, stability, distance),
        curve=Curve(np.arange(len(residuals), dtype=float), np.array(residuals), dist),
        extra={
            "times": times,
            "min_eigenvalue": report.min_eigenvalue if report else math.nan,
            "largest_angle": float(np.max(np.abs(q))) if finite else math.inf,
            "constraint_error": statics.loop_error(q),  # 0 for a tree
        },
    )


def run_step_cost(program: Path, urdf: Path, steps: int, repeats: int) -> dict:
    proc = subprocess.run(
        [str(program), str(urdf), str(steps), str(repeats), "--json"],
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"step_cost {urdf} failed: {proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run_loop_step_cost(program: Path, statics: Statics, steps: int, repeats: int) -> dict:
    """benchmarks/loop_step_cost on a scene with loops: its URDF, its loops by frame name and
    its start (the program moves it onto the loops as the solver does); gravity alone."""
    scene = statics.scene
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
    return json.loads(proc.stdout.strip().splitlines()[-1])


# --- the plan ---------------------------------------------------------------------------------


class Progress:
    """A progress bar on stderr: done/total, elapsed time and what runs now."""

    def __init__(self, total: int, stream=sys.stderr) -> None:
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
    (5, 10),
    repeats=1,
    sweep_repeats=1,
    kts=(0.0, 0.5),
    errs=(1e-12, 1e-4),
    dss=(30, 100),
    max_es=(1e-12, 1e-16),
    damping_factors=(),
    step_cost_steps=2000,
    step_cost_repeats=3,
)


def plan(config: Config, results: Results, programs: Path, work: Path) -> list:
    """The tasks, as (label, callable) pairs, run in order under the progress bar."""
    tasks: list[tuple[str, Callable[[], None]]] = []
    baselines = programs / "baselines"
    step_cost = programs / "step_cost"
    loop_step_cost = programs / "loop_step_cost"
    reps, sreps = config.repeats, config.sweep_repeats

    benches = {name: make_scene(name) for name in config.scenes}  # built once
    for name in config.scenes:

        def setup(name=name):
            bench = benches[name]
            statics = Statics(bench.scene)
            results.scenes[name] = SceneData(
                bench,
                statics,
                reference(statics),
                bench.description,
                statics.force_scale,
                statics.model.nv,
                len(bench.scene.loops),
                statics.mobility,
            )

        tasks.append((f"{name}: reference equilibrium", setup))

        def main_runs(name=name):
            d = results.scenes[name]
            s, ref = d.statics, d.ref
            for energy in ("exact", "simplified"):
                d.runs[f"kd_{energy}"] = run_kd(
                    s, ref, {"energy": energy, "max_e": DEEP_MAX_E}, reps
                )

        tasks.append((f"{name}: kinetic damping, both energy measures", main_runs))

        def baseline_runs(name=name):
            d = results.scenes[name]
            s, ref = d.statics, d.ref
            if d.loops:
                # The C++ baselines run unconstrained ABA: they cannot hold a loop. Newton (the
                # reduced one, steps moved back onto the loops) can.
                d.runs["newton"] = run_newton(s, ref, line_search=False)
                d.runs["newton_ls"] = run_newton(s, ref, line_search=True)
                return
            d.damping = damping_rule(s, ref)
            for method, c in (("viscous", d.damping.joint), ("mass_damping", d.damping.mass)):
                d.runs[method] = run_baseline(baselines, s, ref, method, reps, work, damping=c)
                for factor in config.damping_factors:
                    d.damping_sweep[(method, factor)] = run_baseline(
                        baselines,
                        s,
                        ref,
                        method,
                        1,
                        work,
                        damping=factor * c,
                        curve=False,
                        max_time=BASELINE_SIDE_TIME,
                    )
            d.runs["fire"] = run_baseline(baselines, s, ref, "fire", reps, work)
            d.runs["newton"] = run_newton(s, ref, line_search=False)
            d.runs["newton_ls"] = run_newton(s, ref, line_search=True)

        tasks.append((f"{name}: viscous damping, FIRE (trees only), Newton", baseline_runs))

        def sweep_kt(name=name):
            d = results.scenes[name]
            d.sweeps["kt"] = [
                run_kd(d.statics, d.ref, {"energy": e, "kt": kt, "max_e": DEEP_MAX_E}, sreps)
                for e in ("exact", "simplified")
                for kt in config.kts
            ]

        tasks.append((f"{name}: kt sweep", sweep_kt))

        def sweep_stop(name=name):
            d = results.scenes[name]
            s, ref = d.statics, d.ref
            d.sweeps["err"] = [run_kd(s, ref, {"err": x}, sreps, curve=False) for x in config.errs]
            d.sweeps["ds"] = [run_kd(s, ref, {"ds": x}, sreps, curve=False) for x in config.dss]
            d.sweeps["max_e"] = [
                run_kd(s, ref, {"max_e": x, "energy": e}, sreps, curve=False)
                for e in ("exact", "simplified")
                for x in config.max_es
            ]

        tasks.append((f"{name}: err, ds and max_e sweeps", sweep_stop))

        def sweep_other(name=name):
            d = results.scenes[name]
            s, ref = d.statics, d.ref
            deep = {"max_e": DEEP_MAX_E}
            d.sweeps["backtrack"] = [
                run_kd(s, ref, {**deep, "energy": e, "backtrack": b}, sreps)
                for e in ("exact", "simplified")
                for b in (False, True)
            ]
            start_dt = DT_SAFETY * s.time_scale(s.q0, True)["critical_step"]
            # At least DT_SWEEP_SECONDS each: an unscaled stiff mode needs many small steps.
            budget = {
                **deep,
                "max_steps": max(ref.step_budget, int(DT_SWEEP_SECONDS / ref.seconds_per_step)),
            }
            d.sweeps["dt"] = [
                run_kd(s, ref, budget, sreps, label="auto"),
                run_kd(
                    s, ref, {**budget, "scale_stiff_modes": False}, sreps, label="auto, unscaled"
                ),
                run_kd(s, ref, {**budget, "dt": start_dt}, sreps, label="fixed, start"),
                run_kd(s, ref, {**budget, "dt": start_dt / 4}, sreps, label="fixed, start / 4"),
            ]

        tasks.append((f"{name}: backtracking, fixed against automatic dt", sweep_other))

    # The cost of one step against bare aba + integrate.
    cost_models = [
        ("ur5", pinsettle.robot_urdf("ur5")),
        ("pendulum", ROOT / "robots/pendulum.urdf"),
    ]
    if len(config.scenes) > 1:
        cost_models.append(("chain20", ROOT / "robots/chain20.urdf"))
    for name, urdf in cost_models:

        def cost(name=name, urdf=urdf):
            results.step_cost[name] = run_step_cost(
                step_cost, urdf, config.step_cost_steps, config.step_cost_repeats
            )

        tasks.append((f"step cost: {name}", cost))
    for name in (n for n in config.scenes if benches[n].scene.loops):

        def loop_cost(name=name):
            results.loop_step_cost[name] = run_loop_step_cost(
                loop_step_cost,
                results.scenes[name].statics,
                config.step_cost_steps,
                config.step_cost_repeats,
            )

        tasks.append((f"step cost: {name} (closed loops)", loop_cost))

    # Scaling with chain length.
    for n in config.chain_lengths:

        def scale(n=n):
            bench = chain_scene(n)
            statics = Statics(bench.scene)
            ref = reference(statics)
            runs = [run_kd(statics, ref, {}, config.sweep_repeats, curve=False)]
            runs.append(
                run_kd(statics, ref, {"max_e": DEEP_MAX_E}, config.sweep_repeats, label="deep")
            )
            path = work / f"chain{n}.urdf"
            path.write_text(chain_urdf(n))
            # Enough steps that the solver's set-up (the first step estimate, the final
            # stability check: O(nv^3)) weighs little against them.
            steps = max(config.step_cost_steps // 4, config.step_cost_steps * 5 // n)
            cost = run_step_cost(step_cost, path, steps, 3)
            results.scaling.append({"n": n, "runs": runs, "cost": cost})

        tasks.append((f"scaling: chain of {n}", scale))
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


def machine() -> dict:
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
) -> Results:
    """Run everything and write output/benchmarks.md and output/benchmarks/*.png; with
    ``update_readme``, also the README's speed section (between its bench:summary markers)."""

    def log(msg: str) -> None:
        if not quiet:
            print(msg, file=sys.stderr, flush=True)

    results = Results(config, machine=machine())
    programs = build_programs(build_dir, log)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="pinsettle-bench-") as tmp:
        tasks = plan(config, results, programs, Path(tmp))
        progress = Progress(len(tasks), stream=open(os.devnull, "w") if quiet else sys.stderr)
        for label, task in tasks:
            progress.show(label)
            task()
            progress.advance()
        progress.show("writing the report")
        progress.close()
    results.machine["load_end"] = os.getloadavg()
    results.seconds = time.perf_counter() - start
    report_writer.write(results, output)
    if update_readme and report_writer.update_readme(results, ROOT / "README.md"):
        log("updated the speed section of README.md")
    log(f"wrote {output / 'benchmarks.md'} and {output / 'benchmarks'}/")
    return results


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a tiny run (one scene, few repeats) into build/bench-quick unless --output is given",
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
    generate(config, output, args.build_dir, update_readme=readme and not args.no_readme)
    return 0


if __name__ == "__main__":
    sys.exit(main())

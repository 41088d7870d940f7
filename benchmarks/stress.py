"""The stress suite: extreme mechanisms, each checked against an independent Newton solution.

Every case is a scene (a model, its springs and loads, a start) solved with each energy measure
and kt in {0, 0.5, 0.9}. A case passes when it ends

- ``converged``, within 1e-6 (rad or m) in every joint of the equilibrium that Newton's method
  finds from the answer on this module's own reimplementation of the static force (gravity from
  Pinocchio's RNEA, springs and loads written out here with frame Jacobians, a finite-difference
  Jacobian: nothing of pinsettle's force or stiffness code), and that equilibrium stable or
  neutral by the eigenvalues of the symmetric part of that same finite-difference Jacobian (a
  rest on a saddle fails, whatever the solver's own verdict says); a case with joint stops
  (the UR5's own limits) holds the joints pressed on a stop out of Newton and of the
  eigenvalues, and checks the conditions of a rest there: every joint within its stops, the
  static force at a pressed one pushing into the stop;
- or with the status the case expects (``no_equilibrium``),

and never with a non-finite value, a crash or a hang (each run has a wall-clock budget).

``python benchmarks/stress.py`` runs every case and writes docs/robustness.md (this table, the
measured safety factor of the automatic step and what the solver does about each extreme);
tests/test_stress.py runs the same cases under pytest.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio
import pinsettle

KTS = (0.0, 0.5, 0.9)
ENERGIES = ("exact", "simplified")
JOINT_TOLERANCE = 1e-6  # rad or m, every joint, against Newton
MAX_TIME = 60.0  # s of wall clock per run: a run that needs more is a failure, not a hang


# --- the physics, written out independently of pinsettle's elements ---------------------------


#: A point in a frame (m).
Point = tuple[float, float, float]


@dataclass
class Physics:
    """A mechanism and what acts on it, in a form both pinsettle and the reference read."""

    model: pinocchio.Model
    joint_springs: list[tuple[str, float, float]] = field(default_factory=list)  # joint, k, rest
    # (frame a, point in a, frame b, point in b, stiffness, rest length)
    springs: list[tuple[str, Point, str, Point, float, float]] = field(default_factory=list)
    loads: list[tuple[str, float]] = field(default_factory=list)  # joint, effort (1-DoF)
    # joint, lower, upper (rad or m, 1-DoF): the only stops; the model's own limits are off
    stops: list[tuple[str, float, float]] = field(default_factory=list)

    def scene(self) -> pinsettle.Scene:
        scene = pinsettle.Scene(self.model, limits=False)
        for joint, lower, upper in self.stops:
            scene.set_limit(joint, lower, upper)
        for joint, k, rest in self.joint_springs:
            scene.add_joint_spring(joint, stiffness=k, rest=rest)
        for fa, pa, fb, pb, k, rest in self.springs:
            scene.add_spring(
                {"frame": fa, "point": list(pa)},
                {"frame": fb, "point": list(pb)},
                stiffness=k,
                rest_length=rest,
            )
        for joint, effort in self.loads:
            scene.add_load(joint, effort)
        return scene


def _point_jacobian(
    model: pinocchio.Model, data: pinocchio.Data, frame: str, point: Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """World position of a point fixed in a frame and its linear Jacobian (world axes)."""
    fid = model.getFrameId(frame)
    placement = data.oMf[fid]
    world = placement.act(np.asarray(point, dtype=float))
    J = pinocchio.getFrameJacobian(model, data, fid, pinocchio.LOCAL_WORLD_ALIGNED)
    offset = world - placement.translation
    # v_point = v_frame + w x offset = J_lin v - [offset]x J_ang v
    return world, J[:3] - pinocchio.skew(offset) @ J[3:]


def static_force(physics: Physics, q: np.ndarray) -> np.ndarray:
    """Net static generalized force: gravity minus springs and loads; zero at an equilibrium."""
    model = physics.model
    data = model.createData()
    force: np.ndarray = pinocchio.computeGeneralizedGravity(model, data, q).copy()
    for joint, k, rest in physics.joint_springs:
        j = model.getJointId(joint)
        force[model.idx_vs[j]] += k * (q[model.idx_qs[j]] - rest)
    if physics.springs:
        pinocchio.computeJointJacobians(model, data, q)
        pinocchio.updateFramePlacements(model, data)
        for fa, pa, fb, pb, k, rest in physics.springs:
            xa, Ja = _point_jacobian(model, data, fa, pa)
            xb, Jb = _point_jacobian(model, data, fb, pb)
            d = xa - xb
            length = np.linalg.norm(d)
            force -= (Ja - Jb).T @ (-k * (length - rest) * d / length)
    for joint, effort in physics.loads:
        force[model.idx_vs[model.getJointId(joint)]] -= effort
    return force


def jacobian(physics: Physics, q: np.ndarray) -> np.ndarray:
    """d static_force / dq by central differences along each joint-velocity direction (step
    1e-7 through pinocchio.integrate): the stiffness matrix, nothing of pinsettle's."""
    model = physics.model
    J = np.empty((model.nv, model.nv))
    for i in range(model.nv):
        e = np.zeros(model.nv)
        e[i] = 1e-7
        plus = static_force(physics, pinocchio.integrate(model, q, e))
        minus = static_force(physics, pinocchio.integrate(model, q, -e))
        J[:, i] = (plus - minus) / 2e-7
    return J


def newton(
    physics: Physics, q: np.ndarray, iterations: int = 30, held: np.ndarray | None = None
) -> tuple[np.ndarray, float]:
    """Newton's method on the static force from q with a central-difference Jacobian (least
    squares: neutral directions are left alone), until the step is below 1e-13 or stops
    helping. ``held`` (velocity indices) are coordinates pressed against a stop: they do not
    move and their force is the stop's to carry. Returns the root and the size of the last step
    taken (rad or m): the root is known to about that."""
    model = physics.model
    free = np.setdiff1d(np.arange(model.nv), [] if held is None else held)
    q = q.copy()
    last = math.inf
    for _ in range(iterations):
        r = static_force(physics, q)[free]
        if not np.any(r):
            return q, 0.0
        J = jacobian(physics, q)[np.ix_(free, free)]
        step = np.zeros(model.nv)
        step[free] = np.linalg.lstsq(J, -r, rcond=1e-8)[0]  # FD noise: ~1e-8 of the largest
        size = float(np.max(np.abs(step)))
        trial = pinocchio.integrate(model, q, step)
        # From a good answer Newton takes full steps; one that does not lower |r| is round-off.
        if np.max(np.abs(static_force(physics, trial)[free])) >= np.max(np.abs(r)):
            return q, min(last, size)
        q, last = trial, size
        if size < 1e-13:
            break
    return q, last


STOP_TOLERANCE = 1e-9  # rad or m: a coordinate this close to a stop is pressed against it


def pressed(physics: Physics, q: np.ndarray) -> tuple[np.ndarray, str]:
    """The coordinates of q pressed against a stop (velocity indices), and what breaks the
    conditions of a rest at stops, "" if nothing: every coordinate within its stops, and at a
    pressed one the static force pushing into the stop (a stop pushes, it never pulls), to
    1e-8 of the largest static force."""
    model = physics.model
    force = static_force(physics, q)
    slack = 1e-8 * max(float(np.max(np.abs(force))), 1e-300)
    held: list[int] = []
    for joint, lower, upper in physics.stops:
        j = model.getJointId(joint)
        x, i = float(q[model.idx_qs[j]]), model.idx_vs[j]
        if not lower - STOP_TOLERANCE <= x <= upper + STOP_TOLERANCE:
            return np.array(held, dtype=int), f"{joint} at {x:.6g} outside [{lower:g}, {upper:g}]"
        # The static force is what holds the mechanism: positive at a lower stop means the
        # mechanism pushes down into it.
        for bound, sign in ((lower, 1.0), (upper, -1.0)):
            if abs(x - bound) <= STOP_TOLERANCE:
                if sign * force[i] < -slack:
                    return np.array(held, dtype=int), (
                        f"{joint} at its stop {bound:g} pulled away from it ({force[i]:.2e})"
                    )
                held.append(i)
    return np.array(held, dtype=int), ""


# Zero eigenvalues (neutral directions) are told from negative ones within this fraction of the
# largest, or within the finite-difference noise of the Jacobian if that is larger: its
# asymmetry (the stiffness of springs, loads and gravity is symmetric) times its size.
NEUTRAL_TOLERANCE = 1e-7


@dataclass
class Stability:
    verdict: str  # "stable", "neutral" or "unstable"
    min_eigenvalue: float  # N m/rad or N/m
    tolerance: float


def stability(physics: Physics, q: np.ndarray, held: np.ndarray | None = None) -> Stability:
    """The kind of rest at q from the eigenvalues of the symmetric part of this module's own
    finite-difference stiffness (the Jacobian Newton uses), not from pinsettle's verdict; with
    ``held`` (coordinates pressed against a stop) that of the free coordinates."""
    free = np.setdiff1d(np.arange(physics.model.nv), [] if held is None else held)
    if free.size == 0:  # every coordinate pressed on a stop: nothing can move
        return Stability("stable", math.inf, 0.0)
    J = jacobian(physics, q)[np.ix_(free, free)]
    eigenvalues = np.linalg.eigvalsh(0.5 * (J + J.T))
    noise = len(J) * float(np.max(np.abs(J - J.T)))
    tolerance = max(NEUTRAL_TOLERANCE * float(np.max(np.abs(eigenvalues))), noise, 1e-300)
    smallest = float(eigenvalues[0])
    if smallest < -tolerance:
        verdict = "unstable"
    elif smallest <= tolerance:
        verdict = "neutral"
    else:
        verdict = "stable"
    return Stability(verdict, smallest, tolerance)


# --- the cases ----------------------------------------------------------------------------------


def chain(
    masses: Sequence[float] | np.ndarray,
    lengths: Sequence[float] | np.ndarray,
    gravity: float = 9.81,
) -> pinocchio.Model:
    """A planar chain of revolute joints about y, link k a rod of mass masses[k] and length
    lengths[k] (centre of mass at its middle), each with a frame 'link{k}' at its root."""
    model = pinocchio.Model()
    parent = 0
    for k, (m, length) in enumerate(zip(masses, lengths, strict=True)):
        offset = 0.0 if k == 0 else -lengths[k - 1]
        placement = pinocchio.SE3(np.eye(3), np.array([0.0, 0.0, offset]))
        parent = model.addJoint(parent, pinocchio.JointModelRY(), placement, f"j{k}")
        inertia = m * length * length / 12.0
        model.appendBodyToJoint(
            parent,
            pinocchio.Inertia(
                m, np.array([0.0, 0.0, -length / 2]), np.diag([inertia, inertia, 1e-3 * inertia])
            ),
            pinocchio.SE3.Identity(),
        )
        model.addFrame(
            pinocchio.Frame(
                f"link{k}", parent, 0, pinocchio.SE3.Identity(), pinocchio.FrameType.BODY
            )
        )
    model.gravity = pinocchio.Motion(np.array([0.0, 0.0, -gravity]), np.zeros(3))
    return model


def heavy_and_light(light_joint: pinocchio.JointModel) -> pinocchio.Model:
    """A 10 kg pendulum (1 m) carrying a 10 g body on a second joint at its tip."""
    model = chain([10.0], [1.0])
    joint = model.addJoint(
        1, light_joint, pinocchio.SE3(np.eye(3), np.array([0.0, 0.0, -1.0])), "light"
    )
    model.appendBodyToJoint(
        joint,
        pinocchio.Inertia(0.01, np.array([0.0, 0.0, -0.05]), np.eye(3) * 1e-5),
        pinocchio.SE3.Identity(),
    )
    model.addFrame(
        pinocchio.Frame("light", joint, 0, pinocchio.SE3.Identity(), pinocchio.FrameType.BODY)
    )
    return model


#: A case's builder: the reference physics (None where there is no equilibrium to check),
#: the scene and its start.
Build = Callable[[], tuple[Physics | None, pinsettle.Scene, np.ndarray]]


@dataclass
class Case:
    name: str
    group: str
    build: Build
    expect: str = "equilibrium"  # or a status: "no_equilibrium"
    note: str = ""
    settings: dict[str, Any] = field(default_factory=dict)  # beyond the defaults, in the table


def model_stops(model: pinocchio.Model) -> list[tuple[str, float, float]]:
    """The stops of a model's own position limits, read here: joints with one coordinate and one
    degree of freedom whose limits differ (a URDF writes equal ones for none); a side beyond
    1e10 (rad or m) or not finite is no stop."""
    stops = []
    for j in range(1, model.njoints):
        if model.nqs[j] != 1 or model.nvs[j] != 1:
            continue
        lower = float(model.lowerPositionLimit[model.idx_qs[j]])
        upper = float(model.upperPositionLimit[model.idx_qs[j]])
        if lower == upper:
            continue
        lower = lower if -1e10 < lower else -math.inf
        upper = upper if upper < 1e10 else math.inf
        if math.isfinite(lower) or math.isfinite(upper):
            stops.append((model.names[j], lower, upper))
    return stops


def _physics_case(physics: Physics, q0: Sequence[float] | np.ndarray) -> Build:
    def build() -> tuple[Physics | None, pinsettle.Scene, np.ndarray]:
        return physics, physics.scene(), np.asarray(q0, dtype=float)

    return build


def _scene_case(name: str, reference: bool = True) -> Build:
    """A scene of robots/ (gravity only when ``reference``: the reference needs no elements)."""

    def build() -> tuple[Physics | None, pinsettle.Scene, np.ndarray]:
        scene = pinsettle.load_scene(pinsettle.scene_path(name))
        stops = model_stops(scene.model) if scene.limits and not scene.joint_limits else []
        physics = Physics(scene.model, stops=stops) if reference else None
        if reference:
            assert not scene.has_elements, name
        return physics, scene, scene.q0()

    return build


def stiffness_cases() -> list[Case]:
    """A 10 g body on a stiff spring next to a 10 kg pendulum."""
    out = []
    for k in (1e2, 1e5, 1e8):
        model = heavy_and_light(pinocchio.JointModelPZ())
        physics = Physics(model, joint_springs=[("light", k, 0.0)])
        out.append(
            Case(
                f"slider spring k={k:.0e}",
                "stiffness",
                _physics_case(physics, [0.8, 0.0]),
                note="10 kg pendulum, 10 g slider at its tip on a joint spring",
            )
        )
    model = heavy_and_light(pinocchio.JointModelRY())
    physics = Physics(
        model, springs=[("light", (0.0, 0.0, -0.1), "universe", (0.5, 0.0, -1.0), 1e8, 0.0)]
    )
    out.append(
        Case(
            "point spring k=1e+08",
            "stiffness",
            _physics_case(physics, [0.3, 0.0]),
            note="tip of the 10 g link tied to a world point",
        )
    )
    return out


def span_cases() -> list[Case]:
    """Mass ratio 1e-4 .. 1e4 kg (unit lengths), link lengths 1 mm .. 100 m (unit masses),
    both."""
    n = 9
    masses = np.logspace(-4, 4, n)
    lengths = np.logspace(-3, 2, n)
    spans = [
        ("masses 1e-4..1e4 kg, root light", "mass ratio", masses, np.ones(n)),
        ("masses 1e4..1e-4 kg, root heavy", "mass ratio", masses[::-1], np.ones(n)),
        ("lengths 1 mm..100 m, root short", "scale", np.ones(n), lengths),
        ("lengths 100 m..1 mm, root long", "scale", np.ones(n), lengths[::-1]),
        ("light short root to heavy long tip", "mass and scale", masses, lengths),
        ("heavy short root to light long tip", "mass and scale", masses, lengths[::-1]),
    ]
    out = []
    for name, group, ms, ls in spans:
        settings = {}
        if name.startswith("masses 1e4"):
            # The stopping rule bounds energy (J): a 0.1 g tip link 1.6e-6 rad off stores less
            # than 1e-12 J, far below the default max_e, so 1e-6 rad needs a smaller bound.
            settings = {"max_e": 1e-16}
        out.append(
            Case(
                name,
                group,
                _physics_case(Physics(chain(ms, ls)), np.full(n, 0.5)),
                settings=settings,
            )
        )
    return out


def chain_length_cases() -> list[Case]:
    """Chain length 2 .. 100 (1 kg, 1 m links), released from horizontal."""
    out = []
    for links in (2, 10, 30, 100):
        q0 = np.zeros(links)
        q0[0] = math.pi / 2
        physics = Physics(chain([1.0] * links, [1.0] * links))
        out.append(Case(f"chain of {links}", "chain length", _physics_case(physics, q0)))
    return out


def gravity_cases() -> list[Case]:
    """Gravity 0 .. 1000 m/s^2: five links with joint springs (rest 0.3 rad, 10 N m/rad)."""
    out = []
    for g in (0.0, 1e-3, 9.81, 1000.0):
        model = chain([1.0] * 5, [1.0] * 5, gravity=g)
        physics = Physics(model, joint_springs=[(f"j{k}", 10.0, 0.3) for k in range(5)])
        out.append(
            Case(f"gravity {g:g} m/s^2", "gravity", _physics_case(physics, np.full(5, -1.0)))
        )
    return out


def far_start_cases() -> list[Case]:
    """Far from equilibrium: a chain folded nearly upright, the UR5 in a contorted pose."""
    folded = Physics(chain([1.0] * 5, [1.0] * 5))
    ur5 = pinsettle.load_robot("ur5")
    contorted = Physics(ur5, stops=model_stops(ur5))
    return [
        Case(
            "chain of 5 folded upright",
            "far start",
            _physics_case(folded, [3.0, -2.9, 2.8, -2.7, 2.6]),
        ),
        Case(
            "UR5 from a contorted pose",
            "far start",
            _physics_case(contorted, [2.5, -2.0, 2.8, -2.5, 1.5, 1.0]),
        ),
    ]


def saddle_cases() -> list[Case]:
    """Exactly at an unstable equilibrium."""
    return [
        Case("pendulum upright", "saddle start", _scene_case("pendulum_upright")),
        Case("UR5 on a saddle", "saddle start", _scene_case("ur5_saddle")),
    ]


def no_equilibrium_cases() -> list[Case]:
    return [
        Case(name, "no equilibrium", _scene_case(name, False), expect="no_equilibrium")
        for name in ("torque_disk", "free_fall", "overloaded_pendulum")
    ]


def cases() -> list[Case]:
    groups = (
        stiffness_cases,
        span_cases,
        chain_length_cases,
        gravity_cases,
        far_start_cases,
        saddle_cases,
        no_equilibrium_cases,
    )
    return [case for group in groups for case in group()]


# --- running them -------------------------------------------------------------------------------


@dataclass
class Outcome:
    case: str
    group: str
    settings: str
    energy: str
    kt: float
    status: str
    stability: str
    steps: int
    seconds: float
    error: float  # max |q - q_newton| (rad or m); nan when there is no equilibrium to match
    reference_stability: str  # from the reference's own stiffness at the Newton root; "-" if none
    reference_min_eigenvalue: float  # N m/rad or N/m; nan when not assessed
    residual: float
    dt_reductions: int
    scaled_modes: int
    passed: bool
    why: str


def run(case: Case, energy: str, kt: float) -> Outcome:
    physics, scene, q0 = case.build()
    start = time.perf_counter()
    settings = {"max_time": MAX_TIME, **case.settings}
    result = pinsettle.solve(scene, q0, energy=energy, kt=kt, **settings)
    seconds = time.perf_counter() - start
    finite = bool(np.all(np.isfinite(result.q)) and np.all(np.isfinite(result.v)))
    error = math.nan
    reference = None
    why = ""
    if not finite:
        why = "non-finite q or v"
    elif case.expect == "equilibrium":
        if physics is None:  # only the no-equilibrium cases go without
            raise RuntimeError(f"{case.name}: an equilibrium case needs its reference physics")
        if not result.converged:
            why = f"ended {result.status}"
        else:
            held, broken = pressed(physics, result.q)
            root, uncertainty = newton(physics, result.q, held=held)
            if broken:
                why = broken
            elif not uncertainty <= 1e-3 * JOINT_TOLERANCE:
                why = f"reference Newton did not settle (last step {uncertainty:.1e})"
            else:
                diff = pinocchio.difference(physics.model, root, result.q)
                error = float(np.max(np.abs(diff)))
                reference = stability(physics, root, held)
                if not error <= JOINT_TOLERANCE:
                    why = f"{error:.1e} from the Newton root"
                elif reference.verdict == "unstable":
                    why = (
                        f"rest on a saddle: the reference stiffness has eigenvalue "
                        f"{reference.min_eigenvalue:.3g} (tolerance {reference.tolerance:.1e}); "
                        f"the solver said {result.stability}"
                    )
    elif result.status != case.expect:
        why = f"ended {result.status}, expected {case.expect}"
    return Outcome(
        case.name,
        case.group,
        ", ".join(f"{k} = {v:g}" for k, v in case.settings.items()),
        energy,
        kt,
        result.status,
        result.stability,
        result.steps,
        seconds,
        error,
        "-" if reference is None else reference.verdict,
        math.nan if reference is None else reference.min_eigenvalue,
        result.residual,
        result.dt_reductions,
        result.scaled_modes,
        not why,
        why,
    )


def runs() -> list[tuple[Case, str, float]]:
    return [(case, energy, kt) for case in cases() for energy in ENERGIES for kt in KTS]


# --- the report ---------------------------------------------------------------------------------


def table(outcomes: list[Outcome]) -> str:
    lines = [
        "| group | case | settings | energy | kt | outcome | steps | time (ms) | error vs Newton "
        "| reference stiffness | residual | halvings | stiff modes | pass |",
        "| --- | --- | --- | --- | --- | --- | ---: | ---: | ---: | --- | ---: | ---: | ---: "
        "| --- |",
    ]
    for o in outcomes:
        outcome = o.status + (f", {o.stability}" if o.status == "converged" else "")
        error = "-" if math.isnan(o.error) else f"{o.error:.1e}"
        reference = (
            "-"
            if math.isnan(o.reference_min_eigenvalue)
            else f"{o.reference_stability}, min {o.reference_min_eigenvalue:.2g}"
        )
        verdict = "yes" if o.passed else f"**no**: {o.why}"
        lines.append(
            f"| {o.group} | {o.case} | {o.settings or 'defaults'} | {o.energy} | {o.kt:g} "
            f"| {outcome} | {o.steps:,} "
            f"| {1e3 * o.seconds:.1f} | {error} | {reference} | {o.residual:.1e} "
            f"| {o.dt_reductions} "
            f"| {o.scaled_modes} | {verdict} |"
        )
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--output", default=str(Path(__file__).resolve().parents[1] / "docs" / "robustness.md")
    )
    parser.add_argument(
        "--skip-dt-safety", action="store_true", help="leave out the safety-factor sweep"
    )
    args = parser.parse_args()
    outcomes = []
    plan = runs()
    for i, (case, energy, kt) in enumerate(plan, 1):
        outcome = run(case, energy, kt)
        outcomes.append(outcome)
        mark = "ok" if outcome.passed else f"FAIL ({outcome.why})"
        print(f"[{i}/{len(plan)}] {case.name} {energy} kt={kt:g}: {mark}", file=sys.stderr)
    passed = sum(o.passed for o in outcomes)
    dt_rows = None
    if not args.skip_dt_safety:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import dt_safety

        print("measuring the safety factor of the automatic step ...", file=sys.stderr)
        dt_rows = dt_safety.measure(dt_safety.FACTORS, 2_000_000)
    text = report(outcomes, passed, dt_rows) + kept_sections(Path(args.output))
    Path(args.output).write_text(text, encoding="utf-8")
    print(f"{passed}/{len(outcomes)} passed; wrote {args.output}", file=sys.stderr)
    return 0 if passed == len(outcomes) else 1


# Sections of the output written by hand, after the generated ones: kept as they are.
KEPT_SECTIONS = "\n## Reliability\n"


def kept_sections(path: Path) -> str:
    """The hand-written end of an existing output (from its Reliability section on), or ''."""
    try:
        old = path.read_text(encoding="utf-8")
    except OSError:
        return ""
    at = old.find(KEPT_SECTIONS)
    return "" if at < 0 else old[at:]


def report(outcomes: list[Outcome], passed: int, dt_rows: list[dict[str, Any]] | None) -> str:
    from datetime import date

    total = sum(o.seconds for o in outcomes)
    machine = f"{_cpu()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    parts = [TEMPLATE_HEAD.format(date=date.today().isoformat(), machine=machine)]
    if dt_rows is not None:
        parts.append(dt_text(dt_rows))
        parts.append(dt_table(dt_rows))
    parts.append(
        TEMPLATE_TABLE.format(
            passed=passed, runs=len(outcomes), seconds=total, tolerance=JOINT_TOLERANCE
        )
    )
    parts.append(table(outcomes))
    return "\n".join(parts) + "\n"


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.machine()


def dt_text(rows: list[dict[str, Any]]) -> str:
    """The paragraph above the safety factor's table, its counts from the rows: the largest
    factor up to which every run converged and the one with the fewest steps in total."""
    every = [row for row in rows if row["converged"] == row["runs"]]
    largest = max((row["c"] for row in every), default="none")
    fewest = min(every, key=lambda row: row["total_steps"])["c"] if every else "none"
    import dt_safety  # beside this file (main puts its folder on the path)

    runs = rows[0]["runs"]
    scenes = runs // len(dt_safety.KTS)
    return TEMPLATE_DT.format(scenes=scenes, runs=runs, largest=largest, fewest=fewest)


def dt_table(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| c (dt_safety) | converged | total steps | median steps | step halvings | failed |",
        "| --- | --- | ---: | ---: | ---: | --- |",
    ]
    for row in rows:
        lines.append(
            f"| {row['c']} | {row['converged']}/{row['runs']} | {row['total_steps']:,} "
            f"| {row['median_steps']:,.0f} | {row['reductions']} | {', '.join(row['failed'])} |"
        )
    return "\n".join(lines) + "\n"


TEMPLATE_HEAD = """# Robustness

Generated by `python benchmarks/stress.py` on {date} ({machine}). Do not edit by hand.

What the solver does about the hard cases, and the measured outcome of each.

## The automatic time step

`dt = "auto"` (the default) sets the step to `dt_safety * 2 / omega_max`, with `omega_max^2`
the largest of the eigenvalues of `M(q)^-1 K(q)` (K the stiffness matrix of gravity, springs
and loads: Pinocchio's analytic gravity derivatives plus the springs' own stiffness) and the
joint pull `|M^-1 tau|` per unit of motion (where K vanishes, an arm held horizontal, the pull
still sets the time scale). With dampers the limit is that of semi-implicit Euler with damping.
The step is re-estimated when the mechanism has moved 0.1 rad (or m) since the last estimate,
never grows more than twofold at once, and bounds the turn per step to `dt_safety` rad.

**Stiff modes.** A 1e8 N/m spring on a 10 g body next to a 10 kg pendulum has modes at 1e5 and
3 rad/s: an explicit step resolves the fast one and takes 1e5 steps per swing of the slow one.
With `scale_stiff_modes` (the default) the modes more than 1e4 in eigenvalue (100x in
frequency) above everything below them, or more than 1e6 above the softest, get a constant
added inertia `W^T diag(d) W` along their shapes, which brings them down to the level of the
rest. The scaled system is still a mechanical system with the same potential, so its equilibria
and their stability are those of the real one; only the stiff modes move more slowly. The
added inertia enters the exact kinetic energy used by the peak detector, the acceleration is
solved exactly (Woodbury identity on ABA's answer), and a change of modes at a re-estimate never
adds kinetic energy.
"""

TEMPLATE_DT = """\
**The safety factor `dt_safety`.** Measured, not guessed: every scene of the library with an
equilibrium ({scenes} of them, {runs} runs), kt in {{0, 0.5, 0.9}}, each factor c (`python
benchmarks/dt_safety.py` prints the same table), with the other settings at their defaults
(backtracking on); a run counts as converged at a rest that is not unstable (`marginal`
included: go1 with its motors off may rest within 1 % of sliding). Past the largest factor at
which every run still converged ({largest} here), runs start to fail (the stable limit is that of
the linearised mechanism, and large motions are more demanding), while below it the steps grow
roughly as 1/c (the fewest in total at {fewest}). The default, 0.3 with backtracking and the
exact energy (0.2 otherwise), sits well below that: it is the largest factor that also kept
every basin of 540 releases of the bistable pendulum (`python benchmarks/basins.py`; 0.4 lost
4), since a coarse step can carry a mechanism over a hump. Without backtracking every run
converged only up to 0.3 (16 of 33 at 0.5, measured on the 11 scenes the library had then): a
peak is seen one step late, and stopping dead there overshoots when the step is coarse.

"""

TEMPLATE_TABLE = """
## Divergence guard

If the kinetic energy grows tenfold per step for ten steps in a row (no resolved motion does
that), or a value becomes non-finite, the run goes back to the last good state (the start, or
the last damping event of a clean stretch), halves the step and goes on; `dt_reductions`
counts that. Status `diverged` only after 30 halvings.

## Stability verdict and unstable starts

Every result carries `stability` (`stable`, `neutral` with the number of neutral directions, or
`unstable`) and the smallest eigenvalue of the stiffness matrix K restricted to the free joints,
with a tolerance scaled to K's size. A mechanism at rest where K has a negative eigenvalue (a
pendulum exactly upright, the UR5 at `[0, pi/2, 0, pi/2, 0, 0]`) is never reported converged:
it is pushed along the most negative eigenvector and goes on to a stable rest.

## No equilibrium

A run whose energy released per doubling of the run (kinetic energy gained plus energy taken
out) and travelled distance both grow at least 1.5x per doubling, eight times in a row, ends with
`no_equilibrium` and a reason naming the joint that travelled furthest: first kt drops to 0 (full
stops at every peak, to tell a deep well from a runaway), then a second such run decides. That
takes at most 2 x 256 x ds steps after the release starts to grow.

## Newton polish

`polish = true` follows a converged run with Newton steps on the static force with the analytic
K; the polished pose is kept only if it stays of the same stability and within the basin.
`residual_before_polish` and `residual` report both.

## The stress suite

{passed}/{runs} runs passed, {seconds:.1f} s of solving in all. A run passes when it ends
converged within {tolerance:g} (rad or m) in every joint of the equilibrium that an independent
Newton solve (this suite's own static force: Pinocchio's RNEA for gravity, springs and loads
written out with frame Jacobians, central-difference Jacobian) finds from its answer, and that
equilibrium is stable or neutral by the eigenvalues of the symmetric part of the same
central-difference Jacobian (not by the solver's verdict: a rest on a saddle fails), or when it
ends with the status the case expects. `error vs Newton` is that distance; `reference
stiffness` the reference's verdict and smallest eigenvalue (N m/rad or N/m; neutral within
1e-7 of the largest or the differences' noise); `residual` the largest net static generalized
force left (N m or N); `halvings` the divergence guard's step halvings; `stiff modes` the most
modes slowed at once. Default settings otherwise. Failures stay in the table until they are
fixed.

"""


if __name__ == "__main__":
    sys.exit(main())

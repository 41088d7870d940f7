"""The Python face of the C++ solver: ``solve``, its result and the static checks (the
settings are in ``_settings``)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio

from . import _core
from ._checks import as_flag, as_vector
from ._scene import Scene, has_mimic_joints
from ._settings import Settings


@dataclass(frozen=True)
class Trace:
    """Samples recorded every ``stride`` steps (``Settings.trace_every``).

    ``q`` (samples x model.nq) is recorded with ``Settings.trace_configurations``, else None.
    ``event_step``/``event_time``/``event_kind`` list every velocity change: 'damping' at an
    energy peak, 'push' off an unstable rest, 'rollback' to the last good state with the step
    halved, 'impact' of a joint on its stop (never decimated); ``event_joint`` gives the joint
    of each impact (its index in the model solved, the full model for a scene), -1 for the
    other kinds.
    """

    step: np.ndarray
    time: np.ndarray
    kinetic_energy: np.ndarray
    simplified_kinetic_energy: np.ndarray
    stride: int
    q: np.ndarray | None = None
    event_step: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    event_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    event_kind: tuple[str, ...] = ()
    event_joint: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


@dataclass(frozen=True)
class Progress:
    """A running solve's state, given to ``solve(..., progress=f)`` every ``check_every`` steps.

    ``steps`` taken so far, ``sim_time`` simulated (s), ``kinetic_energy`` of the last step
    evaluated (J, the exact measure: that of the state one step before), ``peaks`` the damping
    events so far, ``residual`` at the current configuration (N m or N, as
    ``Result.residual``; nan if the core has none to give), ``wall_time`` since the solve
    started (s).
    """

    steps: int
    sim_time: float
    kinetic_energy: float
    peaks: int
    residual: float
    wall_time: float


def _progress_reporter(
    progress: Callable[[Progress], object] | None,
) -> Callable[[Mapping[str, Any]], None] | None:
    """What the C++ loop calls with its plain dict: ``progress`` given a ``Progress``."""
    if progress is None:
        return None
    if not callable(progress):
        raise TypeError(f"progress must be callable or None, got {type(progress).__name__}")

    def report(record: Mapping[str, Any]) -> None:
        progress(
            Progress(
                steps=int(record["steps"]),
                sim_time=float(record["sim_time"]),
                kinetic_energy=float(record["kinetic_energy"]),
                peaks=int(record["peaks"]),
                residual=float(record["residual"]),
                wall_time=float(record["wall_time"]),
            )
        )

    return report


@dataclass(frozen=True)
class Contact:
    """A ground contact at a rest: the point ``name`` (a ``[[contact]]``) on the ground
    ``ground``, where it touches (``point``, world, m: a sphere's lowest point), the ground's
    unit ``normal``, the force the ground exerts on the body there (``normal_force`` >= 0, N;
    ``tangential_force``, world, N, in the ground's plane), the ``gap`` (m, negative when sunk
    in), whether it is ``sticking`` (the tangential force strictly inside the friction cone;
    at its edge the contact would slide) and whether the rest hangs on it by a thread,
    ``marginal``: it carries at most 1e-3 of the largest normal force, or its tangential force
    is within 1 % of the cone's edge (a stable rest held so is ``'marginal'``). ``body`` is the
    body (link) the point is on, '' where the solve had no scene to tell it."""

    name: str
    ground: str
    point: np.ndarray
    normal: np.ndarray
    normal_force: float
    tangential_force: np.ndarray
    gap: float
    sticking: bool
    marginal: bool
    body: str = ""


@dataclass(frozen=True)
class Result:
    """Outcome of a solve.

    ``q`` (dim model.nq) and ``v`` (dim model.nv) are the final state (of the full model for a
    scene, locked joints included); ``status`` is one of 'converged', 'max_steps',
    'time_limit', 'aborted', 'diverged'; ``residual`` is max |rnea(q, 0, 0) - applied efforts|
    over the free joints in N m or N; energies are those of the final state; ``joints`` maps
    each joint name to its final value (a number for a 1-DoF joint, a list otherwise, each
    quaternion w first as ``Scene.set_start`` takes it: a free-flyer x, y, z, qw, qx, qy, qz,
    a spherical joint qw, qx, qy, qz; ``q`` keeps Pinocchio's order, w last).
    ``stability`` is 'stable', 'neutral' or 'unstable' (with contacts also 'marginal', see
    below) from the eigenvalues of the stiffness matrix at ``q`` (``min_stiffness_eigenvalue``
    the smallest, N m/rad or N/m; ``neutral_directions`` how many are zero within the
    tolerance); ``pushes`` counts the
    pushes off an unstable rest (a saddle or a maximum is never reported converged).
    ``status`` 'no_equilibrium' means the potential falls without bound along the motion;
    ``reason`` says what was seen (also for 'diverged'). ``dt`` is the step in force at the end,
    ``dt_estimates`` the automatic estimates made, ``dt_reductions`` the roll-backs with the
    step halved (divergence guard), ``scaled_modes`` the most stiff modes slowed at once,
    ``scaled_joints`` the most joints given a fictitious inertia at once. With
    ``polish``: ``residual_before_polish`` (where the run stopped, or where Newton took over at
    a damping event: ``newton_takeover``), ``polish_iterations`` and whether the polished pose
    was kept (``polished``). ``mobility`` is the mechanism's degrees of freedom (nv of the free
    joints less the independent loop equations). ``loops`` counts the loop closures. With loops
    (a ``Scene`` with ``[[loop]]``): ``assembly_distance`` how far the start moved to close
    them (rad or m), ``constraint_error`` the largest loop error of ``q`` (m or rad), and
    ``residual``,
    ``stability`` and the stiffness eigenvalues are those of the closed mechanism (the static
    force along the motions the loops allow, K restricted to them).

    Joint stops (``limits``: whether any were in force, the model's position limits or stops
    set on a scene): ``at_limit`` maps each joint resting on a stop at the end to 'lower' or
    'upper', ``limit_reactions`` to the stop's reaction (>= 0, N m or N: the force it pushes
    with), ``start_clamped`` each joint whose start was outside its stops to how far it was
    moved onto the nearest one (rad or m). ``equal_limits`` names the joints whose lower and
    upper model limits are equal, taken as no stop; ``unapplied_limits`` the joints of several
    configuration entries (planar, spherical, free-flyer, continuous) whose model limits are
    not Pinocchio's placeholders, which no stop applies (solve warns). With stops ``residual``
    is the largest violation of the conditions of a rest against them (|force| off the stops, a
    stop that would have to pull) and the stability verdict is that of K restricted to the
    joints not pressed on a stop.

    Ground contacts (a scene with ``[[ground]]`` and ``[[contact]]``): ``contacts`` lists each
    contact point closed at the end (gap within 1e-6 m) as a ``Contact``, with the forces that
    balance the rest: of all the forces in the friction cones that do, the least in norm (a body
    on more points than it needs, a box on four corners, leaves the share open to a rigid
    model). ``residual`` is what those forces leave unbalanced, and the verdict is that of K
    restricted to the motions the sticking contacts leave free (stable when they hold every
    motion); a stable rest held by a ``marginal`` contact is ``'marginal'``.
    """

    q: np.ndarray
    v: np.ndarray
    status: str
    steps: int
    peaks: int
    pushes: int
    sim_time: float
    wall_time: float
    kinetic_energy: float
    simplified_kinetic_energy: float
    residual: float
    residual_before_polish: float
    polish_iterations: int
    polished: bool
    dt: float
    dt_estimates: int
    dt_reductions: int
    scaled_modes: int
    scaled_joints: int
    reason: str
    mobility: int
    assembly_distance: float
    constraint_error: float
    loops: int
    stability: str
    min_stiffness_eigenvalue: float
    neutral_directions: int
    trace: Trace | None = None
    settings: Settings = field(default_factory=Settings, repr=False)
    joints: dict[str, float | list[float]] = field(default_factory=dict, repr=False)
    limits: bool = False
    at_limit: dict[str, str] = field(default_factory=dict)
    limit_reactions: dict[str, float] = field(default_factory=dict)
    start_clamped: dict[str, float] = field(default_factory=dict)
    equal_limits: tuple[str, ...] = ()
    unapplied_limits: tuple[str, ...] = ()
    #: 'rad' or 'm' for each joint named in at_limit or start_clamped (for the summary).
    units: dict[str, str] = field(default_factory=dict, repr=False)
    contacts: tuple[Contact, ...] = ()

    @property
    def converged(self) -> bool:
        return self.status == "converged"

    @classmethod
    def _of_fields(cls, fields: dict[str, Any]) -> Result:
        """The Result holding ``fields``, every field given (as a solve has them). Set at once:
        the frozen dataclass's ``__init__`` sets its 38 fields one ``object.__setattr__`` at a
        time, 10 us of a 100 us UR5 solve."""
        result = object.__new__(cls)
        object.__setattr__(result, "__dict__", fields)
        return result

    def summary(self, model: Any = None) -> str:
        """A readable report with the final joint values by name. Given ``model``, the model or
        scene solved, the residual and the stiffness are in its joints' units and the stability
        line names the joints its neutral directions move (the stiffness assessed again at
        ``q``, with ``limits=self.limits``); without it the residual reads N m or N."""
        kinds = None if model is None else effort_kinds(model)
        # The stiffness is that of the joints off their stops.
        off_stops = None if model is None else effort_kinds(model, without=self.at_limit)
        lines = [
            f"status           {self.status}",
            self._steps_line(),
            f"wall time        {self.wall_time * 1e3:.3f} ms",
            self._residual_line("N m or N" if kinds is None else effort_unit(kinds)),
            self._time_step_line(),
            f"kinetic energy   {self.kinetic_energy:.3e} J",
            *self._loops_lines(),
            *self._contacts_lines(),
            self._stability_line(off_stops, None if model is None else neutral_joints(model, self)),
            *self._note_lines(),
        ]
        if self.reason:
            lines.append(f"reason           {self.reason}")
        if self.joints:
            lines.append("joints")
            lines += [self._joint_line(name, value) for name, value in self.joints.items()]
        return "\n".join(lines)

    def _stability_line(self, kinds: set[str] | None, moving: tuple[str, ...] | None) -> str:
        """The verdict and what it rests on: the smallest stiffness eigenvalue (0 when within
        the verdict's tolerance, as a neutral verdict's smallest is), the directions free to
        move at no cost and the joints they move (``moving``, when known)."""
        head = f"stability        {self.stability} ("
        if self.stability in ("stable", "marginal") and self.min_stiffness_eigenvalue == 0.0:
            # Stable with a zero eigenvalue: K restricted to no motion at all (a stable
            # verdict's smallest eigenvalue is above a tolerance > 0 otherwise).
            return head + f"held in every motion by {self._holders()})"
        smallest = 0.0 if self.stability == "neutral" else self.min_stiffness_eigenvalue
        unit = "" if kinds is None else stiffness_unit(kinds)
        text = f"smallest stiffness eigenvalue {smallest:.4g}{unit}"
        if self.at_limit:
            text += " on the joints off their stops"
        count = self.neutral_directions
        if count:
            text += ": " if self.stability == "neutral" else "; also "
            text += f"{count} direction{'s' if count > 1 else ''} free to move at no cost"
            if moving:
                text += ", moving " + ", ".join(moving)
        return head + text + ")"

    def _holders(self) -> str:
        """What holds a rest in every motion: its contacts, its stops, or both."""
        if self.contacts and self.at_limit:
            return "its contacts and its stops"
        if self.contacts:
            return "its contacts"
        return "its stops" if self.at_limit else "its constraints"

    def _steps_line(self) -> str:
        pushes = (
            f"{self.pushes} push{'es' if self.pushes > 1 else ''} off an unstable rest, "
            if self.pushes
            else ""
        )
        return (
            f"steps            {self.steps} ({self.peaks} damping events, {pushes}"
            f"{self.sim_time:.4g} s simulated)"
        )

    def _residual_line(self, unit: str) -> str:
        if self.loops:
            along = ", along the motions the loops allow)"
        elif self.limits:
            along = " off the stops, max pull asked of a stop)"
        else:
            along = ")"
        polish = (
            f", {self.residual_before_polish:.3e} before the Newton polish" if self.polished else ""
        )
        return (
            f"residual         {self.residual:.3e} {unit} (max |net static generalized force|"
            f"{along}{polish}"
        )

    def _time_step_line(self) -> str:
        parts = [f"time step        {self.dt:.4g} s"]
        if self.dt_estimates:
            parts.append(f" ({self.dt_estimates} automatic estimates)")
        if self.dt_reductions:
            parts.append(f", halved {self.dt_reductions} times")
        if self.scaled_modes:
            plural = "s" if self.scaled_modes > 1 else ""
            parts.append(f", {self.scaled_modes} stiff mode{plural} slowed")
        if self.scaled_joints:
            plural = "s" if self.scaled_joints > 1 else ""
            parts.append(f", {self.scaled_joints} joint{plural} given a fictitious inertia")
        return "".join(parts)

    def _contacts_lines(self) -> list[str]:
        if not self.contacts:
            return []
        total = sum(c.normal_force for c in self.contacts)
        lines = [
            f"contacts         {len(self.contacts)} closed, normal forces summing to {total:.6g} N"
        ]
        for c in self.contacts:
            state = "sticking" if c.sticking else "at the cone's edge"
            if c.marginal:
                state += ", marginal"
            lines.append(
                f"  {c.name + (f' ({c.body})' if c.body and c.body != c.name else ''):<14} "
                f"on {c.ground}: normal {c.normal_force:.6g} N, tangential "
                f"{float(np.linalg.norm(c.tangential_force)):.4g} N, gap {c.gap:.2e} m, {state}"
            )
        return lines

    def _loops_lines(self) -> list[str]:
        if not self.loops:
            return []
        plural = "s" if self.mobility != 1 else ""
        return [
            f"loops            {self.mobility} degree{plural} of freedom, constraint error "
            f"{self.constraint_error:.1e}, start moved {self.assembly_distance:.3g} to assemble"
        ]

    def _note_lines(self) -> list[str]:
        lines = []
        if self.start_clamped:
            moved = ", ".join(
                f"{name} moved {distance:.4g} {self.units.get(name, 'rad')}"
                for name, distance in self.start_clamped.items()
            )
            lines.append(
                f"start clamped    {moved} onto the nearest stop (the start was outside its limits)"
            )
        if self.equal_limits:
            lines.append(
                "note             "
                + ", ".join(self.equal_limits)
                + ": lower and upper limits equal in the model (a URDF's default when they "
                "are left out), taken as no stop"
            )
        if self.unapplied_limits:
            lines.append(
                "note             "
                + ", ".join(self.unapplied_limits)
                + ": position limits in the model not applied (stops act on revolute, "
                "prismatic and helical joints only)"
            )
        return lines

    def _joint_line(self, name: str, value: float | list[float]) -> str:
        values = value if isinstance(value, list) else [value]
        line = f"  {name:<28} " + " ".join(f"{x: .9f}" for x in values)
        if name in self.at_limit:
            unit = "N" if self.units.get(name) == "m" else "N m"
            line += (
                f"  at {self.at_limit[name]} stop, reaction "
                f"{self.limit_reactions.get(name, 0.0):.3g} {unit}"
            )
        return line

    def to_dict(self) -> dict[str, Any]:
        """The result as plain JSON-ready values (the ``pinsettle solve --json`` object)."""
        return {
            "status": self.status,
            "converged": self.converged,
            "joints": self.joints,
            "q": self.q.tolist(),
            "steps": self.steps,
            "peaks": self.peaks,
            "pushes": self.pushes,
            "sim_time_s": self.sim_time,
            "wall_time_s": self.wall_time,
            "residual": self.residual,
            "residual_before_polish": self.residual_before_polish,
            "polish_iterations": self.polish_iterations,
            "polished": self.polished,
            "reason": self.reason,
            "dt": self.dt,
            "dt_estimates": self.dt_estimates,
            "dt_reductions": self.dt_reductions,
            "scaled_modes": self.scaled_modes,
            "scaled_joints": self.scaled_joints,
            "loops": self.loops,
            "mobility": self.mobility,
            "assembly_distance": self.assembly_distance,
            "constraint_error": self.constraint_error,
            "kinetic_energy": self.kinetic_energy,
            "simplified_kinetic_energy": self.simplified_kinetic_energy,
            "stability": self.stability,
            "min_stiffness_eigenvalue": self.min_stiffness_eigenvalue,
            "neutral_directions": self.neutral_directions,
            "limits": self.limits,
            "at_limit": self.at_limit,
            "limit_reactions": self.limit_reactions,
            "start_clamped": self.start_clamped,
            "equal_limits": list(self.equal_limits),
            "unapplied_limits": list(self.unapplied_limits),
            "contacts": [
                {
                    "name": c.name,
                    "body": c.body,
                    "ground": c.ground,
                    "point": c.point.tolist(),
                    "normal": c.normal.tolist(),
                    "normal_force": c.normal_force,
                    "tangential_force": c.tangential_force.tolist(),
                    "gap": c.gap,
                    "sticking": c.sticking,
                    "marginal": c.marginal,
                }
                for c in self.contacts
            ],
        }


def _check_model(model: Any) -> None:
    if not isinstance(model, pinocchio.Model):
        raise TypeError(f"model must be a pinocchio.Model, got {type(model).__name__}")


def solver_memory(model: pinocchio.Model) -> int:
    """Bytes a Solver of the model needs, before one is built: one ``pinocchio.Data``, of which
    Pinocchio 4.1 keeps four nv x nv x nv tensors of second-order derivatives (32 nv^3 bytes,
    2 GB at nv = 400). A solver, a solve or an evaluation that would not fit in the memory the
    machine has available raises MemoryError saying so, before it allocates."""
    _check_model(model)
    return int(_core.data_memory(model))


def kinetic_energies(model: pinocchio.Model, q: Any, v: Any) -> tuple[float, float]:
    """Both energy measures at the state (q, v): the exact sum 1/2 m|v|^2 + 1/2 w^T I w (J,
    equal to 1/2 v^T M(q) v) and the simplified sum |v|^2 + |w|^2 over the bodies."""
    _check_model(model)
    return _core.kinetic_energies(
        model, as_vector(q, "q", model.nq, "model.nq"), as_vector(v, "v", model.nv, "model.nv")
    )


def static_force(model: pinocchio.Model, q: Any) -> np.ndarray:
    """rnea(q, 0, 0): the net static generalized force under gravity (dim model.nv, N m or N).
    For a scene, ``scene.static_force(q)`` includes its springs and loads. A model with mimic
    joints: each follower's effort counts on its leader (times the multiplier), as Pinocchio's
    own rnea on such a model."""
    _check_model(model)
    if has_mimic_joints(model):
        scene = Scene(model)
        q_full = scene.from_mimic_q(as_vector(q, "q", model.nq, "model.nq"))
        return scene.to_mimic_force(_core.static_force(scene.model, q_full))
    return _core.static_force(model, as_vector(q, "q", model.nq, "model.nq"))


def static_residual(model: Any, q: Any) -> float:
    """max |net static generalized force| (N m or N) of a model under gravity, or a scene's
    ``residual(q)`` (with joint stops, the residual of a rest against them)."""
    if isinstance(model, Scene):
        return model.residual(q)
    force = static_force(model, q)
    return float(np.max(np.abs(force)))


@dataclass(frozen=True)
class StabilityReport:
    """The stiffness matrix K = d tau_static / dq at a configuration and its verdict.

    ``verdict``: 'stable' (every eigenvalue of the symmetric part of K positive beyond
    ``tolerance``), 'neutral' (none negative, ``neutral_directions`` zero) or 'unstable' (one
    negative). ``eigenvalues`` in increasing order (N m/rad or N/m), ``softest_direction`` the
    unit eigenvector of the smallest (a joint-velocity direction, dim nv). ``basis`` (nv x dim
    K) gives the joint velocities K's coordinates stand for: the identity for a tree; for a
    scene with loops, an orthonormal basis of the motions the loops allow, K being restricted
    to them (including the curvature of the loops under their reactions); with joint stops, the
    joints not pressed on a stop (a selection of columns of the identity), K restricted to them.
    With stops, ``stop_contacts`` lists the joints resting on a stop at q as (joint, 'lower' or
    'upper', reaction >= 0 in N m or N) and ``stop_residual`` is the residual of a rest against
    them (as ``Result.residual``); without stops, empty and None.
    """

    verdict: str
    min_eigenvalue: float
    neutral_directions: int
    tolerance: float
    eigenvalues: np.ndarray
    softest_direction: np.ndarray
    stiffness_matrix: np.ndarray
    basis: np.ndarray
    stop_contacts: list[tuple[str, str, float]] = field(default_factory=list)
    stop_residual: float | None = None


def _limits_flag(limits: Any, default: bool) -> bool:
    return default if limits is None else as_flag(limits, "limits")


def assess_stability(model: Any, q: Any, *, limits: bool | None = None) -> StabilityReport:
    """Stability of a rest at ``q`` of a ``pinocchio.Model`` under gravity or of a ``Scene``
    (all its elements; K on the free joints). Gravity's part of K comes from Pinocchio's
    analytic derivatives, the elements' part from central finite differences. With joint stops
    (``limits`` as for ``solve``: None honours a bare model's position limits and a scene's own
    setting) K is restricted to the joints not pressed on a stop at q. A model with mimic joints
    is assessed as the coupled mechanism: K on an orthonormal basis of the motions the couplings
    allow, each follower counted as a joint of its own (``Scene(model).model``); ``basis`` and
    ``softest_direction`` in the model's own coordinates (the followers' rows left out)."""
    if isinstance(model, Scene):
        q = as_vector(q, "q", model.model.nq, "model.nq")
        compiled = model.compile(q)
        stops = compiled.stops_for(_limits_flag(limits, model.limits))
        raw = _core.stiffness(
            compiled.model, q[compiled.q_index], compiled.elements, compiled.loops, stops
        )
    else:
        _check_model(model)
        if has_mimic_joints(model):  # the coupled mechanism, reported in the model's coordinates
            scene = Scene(model)
            q_full = scene.from_mimic_q(as_vector(q, "q", model.nq, "model.nq"))
            report = assess_stability(scene, q_full, limits=limits)
            return dataclasses.replace(
                report,
                softest_direction=scene.to_mimic_v(report.softest_direction),
                basis=scene.to_mimic_v(report.basis),
            )
        stops = (True, []) if _limits_flag(limits, True) else None
        raw = _core.stiffness(model, as_vector(q, "q", model.nq, "model.nq"), None, None, stops)
    return StabilityReport(**raw)


def effort_kinds(model: Any, without: Collection[str] = ()) -> set[str]:
    """The units of the generalized forces of a model's joints, or of a scene's free joints
    (its locked joints left out), less the joints named in ``without``: 'N m' along a
    velocity that turns a body (revolute, helical, spherical, a free-flyer's angular part),
    'N' along one that only moves it along a line (prismatic, a free-flyer's linear part),
    read off each joint's motion subspace."""
    locked = set(without)
    if isinstance(model, Scene):
        locked.update(model.locked)
        model = model.model
    _check_model(model)
    q = pinocchio.neutral(model)
    kinds: set[str] = set()
    for j, (joint, name) in enumerate(zip(model.joints, model.names, strict=True)):
        if j == 0 or model.nvs[j] == 0 or name in locked:  # the universe, a mimic follower
            continue
        data = joint.createData()
        joint.calc(data, q)
        subspace = np.asarray(data.S).reshape(6, -1)
        kinds.update("N m" if np.any(column[3:] != 0.0) else "N" for column in subspace.T)
    return kinds


def effort_unit(kinds: set[str]) -> str:
    """The unit of a residual over joints of these ``effort_kinds``: 'N m', 'N' or, mixed,
    'N m or N'."""
    return " or ".join(unit for unit in ("N m", "N") if unit in kinds) or "N m or N"


def stiffness_unit(kinds: set[str]) -> str:
    """' N m/rad' or ' N/m', the unit of a stiffness eigenvalue over joints of one kind; ''
    over both (an eigenvector then mixes turns and moves: no one unit)."""
    if kinds == {"N m"}:
        return " N m/rad"
    return " N/m" if kinds == {"N"} else ""


#: A joint is named as moved by the neutral directions when its velocity carries at least
#: this share of them (the diagonal of the projector onto them, summed over its velocities:
#: 1 for a joint a neutral direction moves alone).
NEUTRAL_SHARE = 0.01


def neutral_joints(model: Any, result: Result) -> tuple[str, ...]:
    """The joints that the neutral directions of ``result``'s rest move, in the model's order,
    from the stiffness assessed again at ``result.q`` (``assess_stability``, with
    ``limits=result.limits``). () without neutral directions, with contacts (the solver's
    verdict restricts K to the motions they leave free; ``assess_stability`` leaves them out),
    when the assessment does not find the solver's verdict, or has no memory for it."""
    if not result.neutral_directions or result.contacts:
        return ()
    try:
        report = assess_stability(model, result.q, limits=result.limits)
    except MemoryError:
        return ()
    if (report.verdict, report.neutral_directions) != (
        result.stability,
        result.neutral_directions,
    ):
        return ()
    stiffness = report.stiffness_matrix
    values, vectors = np.linalg.eigh(0.5 * (stiffness + stiffness.T))
    free = report.basis @ vectors[:, np.abs(values) <= report.tolerance]
    # An orthonormal basis of the neutral motions in joint velocities: the share of each
    # velocity is then the same whichever eigenvectors eigh picked among equal eigenvalues.
    share = np.sum(np.linalg.qr(free)[0] ** 2, axis=1)
    naming = model.compile(result.q).model if isinstance(model, Scene) else model
    moved = []
    for j in range(1, naming.njoints):
        start, size = naming.idx_vs[j], naming.nvs[j]
        if size and share[start : start + size].sum() >= NEUTRAL_SHARE:
            moved.append(str(naming.names[j]))
    return tuple(moved)

"""``Solver``: a mechanism made ready for the core once (its model checked, its scene compiled,
its stops and forces handed over, the core's workspace allocated), then solved from as many
starts as wanted. ``pinsettle.solve`` is one ``Solver`` used once."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio

from . import _core
from ._checks import as_vector
from ._scene import Scene, _body_frame, has_mimic_joints
from ._scene_values import JointReader
from ._settings import Settings, make_settings
from ._solve import Contact, Progress, Result, Trace, _limits_flag, _progress_reporter


@dataclass
class _Mechanism:
    """What one core solver was built from: the compiled scene (the model it solves, locked
    joints removed; None for a user's model, solved as it is), the limit notes, and the core
    solver."""

    core: Any  # _core.Solver
    compiled: Any  # the scene's _Compiled, or None
    equal: tuple[str, ...]
    unapplied: tuple[str, ...]
    #: The body of each contact point (_contact_bodies), found once for all its solves.
    bodies: dict[str, str] = field(default_factory=dict)


class Solver:
    """A kinetic-damping solver for one mechanism, reusable across solves.

    ``Solver(model, settings=None, *, limits=None, **overrides)`` does once what every solve
    of the mechanism shares: the model checked, a scene compiled (locked joints removed, force
    elements, loops and stops resolved), the settings checked, and the core's Pinocchio data
    and workspace allocated. ``solve(q0=None, *, v0=None, callback=None, progress=None)``
    then settles it from a start (arguments as ``pinsettle.solve``'s) and returns a
    ``Result``. A scene is read when the solver is made: change the scene, make a new solver.
    A start whose locked joints differ from the scene's start rebuilds the reduced model for
    that solve (the locked values are part of it).

    One solver runs one solve at a time (it owns its workspace): give each thread its own.
    """

    def __init__(
        self,
        model: Any,
        settings: Settings | Mapping[str, Any] | None = None,
        *,
        limits: bool | None = None,
        **overrides: Any,
    ) -> None:
        self._setup(model, settings, limits, overrides)
        if self._mechanism.unapplied:
            _warn_unapplied(self._mechanism.unapplied, stacklevel=3)  # the caller of Solver()

    def _setup(
        self,
        model: Any,
        settings: Settings | Mapping[str, Any] | None,
        limits: bool | None,
        overrides: dict[str, Any],
    ) -> None:
        self._mimic: pinocchio.Model | None = None
        if isinstance(model, pinocchio.Model) and has_mimic_joints(model):
            # Each follower coupled to its leader (a constraint, as loops are), solved as a
            # scene; starts and answers in the model's own coordinates.
            self._mimic, model = model, Scene(model)
        if isinstance(model, Scene):
            self._scene: Scene | None = model
            self._naming = model.model
            default = model.settings
            self._limits = _limits_flag(limits, model.limits)
        elif isinstance(model, pinocchio.Model):
            if model.nv == 0:
                raise ValueError("model has no degree of freedom: nothing to settle")
            self._scene, self._naming, default = None, model, None
            self._limits = _limits_flag(limits, True)
        else:
            raise TypeError(
                f"model must be a pinocchio.Model or a pinsettle.Scene, got {type(model).__name__}"
            )
        self._settings = make_settings(default if settings is None else settings, overrides)
        self._settings.check()
        self._reader = JointReader(self._naming)
        self._zero_v = np.zeros(self._naming.nv)
        if self._scene is None:
            self._q0 = pinocchio.neutral(self._naming)
            self._mechanism = _model_mechanism(self._naming, self._limits, self._reader)
        else:
            self._q0 = self._scene.q0()
            self._mechanism = _scene_mechanism(self._scene, self._scene.compile(), self._limits)

    @property
    def settings(self) -> Settings:
        """The settings every solve of this solver uses (a copy)."""
        return self._settings.replace()

    @property
    def model(self) -> Any:
        """The model or scene this solver was made for."""
        if self._mimic is not None:
            return self._mimic
        return self._naming if self._scene is None else self._scene

    def solve(
        self,
        q0: Any = None,
        *,
        v0: Any = None,
        callback: Callable[[], bool] | None = None,
        progress: Callable[[Progress], object] | None = None,
    ) -> Result:
        """Settle the mechanism from rest at ``q0`` (or from (``q0``, ``v0``)); see
        ``pinsettle.solve`` for the arguments and the ``Result``."""
        if callback is not None and not callable(callback):
            raise TypeError(f"callback must be callable or None, got {type(callback).__name__}")
        report = _progress_reporter(progress)
        if self._mimic is not None:
            return self._solve_mimic(self._mimic, q0, v0, callback, report)
        if self._scene is None:
            return self._solve_model(q0, v0, callback, report)
        return self._solve_scene(self._scene, q0, v0, callback, report)

    def _solve_model(
        self,
        q0: Any,
        v0: Any,
        callback: Callable[[], bool] | None,
        report: Callable[[Mapping[str, Any]], None] | None,
    ) -> Result:
        """A pinocchio.Model solved as it is."""
        model = self._naming
        q = self._q0 if q0 is None else as_vector(q0, "q0", model.nq, "model.nq")
        v = self._zero_v if v0 is None else as_vector(v0, "v0", model.nv, "model.nv")
        core = self._mechanism.core  # the Result gets settings of its own, as below
        return self._result(core.solve(q, v, self._settings._copy(), callback, report))

    def _solve_scene(
        self,
        scene: Scene,
        q0: Any,
        v0: Any,
        callback: Callable[[], bool] | None,
        report: Callable[[Mapping[str, Any]], None] | None,
    ) -> Result:
        """A scene solved on its compiled model, the answer back in the scene's full model."""
        full = scene.model
        q_full = self._q0 if q0 is None else as_vector(q0, "q0", full.nq, "model.nq")
        v_full = self._zero_v if v0 is None else as_vector(v0, "v0", full.nv, "model.nv")
        mechanism = self._mechanism_at(scene, q_full)
        compiled = mechanism.compiled
        if v0 is not None and np.any(np.delete(v_full, compiled.v_index) != 0.0):
            raise ValueError("v0 must be zero on the locked joints " + ", ".join(scene.locked))
        raw = mechanism.core.solve(
            q_full[compiled.q_index],
            v_full[compiled.v_index],
            self._settings._copy(),  # the Result's own: changing it changes no other solve
            callback,
            report,
        )
        raw["q"] = compiled.full_q(raw["q"])
        raw["v"] = compiled.full_v(raw["v"], full.nv)
        raw["joints"] = self._reader.values(raw["q"])  # of the full model
        raw["equal_limits"] = mechanism.equal  # less the joints the scene sets stops on
        bodies = mechanism.bodies
        raw["contacts"] = [(*c, bodies.get(c[0], "")) for c in raw["contacts"] or ()]
        trace = raw["trace"]
        if trace is not None:
            if trace["q"] is not None:
                trace["q"] = np.array([compiled.full_q(row) for row in trace["q"]])
            trace["event_joint"] = _full_joints(compiled.model, full, trace["event_joint"])
        return self._result(raw)

    def _mechanism_at(self, scene: Scene, q_full: np.ndarray) -> _Mechanism:
        """The mechanism for a start: the solver's own, unless the start's locked joints are
        elsewhere (the reduced model holds them where they are)."""
        if not scene.locked:
            return self._mechanism
        reference = self._mechanism.compiled
        locked = np.setdiff1d(np.arange(scene.model.nq), reference.q_index)
        if np.array_equal(q_full[locked], reference.q_ref[locked]):
            return self._mechanism
        return _scene_mechanism(scene, scene.compile(q_full), self._limits)

    def _solve_mimic(
        self,
        model: pinocchio.Model,
        q0: Any,
        v0: Any,
        callback: Callable[[], bool] | None,
        report: Callable[[Mapping[str, Any]], None] | None,
    ) -> Result:
        """The model's mimic joints held as couplings: the start and the answer converted
        between the model's coordinates and the scene's."""
        import dataclasses

        scene = self._scene
        assert scene is not None  # made of the model
        if q0 is not None:
            q0 = scene.from_mimic_q(as_vector(q0, "q0", model.nq, "model.nq"))
        if v0 is not None:
            v0 = scene.from_mimic_v(as_vector(v0, "v0", model.nv, "model.nv"))
        result = self._solve_scene(scene, q0, v0, callback, report)
        trace = result.trace
        if trace is not None and trace.q is not None:
            trace = dataclasses.replace(trace, q=scene.to_mimic_q(trace.q))
        return dataclasses.replace(
            result, q=scene.to_mimic_q(result.q), v=scene.to_mimic_v(result.v), trace=trace
        )

    @staticmethod
    def _result(raw: dict[str, Any]) -> Result:
        """The Result of the core's fields (every one given, the joints by name too)."""
        trace = raw["trace"]
        if trace is not None:
            trace["event_kind"] = tuple(trace["event_kind"])
            raw["trace"] = Trace(**trace)
        if raw["contacts"]:
            raw["contacts"] = tuple(Contact(*c) for c in raw["contacts"])
        else:
            raw["contacts"] = ()
        return Result._of_fields(raw)


def solve(
    model: Any,
    q0: Any = None,
    settings: Settings | Mapping[str, Any] | None = None,
    *,
    v0: Any = None,
    callback: Callable[[], bool] | None = None,
    limits: bool | None = None,
    progress: Callable[[Progress], object] | None = None,
    **overrides: Any,
) -> Result:
    """Settle a mechanism by kinetic damping and return where it comes to rest (a ``Solver``
    made and used once: to solve one mechanism from many starts, keep a ``Solver``).

    Args:
        model: a ``pinocchio.Model`` (from the ``pin`` package) or a ``pinsettle.Scene``.
        q0: start configuration (dim model.nq, the full model for a scene); the neutral
            configuration (a scene's start) when None.
        settings: a ``Settings`` (or a dict of fields); never modified. For a scene, its
            ``[solver]`` settings when None.
        v0: start joint velocity (dim model.nv); zero when None.
        callback: called every ``check_every`` steps without arguments; returning True stops the
            run with status 'aborted'. Ctrl-C does the same.
        limits: whether the model's position limits are joint stops. None: yes for a
            ``pinocchio.Model``, the scene's own setting (``Scene.limits``, ``[model] limits``)
            for a scene; True or False overrides it. Stops set on a scene (``set_limit``,
            ``[[limit]]``) apply either way.
        progress: called every ``check_every`` steps with a ``Progress`` (steps, simulated
            time, kinetic energy, damping events, residual, wall time); its return value is
            ignored, an exception from it ends the run and is raised here. None (the default)
            costs nothing.
        **overrides: any ``Settings`` field, e.g. ``kt=0.3``.

    Raises:
        TypeError: ``model`` is neither a ``pinocchio.Model`` nor a ``Scene``; an unknown
            setting or a value of the wrong type.
        ValueError: a setting out of range, or a ``q0``/``v0`` of the wrong size, with a
            non-finite entry or a non-normalised quaternion; the message names it. A
            ``SceneError`` (a ValueError) for joint stops on a scene with loops (not supported
            yet).
    """
    if callback is not None and not callable(callback):
        raise TypeError(f"callback must be callable or None, got {type(callback).__name__}")
    solver = Solver.__new__(Solver)
    solver._setup(model, settings, limits, overrides)
    if solver._mechanism.unapplied:
        _warn_unapplied(solver._mechanism.unapplied, stacklevel=2)  # the caller of solve
    return solver.solve(q0, v0=v0, callback=callback, progress=progress)


def _model_mechanism(model: pinocchio.Model, limits: bool, reader: JointReader) -> _Mechanism:
    """A pinocchio.Model solved as it is, its position limits as stops unless limits=False;
    the core names the joints' values."""
    core = _core.Solver(model, None, None, (True, []) if limits else None, reader.fields())
    equal = tuple(str(name) for name in core.equal_limits)
    unapplied = tuple(str(name) for name in core.unapplied_limits)
    return _Mechanism(core, None, equal, unapplied)


def _scene_mechanism(scene: Scene, compiled: Any, limits: bool) -> _Mechanism:
    """A scene's compiled model with its elements, loops and stops (the limit notes as the
    core found them, less the joints the scene sets stops on)."""
    stops = compiled.stops_for(limits)
    core = _core.Solver(
        compiled.model, compiled.elements, compiled.loops, stops, contacts=compiled.contacts
    )
    equal = tuple(compiled.unset_equal_limits(core.equal_limits))
    unapplied = tuple(str(name) for name in core.unapplied_limits)
    return _Mechanism(core, compiled, equal, unapplied, _contact_bodies(scene))


def _warn_unapplied(unapplied: tuple[str, ...], stacklevel: int) -> None:
    """The model's limits that no stop applies (joints of several configuration entries)."""
    warnings.warn(
        "position limits of "
        + ", ".join(repr(name) for name in unapplied)
        + " are not applied: stops act on joints of one configuration entry (revolute, "
        "prismatic, helical), not on planar, spherical, free-flyer or continuous joints; "
        "pass limits=False to solve without the model's limits",
        UserWarning,
        stacklevel=stacklevel + 1,
    )


def _contact_bodies(scene: Scene) -> dict[str, str]:
    """The body (link: the BODY frame the point's frame hangs from) of each contact point."""
    model = scene.model
    bodies = {}
    for contact in scene.contacts:
        if not model.existFrame(contact.frame):
            continue
        f = _body_frame(model, contact.frame)  # a body's first: a joint may share its name
        while model.frames[f].type != pinocchio.FrameType.BODY and model.frames[f].parentFrame != f:
            f = model.frames[f].parentFrame
        bodies[contact.name] = model.frames[f].name
    return bodies


def _full_joints(reduced: pinocchio.Model, full: pinocchio.Model, joints: Any) -> np.ndarray:
    """Joint indices of the reduced model (locked joints removed) as indices of the full
    model, by name; -1 stays -1."""
    indices: np.ndarray = np.asarray(joints, dtype=np.int64)
    if reduced is full:
        return indices
    ids = [full.getJointId(name) for name in reduced.names]
    return np.array([ids[j] if j >= 0 else -1 for j in indices], dtype=np.int64)

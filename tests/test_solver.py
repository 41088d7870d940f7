"""pinsettle.Solver: a solver made once and reused gives the answers of pinsettle.solve, run
after run, whatever came before; the core names the joints' values as the Python layer does."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pinocchio
import pinsettle
import pytest
from pinsettle._scene_values import joint_values

ROBOTS = pinsettle.scenes_dir()


def _same(a: pinsettle.Result, b: pinsettle.Result) -> None:
    """Every field equal (arrays to the bit), the wall time aside."""
    for f in dataclasses.fields(pinsettle.Result):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if f.name == "wall_time":
            continue
        if isinstance(x, np.ndarray):
            assert np.array_equal(x, y), f.name
        elif isinstance(x, float) and math.isnan(x):
            assert math.isnan(y), f.name
        else:
            assert x == y, f.name


def _mimic_panda() -> pinocchio.Model:
    return pinocchio.buildModelFromUrdf(pinsettle.robot_urdf("panda"), mimic=True)


MECHANISMS = {
    "ur5": lambda: pinsettle.load_robot("ur5"),
    "panda_mimic": _mimic_panda,
    "fourbar_stop": lambda: pinsettle.load_scene(ROBOTS / "fourbar_stop.toml"),
    "panda_fingers_locked": lambda: pinsettle.load_scene(ROBOTS / "panda_fingers_locked.toml"),
    "double_pendulum_springs": lambda: pinsettle.load_scene(
        ROBOTS / "double_pendulum_springs.toml"
    ),
    "slider_spring": lambda: pinsettle.load_scene(ROBOTS / "slider_spring.toml"),
}


def _starts(mechanism) -> list[np.ndarray | None]:
    """The mechanism's own start, and one moved 0.05 along every joint (a scene's locked
    joints too: they are held there)."""
    model = mechanism.model if isinstance(mechanism, pinsettle.Scene) else mechanism
    start = mechanism.q0() if isinstance(mechanism, pinsettle.Scene) else pinocchio.neutral(model)
    return [None, pinocchio.integrate(model, start, np.full(model.nv, 0.05))]


@pytest.mark.parametrize("name", MECHANISMS)
def test_a_kept_solver_answers_as_solve_does(name):
    mechanism = MECHANISMS[name]()
    solver = pinsettle.Solver(mechanism, max_steps=20_000)
    for start in _starts(mechanism) * 2:  # twice over: nothing of a run stays in the next
        kept = solver.solve(start)
        fresh = pinsettle.solve(mechanism, start, max_steps=20_000)
        _same(kept, fresh)
        assert kept.settings == solver.settings


def test_a_run_does_not_change_the_next():
    model = pinsettle.load_robot("ur5")
    solver = pinsettle.Solver(model)
    q1 = pinocchio.neutral(model)
    q2 = pinocchio.integrate(model, q1, np.linspace(-1.0, 1.0, model.nv))
    first = solver.solve(q1)
    solver.solve(q2, v0=np.ones(model.nv))
    solver.solve(q2, callback=lambda: True)  # aborted at its first poll
    _same(first, solver.solve(q1))


def test_each_result_has_settings_of_its_own():
    # A kept solver's results do not share its settings: changing one result's changes neither
    # the solver's nor another result's.
    for mechanism in (pinsettle.load_robot("ur5"), MECHANISMS["fourbar_stop"]()):
        solver = pinsettle.Solver(mechanism, kt=0.3)
        first, second = solver.solve(), solver.solve()
        assert first.settings is not second.settings and first.settings == solver.settings
        first.settings.kt = 0.9
        assert solver.settings.kt == 0.3 and second.settings.kt == 0.3
        assert solver.solve().settings.kt == 0.3


def _all_kinds() -> pinocchio.Model:
    """A tree of every joint layout the names give: free-flyer, spherical, continuous,
    revolute, prismatic, planar."""
    model = pinocchio.Model()
    inertia = pinocchio.Inertia(1.0, np.array([0.0, 0.0, -0.1]), np.eye(3) * 0.01)
    parent = 0
    for name, joint in [
        ("free", pinocchio.JointModelFreeFlyer()),
        ("ball", pinocchio.JointModelSpherical()),
        ("wheel", pinocchio.JointModelRUBZ()),
        ("hinge", pinocchio.JointModelRY()),
        ("slide", pinocchio.JointModelPZ()),
        ("plane", pinocchio.JointModelPlanar()),
    ]:
        parent = model.addJoint(parent, joint, pinocchio.SE3.Identity(), name)
        model.appendBodyToJoint(parent, inertia, pinocchio.SE3.Identity())
    return model


def test_the_core_names_joints_as_the_python_layer_does():
    # The core reads each joint's value from q by the layout the Python layer gives it
    # (quaternions w first, a continuous joint's angle); joint_values is the Python reading.
    model = _all_kinds()
    rng = np.random.default_rng(7)
    q0 = pinocchio.randomConfiguration(
        model, -np.ones(model.nq), np.ones(model.nq)
    )  # unit quaternions and (cos, sin) pairs
    solver = pinsettle.Solver(model, max_steps=50, limits=False)
    for v0 in (np.zeros(model.nv), rng.normal(size=model.nv)):
        result = solver.solve(q0, v0=v0)
        expected = joint_values(model, result.q)
        assert list(result.joints) == list(expected)
        for name, value in expected.items():
            assert np.array_equal(np.atleast_1d(result.joints[name]), np.atleast_1d(value)), name
    w, x, y, z = result.joints["ball"]  # w first, as Scene.set_start takes it
    assert [x, y, z, w] == result.q[7:11].tolist()


def test_stops_are_named_with_their_units():
    scene = pinsettle.load_scene(ROBOTS / "slider_spring.toml")
    model = scene.model
    names = [model.names[j] for j in range(1, model.njoints)]
    kinds = {model.names[j]: model.joints[j].shortname() for j in range(1, model.njoints)}
    solver = pinsettle.Solver(scene)
    # A start past every stop: each joint is moved onto one, and named in start_clamped.
    past = np.array(model.upperPositionLimit) + 0.1
    result = solver.solve(np.where(np.isfinite(past), past, 0.0))
    named = set(result.at_limit) | set(result.start_clamped)
    assert named and named <= set(names)
    for name in named:
        prismatic = "Prismatic" in kinds[name] or kinds[name] in (
            "JointModelPX",
            "JointModelPY",
            "JointModelPZ",
        )
        assert result.units[name] == ("m" if prismatic else "rad"), name
    for name, side in result.at_limit.items():
        assert side in ("lower", "upper") and result.limit_reactions[name] >= 0


@pytest.mark.parametrize(
    "make, error, text",
    [
        (lambda m: pinsettle.Solver("ur5"), TypeError, "model must be a pinocchio.Model or"),
        (lambda m: pinsettle.Solver(m, kt=1.5), ValueError, "kt"),
        (lambda m: pinsettle.Solver(m, limits="yes"), TypeError, "limits must be True or False"),
        (lambda m: pinsettle.Solver(m).solve(np.zeros(3)), ValueError, "q0 must have shape (6,)"),
        (lambda m: pinsettle.Solver(m).solve(v0=[math.nan] * 6), ValueError, "v0[0] is nan"),
        (lambda m: pinsettle.Solver(m).solve(callback=1), TypeError, "callback must be callable"),
    ],
)
def test_bad_input_is_named(make, error, text):
    with pytest.raises(error) as caught:
        make(pinsettle.load_robot("ur5"))
    assert text in str(caught.value)

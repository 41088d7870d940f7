"""Settings.newton_takeover (on by default, with the polish): at a damping event the polish's
Newton is tried from where the mechanism stands, and a rest it reaches at round-off, within the
polish's reach and of the same kind, ends the run. Checked against the independent physics of
tests/scene_reference.py: the rest is an equilibrium (against the stops: the KKT conditions),
its verdict is that of the stiffness differenced there (tests/verdict_reference.py: on the
joints off their stops and the motions the loops allow, classified with the solver's rule),
for the takeover's rest and the damping's alike, and a strict minimum is the same rest the
damping alone comes to."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest
from scene_reference import Reference
from verdict_reference import describe, scene_verdict

ROBOTS = Path(__file__).parents[1] / "robots"

# Scenes that come to a rest: trees, closed loops, and with their own joint stops.
RESTING = [
    ("pendulum", False),
    ("bistable_pendulum", False),
    ("double_pendulum_springs", False),
    ("planar_3link_spring", False),
    ("slider_spring", False),
    ("ur5", False),
    ("ur5_tool_spring", False),
    ("ur5_saddle", False),
    ("chain20", False),
    ("fourbar", None),
    ("slider_crank", None),
    ("parallel_gripper", None),
    ("fourbar_stop", None),
    ("panda", None),
    ("panda_fingers_locked", None),
    ("xarm7", None),
]


def force_scale(scene: pinsettle.Scene, ref: Reference) -> float:
    """The largest pull at the start and at a few random configurations (the saddle scene
    starts on an equilibrium)."""
    rng = np.random.default_rng(3)
    starts = [scene.q0()] + [ref.random_configuration(rng) for _ in range(4)]
    return max(ref.residual(q) for q in starts)


@pytest.mark.parametrize("name, limits", RESTING, ids=[n for n, _ in RESTING])
def test_a_rest_newton_takes_over_is_an_equilibrium_of_the_same_kind(name, limits):
    path = ROBOTS / f"{name}.toml"
    scene = pinsettle.load_scene(path)
    ref = Reference.from_toml(path)
    if limits is not None:
        ref.limits = limits  # the solve's override of the scene's own setting
    damped = pinsettle.solve(scene, limits=limits, newton_takeover=False)
    taken = pinsettle.solve(scene, limits=limits, newton_takeover=True)
    assert damped.status == taken.status == "converged"
    tol = 1e-10 * force_scale(scene, ref)
    model = ref.reduced(taken.q)
    q = ref.to_reduced(model, taken.q)
    force = ref.force_reduced(model, q)
    if ref.loops:  # closed, and no force along the motions the loops allow (off the stops)
        error, jacobian = ref.loop_jacobian(ref.full, taken.q)
        assert np.max(np.abs(error)) < 1e-10
        _, sigma, vt = np.linalg.svd(jacobian)
        allowed = vt[int(np.sum(sigma > 1e-9 * sigma[0])) :].T
        if not taken.at_limit:
            assert np.max(np.abs(allowed.T @ ref.force(taken.q))) <= tol
        assert taken.at_limit == damped.at_limit
    elif taken.limits:  # KKT: inside, no force on a free joint, a push into each stop it rests on
        violation, contacts, inside = ref.rest_conditions(model, q, force)
        assert inside and float(np.max(violation, initial=0.0)) <= tol, violation
        assert taken.at_limit == {n: side for n, (side, _) in contacts.items()}
        assert all(reaction >= 0.0 for _, reaction in contacts.values())
        assert taken.at_limit == damped.at_limit
    else:
        assert ref.residual(taken.q) <= tol, (ref.residual(taken.q), tol)
    # Each run's verdict and smallest eigenvalue are the reference's at its own rest.
    for result in (taken, damped):
        verdict = scene_verdict(ref, result.q)
        assert verdict.decided, describe(verdict)
        verdict.check(result.stability, result.min_stiffness_eigenvalue)
    assert str(taken.stability) == str(damped.stability)
    assert taken.residual <= taken.residual_before_polish
    if taken.stability == "stable":  # a strict minimum: the damping's own rest
        assert np.abs(pinocchio.difference(scene.model, damped.q, taken.q)).max() < 1e-8
    assert taken.steps <= damped.steps


def test_newton_takes_over_long_before_the_damping_alone_stops():
    # Measured: 66 steps with the damping alone, 22 with the takeover.
    scene = pinsettle.load_scene("double_pendulum_springs")
    damped = pinsettle.solve(scene, newton_takeover=False)
    taken = pinsettle.solve(scene)  # the default
    assert taken.settings.newton_takeover
    assert taken.steps < 0.5 * damped.steps, (taken.steps, damped.steps)
    assert taken.polished and taken.polish_iterations >= 1
    assert taken.residual_before_polish > taken.residual


def test_without_the_polish_the_run_is_the_damping_s_own():
    scene = pinsettle.load_scene("double_pendulum_springs")
    plain = pinsettle.solve(scene, polish=False, newton_takeover=True)
    damped = pinsettle.solve(scene, polish=False, newton_takeover=False)
    assert plain.steps == damped.steps and np.array_equal(plain.q, damped.q)
    assert not plain.polished


@pytest.mark.parametrize("name", ["free_fall", "torque_disk", "overloaded_pendulum"])
def test_no_equilibrium_stays_no_equilibrium(name):
    taken = pinsettle.solve(pinsettle.load_scene(name), max_steps=200_000, newton_takeover=True)
    assert taken.status == "no_equilibrium"


def test_a_start_at_an_unstable_rest_is_pushed_off_not_taken():
    # The upright pendulum starts at rest on its unstable equilibrium: Newton there would stay
    # (zero residual); the rest check pushes it off and the run ends hanging down, stable.
    taken = pinsettle.solve(pinsettle.load_scene("pendulum_upright"), newton_takeover=True)
    assert taken.status == "converged" and taken.stability == "stable"
    assert taken.pushes >= 1


def test_a_rest_held_by_a_stop_and_the_loops_is_taken_where_they_hold_it():
    # The four-bar's one degree of freedom held by the rocker's stop: Newton's step clamps it
    # onto the stop, where nothing is left to move; that is a rest at round-off (its closed
    # form and the stop's reaction are checked in tests/test_limits.py on the default run).
    scene = pinsettle.load_scene("fourbar_stop")
    damped = pinsettle.solve(scene, newton_takeover=False)
    taken = pinsettle.solve(scene)
    assert taken.converged and taken.steps < damped.steps, (taken.steps, damped.steps)
    # Held on its stop, to the bit, since the loops' projection keeps pinned joints exactly:
    # the rest is at round-off where the takeover finds it (no Newton iteration left to take).
    assert taken.residual <= 1e-12 and damped.residual <= 1e-12
    assert taken.at_limit == damped.at_limit == {"rocker_joint": "upper"}
    assert np.abs(taken.q - damped.q).max() < 1e-12
    assert taken.limit_reactions["rocker_joint"] == pytest.approx(
        damped.limit_reactions["rocker_joint"], rel=1e-9
    )
    assert taken.stability == damped.stability == "stable"

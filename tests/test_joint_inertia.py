"""Fictitious joint inertia (``Settings.scale_joint_inertia``): dynamic relaxation's masses,
kept diagonal, that bring every joint's rate down towards the slowest one's.

The equilibria and their stability do not depend on the masses, so every answer is checked
against the same conditions as without: the static force recomputed with
``pinocchio.computeGeneralizedGravity`` at the result, the rest a default solve finds, and the
stiffness eigenvalues for the verdict. What changes is the path, measured in steps (a count,
not a time).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest

ROBOTS = Path(__file__).parents[1] / "robots"
sys.path.insert(0, str(ROBOTS))
from make_chain import chain_urdf  # noqa: E402


def gravity(model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
    return pinocchio.computeGeneralizedGravity(model, model.createData(), q).copy()


def smallest_stiffness_eigenvalue(model: pinocchio.Model, q: np.ndarray) -> float:
    K = pinocchio.computeGeneralizedGravityDerivatives(model, model.createData(), q)
    return float(np.linalg.eigvalsh(0.5 * (K + K.T)).min())


@pytest.mark.parametrize("n", [20, 50])
@pytest.mark.parametrize("start", ["horizontal", "curled"])
def test_chain_comes_to_the_same_rest_in_far_fewer_steps(n, start):
    model = pinocchio.buildModelFromXML(chain_urdf(n))  # limits +-pi: the stops are in force
    armature = model.armature.copy()
    q0 = np.zeros(model.nq)
    q0[0] = np.pi / 2
    if start == "curled":
        q0[1:] = 0.05
    plain = pinsettle.solve(model, q0, scale_joint_inertia=False)
    scaled = pinsettle.solve(model, q0, scale_joint_inertia=True)
    assert plain.converged and scaled.converged, scaled.summary()
    assert plain.scaled_joints == 0 and scaled.scaled_joints >= n // 2
    np.testing.assert_array_equal(model.armature, armature)  # the user's model is untouched
    # Straight down, as the default run finds, checked outside the solver.
    assert np.max(np.abs(scaled.q)) < 1e-9
    assert np.max(np.abs(pinocchio.difference(model, plain.q, scaled.q))) < 1e-9
    start_force = float(np.max(np.abs(gravity(model, q0))))
    assert np.max(np.abs(gravity(model, scaled.q))) <= 1e-12 * start_force
    assert scaled.stability == "stable" and smallest_stiffness_eigenvalue(model, scaled.q) > 0
    assert 3 * scaled.steps < plain.steps, (scaled.steps, plain.steps)


def test_robot_with_armature_of_its_own_rests_where_it_did():
    # The UR5's own armature (motor inertia, part of the model) stays; the fictitious inertia
    # comes on top. Same rest conditions as the default run.
    model = pinsettle.load_robot("ur5", floating=False)
    model.armature = np.full(model.nv, 0.05)
    q0 = pinocchio.neutral(model)
    plain = pinsettle.solve(model, q0)
    scaled = pinsettle.solve(model, q0, scale_joint_inertia=True)
    assert scaled.converged and scaled.scaled_joints > 0
    np.testing.assert_array_equal(model.armature, np.full(model.nv, 0.05))
    scale = float(np.max(np.abs(gravity(model, q0))))
    assert np.max(np.abs(gravity(model, scaled.q))) <= 1e-10 * scale
    assert scaled.stability == plain.stability
    assert scaled.residual <= 1e-10 * scale
    assert "given a fictitious inertia" in scaled.summary()
    assert scaled.to_dict()["scaled_joints"] == scaled.scaled_joints


@pytest.mark.parametrize(
    "overrides",
    [{"energy": "simplified"}, {"dt": 1e-3, "max_steps": 200}],
    ids=["simplified_energy", "fixed_step"],
)
def test_not_applied_where_it_has_no_meaning(overrides):
    # The simplified energy does not count the added inertia (its peaks would not be the
    # scaled motion's); a fixed step has no estimate to choose it at.
    model = pinocchio.buildModelFromXML(chain_urdf(5))
    q0 = np.zeros(model.nq)
    q0[0] = 1.0
    result = pinsettle.solve(model, q0, scale_joint_inertia=True, **overrides)
    assert result.scaled_joints == 0


def test_not_applied_to_one_joint_or_closed_loops():
    pendulum = pinsettle.solve(
        pinsettle.load_scene(ROBOTS / "pendulum.toml"), scale_joint_inertia=True
    )
    assert pendulum.converged and pendulum.scaled_joints == 0
    fourbar = pinsettle.solve(
        pinsettle.load_scene(ROBOTS / "fourbar.toml"), scale_joint_inertia=True
    )
    assert fourbar.converged and fourbar.scaled_joints == 0


def test_setting_defaults_to_auto():
    assert pinsettle.Settings().scale_joint_inertia == "auto"
    assert pinsettle.Settings(scale_joint_inertia=True).scale_joint_inertia is True
    assert pinsettle.Settings(scale_joint_inertia=False).scale_joint_inertia is False


def chain_start(n: int) -> tuple[pinocchio.Model, np.ndarray]:
    model = pinocchio.buildModelFromXML(chain_urdf(n))
    q0 = np.zeros(model.nq)
    q0[0] = np.pi / 2
    return model, q0


@pytest.mark.parametrize("n", [19, 20])
def test_auto_gives_it_from_twenty_degrees_of_freedom(n):
    # 'auto' is True from 20 joints up (the measured rule), False below: the same run, step
    # for step and to the bit, as the setting given by hand.
    model, q0 = chain_start(n)
    auto = pinsettle.solve(model, q0)
    given = pinsettle.solve(model, q0, scale_joint_inertia=n >= 20)
    assert auto.converged
    assert (auto.scaled_joints > 0) == (n >= 20)
    assert auto.steps == given.steps and auto.peaks == given.peaks
    np.testing.assert_array_equal(auto.q, given.q)
    assert np.max(np.abs(gravity(model, auto.q))) <= 1e-12 * np.max(np.abs(gravity(model, q0)))


def test_auto_leaves_it_off_with_ground_contacts():
    # Talos standing on a floor (38 degrees of freedom, eight sole contacts): contact scenes
    # lost with it, so 'auto' leaves it off; True still gives it.
    scene = pinsettle.load_scene("talos_standing")
    auto = pinsettle.Solver(scene, max_steps=2).solve()
    given = pinsettle.Solver(scene, max_steps=2, scale_joint_inertia=True).solve()
    assert scene.model.nv >= 20
    assert auto.scaled_joints == 0 and given.scaled_joints > 0

"""No run on a floor makes energy: between damping events the mechanism may only gain the
kinetic energy gravity gives it (its potential energy falls by as much), less what contacts and
stops take. gymnasium's walker2d, lying on its floor with its feet on their stops, slid along
the floor at constant height for as long as it ran (inexact contact impulses): over 10 s the
steps made 5,660 J from nothing against the 119 J its fall released, and the run never ended.

The check: over every step of the trace that is not a damping event, a push or a roll-back,
the rise of the mechanical energy (kinetic plus gravity's potential, Pinocchio's own, outside the
solver, plus the joint springs') summed over the run stays a small share of the potential energy
released (the explicit step's own error, 6 % on the hopper at its large steps). Only scenes whose
forces are gravity, joint springs, contacts and stops."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest
import third_party_models as gallery

REQUIRED = os.environ.get("PINSETTLE_REQUIRE_MODELS") == "1"
# The energy the steps may make, as a share of the potential energy the run released.
MADE_SHARE = 0.25

GYM = ["walker2d.xml", "walker2d_v5.xml", "hopper.xml", "ant.xml", "humanoid.xml"]
DM = ["suite/walker.xml", "suite/hopper.xml"]
LIBRARY = ["go1_motors_off", "box_on_floor", "mjcf_ant"]


def _model_file(package: str, folder: str, name: str) -> Path:
    if importlib.util.find_spec(package) is None:
        message = f"the floor-energy check of {name} needs '{package}' (pip install '.[test]')"
        if REQUIRED:
            pytest.fail(message)
        pytest.skip(message)
    root = gallery.package_dir(package)
    assert root is not None
    return root / folder / name


def energy_made(scene: pinsettle.Scene, result: pinsettle.Result) -> tuple[float, float]:
    """(energy the steps made, potential energy released) over the run's trace (J)."""
    trace = result.trace
    assert trace is not None and trace.q is not None and trace.stride == 1
    model = scene.model
    data = model.createData()
    potential = np.array(
        [
            pinocchio.computePotentialEnergy(model, data, q) + spring_energy(scene, q)
            for q in trace.q
        ]
    )
    mechanical = trace.kinetic_energy + potential
    # Damping takes energy out and a push puts a tiny amount in; a roll-back restores a state:
    # none of them is a step. An impact (a joint landing on its stop) is a step.
    events = {
        int(step)
        for step, kind in zip(trace.event_step, trace.event_kind, strict=True)
        if kind != "impact"
    }
    made = 0.0
    for k in range(len(trace.step) - 1):
        if int(trace.step[k]) in events or int(trace.step[k + 1]) in events:
            continue
        made += max(0.0, mechanical[k + 1] - mechanical[k])
    return made, float(potential[0] - potential[-1])


def spring_energy(scene: pinsettle.Scene, q: np.ndarray) -> float:
    """The joint springs' energy, 1/2 k (q - rest)^2 each (one-coordinate joints)."""
    model = scene.model
    energy = 0.0
    for spring in scene.joint_springs:
        j = model.getJointId(spring.joint)
        assert model.nqs[j] == 1, f"{spring.joint}: a spring on a joint of {model.nqs[j]} entries"
        energy += 0.5 * spring.stiffness * (q[model.idx_qs[j]] - spring.rest) ** 2
    return energy


def solve_traced(scene: pinsettle.Scene) -> pinsettle.Result:
    return pinsettle.solve(
        scene,
        trace_every=1,
        trace_capacity=10**6,
        trace_configurations=True,
        max_time=10.0,
    )


def check_run(scene: pinsettle.Scene) -> pinsettle.Result:
    assert not scene.loads, "the check counts gravity and joint springs alone"
    result = solve_traced(scene)
    assert result.status == "converged", (result.status, result.steps, result.reason)
    assert result.contacts, "it rests on nothing"
    made, released = energy_made(scene, result)
    assert released > 0
    assert made <= MADE_SHARE * released, (made, released)
    return result


@pytest.mark.parametrize("name", GYM)
def test_gymnasium_robots_on_their_floors_make_no_energy(name):
    check_run(pinsettle.load_scene(_model_file("gymnasium", "envs/mujoco/assets", name)))


@pytest.mark.parametrize("name", DM)
def test_dm_control_robots_on_their_floors_make_no_energy(name):
    check_run(pinsettle.load_scene(_model_file("dm_control", "", name)))


@pytest.mark.parametrize("name", LIBRARY)
def test_library_contact_scenes_make_no_energy(name):
    check_run(pinsettle.load_scene(name))


def test_the_check_catches_energy_made_from_nothing():
    """The sum sees a step that makes energy: the same run with one sample's kinetic energy
    raised by the energy the run released, between ordinary steps, fails the check."""
    scene = pinsettle.load_scene("box_on_floor")
    result = solve_traced(scene)
    made, released = energy_made(scene, result)
    assert made <= MADE_SHARE * released
    trace = result.trace
    assert trace is not None
    events = {
        int(s)
        for s, kind in zip(trace.event_step, trace.event_kind, strict=True)
        if kind != "impact"
    }
    k = next(
        i
        for i in range(1, len(trace.step) - 1)
        if not events & {int(trace.step[i - 1]), int(trace.step[i]), int(trace.step[i + 1])}
    )
    trace.kinetic_energy[k] += released
    made_after, _ = energy_made(scene, result)
    assert made_after > MADE_SHARE * released


@pytest.mark.parametrize("name", ["walker2d.xml", "walker2d_v5.xml"])
def test_walker2d_rests_on_its_floor_as_mujoco_judges(name):
    """The walker lies on its floor, its feet on their stops: its contact forces (through
    MuJoCo's Jacobians) and stops balance MuJoCo's static force, the floor carries its weight to
    1e-9, every force lies in its cone, nothing sinks in more than 1e-6 m, and MuJoCo's own
    contacts at the answer agree."""
    if importlib.util.find_spec("mujoco") is None and not REQUIRED:
        pytest.skip("the MJCF judge needs mujoco")
    path = _model_file("gymnasium", "envs/mujoco/assets", name)
    run = gallery.run_cli(path, False, ("--max-time", "10"))
    assert run.code == 0 and run.answer is not None, run.stderr[-500:]
    answer = run.answer
    assert answer["status"] == "converged", (answer["status"], answer["reason"])
    verdict = gallery.judge_mjcf_on_floor(path, answer)
    assert not verdict.problems, verdict.problems
    assert answer["residual"] <= gallery.REL_TOL * verdict.scale
    assert min(c["gap"] for c in answer["contacts"]) >= -gallery.CONTACT_GAP_TOL

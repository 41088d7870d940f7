"""Every entry point of pinsettle's C++ binding, a few times each, for LeakSanitizer.

Run by .ci/sanitize on the sanitized module with leak detection on: whatever the binding
allocates (solvers, force elements, loops, stops, traces, results, error messages) must be
freed by the time the interpreter exits. Not a test of answers (the test suite is).
"""

from __future__ import annotations

import contextlib
import io
import math
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
from pinsettle.__main__ import main

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
SCENES = ["pendulum", "fourbar", "slider_crank", "double_pendulum_springs", "ur5_tool_spring"]


def expect(error: type[Exception], call, *args, **kwargs) -> None:
    try:
        call(*args, **kwargs)
    except error:
        return
    raise AssertionError(f"{call.__name__}{args} did not raise {error.__name__}")


def chain(links: int):
    """A chain of hinges (the model only: its Data is what is checked)."""
    model = pinocchio.Model()
    parent = 0
    for k in range(links):
        placement = pinocchio.SE3(np.eye(3), np.array([0.0, 0.0, -0.1 if k else 0.0]))
        parent = model.addJoint(parent, pinocchio.JointModelRY(), placement, f"joint{k + 1}")
        model.appendBodyToJoint(
            parent, pinocchio.Inertia.FromSphere(0.1, 0.01), pinocchio.SE3.Identity()
        )
    return model


def exercise(ur5, scenes) -> None:
    r = pinsettle.solve(
        ur5, trace_every=5, trace_configurations=True, callback=lambda: False, polish=True
    )
    pinsettle.solve(ur5, limits=False, v0=np.full(ur5.nv, 0.1), dt=1e-3)
    pinsettle.solve(ur5, callback=lambda: True, check_every=10)  # aborted
    for scene in scenes:
        pinsettle.solve(scene, trace_every=3)
        pinsettle.assess_stability(scene, scene.q0())
    pinsettle.assess_stability(ur5, r.q)
    pinsettle.static_force(ur5, r.q)
    pinsettle.kinetic_energies(ur5, r.q, np.ones(ur5.nv))
    # A kept solver (the binding's Solver owns the elements, loops and stops it was given), reused
    # from other starts, on a model and on a scene; and the settings' declared fields.
    solver = pinsettle.Solver(ur5)
    solver.solve()
    solver.solve(r.q, v0=np.full(ur5.nv, 0.1))
    for scene in scenes[:2]:
        kept = pinsettle.Solver(scene)
        kept.solve()
        kept.solve(scene.q0())
    pinsettle.Settings.fields()
    # Errors thrown in C++ and turned into Python exceptions.
    for bad in [{"kt": 2.0}, {"dt": -1.0}, {"max_steps": 0}]:
        expect(ValueError, pinsettle.solve, ur5, **bad)
    expect(ValueError, pinsettle.solve, ur5, np.full(ur5.nq, math.nan))
    expect(ValueError, pinsettle.solve, ur5, np.zeros(3))
    # The memory a model's Data takes, and a model whose Data (32 GB) does not fit.
    assert pinsettle.solver_memory(ur5) > 0
    expect(MemoryError, pinsettle.solve, chain(1000))
    # The command line, in process.
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["solve", str(ROBOTS / "fourbar.toml")]) == 0
        assert main(["solve", str(ROBOTS / "no_such_scene.toml")]) == 2


def run() -> None:
    ur5 = pinsettle.load_robot("ur5")
    scenes = [pinsettle.load_scene(ROBOTS / f"{name}.toml") for name in SCENES]
    for _ in range(3):
        exercise(ur5, scenes)


if __name__ == "__main__":
    run()
    print("leak_check: every entry point ran")

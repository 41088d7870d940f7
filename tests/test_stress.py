"""The stress suite (benchmarks/stress.py) as tests: every extreme case, each energy measure and
kt in {0, 0.5, 0.9}, must end converged and stable or neutral at the independent Newton root
(1e-6 in every joint), or with the status the case expects; never non-finite, never past its
wall-clock budget."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "stress.py"
_spec = importlib.util.spec_from_file_location("pinsettle_stress", _PATH)
stress = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = stress  # dataclasses look their module up there
_spec.loader.exec_module(stress)

RUNS = stress.runs()


@pytest.mark.parametrize(
    "case, energy, kt", RUNS, ids=[f"{c.name}-{e}-kt{kt:g}" for c, e, kt in RUNS]
)
def test_stress_case(case, energy, kt):
    outcome = stress.run(case, energy, kt)
    assert outcome.passed, f"{case.name} ({energy}, kt={kt}): {outcome.why}"
    assert outcome.seconds < stress.MAX_TIME  # the budget, not a speed claim: never a hang
    if case.expect == "equilibrium":
        assert outcome.error <= stress.JOINT_TOLERANCE
    else:
        assert math.isnan(outcome.error) and outcome.status == case.expect


def test_the_suite_covers_the_extremes_of_the_issue():
    names = {c.name for c in stress.cases()}
    groups = {c.group for c in stress.cases()}
    assert {"stiffness", "mass ratio", "scale", "chain length", "gravity"} <= groups
    assert {"far start", "saddle start", "no equilibrium"} <= groups
    assert "slider spring k=1e+08" in names and "chain of 100" in names and "chain of 2" in names
    assert {"gravity 0 m/s^2", "gravity 1000 m/s^2"} <= names
    assert len(RUNS) == len(stress.cases()) * 2 * 3


def test_the_reference_is_independent_and_right():
    # The suite's Newton reference against a closed form: a pendulum with a joint spring,
    # m g l sin(t) = -k (t - rest) at rest (l the rod's centre of mass, 0.5 m).
    model = stress.chain([1.0], [1.0])
    physics = stress.Physics(model, joint_springs=[("j0", 20.0, 1.0)])
    root, uncertainty = stress.newton(physics, np.array([0.5]))
    t = root[0]
    assert uncertainty < 1e-12
    assert 1.0 * 9.81 * 0.5 * math.sin(t) == pytest.approx(-20.0 * (t - 1.0), abs=1e-12)
    # And its static force is that of pinsettle's scene of the same physics.
    scene = physics.scene()
    q = np.array([0.3])
    assert stress.static_force(physics, q) == pytest.approx(scene.static_force(q), abs=1e-12)

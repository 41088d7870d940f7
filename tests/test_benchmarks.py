"""The benchmark report (benchmarks/report.py) on its tiny ``--quick`` configuration: it runs end
to end (the C++ baselines and step_cost are built against the installed package), writes its
report and figures, and what it measured hangs together. No timing assertions: times are only
checked to be there.

PINSETTLE_BENCH_BUILD names a build folder to keep between runs (like PINSETTLE_CPP_TEST_BUILD).
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import report  # noqa: E402  (benchmarks/report.py)
import report_data  # noqa: E402  (benchmarks/report_data.py)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    build = os.environ.get("PINSETTLE_BENCH_BUILD")
    build = Path(build) if build else tmp_path_factory.mktemp("bench-build")
    output = tmp_path_factory.mktemp("bench-report")
    results = report.generate(report.QUICK, output, build, quiet=True)
    return results, output


def test_stays_below():
    values = np.array([1.0, 1e-3, 1e-7, 1e-5, 1e-8, 1e-9])
    assert report_data.stays_below(values, 1e-6) == 4  # the swing through 1e-7 does not count
    assert report_data.stays_below(values, 10.0) == 0
    assert report_data.stays_below(values, 1e-12) is None
    assert report_data.stays_below(np.array([1.0, np.nan, 1e-9]), 1e-6) == 2


def test_the_report_and_its_figures_are_written(quick):
    results, output = quick
    text = (output / "benchmarks.md").read_text()
    figures = sorted(p.name for p in (output / "benchmarks").glob("*.png"))
    expected = [f"{name}.png" for name in results.scenes] + ["kt.png", "max_e.png", "scaling.png"]
    assert sorted(expected) == figures
    for name in figures:
        assert (output / "benchmarks" / name).stat().st_size > 1000
        assert f"(benchmarks/{name})" in text
    for section in (
        "## In short",
        "## Summary",
        "## Exact against simplified energy",
        "## kt",
        "## The stopping rule",
        "## Peak backtracking",
        "## Fixed against automatic dt",
        "## Baselines",
        "## Cost of one step",
        "## Scaling with chain length",
        "## Closed loops",
    ):
        assert section in text
    assert results.machine["cpu"] in text and results.machine["date"] in text
    assert "nan" not in text.replace("nanosecond", "")
    # Every table is well formed: as many cells in each row as in its header.
    lines = text.splitlines()
    for k, line in enumerate(lines[:-1]):
        if line.startswith("| ") and lines[k + 1].startswith("| ---"):
            width = line.count("|")
            for row in lines[k + 1 :]:
                if not row.startswith("|"):
                    break
                assert row.count("|") == width, row


def test_the_reference_is_a_stable_root_checked_independently(quick):
    results, _ = quick
    for d in results.scenes.values():
        assert d.ref.stability in ("stable", "neutral")
        assert d.ref.residual <= 1e-12
        assert d.ref.fd_step <= 1e-10  # a Newton step of its own finds nothing to correct


def test_error_curves_fall_to_the_final_error(quick):
    results, _ = quick
    for d in results.scenes.values():
        for key, run in d.runs.items():
            c = run.curve
            assert c is not None, key
            assert np.all(np.diff(c.steps) > 0), key
            if run.method == "newton":
                continue
            assert c.steps[-1] == run.steps, key
            # The last sample is the final state: the curve ends at the final error.
            assert c.distance[-1] == pytest.approx(run.distance, abs=1e-15), key
            assert c.residual[-1] == pytest.approx(run.residual, rel=1e-12, abs=1e-18), key
            # It falls: the end is far below the start, and the worst of the last tenth far
            # below the worst of the first tenth.
            tenth = max(1, c.steps.size // 10)
            assert np.max(c.residual[-tenth:]) < 1e-6 * np.max(c.residual[:tenth]), key
            assert np.max(c.distance[-tenth:]) < 1e-6 * np.max(c.distance[:tenth]), key
            # A level reached is reached in order.
            a, b = run.reach("residual", 1e-6), run.reach("residual", 1e-10)
            assert a is not None and b is not None and a[0] <= b[0], key
            assert run.seconds and all(s > 0 for s in run.seconds), key


def test_every_method_rests_at_the_pendulums_equilibrium(quick):
    results, _ = quick
    d = results.scenes["pendulum"]
    for key in ("kd_exact", "kd_simplified", "viscous", "mass_damping", "fire"):
        run = d.runs[key]
        assert run.status == "converged", key
        assert run.residual <= 1e-10, key
        assert run.stability == "stable", key
        assert run.landing.from_reference <= 1e-9, key


def test_newton_lands_on_a_root_and_says_which(quick):
    results, _ = quick
    d = results.scenes["pendulum"]
    for key in ("newton", "newton_ls"):
        run = d.runs[key]
        assert run.status == "root"
        assert run.residual <= 1e-10
        # Its landing is judged with pinsettle.assess_stability: the hanging pendulum.
        assert run.stability == "stable"
        assert run.distance <= 1e-9
        assert run.curve.residual[0] == pytest.approx(1.0)  # relative to the force scale


def test_sweeps_and_scaling_are_complete(quick):
    results, _ = quick
    config = results.config
    d = results.scenes["pendulum"]
    assert len(d.sweeps["kt"]) == 2 * len(config.kts)
    assert len(d.sweeps["max_e"]) == 2 * len(config.max_es)
    assert [r.settings["err"] for r in d.sweeps["err"]] == list(config.errs)
    assert [r.settings["ds"] for r in d.sweeps["ds"]] == list(config.dss)
    assert all(r.status == "converged" for runs in d.sweeps.values() for r in runs)
    # A smaller max_e never leaves a larger error by much (the stopping rule's trade-off).
    exact = [r for r in d.sweeps["max_e"] if r.settings["energy"] == "exact"]
    assert exact[-1].distance <= exact[0].distance * 1.01 + 1e-15
    assert [row["n"] for row in results.scaling] == list(config.chain_lengths)
    for row in results.scaling:
        assert row["runs"][0].status == "converged"
        assert set(row["cost"]["ns_per_step"]) >= {"bare", "exact", "simplified"}
    for cost in results.step_cost.values():
        assert cost["settled_steps"] == cost["steps"]  # the solver ran every step it was timed
        assert all(math.isfinite(x) and x > 0 for x in cost["ns_per_step"]["bare"])


def test_the_loop_scene_is_measured_on_the_closed_mechanism(quick):
    results, output = quick
    text = (output / "benchmarks.md").read_text()
    assert "fourbar" in report.QUICK.scenes
    d = results.scenes["fourbar"]
    assert d.loops >= 1 and 1 <= d.mobility < d.nv
    # Its start is on the loops, where the solver starts; the force scale is taken there.
    assert d.statics.loop_error(d.statics.q0) <= 1e-10
    assert d.ref.constraint_error <= 1e-10
    # KD curves, the reduced Newton, the kt sweep; no baselines (unconstrained ABA), said so.
    assert set(d.runs) == {"kd_exact", "kd_simplified", "newton", "newton_ls"}
    assert d.damping is None and not d.damping_sweep
    assert len(d.sweeps["kt"]) == 2 * len(results.config.kts)
    for key in ("kd_exact", "kd_simplified"):
        run = d.runs[key]
        assert run.status == "converged", key
        assert run.residual <= 1e-10 and run.stability == "stable", key
        assert run.landing.from_reference <= 1e-9, key
        # The report's own measure of the loops agrees with the solver's, and both are tiny.
        assert run.extra["constraint_error"] <= 1e-10, key
        assert run.extra["solver_constraint_error"] <= 1e-10, key
        assert run.extra["constraint_error_along"] <= 1e-10, key
    for run in (r for sweep in d.sweeps.values() for r in sweep):
        assert run.extra["constraint_error"] <= 1e-10, run.label
    for key in ("newton", "newton_ls"):
        run = d.runs[key]
        assert run.status == "root" and run.stability == "stable", key
        assert run.extra["constraint_error"] <= 1e-10, key
    # In the report: its summary rows, its figure, the closed-loops paragraph and the note.
    assert "| `fourbar` | KD exact |" in text
    assert "(benchmarks/fourbar.png)" in text
    assert "- **Closed loops**:" in text
    assert "baselines run on trees only" in text
    # The step's cost against a bare constrained step: the solver ran every step it was timed,
    # stayed on the loops, and every time is a real one.
    cost = results.loop_step_cost["fourbar"]
    assert cost["settled_steps"] == cost["steps"] and cost["rows"] == 3
    assert cost["constraint_error"] <= 1e-10
    for times in cost["ns_per_step"].values():
        assert len(times) == results.config.step_cost_repeats
        assert all(math.isfinite(x) and x > 0 for x in times)
    assert "`benchmarks/loop_step_cost.cpp`, in the same run" in text

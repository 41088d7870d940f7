"""The benchmark report (benchmarks/report.py) on its tiny ``--quick`` configuration: it runs end
to end (the C++ baselines, step_cost and kd_profile are built against the installed package),
writes its report and figures, and what it measured hangs together. No timing assertions: times
are only checked to be there and to add up.

PINSETTLE_BENCH_BUILD names a build folder to keep between runs (like PINSETTLE_CPP_TEST_BUILD).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import os
import re
import statistics
import sys
import types
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import report  # noqa: E402  (benchmarks/report.py)
import report_data  # noqa: E402  (benchmarks/report_data.py)
import report_format  # noqa: E402  (benchmarks/report_format.py)
import report_goals  # noqa: E402  (benchmarks/report_goals.py)
import report_measures  # noqa: E402  (benchmarks/report_measures.py)
import report_readme  # noqa: E402  (benchmarks/report_readme.py)
import report_writer  # noqa: E402  (benchmarks/report_writer.py)
from scene_statics import Statics  # noqa: E402  (benchmarks/scene_statics.py)

HAS_MUJOCO = importlib.util.find_spec("mujoco") is not None


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    build = os.environ.get("PINSETTLE_BENCH_BUILD")
    build = Path(build) if build else tmp_path_factory.mktemp("bench-build")
    output = tmp_path_factory.mktemp("bench-report")
    # A section another tool writes into the same file: the report must keep it.
    (output / "benchmarks.md").write_text(
        "# old\n\nloose text\n\n<!-- sweep:throughput (another tool) -->\nTHROUGHPUT 42\n"
        "<!-- /sweep:throughput -->\n"
    )
    results = report.generate(report.QUICK, output, build, quiet=True)
    return results, output, build


def test_stays_below():
    values = np.array([1.0, 1e-3, 1e-7, 1e-5, 1e-8, 1e-9])
    assert report_data.stays_below(values, 1e-6) == 4  # the swing through 1e-7 does not count
    assert report_data.stays_below(values, 10.0) == 0
    assert report_data.stays_below(values, 1e-12) is None
    assert report_data.stays_below(np.array([1.0, np.nan, 1e-9]), 1e-6) == 2


def test_a_best_on_the_edge_of_its_sweep_grid_is_named():
    grid = report_data.Config(scenes=(), chain_lengths=(), repeats=1, sweep_repeats=1).sweep(
        "viscous"
    )
    safeties = sorted({g["dt_safety"] for g in grid})
    factors = sorted({g["damping_factor"] for g in grid})
    inside = {"dt_safety": safeties[1], "damping_factor": factors[1]}
    assert report_writer.grid_edges(grid, inside) == []
    corner = {"dt_safety": safeties[-1], "damping_factor": factors[0]}
    assert report_writer.grid_edges(grid, corner) == [
        f"dt_safety {safeties[-1]:g}, the largest tried",
        f"damping_factor {factors[0]:g}, the smallest tried",
    ]
    # FIRE's metric is a choice, not a range: never an edge.
    fire = report_data.Config(scenes=(), chain_lengths=(), repeats=1, sweep_repeats=1).sweep("fire")
    assert report_writer.grid_edges(fire, {"dt_max": 1.0, "metric": "mass"}) == []


def _point(settings, seconds):
    status = "converged" if seconds is not None else "diverged"
    time = 1.0 if seconds is None else seconds
    return report_data.SweepPoint(dict(settings), status, 1, time, 0.0, 0, [], 0, 0.0)


def test_a_sweep_grows_past_the_edge_its_best_sits_on():
    # A time with its minimum at dt_safety 1.25 and damping_factor 1 / 16: the grid
    # (0.5, 0.8) x (0.25, 1) has its best in a corner, and the sweep grows past both edges
    # (x 1.25, x 1 / 4) until the best is inside; runs past dt_safety 1.3 fail.
    def run(settings):
        s, f = settings["dt_safety"], settings["damping_factor"]
        if s > 1.3:
            return _point(settings, None)
        return _point(settings, abs(math.log(s / 1.25)) + abs(math.log(f * 16)))

    grid = [{"dt_safety": s, "damping_factor": f} for f in (0.25, 1.0) for s in (0.5, 0.8)]
    points = report.sweep_inside(run, grid, extensions=4)
    assert [p.settings for p in points][:4] == grid
    best = report.fastest(points)
    assert best.settings == {"dt_safety": 1.25, "damping_factor": 1 / 16}
    tried = [p.settings for p in points]
    assert {t["dt_safety"] for t in tried} == {0.5, 0.8, 1.0, 1.25, 1.5625}
    assert {t["damping_factor"] for t in tried} == {1 / 64, 1 / 16, 0.25, 1.0}
    assert report_writer.grid_edges(tried, best.settings) == []
    assert len(tried) == len({tuple(sorted(t.items())) for t in tried})  # none twice
    # With no extension left, the best stays on the edge, and the report names it.
    points = report.sweep_inside(run, grid, extensions=0)
    assert [p.settings for p in points] == grid
    assert report_writer.grid_edges(grid, report.fastest(points).settings)


def test_the_baselines_finish_with_the_solvers_newton_and_newton_is_a_peer(quick):
    results, _, _ = quick
    d = results.scenes["pendulum"]
    for family in report_data.BASELINES:
        method, newton = report_data.baseline_method(family)
        run = d.runs[f"{family}_rule"]
        if newton:
            # The takeover was tried and ended the run at round-off (its rest the curve's last
            # sample, one step after the last damped one).
            assert run.extra["newton_tries"] >= 1 and run.extra["by_newton"], family
            assert run.residual <= 1e-14, family
            assert run.curve.residual[-1] <= 1e-14 and run.curve.steps[-1] == run.steps
            plain = d.runs[f"{method}_rule"]
            assert run.steps < plain.steps, family
        else:
            assert run.extra["newton_tries"] == 0 and not run.extra["by_newton"], family
    tr = d.runs[f"{report_data.NEWTON_TR}_best"]
    assert tr.status == "converged" and tr.stability == "stable"
    assert tr.residual <= 1e-10


def test_every_methods_best_is_timed_in_interleaved_rounds(quick):
    results, _, _ = quick
    d = results.scenes["pendulum"]
    assert list(d.interleaved) == ["kd_default", *report_data.BASELINES]
    for key, times in d.interleaved.items():
        assert len(times) == results.config.interleave_rounds, key
        assert all(0 < t < 1 for t in times), key
    found = report_measures.fastest_interleaved(d)
    assert found is not None and found[0] in report_data.BASELINES
    assert not results.scenes["fourbar"].interleaved  # no baselines on a closed loop


def test_the_report_and_its_figures_are_written(quick):
    results, output, _ = quick
    text = (output / "benchmarks.md").read_text()
    figures = sorted(p.name for p in (output / "benchmarks").glob("*.png"))
    expected = [f"{name}.png" for name in results.scenes]
    expected += ["kt.png", "max_e.png", "scaling.png", "gallery.png"]
    assert sorted(expected) == figures
    for name in figures:
        assert (output / "benchmarks" / name).stat().st_size > 1000
        assert f"(benchmarks/{name})" in text
    for section in (
        "## Goals",
        "## Scenes: error against run time",
        "### In short",
        "### How it is measured",
        "### The default settings",
        "### Baselines at their rule and at their best",
        "### Newton from the start",
        "### Summary",
        "### Exact against simplified energy",
        "### kt",
        "### The stopping rule",
        "### Peak backtracking",
        "### Fixed against automatic dt",
        "### Closed loops",
        "## Cost of one step",
        "## Where a solve's time goes",
        "## Scaling with chain length",
        "## The robot gallery, and MuJoCo",
        "**Goal 1**",
        "**Goal 2**",
        "**Goal 4**",
        "**Goal 5**",
        "**Issue 18, step cost**",
        "shared with other jobs",
    ):
        assert section in text, section
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


def assert_behind(line, name, family, seconds):
    """A goal line that says KD is behind on the scene, naming the peer and its time."""
    assert "**not met**" in line
    label = report_data.BASELINE_LABELS[family]
    assert f"{name} ({label} {report_format.fmt_time(seconds)} against KD's" in line


def test_goal_1_says_which_baseline_is_faster_and_why(quick):
    # The quick run's KD made 1,000 times slower and each baseline's sweep-best run 10 times
    # slower than its rule run: the goal line must say "not met", name the baseline's fastest
    # time (its rule run or a sweep point, not the slowed best run) and give the measured
    # reasons.
    results, _, _ = quick
    name = report_measures.compared(results)[0]
    d = dataclasses.replace(results.scenes[name], runs=dict(results.scenes[name].runs))
    slowed = dataclasses.replace(results, scenes={**results.scenes, name: d})

    def slower(run, factor):
        return dataclasses.replace(
            run, seconds=[s * factor for s in run.seconds], setup=run.setup * factor
        )

    for key in (report_measures.kd_key(), "kd_default"):
        d.runs[key] = slower(d.runs[key], 1000.0)
    for family in report_data.BASELINES:
        d.runs[f"{family}_best"] = slower(d.runs[f"{family}_rule"], 10.0)
    fastest = {}
    for f in report_data.BASELINES:
        times = [report_measures.time_to(d.runs[f"{f}_rule"])]
        times += [p.time_to for p in d.baseline_sweep[f]]
        times = [t for t in times if t is not None]
        if times:
            fastest[f] = min(times)
            assert report_measures.fastest_baseline(d, f)[0] == fastest[f]
    assert fastest
    goals = report_goals.goals_section(slowed).splitlines()
    # Against every peer: the fastest named, and where it is Newton from the start, why.
    family = min(fastest, key=fastest.get)
    line = next(x for x in goals if "**Goal 1**" in x)
    assert_behind(line, name, family, fastest[family])
    if family == report_data.NEWTON_TR:
        assert f"Why, on {name}: Newton with a trust region solves the statics" in line
    # Against the peers that follow the dynamics: the fastest of those, and the measured
    # reasons.
    dynamic = {f: t for f, t in fastest.items() if f in report_goals.DYNAMIC_PEERS}
    family = min(dynamic, key=dynamic.get)
    line = next(x for x in goals if "**Goal 1 against the peers that follow the dynamics**" in x)
    assert_behind(line, name, family, fastest[family])
    assert "KD damps once every" in line and "set-up" in line
    kd = d.runs[report_measures.kd_key()]
    tk = report_measures.kd_reach(d)[0]  # the KD time the line gives
    assert (
        f"KD's set-up {report_format.fmt_time(kd.setup)} is {kd.setup / tk:.0%} of its time" in line
    )
    if kd.setup / tk > report_goals.SETUP_HEAVY:
        assert f"Why, on {name}" in line
    if d.nv == 1:  # one mode: the line compares the steps and a step's time, as measured
        reach = report_measures.kd_reach(d)
        best = report_measures.fastest_baseline(d, family)
        assert reach is not None and reach[1] and best is not None
        steps = reach[1]
        assert f"Why, on {name} (one degree of freedom): {name}: " in line
        assert f"{best[2]:,} steps in {report_format.fmt_time(best[0])}" in line
        assert f"KD {steps:,} in" in line


#: What the README's speed section must not say: it reports measurements to users; the goals
#: of the issues, met or not, are in the report's Goals part.
GOAL_WORDS = re.compile(r"\bissue\b|\bgoal\b|\bmet\b|#\d", re.IGNORECASE)


def summary_block(text: str) -> str:
    start = text.index(report_readme.README_BEGIN)
    return text[start : text.index(report_readme.README_END, start)]


def test_the_readme_block_says_what_was_measured_and_no_goals(quick):
    results, _, _ = quick
    block = report_readme.readme_block(results)
    assert block.startswith(report_readme.README_BEGIN)
    assert block.endswith(report_readme.README_END)
    assert not GOAL_WORDS.search(block), GOAL_WORDS.search(block)
    flat = " ".join(block.split())  # unwrapped
    for start in ("- **One step**", "- **Robot gallery**", "- **Where a solve's time goes**"):
        assert start in flat, start
    # The same measurements as the report's Goals part, without the verdicts.
    assert report_goals.gallery_tally(results) in flat
    goals = report_goals.goals_section(results)
    assert report_goals.gallery_tally(results) in goals and "**Goal 4**" in goals
    for line in block.splitlines():
        assert len(line) <= 100, line


def test_the_committed_readme_summary_has_no_goals():
    # The README's block is the generator's (the last full run's numbers): no issue numbers, no
    # goals met or not.
    readme = (report.ROOT / "README.md").read_text(encoding="utf-8")
    block = summary_block(readme)
    assert not GOAL_WORDS.search(block), GOAL_WORDS.search(block)


def test_goal_5_says_why_from_the_measured_growth():
    # Steps growing as n^1.5 and a step as n^1: the time grows as n^2.5, and the line says
    # which part grows; a refused length is named with the solver's own reason.
    n = [5, 10, 20, 40]
    steps = [100 * k**1.5 for k in n]
    per = [1e-6 * k for k in n]
    wall = [s * p for s, p in zip(steps, per, strict=True)]
    results = types.SimpleNamespace(scaling=[{"n": 400, "refused": "model: nv = 400 is too big"}])
    text = report_goals.goal5_reasons(results, n, steps, per, wall)
    assert "the steps grow as n^1.50" in text and "a step as n^1.00" in text
    assert "400 links are refused: model: nv = 400 is too big." in text
    quadratic = [s / k**0.5 for s, k in zip(wall, n, strict=True)]
    assert "Why" not in report_goals.goal5_reasons(
        types.SimpleNamespace(scaling=[]), n, steps, per, quadratic
    )


def test_goal_4_says_why_a_short_run_passes_the_bound():
    def row(name, fraction, setup):
        parts = {"setup": setup, "estimates": 0.0, "assessments": 1e-3}
        return {
            "name": name,
            "nv": 100,
            "steps": 70,
            "fraction": fraction,
            "parts": parts,
            "estimate_count": 0,
            "assessment_count": 1,
            "bare": 70 * 1e-5,  # 10 us a bare step
        }

    # 3 ms of set-up and 1 ms of verdicts are 400 bare steps of 10 us; a row within the bound
    # gets no reason.
    text = report_goals.fixed_cost_reasons([row("chain100", 0.5, 3e-3), row("ur5", 0.2, 1e-3)])
    assert text.startswith(" Why, on chain100 (50.0%): its run is 70 steps")
    assert "O(nv^3) with nv = 100" in text and "cost as much as 400 of its bare steps" in text
    assert "ur5" not in text


def test_goal_5_gives_the_growth_without_joint_inertia_only_where_every_chain_converged():
    def row(n, status, steps, seconds):
        off = {"status": status, "steps": steps, "seconds": seconds}
        return {"n": n, "no_joint_inertia": off}

    # Time as n^2.5 without the option: the line gives its fit and the steps' range.
    rows = [row(k, "converged", 30 + k, 1e-6 * k**2.5) for k in (5, 20, 80)]
    text = report_goals.joint_inertia_growth(types.SimpleNamespace(scaling=rows))
    assert "`scale_joint_inertia = False` the same chains (5 to 80 links) take 35 to 110" in text
    assert "grows as n^2.50" in text and "from 20 degrees of freedom" in text
    rows[1]["no_joint_inertia"]["status"] = "max_steps"
    assert report_goals.joint_inertia_growth(types.SimpleNamespace(scaling=rows)) == ""
    assert report_goals.joint_inertia_growth(types.SimpleNamespace(scaling=rows[:1])) == ""


def test_the_report_keeps_what_it_did_not_write(quick):
    _, output, _ = quick
    text = (output / "benchmarks.md").read_text()
    # The other tool's delimited section is kept whole (at the end: it followed no part of the
    # report); loose text of the old file is not.
    assert (
        "<!-- sweep:throughput (another tool) -->\nTHROUGHPUT 42\n<!-- /sweep:throughput -->"
        in (text)
    )
    assert "loose text" not in text
    assert text.index("<!-- /report:gallery -->") < text.index("<!-- sweep:throughput")
    for name in report_writer.REGIONS:
        assert text.count(f"<!-- report:{name} ") == 1, name
        assert text.count(f"<!-- /report:{name} -->") == 1, name


def test_a_partial_report_replaces_only_its_parts():
    old = report_writer.merge(
        "",
        {"header": "H1", "goals": "G1", "scenes": "S1", "gallery": "Y1"},
    )
    old = old.replace(
        "<!-- /report:scenes -->\n", "<!-- /report:scenes -->\n<!-- x:y -->\nX\n<!-- /x:y -->\n"
    )
    new = report_writer.merge(old, {"header": "H2", "gallery": "Y2"})
    ours, foreign = report_writer.split_regions(new)
    assert {name: block.splitlines()[1] for name, block in ours.items()} == {
        "header": "H2",
        "goals": "G1",
        "scenes": "S1",
        "gallery": "Y2",
    }
    assert foreign == [("scenes", "<!-- x:y -->\nX\n<!-- /x:y -->\n")]
    # The other block stays right after the part it followed.
    assert new.index("<!-- /report:scenes -->") < new.index("<!-- x:y -->")
    assert new.index("<!-- x:y -->") < new.index("<!-- report:gallery")


def test_sections_are_checked():
    assert report.parse_sections("gallery, cost") == ("gallery", "cost")
    with pytest.raises(Exception, match="comma-separated list of scenes, cost"):
        report.parse_sections("galery")


def test_the_reference_is_a_stable_root_checked_independently(quick):
    results, _, _ = quick
    for d in results.scenes.values():
        assert d.ref.stability in ("stable", "neutral")
        assert d.ref.residual <= 1e-12
        assert d.ref.fd_step <= 1e-10  # a Newton step of its own finds nothing to correct
    # The pendulum's q* recomputed with a model of Pinocchio's own: gravity vanishes there.
    d = results.scenes["pendulum"]
    model = pinocchio.buildModelFromUrdf(str(report.ROOT / "robots" / "pendulum.urdf"))
    g = pinocchio.computeGeneralizedGravity(model, model.createData(), d.ref.q)
    assert np.max(np.abs(g)) <= 1e-12 * d.force_scale
    assert abs(math.remainder(float(d.ref.q[0]), 2 * math.pi)) <= 1e-12  # hanging down


def test_the_reference_uses_none_of_pinsettles_statics(monkeypatch):
    """Issue 19: the reference's residual, Newton steps and verdict come from the test
    reference's physics (tests/scene_reference.py), not from pinsettle's static force,
    stiffness or verdict: with those disabled, the reference and a landing still work."""
    scenes = {name: report.make_scene(name) for name in ("bistable_pendulum", "fourbar")}
    statics = {name: Statics(b.scene, b.reference) for name, b in scenes.items()}

    def refuse(*args, **kwargs):
        raise AssertionError("pinsettle's statics were used")

    monkeypatch.setattr(pinsettle, "assess_stability", refuse)
    monkeypatch.setattr(pinsettle, "static_force", refuse)
    monkeypatch.setattr(pinsettle._core, "static_force", refuse)
    monkeypatch.setattr(pinsettle._core, "assess_stability", refuse, raising=False)
    monkeypatch.setattr(pinsettle.Scene, "static_force", refuse)
    monkeypatch.setattr(pinsettle.Scene, "residual", refuse)
    monkeypatch.setattr(pinsettle.Scene, "assemble", refuse)
    for name, s in statics.items():
        ref = report.reference(s)
        assert ref.residual <= 1e-12 and ref.stability == "stable", name
        land = report.landing(s, ref, ref.q)
        assert land.stability == "stable" and land.from_reference <= 1e-12, name
    # The bistable pendulum rests off the bottom, where gravity alone would not hold it: its
    # spring is in the reference's force.
    assert abs(report.reference(statics["bistable_pendulum"]).q[0]) > 0.5


def test_error_curves_fall_to_the_final_error(quick):
    results, _, _ = quick
    for d in results.scenes.values():
        for key, run in d.runs.items():
            c = run.curve
            if key == "kd_default":
                assert c is None
                continue
            assert c is not None, key
            assert np.all(np.diff(c.steps) > 0), key
            if run.method == "newton":
                continue
            assert c.steps[-1] == run.steps, key
            # The last sample is the final state: the curve ends at the final error.
            assert c.distance[-1] == pytest.approx(run.distance, abs=1e-15), key
            assert c.residual[-1] == pytest.approx(run.residual, rel=1e-12, abs=1e-18), key
            if run.extra.get("by_newton") or run.method == report_data.NEWTON_TR:
                # Newton's finish: a few samples, the last a jump to round-off.
                assert c.residual[-1] <= 1e-12 * np.max(c.residual), key
                continue
            # It falls: the end is far below the start, and the worst of the last tenth far
            # below the worst of the first tenth.
            tenth = max(1, c.steps.size // 10)
            assert np.max(c.residual[-tenth:]) < 1e-6 * np.max(c.residual[:tenth]), key
            assert np.max(c.distance[-tenth:]) < 1e-6 * np.max(c.distance[:tenth]), key
            # A level reached is reached in order, and no sooner than the set-up.
            a, b = run.reach("residual", 1e-6), run.reach("residual", 1e-10)
            assert a is not None and b is not None and a[0] <= b[0], key
            assert run.setup <= a[1] <= b[1], key
            assert run.seconds and all(s > 0 for s in run.seconds), key


def test_every_method_rests_at_the_pendulums_equilibrium(quick):
    results, _, _ = quick
    d = results.scenes["pendulum"]
    keys = ["kd_exact", "kd_simplified", "kd_default"]
    keys += [f"{f}_{kind}" for f in report_data.BASELINES for kind in ("rule", "best")]
    for key in keys:
        run = d.runs[key]
        assert run.status == "converged", key
        assert run.residual <= (1e-10 if key != "kd_default" else 1e-6), key
        assert run.stability == "stable", key
        assert run.landing.from_reference <= 1e-9, key


def test_the_default_run_is_timed_in_cpp_like_the_baselines(quick):
    # On a tree the default run's times are kd_profile's polished solves (the same run:
    # report.time_in_cpp checks its steps and Newton iterations), pinsettle.solve's kept apart.
    results, _, _ = quick
    d = results.scenes["pendulum"]
    run = d.runs["kd_default"]
    assert run.seconds == d.profile["polish_wall"]
    assert run.extra["python_seconds"] and all(s > 0 for s in run.extra["python_seconds"])
    assert d.profile["polish_steps"] == run.steps
    bad = dict(d.profile, polish_steps=run.steps + 1)
    with pytest.raises(RuntimeError, match="not the same run"):
        report.time_in_cpp(run, bad)


def test_the_baselines_take_the_start_only_and_are_swept(quick):
    results, _, _ = quick
    config = results.config
    d = results.scenes["pendulum"]
    # The stability limit the baselines' set-up found is the start's (without stiff-mode
    # scaling), recomputed here by pinsettle's own time scale.
    limit = d.statics.time_scale(d.statics.q0)["critical_step"]
    for family in report_data.BASELINES:
        rule = d.runs[f"{family}_rule"]
        assert rule.settings == report_data.BASELINE_RULES[family]
        method, newton = report_data.baseline_method(family)
        if method == "newton":  # Newton from the start: no set-up, its first radius
            assert rule.setup == 0 and rule.extra["dt"] == rule.settings["radius"]
        else:
            assert rule.extra["limit"] == pytest.approx(limit, rel=1e-9), family
            assert 0 < rule.setup < rule.time, family
        if method in ("fire", "fire2"):
            assert rule.extra["dt_max"] == pytest.approx(2.0 * limit, rel=1e-12)
            assert rule.extra["dt"] == pytest.approx(0.2 * limit, rel=1e-12)
        if family == "viscous":  # dampers taken implicitly: the undamped limit bounds the step
            safety = report_data.BASELINE_RULES[family]["dt_safety"]
            assert rule.extra["dt"] == pytest.approx(safety * limit, rel=1e-12)
        # The sweep covers its grid, the rule among them, and what it grew past an edge; the
        # best is its fastest.
        points = d.baseline_sweep[family]
        grid = config.sweep(family)
        assert [p.settings for p in points][: len(grid)] == grid
        assert report_data.BASELINE_RULES[family] in [p.settings for p in points]
        done = [p for p in points if p.time_to is not None]
        assert done, family
        fastest = min(done, key=lambda p: p.seconds)
        best = d.runs[f"{family}_best"]
        assert best.settings == fastest.settings, family
        for p in points:
            assert (p.setup > 0 or method == "newton") and p.seconds >= p.setup, family
    # The loop scene has no baselines, said so.
    assert not results.scenes["fourbar"].baseline_sweep


def test_newton_lands_on_a_root_and_says_which(quick):
    results, _, _ = quick
    d = results.scenes["pendulum"]
    for key in ("newton", "newton_ls"):
        run = d.runs[key]
        assert run.status == "root"
        assert run.residual <= 1e-10
        # Its landing is judged with the independent stiffness: the hanging pendulum.
        assert run.stability == "stable"
        assert run.distance <= 1e-9
        assert run.curve.residual[0] == pytest.approx(1.0)  # relative to the force scale


def test_sweeps_are_complete(quick):
    results, _, _ = quick
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


def test_the_step_cost_with_and_without_stops(quick):
    results, _, _ = quick
    assert list(results.step_cost) == list(results.config.cost_models)
    for name, cost in results.step_cost.items():
        assert cost["settled_steps"] == cost["steps"], name  # every timed step was taken
        for key in ("bare", "exact", "stops"):
            times = cost["ns_per_step"][key]
            assert len(times) == results.config.step_cost_repeats, (name, key)
            assert all(math.isfinite(x) and x > 0 for x in times), (name, key)
    # The UR5's URDF has a stop on each of its 6 joints; the pendulum's too.
    assert results.step_cost["ur5"]["stop_count"] == 6
    text = report_writer.cost_section(results)
    assert "stops / no stops" in text and "**Joint stops**" in text


def test_the_overhead_split_adds_up(quick):
    results, _, _ = quick
    assert list(results.overhead) == list(results.config.overhead_scenes)
    for name, p in results.overhead.items():
        m = p["median"]
        assert p["status"] == "converged", name
        # One set-up (the first estimate), at least the final assessment; the parts are inside
        # the solve. The default solve (polish and Newton's takeover) is the plain one or one
        # that Newton ended sooner, at a damping event; its parts are inside it too.
        assert m["setup"] > 0 and p["assessment_count"] >= 1, name
        for k in range(len(p["wall"])):
            parts = p["setup"][k] + p["estimates"][k] + p["assessments"][k]
            assert parts <= p["wall"][k], name
        for k in range(len(p["polish_wall"])):
            parts = (
                p["polish_setup"][k]
                + p["polish_estimates"][k]
                + p["polish_assessments"][k]
                + p["polish_stiffness"][k]
            )
            assert 0 < parts <= p["polish_wall"][k], name
        assert 0 < p["polish_steps"] <= p["steps"] and p["polish_iterations"] >= 0, name
        # Every estimate went through the wrapper: the first (the set-up) and the others.
        assert p["dt_estimates"] == p["estimate_count"] + 1, name


def test_scaling_covers_the_chain_lengths(quick):
    results, _, _ = quick
    config = results.config
    assert [row["n"] for row in results.scaling] == list(config.chain_lengths)
    for row in results.scaling:
        if "refused" in row:  # too many degrees of freedom for pinsettle: said so
            assert row["n"] > 300 and "nv" in row["refused"]
            continue
        if row["n"] > 100:  # a long chain may run out of its max_time
            assert row["profile"]["status"] in ("converged", "time_limit"), row["n"]
            continue
        assert row["profile"]["status"] == "converged", row["n"]
        assert row["residual"] <= 1e-6, row["n"]  # relative, independent physics
        assert row["distance"] <= 1e-3, row["n"]  # hanging straight down
        assert all(x > 0 for x in row["profile"]["bare_step"])
        if row["n"] <= config.deep_chain_max:
            assert steps_to_level(row["deep"]) is not None


def steps_to_level(run):
    hit = run.reach("residual", report_data.RESIDUAL_LEVELS[-1])
    return None if hit is None else hit[0]


def test_the_gallery_checks_every_robot_independently(quick):
    results, output, _ = quick
    text = (output / "benchmarks.md").read_text()
    rows = {row["name"]: row for row in results.gallery}
    assert list(rows) == list(results.config.robots)
    for name, row in rows.items():
        assert row["status"] == "converged", name
        assert row["outside"] <= 0.0, name  # inside its limits
        # The independent rest conditions: tiny against the start's static force.
        assert row["residual"] <= 1e-6 * max(row["force_scale"], 1.0), name
        assert row["stability"] in ("stable", "neutral"), name
        assert f"| `{name}` |" in text
    falling = {row["name"]: row for row in results.floating}
    assert list(falling) == ["solo12"]
    assert falling["solo12"]["status"] == "no_equilibrium" and falling["solo12"]["reason"]
    if not HAS_MUJOCO:
        # Where CI requires it (PINSETTLE_REQUIRE_MUJOCO=1, as PINSETTLE_REQUIRE_CHROMIUM for
        # playback), a missing MuJoCo is a failure, not a gallery without its MuJoCo rows.
        if os.environ.get("PINSETTLE_REQUIRE_MUJOCO") == "1":
            pytest.fail(
                "MuJoCo is required here (PINSETTLE_REQUIRE_MUJOCO=1) but is not installed: "
                "the gallery's MuJoCo rows were not measured; pip install '.[test]' installs it"
            )
        assert all(row["mujoco"]["status"] == "not installed" for row in rows.values())
        assert "not installed" in text
        return
    # MuJoCo cannot load finger_edu's inertias, and says why; it settles the UR5 and the double
    # pendulum, inside their limits up to its soft limits, at a rest the independent physics
    # accepts to MuJoCo's own accuracy.
    assert rows["finger_edu"]["mujoco"]["status"] == "cannot load"
    assert "inertia" in rows["finger_edu"]["mujoco"]["reason"]
    assert "`finger_edu`: " in text
    for name in ("ur5", "double_pendulum"):
        mj = rows[name]["mujoco"]
        assert mj["status"] == "settled", name
        assert mj["steps"] > 0 and statistics.median(mj["seconds"]) > 0, name
        assert mj["residual"] <= 1e-2 * max(rows[name]["force_scale"], 1.0), name
        assert mj["outside"] <= 1e-2, name
    # MuJoCo runs at one setting here: the answers are compared, its time is no speed claim
    # (no ratio, no goal on it; that is MuJoCo at its best, benchmarks/mujoco_best.py).
    gallery = text.split("<!-- report:gallery", 1)[1].split("<!-- /report:gallery -->", 1)[0]
    assert "MuJoCo / KD" not in gallery and "times pinsettle's" not in gallery
    assert "as its users do" not in gallery and "its time says nothing of it" in gallery


def test_the_loop_scene_is_measured_on_the_closed_mechanism(quick):
    results, output, _ = quick
    text = (output / "benchmarks.md").read_text()
    assert "fourbar" in report.QUICK.scenes
    d = results.scenes["fourbar"]
    assert d.loops >= 1 and 1 <= d.mobility < d.nv
    # Its start is on the loops, where the solver starts; the force scale is taken there.
    assert d.statics.loop_error(d.statics.q0) <= 1e-10
    assert d.ref.constraint_error <= 1e-10
    # KD curves, the reduced Newton, the kt sweep; no baselines (unconstrained ABA), said so.
    assert set(d.runs) == {"kd_exact", "kd_simplified", "kd_default", "newton", "newton_ls"}
    assert not d.baseline_sweep and d.profile is None
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


def test_unfinished_chains_tell_a_refusal_from_a_run_out_of_time():
    config = types.SimpleNamespace(scaling_max_time=150.0)
    rows = [
        {"n": 5, "profile": {"status": "converged"}},
        {"n": 300, "profile": {"status": "time_limit"}},
        {"n": 400, "refused": "model: nv = 400 is too big"},
        {"n": 1000, "refused": "model: nv = 1000 is too big"},
    ]
    results = types.SimpleNamespace(scaling=rows, config=config)
    assert report_goals.unfinished_chains(results) == (
        "300 links did not converge within 150 s; 400, 1000 links were refused"
    )
    results.scaling = rows[:1]
    assert report_goals.unfinished_chains(results) == ""


# --- the contact part (benchmarks/contact_drop.py) ---------------------------------------------

import contact_drop  # noqa: E402  (benchmarks/contact_drop.py)


@pytest.fixture(scope="module")
def contact():
    """The contact part's small sweep, measured alone (no C++ program): a few seconds."""
    if not HAS_MUJOCO and os.environ.get("PINSETTLE_REQUIRE_MUJOCO") == "1":
        pytest.fail("MuJoCo is required here (PINSETTLE_REQUIRE_MUJOCO=1) but is not installed")
    return contact_drop.measure(contact_drop.QUICK)


def _go1_weight():
    """go1's weight from its URDF with Pinocchio alone (N)."""
    model = pinocchio.buildModelFromUrdf(
        str(pinsettle.robot_urdf("go1")), pinocchio.JointModelFreeFlyer()
    )
    return pinocchio.computeTotalMass(model) * 9.81


def test_the_contact_part_rests_on_the_floor(contact):
    # pinsettle's rest: converged, every contact point on or above the floor within 1e-6 m
    # (the gaps recomputed from Pinocchio's frames), the floor carrying the weight to 1e-9.
    weight = _go1_weight()
    assert [s["name"] for s in contact["scenes"]] == list(contact_drop.QUICK.scenes)
    for scene in contact["scenes"]:
        assert scene["weight"] == pytest.approx(weight, rel=1e-12)
        ours = scene["ours"]
        assert ours["status"] == "converged" and ours["closed"] == scene["contacts"]
        assert min(ours["gaps"]) >= -contact_drop.GAP_TOLERANCE
        assert abs(ours["normal_force"] - 1.0) <= 1e-9 and ours["com_height"] > 0
        assert len(ours["seconds"]) == contact_drop.QUICK.repeats * contact_drop.OURS_PER_ROUND
        assert all(s > 0 for s in ours["seconds"])
        # The step cost: four contacts closed at rest, none while falling free.
        cost = scene["step_cost"]
        assert cost["resting_closed"] == scene["contacts"] and cost["free_closed"] == 0
        assert cost["resting"] > 0 and cost["free"] > 0


@pytest.mark.skipif(not HAS_MUJOCO, reason="mujoco is not installed (pip install '.[test]')")
def test_mujocos_go1_is_pinocchios_and_carries_its_weight(contact):
    weight = _go1_weight()
    sweep = contact_drop.QUICK
    for scene in contact["scenes"]:
        check = scene["model_check"]
        # The same mechanism: mass, joints, axes, contact centres and centre of mass.
        assert check["mass_mujoco"] == pytest.approx(weight / 9.81, rel=1e-9)
        assert check["hinges"] == check["joints_pinocchio"] == 12
        assert check["axis"] <= 1e-12 and check["contact_centre"] <= 1e-12
        assert check["com"] <= 1e-12
        assert check["springs"] == 12 and check["spring"] <= 1e-12  # go1_standing's
        assert check["diagonal_inertia"] == ["base"]
        runs = scene["runs"]
        assert len(runs) == len(sweep.timesteps) * len(sweep.integrators) * len(sweep.dampings)
        done = contact_drop.at_rest(runs)
        assert done, scene["name"]
        for run in done:
            # At rest by its own static residual; its (soft) contacts carry the weight to 1 %
            # and sink in, by less than a centimetre.
            assert run["residual"] <= contact_drop.LEVEL
            assert abs(run["normal_force"] - 1.0) <= 1e-2
            assert 0 < run["penetration"] < 1e-2
            assert len(run["seconds"]) == sweep.repeats and run["time"] > 0
            assert run["sim_time"] == pytest.approx(run["steps"] * run["timestep"])
        # At its best: the fastest of the runs at rest on the floor (centre of mass above it).
        on_floor = [run for run in done if run["com_height"] > 0]
        assert contact_drop.best(runs)["time"] == min(run["time"] for run in on_floor)


def test_the_contact_section_is_a_well_formed_table(contact):
    text = contact_drop.section(contact)
    rows = [line for line in text.splitlines() if line.startswith("| `go1")]
    assert len(rows) == 2 * len(contact["scenes"])  # the comparison and the step cost
    header = next(line for line in text.splitlines() if line.startswith("| scene | contacts"))
    assert rows[0].count("|") == header.count("|")
    assert "nan" not in text
    if HAS_MUJOCO:
        assert f"MuJoCo {contact['mujoco']['version']}" in text
        assert "came to rest" in text


def test_mujocos_model_refuses_what_it_does_not_hold():
    with pytest.raises(ValueError, match="ur5: needs a URDF robot with a free-flyer root"):
        contact_drop.mujoco_model(pinsettle.load_scene("ur5"))


def test_the_contact_section_tells_rests_below_the_floor_apart():
    # Synthetic runs: MuJoCo's best is the fastest rest on the floor, not a faster one below
    # it; whole damping groups are named as such, the others listed.
    def run(dt, damping, status, time=None, com=0.2):
        return {
            "timestep": dt,
            "integrator": "Euler",
            "damping": damping,
            "status": status,
            "time": time,
            "com_height": com,
        }

    runs = [
        run(1e-3, 0.1, "at rest", 0.01, com=-0.2),
        run(2e-3, 0.1, "at rest", 0.02, com=-0.2),
        run(1e-3, 1.0, "at rest", 0.05),
        run(2e-3, 1.0, "not at rest"),
    ]
    assert contact_drop.best(runs) is runs[2]
    assert contact_drop.below(runs) == runs[:2]
    assert contact_drop._which(runs[:2], runs, "{time} s") == "every setting with damping 0.1"
    assert (
        contact_drop._which([runs[0], runs[3]], runs, "{status}")
        == "1 ms, Euler, damping 0.1 (at rest); 2 ms, Euler, damping 1 (not at rest)"
    )


def test_the_contact_part_says_when_mujoco_is_missing(monkeypatch):
    # Without MuJoCo the part still measures pinsettle and says what is missing.
    monkeypatch.setattr(contact_drop, "mujoco", None)
    sweep = contact_drop.Sweep(scenes=("go1_standing",), repeats=1, cost_steps=(50, 150))
    record = contact_drop.empty_record(sweep)
    record["scenes"] = [contact_drop.measure_scene("go1_standing", sweep)]
    assert record["scenes"][0]["runs"] == [] and record["scenes"][0]["ours"]["time"] > 0
    text = contact_drop.section(record)
    assert "MuJoCo was not measured: mujoco is not installed" in text
    assert "| not installed | - |" in text and "\n\n\n" not in text


@pytest.mark.parametrize("integrator", ["Euler", "implicitfast", "implicit"])
def test_mujocos_damped_step_is_the_momentum_descent_the_report_says(integrator):
    # The MuJoCo section explains its best settings by the step it takes with joint damping D:
    # v+ = (M + hD)^-1 (M v + h f), q+ = q + h v+, D taken implicitly by all three integrators.
    # From rest (no Coriolis force, f = gravity's) one step of MuJoCo itself must match it.
    pytest.importorskip("mujoco")
    import gallery
    import mujoco
    import mujoco_best

    m, why, _ = gallery.load_mujoco(pinsettle.robot_urdf("ur5"))
    assert m is not None, why
    diag = mujoco_best.mass_diagonal(m)
    setting = mujoco_best.Setting(0.3, integrator, "mass", 2.0)
    mujoco_best.configure(m, setting, diag)
    d = mujoco.MjData(m)
    d.qpos[:] = [0.3, -1.0, 0.8, 0.2, -0.5, 0.1]  # inside the limits: no constraint force
    mujoco.mj_forward(m, d)
    mass = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, mass)
    h, damping = setting.timestep, np.diag(setting.value * diag)
    expected_v = np.linalg.solve(mass + h * damping, -h * d.qfrc_bias)
    q = d.qpos.copy()
    mujoco.mj_step(m, d)
    assert np.allclose(d.qvel, expected_v, rtol=1e-9, atol=1e-12)
    assert np.allclose(d.qpos, q + h * expected_v, rtol=1e-12, atol=1e-12)
    # The momentum the section quotes for this setting, h a = 0.6: about 1 / (1 + h a).
    assert mujoco_best.damping_per_step(setting, diag) == pytest.approx(0.6)
    uniform = setting._replace(kind="uniform", value=0.5)
    assert mujoco_best.damping_per_step(uniform, diag) == pytest.approx(np.median(0.3 * 0.5 / diag))


def test_mujocos_best_counts_its_steps_exactly():
    # mujoco_best checks the residual every CHUNK steps; the best's step count is then made
    # exact. Checked here one step at a time on the UR5 at a setting that settles.
    pytest.importorskip("mujoco")
    import gallery
    import mujoco
    import mujoco_best

    m, why, _ = gallery.load_mujoco(pinsettle.robot_urdf("ur5"))
    assert m is not None, why
    diag = mujoco_best.mass_diagonal(m)
    mujoco_best.configure(m, mujoco_best.Setting(0.45, "Euler", "mass", 2.0), diag)
    check = mujoco_best.Checker(m, mujoco_best.force_scale(m))
    level = mujoco_best.LEVELS[-1]
    chunked = mujoco_best.run(m, check)["first"][level]
    assert chunked % mujoco_best.CHUNK == 0
    exact, qpos = mujoco_best.exact_first(m, check, chunked, level)
    d = mujoco.MjData(m)
    residuals, configurations = [], []
    for _ in range(chunked):
        mujoco.mj_step(m, d)
        residuals.append(check(d.qpos))
        configurations.append(d.qpos.copy())
    first = next(k + 1 for k, r in enumerate(residuals) if r <= level)
    assert exact == first and chunked - mujoco_best.CHUNK < exact <= chunked
    # ... with the configuration there, the same as the timed run's end after as many steps.
    assert np.array_equal(qpos, configurations[exact - 1])
    assert np.array_equal(qpos, mujoco_best.time_steps(m, exact, 1)[1])
    # A best the local search took past the grid is flagged as on its edge.
    low = mujoco_best.Setting(0.45, "Euler", "mass", mujoco_best.MASS[0] / 2)
    assert mujoco_best.edges(low) == [f"a = {low.value:g}"]


def test_mujocos_local_search_moves_downhill_and_samples_near_its_best():
    # mujoco_best's search after its grid, on a synthetic cost: a smooth bowl in (log h, log c)
    # plus a per-point ripple, as rugged as the steps to rest are near a limit.
    pytest.importorskip("mujoco")
    import mujoco_best as mb

    def ripple(s):
        return 0.3 * math.sin(37.0 * math.log(s.timestep)) * math.cos(23.0 * math.log(s.value))

    def bowl(s):
        return math.log(s.timestep / 0.05) ** 2 + math.log(s.value / 3.0) ** 2

    calls: list = []

    def cost(s):
        calls.append(s)
        return 100.0 * (1.5 + bowl(s) + ripple(s)) * (1.0 if s.integrator == "Euler" else 1.3)

    here = mb.Setting(0.2, "implicit", "mass", 30.0)
    around = mb.neighbours(here, 2.0)
    assert len(set(around)) == 11 and all(s.kind == "mass" for s in around)
    same = [s for s in around if s.integrator == here.integrator and s.tolerance == here.tolerance]
    assert {(s.timestep, s.value) for s in same} == {
        (here.timestep * a, here.value * b) for a in (2.0, 1.0, 0.5) for b in (2.0, 1.0, 0.5)
    } - {(here.timestep, here.value)}
    # the same setting at the other solver tolerance is a neighbour too
    assert here._replace(tolerance=mb.TIGHT) in around
    assert mb.neighbours(here._replace(tolerance=mb.TIGHT), 2.0)[-1] == here
    end = mb.step_down(here, cost, 2.0**0.25, lambda: True)
    # Downhill to a point no neighbour improves on, with Euler's cheaper steps.
    assert cost(end) < cost(here) and end.integrator == "Euler"
    assert all(cost(s) >= cost(end) for s in mb.neighbours(end, 2.0**0.25))

    # The scatter: SCATTER draws around each of the best (here two), within SCATTER_SPAN in
    # the step and the damping, any integrator, the same draws each run; the search from the
    # best of them ends where no neighbour at the smallest factor is faster.
    def run_scatter():
        book = {s: cost(s) for s in [here, end]}

        def scored_cost(s):
            book.setdefault(s, cost(s))
            return book[s]

        calls.clear()
        mb.scatter(book, scored_cost)
        return list(calls), book

    made, book = run_scatter()
    span = mb.SCATTER_SPAN * (1 + 1e-12)
    for centre, drawn in ((end, made[: mb.SCATTER]), (here, made[mb.SCATTER : 2 * mb.SCATTER])):
        assert all(s.kind == "mass" for s in drawn)
        assert all(1 / span <= s.timestep / centre.timestep <= span for s in drawn)
        assert all(1 / span <= s.value / centre.value <= span for s in drawn)
        assert {s.integrator for s in drawn} == set(mb.INTEGRATOR_NAMES)
        assert {s.tolerance for s in drawn} == set(mb.TOLERANCES)
    best = min(book, key=book.get)
    assert book[best] <= min(book[s] for s in made[: 2 * mb.SCATTER])
    assert all(cost(s) >= book[best] for s in mb.neighbours(best, mb.REFINE_FACTORS[-1]))
    assert run_scatter()[0][: 2 * mb.SCATTER] == made[: 2 * mb.SCATTER]


def test_mujocos_residual_on_a_limit_is_solved_to_convergence():
    # talos_left_arm at a setting the sweep met, after 1860 steps, rests on a limit: MuJoCo's
    # constraint solver at its default tolerance takes no iteration there and reads qacc = 0,
    # a residual of 0 between checks of 5e-9. Both scripts' checks solve it to convergence and
    # leave the model's solver settings as they were.
    pytest.importorskip("mujoco")
    import copy

    import gallery
    import mujoco
    import mujoco_best
    import mujoco_outside

    m, why, _ = gallery.load_mujoco(pinsettle.robot_urdf("talos_left_arm"))
    assert m is not None, why
    setting = mujoco_best.Setting(0.2, "Euler", "mass", 0.03 * 2**0.5)
    mujoco_best.configure(m, setting, mujoco_best.mass_diagonal(m))
    d = mujoco.MjData(m)
    mujoco.mj_step(m, d, nstep=1860)
    scale = mujoco_best.force_scale(m)
    fresh = mujoco.MjData(m)
    fresh.qpos[:] = d.qpos
    mujoco.mj_forward(m, fresh)
    assert fresh.nefc > 0 and fresh.solver_niter[0] == 0 and not np.any(fresh.qacc)
    kept = (m.opt.tolerance, m.opt.ls_tolerance, m.opt.iterations)
    best = mujoco_best.Checker(m, scale)(d.qpos)
    outside = mujoco_outside.static_residual(m, mujoco.MjData(m), d.qpos, scale)
    assert (m.opt.tolerance, m.opt.ls_tolerance, m.opt.iterations) == kept
    # The converged solve, from another model whose solver settings are tight for good.
    tight = copy.copy(m)
    tight.opt.tolerance, tight.opt.iterations = 1e-15, 1000
    again = mujoco.MjData(tight)
    again.qpos[:] = d.qpos
    mujoco.mj_forward(tight, again)
    force = np.zeros(m.nv)
    mujoco.mj_mulM(tight, again, force, again.qacc)
    expected = np.max(np.abs(force)) / scale
    assert 1e-9 < expected < 1e-7
    assert best == pytest.approx(expected, rel=1e-6)
    assert outside == pytest.approx(expected, rel=1e-6)


def test_mujocos_stopping_rule_is_the_static_residual_pinocchio_gives():
    # benchmarks/mujoco_best.py stops MuJoCo at the same static residual as pinsettle: M qacc
    # at zero velocity. Off the limits that is gravity's generalized force, recomputed here by
    # Pinocchio on the same URDF at random configurations.
    pytest.importorskip("mujoco")  # the test extra installs it
    import gallery
    import mujoco_best

    m, why, _ = gallery.load_mujoco(pinsettle.robot_urdf("ur5"))
    assert m is not None, why
    model = pinsettle.load_robot("ur5", floating=False)
    data = model.createData()
    check = mujoco_best.Checker(m, 1.0)
    rng = np.random.default_rng(4)
    for _ in range(5):
        qpos = rng.uniform(-2.0, 2.0, m.nq)  # inside the UR5's limits of 2 pi
        q = gallery.mujoco_q(m, qpos, model)
        gravity = pinocchio.computeGeneralizedGravity(model, data, q)
        assert check(qpos) == pytest.approx(np.max(np.abs(gravity)), rel=1e-9)


def test_mujocos_best_sweeps_and_applies_the_solver_tolerance():
    # mujoco_best's grid: every setting at MuJoCo's default solver tolerance, TIGHT_INTEGRATORS'
    # at TIGHT too; configure puts the tolerance into the model, the label says it.
    pytest.importorskip("mujoco")
    import gallery
    import mujoco
    import mujoco_best as mb

    settings = mb.sweep_settings()
    default = [s for s in settings if s.tolerance == mb.DEFAULT_TOLERANCE]
    tight = [s for s in settings if s.tolerance == mb.TIGHT]
    assert len(default) + len(tight) == len(settings) == len(set(settings))
    assert {s.integrator for s in tight} == set(mb.TIGHT_INTEGRATORS)
    assert {s.twin() for s in tight} == {s for s in default if s.integrator in mb.TIGHT_INTEGRATORS}
    m, why, _ = gallery.load_mujoco(pinsettle.robot_urdf("talos_left_arm"))
    assert m is not None, why
    assert mb.DEFAULT_TOLERANCE == m.opt.tolerance  # MuJoCo's own default
    diag = mb.mass_diagonal(m)
    setting = mb.Setting(0.2, "Euler", "mass", 0.0424, mb.TIGHT)
    mb.configure(m, setting, diag)
    assert m.opt.tolerance == mb.TIGHT and setting.label().endswith(", tol 1e-10")
    check = mb.Checker(m, mb.force_scale(m))
    # On talos_left_arm's limits the tight solve reaches 1e-10 within 2500 steps and stays
    # below it; at the default the same setting's residual wanders between about 1e-10 and
    # 1e-8 (below 1e-10 at a lucky step only). The check leaves the configured tolerance.
    reached = mb.run(m, check, 2500)
    assert m.opt.tolerance == mb.TIGHT
    assert reached["status"] == "reached" and reached["constrained"]

    def tail(s):
        mb.configure(m, s, diag)
        d = mujoco.MjData(m)
        mujoco.mj_step(m, d, nstep=2400)
        out = []
        for _ in range(60):
            mujoco.mj_step(m, d, nstep=mb.CHUNK)
            out.append(check(d.qpos))
        assert m.opt.tolerance == s.tolerance
        return np.array(out)

    assert tail(setting).max() <= mb.LEVELS[-1]
    loose = tail(setting.twin())
    assert loose.max() > 10 * mb.LEVELS[-1] and np.mean(loose <= mb.LEVELS[-1]) < 0.1
    # A run with no constraint row is the same at either tolerance, so its twin is copied.
    u, why, _ = gallery.load_mujoco(pinsettle.robot_urdf("ur5"))
    assert u is not None, why
    free = mb.Setting(0.45, "Euler", "mass", 2.0)
    runs = {}
    for s in (free, free.twin()):
        mb.configure(u, s, mb.mass_diagonal(u))
        runs[s] = mb.run(u, mb.Checker(u, mb.force_scale(u)))
        d = mujoco.MjData(u)
        mujoco.mj_step(u, d, nstep=runs[s]["steps"])
        runs[s]["qpos"] = d.qpos.copy()
    assert not runs[free]["constrained"]
    assert np.array_equal(runs[free]["qpos"], runs[free.twin()]["qpos"])
    assert mb.copied(free, runs[free]) == runs[free] | {"twin": free}
    assert mb.copied(setting, reached) is None

"""benchmarks/mujoco_outside.py, the outside check of MuJoCo's best: its residual against
Pinocchio's gravity, its reading of the section's table, a small search whose best is replayed
from the start, and its writing of the block. Fast (a few seconds), no timing assertions.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

import mujoco  # noqa: E402
import pinocchio  # noqa: E402
import pinsettle  # noqa: E402

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import mujoco_outside as mo  # noqa: E402  (benchmarks/mujoco_outside.py)
from gallery import mujoco_q, rest_check  # noqa: E402  (benchmarks/gallery.py)
from independent import CachedReference  # noqa: E402  (benchmarks/independent.py)


def test_residual_is_pinocchio_gravity_over_the_scale() -> None:
    """Inside the limits, at rest, the net force is gravity alone: the residual is max |g(q)|
    (Pinocchio's) over max |g(q0)|, whatever the damping setting."""
    urdf = pinsettle.robot_urdf("ur5")
    bench = mo.Bench(urdf)
    model = pinocchio.buildModelFromUrdf(str(urdf))
    data = model.createData()
    scale = np.max(
        np.abs(pinocchio.computeGeneralizedGravity(model, data, pinocchio.neutral(model)))
    )
    assert bench.scale == pytest.approx(scale, rel=1e-9)
    bench.configure(mo.Setting(0.3, "implicit", "mass", 2.0))
    m = bench.model
    low, high = m.jnt_range[:, 0], m.jnt_range[:, 1]
    assert np.all(m.jnt_limited) and np.all(high > low)
    rng = np.random.default_rng(7)
    scratch = mujoco.MjData(m)
    for _ in range(20):
        qpos = low + (high - low) * rng.uniform(0.05, 0.95, m.nq)
        gravity = pinocchio.computeGeneralizedGravity(model, data, mujoco_q(m, qpos, model))
        expected = np.max(np.abs(gravity)) / scale
        got = mo.static_residual(m, scratch, qpos, bench.scale)
        assert got == pytest.approx(expected, rel=1e-8, abs=1e-14)
        assert bench.residual(qpos) == got


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("458.502 ms, Euler, a = 2.12132/s", mo.Setting(0.458502, "Euler", "mass", 2.12132)),
        ("1 ms, Euler, c = 0.1", mo.Setting(1e-3, "Euler", "uniform", 0.1)),
        (
            "25.9368 ms, implicit, a = 5.04538/s",
            mo.Setting(25.9368e-3, "implicit", "mass", 5.04538),
        ),
        ("200 ms, implicitfast, a = 30/s", mo.Setting(0.2, "implicitfast", "mass", 30.0)),
        ("5000 ms, implicitfast, c = 10", mo.Setting(5.0, "implicitfast", "uniform", 10.0)),
        # mujoco_best's labels, with the solver tolerance
        (
            "29.5365 ms, Euler, a = 0.771105/s, tol 1e-10",
            mo.Setting(29.5365e-3, "Euler", "mass", 0.771105, 1e-10),
        ),
        ("1 ms, Euler, c = 0.03, tol 1e-08", mo.Setting(1e-3, "Euler", "uniform", 0.03, 1e-8)),
        (
            "204.151 ms, implicitfast, a = 0.0139412/s, tol 3.16e-11",
            mo.Setting(0.204151, "implicitfast", "mass", 0.0139412, 3.16e-11),
        ),
    ],
)
def test_parse_setting(text: str, expected: mo.Setting) -> None:
    got = mo.parse_setting(text)
    assert got.integrator == expected.integrator and got.kind == expected.kind
    assert got.timestep == pytest.approx(expected.timestep, rel=1e-12)
    assert got.value == pytest.approx(expected.value, rel=1e-12)
    # without ", tol ..." it is MuJoCo's default
    assert got.tolerance == pytest.approx(expected.tolerance, rel=1e-12)
    if ", tol " not in text:
        assert got.tolerance == mujoco.MjModel.from_xml_string("<mujoco/>").opt.tolerance
    # its label reads back to itself
    assert mo.parse_setting(got.label()) == got


@pytest.mark.parametrize(
    "text",
    [
        "no valid rest reached 1e-06",
        "458.502 ms, RK4, a = 2.12132/s",
        "1 ms, Euler, b = 0.1",
        "1 ms Euler c = 0.1",
        "1 s, Euler, c = 0.1",
        "1 ms, Euler, a = 0.1",  # a without its unit
        "0 ms, Euler, c = 0.1",
        "1 ms, Euler, c = 0",
        "1 ms, Euler, c = 0.1, tol",
        "1 ms, Euler, c = 0.1 tol 1e-10",
        "1 ms, Euler, c = 0.1, tolerance 1e-10",
        "",
    ],
)
def test_parse_setting_rejects(text: str) -> None:
    with pytest.raises(ValueError, match="not a MuJoCo setting"):
        mo.parse_setting(text)


SECTION = """\
# Benchmarks

<!-- mujoco:best (written by benchmarks/mujoco_best.py) -->
## MuJoCo at its best, per robot

| robot | nv | MuJoCo best setting | level | steps | simulated (s) | MuJoCo (ms) | more |
|---|---|---|---|---|---|---|---|
| asr_twodof | 2 | 1 ms, Euler, c = 0.1 | 1e-10 | 10 | 0.01 | 0.0327 | x |
| kinova | 6 | no valid rest reached 1e-06 | | | | | x |
| xarm7 | 7 | 20 ms, Euler, a = 0.3/s | 1e-08 | 17020 | 340 | 95.9 ± 6% | x |
| panda | 9 | 29.5 ms, Euler, a = 0.77/s, tol 1e-10 | 1e-10 | 1125 | 33.2 | 7 ± 1% | x |

Prose.
<!-- /mujoco:best -->
"""


def test_parse_section() -> None:
    rows = mo.parse_section(SECTION)
    assert [row.robot for row in rows] == ["asr_twodof", "xarm7", "panda"]
    assert rows[0] == mo.Recorded(
        "asr_twodof", mo.Setting(1e-3, "Euler", "uniform", 0.1), 1e-10, 10, 0.0327
    )
    assert rows[1].setting == mo.Setting(0.02, "Euler", "mass", 0.3)
    assert (rows[1].level, rows[1].steps, rows[1].ms) == (1e-8, 17020, 95.9)
    assert rows[2].setting == mo.Setting(29.5 * 1e-3, "Euler", "mass", 0.77, 1e-10)


def test_mujoco_best_labels_read_back() -> None:
    # The section's labels are mujoco_best's: each reads back to the same setting.
    import mujoco_best as mb

    chosen = [*mb.sweep_settings()[::37], mb.Setting(0.02953652292, "Euler", "mass", 0.7711054127)]
    assert {s.tolerance for s in chosen} == set(mb.TOLERANCES)
    for setting in chosen:
        got = mo.parse_setting(setting.label())
        assert (got.integrator, got.kind) == (setting.integrator, setting.kind)
        assert got.tolerance == setting.tolerance, setting.label()
        assert got.timestep == pytest.approx(setting.timestep, rel=1e-9)
        assert got.value == pytest.approx(setting.value, rel=1e-9)


def test_the_tolerance_is_applied_and_tight_settles_where_the_default_wanders() -> None:
    # talos_left_arm settles onto a soft limit: a step's constraint solve stops at the solver
    # tolerance. At MuJoCo's default (1e-8) the residual, checked after every step, wanders
    # between about 1e-10 and 1e-8 and only dips below 1e-10 at a lucky step; at 1e-10 the same
    # setting settles below 1e-10 and stays there.
    urdf = pinsettle.robot_urdf("talos_left_arm")
    bench = mo.Bench(urdf)
    tight = mo.Setting(0.2, "Euler", "mass", 0.0424, 1e-10)
    bench.configure(tight._replace(tolerance=3e-12))
    assert bench.model.opt.tolerance == 3e-12

    def tail(setting: mo.Setting) -> np.ndarray:
        bench.configure(setting)
        assert bench.model.opt.tolerance == setting.tolerance
        d = mujoco.MjData(bench.model)
        mujoco.mj_step(bench.model, d, nstep=2400)
        residuals = []
        for _ in range(600):
            mujoco.mj_step(bench.model, d)
            residuals.append(bench.residual(d.qpos))
            assert bench.model.opt.tolerance == setting.tolerance  # the check restores it
        return np.array(residuals)

    at_tight = tail(tight)
    at_default = tail(tight._replace(tolerance=mo.MUJOCO_TOLERANCE))
    assert at_tight.max() <= mo.LEVEL
    assert at_default.max() > 10 * mo.LEVEL and np.mean(at_default <= mo.LEVEL) < 0.05
    reached = mo.settle(bench, tight, mo.LEVEL, cap=2500)
    assert reached.status == "reached"
    assert mo.replay(bench, tight, reached.steps, mo.LEVEL)["first"] == reached.steps


def test_the_search_spans_the_tolerance() -> None:
    # The sample and Nelder-Mead move in (log timestep, log damping, log tolerance).
    low, high = mo.TOLERANCE_RANGE
    assert len(mo.bounds("mass")) == 3 and mo.bounds("mass")[2] == pytest.approx(
        (np.log(low), np.log(high))
    )
    s = mo.setting_at(("Euler", "mass"), np.array([np.log(0.1), np.log(2.0), np.log(1e-10)]))
    assert s == mo.Setting(
        pytest.approx(0.1), "Euler", "mass", pytest.approx(2.0), pytest.approx(1e-10)
    )
    clipped = mo.setting_at(("Euler", "mass"), np.array([0.0, 0.0, 0.0]))
    assert clipped.tolerance == pytest.approx(high)


def test_parse_section_rejects() -> None:
    with pytest.raises(ValueError, match=r"not a MuJoCo setting: '1 ms, Euler, c = oops'"):
        mo.parse_section(SECTION.replace("1 ms, Euler, c = 0.1", "1 ms, Euler, c = oops"))
    with pytest.raises(ValueError, match="no column level"):
        mo.parse_section(SECTION.replace("| level |", "| lvl |"))
    with pytest.raises(ValueError, match="no section"):
        mo.parse_section("# Benchmarks\n")


def test_small_search_reaches_the_level_at_a_valid_rest() -> None:
    urdf = pinsettle.robot_urdf("double_pendulum")
    search = mo.search_robot(mo.Bench(urdf), mo.Judge(urdf), mo.LEVEL, budget=30, seed=1)
    assert len(search.runs) <= 30
    best = mo.best_valid(search)
    assert best is not None
    setting, run = best
    assert run.status == "reached" and 0 < run.steps < mo.MAX_STEPS
    # from the start again, on a fresh model, for its step count: the level, recomputed
    bench = mo.Bench(urdf)
    bench.configure(setting)
    d = mujoco.MjData(bench.model)
    mujoco.mj_step(bench.model, d, nstep=run.steps)
    scratch = mujoco.MjData(bench.model)
    assert mo.static_residual(bench.model, scratch, d.qpos, bench.scale) <= mo.LEVEL
    # and not one step earlier (the step count is exact)
    mujoco.mj_resetData(bench.model, d)
    mujoco.mj_step(bench.model, d, nstep=run.steps - 1)
    assert mo.static_residual(bench.model, scratch, d.qpos, bench.scale) > mo.LEVEL
    ref = CachedReference(pinocchio.buildModelFromUrdf(str(urdf)))
    check = rest_check(ref, mujoco_q(bench.model, run.qpos, ref.full))
    assert check["outside"] <= mo.OUTSIDE_TOL and check["stability"] != "unstable"
    replayed = mo.replay(bench, setting, run.steps, mo.LEVEL)
    assert replayed["first"] == run.steps


OTHER = "<!-- mujoco:other -->\nkept\n<!-- /mujoco:other -->\n"


def test_put_block_inserts_then_replaces(tmp_path: Path) -> None:
    doc = tmp_path / "benchmarks.md"
    head = SECTION
    doc.write_text(head + "\n" + OTHER, encoding="utf-8")
    first = f"{mo.BEGIN}\n### An outside check of MuJoCo's best\n\none\n{mo.END}\n"
    mo.put_block(first, doc)
    assert doc.read_text(encoding="utf-8") == head + "\n" + first + "\n" + OTHER
    second = f"{mo.BEGIN}\n### An outside check of MuJoCo's best\n\ntwo\nlines\n{mo.END}\n"
    mo.put_block(second, doc)
    assert doc.read_text(encoding="utf-8") == head + "\n" + second + "\n" + OTHER
    mo.put_block(second, doc)  # idempotent
    assert doc.read_text(encoding="utf-8").count(mo.BEGIN) == 1
    # at the very end of a file
    doc.write_text(head, encoding="utf-8")
    mo.put_block(first, doc)
    assert doc.read_text(encoding="utf-8") == head + "\n" + first
    doc.write_text("# nothing to follow\n", encoding="utf-8")
    with pytest.raises(ValueError, match="no line"):
        mo.put_block(first, doc)


def test_a_best_that_does_not_replay_is_no_agreement() -> None:
    # Rows as compare() makes them: the section's best agrees only when, run again from the
    # start, it reaches its level at a valid rest within its steps, and is within AGREE times
    # of the outside best (or the outside found none).
    setting = mo.Setting(0.5, "Euler", "mass", 2.0)

    def row(robot: str, section_s: float, outside_s: float | None, first: int | None) -> dict:
        made = {
            "recorded": mo.Recorded(robot, setting, 1e-10, 60, 0.3),
            "level": 1e-10,
            "runs": 250,
            "replayed": {"first": first, "valid": True},
            "best": None if outside_s is None else (setting, 50),
            "section_s": section_s,
        }
        return made if outside_s is None else made | {"outside_s": outside_s}

    rows = [
        row("fast", 1.0, 1.0, 55),
        row("slow", 2.0, 1.0, 58),
        row("lucky", 1.0, None, None),
        row("alone", 1.0, None, 60),
    ]
    assert [mo.agrees(r) for r in rows] == [True, False, False, True]
    text = "\n".join(mo.closing(rows))
    assert "on 2 of 4 robots; not on slow (2.00); lucky (its setting does not replay)." in text
    assert "The outside search reached no valid rest on: lucky, alone; there the" in text
    assert "does NOT reach its level at a valid rest within its steps on: lucky." in text
    assert mo.table_row(rows[2]).endswith("| **no** |")


def test_a_diverging_setting_leaves_no_mujoco_log(tmp_path, monkeypatch) -> None:
    # A step of 0.5 s without damping: the double pendulum blows up within a few steps, and
    # MuJoCo, stepped plainly, appends its warning to MUJOCO_LOG.TXT in the working directory.
    urdf = pinsettle.robot_urdf("double_pendulum")
    bench = mo.Bench(urdf)
    wild = mo.Setting(0.5, "Euler", "uniform", 0.0)
    plain, searched = tmp_path / "plain", tmp_path / "searched"
    plain.mkdir()
    searched.mkdir()
    monkeypatch.chdir(plain)
    bench.configure(wild)
    d = mujoco.MjData(bench.model)
    mujoco.mj_step(bench.model, d, nstep=50)
    assert d.warning[int(mujoco.mjtWarning.mjWARN_BADQACC)].number > 0
    assert (plain / "MUJOCO_LOG.TXT").exists()
    # The search's run of the same setting sees the divergence and writes no log.
    monkeypatch.chdir(searched)
    assert mo.settle(bench, wild, mo.LEVEL, cap=50).status == "diverged"
    assert not (searched / "MUJOCO_LOG.TXT").exists()
    assert mujoco.get_mju_user_warning() is None  # the default put back

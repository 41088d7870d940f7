"""The ``pinsettle`` command line, run as ``python -m pinsettle`` in a subprocess."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pinsettle", *args],
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.fixture(scope="module")
def ur5_json() -> tuple[subprocess.CompletedProcess, dict]:
    proc = run("demo", "ur5", "--json")
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1, proc.stdout  # exactly one JSON object, nothing else on stdout
    return proc, json.loads(lines[0])


def test_demo_json(ur5_json):
    proc, out = ur5_json
    assert proc.returncode == 0, proc.stderr
    assert out["status"] == "converged" and out["converged"] is True
    assert out["residual"] < 1e-5
    assert out["steps"] > 0 and out["peaks"] > 0


def test_demo_json_joints_match_q_and_are_an_equilibrium(ur5_json, ur5):
    _, out = ur5_json
    names = [ur5.names[j] for j in range(1, ur5.njoints)]
    assert list(out["joints"]) == names
    q = np.array(out["q"])
    assert q.shape == (ur5.nq,)
    assert [out["joints"][name] for name in names] == out["q"]  # all 1-dof joints
    # The answer recomputed with pinocchio, outside pinsettle: a static equilibrium.
    g = pinocchio.computeGeneralizedGravity(ur5, ur5.createData(), q)
    assert np.max(np.abs(g)) == pytest.approx(out["residual"], rel=1e-9)
    assert np.max(np.abs(g)) < 1e-5


def test_demo_json_free_flyer_joint_is_a_list():
    # A multi-dof joint appears as the list of its q entries. Nothing holds the floating
    # quadruped: the run ends at once, naming its root.
    proc = run("demo", "solo12", "--json", "--max-steps", "50")
    assert proc.returncode == 1  # not converged
    out = json.loads(proc.stdout)
    assert out["status"] == "no_equilibrium" and out["steps"] == 0
    assert "'root_joint'" in out["reason"]
    root = out["joints"]["root_joint"]
    assert isinstance(root, list) and len(root) == 7
    # By name the quaternion is w first (MuJoCo's qpos); q keeps Pinocchio's order, w last.
    q = out["q"]
    assert root == [*q[:3], q[6], *q[3:6]]


def test_demo_flags_reach_the_solver():
    proc = run("demo", "double_pendulum", "--json", "--kt", "0", "--max-e", "1e-16")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    # Same answer as the library with the same settings.
    model = pinsettle.load_robot("double_pendulum")
    result = pinsettle.solve(model, kt=0.0, max_e=1e-16)
    assert out["steps"] == result.steps
    assert out["q"] == pytest.approx(result.q.tolist(), abs=1e-12)


@pytest.mark.parametrize(
    "flags, settings",
    [
        (["--dt", "2e-3"], {"dt": 2e-3}),
        (["--dt-safety", "0.1"], {"dt_safety": 0.1}),
        (["--dt-growth", "1.5"], {"dt_growth": 1.5}),
        (["--polish"], {"polish": True}),
        (["--no-polish"], {"polish": False}),
        (["--no-backtrack"], {"backtrack": False}),
        (["--scale-joint-inertia"], {"scale_joint_inertia": True}),
        (["--no-scale-joint-inertia"], {"scale_joint_inertia": False}),
        (["--no-newton-takeover"], {"newton_takeover": False}),
    ],
)
def test_demo_step_flags_reach_the_solver(flags, settings):
    proc = run("demo", "double_pendulum", "--json", *flags)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    result = pinsettle.solve(pinsettle.load_robot("double_pendulum"), **settings)
    assert out["steps"] == result.steps and out["dt"] == result.dt
    assert out["polished"] == result.polished


def test_scale_stiff_modes_flag(tmp_path):
    # A 1e6 N m/rad joint spring on the double pendulum's second joint: a mode far faster than
    # the first joint's swing. Slowed by default, resolved with --no-scale-stiff-modes.
    scene = tmp_path / "stiff.toml"
    scene.write_text(
        '[model]\nrobot = "double_pendulum"\n[start]\njoint1 = 1.0\n'
        '[[joint_spring]]\njoint = "joint2"\nstiffness = 1e6\n',
        encoding="utf-8",
    )
    outs = {}
    for flag in ("--scale-stiff-modes", "--no-scale-stiff-modes"):
        proc = run("solve", str(scene), "--json", flag)
        assert proc.returncode == 0, proc.stderr
        outs[flag] = json.loads(proc.stdout)
    scaled, plain = outs["--scale-stiff-modes"], outs["--no-scale-stiff-modes"]
    assert scaled["scaled_modes"] == 1 and plain["scaled_modes"] == 0
    assert scaled["dt"] > 100 * plain["dt"] and scaled["steps"] < plain["steps"]
    # The same rest either way.
    assert scaled["q"] == pytest.approx(plain["q"], abs=1e-4)  # both polished from max_e = 1e-6 J


def test_demo_text_output():
    proc = run("demo", "double_pendulum")
    assert proc.returncode == 0, proc.stderr
    assert "status           converged" in proc.stdout
    assert "joint1" in proc.stdout and "joint2" in proc.stdout
    assert "recomputed with pinocchio" in proc.stdout


def test_demo_text_gives_units_and_names_the_free_joints(ur5_json):
    proc = run("demo", "ur5")
    assert proc.returncode == 0, proc.stderr
    out = ur5_json[1]
    lines = {line[:17].strip(): line[17:] for line in proc.stdout.splitlines()}
    assert lines["residual"].startswith(f"{out['residual']:.3e} N m (max |net static"), lines
    assert lines["check"] == f"|g(q)| = {out['residual']:.3e} N m recomputed with pinocchio"
    assert lines["stability"] == (
        "neutral (smallest stiffness eigenvalue 0 N m/rad: 3 directions free to move at no "
        "cost, moving shoulder_pan_joint, wrist_2_joint, wrist_3_joint)"
    )
    # The JSON keeps its fields: the raw smallest eigenvalue and the count.
    assert out["stability"] == "neutral" and out["neutral_directions"] == 3
    assert "min_stiffness_eigenvalue" in out


def test_demo_not_converged_exits_1():
    proc = run("demo", "ur5", "--max-steps", "5")
    assert proc.returncode == 1
    assert "status           max_steps" in proc.stdout


def test_demo_unknown_robot_exits_2_without_traceback():
    proc = run("demo", "nosuchrobot")
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert "unknown robot 'nosuchrobot'" in proc.stderr
    assert "ur5" in proc.stderr  # lists the known names
    assert "Traceback" not in proc.stderr


def test_demo_bad_setting_exits_2_without_traceback():
    proc = run("demo", "ur5", "--kt", "1.5")
    assert proc.returncode == 2
    assert "kt must be in [0, 1)" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_bad_flag_value_is_an_argparse_error():
    proc = run("demo", "ur5", "--kt", "abc")
    assert proc.returncode == 2
    assert "--kt" in proc.stderr and "Traceback" not in proc.stderr


def test_no_command_is_a_usage_error():
    proc = run()
    assert proc.returncode == 2
    assert "usage:" in proc.stderr


def test_robots_lists_the_names():
    proc = run("robots")
    assert proc.returncode == 0
    rows = dict(line.split(None, 1) for line in proc.stdout.strip().splitlines())
    assert sorted(rows) == pinsettle.robot_names()
    assert rows["ur5"] == "fixed base"
    assert rows["solo12"] == "floating base"


def test_cmake_dir():
    proc = run("cmake-dir")
    assert proc.returncode == 0
    folder = Path(proc.stdout.strip())
    assert folder.is_dir()
    assert (folder / "pinsettleConfig.cmake").is_file()
    assert str(folder) == pinsettle.get_cmake_dir()


# --- Ctrl-C on pinsettle solve ----------------------------------------------------------------


def _restore_sigint() -> None:
    # In the child before it runs: Python's own Ctrl-C handling, whoever started pytest (a
    # shell's background job starts it with SIGINT ignored, and Python then leaves it so).
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture(scope="module")
def swinging_chain(tmp_path_factory, chain_urdf) -> tuple[Path, pinocchio.Model]:
    """A 30-link chain released horizontal with a fixed step of 10 us and max_e = 0: still
    swinging seconds later (a tenth of a second simulated per second), and only a signal ends
    its run."""
    folder = tmp_path_factory.mktemp("ctrl_c")
    (folder / "chain30.urdf").write_text(chain_urdf(30), encoding="utf-8")
    scene = folder / "chain30.toml"
    scene.write_text(
        '[model]\nurdf = "chain30.urdf"\n[start]\njoint1 = 1.5707963267948966\n'
        "[solver]\ndt = 1e-5\nmax_e = 0\nmax_steps = 1000000000000\nnewton_takeover = false\n",
        encoding="utf-8",
    )
    return scene, pinocchio.buildModelFromUrdf(str(folder / "chain30.urdf"))


@pytest.mark.skipif(sys.platform == "win32", reason="sends SIGINT")
@pytest.mark.parametrize("output", ["json", "text"])
def test_ctrl_c_stops_a_solve_and_prints_where_it_stood(output, swinging_chain):
    # Ctrl-C must end the run within a check interval, with the README's exit status for a run
    # that did not converge (1), status 'aborted', no traceback, and the state the chain stood
    # in (still moving), printed as a finished run's is.
    scene, model = swinging_chain
    flags = ["--json"] if output == "json" else []
    proc = subprocess.Popen(
        [sys.executable, "-m", "pinsettle", "solve", str(scene), *flags],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_restore_sigint,
    )
    try:
        time.sleep(2.0)  # start-up (~1 s here), then solving
        assert proc.poll() is None, proc.communicate()  # still solving
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            pytest.fail("pinsettle solve still ran 10 s after Ctrl-C")
        stopped = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert stopped < 5.0, stopped  # measured 0.1 s
    assert proc.returncode == 1, (proc.returncode, out, err)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    names = [model.names[j] for j in range(1, model.njoints)]
    if output == "text":
        assert "status           aborted" in out, out
        for name in names:
            assert re.search(rf"^\s+{name}\s+-?\d+\.\d+", out, re.MULTILINE), (name, out)
        return
    lines = out.strip().splitlines()
    assert len(lines) == 1, out  # exactly one JSON object
    state = json.loads(lines[0])
    assert state["status"] == "aborted" and state["converged"] is False
    assert state["steps"] > 0 and state["sim_time_s"] > 0 and state["wall_time_s"] >= 1.0
    assert state["kinetic_energy"] > 0.0  # caught moving: no rest
    q = np.array(state["q"])
    assert q.shape == (model.nq,) and list(state["joints"]) == names
    assert [state["joints"][name] for name in names] == state["q"]
    # The residual printed is that of the state printed, by Pinocchio's gravity there (the
    # chain's URDF has no stops), and far from a rest's.
    g = np.max(np.abs(pinocchio.computeGeneralizedGravity(model, model.createData(), q)))
    assert state["residual"] == pytest.approx(g, rel=1e-9) and g > 1e-3, (state["residual"], g)

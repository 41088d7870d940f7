"""The third-party model gallery: model files that ship with dm_control, gymnasium,
gymnasium-robotics and pybullet, each solved by ``pinsettle solve FILE --json`` as a user
would, and each answer judged by another library's physics (tests/third_party_models.py:
MuJoCo's static force for MJCF, Pinocchio's gravity with the file's mimic couplings for URDF).

The model packages come with the ``models`` extra (and the ``test`` extra). Without one of
them its files are skipped, except where PINSETTLE_REQUIRE_MODELS=1 (set by .ci/run): there a
missing package fails.
"""

from __future__ import annotations

import copy
import functools
import importlib.util
import os
from pathlib import Path
from typing import Any

import pytest
import third_party_models as gallery  # tests/third_party_models.py (tests/ is on sys.path)

REQUIRED = os.environ.get("PINSETTLE_REQUIRE_MODELS") == "1"


def _require(module: str, what: str) -> None:
    """Skip without the module, or fail where the models are required."""
    if importlib.util.find_spec(module) is not None:
        return
    message = f"{what} needs '{module}' (pip install '.[models]' or '.[test]')"
    if REQUIRED:
        pytest.fail(f"{message}: required here (PINSETTLE_REQUIRE_MODELS=1)")
    pytest.skip(message)


def test_gallery_has_at_least_40_files() -> None:
    files = {(case.package, case.path) for case in gallery.CASES}
    assert len(files) >= 40
    ids = [case.id for case in gallery.CASES]
    assert len(ids) == len(set(ids)), "a case is listed twice"
    assert {case.package for case in gallery.CASES} == set(gallery.PACKAGES)


@functools.cache
def _run(case: gallery.Case) -> gallery.Run:
    """The case's command, run once per session (the judge's own tests reuse answers)."""
    root = gallery.package_dir(case.package)
    assert root is not None
    return gallery.run_cli(root / case.path, case.floating, case.flags)


@pytest.mark.parametrize("case", gallery.CASES, ids=[case.id for case in gallery.CASES])
def test_third_party_file(case: gallery.Case) -> None:
    _require(case.package, case.id)
    _require("scipy", "the judge")
    if case.path.endswith(".xml"):
        _require("mujoco", "the MJCF judge")
    root = gallery.package_dir(case.package)
    assert root is not None
    path = root / case.path
    assert path.is_file(), f"{path} is not in the installed {gallery.PACKAGES[case.package]}"

    run = _run(case)
    command = f"pinsettle solve {case.id} --json"
    assert run.code is not None, (
        f"{command} did not end within {gallery.COMMAND_TIMEOUT:.0f} s: {run.stderr[-300:]}"
    )
    assert "Traceback" not in run.stderr, f"{command} crashed:\n{run.stderr[-2000:]}"

    if run.code == 2:
        assert case.may_refuse, f"{command} refused a file it must read: {run.stderr.strip()}"
        assert not run.stdout.strip(), f"a refusal printed on stdout: {run.stdout[:300]}"
        problems = gallery.refusal_problems(run, path.name)
        assert not problems, f"{command}: " + "; ".join(problems)
        return

    assert run.code in (0, 1), f"{command} exited {run.code}: {run.stderr[-500:]}"
    answer = run.answer
    assert answer is not None, f"{command} printed no JSON object: {run.stdout[:300]}"
    status = answer["status"]
    assert answer["converged"] == (status == "converged")
    assert (run.code == 0) == (status == "converged"), f"exit {run.code} with status {status}"

    verdict = gallery.judge(path, answer, case.floating)
    if verdict.falls:
        assert status == "no_equilibrium", (
            f"{command}: nothing holds the model against gravity, so no rest exists, but the "
            f"run ended {status} after {answer['wall_time_s']:.1f} s ({answer['steps']} steps, "
            f"residual {answer['residual']:.3g})"
        )
        assert run.cpu_seconds <= gallery.FALL_CPU_SECONDS, (
            f"{command}: the fall took {run.cpu_seconds:.1f} s of CPU time to call (the solve "
            f"{answer['wall_time_s']:.1f} s of wall time)"
        )
        assert not verdict.problems, f"{command}: " + "; ".join(verdict.problems)
        return

    assert status == "converged", (
        f"{command} ended {status} ({answer.get('reason') or 'no reason given'}; residual "
        f"{answer['residual']:.3g}) where a rest exists"
    )
    assert not verdict.problems, f"{command}: " + "; ".join(verdict.problems)
    # 'converged' is a rest by pinsettle's own measure too.
    assert answer["residual"] <= gallery.REL_TOL * verdict.scale, (
        f"{command}: converged with residual {answer['residual']:.3g} "
        f"(force scale {verdict.scale:.3g})"
    )


# --- the judge itself: right answers pass, wrong ones do not ----------------------------------


def _case(package: str, path: str, floating: bool = False) -> gallery.Case:
    case = next(
        c for c in gallery.CASES if (c.package, c.path, c.floating) == (package, path, floating)
    )
    _require(case.package, case.id)
    _require("scipy", "the judge")
    if path.endswith(".xml"):
        _require("mujoco", "the MJCF judge")
    return case


def _right_answer(case: gallery.Case) -> tuple[Path, dict[str, Any]]:
    run = _run(case)
    assert run.answer is not None and run.answer["converged"], run.stderr[-300:]
    root = gallery.package_dir(case.package)
    assert root is not None
    path = root / case.path
    verdict = gallery.judge(path, run.answer, case.floating)
    assert not verdict.falls and not verdict.problems, verdict.problems
    return path, run.answer


def _wrong(path: Path, answer: dict[str, Any], change: Any, floating: bool = False) -> list[str]:
    """The judge's problems with a changed copy of a right answer."""
    wrong = copy.deepcopy(answer)
    change(wrong)
    return gallery.judge(path, wrong, floating).problems


@pytest.mark.parametrize(
    ("package", "path", "moved"),
    [
        # MJCF: a hanging humanoid, hips and spine on stops; its knee swings free.
        ("dm_control", "locomotion/walkers/assets/humanoid_CMU_V2020.xml", "ltibiarx"),
        # URDF: the Panda, its shoulder on a stop, its second finger a mimic; the elbow free.
        ("pybullet_data", "franka_panda/panda.urdf", "panda_joint4"),
    ],
)
def test_judge_rejects_a_wrong_rest(package: str, path: str, moved: str) -> None:
    case = _case(package, path)
    file, answer = _right_answer(case)
    assert answer["at_limit"], "the judge's test needs a rest on a stop"
    assert moved in answer["joints"] and moved not in answer["at_limit"]
    stopped = next(iter(answer["at_limit"]))

    def move(a: dict[str, Any]) -> None:
        a["joints"][moved] += 1e-3

    def unlist(a: dict[str, Any]) -> None:  # the stop's reaction must then be balanced
        del a["at_limit"][stopped]

    def flip(a: dict[str, Any]) -> None:
        a["at_limit"][stopped] = "upper" if a["at_limit"][stopped] == "lower" else "lower"

    def misreport(a: dict[str, Any]) -> None:
        a["limit_reactions"][stopped] = 2.0 * a["limit_reactions"][stopped] + 1.0

    def drop(a: dict[str, Any]) -> None:
        del a["joints"][moved]

    # Each wrong answer is caught for its own reason: the net force off the stops, a stop that
    # would have to pull, a joint off the bound it is listed on, a wrong reaction, a joint left
    # out.
    for change, reason in (
        (move, "not a rest"),
        (unlist, "not a rest"),
        (flip, f"'{stopped}' listed at its"),
        (misreport, "stop reaction"),
        (drop, "missing"),
    ):
        problems = _wrong(file, answer, change)
        assert any(reason in p for p in problems), f"{case.id} {change.__name__}: {problems}"


def test_judge_applies_the_mimic_coupling() -> None:
    file, answer = _right_answer(_case("pybullet_data", "franka_panda/panda.urdf"))
    assert "panda_finger_joint2" in answer["joints"]

    def uncouple(a: dict[str, Any]) -> None:
        a["joints"]["panda_finger_joint2"] += 1e-3

    assert _wrong(file, answer, uncouple)


def test_judge_projects_onto_the_loop(tmp_path: Path) -> None:
    """A four-bar closed by a <connect>: at the rest MuJoCo's static force is not 0 (the loop
    holds part of it), the judge takes it; moved off the rest, or off the loop, it does not."""
    _require("mujoco", "the MJCF judge")
    _require("scipy", "the judge")
    file = tmp_path / "fourbar.xml"
    file.write_text(FOURBAR)
    run = gallery.run_cli(file, False)
    assert run.code == 0 and run.answer is not None, run.stderr
    answer = run.answer
    verdict = gallery.judge(file, answer, False)
    assert not verdict.problems and not verdict.falls, verdict.problems
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(file))
    d = mujoco.MjData(m)
    d.qpos[:] = [answer["joints"][n] for n in ("crank", "coupler", "rocker")]
    mujoco.mj_forward(m, d)
    assert abs(d.qfrc_bias).max() > 1e3 * gallery.REL_TOL * verdict.scale

    def move(a: dict[str, Any]) -> None:
        a["joints"]["crank"] += 1e-3

    problems = _wrong(file, answer, move)
    assert any("equality" in p for p in problems), problems


def test_weld_hung_arm_on_its_stops_comes_to_rest(tmp_path: Path) -> None:
    """Fetch's reach task in small: a heavy base on three slides hung from a light arm whose
    gripper is welded to the world, its lift joint pressed onto its upper stop. Each impact on a
    stop once handed energy from the light joints to the heavy base (the velocity was projected
    onto the loop in joint coordinates, not in the mass matrix's metric): the arm rang at its
    stops, with an energy peak every 4 steps, until max_steps. The ranges are in degrees
    (MJCF's default unit): the arm's joints hit their stops at once, and the weld closes only if
    the projection lets some of them leave their stop; pinning them all left the weld 0.054 open,
    and that was called converged. It must come to a rest that MuJoCo confirms (its static force
    balanced, its equality satisfied), with the lift joint on its stop."""
    _require("mujoco", "the MJCF judge")
    _require("scipy", "the judge")
    file = tmp_path / "hung_arm.xml"
    file.write_text(HUNG_ARM)
    run = gallery.run_cli(file, False, ("--max-steps", "50000"))
    assert run.answer is not None, run.stderr
    answer = run.answer
    assert answer["status"] == "converged", (answer["status"], answer["steps"], answer["residual"])
    assert answer["at_limit"].get("lift") == "upper", answer["at_limit"]
    verdict = gallery.judge(file, answer, False)
    assert not verdict.problems and not verdict.falls, verdict.problems
    assert answer["residual"] <= gallery.REL_TOL * verdict.scale


@pytest.fixture(scope="module")
def ant_on_its_floor() -> tuple[Path, Any]:
    """gymnasium's ant.xml and `pinsettle solve ant.xml --json` as a user types it (its floor
    taken by default), run once for the tests that judge it."""
    _require("gymnasium", "gymnasium's ant")
    _require("mujoco", "the MJCF judge")
    _require("scipy", "the judge")
    root = gallery.package_dir("gymnasium")
    assert root is not None
    path = root / "envs/mujoco/assets/ant.xml"
    return path, gallery.run_cli(path, False)


def test_mjcf_rests_on_its_floor(ant_on_its_floor: tuple[Path, Any]) -> None:
    """gymnasium's ant, its root free: ``pinsettle solve ant.xml --json`` takes the file's
    floor and geoms (MuJoCo collides them) by default and stands the ant on it, a rest MuJoCo
    confirms: the answer's contact forces, through MuJoCo's Jacobians, and its stops balance
    MuJoCo's static force, the floor carries the weight to 1e-9, no contact sinks in (by the
    answer or by MuJoCo's own contacts at the answer, each of the answer's found there)."""
    path, run = ant_on_its_floor
    assert run.code == 0 and run.answer is not None, run.stderr[-500:]
    answer = run.answer
    assert answer["status"] == "converged", (answer["status"], answer["reason"])
    assert len(answer["contacts"]) >= 3 and all(c["ground"] == "floor" for c in answer["contacts"])
    verdict = gallery.judge_mjcf_on_floor(path, answer)
    assert not verdict.problems, verdict.problems
    assert answer["residual"] <= gallery.REL_TOL * verdict.scale
    # The same file without its floor falls: nothing else holds it.
    fall = gallery.run_cli(path, False, ("--no-contacts",))
    assert fall.answer is not None and fall.answer["status"] == "no_equilibrium"
    assert gallery.judge(path, fall.answer, False).falls


def test_judge_rejects_a_rest_off_the_floor(ant_on_its_floor: tuple[Path, Any]) -> None:
    """The floor judge catches a wrong rest: the ant lifted 1 mm (MuJoCo finds no contacts),
    a contact force halved (the weight is not carried), a joint moved (not a rest)."""
    path, run = ant_on_its_floor
    assert run.answer is not None and run.answer["converged"], run.stderr[-300:]

    def lift(a: dict[str, Any]) -> None:
        a["joints"]["root"][2] += 1e-3

    def halve(a: dict[str, Any]) -> None:
        a["contacts"][0]["normal_force"] *= 0.5

    def move(a: dict[str, Any]) -> None:
        a["joints"]["hip_1"] += 1e-3

    for change, reason in ((lift, "distance"), (halve, "carry"), (move, "not a rest")):
        wrong = copy.deepcopy(run.answer)
        change(wrong)
        problems = gallery.judge_mjcf_on_floor(path, wrong).problems
        assert any(reason in p for p in problems), f"{change.__name__}: {problems}"


def test_judge_tells_a_fall() -> None:
    case = _case("pybullet_data", "mjcf/capsule.xml")  # a lone free body
    run = _run(case)
    assert run.answer is not None
    root = gallery.package_dir(case.package)
    assert root is not None
    file = root / case.path
    assert gallery.judge(file, run.answer, False).falls
    # The same body held where the file puts it (not in the answer): no fall.
    held = copy.deepcopy(run.answer)
    held["joints"] = {n: v for n, v in held["joints"].items() if not isinstance(v, list)}
    assert not gallery.judge(file, held, False).falls


FOURBAR = """<mujoco model="fourbar">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="crank_link">
      <joint name="crank" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="1"/>
      <body name="coupler_link" pos="0.3 0 0">
        <joint name="coupler" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.5 0 0.2" size="0.02" mass="2"/>
      </body>
    </body>
    <body name="rocker_link" pos="0.9 0 0">
      <joint name="rocker" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 -0.1 0 0.2" size="0.02" mass="1"/>
    </body>
  </worldbody>
  <equality>
    <connect body1="coupler_link" body2="rocker_link" anchor="0.5 0 0.2"/>
  </equality>
</mujoco>
"""


HUNG_ARM = """<mujoco model="hung_arm">
  <option gravity="0 0 -9.81"/>
  <worldbody>
    <body name="mocap" mocap="true" pos="0.6 0 0.9"/>
    <body name="base">
      <joint name="slide_x" type="slide" axis="1 0 0"/>
      <joint name="slide_y" type="slide" axis="0 1 0"/>
      <joint name="slide_z" type="slide" axis="0 0 1"/>
      <geom type="box" size="0.25 0.25 0.2" mass="70"/>
      <body name="torso" pos="0 0 0.4">
        <joint name="lift" type="slide" axis="0 0 1" range="0 0.35" limited="true"/>
        <geom type="box" size="0.1 0.1 0.2" mass="10"/>
        <body name="head" pos="0 0 0.3">
          <joint name="head_pan" axis="0 0 1" range="-1.57 1.57" limited="true"/>
          <geom type="box" pos="0.05 0 0" size="0.1 0.1 0.05" mass="2"/>
        </body>
        <body name="shoulder" pos="0.1 0 0.2">
          <joint name="shoulder_pan" axis="0 0 1" range="-1.6 1.6" limited="true"/>
          <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.04" mass="2"/>
          <body name="upper_arm" pos="0.1 0 0">
            <joint name="shoulder_lift" axis="0 1 0" range="-1.2 1.5" limited="true"/>
            <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.04" mass="2"/>
            <body name="forearm" pos="0.3 0 0">
              <joint name="elbow" axis="0 1 0" range="-2.2 2.2" limited="true"/>
              <joint name="forearm_roll" axis="1 0 0"/>
              <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.03" mass="1"/>
              <body name="gripper" pos="0.1 0 0">
                <joint name="wrist" axis="0 1 0" range="-2.1 2.1" limited="true"/>
                <geom type="box" size="0.03 0.03 0.03" mass="0.5"/>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <equality>
    <weld body1="mocap" body2="gripper"/>
  </equality>
</mujoco>
"""

"""Sweeps (pinsettle.sweep, pinsettle.distinct_rests, ``pinsettle sweep``).

Every row is checked against what it stands for: the same case solved alone with
``pinsettle.solve`` (bit for bit), closed forms of the bistable pendulum (its rests, its basins
under kt = 0, its fold), and residuals recomputed with Pinocchio. The cluster tests run a real
Dask cluster on 127.0.0.1: a scheduler and two workers, each a process of its own.
"""

from __future__ import annotations

import json
import math
import os
import pty
import re
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import distributed
import numpy as np
import pandas as pd
import pinocchio
import pinsettle
import pytest
from pandas.testing import assert_frame_equal
from pinsettle import _sweep, _sweep_cases, _sweep_cli
from pinsettle.__main__ import main
from scipy.optimize import brentq

ROBOTS = Path(__file__).resolve().parents[1] / "robots"

# The bistable pendulum (robots/bistable_pendulum.toml): a 1 kg bob l = 1 m below the hinge, a
# spring of stiffness k from the bob to a point h = 2 m below the hinge, rest length L0.
M, G, L, H = 1.0, 9.81, 1.0, 2.0
OUTCOME = ["status", "residual", "stability", "min_stiffness_eigenvalue", "steps"]


def bistable(stiffness: float = 40.0, rest_length: float = 1.5, load: float | None = None):
    """The bistable pendulum built in code (optionally with a constant effort on the hinge)."""
    scene = pinsettle.Scene.from_urdf(ROBOTS / "pendulum.urdf")
    scene.add_spring(
        {"frame": "arm", "point": [0.0, 0.0, -1.0]},
        {"frame": "universe", "point": [0.0, 0.0, -2.0]},
        stiffness=stiffness,
        rest_length=rest_length,
    )
    if load is not None:
        scene.add_load("hinge", load)
    scene.set_start(hinge=0.2)
    return scene


def spring_length(t: float) -> float:
    return math.sqrt(L * L + H * H - 2 * L * H * math.cos(t))


def bistable_torque(t: float, k: float, rest_length: float, load: float = 0.0) -> float:
    """dV/dt of V = -m g l cos t + 1/2 k (d - L0)^2 - load t: zero at a rest."""
    d = spring_length(t)
    return math.sin(t) * (M * G * L + k * (d - rest_length) * L * H / d) - load


def bistable_rest(k: float, rest_length: float) -> float:
    """The positive rest angle: d* = k L0 h / (k h + m g), cos t* = (l^2 + h^2 - d*^2) / 2lh."""
    d = k * rest_length * H / (k * H + M * G)
    return math.acos((L * L + H * H - d * d) / (2 * L * H))


def same_outcome(row: pd.Series, result: pinsettle.Result, joints: list[str]) -> None:
    """A row and a one-by-one solve agree to the bit."""
    assert row["status"] == result.status
    assert row["steps"] == result.steps
    assert row["stability"] == result.stability
    for name in ("residual", "min_stiffness_eigenvalue"):
        assert row[name] == getattr(result, name), name
    for name in joints:
        assert row[name] == result.joints[name], name


def rest_violation(model: pinocchio.Model, q: np.ndarray) -> float:
    """The conditions of a rest against the model's stops, with Pinocchio alone: |g| off the
    stops; at a stop, the pull it would have to give (all UR5 joints are 1-DoF, nq = nv)."""
    g = pinocchio.computeGeneralizedGravity(model, model.createData(), q)
    violation = np.abs(g)
    at_lower, at_upper = q <= model.lowerPositionLimit, q >= model.upperPositionLimit
    violation[at_lower] = np.maximum(0.0, -g[at_lower])
    violation[at_upper] = np.maximum(0.0, g[at_upper])
    return float(violation.max())


def without_times(df: pd.DataFrame) -> pd.DataFrame:
    return df.drop(columns="wall_time")


# --- the table against one-by-one solves -------------------------------------------------------


def test_grid_rows_are_the_one_by_one_solves():
    starts = np.array([[-2.5], [-0.2], [0.3], [2.9]])
    vary = {"spring[0].stiffness": [30.0, 40.0, 55.0], "spring[0].rest_length": [1.3, 1.6]}
    df = pinsettle.sweep(bistable(), vary, starts, workers=2, progress=False)
    assert len(df) == 3 * 2 * 4 and list(df["case"]) == list(range(24))
    assert not df.attrs["pinsettle"]["continuation"]  # two keys: a grid, no continuation
    grid = {
        (k, r, s)
        for k in vary["spring[0].stiffness"]
        for r in vary["spring[0].rest_length"]
        for s in range(4)
    }
    assert (
        set(zip(df["spring[0].stiffness"], df["spring[0].rest_length"], df["start"], strict=True))
        == grid
    )
    for _, row in df.iterrows():
        alone = bistable(row["spring[0].stiffness"], row["spring[0].rest_length"])
        result = pinsettle.solve(alone, starts[row["start"]])
        same_outcome(row, result, ["hinge"])
        assert row["start.hinge"] == starts[row["start"], 0]
        assert row["wall_time"] > 0 and row["error"] == ""
        # The rest against its closed form (spring long enough for two rests: +-t*).
        assert (
            abs(
                abs(row["hinge"])
                - bistable_rest(alone.springs[0].stiffness, alone.springs[0].rest_length)
            )
            < 1e-6
        )


def test_zip_pairs_values():
    vary = {"spring[0].stiffness": [30.0, 50.0], "spring[0].rest_length": [1.3, 1.7]}
    df = pinsettle.sweep(bistable(), vary, zip=True, continuation=False, progress=False)
    assert list(zip(df["spring[0].stiffness"], df["spring[0].rest_length"], strict=True)) == [
        (30.0, 1.3),
        (50.0, 1.7),
    ]
    for _, row in df.iterrows():
        alone = bistable(row["spring[0].stiffness"], row["spring[0].rest_length"])
        same_outcome(row, pinsettle.solve(alone), ["hinge"])


def test_random_starts_are_identical_whatever_the_workers():
    scene = pinsettle.load_scene(pinsettle.scene_path("ur5"))
    one = pinsettle.sweep(scene, starts=("random", 8, 7), workers=1, progress=False)
    two = pinsettle.sweep(scene, starts=("random", 8, 7), workers=2, progress=False)
    assert_frame_equal(without_times(one), without_times(two))
    names = [scene.model.names[j] for j in range(1, scene.model.njoints)]
    lower, upper = scene.model.lowerPositionLimit, scene.model.upperPositionLimit
    for _, row in one.iterrows():
        q0 = np.array([row[f"start.{name}"] for name in names])
        assert np.all(q0 >= lower) and np.all(q0 <= upper)  # inside the stops
        same_outcome(row, pinsettle.solve(scene, q0), names)
        q = np.array([row[n] for n in names])
        assert row["status"] == "converged" and rest_violation(scene.model, q) < 1e-5
        on_stops = {
            name
            for name in names
            if q[names.index(name)] in (lower[names.index(name)], upper[names.index(name)])
        }
        assert on_stops == {item.split(":")[0] for item in row["at_limit"].split(",") if item}
    # The seed fixes the starts; another seed draws others.
    again = pinsettle.sweep(scene, starts=("random", 8, 7), progress=False)
    other = pinsettle.sweep(scene, starts=("random", 8, 8), progress=False)
    assert np.array_equal(again["start.elbow_joint"], one["start.elbow_joint"])
    assert not np.array_equal(other["start.elbow_joint"], one["start.elbow_joint"])


def test_start_keys_set_the_start():
    df = pinsettle.sweep(bistable(), {"start.hinge": [-1.0, 0.4]}, progress=False)
    assert not df.attrs["pinsettle"]["continuation"]
    for _, row in df.iterrows():
        same_outcome(row, pinsettle.solve(bistable(), [row["start.hinge"]]), ["hinge"])
    assert np.sign(df["hinge"]).tolist() == [-1.0, 1.0]


def test_gravity_load_and_force_keys_against_closed_forms():
    slider = pinsettle.load_scene(pinsettle.scene_path("slider_spring"))  # m = 2 kg, k = 500
    numbers = pinsettle.sweep(slider, {"gravity": [0.0, 5.0, 9.81, 20.0]}, progress=False)
    vectors = pinsettle.sweep(
        slider,
        {"gravity": [[0, 0, 0], [0, 0, -5.0], [0, 0, -9.81], [0, 0, -20.0]]},
        progress=False,
    )
    assert "gravity" in numbers.columns and "gravity[2]" in vectors.columns
    assert vectors["gravity[2]"].tolist() == [0.0, -5.0, -9.81, -20.0]
    for g, x in zip(numbers["gravity"], numbers["slider"], strict=True):
        assert x == pytest.approx(-2.0 * g / 500.0, abs=1e-7)
    assert numbers["slider"].tolist() == vectors["slider"].tolist()  # a magnitude along -z

    effort = bistable(stiffness=0.0, load=1.0)  # a plain pendulum with a torque on its hinge
    df = pinsettle.sweep(effort, {"load[0].effort": [0.0, 2.0, 4.0]}, progress=False)
    for tau, t in zip(df["load[0].effort"], df["hinge"], strict=True):
        assert t == pytest.approx(math.asin(tau / (M * G * L)), abs=1e-7)

    pushed = pinsettle.Scene.from_urdf(ROBOTS / "pendulum.urdf")
    pushed.add_load(frame="arm", point=[0, 0, -1.0], force=[1.0, 0, 0])
    df = pinsettle.sweep(pushed, {"load[0].force": [0.5, 3.0]}, progress=False)
    for f, t in zip(df["load[0].force"], df["hinge"], strict=True):
        assert t == pytest.approx(-math.atan(f / (M * G)), abs=1e-7)  # tan t = -F / m g


def test_payload_rests_recomputed_with_pinocchio():
    scene = pinsettle.load_scene(pinsettle.scene_path("ur5_tool_spring"))
    masses = [0.0, 1.5, 3.0]
    df = pinsettle.sweep(scene, {"payload.tool0.mass": masses}, progress=False)
    assert df.attrs["pinsettle"]["continuation"]  # one key: each case from the previous rest
    model = pinsettle.load_robot("ur5")  # no payload: the payload is a force here
    data = model.createData()
    frame = model.getFrameId("tool0")
    spring = scene.springs[0]
    names = [model.names[j] for j in range(1, model.njoints)]
    heights = []
    for _, row in df.iterrows():
        q = np.array([row[n] for n in names])
        pinocchio.framesForwardKinematics(model, data, q)
        tool = data.oMf[frame].translation.copy()
        jac = pinocchio.computeFrameJacobian(
            model, data, q, frame, pinocchio.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )[:3]
        pull = -spring.stiffness * (tool - np.array(spring.b_point))  # rest length 0
        weight = np.array([0.0, 0.0, -9.81 * row["payload.tool0.mass"]])
        tau = pinocchio.computeGeneralizedGravity(model, data, q) - jac.T @ (pull + weight)
        assert row["status"] == "converged" and np.max(np.abs(tau)) < 1e-5
        heights.append(tool[2])
    assert heights[0] > heights[1] > heights[2]  # a heavier payload sags more


def test_continuation_rows_are_chained_one_by_one_solves():
    lengths = [1.6, 1.5, 1.4]
    df = pinsettle.sweep(bistable(), {"spring[0].rest_length": lengths}, [[-0.7]], progress=False)
    assert df["jump"].isna().tolist() == [True, False, False]  # the first has no previous rest
    q = np.array([-0.7])
    for (_, row), rest_length in zip(df.iterrows(), lengths, strict=True):
        result = pinsettle.solve(bistable(rest_length=rest_length), q)
        same_outcome(row, result, ["hinge"])
        q = result.q


def test_continuation_is_identical_whatever_the_workers():
    vary = {"spring[0].rest_length": np.linspace(1.8, 1.2, 7)}
    starts = np.array([[-1.0], [1.0], [0.3]])
    one = pinsettle.sweep(bistable(load=0.5), vary, starts, workers=1, progress=False)
    two = pinsettle.sweep(bistable(load=0.5), vary, starts, workers=2, progress=False)
    assert_frame_equal(without_times(one), without_times(two))


# --- the bistable pendulum: basins and the fold -------------------------------------------------


def test_bistable_basins_match_the_analytic_split():
    # With kt = 0 the bob stops dead at each peak of its kinetic energy, i.e. at the bottom of
    # the well it falls into: a start in (0, pi) rests at +t*, one in (-pi, 0) at -t*. (With
    # the default kt = 0.5 it may swing over the top at 0 first: the basins are the solver's.)
    df = pinsettle.sweep(bistable(), starts=("random", 201, 2026), kt=0.0, progress=False)
    rests = pinsettle.distinct_rests(df)
    t_star = bistable_rest(40.0, 1.5)
    assert len(rests) == 2 and set(rests["stability"]) == {"stable"}
    assert sorted(rests["hinge"]) == pytest.approx([-t_star, t_star], abs=1e-6)
    assert (df["status"] == "converged").all()
    assert (np.sign(df["hinge"]) == np.sign(df["start.hinge"])).all()  # each start's own well
    positive = (df["start.hinge"] > 0).sum() / len(df)
    by_sign = dict(zip(np.sign(rests["hinge"]), rests["fraction"], strict=True))
    negative = (df["start.hinge"] < 0).sum() / len(df)
    assert by_sign[1.0] == positive and by_sign[-1.0] == negative
    # The analytic split is half and half (the wells are equally wide): 201 uniform starts give
    # that within three standard deviations.
    assert abs(positive - 0.5) < 3 * math.sqrt(0.25 / 201)


def test_continuation_jumps_at_the_analytic_fold():
    # A constant 0.5 N m on the hinge tilts the symmetric pitchfork: following the rest on the
    # disfavoured (negative) side while the spring's rest length shrinks, the branch ends at a
    # fold and the bob snaps over to the positive side.
    load = 0.5
    lengths = np.linspace(2.0, 1.0, 41)
    df = pinsettle.sweep(
        bistable(load=load), {"spring[0].rest_length": lengths}, [[-1.0]], progress=False
    )
    jumps = df.index[df["jump"].fillna(False)].tolist()
    assert len(jumps) == 1
    i = jumps[0]

    # The fold: dV/dt = 0 and d2V/dt2 = 0 (a negative angle), by bisection on the rest length
    # between one that still has a negative rest and one that has none.
    def negative_rest(rest_length: float) -> float | None:
        grid = np.linspace(-math.pi / 2, -1e-6, 4001)
        values = [bistable_torque(t, 40.0, rest_length, load) for t in grid]
        for a, b, fa, fb in zip(grid[:-1], grid[1:], values[:-1], values[1:], strict=True):
            if fa < 0 <= fb or fa > 0 >= fb:
                return brentq(bistable_torque, a, b, args=(40.0, rest_length, load), xtol=1e-14)
        return None

    low, high = 1.0, 2.0  # none at 1.0, one at 2.0
    assert negative_rest(low) is None and negative_rest(high) is not None
    while high - low > 1e-9:
        middle = 0.5 * (low + high)
        low, high = (low, middle) if negative_rest(middle) is not None else (middle, high)
    fold = 0.5 * (low + high)
    assert lengths[i] < fold <= lengths[i - 1]
    # Before the fold the rows follow the analytic negative branch, after it the positive one.
    for k in (0, i - 1):
        assert df["hinge"][k] == pytest.approx(negative_rest(lengths[k]), abs=1e-6)
    assert (df["hinge"][:i] < 0).all() and (df["hinge"][i:] > 0).all()
    for k in range(i, len(lengths)):
        t = df["hinge"][k]
        assert abs(bistable_torque(t, 40.0, lengths[k], load)) < 1e-6

    # Followed the other way, from the favoured side, the rest never jumps.
    up = pinsettle.sweep(
        bistable(load=load), {"spring[0].rest_length": lengths[::-1]}, [[0.2]], progress=False
    )
    assert not up["jump"].fillna(False).any() and (up["hinge"] > 0).all()


# --- distinct rests -------------------------------------------------------------------------------


def test_distinct_rests_takes_angles_modulo_two_pi():
    scene = bistable()
    df = pinsettle.sweep(scene, starts=[[0.3], [-0.4]], progress=False)
    df = pd.concat([df, df.assign(case=[2, 3], hinge=df["hinge"] + 2 * math.pi)])
    df.attrs = pinsettle.sweep(scene, starts=[[0.3]], progress=False).attrs
    rests = pinsettle.distinct_rests(df)
    assert rests["count"].tolist() == [2, 2] and rests["fraction"].tolist() == [0.5, 0.5]
    # A table read back from CSV keeps no attrs: the scene says which columns are angles.
    bare = df.copy()
    bare.attrs = {}
    with pytest.raises(ValueError, match=r"pass the scene, distinct_rests\(df, scene=...\)"):
        pinsettle.distinct_rests(bare)
    assert pinsettle.distinct_rests(bare, scene=scene)["count"].tolist() == [2, 2]
    with pytest.raises(ValueError, match="tol must be a number > 0"):
        pinsettle.distinct_rests(df, tol=0)


def test_distinct_rests_per_value_of_the_varied_keys():
    vary = {"spring[0].rest_length": [1.0, 1.5]}
    df = pinsettle.sweep(bistable(), vary, [[0.5], [-0.5]], continuation=False, progress=False)
    rests = pinsettle.distinct_rests(df)
    # At L0 = 1.0 only hanging straight down is stable; at 1.5 the two tilted rests.
    assert rests.groupby("spring[0].rest_length").size().to_dict() == {1.0: 1, 1.5: 2}
    assert rests[rests["spring[0].rest_length"] == 1.0]["hinge"].abs().max() < 1e-6


# --- bad input ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "vary, error, pattern",
    [
        ({"spring[0].stifness": [1.0]}, ValueError, r"unknown field 'stifness'.*'stiffness'"),
        ({"spring[3].stiffness": [1.0]}, ValueError, r"index 3 is past the scene's 1 \[\[spring"),
        ({"joint_spring[0].stiffness": [1.0]}, ValueError, r"index 0 is past .* 0 \[\[joint_sp"),
        ({"spring.stiffness": [1.0]}, ValueError, r"unknown vary key 'spring.stiffness'"),
        ({"start.hing": [1.0]}, ValueError, r"unknown joint 'hing' \(did you mean 'hinge'\?\)"),
        ({"payload.universe.mass": [1.0]}, ValueError, "fixed to the world"),
        ({"payload.nowhere.mass": [1.0]}, ValueError, "unknown frame 'nowhere'"),
        ({"spring[0].stiffness": []}, ValueError, r"has no values \(a range needs N >= 1\)"),
        ({"spring[0].stiffness": 3.0}, TypeError, "must be a list of values"),
        ({"spring[0].stiffness": ["a"]}, TypeError, r"vary\['spring\[0\].stiffness'\]\[0\]"),
        ({"spring[0].stiffness": [math.nan]}, ValueError, "must be finite"),
        ({"gravity": [[0, 0]]}, ValueError, r"must have 3 entries, got 2"),
        ({"gravity": [1.0, [0, 0, -1]]}, TypeError, "all numbers or all vectors"),
        ({3: [1.0]}, TypeError, "vary keys must be strings"),
    ],
)
def test_bad_vary(vary, error, pattern):
    with pytest.raises(error, match=pattern):
        pinsettle.sweep(bistable(), vary, progress=False)


@pytest.mark.parametrize(
    "kwargs, error, pattern",
    [
        (
            {"starts": [[0.1, 0.2]]},
            ValueError,
            r"shape \(n, model.nq = 1\) with n >= 1, got \(1, 2\)",
        ),
        ({"starts": [[math.inf]]}, ValueError, r"starts\[0\]\[0\] is inf"),
        ({"starts": ("random", 0, 1)}, ValueError, "n must be an integer >= 1, got 0"),
        ({"starts": ("random", 5)}, ValueError, r"\('random', n, seed\)"),
        ({"starts": ("random", 5, -1)}, ValueError, "seed must be an integer >= 0"),
        ({"workers": 0}, ValueError, "workers must be an integer >= 1"),
        ({"kt": 2.0}, ValueError, "kt"),
        ({"client": object(), "scheduler": "tcp://127.0.0.1:1"}, ValueError, "not both"),
        ({"scheduler": "tcp://127.0.0.1:1", "workers": 2}, ValueError, "workers= sets local"),
        ({"scheduler": "nonsense"}, ValueError, r"expected tcp://HOST:PORT"),
        ({"scheduler": "tcp://127.0.0.1:99999"}, ValueError, r"expected tcp://HOST:PORT"),
        ({"chunk_size": 0}, ValueError, "chunk_size must be an integer >= 1"),
        ({"progress": "yes"}, TypeError, "progress must be"),
        (
            {"vary": {"start.hinge": [0.1, 0.2]}, "continuation": True},
            ValueError,
            "a start cannot vary along it",
        ),
        (
            {
                "vary": {"spring[0].stiffness": [1.0], "spring[0].rest_length": [1.0, 2.0]},
                "zip": True,
            },
            ValueError,
            r"spring\[0\].stiffness: 1, spring\[0\].rest_length: 2",
        ),
    ],
)
def test_bad_arguments(kwargs, error, pattern):
    with pytest.raises(error, match=pattern):
        pinsettle.sweep(bistable(), **{"progress": False, **kwargs})


def test_gravity_number_needs_a_direction():
    scene = bistable()
    scene.gravity = [0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="gravity is zero, so a number .* has no direction"):
        pinsettle.sweep(scene, {"gravity": [9.81]}, progress=False)


def test_bad_case_values_are_recorded_and_the_sweep_goes_on():
    vary = {"spring[0].stiffness": [40.0, -5.0, 30.0], "payload.arm.mass": [0.0, -1.0]}
    df = pinsettle.sweep(bistable(), vary, progress=False)
    bad = df[(df["spring[0].stiffness"] < 0) | (df["payload.arm.mass"] < 0)]
    good = df.drop(bad.index)
    assert len(bad) == 4 and (bad["status"] == "error").all()
    assert bad["hinge"].isna().all() and bad["steps"].isna().all()
    stiffness = bad[bad["payload.arm.mass"] == 0]["error"]
    assert stiffness.str.contains(r"spring\[0\].stiffness: stiffness must be >= 0").all()
    mass = bad[bad["payload.arm.mass"] < 0]["error"]
    assert mass.str.contains(r"payload.arm.mass: the mass must be >= 0").all()
    assert (good["status"] == "converged").all() and (good["error"] == "").all()


def test_resume_must_be_the_same_sweep():
    vary = {"spring[0].rest_length": [1.4, 1.6]}
    done = pinsettle.sweep(bistable(), vary, progress=False)
    again = pinsettle.sweep(bistable(), vary, progress=False, resume=done.iloc[:1])
    assert again.attrs["pinsettle"]["resumed"] == 1 and again.attrs["pinsettle"]["solved"] == 1
    assert again["wall_time"][0] == done["wall_time"][0]  # kept, not solved again
    assert_frame_equal(without_times(again), without_times(done))
    other = {"spring[0].rest_length": [1.4, 1.7]}
    with pytest.raises(ValueError, match=r"case 1 has spring\[0\].rest_length = 1.6, this sw"):
        pinsettle.sweep(bistable(), other, progress=False, resume=done)
    with pytest.raises(ValueError, match="case 0 is in the table twice"):
        pinsettle.sweep(bistable(), vary, progress=False, resume=pd.concat([done, done]))
    with pytest.raises(ValueError, match="no column spring"):
        pinsettle.sweep(bistable(), {"spring[0].stiffness": [1.0]}, progress=False, resume=done)


# --- what the sweep leaves out and carries -----------------------------------------------------


def test_solving_never_imports_pandas_or_dask():
    code = (
        "import sys, pinsettle\n"
        "scene = pinsettle.load_scene(pinsettle.scene_path('bistable_pendulum'))\n"
        "assert pinsettle.solve(scene).converged\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('pandas', 'pyarrow', 'dask', 'distributed')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize(
    "missing, call, extra",
    [
        ("pandas", "pinsettle.sweep(scene, starts=[[0.1]])", "pinsettle[sweep]"),
        (
            "distributed",
            "pinsettle.sweep(scene, scheduler='tcp://127.0.0.1:1')",
            "pinsettle[cluster]",
        ),
    ],
)
def test_missing_extra_is_a_clear_message(missing, call, extra):
    code = (
        f"import sys; sys.modules['{missing}'] = None\n"
        "import pinsettle\n"
        "scene = pinsettle.load_scene(pinsettle.scene_path('bistable_pendulum'))\n"
        "try:\n"
        f"    {call}\n"
        "except ImportError as error:\n"
        "    print(error)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert f"pip install '{extra}'" in out.stdout, out.stderr


def test_sweep_layers():
    """The cases below the cluster below the plan below the command (docs/architecture.md)."""
    from test_imports import PACKAGE, package_graph

    graph = package_graph(PACKAGE)
    assert {"_sweep", "_sweep_cluster", "_sweep_cli"}.isdisjoint(graph["_sweep_cases"])
    assert {"_sweep", "_sweep_cli"}.isdisjoint(graph["_sweep_cluster"])
    assert "_sweep_cli" not in graph["_sweep"] and "_sweep_cases" in graph["_sweep"]
    # Nothing below the sweep imports it: solving never loads it for pandas or Dask.
    for low in ("_checks", "_settings", "_scene", "_solve", "robots", "scenes"):
        assert not {m for m in graph[low] if m.startswith("_sweep")}, low


@pytest.mark.parametrize("name", pinsettle.scene_names())
def test_scenes_travel_as_data(name):
    # What a Dask worker rebuilds from the scene's data is the same scene: same model, same
    # elements, loops and stops as the C++ core takes them.
    scene = pinsettle.load_scene(pinsettle.scene_path(name))
    import pickle

    data = pickle.loads(pickle.dumps(_sweep_cases.scene_data(scene)))
    rebuilt = _sweep_cases.build_scene(data, [], ())
    assert rebuilt.model == scene.model
    mine, theirs = rebuilt.compile(), scene.compile()
    assert repr(mine.elements) == repr(theirs.elements)
    assert repr(mine.loops) == repr(theirs.loops) and mine.stops == theirs.stops
    assert repr(mine.contacts) == repr(theirs.contacts)


# --- a real Dask cluster on this machine ----------------------------------------------------------


@pytest.fixture(scope="module")
def cluster():
    """A scheduler and two single-threaded workers, each in a process of its own, on
    127.0.0.1."""
    from distributed.deploy.subprocess import SubprocessCluster

    spec = SubprocessCluster(
        host="127.0.0.1", n_workers=2, threads_per_worker=1, dashboard_address=None
    )
    client = distributed.Client(spec, set_as_default=False)
    client.wait_for_workers(2, timeout=60)
    yield client
    client.close()
    spec.close()


def test_cluster_gives_the_local_table(cluster):
    scene = bistable()
    vary = {"spring[0].stiffness": [30.0, 45.0], "spring[0].rest_length": [1.3, 1.6]}
    local = pinsettle.sweep(scene, vary, ("random", 15, 4), progress=False)
    remote = pinsettle.sweep(scene, vary, ("random", 15, 4), client=cluster, progress=False)
    assert remote.attrs["pinsettle"]["cluster"] and remote.attrs["pinsettle"]["workers"] == 2
    assert_frame_equal(without_times(local), without_times(remote))
    # Continuation: one branch per start, each a task.
    vary = {"spring[0].rest_length": np.linspace(2.0, 1.0, 11)}
    local = pinsettle.sweep(bistable(load=0.5), vary, [[-1.0], [0.5]], progress=False)
    remote = pinsettle.sweep(
        bistable(load=0.5), vary, [[-1.0], [0.5]], client=cluster, progress=False
    )
    assert_frame_equal(without_times(local), without_times(remote))
    assert local["jump"].fillna(False).sum() == 1


def test_cluster_reruns_the_cases_of_a_worker_that_dies(cluster):
    scene = pinsettle.load_scene(pinsettle.scene_path("ur5"))
    killed = {}

    def kill_a_busy_worker(done: int, total: int) -> None:
        if killed:
            return
        busy = [address for address, keys in cluster.processing().items() if keys]
        pids = cluster.run(os.getpid, workers=busy[:1])
        for address, pid in pids.items():
            os.kill(pid, signal.SIGKILL)
            killed[address] = pid

    remote = pinsettle.sweep(
        scene, starts=("random", 40, 5), client=cluster, chunk_size=2, progress=kill_a_busy_worker
    )
    assert killed  # a worker with cases in flight died mid-sweep
    local = pinsettle.sweep(scene, starts=("random", 40, 5), progress=False)
    # Every case once, each the same as on this machine.
    assert list(remote["case"]) == list(range(40))
    assert (remote["error"] == "").all(), remote["error"].unique()
    assert_frame_equal(without_times(local), without_times(remote))
    cluster.wait_for_workers(2, timeout=60)  # the nanny starts a new one


KILL_FIRST_TASK = """
import os

import distributed


class KillFirstTask(distributed.WorkerPlugin):
    \"\"\"The worker running the sweep's first task dies (every time).\"\"\"

    name = "pinsettle-test-kill-first-task"

    def transition(self, key, start, finish, **kwargs):
        key = str(key)
        if finish == "executing" and key.startswith("pinsettle-sweep-") and key.endswith("-0"):
            os._exit(1)
"""


def test_cluster_marks_the_cases_dask_gives_up_on(tmp_path, monkeypatch):
    # The plugin in a module of its own, importable by the workers (they inherit PYTHONPATH).
    (tmp_path / "sweep_kill_first_task.py").write_text(KILL_FIRST_TASK, encoding="utf-8")
    monkeypatch.setenv("PYTHONPATH", f"{tmp_path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    monkeypatch.syspath_prepend(str(tmp_path))
    from sweep_kill_first_task import KillFirstTask

    # A LocalCluster (workers in processes of their own) whose scheduler gives up on a task the
    # first time a worker dies running it.
    spec = distributed.LocalCluster(
        host="127.0.0.1",
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",
        scheduler_kwargs={"allowed_failures": 0},
    )
    client = distributed.Client(spec, set_as_default=False)
    try:
        client.register_plugin(KillFirstTask())
        df = pinsettle.sweep(
            bistable(), starts=("random", 12, 1), client=client, chunk_size=3, progress=False
        )
    finally:
        client.close()
        spec.close()
    assert list(df["case"]) == list(range(12))  # none lost, none twice
    marked = df[df["status"] == "error"]
    assert {0, 1, 2} <= set(marked["case"])  # the first task's cases
    assert marked["error"].str.contains("the workers running this case died").all()
    fine = df[df["status"] != "error"]
    local = pinsettle.sweep(bistable(), starts=("random", 12, 1), progress=False)
    local = local.set_index("case").loc[fine["case"]].reset_index()
    assert_frame_equal(without_times(local), without_times(fine.reset_index(drop=True)))


def test_cluster_left_without_workers_marks_the_cases_left(monkeypatch):
    from pinsettle import _sweep_cluster

    monkeypatch.setattr(_sweep_cluster, "NO_WORKER_TIMEOUT", 1.0)
    spec = distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
    )
    client = distributed.Client(spec, set_as_default=False)
    gone = []

    def remove_the_workers(done: int, total: int) -> None:
        if not gone:
            gone.append(done)
            spec.scale(0)

    try:
        df = pinsettle.sweep(
            pinsettle.load_scene(pinsettle.scene_path("ur5")),
            starts=("random", 40, 1),
            client=client,
            chunk_size=2,
            progress=remove_the_workers,
        )
    finally:
        client.close()
        spec.close()
    assert list(df["case"]) == list(range(40))  # every case: solved, or marked
    marked = df[df["status"] == "error"]
    assert len(marked) > 0, marked["error"].unique()
    reasons = r"no worker left on the cluster|the cluster dropped this case \(.*\)"
    assert marked["error"].str.fullmatch(reasons).all(), marked["error"].unique()
    assert (df.drop(marked.index)["status"] == "converged").all()


def _silent_port() -> tuple[socket.socket, int]:
    """A port that accepts connections and never says a word."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    return server, server.getsockname()[1]


def test_scheduler_that_does_not_answer_is_a_clear_error():
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    port = server.getsockname()[1]
    server.close()  # nothing listens there now
    with pytest.raises(ConnectionError, match=rf"scheduler tcp://127.0.0.1:{port} does not"):
        pinsettle.sweep(bistable(), starts=[[0.1]], scheduler=f"tcp://127.0.0.1:{port}")
    silent, port = _silent_port()
    try:
        with pytest.raises(ConnectionError, match="does not answer"):
            pinsettle.sweep(
                bistable(), starts=[[0.1]], scheduler=f"tcp://127.0.0.1:{port}", connect_timeout=1
            )
    finally:
        silent.close()
    # A cluster without workers: no wait for ever.
    empty = distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=":0")
    client = distributed.Client(empty, set_as_default=False)
    try:
        with pytest.raises(ConnectionError, match="has no worker"):
            pinsettle.sweep(bistable(), starts=[[0.1]], client=client, connect_timeout=1)
    finally:
        client.close()
        empty.close()


# --- the command line -----------------------------------------------------------------------------


def run_cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "pinsettle", "sweep", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_cli_summary_and_json(tmp_path):
    out = tmp_path / "basins.parquet"
    proc = run_cli(
        "bistable_pendulum", "--random", "101", "--seed", "3", "--kt", "0", "--out", str(out)
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # no progress bar off a terminal
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("bistable_pendulum: 101 of 101 cases; 101 run in")
    assert lines[1] == "status   converged 101"
    assert lines[2].startswith("rests    2 distinct")
    assert f"wrote    {out} (101 rows)" in lines
    df = pd.read_parquet(out)
    same = pinsettle.sweep(bistable(), starts=("random", 101, 3), kt=0.0, progress=False)
    assert_frame_equal(without_times(df), without_times(same), check_like=False)
    proc = run_cli("bistable_pendulum", "--vary", "spring[0].rest_length=1.6:1.4:3", "--json")
    assert proc.returncode == 0, proc.stderr
    info = json.loads(proc.stdout)
    assert info["cases"] == 3 and info["status_counts"] == {"converged": 3}
    assert [row["spring[0].rest_length"] for row in info["rows"]] == [1.6, 1.5, 1.4]
    assert info["jumps"] == [] and len(info["distinct_rests"]) == 3
    rest = bistable_rest(40.0, 1.5)
    assert info["rows"][1]["hinge"] == pytest.approx(rest, abs=1e-6)


def test_cli_resume_skips_the_cases_done(tmp_path):
    out = tmp_path / "grid.csv"
    args = [
        "bistable_pendulum",
        "--vary",
        "spring[0].stiffness=30:50:3",
        "--vary",
        "spring[0].rest_length=1.3,1.6",
        "--random",
        "4",
        "--out",
        str(out),
    ]
    assert run_cli(*args).returncode == 0
    full = _sweep_cli.read_table(out)
    assert len(full) == 24
    part = full[full["case"] % 3 != 1]  # as if some cases had not been run
    part.to_csv(out, index=False)
    proc = run_cli(*args)
    assert proc.returncode == 0, proc.stderr
    assert "(16 from the file); 8 run" in proc.stdout
    again = _sweep_cli.read_table(out)
    assert_frame_equal(without_times(again), without_times(full))
    kept = again[again["case"] % 3 != 1]["wall_time"].to_numpy()
    assert np.array_equal(kept, part["wall_time"].to_numpy())  # not solved again


def test_cli_ctrl_c_writes_what_is_done_and_resumes(tmp_path):
    out = tmp_path / "stopped.parquet"
    args = [
        sys.executable,
        "-m",
        "pinsettle",
        "sweep",
        "bistable_pendulum",
        "--random",
        "4000",
        "--workers",
        "1",
        "--out",
        str(out),
    ]
    master, slave = pty.openpty()  # a terminal for stderr: the progress bar shows
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=slave, text=True)
    os.close(slave)
    seen = b""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        ready, _, _ = select.select([master], [], [], 1.0)
        if ready:
            try:
                seen += os.read(master, 4096)
            except OSError:
                break
            counts = re.findall(rb"\] (\d+)/4000 cases", seen)
            if counts and int(counts[-1]) >= 100:
                proc.send_signal(signal.SIGINT)
                break
    stdout, _ = proc.communicate(timeout=120)
    os.close(master)
    assert re.search(rb"\[#*\.*\] \d+/4000 cases  [\d.]+/s  \d+:\d\d left", seen), seen[-300:]
    assert proc.returncode == 130, stdout
    assert "interrupted: run the same command again" in stdout
    stopped = pd.read_parquet(out)
    n = len(stopped)
    assert 100 <= n < 4000 and list(stopped["case"]) == list(range(n))  # one worker: in order
    assert stopped.attrs["pinsettle"]["interrupted"]
    # The same command again solves the rest only, and the whole is an uninterrupted sweep.
    resumed = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert f"({n} from the file); {4000 - n} run" in resumed.stdout
    whole = pd.read_parquet(out)
    fresh = pinsettle.sweep(
        pinsettle.load_scene(pinsettle.scene_path("bistable_pendulum")),
        starts=("random", 4000, 0),
        progress=False,
    )
    assert_frame_equal(without_times(whole), without_times(fresh))
    assert np.array_equal(whole["wall_time"][:n], stopped["wall_time"])


def test_cli_scheduler_gives_the_local_table(cluster, tmp_path):
    address = cluster.scheduler.address
    args = [
        "bistable_pendulum",
        "--vary",
        "spring[0].rest_length=1.2:1.8:4",
        "--random",
        "5",
        "--continuation",
    ]
    remote = run_cli(*args, "--scheduler", address, "--out", str(tmp_path / "r.parquet"))
    local = run_cli(*args, "--out", str(tmp_path / "l.parquet"))
    assert remote.returncode == 0 and local.returncode == 0, remote.stderr + local.stderr
    assert "on the cluster's 2 workers" in remote.stdout
    a, b = pd.read_parquet(tmp_path / "r.parquet"), pd.read_parquet(tmp_path / "l.parquet")
    assert_frame_equal(without_times(a), without_times(b))


@pytest.mark.parametrize(
    "args, pattern",
    [
        (["--vary", "spring[9].stiffness=1:2:3"], r"index 9 is past the scene's 1 \[\[spring"),
        (["--vary", "sprung[0].stiffness=1:2:3"], "unknown vary key 'sprung"),
        (["--vary", "spring[0].stiffness=1:2:0"], "N must be an integer >= 1, got 0"),
        (["--vary", "spring[0].stiffness=1:2"], "expected LO:HI:N"),
        (["--vary", "spring[0].stiffness"], "--vary expects KEY=LO:HI:N"),
        (["--vary", "spring[0].stiffness=1,x"], "expected LO:HI:N"),
        (["--random", "0"], "--random N: N must be an integer >= 1"),
        (["--random", "5", "--out", "x.txt"], "--out x.txt: the file must end in .parquet or"),
        (["--random", "5", "--out", "/no/such/dir/x.csv"], "no such folder"),
        (["--seed", "3", "--vary", "spring[0].stiffness=1:2:2"], "--seed goes with --random"),
        ([], "nothing to sweep"),
        (["--random", "3", "--workers", "0"], "workers must be an integer >= 1"),
        (["--random", "3", "--scheduler", "here"], "expected tcp://HOST:PORT"),
        (["--random", "3", "--kt", "5"], "kt"),
    ],
)
def test_cli_bad_input(args, pattern, capsys):
    assert main(["sweep", "bistable_pendulum", *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pinsettle: error: ") and re.search(pattern, err), err
    assert len(err.strip().splitlines()) == 1


def test_cli_scheduler_that_does_not_answer():
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    port = server.getsockname()[1]
    server.close()
    proc = run_cli(
        "bistable_pendulum", "--random", "3", "--scheduler", f"tcp://127.0.0.1:{port}", timeout=60
    )
    assert proc.returncode == 2
    assert f"scheduler tcp://127.0.0.1:{port} does not answer" in proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_cli_reports_the_cases_in_error():
    proc = run_cli(
        "bistable_pendulum", "--vary", "spring[0].stiffness=-1,40,-2", "--no-continuation"
    )
    assert proc.returncode == 1  # not every case converged
    assert "status   error 2, converged 1" in proc.stdout
    assert "error    case 0: spring[0].stiffness: stiffness must be >= 0, got -1.0" in proc.stdout
    assert "error    case 2: spring[0].stiffness: stiffness must be >= 0, got -2.0" in proc.stdout


def test_cli_resume_from_another_sweep_is_refused(tmp_path):
    out = tmp_path / "a.csv"
    assert run_cli("bistable_pendulum", "--random", "3", "--out", str(out)).returncode == 0
    proc = run_cli("bistable_pendulum", "--random", "3", "--seed", "1", "--out", str(out))
    assert proc.returncode == 2 and "the table is not of this sweep: case 0 has" in proc.stderr


def test_progress_bar_only_on_a_terminal():
    stream = type("S", (), {"isatty": lambda self: False, "write": None})()
    bar = _sweep.ProgressBar(stream)
    bar(1, 2)  # would fail if it wrote anything
    assert not bar.enabled
    lines: list[str] = []
    tty = type(
        "T",
        (),
        {
            "isatty": lambda self: True,
            "write": lambda self, s: lines.append(s),
            "flush": lambda self: None,
        },
    )()
    bar = _sweep.ProgressBar(tty)
    bar(5, 10)
    bar(10, 10)
    assert re.match(r"\r\[#{15}\.{15}\] 5/10 cases  [\d.]+/s  \d+:\d\d left", lines[0])
    assert lines[-1] == "\n" and "10/10 cases" in lines[-2]


def test_sweep_in_a_thread_leaves_ctrl_c_alone():
    # Off the main thread no signal handler is installed (Python allows none there).
    results = []
    before = signal.getsignal(signal.SIGINT)
    thread = threading.Thread(
        target=lambda: results.append(pinsettle.sweep(bistable(), starts=[[0.1]], progress=False))
    )
    thread.start()
    thread.join(60)
    assert len(results) == 1 and results[0]["status"][0] == "converged"
    assert signal.getsignal(signal.SIGINT) is before

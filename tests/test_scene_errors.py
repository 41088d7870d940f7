"""Bad scene input, through ``pinsettle.load_scene`` and ``pinsettle solve``: each mistake gets a
message that names the file, the key or name and what was expected; the command line exits
with status 2 and prints that message, never a traceback. Also the command line on good scenes:
its JSON, exit statuses, flags and the scene list.

Every command line run of this module is started at once by a module fixture (they take about
half a second each, mostly the start of Python and pinocchio) and the tests read the outcomes.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pinsettle
import pytest

ROBOTS = Path(__file__).parents[1] / "robots"
PENDULUM = ROBOTS / "pendulum.urdf"
PLANAR = ROBOTS / "planar_3link.urdf"

HEAD = f'[model]\nurdf = "{PENDULUM}"\n'
FLOATING = f'[model]\nurdf = "{PENDULUM}"\nfloating = true\n'
PLANAR_HEAD = f'[model]\nurdf = "{PLANAR}"\n'
SPRING = (
    '[[spring]]\na = {{ frame = "arm"{a} }}\nb = {{ frame = "universe"{b} }}\nstiffness = 1.0\n'
)


def spring(a: str = "", b: str = "", extra: str = "") -> str:
    return HEAD + SPRING.format(a=a, b=b) + extra


# id -> (scene file text, exception, fragments the message must contain). Each fragment names
# the place (table, key, element number), the culprit or what was expected.
CASES: dict[str, tuple[str, type[Exception], list[str]]] = {
    # -- the file and its syntax
    "toml-syntax": (
        HEAD + "[start]\nhinge = 0.1\nhinge2 = = 3\n",
        pinsettle.SceneError,
        ["TOML syntax error", "line 5"],
    ),
    "toml-syntax-table": ("[model\n", pinsettle.SceneError, ["TOML syntax error", "line 1"]),
    # -- [model]
    "no-model": ("[start]\nhinge = 1.0\n", pinsettle.SceneError, ["missing table [model]"]),
    "model-not-a-table": ('model = "ur5"\n', pinsettle.SceneError, ["[model] must be a table"]),
    "urdf-and-robot": (
        HEAD + 'robot = "ur5"\n',
        pinsettle.SceneError,
        ["[model]", "exactly one of 'urdf'", "'robot'", "got both"],
    ),
    "neither-urdf-nor-robot": (
        "[model]\nfloating = false\n",
        pinsettle.SceneError,
        ["[model]", "exactly one of 'urdf'", "got neither"],
    ),
    "unknown-robot": (
        '[model]\nrobot = "ur6"\n',
        pinsettle.SceneError,
        ["[model] robot", "unknown robot 'ur6'", "did you mean 'ur5'?", "known robots:", "panda"],
    ),
    "robot-not-a-string": ("[model]\nrobot = 5\n", pinsettle.SceneError, ["[model] robot", "5"]),
    "urdf-not-a-string": ("[model]\nurdf = 3\n", pinsettle.SceneError, ["[model] urdf", "3"]),
    "urdf-missing": (
        '[model]\nurdf = "nowhere.urdf"\n',
        pinsettle.SceneError,
        ["[model] urdf", "URDF file not found", "nowhere.urdf"],
    ),
    "urdf-broken": (
        '[model]\nurdf = "broken.urdf"\n',
        pinsettle.SceneError,
        ["[model] urdf", "broken.urdf", "does not parse"],
    ),
    "floating-not-a-bool": (
        HEAD + 'floating = "yes"\n',
        pinsettle.SceneError,
        ["[model] floating", "true or false", "'yes'"],
    ),
    "gravity-2-entries": (
        HEAD + "gravity = [0.0, -9.81]\n",
        pinsettle.SceneError,
        ["[model]", "gravity must have 3 entries, got 2"],
    ),
    "gravity-a-string": (
        HEAD + 'gravity = "down"\n',
        pinsettle.SceneError,
        ["[model]", "gravity must be a list of 3 numbers", "'down'"],
    ),
    "gravity-with-a-bool": (
        HEAD + "gravity = [0.0, 0.0, true]\n",
        pinsettle.SceneError,
        ["gravity[2] must be a number", "bool"],
    ),
    "locked-not-a-list": (
        HEAD + 'locked = "hinge"\n',
        pinsettle.SceneError,
        ["[model] locked must be a list of joint names", "'hinge'"],
    ),
    "locked-unknown-joint": (
        PLANAR_HEAD + 'locked = ["jiont2"]\n',
        pinsettle.SceneError,
        ["[model] locked", "unknown joint 'jiont2'", "did you mean 'joint2'?", "joint1, joint2"],
    ),
    "every-joint-locked": (
        HEAD + 'locked = ["hinge"]\n',
        pinsettle.SceneError,
        ["every joint is locked", "nothing to settle"],
    ),
    # -- unknown keys, everywhere
    "unknown-top-level-key": (
        HEAD.replace("[model]", "[modle]"),
        pinsettle.SceneError,
        ["top level", "unknown key 'modle'", "did you mean 'model'?", "known keys: model, start"],
    ),
    "unknown-top-level-table": (
        HEAD + "[springs]\n",
        pinsettle.SceneError,
        ["top level", "unknown key 'springs'", "did you mean 'spring'?"],
    ),
    "unknown-model-key": (
        HEAD + "gravty = [0.0, 0.0, -9.81]\n",
        pinsettle.SceneError,
        ["[model]", "unknown key 'gravty'", "did you mean 'gravity'?"],
    ),
    "unknown-joint-spring-key": (
        HEAD + '[[joint_spring]]\njoint = "hinge"\nstifness = 10.0\n',
        pinsettle.SceneError,
        ["[[joint_spring]] #1", "unknown key 'stifness'", "did you mean 'stiffness'?"],
    ),
    "unknown-spring-key": (
        spring(extra="rest_lenght = 0.5\n"),
        pinsettle.SceneError,
        ["[[spring]] #1", "unknown key 'rest_lenght'", "did you mean 'rest_length'?"],
    ),
    "unknown-spring-end-key": (
        spring(a=", pont = [0.0, 0.0, -1.0]"),
        pinsettle.SceneError,
        ["[[spring]] #1", "a:", "unknown key 'pont'", "did you mean 'point'?"],
    ),
    "unknown-load-key": (
        HEAD + '[[load]]\nframe = "arm"\nforc = [1.0, 0.0, 0.0]\n',
        pinsettle.SceneError,
        ["[[load]] #1", "unknown key 'forc'", "did you mean 'force'?"],
    ),
    "unknown-solver-key": (
        HEAD + "[solver]\nmax_step = 10\n",
        pinsettle.SceneError,
        ["[solver]", "unknown key 'max_step'", "did you mean 'max_steps'?", "kt"],
    ),
    "unknown-solver-setting": (
        HEAD + "[solver]\ndamping = 0.1\n",
        pinsettle.SceneError,
        ["[solver]", "unknown key 'damping'", "known keys: dt, dt_safety, dt_growth, kt"],
    ),
    # -- unknown joints and frames
    "start-unknown-joint": (
        HEAD + "[start]\nhinj = 1.0\n",
        pinsettle.SceneError,
        ["[start]", "unknown joint 'hinj'", "did you mean 'hinge'?"],
    ),
    "joint-spring-unknown-joint": (
        HEAD + '[[joint_spring]]\njoint = "hing"\nstiffness = 1.0\n',
        pinsettle.SceneError,
        ["[[joint_spring]] #1", "unknown joint 'hing'", "did you mean 'hinge'?"],
    ),
    "second-joint-spring-unknown-joint": (
        PLANAR_HEAD
        + '[[joint_spring]]\njoint = "joint1"\nstiffness = 1.0\n'
        + '[[joint_spring]]\njoint = "joint_3"\nstiffness = 1.0\n',
        pinsettle.SceneError,
        ["[[joint_spring]] #2", "unknown joint 'joint_3'", "did you mean 'joint3'?"],
    ),
    "load-unknown-joint": (
        HEAD + '[[load]]\njoint = "hing"\neffort = 1.0\n',
        pinsettle.SceneError,
        ["[[load]] #1", "unknown joint 'hing'", "did you mean 'hinge'?"],
    ),
    "spring-unknown-frame": (
        spring().replace('frame = "arm"', 'frame = "arn"'),
        pinsettle.SceneError,
        ["[[spring]] #1", "a.frame", "unknown frame 'arn'", "did you mean 'arm'?"],
    ),
    "spring-unknown-world-frame": (
        spring().replace('"universe"', '"univers"'),
        pinsettle.SceneError,
        ["[[spring]] #1", "b.frame", "unknown frame 'univers'", "did you mean 'universe'?"],
    ),
    "load-unknown-frame": (
        HEAD + '[[load]]\nframe = "arn"\nforce = [1.0, 0.0, 0.0]\n',
        pinsettle.SceneError,
        ["[[load]] #1", "unknown frame 'arn'", "did you mean 'arm'?"],
    ),
    "joint-not-a-string": (
        HEAD + "[[joint_spring]]\njoint = 1\nstiffness = 1.0\n",
        pinsettle.SceneError,
        ["[[joint_spring]] #1", "joint must be a joint name (str)", "int"],
    ),
    # -- signs
    "negative-joint-spring-stiffness": (
        HEAD + '[[joint_spring]]\njoint = "hinge"\nstiffness = -1.0\n',
        pinsettle.SceneError,
        ["[[joint_spring]] #1", "stiffness must be >= 0", "-1.0"],
    ),
    "negative-joint-spring-damping": (
        HEAD + '[[joint_spring]]\njoint = "hinge"\nstiffness = 1.0\ndamping = -0.1\n',
        pinsettle.SceneError,
        ["[[joint_spring]] #1", "damping must be >= 0", "-0.1"],
    ),
    "negative-spring-stiffness": (
        spring().replace("stiffness = 1.0", "stiffness = -5.0"),
        pinsettle.SceneError,
        ["[[spring]] #1", "stiffness must be >= 0", "-5.0"],
    ),
    "negative-spring-damping": (
        spring(extra="damping = -2.0\n"),
        pinsettle.SceneError,
        ["[[spring]] #1", "damping must be >= 0", "-2.0"],
    ),
    "negative-rest-length": (
        spring(extra="rest_length = -0.5\n"),
        pinsettle.SceneError,
        ["[[spring]] #1", "rest_length must be >= 0", "-0.5"],
    ),
    "infinite-stiffness": (
        spring().replace("stiffness = 1.0", "stiffness = inf"),
        pinsettle.SceneError,
        ["[[spring]] #1", "stiffness must be finite", "inf"],
    ),
    "nan-rest": (
        HEAD + '[[joint_spring]]\njoint = "hinge"\nstiffness = 1.0\nrest = nan\n',
        pinsettle.SceneError,
        ["[[joint_spring]] #1", "rest must be finite", "nan"],
    ),
    # -- vector lengths
    "spring-point-2-entries": (
        spring(a=", point = [0.0, 0.0]"),
        pinsettle.SceneError,
        ["[[spring]] #1", "a.point must have 3 entries, got 2"],
    ),
    "load-point-4-entries": (
        HEAD + '[[load]]\nframe = "arm"\npoint = [0, 0, -1, 0]\nforce = [1.0, 0.0, 0.0]\n',
        pinsettle.SceneError,
        ["[[load]] #1", "point must have 3 entries, got 4"],
    ),
    "load-force-2-entries": (
        HEAD + '[[load]]\nframe = "arm"\nforce = [1.0, 0.0]\n',
        pinsettle.SceneError,
        ["[[load]] #1", "force must have 3 entries, got 2"],
    ),
    "load-torque-2-entries": (
        HEAD + '[[load]]\nframe = "arm"\nforce = [1.0, 0.0, 0.0]\ntorque = [1.0, 2.0]\n',
        pinsettle.SceneError,
        ["[[load]] #1", "torque must have 3 entries, got 2"],
    ),
    "effort-of-a-free-flyer-3-entries": (
        FLOATING + '[[load]]\njoint = "root_joint"\neffort = [1.0, 2.0, 3.0]\n',
        pinsettle.SceneError,
        ["[[load]] #1", "effort must have 6 entries, got 3"],
    ),
    # -- types
    "string-stiffness": (
        HEAD + '[[joint_spring]]\njoint = "hinge"\nstiffness = "100"\n',
        pinsettle.SceneError,
        ["[[joint_spring]] #1", "stiffness must be a number", "str", "'100'"],
    ),
    "bool-stiffness": (
        spring().replace("stiffness = 1.0", "stiffness = true"),
        pinsettle.SceneError,
        ["[[spring]] #1", "stiffness must be a number", "bool"],
    ),
    "bool-effort": (
        HEAD + '[[load]]\njoint = "hinge"\neffort = false\n',
        pinsettle.SceneError,
        ["[[load]] #1", "effort must be a number", "bool"],
    ),
    "bool-start": (
        HEAD + "[start]\nhinge = true\n",
        pinsettle.SceneError,
        ["[start]", "'hinge' must be a number", "bool"],
    ),
    "string-start": (
        HEAD + '[start]\nhinge = "up"\n',
        pinsettle.SceneError,
        ["[start]", "'hinge' must be a number", "'up'"],
    ),
    "spring-end-a-string": (
        HEAD + '[[spring]]\na = "arm"\nb = { frame = "universe" }\nstiffness = 1.0\n',
        pinsettle.SceneError,
        ["[[spring]] #1", "a must be an inline table", "'arm'"],
    ),
    # -- start values of the wrong shape
    "start-scalar-for-a-free-flyer": (
        FLOATING + "[start]\nroot_joint = 1.0\n",
        pinsettle.SceneError,
        ["[start]", "'root_joint'", "JointModelFreeFlyer", "7 configuration entries", "list of 7"],
    ),
    "start-free-flyer-6-entries": (
        FLOATING + "[start]\nroot_joint = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\n",
        pinsettle.SceneError,
        ["[start]", "'root_joint' must have 7 entries, got 6"],
    ),
    "start-list-for-a-1-dof-joint": (
        HEAD + "[start]\nhinge = [0.1]\n",
        pinsettle.SceneError,
        ["[start]", "'hinge'", "one degree of freedom", "give one number", "[0.1]"],
    ),
    "start-of-a-locked-joint-a-list": (
        PLANAR_HEAD + 'locked = ["joint2"]\n[start]\njoint2 = [0.1, 0.2]\n',
        pinsettle.SceneError,
        ["[start]", "'joint2'", "one degree of freedom", "[0.1, 0.2]"],
    ),
    "start-of-a-locked-free-flyer-a-scalar": (
        FLOATING.replace("floating = true\n", 'floating = true\nlocked = ["root_joint"]\n')
        + "[start]\nroot_joint = 0.5\n",
        pinsettle.SceneError,
        ["[start]", "'root_joint'", "7 configuration entries"],
    ),
    # -- elements on locked or multi-DoF joints, useless elements
    "joint-spring-on-a-locked-joint": (
        PLANAR_HEAD + 'locked = ["joint2"]\n[[joint_spring]]\njoint = "joint2"\nstiffness = 1.0\n',
        pinsettle.SceneError,
        ["[[joint_spring]] #1 on joint 'joint2'", "the joint is locked"],
    ),
    "load-on-a-locked-joint": (
        PLANAR_HEAD + 'locked = ["joint2"]\n[[load]]\njoint = "joint2"\neffort = 1.0\n',
        pinsettle.SceneError,
        ["[[load]] #1 on joint 'joint2'", "the joint is locked"],
    ),
    "spring-to-a-body-locked-to-the-world": (
        PLANAR_HEAD
        + 'locked = ["joint1"]\n[[spring]]\na = { frame = "link1" }\n'
        + 'b = { frame = "universe", point = [1.0, 0.0, 0.0] }\nstiffness = 1.0\n',
        pinsettle.SceneError,
        ["[[spring]] #1", "on the same rigid body", "the world", "locked joints are removed"],
    ),
    "spring-within-one-body": (
        spring(b=", point = [1.0, 0.0, 0.0]").replace('"universe"', '"arm"'),
        pinsettle.SceneError,
        ["[[spring]] #1", "on the same rigid body", "'hinge'"],
    ),
    "joint-spring-on-a-free-flyer": (
        FLOATING + '[[joint_spring]]\njoint = "root_joint"\nstiffness = 1.0\n',
        pinsettle.SceneError,
        ["[[joint_spring]] #1", "'root_joint'", "6 degrees of freedom", "needs a 1-DoF joint"],
    ),
    "load-on-the-world": (
        HEAD + '[[load]]\nframe = "universe"\nforce = [1.0, 0.0, 0.0]\n',
        pinsettle.SceneError,
        ["[[load]] #1", "'universe'", "does nothing"],
    ),
    # -- missing keys, mixed-up loads
    "joint-spring-without-stiffness": (
        HEAD + '[[joint_spring]]\njoint = "hinge"\n',
        pinsettle.SceneError,
        ["[[joint_spring]] #1", "missing key 'stiffness'"],
    ),
    "spring-without-b": (
        HEAD + '[[spring]]\na = { frame = "arm" }\nstiffness = 1.0\n',
        pinsettle.SceneError,
        ["[[spring]] #1", "missing key 'b'"],
    ),
    "spring-end-without-frame": (
        spring().replace('frame = "arm"', "point = [0.0, 0.0, -1.0]"),
        pinsettle.SceneError,
        ["[[spring]] #1", "a:", "missing key 'frame'"],
    ),
    "joint-load-without-effort": (
        HEAD + '[[load]]\njoint = "hinge"\n',
        pinsettle.SceneError,
        ["[[load]] #1", "missing key 'effort'"],
    ),
    "load-with-joint-and-frame": (
        HEAD + '[[load]]\njoint = "hinge"\neffort = 1.0\nframe = "arm"\n',
        pinsettle.SceneError,
        ["[[load]] #1", "'joint' and 'effort' only", "'frame'"],
    ),
    "load-with-neither": (
        HEAD + "[[load]]\nforce = [1.0, 0.0, 0.0]\n",
        pinsettle.SceneError,
        ["[[load]] #1", "needs 'joint'", "or 'frame'"],
    ),
    # -- [[payload]]
    "payload-missing-mass": (
        HEAD + '[[payload]]\nframe = "arm"\n',
        pinsettle.SceneError,
        ["[[payload]] #1", "missing key 'mass'"],
    ),
    "payload-missing-frame": (
        HEAD + "[[payload]]\nmass = 1.0\n",
        pinsettle.SceneError,
        ["[[payload]] #1", "missing key 'frame'"],
    ),
    "payload-unknown-key": (
        HEAD + '[[payload]]\nframe = "arm"\nmass = 1.0\npoint = [0.0, 0.0, 0.1]\n',
        pinsettle.SceneError,
        ["[[payload]] #1", "unknown key 'point'", "offset"],
    ),
    "payload-unknown-frame": (
        HEAD + '[[payload]]\nframe = "armm"\nmass = 1.0\n',
        pinsettle.SceneError,
        ["[[payload]] #1", "frame: unknown frame 'armm'", "did you mean 'arm'?"],
    ),
    "payload-on-the-world": (
        HEAD + '[[payload]]\nframe = "universe"\nmass = 1.0\n',
        pinsettle.SceneError,
        ["[[payload]] #1", "'universe' is fixed to the world"],
    ),
    "payload-mass-zero": (
        HEAD + '[[payload]]\nframe = "arm"\nmass = 0.0\n',
        pinsettle.SceneError,
        ["[[payload]] #1", "mass must be > 0 (kg), got 0.0"],
    ),
    "payload-mass-negative": (
        HEAD + '[[payload]]\nframe = "arm"\nmass = -3\n',
        pinsettle.SceneError,
        ["[[payload]] #1", "mass must be > 0 (kg), got -3.0"],
    ),
    "payload-mass-nan": (
        HEAD + '[[payload]]\nframe = "arm"\nmass = nan\n',
        pinsettle.SceneError,
        ["[[payload]] #1", "mass must be finite, got nan"],
    ),
    "payload-mass-a-string": (
        HEAD + '[[payload]]\nframe = "arm"\nmass = "2 kg"\n',
        pinsettle.SceneError,
        ["[[payload]] #1", "mass must be a number", "'2 kg'"],
    ),
    "payload-offset-of-two": (
        HEAD + '[[payload]]\nframe = "arm"\nmass = 1.0\noffset = [0.0, 0.1]\n',
        pinsettle.SceneError,
        ["[[payload]] #1", "offset must have 3 entries, got 2"],
    ),
    "payload-a-table": (
        HEAD + '[payload]\nframe = "arm"\nmass = 1.0\n',
        pinsettle.SceneError,
        ["'payload' must be an array of tables ([[payload]])"],
    ),
    # -- [model] contacts and floor
    "floor-with-contacts-none": (
        HEAD + 'contacts = "none"\nfloor = true\n',
        pinsettle.SceneError,
        ["[model] floor needs contact points", 'contacts = "none" leaves them out'],
    ),
    "floor-not-a-height": (
        HEAD + 'floor = "low"\n',
        pinsettle.SceneError,
        ["[model] floor must be true", "a height z (m)", "'low'"],
    ),
    "floor-without-collision-geometry": (
        FLOATING + "floor = true\n",
        pinsettle.SceneError,
        ["[model] contacts", "pendulum.urdf has no collision geometry"],
    ),
    "hull-points-without-contacts": (
        HEAD + "hull_points = 8\n",
        pinsettle.SceneError,
        ["[model] hull_points is for contacts from the model's collision shapes"],
    ),
    "contacts-exclude-with-contacts-none": (
        HEAD + 'contacts = "none"\ncontacts_exclude = ["arm"]\n',
        pinsettle.SceneError,
        ["[model] contacts_exclude is for contacts", 'without contacts = "none"'],
    ),
    # -- tables of the wrong kind
    "joint-spring-a-table": (
        HEAD + '[joint_spring]\njoint = "hinge"\nstiffness = 1.0\n',
        pinsettle.SceneError,
        ["'joint_spring' must be an array of tables ([[joint_spring]])"],
    ),
    "spring-a-table": (
        HEAD + "[spring]\nstiffness = 1.0\n",
        pinsettle.SceneError,
        ["'spring' must be an array of tables ([[spring]])"],
    ),
    "load-a-table": (
        HEAD + '[load]\njoint = "hinge"\neffort = 1.0\n',
        pinsettle.SceneError,
        ["'load' must be an array of tables ([[load]])"],
    ),
    "start-not-a-table": (
        "start = 1\n" + HEAD,
        pinsettle.SceneError,
        ["[start] must be a table"],
    ),
    # -- [solver]
    "solver-kt-out-of-range": (
        HEAD + "[solver]\nkt = 1.5\n",
        pinsettle.SceneError,
        ["[solver]", "kt must be in [0, 1)", "1.5"],
    ),
    "solver-kt-a-string": (
        HEAD + '[solver]\nkt = "half"\n',
        pinsettle.SceneError,
        ["[solver]", "setting 'kt' expects float", "'half'"],
    ),
    "solver-max-steps-a-float": (
        HEAD + "[solver]\nmax_steps = 1e4\n",
        pinsettle.SceneError,
        ["[solver]", "setting 'max_steps' expects int"],
    ),
    "solver-energy-unknown": (
        HEAD + '[solver]\nenergy = "fast"\n',
        pinsettle.SceneError,
        ["[solver]", 'energy must be "exact" or "simplified"', '"fast"'],
    ),
    "solver-dt-zero": (
        HEAD + "[solver]\ndt = 0.0\n",
        pinsettle.SceneError,
        ["[solver]", "dt must be 'auto' or a finite number > 0"],
    ),
}

# Command line runs that are not a scene file of CASES: id -> (arguments, fragments).
CLI_ERRORS: dict[str, tuple[list[str], list[str]]] = {
    "missing-file": (["solve", "{tmp}/nope.toml"], ["scene file not found", "nope.toml"]),
    "unknown-scene-name": (
        ["solve", "pendulm"],
        ["no such scene", "unknown scene 'pendulm'", "did you mean 'pendulum'?", "chain20"],
    ),
    "start-without-value": (
        ["solve", "pendulum", "--start", "hinge"],
        ["--start expects JOINT=VALUE", "'hinge'"],
    ),
    "start-without-joint": (["solve", "pendulum", "--start", "=0.3"], ["--start expects JOINT"]),
    "start-not-a-number": (
        ["solve", "pendulum", "--start", "hinge=abc"],
        ["--start hinge", "expected a number", "'abc'"],
    ),
    "start-unknown-joint": (
        ["solve", "pendulum", "--start", "hinj=0.3"],
        ["--start", "unknown joint 'hinj'", "did you mean 'hinge'?"],
    ),
    "start-list-for-a-1-dof-joint": (
        ["solve", "pendulum", "--start", "hinge=0.1,0.2"],
        ["--start", "'hinge'", "one degree of freedom"],
    ),
    "flag-out-of-range": (["solve", "pendulum", "--kt", "1.5"], ["kt must be in [0, 1)"]),
    # -- the contacts of a model file
    "no-contacts-with-contacts": (
        ["solve", str(PENDULUM), "--no-contacts", "--contacts", "collision"],
        ["--no-contacts and --contacts collision: give one of them"],
    ),
    "floor-with-no-contacts": (
        ["solve", str(PENDULUM), "--floor", "--no-contacts"],
        ["--floor needs contact points, and --no-contacts leaves them out"],
    ),
    "floor-without-collision-geometry": (
        ["solve", str(PENDULUM), "--floating", "--floor"],
        ["pendulum.urdf has no collision geometry"],
    ),
    "urdf-contacts-without-floor": (
        ["solve", str(PENDULUM), "--contacts", "collision"],
        ["pendulum.urdf: contacts 'collision'", "a URDF has no ground", "--floor"],
    ),
    "contacts-flag-on-a-scene-file": (
        ["solve", "pendulum", "--no-contacts"],
        ["contacts applies to a model file", "[model] contacts"],
    ),
    "floor-flag-on-a-scene-file": (
        ["solve", "box_on_floor", "--floor"],
        ["floor applies to a model file", "[model] floor"],
    ),
}

# Command line runs on good scenes: id -> arguments.
CLI_RUNS: dict[str, list[str]] = {
    **{f"json-{name}": ["solve", name, "--json"] for name in ["pendulum", "bistable_pendulum"]},
    "json-file": ["solve", str(ROBOTS / "slider_spring.toml"), "--json"],
    # The step budget ends these two: no Newton taking over at a damping event before it.
    "json-locked": [
        "solve",
        "panda_fingers_locked",
        "--json",
        "--max-steps",
        "100",
        "--no-newton-takeover",
    ],
    "torque-disk": ["solve", "torque_disk", "--json"],
    "torque-disk-text": ["solve", "torque_disk"],
    "max-steps-flag": ["solve", "pendulum", "--json", "--max-steps", "10", "--no-newton-takeover"],
    "flags-override-solver": ["solve", "torque_disk", "--json", "--max-steps", "100"],
    "kt-flag": ["solve", "slider_spring", "--json", "--kt", "0.5", "--energy", "simplified"],
    "start-flag": ["solve", "bistable_pendulum", "--json", "--start", "hinge=-0.2"],
    "start-flag-locked": [
        "solve",
        "panda_fingers_locked",
        "--json",
        "--max-steps",
        "3000",
        "--start",
        "panda_finger_joint1=0.035",
    ],
    "text": ["solve", "double_pendulum_springs"],
    "scenes": ["scenes"],
}


def write_case(folder: Path, case: str) -> Path:
    path = folder / f"{case}.toml"
    path.write_text(CASES[case][0], encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """Every case's scene file, and a broken URDF, in one folder."""
    folder = tmp_path_factory.mktemp("scenes")
    (folder / "broken.urdf").write_text("<robot name='x'><link name='a'></robot>\n")
    for case in CASES:
        write_case(folder, case)
    return folder


@pytest.fixture(scope="module")
def cli(folder, tmp_path_factory) -> dict[str, subprocess.CompletedProcess]:
    """Every command line run of this module, started together, from a folder that is
    neither the project nor the scene library (library scenes are found by name)."""
    cwd = tmp_path_factory.mktemp("cwd")
    runs = {f"case-{case}": ["solve", str(folder / f"{case}.toml")] for case in CASES}
    runs.update(
        {
            f"error-{key}": [a.format(tmp=folder) for a in args]
            for key, (args, _) in CLI_ERRORS.items()
        }
    )
    runs.update({f"run-{key}": args for key, args in CLI_RUNS.items()})

    def run(args: list[str]) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "pinsettle", *args],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=cwd,
        )

    with ThreadPoolExecutor(max_workers=2 * (os.cpu_count() or 1)) as pool:
        procs = dict(zip(runs, pool.map(run, runs.values()), strict=True))
    return procs


# --- load_scene -------------------------------------------------------------------------------


@pytest.mark.parametrize("case", sorted(CASES))
def test_load_scene_names_the_mistake(case, folder):
    _, error, fragments = CASES[case]
    path = folder / f"{case}.toml"
    with pytest.raises(error) as info:
        pinsettle.load_scene(path)
    message = str(info.value)
    assert message.startswith(f"{path}: "), message  # the file comes first
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    assert "\n" not in message


def test_missing_scene_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"^scene file not found: .*nope\.toml$"):
        pinsettle.load_scene(tmp_path / "nope.toml")
    with pytest.raises(FileNotFoundError, match=r"^scene file not found"):
        pinsettle.load_scene(tmp_path)  # a folder is not a scene file


def test_scene_error_is_a_value_error():
    assert issubclass(pinsettle.SceneError, ValueError)


def test_urdf_path_is_relative_to_the_scene_file(folder, tmp_path):
    # Written next to the scene, found from anywhere; the message names where it looked.
    (tmp_path / "pendulum.urdf").write_text(PENDULUM.read_text())
    scene_file = tmp_path / "ok.toml"
    scene_file.write_text('[model]\nurdf = "pendulum.urdf"\n')
    assert pinsettle.load_scene(scene_file).model.nq == 1
    with pytest.raises(pinsettle.SceneError, match=rf"URDF file not found: {folder}/nowhere.urdf"):
        pinsettle.load_scene(folder / "urdf-missing.toml")


def test_not_utf8(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(b"# caf\xe9\n[model]\nrobot = 'ur5'\n")
    with pytest.raises(pinsettle.SceneError, match=r"not a UTF-8 text file"):
        pinsettle.load_scene(path)


def test_scene_api_checks_like_the_file():
    # The same checks guard the Python API, without the file prefix.
    scene = pinsettle.Scene.from_urdf(PENDULUM)
    with pytest.raises(pinsettle.SceneError, match=r"^joint: unknown joint 'hing' \(did you mean"):
        scene.add_joint_spring("hing", 1.0)
    with pytest.raises(pinsettle.SceneError, match=r"^stiffness must be >= 0, got -1.0$"):
        scene.add_spring("arm", ("universe", [0, 0, -2]), -1.0)
    with pytest.raises(pinsettle.SceneError, match=r"^force must have 3 entries, got 2"):
        scene.add_load(frame="arm", force=[1.0, 2.0])
    with pytest.raises(pinsettle.SceneError, match=r"either 'joint' .* or 'frame', not both"):
        scene.add_load("hinge", 1.0, frame="arm")
    with pytest.raises(pinsettle.SceneError, match=r"^gravity must have 3 entries"):
        pinsettle.Scene(scene.model, gravity=[0.0, -9.81])
    with pytest.raises(TypeError, match=r"^model must be a pinocchio.Model"):
        pinsettle.Scene("pendulum.urdf")
    scene.lock("hinge")
    with pytest.raises(pinsettle.SceneError, match=r"every joint is locked"):
        pinsettle.solve(scene)
    # Nothing bad was kept.
    assert not scene.has_elements


# --- the command line: bad input --------------------------------------------------------------


def assert_clean_error(proc: subprocess.CompletedProcess, fragments: list[str]) -> None:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert proc.stdout == ""
    assert "Traceback" not in proc.stderr
    assert proc.stderr.startswith("pinsettle: error: "), proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr  # one line
    for fragment in fragments:
        assert fragment in proc.stderr, (fragment, proc.stderr)


@pytest.mark.parametrize("case", sorted(set(CASES) - {"urdf-broken"}))
def test_cli_scene_error(case, cli, folder):
    proc = cli[f"case-{case}"]
    assert_clean_error(proc, CASES[case][2])
    assert f"{folder / case}.toml: " in proc.stderr


def test_cli_broken_urdf(cli, folder):
    # urdfdom prints its own diagnosis to stderr before pinsettle's message: the message is
    # the last line, still with exit status 2 and no traceback.
    proc = cli["case-urdf-broken"]
    assert proc.returncode == 2 and proc.stdout == ""
    assert "Traceback" not in proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("pinsettle: error: ")
    for fragment in CASES["urdf-broken"][2]:
        assert fragment in last


@pytest.mark.parametrize("key", sorted(CLI_ERRORS))
def test_cli_error(key, cli):
    assert_clean_error(cli[f"error-{key}"], CLI_ERRORS[key][1])


# --- the command line: good scenes ------------------------------------------------------------

JSON_KEYS = {
    "status",
    "converged",
    "joints",
    "q",
    "steps",
    "peaks",
    "wall_time_s",
    "residual",
    "kinetic_energy",
    "stability",
    "min_stiffness_eigenvalue",
    "neutral_directions",
}


def json_of(proc: subprocess.CompletedProcess) -> dict:
    lines = proc.stdout.strip().splitlines()
    assert len(lines) == 1, proc.stdout  # exactly one JSON object, nothing else
    out = json.loads(lines[0])
    assert isinstance(out, dict)
    assert JSON_KEYS <= set(out), set(out)
    assert out["stability"] in ("stable", "neutral", "unstable")
    if out["converged"]:  # a saddle or a maximum is never reported converged
        assert out["stability"] != "unstable"
    assert out["converged"] == (out["status"] == "converged")
    assert proc.returncode == (0 if out["converged"] else 1), proc.stderr
    assert "Traceback" not in proc.stderr
    return out


@pytest.mark.parametrize("name", ["pendulum", "bistable_pendulum"])
def test_cli_json_by_name_from_any_folder(name, cli):
    out = json_of(cli[f"run-json-{name}"])
    assert out["status"] == "converged"
    scene = pinsettle.load_scene(ROBOTS / f"{name}.toml")
    result = pinsettle.solve(scene)
    assert out["q"] == result.q.tolist()  # same answer as the library, to the bit
    assert out["joints"] == result.joints
    assert out["steps"] == result.steps and out["peaks"] == result.peaks
    assert out["residual"] == result.residual < 1e-5
    assert Path(out["scene"]).name == f"{name}.toml"


def test_cli_json_of_a_file_path(cli):
    out = json_of(cli["run-json-file"])
    assert out["converged"]
    assert out["joints"]["slider"] == pytest.approx(-2.0 * 9.81 / 500.0, abs=1e-8)
    assert out["scene"] == str(ROBOTS / "slider_spring.toml")


def test_cli_json_of_a_locked_scene_has_the_full_q(cli):
    out = json_of(cli["run-json-locked"])
    assert out["status"] == "max_steps" and out["steps"] == 100
    assert len(out["q"]) == 9
    assert out["joints"]["panda_finger_joint1"] == out["joints"]["panda_finger_joint2"] == 0.02
    out = json_of(cli["run-start-flag-locked"])
    assert out["joints"]["panda_finger_joint1"] == 0.035


def test_cli_torque_disk_exits_1(cli):
    out = json_of(cli["run-torque-disk"])
    assert out["status"] == "no_equilibrium" and "falls without bound" in out["reason"]
    assert cli["run-torque-disk"].returncode == 1
    text = cli["run-torque-disk-text"]
    assert text.returncode == 1
    assert "status           no_equilibrium" in text.stdout
    assert "reason           the potential energy falls without bound" in text.stdout
    assert "Balanced disk" in text.stdout.splitlines()[0]  # the title is the description


def test_cli_flags_override_the_scene(cli):
    out = json_of(cli["run-max-steps-flag"])
    assert out["status"] == "max_steps" and out["steps"] == 10
    assert cli["run-max-steps-flag"].returncode == 1
    out = json_of(cli["run-flags-override-solver"])  # [solver] max_steps = 20000
    assert out["status"] == "max_steps" and out["steps"] == 100
    out = json_of(cli["run-kt-flag"])
    scene = pinsettle.load_scene(ROBOTS / "slider_spring.toml")
    result = pinsettle.solve(scene, kt=0.5, energy="simplified")
    assert out["steps"] == result.steps != pinsettle.solve(scene).steps
    assert out["q"] == result.q.tolist()


def test_cli_start_flag(cli):
    out = json_of(cli["run-start-flag"])
    assert out["converged"]
    # The mirror pose of the scene's own start (+0.2 -> +0.637354).
    assert out["joints"]["hinge"] == pytest.approx(-0.637354, abs=1e-6)
    scene = pinsettle.load_scene(ROBOTS / "bistable_pendulum.toml")
    assert out["q"] == pinsettle.solve(scene, [-0.2]).q.tolist()


def test_cli_text_output(cli):
    proc = cli["run-text"]
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("double_pendulum_springs: Double pendulum")
    assert "status           converged" in proc.stdout
    values = dict(line.split() for line in lines if line.startswith("  joint"))
    assert float(values["joint1"]) == pytest.approx(0.738965, abs=1e-6)
    assert float(values["joint2"]) == pytest.approx(-0.105215, abs=1e-6)


def test_cli_scenes_lists_the_library(cli):
    proc = cli["run-scenes"]
    assert proc.returncode == 0 and proc.stderr == ""
    rows = [line.split(None, 1) for line in proc.stdout.strip().splitlines()]
    assert all(len(row) == 2 and row[1].strip() for row in rows), rows  # a description each
    names = [row[0] for row in rows]
    assert names == sorted(p.stem for p in ROBOTS.glob("*.toml"))
    descriptions = dict(rows)
    for name in names:
        first = (ROBOTS / f"{name}.toml").read_text().splitlines()[0]
        assert descriptions[name].strip() == first.lstrip("#").strip()


def test_cli_json_is_the_result_dict():
    # In process: the JSON object is Result.to_dict() plus the scene path.
    scene = pinsettle.load_scene(ROBOTS / "slider_spring.toml")
    out = pinsettle.solve(scene).to_dict()
    assert JSON_KEYS <= set(out)
    assert json.loads(json.dumps(out))["joints"] == out["joints"]
    assert math.isfinite(out["wall_time_s"]) and out["wall_time_s"] >= 0
    assert np.isclose(out["residual"], scene.residual(np.array(out["q"])), rtol=1e-12)

"""The ``pinsettle`` command line."""

from __future__ import annotations

import argparse
import json
import re
import signal
import sys
import time
import webbrowser
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio

import pinsettle
from pinsettle._cli_flags import (
    CONTACT_FLAGS,
    Flag,
    add_flags,
    contact_options,
    flag,
    setting_flags,
)
from pinsettle._memory import new_data
from pinsettle._model_files import ROBOT_SRDF, robot_srdf
from pinsettle._progress import StatusLine, status_line
from pinsettle._settings import SETTING_FIELDS, SETTING_TYPES
from pinsettle._solve import effort_kinds, effort_unit

#: The solver settings' flags, made from the settings' one declaration (a flag's name is its
#: setting's, as _setting_overrides reads it).
SETTING_FLAGS = setting_flags(SETTING_FIELDS)

#: How a model file (URDF, MJCF) becomes a scene.
MODEL_FILE_FLAGS = (
    flag(
        "--floating",
        action="store_true",
        help="with a model file (URDF, MJCF): a free-flyer joint on the root body of a file "
        "that has none (default: the root as the file has it: fixed, or free by an MJCF "
        "<freejoint>, which floats without this flag)",
    ),
    flag(
        "--free-objects",
        choices=["keep", "lock"],
        help="with an MJCF file: its free objects (bodies whose only joint is a free joint, "
        "beside the mechanism) stay free and fall (keep, the default) or are fixed where the "
        "file places them (lock)",
    ),
    flag(
        "--actuator-springs",
        action="store_true",
        help="with an MJCF file: each position actuator on a hinge or slide joint is a joint "
        "spring of stiffness kp towards its control (0, or the ctrl of the keyframe a scene "
        "file's [start] pose names) (default: actuators left out)",
    ),
    *CONTACT_FLAGS,
)

START_FLAG = flag(
    "--start",
    action="append",
    default=[],
    metavar="JOINT=VALUE",
    help="override a joint's start value (repeatable): a number (rad or m), or "
    "comma-separated values for a multi-DoF joint, a quaternion w first as in MuJoCo's "
    "qpos: a free joint x,y,z,qw,qx,qy,qz (root=0,0,1.4,1,0,0,0: 1.4 m up, not turned), "
    "a ball joint qw,qx,qy,qz. The JSON's 'joints' use this order too; its 'q' is "
    "Pinocchio's (w last)",
)

QUIET_FLAG = flag(
    "-q",
    "--quiet",
    action="store_true",
    help="no live progress line (shown on stderr, when it is a terminal, once a solve has "
    "run 0.5 s)",
)

JSON_FLAG = flag("--json", action="store_true", help="print one JSON object")

SCENE_ARGUMENT = flag(
    "scene", help="scene file (.toml), scene name, or model file (.urdf, MJCF .xml)"
)

#: hold and payload: a robot name as well (its URDF).
HELD_SCENE_ARGUMENT = flag(
    "scene",
    help="scene file (.toml), scene name, model file (.urdf, MJCF .xml), or robot name of "
    "example-robot-data (`pinsettle robots`; a scene name first)",
)


def _limits_flag(what: str) -> Flag:
    """--no-limits, for a model (``what``: 'robot', or 'scene model' that has [[limit]] too)."""
    return flag(
        "--no-limits",
        action="store_true",
        help=f"ignore the {what}'s position limits: no joint stops"
        + (" but those of [[limit]]" if what == "scene model" else ""),
    )


def _add_setting_flags(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("solver settings (defaults: pinsettle.Settings())")
    add_flags(group, SETTING_FLAGS)


def _add_limits_flag(parser: argparse.ArgumentParser, what: str) -> None:
    _limits_flag(what).add_to(parser)


def _progress_line(args: argparse.Namespace) -> AbstractContextManager[StatusLine | None]:
    """The live progress line while solving (None off a terminal, with --json or --quiet)."""
    return status_line(sys.stderr, not (args.quiet or getattr(args, "json", False)))


def _limits(args: argparse.Namespace) -> bool | None:
    """False with --no-limits, else None (the model's or the scene's own setting)."""
    return False if args.no_limits else None


def _rest_check(model: pinocchio.Model, q: np.ndarray, limits: bool) -> float:
    """The residual of a rest recomputed with pinocchio alone: |g(q)| on the joints off their
    stops, and on a joint at a stop of the model's position limits the pull asked of the stop
    (max(0, -g) at the lower, max(0, g) at the upper)."""
    g = pinocchio.computeGeneralizedGravity(model, new_data(model, "the residual check"), q)
    violation = np.abs(g)
    if limits:
        for j in range(1, model.njoints):
            if model.nqs[j] != 1 or model.nvs[j] != 1:
                continue
            iq, iv = model.idx_qs[j], model.idx_vs[j]
            lower, upper = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
            if lower == upper:  # a URDF's default when left out: no stop
                continue
            if abs(lower) < 1e10 and q[iq] <= lower:
                violation[iv] = max(0.0, -g[iv])
            elif abs(upper) < 1e10 and q[iq] >= upper:
                violation[iv] = max(0.0, g[iv])
    return float(violation.max()) if violation.size else 0.0


def _setting_overrides(args: argparse.Namespace) -> dict[str, Any]:
    # Every setting that has a flag (the flags' names are the settings' own).
    return {k: getattr(args, k) for k in SETTING_TYPES if getattr(args, k, None) is not None}


def _demo(args: argparse.Namespace) -> int:
    model = pinsettle.load_robot(args.robot)
    q0 = pinocchio.neutral(model)
    with _progress_line(args) as progress:
        result = pinsettle.solve(
            model, q0, limits=_limits(args), progress=progress, **_setting_overrides(args)
        )
    if args.json:
        print(json.dumps(result.to_dict()))
    else:
        print(f"{args.robot}: {model.nq} configuration variables, released at rest from neutral")
        print(result.summary(model))
        independent = _rest_check(model, result.q, result.limits)
        unit = effort_unit(effort_kinds(model))
        if result.at_limit:
            print(
                f"check            {independent:.3e} {unit}: |g(q)| off the stops, pull asked "
                "of a stop, recomputed with pinocchio"
            )
        else:
            print(f"check            |g(q)| = {independent:.3e} {unit} recomputed with pinocchio")
    return 0 if result.converged else 1


def _parse_start(items: list[str]) -> list[tuple[str, str, float | list[float]]]:
    """(the flag's text, joint name, value) of each --start JOINT=VALUE, in order."""
    out: list[tuple[str, str, float | list[float]]] = []
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise ValueError(f"--start expects JOINT=VALUE (e.g. elbow=0.3), got '{item}'")
        try:
            values = [float(x) for x in text.split(",")]
        except ValueError:
            raise ValueError(
                f"--start {name}: expected a number or comma-separated numbers, got '{text}'"
            ) from None
        out.append((item, name, values[0] if len(values) == 1 else values))
    return out


def _set_pose(scene: pinsettle.Scene, pose: str) -> None:
    """--pose: a named pose of the scene, the robot's own SRDF read for it as [start] pose
    does when the scene names none (a robot of example-robot-data)."""
    own = None
    if scene.urdf is not None and pose not in scene.poses and not scene.srdf:
        robots = {pinsettle.robot_urdf(name): name for name in ROBOT_SRDF}
        own = robot_srdf(robots[scene.urdf]) if scene.urdf in robots else None
    if own is not None:
        scene.load_srdf(own)
    try:
        scene.set_pose(pose)
    except pinsettle.SceneError as error:
        raise pinsettle.SceneError(f"--pose {pose}: {error}") from None


def _load_scene(args: argparse.Namespace) -> tuple[pinsettle.Scene, np.ndarray | None]:
    """The scene of args.scene (a scene file or name, a URDF or an MJCF file) and the start of
    its --start flags (None: the scene's own)."""
    path = args.scene
    if getattr(args, "robot_names", False) and not Path(path).is_file():
        # hold and payload take a robot of example-robot-data too, as its URDF
        if path not in pinsettle.scene_names() and path in pinsettle.robot_names():
            path = pinsettle.robot_urdf(path)
    scene = pinsettle.load_scene(
        path,
        floating=True if args.floating else None,
        free_objects=args.free_objects,
        actuator_springs=True if args.actuator_springs else None,
        **contact_options(args),
    )
    pose = getattr(args, "pose", None)  # the commands of _HOLDING have --pose
    if pose is not None:
        _set_pose(scene, pose)
    if not args.start:
        return scene, None if pose is None else scene.q0()
    for item, name, value in _parse_start(args.start):
        # An error names the flag as typed: "--start root=0,0,1,2,0,0,0: the quaternion ..."
        scene._set_joint_start(name, value, f"--start {item}")
    return scene, scene.q0()


# The C++ configuration check's message (Python API users pass Pinocchio's q, and read this):
# "q0[0:7] (joint 'root', JointModelFreeFlyer) = [...] holds a quaternion or cos/sin pair of
# norm 2; it must be 1 within 1e-6 (e.g. pinocchio.normalize)".
_UNIT_NORM = re.compile(
    r"^q0?\[\d+:\d+\] \(joint '(?P<joint>[^']*)', (?P<kind>\w+)\) = \[[^\]]*\] holds a "
    r"quaternion or cos/sin pair of norm (?P<norm>\S+); it must be 1 within \S+ "
    r"\(e\.g\. pinocchio\.normalize\)$"
)


def _for_the_command_line(message: str) -> str:
    """An error of the Python layer as a command-line user reads it: the start of a joint by
    name, its value w first, instead of Pinocchio's configuration indices."""
    found = _UNIT_NORM.match(message)
    if found is None:
        return message
    joint, kind, norm = found.group("joint", "kind", "norm")
    return (
        f"the start of joint '{joint}' ({kind}) holds a quaternion or cos/sin pair of norm "
        f"{norm}; give it unit norm, a quaternion w first (--start {joint}=... as in MuJoCo's "
        "qpos: x,y,z,qw,qx,qy,qz for a free joint, qw,qx,qy,qz for a ball joint)"
    )


def _print_title(scene: pinsettle.Scene) -> None:
    """The scene's name and description, and its notes."""
    print(f"{scene.name}: {scene.description}" if scene.description else scene.name)
    for note in scene.notes:  # what the model file says that the scene leaves out
        print(f"{'note':<17}{note}")


def _solve(args: argparse.Namespace) -> int:
    scene, q0 = _load_scene(args)
    with _progress_line(args) as progress:
        result = pinsettle.solve(
            scene, q0, limits=_limits(args), progress=progress, **_setting_overrides(args)
        )
    if args.json:
        out = {"scene": str(scene.path), "notes": scene.notes, **result.to_dict()}
        print(json.dumps(out))
    else:
        _print_title(scene)
        print(result.summary(scene))
    return 0 if result.converged else 1


def _hold(args: argparse.Namespace) -> int:
    from pinsettle._hold import hold, hold_summary

    scene, q0 = _load_scene(args)
    result = hold(scene, q0)
    if args.json:
        print(json.dumps({"scene": str(scene.path), "notes": scene.notes, **result.to_dict()}))
    else:
        _print_title(scene)
        print(hold_summary(scene.model, result))
    return 1 if result.over_limit else 0


def _payload(args: argparse.Namespace) -> int:
    from pinsettle._hold import payload_at, payload_summary

    scene, q0 = _load_scene(args)
    result = payload_at(scene, q0, args.frame, args.offset, ("--frame", "--offset"))
    if args.json:
        print(json.dumps({"scene": str(scene.path), "notes": scene.notes, **result.to_dict()}))
    else:
        _print_title(scene)
        print(payload_summary(scene.model, result))
    return 1 if result.hold.over_limit else 0


def _speed(text: str) -> float:
    from pinsettle.play import check_speed

    try:
        return check_speed(float(text))
    except ValueError:
        raise ValueError(
            "--speed must be a positive number (simulated seconds per second of playback), "
            f"got '{text}'"
        ) from None


def _serve(viz: Any) -> None:
    """Keep the live server up until Ctrl-C or SIGTERM (then the caller closes it)."""

    def stop(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        while viz.window.server.running:
            time.sleep(0.2)
        print("pinsettle: the meshcat server stopped", file=sys.stderr)
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)


def _play_files(args: argparse.Namespace) -> tuple[Path | None, Path | None]:
    """The page of --html and the plot of --plot (by default with --html: next to the page),
    their folders checked."""
    html = None if args.html is None else Path(args.html)
    plot = Path(args.plot) if args.plot else None
    if html is not None and plot is None:
        plot = html.with_name(html.stem + "_energy.png")
    for name, path in (("--html", html), ("--plot", plot)):
        if path is not None and not path.parent.is_dir():
            raise FileNotFoundError(f"{name} {path}: no such folder: {path.parent}")
    return html, plot


def _show(viz: Any, html: Path | None, plot: Path | None, browse: bool) -> None:
    """Say what plays and where; open the page (``browse``), or serve it live until Ctrl-C."""
    timeline = viz.timeline
    print(
        f"playback: {timeline.sim_time:.4g} s simulated in {timeline.duration:.3g} s "
        f"(speed x{timeline.speed:.3g}), then the final pose held"
    )
    for path in (html, plot):
        if path is not None:
            print(f"wrote {path}")
    if html is not None:
        if browse:
            webbrowser.open(html.resolve().as_uri(), new=2)
        return
    print(f"meshcat: {viz.url} (Ctrl-C to stop)", flush=True)
    if browse:
        viz.open()
    _serve(viz)


def _play(args: argparse.Namespace) -> int:
    # Here, not at the top: the other commands never load the playback module.
    from pinsettle.play import TRACE_SETTINGS, play, require

    require()  # before solving: a missing extra is a one-line message, exit 2
    speed = None if args.speed is None else _speed(args.speed)
    html, plot = _play_files(args)
    scene, q0 = _load_scene(args)
    overrides = {**_setting_overrides(args), **TRACE_SETTINGS}
    with _progress_line(args) as progress:
        result = pinsettle.solve(scene, q0, limits=_limits(args), progress=progress, **overrides)
    _print_title(scene)
    print(
        f"{result.status}: {result.steps} steps, {result.peaks} damping events, "
        f"{result.sim_time:.4g} s simulated"
    )
    with play(scene, result, speed=speed, html=html, plot=plot, live=html is None) as viz:
        _show(viz, html, plot, not args.no_open)
    return 0 if result.converged else 1


def _scenes(args: argparse.Namespace) -> int:
    for name in pinsettle.scene_names():
        scene_file = pinsettle.scene_path(name)
        description = pinsettle._scene._description(scene_file)
        print(f"{name:<28} {description}")
    return 0


def _robots(args: argparse.Namespace) -> int:
    for name in pinsettle.robot_names():
        floating = pinsettle.robots.ROBOTS[name][1]
        print(f"{name:<28} {'floating base' if floating else 'fixed base'}")
    return 0


def _cmake_dir(args: argparse.Namespace) -> int:
    print(pinsettle.get_cmake_dir())
    return 0


@dataclass(frozen=True)
class _Command:
    """A subcommand: its name, help, arguments (in the order of its help) and function; the
    solver settings' flags last when it solves."""

    name: str
    help: str
    func: Callable[[argparse.Namespace], int]
    flags: tuple[Flag, ...] = ()
    settings: bool = False
    description: str | None = None
    robot_names: bool = False  # SCENE may be a robot name of example-robot-data

    def add_to(self, sub: Any) -> None:
        parser = sub.add_parser(self.name, help=self.help, description=self.description)
        add_flags(parser, self.flags)
        if self.settings:
            _add_setting_flags(parser)
        parser.set_defaults(func=self.func, robot_names=self.robot_names)


#: The commands that solve one scene: their own arguments, then those of the model and start.
_SOLVING = (
    _Command(
        "demo",
        "settle a robot of example-robot-data from its neutral pose",
        _demo,
        (
            flag("robot", nargs="?", default="ur5", help="robot name (see `pinsettle robots`)"),
            JSON_FLAG,
            _limits_flag("robot"),
            QUIET_FLAG,
        ),
        settings=True,
    ),
    _Command(
        "solve",
        "settle a scene file (a path, or a scene name of `pinsettle scenes`)",
        _solve,
        (
            SCENE_ARGUMENT,
            JSON_FLAG,
            _limits_flag("scene model"),
            QUIET_FLAG,
            *MODEL_FILE_FLAGS,
            START_FLAG,
        ),
        settings=True,
    ),
    _Command(
        "play",
        "solve a scene and play how it settles in meshcat (needs pinsettle[viz])",
        _play,
        (
            SCENE_ARGUMENT,
            flag(
                "--speed",
                metavar="X",
                help="simulated seconds per second of playback (default: real time, faster so "
                "that a long settle plays in about 6 s, slower so that a short one plays in 3 s)",
            ),
            flag("--html", metavar="FILE", help="write a static HTML page (no server)"),
            flag(
                "--plot",
                metavar="FILE",
                help="energy plot (PNG; default with --html: FILE_energy.png)",
            ),
            flag("--no-open", action="store_true", help="do not open a browser"),
            _limits_flag("scene model"),
            QUIET_FLAG,
            *MODEL_FILE_FLAGS,
            START_FLAG,
        ),
        settings=True,
        description="Solve a scene and play the settling motion in meshcat: live in the "
        "browser (a server on 127.0.0.1 until Ctrl-C), or with --html as a self-contained "
        "page plus the energy plot (PNG) next to it.",
    ),
)

POSE_FLAG = flag(
    "--pose",
    metavar="NAME",
    help="start from a named pose of the model (an SRDF's group_state, an MJCF keyframe); "
    "--start then overrides single joints",
)

#: The commands that read what a pose asks of its motors (no solve: the pose is given).
_HOLDING = (
    _Command(
        "hold",
        "the joint efforts that hold a scene still at its start pose, against their limits",
        _hold,
        (HELD_SCENE_ARGUMENT, JSON_FLAG, *MODEL_FILE_FLAGS, POSE_FLAG, START_FLAG),
        description="The effort each joint's motor applies to hold the mechanism still at the "
        "pose (the scene's start, --pose, --start): gravity minus the scene's springs and "
        "loads, with each joint's effort limit (a URDF's <limit effort>) and the joints over "
        "it. Exit status 1 when a joint is over its limit.",
        robot_names=True,
    ),
    _Command(
        "payload",
        "the largest mass a frame can carry at a pose with every joint within its limit",
        _payload,
        (
            HELD_SCENE_ARGUMENT,
            flag("--frame", required=True, metavar="F", help="frame (link) that carries it"),
            flag(
                "--offset",
                nargs=3,
                type=float,
                default=[0.0, 0.0, 0.0],
                metavar=("X", "Y", "Z"),
                help="the mass's point from the frame's origin, in the frame's axes (m; "
                "default 0 0 0)",
            ),
            JSON_FLAG,
            *MODEL_FILE_FLAGS,
            POSE_FLAG,
            START_FLAG,
        ),
        description="The largest point mass at the frame (its origin, or --offset) that the "
        "pose holds with every joint within its effort limit, and the joint that limits it. "
        "Exit status 1 when the pose cannot hold even no payload.",
        robot_names=True,
    ),
)

#: The commands that list what the package has.
_LISTING = (
    _Command("scenes", "list the scenes of the library with a description", _scenes),
    _Command("robots", "list the robot names", _robots),
    _Command("cmake-dir", "print the folder of pinsettleConfig.cmake", _cmake_dir),
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pinsettle",
        description="Static equilibrium of mechanisms by kinetic damping on Pinocchio.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for command in (*_SOLVING, *_HOLDING):
        command.add_to(sub)
    # The sweep command lives with the sweep (pandas is imported only when it runs).
    from pinsettle import _sweep_cli

    _sweep_cli.add_parser(sub, _add_setting_flags, _add_limits_flag, _setting_overrides)
    for command in _LISTING:
        command.add_to(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        status: int = args.func(args)
        return status
    except (ValueError, TypeError, FileNotFoundError, IsADirectoryError, MemoryError) as error:
        print(f"pinsettle: error: {_for_the_command_line(str(error))}", file=sys.stderr)
        return 2
    except ImportError as error:  # pinsettle play without its optional extra
        from pinsettle.play import MissingDependencyError

        if not isinstance(error, MissingDependencyError):
            raise
        print(f"pinsettle: error: {error}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into head: not an error
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())

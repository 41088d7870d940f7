"""The ``pinsettle`` command line."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def _add_setting_flags(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("solver settings (defaults: pinsettle.Settings())")
    group.add_argument("--energy", choices=["exact", "simplified"], help="peak-detector signal")
    group.add_argument("--kt", type=float, help="velocity scale at each energy peak, in [0, 1)")
    group.add_argument("--dt", type=float, help="time step (s)")
    group.add_argument("--err", type=float, help="relative peak threshold")
    group.add_argument("--ds", type=int, help="stopping window (steps)")
    group.add_argument("--max-e", type=float, help="bound on the energy summed over the window")
    group.add_argument("--max-steps", type=int, help="largest number of steps")
    group.add_argument("--max-time", type=float, help="wall-clock budget (s)")
    group.add_argument("--backtrack", action="store_true", default=None, help="back up to the peak")


def _setting_overrides(args: argparse.Namespace) -> dict:
    keys = ["energy", "kt", "dt", "err", "ds", "max_e", "max_steps", "max_time", "backtrack"]
    return {k: getattr(args, k) for k in keys if getattr(args, k) is not None}


def _demo(args: argparse.Namespace) -> int:
    import pinocchio

    import pinsettle

    model = pinsettle.load_robot(args.robot)
    q0 = pinocchio.neutral(model)
    result = pinsettle.solve(model, q0, **_setting_overrides(args))
    if args.json:
        print(json.dumps(_result_json(model, result)))
    else:
        print(f"{args.robot}: {model.nq} configuration variables, released at rest from neutral")
        print(result.summary(model))
        independent = np.max(
            np.abs(pinocchio.computeGeneralizedGravity(model, model.createData(), result.q))
        )
        print(f"check            |g(q)| = {independent:.3e} recomputed with pinocchio")
    return 0 if result.converged else 1


def _result_json(model, result) -> dict:
    joints = {}
    for j in range(1, model.njoints):
        iq, nq = model.idx_qs[j], model.nqs[j]
        values = result.q[iq : iq + nq].tolist()
        joints[model.names[j]] = values[0] if nq == 1 else values
    return {
        "status": result.status,
        "converged": result.converged,
        "joints": joints,
        "q": result.q.tolist(),
        "steps": result.steps,
        "peaks": result.peaks,
        "wall_time_s": result.wall_time,
        "residual": result.residual,
        "kinetic_energy": result.kinetic_energy,
    }


def _robots(args: argparse.Namespace) -> int:
    import pinsettle

    for name in pinsettle.robot_names():
        floating = pinsettle.robots.ROBOTS[name][1]
        print(f"{name:<28} {'floating base' if floating else 'fixed base'}")
    return 0


def _cmake_dir(args: argparse.Namespace) -> int:
    import pinsettle

    print(pinsettle.get_cmake_dir())
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="pinsettle",
        description="Static equilibrium of mechanisms by kinetic damping on Pinocchio.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="settle a robot of example-robot-data from its neutral pose")
    demo.add_argument("robot", nargs="?", default="ur5", help="robot name (see `pinsettle robots`)")
    demo.add_argument("--json", action="store_true", help="print one JSON object")
    _add_setting_flags(demo)
    demo.set_defaults(func=_demo)
    robots = sub.add_parser("robots", help="list the robot names")
    robots.set_defaults(func=_robots)
    cmake = sub.add_parser("cmake-dir", help="print the folder of pinsettleConfig.cmake")
    cmake.set_defaults(func=_cmake_dir)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, TypeError, FileNotFoundError) as error:
        print(f"pinsettle: error: {error}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into head: not an error
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())

"""``pinsettle sweep``: many cases of a scene from the command line, a table in a file.

A progress bar on stderr when it is a terminal (not with --json), a summary (counts by status,
distinct rests, jumps, throughput), the table written to --out (Parquet or CSV). Ctrl-C stops
after the cases in flight and writes what is done; the same command with the same --out skips
the cases already there (resume).
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from . import _sweep, _sweep_cases, _sweep_plot
from ._cli_flags import CONTACT_FLAGS, add_flags, check_flags, contact_options, flag, switch
from ._scene import load_scene
from .scenes import scene_path

#: Exit status of a sweep stopped by Ctrl-C (what a shell reports for SIGINT).
EXIT_INTERRUPTED = 130
FORMATS = (".parquet", ".csv")


def _random_count(args: argparse.Namespace) -> str | None:
    if args.random is not None and args.random < 1:
        return f"--random N: N must be an integer >= 1, got {args.random}"
    return None


def _seed_with_random(args: argparse.Namespace) -> str | None:
    return "--seed goes with --random N" if args.seed is not None and args.random is None else None


def _plot_file(args: argparse.Namespace) -> str | None:
    """--plot FILE: a .png or .svg file in a folder that exists, matplotlib installed."""
    if args.plot is None:
        return None
    path = Path(args.plot)
    try:
        _sweep_plot.plot_format(path, _sweep_plot.FLAG_NAMES)
        _sweep_plot.require_matplotlib(f"--plot {args.plot}")
    except (ValueError, ImportError) as error:
        return str(error)
    if not path.parent.is_dir():
        return f"--plot {args.plot}: no such folder: {path.parent}"
    if path.is_dir():
        return f"--plot {args.plot} is a folder"
    return None


def _with_plot(args: argparse.Namespace) -> str | None:
    given = [
        f for f, v in (("--plot-column", args.plot_column), ("--plot-key", args.plot_key)) if v
    ]
    if given and args.plot is None:
        return f"{given[0]} goes with --plot FILE"
    return None


def _workers_here(args: argparse.Namespace) -> str | None:
    if args.workers is not None and args.scheduler is not None:
        return "--workers sets local threads; with --scheduler the cluster's run"
    return None


#: The sweep's own arguments, in the order of its help; the checks run in this order too.
FLAGS = (
    flag("scene", help="scene file (.toml), scene name, or model file (.urdf, MJCF .xml)"),
    flag(
        "--vary",
        action="append",
        default=[],
        metavar="KEY=LO:HI:N",
        help="a scene value and its values: N evenly spaced from LO to HI, or a list V1,V2,... "
        "(repeatable: the full grid). Keys: start.JOINT, joint_spring[i].stiffness|rest|damping, "
        "spring[i].stiffness|rest_length|damping, load[i].effort|force|torque|point, "
        "payload[i].mass|offset, gravity, payload.FRAME.mass (a vector value: a magnitude "
        "along the scene's own vector)",
    ),
    flag(
        "--random",
        type=int,
        metavar="N",
        help="N random starts in the limits",
        check=_random_count,
    ),
    flag(
        "--seed",
        type=int,
        metavar="S",
        help="seed of --random (default 0)",
        check=_seed_with_random,
    ),
    flag("--zip", action="store_true", help="pair the --vary values, no grid"),
    switch(
        "--continuation",
        help="start each case from the previous rest and mark jumps (default: on for one "
        "--vary key or --zip)",
    ),
    flag(
        "--workers",
        type=int,
        metavar="N",
        help="local threads (default: cores)",
        check=_workers_here,
    ),
    flag(
        "--scheduler",
        metavar="ADDRESS",
        help="run the cases on the Dask scheduler at tcp://HOST:PORT (pinsettle[cluster])",
    ),
    flag("--out", metavar="FILE", help="the table: FILE.parquet or FILE.csv"),
    flag("--json", action="store_true", help="print one JSON object, no bar"),
    flag(
        "--plot",
        metavar="FILE",
        help="also plot the table, FILE.png or FILE.svg (matplotlib: pinsettle[viz]): a column "
        "against the varied key, the jumps marked",
        check=_plot_file,
    ),
    flag(
        "--plot-column",
        action="append",
        metavar="NAME",
        help="a column of the table to plot (repeatable; default: every joint's value)",
    ),
    flag(
        "--plot-key",
        metavar="KEY",
        help="the column to plot against (default: the varied key; needed when several vary)",
        check=_with_plot,
    ),
)


def add_parser(
    sub: Any,
    add_setting_flags: Callable[[argparse.ArgumentParser], None],
    add_limits_flag: Callable[[argparse.ArgumentParser, str], None],
    overrides: Callable[[argparse.Namespace], dict[str, Any]],
) -> None:
    """The ``sweep`` subcommand (the setting and limits flags are the other commands')."""
    parser = sub.add_parser(
        "sweep",
        help="solve many cases of a scene (a grid of values, random starts) into a table",
        description="Solve a scene for every combination of --vary values and starts, on every "
        "core (or a Dask cluster with --scheduler), and write one row per case to --out. "
        "Ctrl-C stops after the cases in flight and writes what is done; the same command "
        "again resumes. Exit status: 0 every case converged, 1 some did not, 2 bad input, 130 "
        "interrupted.",
    )
    add_flags(parser, FLAGS)
    add_flags(parser, CONTACT_FLAGS)
    add_limits_flag(parser, "scene model")
    add_setting_flags(parser)
    parser.set_defaults(func=lambda args: run(args, overrides(args)))


def parse_vary(items: list[str]) -> dict[str, list[float]]:
    """--vary KEY=LO:HI:N or KEY=V1,V2,... as key -> values.

    Raises:
        ValueError: the form, a number, N < 1, or a key given twice; naming the flag.
    """
    out: dict[str, list[float]] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key or not text:
            raise ValueError(f"--vary expects KEY=LO:HI:N or KEY=V1,V2,..., got '{item}'")
        if key in out:
            raise ValueError(f"--vary {key} is given twice")
        try:
            if ":" in text:
                lo, hi, n = text.split(":")
                count = int(n)
                if count < 1:
                    raise ValueError(f"--vary {item}: N must be an integer >= 1, got {count}")
                values = np.linspace(float(lo), float(hi), count).tolist()
            else:
                values = [float(x) for x in text.split(",")]
        except ValueError as error:
            if str(error).startswith("--vary"):
                raise
            raise ValueError(
                f"--vary {item}: expected LO:HI:N (numbers, N an integer) or V1,V2,... (numbers)"
            ) from None
        bad = [x for x in values if not math.isfinite(x)]
        if bad:
            raise ValueError(f"--vary {item}: values must be finite, got {bad[0]}")
        out[key] = values
    return out


def _out_path(text: str | None) -> Path | None:
    if text is None:
        return None
    path = Path(text)
    if path.suffix not in FORMATS:
        raise ValueError(f"--out {text}: the file must end in .parquet or .csv")
    if not path.parent.is_dir():
        raise FileNotFoundError(f"--out {text}: no such folder: {path.parent}")
    if path.is_dir():
        raise IsADirectoryError(f"--out {text} is a folder")
    if path.suffix == ".parquet":
        try:
            importlib.import_module("pyarrow")
        except ImportError:
            raise _sweep_cases.MissingDependencyError(
                f"--out {text}: Parquet needs pyarrow: {_sweep_cases.SWEEP_EXTRA}"
            ) from None
    return path


def read_table(path: Path) -> Any:
    """A table written by ``write_table``."""
    pd = _sweep_cases.pandas()
    try:
        if path.suffix == ".parquet":
            return pd.read_parquet(path)
        # Numbers read back exactly (pandas 3 does by default; 2.x needs asking).
        exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
        return pd.read_csv(path, keep_default_na=False, na_values=[""], **exact)
    except Exception as error:  # a file of something else: say which and why
        raise ValueError(f"--out {path}: cannot read the table there to resume: {error}") from None


def write_table(df: Any, path: Path) -> None:
    """Write the table next to ``path`` then move it there: an interrupted write leaves the
    old file whole."""
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        if path.suffix == ".parquet":
            df.to_parquet(temporary, index=False)
        else:
            df.to_csv(temporary, index=False)
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def records(df: Any) -> list[dict[str, Any]]:
    """The rows as JSON-ready dicts: numbers exact (repr), missing values None."""

    def plain(value: Any) -> Any:
        if isinstance(value, np.generic):
            value = value.item()
        if value is None or (isinstance(value, float) and math.isnan(value)):
            return None
        if type(value).__name__ == "NAType":
            return None
        return value

    return [{k: plain(v) for k, v in row.items()} for row in df.to_dict(orient="records")]


def _varied(df: Any) -> list[str]:
    """The table's columns of the varied values (``KEY``, or ``KEY[k]`` for a vector)."""
    vary = df.attrs["pinsettle"]["vary"]
    return [c for c in df.columns if c in vary or c.split("[")[0] in vary]


def summary(df: Any, out: Path | None) -> dict[str, Any]:
    """What the sweep found, as JSON-ready values."""
    meta = df.attrs["pinsettle"]
    counts = {str(k): int(v) for k, v in df["status"].value_counts(sort=False).items()}
    rests = _sweep.distinct_rests(df)
    jumps = df[df["jump"].fillna(False)] if "jump" in df.columns else df.iloc[0:0]
    solved, wall = meta["solved"], meta["wall_time"]
    return {
        "scene": meta["scene"],
        "cases": meta["cases"],
        "done": len(df),
        "solved": solved,
        "resumed": meta["resumed"],
        "interrupted": meta["interrupted"],
        "workers": meta["workers"],
        "cluster": meta["cluster"],
        "wall_time_s": wall,
        "cases_per_s": solved / wall if wall > 0 else None,
        "status_counts": counts,
        "distinct_rests": records(rests),
        "jumps": records(jumps[["case", *_varied(df)]]),
        "out": None if out is None else str(out),
    }


def _print_totals(info: dict[str, Any]) -> None:
    """The cases done, where and how fast, and their count by status."""
    where = "on the cluster's" if info["cluster"] else "on"
    rate = info["cases_per_s"]
    print(
        f"{info['scene']}: {info['done']} of {info['cases']} cases"
        + (f" ({info['resumed']} from the file)" if info["resumed"] else "")
        + f"; {info['solved']} run in {info['wall_time_s']:.3g} s {where} "
        f"{info['workers']} worker{'s' if info['workers'] != 1 else ''}"
        + (f", {rate:.4g} cases/s" if rate else "")
    )
    print("status   " + ", ".join(f"{k} {v}" for k, v in info["status_counts"].items()))


def _print_errors(failed: Any) -> None:
    """The first three errors, each with its first case and how many more had it."""
    for message, cases in list(failed.groupby("error", sort=False)["case"])[:3]:
        first = int(cases.iloc[0])
        more = f" and {len(cases) - 1} more" if len(cases) > 1 else ""
        print(f"error    case {first}{more}: {message}")


def _print_rests(rests: list[dict[str, Any]], varied: list[str], joints: list[str]) -> None:
    """The distinct rests (the first ten) or, when the varied values make groups, how many
    there are in each group."""
    groups = {tuple(r.get(c) for c in varied) for r in rests}
    if len(groups) > 1:
        per = [sum(1 for r in rests if tuple(r.get(c) for c in varied) == g) for g in groups]
        count = f"{min(per)}" if min(per) == max(per) else f"{min(per)} to {max(per)}"
        print(f"rests    {count} distinct at each of the {len(groups)} values of the varied keys")
        return
    tolerance = _sweep_cases.REST_TOLERANCE
    print(f"rests    {len(rests)} distinct (stable or neutral, to {tolerance:g})")
    for rest in rests[:10]:
        values = "  ".join(f"{c} {rest[c]: .6f}" for c in joints[:6])
        print(
            f"  {values}  {rest['stability']}, {rest['count']} cases "
            f"({100 * rest['fraction']:.1f}%)"
        )
    if len(rests) > 10:
        print(f"  ... {len(rests) - 10} more")


def _print_jumps(jumps: list[dict[str, Any]]) -> None:
    """The cases whose rest left its continuation branch (the first ten)."""
    text = ", ".join(
        f"case {j['case']} (" + ", ".join(f"{c} = {j[c]:.6g}" for c in j if c != "case") + ")"
        for j in jumps[:10]
    )
    found = f": {text}" if jumps else " (each rest stayed on its branch)"
    print(f"jumps    {len(jumps)}{found}")


def _print_rows(df: Any, info: dict[str, Any], shown: list[str]) -> None:
    """Where the table went, or the table itself (its ``shown`` columns) when it is short."""
    if info["out"]:
        print(f"wrote    {info['out']} ({len(df)} rows)")
    elif len(df) <= 30:
        print(df[shown].to_string(index=False))
    else:
        print("(the table has more than 30 rows: --out FILE.parquet or FILE.csv keeps it)")


def _print_summary(df: Any, info: dict[str, Any]) -> None:
    _print_totals(info)
    failed = df[df["error"].fillna("") != ""]
    _print_errors(failed)
    varied = [c for c in _varied(df) if not c.startswith("start.")]
    joints = [c for j in df.attrs["pinsettle"]["joints"] for c in j["columns"]]
    _print_rests(info["distinct_rests"], varied, joints)
    if "jump" in df.columns:
        _print_jumps(info["jumps"])
    shown = ["case", *varied, "status", *joints[:6], "residual", "stability"]
    shown += ["jump"] if "jump" in df.columns else []
    shown += ["error"] if len(failed) else []
    _print_rows(df, info, shown)
    if info.get("plot"):
        print(f"plot     {info['plot']}")
    if info["interrupted"]:
        print(
            "interrupted: run the same command again to solve the cases left"
            + ("" if info["out"] else " (with --out, to keep what is done)")
        )


def run(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    try:
        return _run(args, overrides)
    except BrokenPipeError:  # output piped into head: the command's own handling
        raise
    except (ConnectionError, _sweep_cases.MissingDependencyError) as error:
        print(f"pinsettle: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # before or after the cases: nothing in flight to keep
        print("pinsettle: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def _sweep_args(args: argparse.Namespace) -> tuple[dict[str, list[float]], Path | None]:
    """The values of --vary and the file of --out, every flag checked."""
    vary = parse_vary(args.vary)
    check_flags(args, FLAGS)
    if not vary and args.random is None:
        raise ValueError("nothing to sweep: give --vary KEY=LO:HI:N and/or --random N")
    return vary, _out_path(args.out)


def _run(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    _sweep_cases.pandas()
    vary, out = _sweep_args(args)
    scene = load_scene(scene_path(args.scene), **contact_options(args))
    resume = read_table(out) if out is not None and out.exists() else None
    starts = None if args.random is None else ("random", args.random, args.seed or 0)
    df = _sweep.sweep(
        scene,
        vary,
        starts,
        zip=args.zip,
        continuation=args.continuation,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.json,
        limits=False if args.no_limits else None,
        resume=resume,
        **overrides,
    )
    if out is not None:
        write_table(df, out)
    info = summary(df, out)
    if args.plot is not None:  # after the table is written: a bad column loses no case
        names = _sweep_plot.FLAG_NAMES
        _sweep_plot._plot(df, args.plot, args.plot_column, args.plot_key, None, names)
        info["plot"] = args.plot
    if args.json:
        if out is None:
            info["rows"] = records(df)
        print(json.dumps(info))
    else:
        _print_summary(df, info)
    if info["interrupted"]:
        return EXIT_INTERRUPTED
    return 0 if info["status_counts"].get("converged", 0) == len(df) else 1

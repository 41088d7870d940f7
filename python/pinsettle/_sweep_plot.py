"""The plot of a sweep: columns of its table against the varied key, its jumps marked.

matplotlib (the ``viz`` extra) is imported only when a plot is made; pandas is the table's.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._play_extra import VIZ_INSTALL
from ._sweep_cases import OUTPUT_COLUMNS, MissingDependencyError, pandas

#: The file formats of a plot, by the file's extension.
PLOT_FORMATS = {".png": "png", ".svg": "svg"}
#: How the errors name the arguments: the Python API's names, and the command line's flags.
API_NAMES = {"column": "column", "key": "key", "path": "path"}
FLAG_NAMES = {"column": "--plot-column", "key": "--plot-key", "path": "--plot"}
#: The columns of a sweep's table that hold no varied value (besides the joints').
_NOT_VARIED = ("case", "start", *OUTPUT_COLUMNS)


def require_matplotlib(what: str) -> None:
    """matplotlib, or a MissingDependencyError naming ``what`` needs it and the extra."""
    try:
        importlib.import_module("matplotlib")
    except ImportError:
        raise MissingDependencyError(
            f"{what} needs matplotlib, which is not installed: {VIZ_INSTALL}"
        ) from None


def plot_format(path: str | Path, names: Mapping[str, str] = API_NAMES) -> str:
    """The format of a plot written to ``path`` ('png' or 'svg'), from its extension.

    Raises:
        ValueError: another extension, naming the argument (or flag) and what it takes.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in PLOT_FORMATS:
        raise ValueError(
            f"{names['path']} {path}: the file must end in .png or .svg (the plot's format), "
            f"got {suffix or 'no extension'}"
        )
    return PLOT_FORMATS[suffix]


@dataclass(frozen=True)
class _Choice:
    """What a plot shows: the varied key (x), the columns (y), the branches (rows of a start,
    in case order)."""

    key: str
    columns: list[str]
    branches: list[tuple[str, Any]]  # what sets a branch apart (text), its rows


def _varied_columns(df: Any) -> list[str]:
    """The table's columns of varied values: those of the keys in ``df.attrs`` (``KEY`` or
    ``KEY[k]``), or, for a table read back from CSV, those before ``status`` that are not the
    case's or the start's."""
    vary = df.attrs.get("pinsettle", {}).get("vary")
    if vary is not None:
        return [c for c in df.columns if c in vary or c.split("[")[0] in vary]
    columns = list(df.columns)
    before = columns[: columns.index("status")] if "status" in columns else columns
    return [c for c in before if c not in _NOT_VARIED and not c.startswith("start.")]


def _joint_columns(df: Any) -> list[str]:
    """The joints' columns: from ``df.attrs``, or those between ``status`` and ``residual``
    (the table's order)."""
    joints = df.attrs.get("pinsettle", {}).get("joints")
    if joints is not None:
        return [c for joint in joints for c in joint["columns"] if c in df.columns]
    columns = list(df.columns)
    if "status" in columns and "residual" in columns:
        return columns[columns.index("status") + 1 : columns.index("residual")]
    return []


def _pick_key(df: Any, key: str | None, names: Mapping[str, str]) -> str:
    varied = _varied_columns(df)
    if key is not None:
        if key not in df.columns:
            raise ValueError(
                f"{names['key']} {key!r}: not a column of the table; its varied keys: "
                f"{', '.join(varied) or 'none'}"
            )
        return key
    if not varied:
        raise ValueError(
            "the table varies no scene value (random starts alone): a plot needs a varied key, "
            f"or a column to plot against ({names['key']})"
        )
    if len(varied) > 1:
        raise ValueError(
            f"the table varies {len(varied)} keys ({', '.join(varied)}): choose the one to plot "
            f"against with {names['key']}"
        )
    return varied[0]


def _pick_columns(
    df: Any, column: str | Sequence[str] | None, names: Mapping[str, str]
) -> list[str]:
    if column is None:
        columns = _joint_columns(df) or ["residual"]
    else:
        columns = [column] if isinstance(column, str) else list(column)
        if not columns:
            raise ValueError(f"{names['column']}: give at least one column")
    unknown = [c for c in columns if c not in df.columns]
    if unknown:
        raise ValueError(
            f"{names['column']} {unknown[0]!r}: not a column of the table; its columns: "
            f"{', '.join(map(str, df.columns))}"
        )
    pd = pandas()
    numeric = [c for c in columns if not pd.api.types.is_numeric_dtype(df[c])]
    if numeric:
        raise ValueError(
            f"{names['column']} {numeric[0]!r}: not a column of numbers (its type is "
            f"{df[numeric[0]].dtype}); plot a joint's value, residual, steps, ..."
        )
    return columns


def choose(
    df: Any,
    column: str | Sequence[str] | None = None,
    key: str | None = None,
    names: Mapping[str, str] = API_NAMES,
) -> _Choice:
    """What the plot of ``df`` shows (see ``plot_sweep``), every choice checked.

    Raises:
        TypeError: ``df`` is not a DataFrame.
        ValueError: an unknown or non-numeric column, an unknown key, or a table that varies
            no key or several without ``key``; naming the argument (or flag, ``names``).
    """
    pd = pandas()
    if not isinstance(df, pd.DataFrame):
        raise TypeError(
            f"df must be a pandas.DataFrame of pinsettle.sweep, got {type(df).__name__}"
        )
    if "case" not in df.columns:
        raise ValueError("df is not a sweep table: it has no column case")
    chosen = _pick_key(df, key, names)
    columns = _pick_columns(df, column, names)
    ordered = df.sort_values("case")
    # A line per start and per value of the other varied keys (a grid), in case order.
    apart = ["start"] if "start" in df.columns else []
    apart += [c for c in _varied_columns(df) if c != chosen]
    if not apart:
        return _Choice(chosen, columns, [("", ordered)])
    branches = []
    for values, group in ordered.groupby(apart, sort=True, dropna=False):
        values = values if isinstance(values, tuple) else (values,)
        text = ", ".join(f"{c} {v:g}" for c, v in zip(apart, values, strict=True))
        branches.append((text, group))
    if len(branches) == 1:  # one start, nothing else varied: nothing to tell apart
        branches = [("", branches[0][1])]
    return _Choice(chosen, columns, branches)


def jump_rows(branch: Any) -> list[int]:
    """The positions (in the branch, case order) of the rows that jumped (``jump`` true)."""
    if "jump" not in branch.columns:
        return []
    return [int(k) for k in np.flatnonzero(branch["jump"].fillna(False).to_numpy(dtype=bool))]


def plot_sweep(
    df: Any,
    path: str | Path | None = None,
    *,
    column: str | Sequence[str] | None = None,
    key: str | None = None,
    title: str | None = None,
) -> Any:
    """Plot columns of a sweep's table against its varied key, the jumps marked.

    Args:
        df: a table of ``pinsettle.sweep`` (or one read back from its Parquet or CSV file).
        path: also write the plot there: PNG or SVG, by the file's extension.
        column: the column, or columns, plotted: by default every joint's value (the rest);
            ``"residual"``, ``"steps"``, ... or any numeric column of the table.
        key: the column plotted against: by default the varied key (a table that varies
            several, or a vector key's entries ``KEY[k]``, needs the choice).

    Returns:
        The ``matplotlib.figure.Figure``: one line per column (and per start, one branch each:
        the line's ``gid`` is the column, its label says the start), the rows that did not
        converge as grey crosses, and at each jump (the ``jump`` column, where the rest left
        its branch: a fold, a snap-through) a dashed red segment from the previous rest to the
        new one, the new ones marked with a red X (a line whose ``gid`` is ``"jumps:COLUMN"``).

    Raises:
        MissingDependencyError (an ImportError): matplotlib is missing (``pinsettle[viz]``).
        TypeError, ValueError: a bad table, column, key or file extension (named).
    """
    require_matplotlib("pinsettle.plot_sweep")
    return _plot(df, path, column, key, title, API_NAMES)


def _plot(
    df: Any,
    path: str | Path | None,
    column: str | Sequence[str] | None,
    key: str | None,
    title: str | None,
    names: Mapping[str, str],
) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fmt = None if path is None else plot_format(path, names)
    choice = choose(df, column, key, names)
    fig = Figure(figsize=(8.0, 4.6), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    jumps = 0
    for b, (where, branch) in enumerate(choice.branches):
        jumps += _draw_branch(ax, branch, choice, where, b * len(choice.columns))
    _decorate(ax, df, choice, jumps, title)
    if path is not None:
        fig.savefig(Path(path), format=fmt)
    return fig


def _draw_branch(ax: Any, branch: Any, choice: _Choice, where: str, first_color: int) -> int:
    """One branch (the rows of one start and one value of the other varied keys, ``where``):
    a column's values as dots (the line whose ``gid`` is the column) joined by solid lines
    along the branch and by a dashed red one across each jump, the failures and the jumps
    marked; the number of jumps. Its lines take the colours from ``first_color`` on."""
    x = branch[choice.key].to_numpy(dtype=float)
    failed = (branch["status"] != "converged").to_numpy(dtype=bool, na_value=True)
    jumped = jump_rows(branch)
    pieces = np.split(np.arange(len(x)), [k for k in jumped if k > 0])
    for c, name in enumerate(choice.columns):
        y = branch[name].to_numpy(dtype=float, na_value=np.nan)
        color = f"C{(first_color + c) % 10}"
        ax.plot(x, y, "o", ms=3.5, color=color, gid=name)
        for p, piece in enumerate(pieces):
            label = (f"{name}, {where}" if where else name) if p == 0 else None
            ax.plot(x[piece], y[piece], "o-", ms=3.5, lw=1.2, color=color, label=label)
        if failed.any():
            ax.plot(x[failed], y[failed], "x", color="0.4", ms=6, gid=f"failed:{name}")
        if jumped:
            for k in (k for k in jumped if k > 0):
                ax.plot(x[k - 1 : k + 1], y[k - 1 : k + 1], "--", color="#e03131", lw=1.6)
            ax.plot(x[jumped], y[jumped], "X", color="#e03131", ms=8, zorder=5, gid=f"jumps:{name}")
    return len(jumped)


def _decorate(ax: Any, df: Any, choice: _Choice, jumps: int, title: str | None) -> None:
    """Labels, the title (the scene, the cases, the jumps), the legend, a log scale for a
    residual."""
    joints = set(_joint_columns(df))
    ax.set_xlabel(choice.key)
    if set(choice.columns) <= joints:
        ax.set_ylabel("joint values (rad or m)")
    else:
        ax.set_ylabel(", ".join(choice.columns))
    values = df[choice.columns].to_numpy(dtype=float, na_value=np.nan)
    finite = values[np.isfinite(values)]
    if choice.columns == ["residual"] and finite.size and (finite >= 0).all() and finite.max() > 0:
        # Residuals span decades (1e-15 to 1e-8); one of exactly 0 stays on the axis (symlog).
        smallest = float(finite[finite > 0].min())
        if (finite > 0).all():
            ax.set_yscale("log")
        else:
            ax.set_yscale("symlog", linthresh=smallest)
    heading = title or df.attrs.get("pinsettle", {}).get("scene", "sweep")
    marked = f", {jumps} jump{'s' if jumps != 1 else ''}" if "jump" in df.columns else ""
    ax.set_title(f"{heading}: {len(df)} cases{marked}", fontsize=11)
    ax.grid(True, alpha=0.3)
    from matplotlib.lines import Line2D

    handles, labels = ax.get_legend_handles_labels()
    if jumps:
        handles.append(Line2D([], [], ls="--", marker="X", color="#e03131"))
        labels.append("jump: the rest left its branch")
    if any(str(line.get_gid()).startswith("failed:") for line in ax.get_lines()):
        handles.append(Line2D([], [], ls="", marker="x", color="0.4"))
        labels.append("not converged")
    ax.legend(handles, labels, fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))

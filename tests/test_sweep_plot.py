"""The plot of a sweep (pinsettle.plot_sweep, ``pinsettle sweep ... --plot FILE``).

What is drawn is read back from the returned matplotlib Figure: each line's data against the
table's columns, the jumps at the rows the table marks (and, for the bistable pendulum's fold,
where its rest changes sign); the files are read back as PNG and SVG.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pd = pytest.importorskip("pandas")
pytest.importorskip("matplotlib")

import pinsettle  # noqa: E402
from pinsettle.__main__ import main  # noqa: E402

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
PNG = b"\x89PNG\r\n\x1a\n"
LENGTHS = np.linspace(2.0, 1.0, 41)


def bistable(load: float = 0.5) -> pinsettle.Scene:
    """The bistable pendulum with a constant effort on its hinge: its negative branch ends at
    a fold (tests/test_sweep.py checks it against the closed form)."""
    scene = pinsettle.load_scene(ROBOTS / "bistable_pendulum.toml")
    scene.add_load("hinge", load)
    return scene


@pytest.fixture(scope="module")
def fold():
    """The rest followed down the negative branch from L0 = 2 m: one jump, at the fold."""
    return pinsettle.sweep(bistable(), {"spring[0].rest_length": LENGTHS}, [[-1.0]], progress=False)


def lines(fig) -> dict[str, object]:
    """The axes' lines by gid (the data lines: a column's name; the jumps: 'jumps:COLUMN')."""
    (ax,) = fig.axes
    return {line.get_gid(): line for line in ax.get_lines() if line.get_gid()}


def test_the_fold_is_plotted_with_its_jump(fold, tmp_path):
    path = tmp_path / "fold.png"
    fig = pinsettle.plot_sweep(fold, path)
    # A PNG of the figure's size.
    from matplotlib import image

    assert path.read_bytes()[:8] == PNG
    height, width = image.imread(path).shape[:2]
    assert (width, height) == tuple(np.round(fig.get_size_inches() * fig.dpi).astype(int))
    # The hinge's rest (the default: every joint) against the varied rest length.
    drawn = lines(fig)
    assert np.array_equal(drawn["hinge"].get_xdata(), fold["spring[0].rest_length"])
    assert np.array_equal(drawn["hinge"].get_ydata(), fold["hinge"])
    assert np.array_equal(drawn["hinge"].get_xdata(), LENGTHS)
    # The jump marked where the table says, which is where the rest snaps to the positive side.
    jumps = np.flatnonzero(fold["jump"].fillna(False).to_numpy(dtype=bool))
    (i,) = jumps
    assert (fold["hinge"][:i] < 0).all() and (fold["hinge"][i:] > 0).all()
    marked = drawn["jumps:hinge"]
    assert np.array_equal(marked.get_xdata(), [LENGTHS[i]])
    assert np.array_equal(marked.get_ydata(), [fold["hinge"][i]])
    # ... joined to the rest it left by a dashed segment.
    (ax,) = fig.axes
    dashed = [line for line in ax.get_lines() if line.get_linestyle() == "--"]
    assert len(dashed) == 1
    assert np.array_equal(dashed[0].get_xdata(), LENGTHS[i - 1 : i + 1])
    assert np.array_equal(dashed[0].get_ydata(), fold["hinge"][i - 1 : i + 1])
    assert ax.get_xlabel() == "spring[0].rest_length"
    assert ax.get_title() == "bistable_pendulum: 41 cases, 1 jump"


def test_a_column_as_svg_and_the_residual_on_a_log_scale(fold, tmp_path):
    path = tmp_path / "residual.svg"
    fig = pinsettle.plot_sweep(fold, path, column="residual")
    text = path.read_text(encoding="utf-8")
    assert text.startswith("<?xml") and "<svg" in text
    (ax,) = fig.axes
    # Residuals span decades: a log scale (symlog where a residual is exactly 0).
    residuals = fold["residual"].to_numpy()
    assert ax.get_yscale() == ("log" if (residuals > 0).all() else "symlog")
    assert np.array_equal(lines(fig)["residual"].get_ydata(), fold["residual"])
    assert "hinge" not in lines(fig)
    # Several columns at once.
    both = lines(pinsettle.plot_sweep(fold, column=["hinge", "steps"]))
    assert np.array_equal(both["steps"].get_ydata(), fold["steps"].to_numpy(dtype=float))


def test_every_joint_of_the_ur5_against_the_payload():
    scene = pinsettle.load_scene(ROBOTS / "ur5_tool_spring.toml")
    df = pinsettle.sweep(scene, {"payload.tool0.mass": [0.0, 2.5, 5.0]}, progress=False)
    drawn = lines(pinsettle.plot_sweep(df))
    joints = [str(n) for n in scene.model.names[1:]]
    assert sorted(drawn) == sorted(joints)  # no jump: no jump markers
    for name in joints:
        assert np.array_equal(drawn[name].get_xdata(), [0.0, 2.5, 5.0])
        assert np.array_equal(drawn[name].get_ydata(), df[name])


def test_a_table_read_back_from_csv(fold, tmp_path):
    fold.to_csv(tmp_path / "fold.csv", index=False)
    back = pd.read_csv(tmp_path / "fold.csv")
    assert not back.attrs
    drawn = lines(pinsettle.plot_sweep(back))
    assert set(drawn) == {"hinge", "jumps:hinge"}
    assert np.allclose(drawn["hinge"].get_xdata(), LENGTHS)


def test_two_keys_need_the_choice_and_make_a_line_per_value_of_the_other():
    vary = {"spring[0].rest_length": [1.2, 1.5, 1.8], "spring[0].stiffness": [30.0, 40.0]}
    df = pinsettle.sweep(bistable(load=0.0), vary, progress=False)
    with pytest.raises(
        ValueError, match=r"varies 2 keys .*choose the one to plot against with key"
    ):
        pinsettle.plot_sweep(df)
    fig = pinsettle.plot_sweep(df, key="spring[0].rest_length")
    (ax,) = fig.axes
    data = [line for line in ax.get_lines() if line.get_gid() == "hinge"]
    assert len(data) == 2
    for line, stiffness in zip(data, (30.0, 40.0), strict=True):
        rows = df[df["spring[0].stiffness"] == stiffness].sort_values("case")
        assert np.array_equal(line.get_xdata(), rows["spring[0].rest_length"])
        assert np.array_equal(line.get_ydata(), rows["hinge"])
    labels = ax.get_legend_handles_labels()[1]
    assert "hinge, spring[0].stiffness 30" in labels


def test_a_line_per_start():
    df = pinsettle.sweep(
        bistable(), {"spring[0].rest_length": [2.0, 1.8]}, [[-1.0], [1.0]], progress=False
    )
    data = [line for line in pinsettle.plot_sweep(df).axes[0].get_lines() if line.get_gid()]
    assert len(data) == 2
    for line, start in zip(data, (0, 1), strict=True):
        assert np.array_equal(line.get_ydata(), df[df["start"] == start]["hinge"])


@pytest.mark.parametrize(
    "kwargs, pattern",
    [
        ({"column": "nope"}, r"column 'nope': not a column of the table; its columns: case, "),
        ({"column": "status"}, r"column 'status': not a column of numbers"),
        ({"column": []}, r"column: give at least one column"),
        ({"key": "nope"}, r"key 'nope': not a column of the table; its varied keys: spring"),
        ({"path": "fold.pdf"}, r"path fold.pdf: the file must end in .png or .svg"),
    ],
)
def test_bad_input_is_named(fold, kwargs, pattern, tmp_path):
    if "path" in kwargs:
        kwargs = {"path": tmp_path / kwargs["path"]}
        pattern = pattern.replace("path fold", f"path {re.escape(str(tmp_path))}/fold")
    with pytest.raises(ValueError, match=pattern):
        pinsettle.plot_sweep(fold, **kwargs)
    assert not list(tmp_path.iterdir())
    with pytest.raises(TypeError, match="df must be a pandas.DataFrame"):
        pinsettle.plot_sweep([1, 2])


def test_random_starts_alone_have_no_key(tmp_path):
    df = pinsettle.sweep(bistable(), starts=("random", 3, 0), progress=False)
    with pytest.raises(ValueError, match=r"varies no scene value .*\(key\)"):
        pinsettle.plot_sweep(df)


def test_missing_matplotlib_names_the_extra(tmp_path):
    code = (
        "import sys; sys.modules['matplotlib'] = None\n"
        "import pandas, pinsettle\n"
        "try:\n"
        "    pinsettle.plot_sweep(pandas.DataFrame({'case': [0]}))\n"
        "except ImportError as error:\n"
        "    print(type(error).__name__, error)\n"
        "from pinsettle.__main__ import main\n"
        f"print(main(['sweep', 'bistable_pendulum', '--random', '2', '--plot', "
        f"r'{tmp_path / 'p.png'}']))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.splitlines() == [
        "MissingDependencyError pinsettle.plot_sweep needs matplotlib, which is not installed: "
        "pip install 'pinsettle[viz]'",
        "2",
    ], out.stderr
    assert "--plot" in out.stderr and "pip install 'pinsettle[viz]'" in out.stderr
    assert not (tmp_path / "p.png").exists()


def test_cli_writes_the_plot(tmp_path, capsys):
    path, table = tmp_path / "fold.png", tmp_path / "fold.csv"
    args = ["sweep", str(ROBOTS / "bistable_pendulum.toml"), "--vary"]
    args += ["spring[0].rest_length=1.5:1.0:6", "--plot", str(path), "--out", str(table)]
    assert main(args) == 0
    assert f"plot     {path}" in capsys.readouterr().out
    assert path.read_bytes()[:8] == PNG and path.stat().st_size > 10_000
    # The same picture as the Python API's of the table written.
    df = pd.read_csv(table)
    again = tmp_path / "again.png"
    pinsettle.plot_sweep(df, again, title="bistable_pendulum")
    from matplotlib import image

    assert np.array_equal(image.imread(path), image.imread(again))


@pytest.mark.parametrize(
    "extra, pattern",
    [
        (["--plot", "{tmp}/x.pdf"], r"--plot \S+/x.pdf: the file must end in .png or .svg"),
        (["--plot", "/no/such/folder/x.png"], r"--plot /no/such/folder/x.png: no such folder"),
        (["--plot-column", "hinge"], r"--plot-column goes with --plot FILE"),
        (["--plot-key", "x"], r"--plot-key goes with --plot FILE"),
        (
            ["--plot", "{tmp}/x.png", "--plot-column", "nope"],
            r"--plot-column 'nope': not a column of the table",
        ),
        (
            ["--plot", "{tmp}/x.png", "--vary", "spring[0].stiffness=30,40"],
            r"varies 2 keys .* with --plot-key",
        ),
        (
            ["--plot", "{tmp}/x.png", "--plot-key", "spring[0].damping"],
            r"--plot-key 'spring\[0\].damping': not a column of the table",
        ),
    ],
)
def test_cli_bad_plot_flags(extra, pattern, tmp_path, capsys):
    extra = [a.replace("{tmp}", str(tmp_path)) for a in extra]
    args = ["sweep", "bistable_pendulum", "--vary", "spring[0].rest_length=1.5:1.0:3", *extra]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("pinsettle: error: ") and re.search(pattern, err), err
    assert len(err.strip().splitlines()) == 1
    assert not list(tmp_path.glob("x.*"))

"""Progress of a running solve (issue 16): ``solve(..., progress=f)`` and the command line's
live status line.

The records are checked against a trace of every step of the same run (simulated time, kinetic
energy, damping events) and the residual recomputed with Pinocchio at the traced
configuration. The status line is checked on a real pseudo-terminal (``os.openpty``: the CLI
runs as a subprocess with its stderr on the terminal), including that it is erased at the end,
and its absence when stderr is a pipe, with ``--json`` and with ``--quiet``.
"""

from __future__ import annotations

import fcntl
import importlib
import io
import math
import os
import re
import select
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest
from pinsettle._progress import DELAY, REDRAWS_PER_SECOND, StatusLine, status_line

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
PENDULUM = ROBOTS / "pendulum.urdf"


def gravity(model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
    return pinocchio.computeGeneralizedGravity(model, model.createData(), q).copy()


# --- the Python API -----------------------------------------------------------------------------


def _traced(target, q0, progress, **settings):
    """A solve with progress reports every step and a trace of every step (no decimation)."""
    settings = {"check_every": 1, "trace_every": 1, "trace_configurations": True, **settings}
    return pinsettle.solve(target, q0, progress=progress, trace_capacity=1_000_000, **settings)


def _check_against_trace(records, result, residual_at):
    """Each record against the trace sample of the same step: time, energy, damping events
    up to it, and its residual recomputed at the traced configuration by ``residual_at``."""
    trace = result.trace
    assert trace.stride == 1 and trace.step[-1] >= result.steps - 1
    assert records, "no progress reported"
    assert all(isinstance(p, pinsettle.Progress) for p in records)
    steps = np.array([p.steps for p in records])
    # One report per poll (every check_every = 1 steps), in order.
    assert np.all(np.diff(steps) == 1), steps[:10]
    assert records[-1].steps <= result.steps
    index = {int(s): k for k, s in enumerate(trace.step)}
    damping_steps = trace.event_step[np.array(trace.event_kind) == "damping"]
    checked = 0
    for p in records:
        k = index.get(p.steps)
        if not k:  # not traced, or the start (no step evaluated yet)
            continue
        checked += 1
        assert p.sim_time == pytest.approx(trace.time[k], rel=1e-12, abs=1e-15)
        # The energy of the last step the core evaluated: that of the state one step before
        # (the dynamics are evaluated, and the energy with them, before the update).
        assert p.kinetic_energy == pytest.approx(trace.kinetic_energy[k - 1], rel=1e-12, abs=0)
        assert p.peaks == np.count_nonzero(damping_steps < p.steps)
        if math.isfinite(p.residual):
            expected = residual_at(trace.q[k])
            assert p.residual == pytest.approx(expected, rel=1e-9, abs=1e-12), p.steps
    assert checked >= len(records) - 1
    assert any(math.isfinite(p.residual) for p in records)
    # Counters and clocks only go forward, and end where the result does.
    for name in ("sim_time", "peaks", "wall_time"):
        values = [getattr(p, name) for p in records]
        assert values == sorted(values), name
    assert records[-1].peaks <= result.peaks and records[-1].sim_time <= result.sim_time
    assert records[-1].wall_time <= result.wall_time


def test_progress_reports_the_run_of_a_model(pendulum):
    records = []
    q0 = np.array([1.0])
    result = _traced(pendulum, q0, records.append, limits=False)
    assert result.converged
    _check_against_trace(records, result, lambda q: float(np.abs(gravity(pendulum, q)).max()))
    # The energy the bob had at its fastest: at most what it had to lose, m g l (1 - cos 1),
    # within the error of the integration (semi-implicit Euler, about dt of it).
    m = pendulum.inertias[1].mass
    lever = float(np.linalg.norm(pendulum.inertias[1].lever))
    released = m * 9.81 * lever * (1 - math.cos(1.0))
    assert max(p.kinetic_energy for p in records) <= released * 1.02
    assert max(p.kinetic_energy for p in records) >= released * 0.5


def test_progress_reports_the_run_of_a_scene():
    scene = pinsettle.load_scene(ROBOTS / "planar_3link_spring.toml")
    records = []
    result = _traced(scene, None, records.append)
    assert result.converged
    _check_against_trace(records, result, scene.residual)


def test_progress_every_check_every_steps(pendulum):
    steps = []
    result = pinsettle.solve(
        pendulum, np.array([1.0]), check_every=16, progress=lambda p: steps.append(p.steps)
    )
    # Every multiple of check_every below the steps the run took (it stops within a step).
    assert steps == list(range(16, result.steps, 16))


def test_progress_return_value_is_ignored(pendulum):
    # A progress callable changes nothing in the run, whatever it returns (True would stop a
    # callback's run).
    plain = pinsettle.solve(pendulum, np.array([1.0]), check_every=1)
    stopping = pinsettle.solve(pendulum, np.array([1.0]), check_every=1, progress=lambda p: True)
    assert stopping.status == plain.status == "converged"
    assert stopping.steps == plain.steps and np.array_equal(stopping.q, plain.q)


def test_progress_exception_ends_the_run_and_is_raised(pendulum):
    calls = []

    def progress(p):
        calls.append(p.steps)
        if len(calls) == 3:
            raise RuntimeError("enough of this")

    with pytest.raises(RuntimeError, match="enough of this"):
        pinsettle.solve(pendulum, np.array([1.0]), check_every=1, progress=progress)
    assert len(calls) == 3


def test_progress_must_be_callable(pendulum):
    with pytest.raises(TypeError, match="progress must be callable or None, got int"):
        pinsettle.solve(pendulum, progress=3)


# --- the status line, fed by hand -----------------------------------------------------------------


class FakeTerminal(io.StringIO):
    """A stream that says it is a terminal."""

    encoding = "utf-8"

    def isatty(self) -> bool:
        return True


def record(wall_time, residual=1e-3, steps=1000, peaks=3):
    return pinsettle.Progress(
        steps=steps,
        sim_time=0.25,
        kinetic_energy=2.5e-4,
        peaks=peaks,
        residual=residual,
        wall_time=wall_time,
    )


def screen(output: str) -> list[str]:
    """The lines a terminal shows after ``output`` (carriage return, erase to the end of the
    line and newline interpreted; nothing else is expected)."""
    lines, line, cursor = [], "", 0
    for token in re.findall(r"\x1b\[K|\r\n|\r|\n|[^\r\n\x1b]+|\x1b", output):
        if token == "\x1b[K":
            line = line[:cursor]
        elif token == "\r":
            cursor = 0
        elif token in ("\n", "\r\n"):
            lines.append(line)
            line, cursor = "", 0
        elif token == "\x1b":
            raise AssertionError(f"unexpected escape sequence in {output!r}")
        else:
            line = line[:cursor] + token + line[cursor + len(token) :]
            cursor += len(token)
    return [*lines, line]


def test_status_line_waits_then_redraws_a_few_times_a_second():
    stream = FakeTerminal()
    line = StatusLine(stream, width=200)
    line(record(0.1))
    line(record(DELAY - 0.01))
    assert stream.getvalue() == ""  # a short solve shows nothing
    line(record(DELAY + 0.01, residual=1e-3))
    first = stream.getvalue()
    assert first.startswith("\r") and first.endswith("\x1b[K")
    text = screen(first)[-1]
    for part in ("1,000 steps", "0.2500 s simulated", "KE 2.5e-4 J", "3 damping events"):
        assert part in text
    assert "residual 1.0e-3 |" in text and text.endswith(f"| {DELAY + 0.01:.1f} s")
    line(record(DELAY + 0.5 / REDRAWS_PER_SECOND, residual=1e-4))
    assert stream.getvalue() == first  # too soon after the last redraw
    line(record(DELAY + 1.2 / REDRAWS_PER_SECOND, residual=1e-4, steps=2000))
    text = screen(stream.getvalue())
    assert len(text) == 1 and "2,000 steps" in text[0] and "residual 1.0e-4 \u2193" in text[0]
    line(record(DELAY + 2.4 / REDRAWS_PER_SECOND, residual=3e-4))
    assert "residual 3.0e-4 \u2191" in screen(stream.getvalue())[0]
    line.close()
    assert screen(stream.getvalue()) == [""]  # erased
    line.close()  # twice: nothing more
    assert stream.getvalue().endswith("\r\x1b[K") and not stream.getvalue().endswith(
        "\r\x1b[K\r\x1b[K"
    )


def test_status_line_before_a_residual_and_in_ascii():
    stream = FakeTerminal()
    stream.encoding = "ascii"
    line = StatusLine(stream, width=200)
    line(record(1.0, residual=math.nan))
    assert "residual - |" in screen(stream.getvalue())[0]
    line(record(2.0, residual=1.0))
    line(record(3.0, residual=0.5))
    assert "residual 5.0e-1 v |" in screen(stream.getvalue())[0]
    line(record(4.0, residual=0.5))
    assert "residual 5.0e-1 = |" in screen(stream.getvalue())[0]
    assert stream.getvalue().isascii()


def test_status_line_in_short_then_cut_on_narrow_terminals():
    wide, narrow, tiny = FakeTerminal(), FakeTerminal(), FakeTerminal()
    for stream, width in ((wide, 200), (narrow, 80), (tiny, 30)):
        StatusLine(stream, width=width)(record(1.0, steps=123_456, peaks=1_234))
    assert screen(wide.getvalue())[0].startswith("solving: 123,456 steps | 0.2500 s simulated")
    short = screen(narrow.getvalue())[0]
    assert short == "123,456 steps  t 0.25 s  KE 2.5e-4 J  1,234 peaks  res 1.0e-3  1.0 s"
    assert screen(tiny.getvalue())[0] == short[:29]


def test_status_line_only_on_a_terminal_and_erased_after_an_error():
    with status_line(io.StringIO()) as line:
        assert line is None  # not a terminal: nothing to call, nothing costs
    with status_line(FakeTerminal(), wanted=False) as line:
        assert line is None
    stream = FakeTerminal()
    with pytest.raises(KeyboardInterrupt), status_line(stream) as line:
        assert isinstance(line, StatusLine)
        line(record(0.9))
        assert "1,000 steps" in screen(stream.getvalue())[0]  # 80 columns: in short
        raise KeyboardInterrupt
    assert screen(stream.getvalue()) == [""]
    stream = FakeTerminal()
    with status_line(stream) as line:
        line(record(0.2))  # a short solve: never drawn, nothing to erase
    assert stream.getvalue() == ""


@pytest.mark.parametrize(
    "argv, wanted",
    [
        (["solve", "pendulum"], True),
        (["solve", "pendulum", "--json"], False),
        (["solve", "pendulum", "--quiet"], False),
        (["solve", "pendulum", "-q"], False),
        (["demo", "ur5"], True),
        (["demo", "ur5", "--json"], False),
        (["demo", "ur5", "--quiet"], False),
    ],
)
def test_cli_gives_a_progress_callable_only_when_it_is_wanted(argv, wanted, monkeypatch):
    main = importlib.import_module("pinsettle.__main__")
    seen = []
    solve = pinsettle.solve

    def spy(*args, **kwargs):
        seen.append(kwargs.get("progress"))
        return solve(*args, **kwargs)

    monkeypatch.setattr(pinsettle, "solve", spy)
    monkeypatch.setattr(sys, "stderr", FakeTerminal())
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    assert main.main(argv) == 0
    assert len(seen) == 1
    assert isinstance(seen[0], StatusLine) if wanted else seen[0] is None


# --- the status line on a real pseudo-terminal ----------------------------------------------------


@pytest.fixture(scope="module")
def long_scene(tmp_path_factory):
    """A 100-link chain released horizontal (robots/make_chain.py): with the step fixed at
    0.2 ms, no stopping bound (max_e = 0), no Newton taking over at a damping event and 50,000
    steps it solves for well over DELAY on any machine (about 2 s on the project's) and ends
    max_steps."""
    folder = tmp_path_factory.mktemp("progress")
    urdf = subprocess.run(
        [sys.executable, str(ROBOTS / "make_chain.py"), "100"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    (folder / "chain100.urdf").write_text(urdf, encoding="utf-8")
    scene = folder / "chain100.toml"
    scene.write_text(
        '[model]\nurdf = "chain100.urdf"\n[start]\njoint1 = 1.5707963267948966\n'
        "[solver]\ndt = 2e-4\nmax_e = 0\nmax_steps = 50000\nnewton_takeover = false\n",
        encoding="utf-8",
    )
    return scene


def run_with_stderr_on_a_terminal(args, columns=200):
    """Run ``python -m pinsettle ARGS`` with stderr on a pseudo-terminal (``columns`` wide)
    and stdout on a pipe; return the exit status, stdout and what the terminal received."""
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, columns, 0, 0))
    env = {**os.environ, "PYTHONIOENCODING": "utf-8"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "pinsettle", *args],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=slave,
        env=env,
    )
    os.close(slave)
    received = b""
    deadline = time.monotonic() + 300
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 1.0)
            if not ready:
                if proc.poll() is not None:
                    break
                continue
            try:
                chunk = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal (it exited)
                break
            if not chunk:
                break
            received += chunk
        stdout = proc.communicate(timeout=60)[0].decode()
    finally:
        os.close(master)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, stdout, received.decode("utf-8")


def wall_seconds(stdout: str) -> float:
    match = re.search(r"wall time\s+([0-9.]+) ms", stdout)
    assert match, stdout
    return float(match.group(1)) / 1e3


def test_status_line_on_a_terminal(long_scene):
    status, stdout, terminal = run_with_stderr_on_a_terminal(["solve", str(long_scene)])
    assert status == 1 and "status           max_steps" in stdout  # the budget, as meant
    wall = wall_seconds(stdout)
    assert wall > DELAY + 2 / REDRAWS_PER_SECOND, f"the solve took {wall:.2f} s: too short"
    draws = [d for d in terminal.split("\r") if d.startswith("solving:")]
    assert len(draws) >= 2, terminal
    steps = [int(re.match(r"solving: ([0-9,]+) steps", d).group(1).replace(",", "")) for d in draws]
    assert steps == sorted(steps) and steps[-1] <= 50_000
    for part in ("s simulated", "KE ", "J", "damping events", "residual ", " s"):
        assert part in draws[-1]
    elapsed = [float(re.search(r"\| ([0-9.]+) s\x1b\[K$", d).group(1)) for d in draws]
    assert elapsed[0] >= DELAY and elapsed == sorted(elapsed) and elapsed[-1] <= wall + 0.05
    # A few redraws a second, not one per report (every 256 steps: about 200 in this run).
    assert len(draws) <= wall * REDRAWS_PER_SECOND + 1
    # Gone at the end: the terminal shows nothing.
    assert screen(terminal) == [""], repr(terminal[-200:])
    assert "Traceback" not in terminal


def test_status_line_fits_a_narrow_terminal(long_scene):
    status, stdout, terminal = run_with_stderr_on_a_terminal(["solve", str(long_scene)], 40)
    draws = [d.removesuffix("\x1b[K") for d in terminal.split("\r")]
    draws = [d for d in draws if d]
    assert draws and all(len(d) <= 39 and re.match(r"[0-9,]+ steps  t ", d) for d in draws)
    assert screen(terminal) == [""]


@pytest.mark.parametrize("flag", ["--json", "--quiet"])
def test_no_status_line_with_json_or_quiet(flag, long_scene):
    status, stdout, terminal = run_with_stderr_on_a_terminal(["solve", str(long_scene), flag])
    assert status == 1 and stdout
    if flag == "--quiet":
        assert wall_seconds(stdout) > DELAY + 2 / REDRAWS_PER_SECOND
    assert terminal == ""


def test_no_status_line_when_stderr_is_not_a_terminal(long_scene):
    proc = subprocess.run(
        [sys.executable, "-m", "pinsettle", "solve", str(long_scene)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 1 and wall_seconds(proc.stdout) > DELAY + 2 / REDRAWS_PER_SECOND
    assert proc.stderr == ""


def test_play_shows_the_status_line_while_it_solves(long_scene, tmp_path):
    for module in ("meshcat", "matplotlib"):
        try:
            importlib.import_module(module)
        except ImportError as error:
            if os.environ.get("PINSETTLE_REQUIRE_CHROMIUM") == "1":
                pytest.fail(f"the viz extra is required here but {module} does not import")
            pytest.skip(f"the viz extra ({module}) is not installed: {error}")
    html = tmp_path / "chain.html"
    status, stdout, terminal = run_with_stderr_on_a_terminal(
        ["play", str(long_scene), "--html", str(html), "--no-open"]
    )
    assert status == 1 and html.is_file() and "max_steps" in stdout
    assert any(d.startswith("solving:") for d in terminal.split("\r")), terminal
    assert screen(terminal) == [""]
    status, stdout, terminal = run_with_stderr_on_a_terminal(
        ["play", str(long_scene), "--html", str(html), "--no-open", "--quiet"]
    )
    assert status == 1 and terminal == ""

"""The command line's live status line: where a long solve stands, on a terminal only.

Built on ``solve(..., progress=)``: the C++ loop reports every ``check_every`` steps and
``StatusLine`` redraws one line of stderr at most ``REDRAWS_PER_SECOND`` times a second, once
the solve has run ``DELAY`` seconds, and erases it at the end. When stderr is not a terminal
(or the caller does not want it) no progress callable is given at all, so the solve runs
exactly as without it.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

from ._solve import Progress

#: Nothing is shown before the solve has run this long (s of wall time): short solves never
#: flicker a line.
DELAY = 0.5
#: At most this many redraws a second (a terminal need not be written thousands of times).
REDRAWS_PER_SECOND = 5.0
#: Move to the start of the line / erase from the cursor to the end of the line (VT100).
_RETURN, _ERASE = "\r", "\x1b[K"


def _terminal_width(stream: TextIO) -> int:
    try:
        return os.get_terminal_size(stream.fileno()).columns
    except (AttributeError, OSError, ValueError):
        return 80


def _short(x: float) -> str:
    """x in two significant digits, exponent without padding: 1.2e-3."""
    mantissa, _, exponent = f"{x:.1e}".partition("e")
    return f"{mantissa}e{int(exponent)}"


class StatusLine:
    """One line redrawn in place on a terminal (``stream``) from ``Progress`` records; call it
    as the ``progress`` of ``solve`` and ``close()`` it after (a ``with`` block does).
    ``width``: the terminal's columns (None: asked of ``stream`` at each redraw)."""

    def __init__(self, stream: TextIO, width: int | None = None) -> None:
        self.stream = stream
        self.width = width
        self.shown = False
        self._last_draw = -math.inf
        self._last_residual = math.nan
        arrows = ("\u2193", "\u2191", "\u2192")  # falling, rising, flat
        try:
            "".join(arrows).encode(getattr(stream, "encoding", None) or "ascii")
            self._arrows = arrows
        except (UnicodeEncodeError, LookupError):
            self._arrows = ("v", "^", "=")

    def __call__(self, progress: Progress) -> None:
        # The solver's own wall clock decides: nothing before DELAY, then a few redraws a
        # second whatever check_every makes of the rate of reports.
        if progress.wall_time < DELAY:
            return
        if progress.wall_time - self._last_draw < 1.0 / REDRAWS_PER_SECOND:
            return
        self._last_draw = progress.wall_time
        # One column short of the width: a line that fills it wraps on some terminals, and a
        # wrapped line cannot be erased with a carriage return.
        width = max((self.width or _terminal_width(self.stream)) - 1, 10)
        self.stream.write(_RETURN + self.text(progress, width) + _ERASE)
        self.stream.flush()
        self.shown = True

    def text(self, progress: Progress, width: int = 1000) -> str:
        """The line for ``progress`` in at most ``width`` characters: labelled in full when
        it fits, in short when that fits, else cut. Updates the residual trend (the change
        since the last line): call once per redraw."""
        residual = progress.residual
        trend = ""
        if math.isfinite(residual):
            before, self._last_residual = self._last_residual, residual
            if math.isfinite(before):
                falling, rising, flat = self._arrows
                trend = " " + (
                    falling if residual < before else rising if residual > before else flat
                )
        value = _short(residual) if math.isfinite(residual) else "-"
        peaks = progress.peaks
        full = (
            f"solving: {progress.steps:,} steps | {progress.sim_time:#.4g} s simulated | "
            f"KE {_short(progress.kinetic_energy)} J | "
            f"{peaks:,} damping event{'' if peaks == 1 else 's'} | residual {value}{trend} | "
            f"{progress.wall_time:.1f} s"
        )
        if len(full) <= width:
            return full
        short = (
            f"{progress.steps:,} steps  t {progress.sim_time:.3g} s  "
            f"KE {_short(progress.kinetic_energy)} J  {peaks:,} peaks  "
            f"res {value}{trend}  {progress.wall_time:.1f} s"
        )
        return short[:width]

    def close(self) -> None:
        """Erase the line if it was drawn."""
        if self.shown:
            self.stream.write(_RETURN + _ERASE)
            self.stream.flush()
            self.shown = False


@contextmanager
def status_line(stream: TextIO, wanted: bool = True) -> Iterator[StatusLine | None]:
    """A ``StatusLine`` on ``stream`` when it is wanted and ``stream`` is a terminal, else
    None (pass it as ``solve``'s ``progress``: None costs nothing); erased on leaving."""
    try:
        terminal = wanted and stream.isatty()
    except (AttributeError, ValueError):  # a replaced or closed stream
        terminal = False
    if not terminal:
        yield None
        return
    line = StatusLine(stream)
    try:
        yield line
    finally:
        line.close()

"""How the benchmark report writes numbers and tables (no measurement in here)."""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence

import numpy as np


def fmt_time(seconds: float | None) -> str:
    if seconds is None or not math.isfinite(seconds):
        return "-"
    if seconds >= 1.0:
        return f"{seconds:.2f} s"
    if seconds >= 1e-3:
        return f"{seconds * 1e3:.3g} ms"
    return f"{seconds * 1e6:.3g} us"


def half_spread(values: Sequence[float]) -> float:
    """Half the range of ``values`` over their median (of interleaved rounds' medians)."""
    return (max(values) - min(values)) / (2 * statistics.median(values))


def fmt_spread(values: Sequence[float], scale: float = 1.0) -> str:
    """Median (min-max) of values times scale, in a time unit."""
    vals = [v * scale for v in values]
    med = statistics.median(vals)
    if len(vals) == 1:
        return f"{fmt_time(med)} (1 run)"
    lo, hi = min(vals), max(vals)
    unit, factor = ("s", 1.0) if med >= 1 else ("ms", 1e3) if med >= 1e-3 else ("us", 1e6)
    return f"{med * factor:.3g} {unit} ({lo * factor:.3g}-{hi * factor:.3g})"


def fmt_steps(steps: float | None) -> str:
    return "-" if steps is None else f"{int(steps):,}"


def plural(n: int, word: str) -> str:
    return f"{n:,} {word}" + ("" if n == 1 else "s")


def fmt_e(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.1e}"


def fmt_list(values: Sequence[float]) -> str:
    return ", ".join(f"{v:g}" for v in values)


def geomean(values: Sequence[float]) -> float:
    values = [v for v in values if v is not None and math.isfinite(v) and v > 0]
    return math.exp(statistics.fmean(math.log(v) for v in values)) if values else math.nan


def slope(x: Sequence[float], y: Sequence[float]) -> float:
    """Least-squares exponent of y against x (log-log)."""
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def table(header: Sequence[str], rows: Sequence[Sequence[str]], right: Sequence[int] = ()) -> str:
    align = ["---:" if k in right else "---" for k in range(len(header))]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def median_with_failures(values: dict[str, float | None]) -> str:
    """'median x over n scenes; k not reached (names)'."""
    ok = [v for v in values.values() if v is not None]
    failed = [n for n, v in values.items() if v is None]
    scenes = "scene" if len(ok) == 1 else "scenes"
    text = f"{statistics.median(ok):.2g} over {len(ok)} {scenes}" if ok else "no scene reached"
    if ok and len(ok) > 1:
        text += f" ({min(ok):.2g} to {max(ok):.2g})"
    return text + (f"; **{len(failed)} not reached** ({', '.join(failed)})" if failed else "")

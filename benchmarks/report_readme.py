"""The speed section of README.md (between its bench:summary markers): what was measured,
for users; the goals are in the report's Goals part."""

from __future__ import annotations

import math
import statistics
import textwrap
from pathlib import Path

import report_data as D
from report_format import geomean
from report_goals import gallery_tally, goal4_rows, unfinished_chains
from report_measures import (
    LEVEL,
    ChainGrowth,
    best_kt,
    compared,
    cost_median,
    cost_ratio,
    energy_tally,
    interleaved_ratios,
    kt_scores,
    loop_scenes,
    stops_ratio,
)
from report_writer import trees_only

README_BEGIN = "<!-- bench:summary (written by benchmarks/report.py) -->"


README_END = "<!-- /bench:summary -->"


def step_cost_line(results: D.Results) -> list[str]:
    """One step over a bare step, per model and per kind of element, and the stops' cost."""
    names = list(results.step_cost)
    if not names:
        return []

    def ratio(name: str, key: str) -> float:
        return cost_median(results, name, key) / cost_median(results, name, "bare")

    def span(key: str) -> str:
        values = [ratio(n, key) for n in names]
        return f"{min(values):.2f}-{max(values):.2f}"

    costs = ", ".join(f"{n} {ratio(n, 'exact'):.2f}" for n in names)
    stops = ", ".join(f"{n} {stops_ratio(results, n):.2f}" for n in names)
    return [
        f"- **One step** costs {costs} times a bare `pinocchio::aba` + `pinocchio::integrate` "
        f"step on the same model (median of interleaved repeats; `benchmarks/step_cost.cpp`). A "
        f"scene without elements: {span('no_elements')}; a joint spring on every joint: "
        f"{span('joint_springs')}; one point spring: {span('point_spring')} (a forward-kinematics "
        f"pass per step to place its ends); the model's joint stops over no stops: {stops}."
    ]


def energy_line(results: D.Results) -> list[str]:
    t = energy_tally(results, results.config.kts)
    return [
        f"- **Exact or simplified energy**: per step, simplified / exact "
        f"{cost_ratio(results):.3f} (UR5); over {len(t['ratios'])} scene and kt pairs, "
        f"{t['geomean']:.2f} times the steps to a residual of {LEVEL:g} (geometric mean; fewer "
        f"in {t['fewer']}, more in {t['more']}, as many in {t['equal']})."
    ]


def kt_line(results: D.Results) -> list[str]:
    score = kt_scores(results, "exact")
    means = ", ".join(
        f"{kt:g}: {geomean([x for x in r if math.isfinite(x)]):.2f}" for kt, r in score.items()
    )
    return [
        f"- **kt**: the fewest steps to a residual of {LEVEL:g} came with kt = "
        f"{best_kt(score):g} (geometric mean over the scenes of the steps over each scene's "
        f"fewest: {means})."
    ]


#: The peers in the README, by group: the damped baselines plain, the same finished by the
#: solver's Newton, and Newton with a trust region.
PEER_GROUPS = {
    "the damped baselines plain (viscous, mass-proportional, adaptive DR, FIRE, FIRE 2.0)": tuple(
        D.DAMPED_LABELS
    ),
    "the same finished by pinsettle's own Newton": tuple(
        f"{f}{D.NEWTON_SUFFIX}" for f in D.DAMPED_LABELS
    ),
    "Newton's method from the start with a trust region": (D.NEWTON_TR,),
}


def group_ratios(results: D.Results, families: tuple[str, ...]) -> dict[str, float]:
    """Per tree scene, the group's fastest in the interleaved timing over KD's defaults."""
    out = {}
    for name in compared(results):
        ratios = interleaved_ratios(results.scenes[name])
        if group := [ratios[f] for f in families if f in ratios]:
            out[name] = min(group)
    return out


def same_rest(results: D.Results) -> str:
    """On how many tree scenes Newton from the start ended at KD's rest (within 1e-8)."""
    ends = [
        run.distance
        for name in compared(results)
        if (run := results.scenes[name].runs.get(f"{D.NEWTON_TR}_best")) is not None
    ]
    same = sum(1 for x in ends if x <= 1e-8)
    if same == len(ends):
        return f"the same rest, to 1e-8, on all {len(ends)} scenes here"
    return f"the same rest, to 1e-8, on {same} of the {len(ends)} scenes here"


def readme_baseline_lines(results: D.Results) -> list[str]:
    parts = []
    for label, families in PEER_GROUPS.items():
        ratios = group_ratios(results, families)
        if not ratios:
            continue
        faster = [n for n, r in ratios.items() if r < 1]
        parts.append(
            f"{label}, {min(ratios.values()):.2g} to {max(ratios.values()):.2g} times KD's time "
            f"(median {statistics.median(ratios.values()):.2g}; faster than KD on "
            f"{len(faster)} of {len(ratios)}" + (f": {', '.join(faster)}" if faster else "") + ")"
        )
    if not parts:
        return []
    lines = [
        f"- **Peers at their best** (C++ on the same Pinocchio model, each swept over its own "
        f"parameters, then every method's best timed again in "
        f"{results.config.interleave_rounds} interleaved rounds; time to a residual of "
        f"{LEVEL:g}, the fastest of each group per tree scene, over KD's defaults): "
        + "; ".join(parts)
        + ". Newton from the start solves the statics directly and finds a minimum of the "
        "potential energy near the start; pinsettle finds the rest the released mechanism comes "
        f"to ({same_rest(results)})."
    ]
    if loop_scenes(results):
        lines.append(f"- The {trees_only(results)}.")
    return lines


def gallery_line(results: D.Results) -> list[str]:
    if not results.gallery:
        return []
    return [f"- **Robot gallery**: {gallery_tally(results)}."]


def overhead_line(results: D.Results) -> list[str]:
    rows = goal4_rows(results)
    if not rows:
        return []
    shares = ", ".join(
        f"{r['name']} {r['fraction']:.1%} ({r['fraction_polish']:.1%} in the default solve)"
        for r in rows
    )
    return [
        "- **Where a solve's time goes**: the set-up, step estimates, stability assessments and "
        f"(in the default solve) the polish's Newton take {shares} of a solve's time "
        "(`benchmarks/kd_profile.cpp`)."
    ]


def chains_line(results: D.Results) -> list[str]:
    growth = ChainGrowth.of(results)
    if growth is None:
        return []
    unfinished = unfinished_chains(results)
    return ["- **Chains**: " + growth.text() + (f"; {unfinished}" if unfinished else "") + "."]


#: The README's speed section, in its order: what was measured, without the goals (those are
#: in the report's Goals part). Each a function of the results giving its lines.
README_LINES = (
    step_cost_line,
    energy_line,
    kt_line,
    readme_baseline_lines,
    gallery_line,
    overhead_line,
    chains_line,
)


def wrap(line: str) -> str:
    """A README line wrapped at 100 characters, a bullet's continuation indented."""
    if not line or line.startswith("<!--"):
        return line
    return textwrap.fill(line, 100, subsequent_indent="  " if line.startswith("- ") else "")


def readme_block(results: D.Results) -> str:
    """The README's speed section: the main ratios of the report, as measured."""
    m = results.machine
    lines = [
        README_BEGIN,
        f"Measured by `python benchmarks/report.py` on this project's {m['cores']}-core machine "
        f"({m['date']}, shared with other jobs: ratios within one run, medians of repeats); the "
        "whole report, with plots of error against wall time and steps for each scene and the "
        "goals this project set itself, is [docs/benchmarks.md](docs/benchmarks.md).",
        "",
    ]
    lines += [line for part in README_LINES for line in part(results)]
    lines.append(README_END)
    return "\n".join(wrap(line) for line in lines)


def update_readme(results: D.Results, readme: Path) -> bool:
    """Replace the block between the markers; False when the README has none."""
    text = readme.read_text(encoding="utf-8")
    start, end = text.find(README_BEGIN), text.find(README_END)
    if start < 0 or end < 0:
        return False
    text = text[:start] + readme_block(results) + text[end + len(README_END) :]
    readme.write_text(text, encoding="utf-8")
    return True

"""The Goals part of the benchmark report: the goals of issues 18 and 20, each measured in
the run, met or not, and why not, from what was measured."""

from __future__ import annotations

import dataclasses
import math

import report_data as D
from report_format import fmt_e, fmt_time, slope
from report_measures import (
    BASELINES,
    GOAL4_SCENES,
    LEVEL,
    ChainGrowth,
    compared,
    fastest_baseline,
    fastest_interleaved,
    kd_key,
    kd_reach,
    kd_time,
    measured_chains,
    mujoco_saddle_stops,
    mujoco_settled,
    overhead_rows,
    refused_chains,
    settled_inside,
    stop_ratios,
    time_to,
)


def unfinished_chains(results: D.Results) -> str:
    """The chains of the scaling section that did not converge in time and those pinsettle
    refused, in words ('' when every chain converged)."""
    refused = [row["n"] for row in refused_chains(results)]
    unconverged = [
        row["n"]
        for row in measured_chains(results)
        if row.get("profile", {}).get("status") != "converged"
    ]
    parts = []
    if unconverged:
        parts.append(
            f"{', '.join(map(str, unconverged))} links did not converge within "
            f"{results.config.scaling_max_time:g} s"
        )
    if refused:
        parts.append(f"{', '.join(map(str, refused))} links were refused")
    return "; ".join(parts)


def goal4_verdict(rows: list[D.Record]) -> str:
    """Goal 4's shares (the damping's own run, polish off, and the default solve), met or not,
    and why not where the default solve's Newton is what passes the bound."""
    text = ", ".join(
        f"{r['name']} {r['fraction']:.1%} ({r['fraction_polish']:.1%} in the default solve)"
        for r in rows
    )
    worst = max(max(r["fraction"], r["fraction_polish"]) for r in rows)
    if worst <= 0.25:
        return text + ": met."
    newton = [r for r in rows if r["fraction"] <= 0.25 < r["fraction_polish"]]
    why = "".join(
        f" Why, on {r['name']} ({r['fraction_polish']:.2%}): the default solve's Newton (its "
        "tries at damping events and the polish) counts as overhead, and it replaces steps: "
        f"{r['default_steps']:,} steps and "
        f"{fmt_time(r['default_wall'])} against {r['steps']:,} steps and "
        f"{fmt_time(r['wall'])} with `polish = False`."
        for r in newton
    )
    return text + ": **not met**." + why + fixed_cost_reasons(rows)


def fixed_cost_reasons(rows: list[D.Record]) -> str:
    """Why the damping's own run (polish off) passes the bound, where it does: a short run
    against costs fixed per solve (the set-up's first step estimate and the verdicts, each a
    stiffness matrix and an eigen-decomposition), in bare steps."""
    out = ""
    for r in rows:
        if r["fraction"] <= 0.25 or r["steps"] == 0:
            continue
        parts = r["parts"]
        per_step = r["bare"] / r["steps"]
        worth = sum(parts.values()) / per_step if per_step > 0 else math.inf
        out += (
            f" Why, on {r['name']} ({r['fraction']:.1%}): its run is {r['steps']:,} steps, and "
            f"its set-up ({fmt_time(parts['setup'])}: the checks and the first step estimate, "
            f"a stiffness matrix and an eigen-decomposition, O(nv^3) with nv = {r['nv']}), "
            f"{r['estimate_count']} later estimates and {r['assessment_count']} stability "
            f"assessments ({fmt_time(parts['estimates'] + parts['assessments'])}) cost as much "
            f"as {worth:,.0f} of its bare steps."
        )
    return out


def saddle_note(results: D.Results) -> str:
    """Where MuJoCo's settle at the gallery's setting stopped on a saddle."""
    unstable = mujoco_saddle_stops(results.gallery, mujoco_settled(results))
    if not unstable:
        return ""
    return (
        f" MuJoCo's settle ends on an unstable rest (a saddle its damped motion did not "
        f"leave) on {', '.join(unstable)}: there pinsettle pushes off and goes on to a "
        "stable rest."
    )


def gallery_tally(results: D.Results) -> str:
    """'k of n robots converge inside their limits ...; floating bases: ...'."""
    falls = [f"{r['name']} {r['status']} in {fmt_time(r['median'])}" for r in results.floating]
    return (
        f"{len(settled_inside(results))} of {len(results.gallery)} robots converge inside "
        "their limits with the default settings (independent check)"
        + (f"; floating bases: {', '.join(falls)}" if falls else "")
    )


#: A behind scene (of more than one degree of freedom) whose KD run damps more often than once
#: in this many steps, or whose set-up is more than this share of KD's time, gets the matching
#: reason in the goal 1 line.
FREQUENT_DAMPING = 15


SETUP_HEAVY = 0.2


def goal1_reasons(
    frequent: list[str],
    setup_heavy: list[str],
    single: list[tuple[str, str, int, float, int, float]],
) -> str:
    """Why KD is behind where goal 1 is not met, in plain words, from what was measured.
    ``single``: the one-degree-of-freedom scenes behind, each (name, the faster baseline, its
    steps and time to the level, KD's steps and time to the level)."""
    text = ""
    if single:
        fewer = all(steps_b <= steps_k for _, _, steps_b, _, steps_k, _ in single)
        text += (
            f" Why, on {', '.join(n for n, *_ in single)} (one degree of freedom): "
            + "; ".join(
                f"{n}: {label} {steps_b:,} steps in {fmt_time(t_b)} "
                f"({fmt_time(t_b / steps_b)} a step, set-up included), KD {steps_k:,} in "
                f"{fmt_time(t_k)} ({fmt_time(t_k / steps_k)})"
                for n, label, steps_b, t_b, steps_k, t_k in single
            )
            + ". A single mode has no slower swing for KD's stops to save, and a damper tuned to "
            "it (its sweep's best) brings it down "
            + ("in as few steps or fewer" if fewer else "in about as many steps")
            + "; each KD step also computes both energies, tests for a peak and controls the "
            "step."
        )
    if frequent:
        text += (
            f" Why, on {', '.join(frequent)}: KD damps every few steps there, and each damping "
            "event (kt = 0) stops the slow swing of the whole mechanism together with the fast "
            "modes whose energy peaked, so the motion starts again from rest; viscous damping "
            "removes energy without stopping the motion, and FIRE mixes its velocity toward "
            "the force, which keeps its power positive for longer between resets."
        )
    if setup_heavy:
        text += (
            f" Why, on {', '.join(setup_heavy)}: the whole run takes microseconds, and KD's "
            "set-up (the checks of the model and the start, the first estimate of the "
            "stability limit and of the stiff modes) is a large share of it."
        )
    return text


def goal5_reasons(
    results: D.Results, n: list[int], steps: list[int], per: list[float], wall: list[float]
) -> str:
    """Why the chains' time grows faster than n^2, or why the longest are missing, from what
    was measured: the growth of the steps and of a step, and the solver's own refusal."""
    text = ""
    if slope(n, wall) > 2:
        text += (
            f" Why: the steps grow as n^{slope(n, steps):.2f} (a longer chain's slowest swing "
            f"takes more of them) and a step as n^{slope(n, per):.2f}."
        )
    refused = refused_chains(results)
    if refused:
        text += (
            f" {', '.join(str(row['n']) for row in refused)} links are refused: "
            + refused[0]["refused"].strip().splitlines()[-1]
            + "."
        )
    return text + joint_inertia_growth(results)


def joint_inertia_growth(results: D.Results) -> str:
    """What the same chains' growth is without the fictitious joint inertia (scale_joint_inertia
    off; the default gives it from 20 links), where all of them converged without it."""
    rows = [r for r in results.scaling if r.get("no_joint_inertia") is not None]
    if len(rows) < 2 or any(r["no_joint_inertia"]["status"] != "converged" for r in rows):
        return ""
    n = [r["n"] for r in rows]
    steps = [r["no_joint_inertia"]["steps"] for r in rows]
    seconds = [r["no_joint_inertia"]["seconds"] for r in rows]
    return (
        f" With `scale_joint_inertia = False` the same chains ({n[0]} to {n[-1]} links) take "
        f"{min(steps):,} to {max(steps):,} steps and their time grows as "
        f"n^{slope(n, seconds):.2f} (the Scaling part): the default gives the fictitious joint "
        "inertia from 20 degrees of freedom (docs/method.md, Fictitious joint inertia)."
    )


@dataclasses.dataclass
class Behind:
    """The scenes where KD is slower than a baseline at its best, for goal 1's line: one entry
    each, and the scenes each reason of goal1_reasons applies to."""

    entries: list[str] = dataclasses.field(default_factory=list)
    frequent: list[str] = dataclasses.field(default_factory=list)
    setup_heavy: list[str] = dataclasses.field(default_factory=list)
    single: list[tuple[str, str, int, float, int, float]] = dataclasses.field(default_factory=list)
    # Where Newton from the start is the fastest: (name, iterations, time, verdict, distance
    # from KD's rest).
    newton: list[tuple[str, int, float, str, float]] = dataclasses.field(default_factory=list)


def behind_entry(
    name: str, label: str, t_b: float, t_k: float, kd: D.Run, resets: int | None
) -> str:
    """'name (baseline time against KD's; how often KD damps; its set-up's share)'."""
    every = kd.steps / kd.peaks if kd.peaks else math.inf
    reset = f" ({kd.peaks:,} times), {label} resets {resets:,} times" if resets is not None else ""
    return (
        f"{name} ({label} {fmt_time(t_b)} against KD's {fmt_time(t_k)}; KD damps once every "
        f"{every:.0f} steps" + reset + f"; KD's set-up {fmt_time(kd.setup)} is "
        f"{kd.setup / t_k:.0%} of its time)"
    )


#: The peers that follow the mechanism's dynamics (all but Newton from the start).
DYNAMIC_PEERS = tuple(f for f in BASELINES if f != D.NEWTON_TR)


def note_behind(
    behind: Behind, name: str, d: D.SceneData, families: tuple[str, ...] = BASELINES
) -> None:
    """Add the scene to ``behind`` where KD did not reach the level or a peer of ``families``
    was faster."""
    reach = kd_reach(d)
    if reach is None:
        behind.entries.append(f"{name} (KD did not reach it)")
        return
    tk, steps_k = reach
    bests = {f: b for f in families if (b := fastest_baseline(d, f)) is not None}
    faster = {f: b[0] for f, b in bests.items() if b[0] < tk}
    if not faster:
        return
    f = min(faster, key=lambda family: faster[family])
    kd = d.runs[kd_key()]
    label = D.BASELINE_LABELS[f]
    behind.entries.append(behind_entry(name, label, faster[f], tk, kd, bests[f][1]))
    if f == D.NEWTON_TR:
        run = d.runs[f"{f}_best"]
        behind.newton.append((name, bests[f][2], faster[f], run.stability, run.distance))
        return
    every = kd.steps / kd.peaks if kd.peaks else math.inf
    if every < FREQUENT_DAMPING and d.nv > 1:  # one mode: no slow swing to stop
        behind.frequent.append(name)
    if d.nv == 1 and steps_k:
        behind.single.append((name, label, bests[f][2], faster[f], steps_k, tk))
    if kd.setup / tk > SETUP_HEAVY:  # of the time the line gives, set-up included
        behind.setup_heavy.append(name)


def fire_rule_failures(results: D.Results) -> str:
    """Where FIRE at its rule did not reach the level, and how many of those KD settled."""
    scenes = results.scenes
    fails = [
        n for n, d in scenes.items() if d.baseline_sweep and time_to(d.runs["fire_rule"]) is None
    ]
    if not fails:
        return ". FIRE at its rule fails none"
    kd_ok = [n for n in fails if kd_time(scenes[n]) is not None]
    return f". FIRE at its rule fails {', '.join(fails)}; KD settles {len(kd_ok)} of them"


def goal1_lines(results: D.Results) -> list[str]:
    names = compared(results)
    if not names:
        return []
    behind, dynamic = Behind(), Behind()
    for name in names:
        note_behind(behind, name, results.scenes[name])
        note_behind(dynamic, name, results.scenes[name], DYNAMIC_PEERS)
    return [
        f"- **Goal 1** (KD with the default settings at least as fast to a residual of "
        f"{LEVEL:g} as every peer at its best, on every tree scene: the damped baselines plain "
        "and finished by the solver's own Newton, and Newton with a trust region; a peer's best "
        "is its fastest run to that level: its rule, a point of its sweep or the sweep's best "
        "setting run in full): "
        + behind_verdict(behind, names)
        + fire_rule_failures(results)
        + " (the whole comparison, per scene, in the Scenes part)."
        + newton_reason(behind.newton),
        "- **Goal 1 against the peers that follow the dynamics** (the damped baselines, plain "
        "and + Newton; without Newton from the start): "
        + behind_verdict(dynamic, names)
        + "."
        + goal1_reasons(dynamic.frequent, dynamic.setup_heavy, dynamic.single),
    ] + interleaved_goal_lines(results, names)


def behind_verdict(behind: Behind, names: list[str]) -> str:
    done = len(names) - len(behind.entries)
    if not behind.entries:
        return f"met on all {len(names)}"
    return f"met on {done} of {len(names)}; **not met** on " + "; ".join(behind.entries)


def newton_reason(newton: list[tuple[str, int, float, str, float]]) -> str:
    """Why Newton from the start is faster, where it is: what it did and where it ended."""
    if not newton:
        return ""
    return (
        f" Why, on {', '.join(n for n, *_ in newton)}: Newton with a trust region solves the "
        "statics directly, a few iterations of one stiffness matrix and one eigen-decomposition "
        "each ("
        + "; ".join(
            f"{n} {it:,} in {fmt_time(t)}, {verdict}, {fmt_e(dist)} from KD's rest"
            for n, it, t, verdict, dist in newton
        )
        + "), where KD simulates the motion to its rest. It descends the potential energy "
        "to a minimum near the start; KD finds the rest the released mechanism comes to, which "
        "on a landscape of several minima need not be the same one."
    )


def interleaved_goal_lines(results: D.Results, names: list[str]) -> list[str]:
    """Goal 1 again on the interleaved timing: per scene, the fastest peer over KD."""
    found = {n: f for n in names if (f := fastest_interleaved(results.scenes[n])) is not None}
    if not found:
        return []
    behind = {n: f for n, f in found.items() if f[1] < 1}
    cells = [f"{n} ({D.BASELINE_LABELS[f]} {r:.2g} of KD's time)" for n, (f, r) in found.items()]
    verdict = f"met on {len(found) - len(behind)} of {len(found)}" + (
        f"; **not met** on {len(behind)}" if behind else ""
    )
    return [
        "- **Goal 1, interleaved timing** (every method's best timed again in "
        f"{results.config.interleave_rounds} interleaved rounds, medians): {verdict}. The "
        "fastest peer per scene: " + "; ".join(cells) + "."
    ]


def goal2_lines(results: D.Results) -> list[str]:
    if not compared(results):
        return []
    defaults = [
        (n, d.runs["kd_default"]) for n, d in results.scenes.items() if "kd_default" in d.runs
    ]
    worse = [f"{n} ({fmt_e(r.residual)})" for n, r in defaults if not r.residual <= LEVEL]
    verdict = (
        f"**not met** on {len(worse)} of {len(defaults)} scenes: " + ", ".join(worse)
        if worse
        else f"met on all {len(defaults)} scenes"
    )
    return [
        f"- **Goal 2** (the default run ends at a relative residual of at most {LEVEL:g}): "
        + verdict
        + "."
    ]


def goal3_lines(results: D.Results) -> list[str]:
    """Goal 3 is judged against MuJoCo at its best (benchmarks/mujoco_best.py), not here: the
    gallery runs MuJoCo at one setting, to compare the answers."""
    if not results.gallery:
        return []
    return [
        "- **Goal 3** (at least 100 times faster than MuJoCo at its best on every robot both "
        "bring to 1e-10, warm, and 30 times on the first call in a process): judged in the part "
        "*MuJoCo at its best, per robot* (`benchmarks/mujoco_best.py`: each robot's ratios and "
        "why). The gallery runs MuJoCo at one setting (a 1 ms step, damping 1) to compare the "
        "answers, not the speed."
    ]


def goal4_rows(results: D.Results) -> list[D.Record]:
    """The overhead rows goal 4 names (a quick run: the scenes it has)."""
    rows = [r for r in overhead_rows(results) if r["name"] in GOAL4_SCENES]
    return rows or overhead_rows(results)


def goal4_lines(results: D.Results) -> list[str]:
    rows = goal4_rows(results)
    if not rows:
        return []
    return [
        "- **Goal 4** (set-up, step estimates, stability assessments and polish at most 25% "
        "of a solve on the UR5, chain20, chain100): " + goal4_verdict(rows)
    ]


def goal5_lines(results: D.Results) -> list[str]:
    growth = ChainGrowth.of(results)
    if growth is None:
        return []
    unfinished = unfinished_chains(results)
    if unfinished:
        verdict = f"; {unfinished}: **not met**."
    else:
        verdict = ": met." if slope(growth.n, growth.wall) <= 2 else ": **not met**."
    return [
        "- **Goal 5** (time no faster than n^2 from 5 to 1,000 links, a step O(n)): "
        + growth.text()
        + verdict
        + goal5_reasons(results, growth.n, growth.steps, growth.per, growth.wall)
    ]


def step_cost_goal_lines(results: D.Results) -> list[str]:
    ratios = stop_ratios(results)
    if not ratios:
        return []
    return [
        "- **Issue 18, step cost** (a step with joint stops at most 1.1 times one "
        "without, UR5 and Panda): "
        + ", ".join(f"{n} {x:.2f}" for n, x in ratios.items())
        + (": met." if max(ratios.values()) <= 1.1 else ": **not met**.")
    ]


def gallery_goal_lines(results: D.Results) -> list[str]:
    if not results.gallery:
        return []
    return [f"- **Issue 18, gallery**: {gallery_tally(results)}."]


#: The goals of issues 18 and 20, in the Goals part's order: each a function of the results
#: giving its line (none when this run did not measure it).
GOALS = (
    goal1_lines,
    goal2_lines,
    goal3_lines,
    goal4_lines,
    goal5_lines,
    step_cost_goal_lines,
    gallery_goal_lines,
)


def goals_section(results: D.Results) -> str:
    """The goals of issues 18 and 20, each measured in this run: met or not, in plain words."""
    lines = [line for goal in GOALS for line in goal(results)]
    return (
        "## Goals\n\n"
        "The figures issues 18 and 20 ask for, as measured in this run (details in the parts "
        "below).\n\n" + "\n".join(lines) + "\n\n"
    )

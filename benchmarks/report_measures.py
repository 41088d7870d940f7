"""What the benchmark report derives from its records (report_data): times to the level,
ratios, the scenes and chains each part compares. No text in here."""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Sequence

import pinsettle
import report_data as D
from report_format import geomean, slope

LEVEL = D.RESIDUAL_LEVELS[-1]  # the level the conclusions compare at


#: The solver's default settings, which the texts quote (they may change).
DEFAULTS = pinsettle.Settings()


BASELINES = D.BASELINES


def reach(run: D.Run, quantity: str, level: float) -> tuple[float, float] | None:
    return run.reach(quantity, level)


def time_to(run: D.Run, level: float = LEVEL) -> float | None:
    hit = run.reach("residual", level)
    return None if hit is None else hit[1]


def steps_to(run: D.Run, level: float = LEVEL) -> float | None:
    hit = run.reach("residual", level)
    return None if hit is None else hit[0]


def loop_scenes(results: D.Results) -> list[str]:
    """The scenes with closed loops, in the report's order."""
    return [name for name, d in results.scenes.items() if d.loops]


def kd_runs(d: D.SceneData) -> list[D.Run]:
    """Every kinetic-damping run on a scene: the main runs and the sweeps'."""
    runs = [r for r in d.runs.values() if r.method == "kd"]
    return runs + [r for sweep in d.sweeps.values() for r in sweep if r.method == "kd"]


def worst_constraint_error(d: D.SceneData) -> float:
    """Largest final loop error (m) over every KD run on the scene, as measured by the report
    and as reported by the solver."""
    return max(
        float(max(r.extra["constraint_error"], r.extra["solver_constraint_error"]))
        for r in kd_runs(d)
    )


def loop_cost_ratio(results: D.Results, name: str, key: str = "exact") -> float:
    """The solver's step on a scene with loops over a bare ``pinocchio::constraintDynamics`` +
    ``integrate`` step (benchmarks/loop_step_cost, medians); nan when not measured."""
    cost = results.loop_step_cost.get(name)
    if cost is None:
        return math.nan
    c = cost["ns_per_step"]
    return float(statistics.median(c[key]) / statistics.median(c["bare"]))


def kd_key() -> str:
    """The main KD run: the default energy measure (its other settings are the defaults but
    max_e, see How it is measured)."""
    return f"kd_{pinsettle.Settings().energy}"


def compared(results: D.Results) -> list[str]:
    """The scenes of the baselines' comparison: trees, not reported apart."""
    return [n for n, d in results.scenes.items() if d.baseline_sweep and not d.apart]


def apart_scenes(results: D.Results) -> list[str]:
    return [n for n, d in results.scenes.items() if d.baseline_sweep and d.apart]


def kd_reach(d: D.SceneData) -> tuple[float, int] | None:
    """KD's time (s) and steps to the level with the default settings: from the curve of the run
    that goes on to round-off (the same trajectory as the default run up to where that stops), or
    the whole default run when it ends below the level sooner (its polish, after the trajectory,
    gets there)."""
    hit = d.runs[kd_key()].reach("residual", LEVEL)
    default = d.runs.get("kd_default")
    if default is not None and default.residual <= LEVEL and (hit is None or default.time < hit[1]):
        return default.time, default.steps
    return None if hit is None else (hit[1], int(hit[0]))


def kd_time(d: D.SceneData) -> float | None:
    """KD's time to the level with the default settings (kd_reach)."""
    reach = kd_reach(d)
    return None if reach is None else reach[0]


def ratio_to_kd(d: D.SceneData, key: str) -> float | None:
    """A baseline's time to the level over KD's (defaults); None when either did not get
    there."""
    tb, tk = time_to(d.runs[key]), kd_time(d)
    return None if tb is None or tk is None else tb / tk


def _pairs(d: D.SceneData, kts: Sequence[float]) -> list[tuple[float, D.Run, D.Run]]:
    by = {(r.settings["energy"], r.settings["kt"]): r for r in d.sweeps["kt"]}
    return [(kt, by[("exact", kt)], by[("simplified", kt)]) for kt in kts]


def energy_tally(results: D.Results, kts: Sequence[float]) -> D.Record:
    """Steps to the level, simplified against exact, over the scenes and the given kt."""
    ratios, fewer, more, equal, missing = [], 0, 0, 0, []
    for name, d in results.scenes.items():
        for kt, e, s in _pairs(d, kts):
            a, b = steps_to(e), steps_to(s)
            if a is None or b is None:
                which = (
                    "both" if a is None and b is None else "exact" if a is None else "simplified"
                )
                missing.append(f"{name} kt={kt:g} ({which})")
                continue
            ratios.append(b / a)
            fewer += b < a
            more += b > a
            equal += b == a
    return {
        "ratios": ratios,
        "fewer": fewer,
        "more": more,
        "equal": equal,
        "missing": missing,
        "geomean": geomean(ratios),
    }


def cost_ratio(results: D.Results, name: str = "ur5") -> float:
    cost = results.step_cost.get(name)
    if not cost:
        return math.nan
    c = cost["ns_per_step"]
    return float(statistics.median(c["simplified"]) / statistics.median(c["exact"]))


def kt_scores(results: D.Results, energy: str) -> dict[float, list[float]]:
    """For each kt: steps to the level over the scene's best kt, per scene (inf: not reached)."""
    score: dict[float, list[float]] = {kt: [] for kt in results.config.kts}
    for d in results.scenes.values():
        steps = {
            r.settings["kt"]: steps_to(r) for r in d.sweeps["kt"] if r.settings["energy"] == energy
        }
        best = min((x for x in steps.values() if x is not None), default=None)
        for kt in results.config.kts:
            x = steps.get(kt)
            score[kt].append(math.inf if x is None or best is None else max(x, 1) / max(best, 1))
    return score


def best_kt(score: dict[float, list[float]]) -> float:
    def key(kt: float) -> tuple[int, float]:
        ratios = score[kt]
        return (sum(not math.isfinite(x) for x in ratios), geomean(ratios))

    return min(score, key=key)


def cost_median(results: D.Results, name: str, key: str) -> float:
    c = results.step_cost[name]["ns_per_step"]
    return statistics.median(c[key]) if c.get(key) else math.nan


def stops_ratio(results: D.Results, name: str) -> float:
    """A step with the model's joint stops over the same step without (step_cost medians)."""
    return cost_median(results, name, "stops") / cost_median(results, name, "exact")


#: The scenes of goal 4 of issue 20.
GOAL4_SCENES = ("ur5", "chain20", "chain100")


def overhead_rows(results: D.Results) -> list[D.Record]:
    """The overhead split per scene, as fractions of the solve's wall time (medians): of the
    plain solve (polish off), and of the default solve (its set-up, estimates, assessments and
    Newton's stiffness matrices; Newton's static-force evaluations, O(n) each, are left out)."""
    out = []
    for name, p in results.overhead.items():
        m = p["median"]
        wall = m["wall"]
        parts = {
            "setup": m["setup"],
            "estimates": m["estimates"],
            "assessments": m["assessments"],
        }
        overhead = sum(parts.values())
        # The default solve's own parts: with Newton's takeover it is not the plain run plus a
        # polish, but a run that Newton may end at a damping event.
        default_parts = (
            m["polish_setup"]
            + m["polish_estimates"]
            + m["polish_assessments"]
            + m["polish_stiffness"]
        )
        fraction_polish = default_parts / m["polish_wall"]
        out.append(
            {
                "name": name,
                "nv": p["nv"],
                "steps": p["steps"],
                "status": p["status"],
                "wall": wall,
                "parts": parts,
                "estimate_count": p["estimate_count"],
                "assessment_count": p["assessment_count"],
                "polish_iterations": p.get("polish_iterations", 0),
                "fraction": overhead / wall,
                "fraction_polish": fraction_polish,
                "default_wall": m["polish_wall"],
                "default_steps": p["polish_steps"],
                "bare": m["bare_step"] * p["steps"],
            }
        )
    return out


def solve_time(row: D.Record) -> float:
    """A scaling chain's default solve, timed whole with its polish (median of the repeats; the
    profile's parts are timed in the same solve without it)."""
    return float(row["profile"]["median"]["polish_wall"])


def solve_steps(row: D.Record) -> int:
    """The steps of a scaling chain's default solve (solve_time's): with Newton's takeover they
    may be fewer than the profile's plain solve took."""
    p = row["profile"]
    return int(p.get("polish_steps", p["steps"]))


def measured_chains(results: D.Results) -> list[D.Record]:
    """The chains of the scaling section that pinsettle took (not refused)."""
    return [row for row in results.scaling if "refused" not in row]


def refused_chains(results: D.Results) -> list[D.Record]:
    """The chains of the scaling section that pinsettle refused (their rows hold its message)."""
    return [row for row in results.scaling if "refused" in row]


def converged_chains(results: D.Results) -> list[D.Record]:
    """The chains whose default solve converged: the ones the growth is fitted over."""
    return [r for r in measured_chains(results) if r["profile"]["status"] == "converged"]


def pair_slope(a: D.Record, b: D.Record) -> float:
    """The exponent of the solve time between two chain lengths."""
    return slope([a["n"], b["n"]], [solve_time(a), solve_time(b)])


def mujoco_settled(results: D.Results) -> list[str]:
    """The robots both pinsettle and MuJoCo's damped settle at the gallery's setting settle."""
    return [
        r["name"]
        for r in results.gallery
        if r["mujoco"].get("status") == "settled" and r["status"] == "converged"
    ]


def settled_inside(results: D.Results) -> list[str]:
    """The robots pinsettle settled inside their limits, not on an unstable rest."""
    return [
        r["name"]
        for r in results.gallery
        if r["status"] == "converged" and r["outside"] <= 0 and r["stability"] != "unstable"
    ]


def mujoco_saddle_stops(gallery: list[D.Record], both: list[str]) -> list[str]:
    """The robots both settle (``both``) where MuJoCo's settle ended on an unstable rest."""
    return [
        r["name"]
        for r in gallery
        if r["name"] in both and r["mujoco"].get("stability") == "unstable"
    ]


def interleaved_ratios(d: D.SceneData) -> dict[str, float]:
    """Each peer's median over KD's in the interleaved timing, where every round converged."""
    kd = d.interleaved.get("kd_default", [])
    if not kd:
        return {}
    return {
        f: statistics.median(ts) / statistics.median(kd)
        for f, ts in d.interleaved.items()
        if f != "kd_default" and ts and all(math.isfinite(t) for t in ts)
    }


def fastest_interleaved(d: D.SceneData) -> tuple[str, float] | None:
    """The fastest peer in the interleaved timing and its median over KD's."""
    ratios = interleaved_ratios(d)
    if not ratios:
        return None
    f = min(ratios, key=lambda k: ratios[k])
    return f, ratios[f]


def fastest_baseline(d: D.SceneData, family: str) -> tuple[float, int | None, int] | None:
    """A baseline at its best: the shortest time to LEVEL (s) among its rule run, the run at the
    sweep's best setting and the sweep's own runs (each timed in its own repeats; a full run may
    be slower than its sweep point when it stalled past the level and was retried with the steps
    halved), with that run's velocity resets (None for the viscous baselines) and its steps to
    the level; None when none got there."""
    fire = family.startswith("fire")
    found: list[tuple[float, int | None, int]] = []
    for run in (d.runs[f"{family}_rule"], d.runs[f"{family}_best"]):
        hit = run.reach("residual", LEVEL)  # (steps, time)
        if hit is not None:
            found.append((hit[1], run.extra.get("resets") if fire else None, int(hit[0])))
    found += [
        (p.seconds, p.resets if fire else None, p.steps)
        for p in d.baseline_sweep.get(family, [])
        if p.time_to is not None
    ]
    return min(found, key=lambda item: item[0], default=None)


@dataclasses.dataclass
class ChainGrowth:
    """The converged chains' lengths and, for each, the default solve's time, steps and time
    per step: what goal 5 and the README's chains line fit."""

    n: list[int]
    wall: list[float]
    steps: list[int]
    per: list[float]

    @classmethod
    def of(cls, results: D.Results) -> ChainGrowth | None:
        done = converged_chains(results)
        if len(done) < 2:
            return None
        wall = [solve_time(r) for r in done]
        per = [w / max(solve_steps(r), 1) for w, r in zip(wall, done, strict=True)]
        return cls([r["n"] for r in done], wall, [solve_steps(r) for r in done], per)

    def text(self) -> str:
        return (
            f"time grows as n^{slope(self.n, self.wall):.2f} and a step as "
            f"n^{slope(self.n, self.per):.2f} over {self.n[0]} to {self.n[-1]} links"
        )


def stop_ratios(results: D.Results) -> dict[str, float]:
    """A step with joint stops over one without, on the UR5 and the Panda (where measured)."""
    return {n: stops_ratio(results, n) for n in ("ur5", "panda") if n in results.step_cost}

"""Sweeps: many equilibria of one scene, one row each in a pandas table.

``sweep(scene, vary=..., starts=...)`` plans the cases (a grid or a zip of scene values, times
the starts), runs them on local threads (each solve runs in C++ with the GIL released) or on a
Dask cluster (``_sweep_cluster``), and returns the table. Every case is an ordinary
``pinsettle.solve`` of a copy of the scene with its values changed, so a row is, bit for bit,
what solving that case alone gives, whatever the number of workers.

pandas is imported only when a table is built and Dask only for a cluster: importing pinsettle
or solving imports neither.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
import os
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent import futures
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio

from . import _core
from ._scene import Scene, load_scene
from ._settings import Settings, make_settings
from ._sweep_cases import (
    OUTPUT_COLUMNS,
    REST_TOLERANCE,
    Collect,
    DataFrame,
    Interrupts,
    JointColumns,
    Key,
    MissingDependencyError,
    Runner,
    Spec,
    Task,
    joint_columns,
    joint_row,
    key_values,
    pandas,
    parse_key,
    q_from_row,
    rest_distance,
    scene_data,
    start_q,
    value_columns,
)
from .scenes import scene_path

__all__ = ["MissingDependencyError", "distinct_rests", "sweep"]

# --- the plan -----------------------------------------------------------------------------------


@dataclass
class Plan:
    """The cases of a sweep: their columns (the varied values, the start) and how they are
    grouped into tasks."""

    keys: list[Key]
    combos: list[tuple[Any, ...]]
    starts: list[np.ndarray]
    continuation: bool
    columns: dict[str, list[Any]]
    specs: list[Spec]

    @property
    def size(self) -> int:
        return len(self.specs)

    def branch_cases(self, start: int) -> list[int]:
        """The cases of the branch of start ``start``, in order."""
        n = len(self.starts)
        return [c * n + start for c in range(len(self.combos))]


def _stop_bounds(scene: Scene, limits: bool | None) -> dict[str, tuple[float, float]]:
    """The stops the solves keep (``limits`` as for ``solve``), (lower, upper) by joint."""
    compiled = scene.compile()
    stops = compiled.stops_for(scene.limits if limits is None else limits)
    if stops is None:
        return {}
    found = _core.joint_stops(compiled.model, stops)["stops"]
    return {str(name): (lower, upper) for name, _, _, lower, upper in found}


def _draw_range(lower: float, upper: float) -> tuple[float, float]:
    """Where a 1-DoF joint between ``lower`` and ``upper`` is drawn: inside its stops, +-pi on a
    side without one."""
    lo = lower if math.isfinite(lower) else -math.pi
    hi = upper if math.isfinite(upper) else math.pi
    if lo > hi:  # a single stop beyond +-pi: a turn from it
        return (lower, lower + 2 * math.pi) if math.isfinite(lower) else (hi - 2 * math.pi, hi)
    return lo, hi


def _free_joints(scene: Scene) -> list[int]:
    """The indices of the joints a start sets (the locked ones keep the scene's start)."""
    model = scene.model
    return [j for j in range(1, model.njoints) if str(model.names[j]) not in scene.locked]


def _draw_ranges(scene: Scene, limits: bool | None) -> tuple[list[float], list[float]]:
    """The lower and upper ends of each drawn entry: one per 1-DoF joint, one per tangent
    entry of a multi-DoF joint."""
    model = scene.model
    bounds = _stop_bounds(scene, limits)
    lows: list[float] = []
    highs: list[float] = []
    for j in _free_joints(scene):
        if model.nvs[j] == 1:
            lo, hi = _draw_range(*bounds.get(str(model.names[j]), (-math.inf, math.inf)))
            lows.append(lo)
            highs.append(hi)
        else:
            lows += [-math.pi] * model.nvs[j]
            highs += [math.pi] * model.nvs[j]
    return lows, highs


def _start_of_draw(scene: Scene, base: np.ndarray, row: np.ndarray) -> np.ndarray:
    """The start of one draw: each multi-DoF joint moved from neutral by its tangent entries,
    then each 1-DoF joint set to its value (an angle for a continuous joint)."""
    model = scene.model
    q: np.ndarray = base.copy()
    v, k = np.zeros(model.nv), 0
    neutral = pinocchio.neutral(model)
    single: list[tuple[int, float]] = []
    for j in _free_joints(scene):
        if model.nvs[j] == 1:
            single.append((j, float(row[k])))
            k += 1
        else:
            iv, nv = model.idx_vs[j], model.nvs[j]
            iq, nq = model.idx_qs[j], model.nqs[j]
            v[iv : iv + nv] = row[k : k + nv]
            q[iq : iq + nq] = neutral[iq : iq + nq]
            k += nv
    if v.any():
        q = pinocchio.integrate(model, q, v)
    for j, x in single:
        iq = model.idx_qs[j]
        if model.nqs[j] == 2:
            q[iq : iq + 2] = (math.cos(x), math.sin(x))
        else:
            q[iq] = x
    return q


def random_starts(scene: Scene, limits: bool | None, n: int, seed: int) -> list[np.ndarray]:
    """``n`` starts drawn uniformly: a 1-DoF joint inside its stops (+-pi where it has none, on
    a side without one), a multi-DoF joint by a tangent vector of entries in +-pi from neutral;
    locked joints at the scene's start."""
    lows, highs = _draw_ranges(scene, limits)
    draws = np.random.default_rng(seed).uniform(np.array(lows), np.array(highs), (n, len(lows)))
    base = scene.q0()
    return [_start_of_draw(scene, base, row) for row in draws]


def _is_count(value: Any, minimum: int) -> bool:
    """Whether ``value`` is an integer (not a bool) >= ``minimum``."""
    return (
        not isinstance(value, bool)
        and isinstance(value, (int, np.integer))
        and bool(value >= minimum)
    )


def _random_spec(scene: Scene, starts: tuple[Any, ...], limits: bool | None) -> list[np.ndarray]:
    """The starts of ``('random', n, seed)``, checked."""
    if starts[0] != "random" or len(starts) != 3:
        raise ValueError(
            f"starts must be an array of start configurations or ('random', n, seed), got "
            f"{starts!r}"
        )
    _, n, seed = starts
    if not _is_count(n, 1):
        raise ValueError(f"starts ('random', n, seed): n must be an integer >= 1, got {n!r}")
    if not _is_count(seed, 0):
        raise ValueError(f"starts ('random', n, seed): seed must be an integer >= 0, got {seed!r}")
    return random_starts(scene, limits, int(n), int(seed))


def _given_starts(starts: Any, nq: int) -> list[np.ndarray]:
    """The rows of an array of starts (n, nq), checked."""
    if isinstance(starts, (str, bytes, Mapping)):
        raise TypeError(
            f"starts must be an array of start configurations (n, model.nq = {nq}) or "
            f"('random', n, seed), got {type(starts).__name__}"
        )
    try:
        array = np.asarray(starts, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(
            f"starts must be an array of numbers, shape (n, model.nq = {nq}), got {starts!r}"
        ) from None
    if array.ndim == 1 and nq == 1:
        array = array.reshape(-1, 1)
    if array.ndim != 2 or array.shape[1] != nq or array.shape[0] < 1:
        raise ValueError(
            f"starts must have shape (n, model.nq = {nq}) with n >= 1, got {array.shape}"
        )
    bad = np.argwhere(~np.isfinite(array))
    if bad.size:
        i, k = bad[0]
        raise ValueError(f"starts[{i}][{k}] is {array[i, k]}; every entry must be finite")
    return [row.copy() for row in array]


def _starts(scene: Scene, starts: Any, limits: bool | None) -> list[np.ndarray] | None:
    """The start configurations of ``starts``: None, an array (n, model.nq) or
    ('random', n, seed)."""
    if starts is None:
        return None
    if isinstance(starts, tuple) and starts and isinstance(starts[0], str):
        return _random_spec(scene, starts, limits)
    return _given_starts(starts, scene.model.nq)


def _vary(scene: Scene, vary: Mapping[str, Any] | None) -> tuple[list[Key], list[list[Any]]]:
    """The keys of ``vary`` and the values each takes, checked."""
    if vary is not None and not isinstance(vary, Mapping):
        raise TypeError(f"vary must be a dict of key -> values, got {type(vary).__name__}")
    vary = dict(vary or {})
    keys = [parse_key(text, scene) for text in vary]
    return keys, [key_values(key, vary[key.text]) for key in keys]


def _combos(keys: list[Key], values: list[list[Any]], pair: bool) -> list[tuple[Any, ...]]:
    """The values of the keys in each case: the full grid, or paired (``zip=True``)."""
    if not pair:
        return list(itertools.product(*values))
    lengths = {key.text: len(v) for key, v in zip(keys, values, strict=True)}
    if len(set(lengths.values())) > 1:
        raise ValueError(
            "zip=True pairs the values of every key: they need as many values each, got "
            + ", ".join(f"{k}: {n}" for k, n in lengths.items())
        )
    return list(zip(*values, strict=True)) if values else [()]


def _continuation(
    continuation: Any, keys: list[Key], combos: list[tuple[Any, ...]], pair: bool
) -> bool:
    """Whether the cases run as continuation branches: as asked, or by default for a 1-D
    sweep without start keys."""
    if not isinstance(continuation, (bool, np.bool_, type(None))):
        raise TypeError(f"continuation must be True, False or None, got {continuation!r}")
    start_keys = [key.text for key in keys if key.kind == "start"]
    if continuation and start_keys:
        raise ValueError(
            "continuation starts each case from the previous rest, so a start cannot vary along "
            f"it: remove {', '.join(start_keys)} or pass continuation=False"
        )
    if continuation is None:
        return bool(len(combos) > 1 and (len(keys) == 1 or pair) and not start_keys)
    return bool(continuation)


def _start_columns(scene: Scene, keys: list[Key], given: list[np.ndarray]) -> list[dict[str, Any]]:
    """The columns of each given start: its joints' values (``start.JOINT``), those of the
    start keys aside (they have columns of their own)."""
    start_joints = {key.name for key in keys if key.kind == "start"}
    joints = [j for j in joint_columns(scene) if j.name not in start_joints]
    names = [f"start.{col}" for j in joints for col in j.columns]
    return [dict(zip(names, joint_row(scene.model, joints, q), strict=True)) for q in given]


def _case_q0(
    model: pinocchio.Model, keys: list[Key], combo: tuple[Any, ...], q: np.ndarray
) -> np.ndarray:
    """The start ``q`` with the values of the case's start keys."""
    for key, value in zip(keys, combo, strict=True):
        if key.kind == "start":
            q = start_q(model, q, key, value)
    return q


def _case_columns(
    keys: list[Key],
    combo: tuple[Any, ...],
    start: int,
    start_columns: list[dict[str, Any]] | None,
) -> dict[str, Any]:
    """The table columns a case's plan fills: (with given starts) the start's number, the
    varied values, (with given starts) the start's joints; in that order."""
    row: dict[str, Any] = {} if start_columns is None else {"start": start}
    for key, value in zip(keys, combo, strict=True):
        row.update(value_columns(key, value))
    row.update({} if start_columns is None else start_columns[start])
    return row


def make_plan(
    scene: Scene,
    vary: Mapping[str, Any] | None,
    starts: Any,
    pair: bool,
    continuation: bool | None,
    limits: bool | None,
) -> Plan:
    """The cases of a sweep, every input checked (errors name the key or argument)."""
    keys, values = _vary(scene, vary)
    combos = _combos(keys, values, pair)
    branches = _continuation(continuation, keys, combos, pair)
    given = _starts(scene, starts, limits)
    start_list = given if given is not None else [scene.q0()]
    start_columns = None if given is None else _start_columns(scene, keys, given)
    columns: dict[str, list[Any]] = {}
    specs: list[Spec] = []
    for c, combo in enumerate(combos):
        changes = tuple((i, v) for i, v in enumerate(combo) if keys[i].kind != "start")
        for s, q_start in enumerate(start_list):
            q0 = _case_q0(scene.model, keys, combo, q_start)
            # In a continuation branch, a case after the first starts from the previous rest.
            specs.append(Spec(len(specs), changes, q0 if not branches or c == 0 else None))
            for name, value in _case_columns(keys, combo, s, start_columns).items():
                columns.setdefault(name, []).append(value)
    return Plan(keys, combos, start_list, branches, columns, specs)


def make_tasks(
    plan: Plan,
    done: Mapping[int, Mapping[str, Any]],
    chunk: int,
    rest_of: Callable[[int], np.ndarray | None],
) -> list[Task]:
    """The tasks of the cases not in ``done``: chunks of ``chunk`` independent cases, or one
    branch per start with continuation (a branch begun in ``done`` goes on from its last
    converged rest, ``rest_of(case)``)."""
    if not plan.continuation:
        todo = [spec for spec in plan.specs if spec.case not in done]
        return [Task(tuple(todo[k : k + chunk])) for k in range(0, len(todo), max(1, chunk))]
    tasks = []
    for s in range(len(plan.starts)):
        cases = plan.branch_cases(s)
        left = [c for c in cases if c not in done]
        if not left:
            continue
        previous = None
        for c in cases[: cases.index(left[0])]:
            q = rest_of(c)
            if q is not None:
                previous = (plan.specs[c].changes, q)
        specs = tuple(plan.specs[c] for c in left)
        if previous is None and specs[0].q0 is None:
            first = plan.specs[cases[0]]
            specs = (Spec(specs[0].case, specs[0].changes, first.q0),) + specs[1:]
        tasks.append(Task(specs, branch=True, previous=previous))
    return tasks


# --- local workers ------------------------------------------------------------------------------


def cpu_count() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover (not Linux)
        return os.cpu_count() or 1


def run_local(
    runner: Runner, tasks: Sequence[Task], workers: int, collect: Collect, stop: Interrupts
) -> None:
    """Run the tasks on ``workers`` threads (each solve in C++ with the GIL released), giving
    each task's rows to ``collect`` once, in the calling thread. After a first Ctrl-C
    (``stop.count``) no new case starts and the cases in flight finish and are collected; after
    a second, the cases in flight are aborted and left out.

    Solves never run in the calling thread, so Ctrl-C never aborts one by itself."""
    pending: dict[futures.Future[list[tuple[int, dict[str, Any]]]], Task] = {}
    queue = iter(tasks)

    def stopping() -> bool:
        return stop.count >= 1

    def aborting() -> bool:
        return stop.count >= 2

    with futures.ThreadPoolExecutor(workers, thread_name_prefix="pinsettle-sweep") as pool:
        while True:
            # A few tasks ahead of the workers, not all: Ctrl-C then leaves little in flight.
            while not stopping() and len(pending) < 2 * workers:
                task = next(queue, None)
                if task is None:
                    break
                pending[pool.submit(runner.run, task, stopping, aborting)] = task
            if not pending:
                return
            done, _ = futures.wait(list(pending), 0.1, futures.FIRST_COMPLETED)
            for future in done:
                del pending[future]
                rows = future.result()
                if aborting():
                    rows = [(case, row) for case, row in rows if row["status"] != "aborted"]
                collect(rows)


# --- the table ------------------------------------------------------------------------------------


class Table:
    """The rows of a sweep as they come, and the DataFrame they make."""

    def __init__(self, plan: Plan, runner: Runner) -> None:
        self.plan = plan
        self.runner = runner
        self.rows: dict[int, dict[str, Any]] = {}

    @property
    def joint_names(self) -> list[str]:
        return [c for joint in self.runner.joints for c in joint.columns]

    def output_columns(self) -> list[str]:
        out = ["status", *self.joint_names, "residual", "stability", "min_stiffness_eigenvalue"]
        if self.runner.has_stops:
            out.append("at_limit")
        out += ["steps", "wall_time"]
        if self.plan.continuation:
            out.append("jump")
        return [*out, "error"]

    def add(self, rows: Iterable[tuple[int, dict[str, Any]]]) -> None:
        for case, row in rows:
            if case in self.rows:  # each case once: a second copy would be a bug
                raise RuntimeError(f"case {case} came back twice")
            self.rows[case] = row

    def rest_of(self, case: int) -> np.ndarray | None:
        """A done case's rest (full configuration), None if it did not converge."""
        row = self.rows.get(case)
        if row is None or row["status"] != "converged":
            return None
        values = [row[c] for c in self.joint_names]
        model = self.runner.base.model
        q0 = self.runner.data["q0"]
        return q_from_row(model, self.runner.joints, values, q0)

    def frame(self, attrs: Mapping[str, Any]) -> DataFrame:
        pd = pandas()
        cases = sorted(self.rows)
        data: dict[str, Any] = {"case": np.array(cases, dtype=np.int64)}
        for name, values in self.plan.columns.items():
            column = [values[c] for c in cases]
            data[name] = np.array(column, dtype=np.int64 if name == "start" else float)
        for name in self.output_columns():
            column = [self.rows[c].get(name) for c in cases]
            if name == "steps":
                data[name] = pd.array(column, dtype="Int64")
            elif name == "jump":
                data[name] = pd.array(column, dtype="boolean")
            elif name in _TEXT_COLUMNS:
                data[name] = pd.array(column, dtype="string")
            else:
                data[name] = np.array(column, dtype=float)
        frame = pd.DataFrame(data)
        frame.attrs["pinsettle"] = dict(attrs)
        return frame

    def load(self, previous: DataFrame) -> None:
        """Take the rows of an earlier run of the same sweep (``resume``), after checking that
        its cases are this sweep's.

        Raises:
            ValueError: a missing column, a case number outside this sweep, or a case whose
                varied values differ from this sweep's.
        """
        cases = self._check_resumed(previous)
        columns = {name: previous[name].tolist() for name in self.output_columns()}
        na = pandas().NA
        for k, case in enumerate(cases):
            row = {name: _resumed_value(name, values[k], na) for name, values in columns.items()}
            if row.get("jump") is not None:
                row["jump"] = str(row["jump"]) in ("True", "true", "1")
            if row["steps"] is not None:
                row["steps"] = int(row["steps"])
            self.add([(int(case), row)])

    def _check_resumed(self, previous: DataFrame) -> np.ndarray:
        """The case numbers of ``previous``, once its columns and cases are checked to be this
        sweep's."""
        pd = pandas()
        if not isinstance(previous, pd.DataFrame):
            raise TypeError(f"resume must be a pandas.DataFrame, got {type(previous).__name__}")
        needed = ["case", *self.plan.columns, *self.output_columns()]
        missing = [c for c in needed if c not in previous.columns]
        if missing:
            raise ValueError(
                f"resume: the table is not of this sweep: it has no column {', '.join(missing)}"
            )
        cases: np.ndarray = previous["case"].to_numpy()
        twice = [
            int(c) for c, n in zip(*np.unique(cases, return_counts=True), strict=True) if n > 1
        ]
        if twice:
            raise ValueError(f"resume: case {twice[0]} is in the table twice")
        outside = [int(c) for c in cases if not 0 <= c < self.plan.size]
        if outside:
            raise ValueError(
                f"resume: the table is not of this sweep: case {outside[0]} is outside its "
                f"{self.plan.size} cases"
            )
        for name, values in self.plan.columns.items():
            given, planned = previous[name].to_numpy(), np.asarray(values)[cases]
            wrong = np.flatnonzero(given != planned)
            if wrong.size:
                k = wrong[0]
                raise ValueError(
                    f"resume: the table is not of this sweep: case {cases[k]} has {name} = "
                    f"{given[k]}, this sweep {planned[k]}"
                )
        return cases


#: The output columns of text: '' where a value is missing.
_TEXT_COLUMNS = ("status", "stability", "at_limit", "error")


def _resumed_value(name: str, value: Any, na: Any) -> Any:
    """A value of a resumed table as the runner gives it: text '' and steps or jump None where
    the file has none (None, ``na``: pandas.NA, or NaN)."""
    absent = value is None or value is na or (isinstance(value, float) and math.isnan(value))
    if name in _TEXT_COLUMNS:
        return "" if absent else str(value)
    if name in ("steps", "jump"):
        return None if absent else value
    return value


# --- progress -------------------------------------------------------------------------------------


Progress = Callable[[int, int], None]


class ProgressBar:
    """Cases done, rate and time left on one terminal line (stderr), redrawn at most 10 times a
    second; nothing when stderr is not a terminal."""

    def __init__(self, stream: Any = None) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.enabled = bool(getattr(self.stream, "isatty", lambda: False)())
        self.started = time.perf_counter()
        self.drawn = 0.0
        #: Cases done before this run (a resumed sweep): not counted in the rate.
        self.first = 0

    def __call__(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if done < total and now - self.drawn < 0.1:
            return
        self.drawn = now
        elapsed = max(now - self.started, 1e-9)
        rate = (done - self.first) / elapsed
        left = (total - done) / rate if rate > 0 else math.inf
        width = 30
        filled = int(width * done / max(total, 1))
        eta = "--:--" if not math.isfinite(left) else _clock(left)
        line = (
            f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} cases  "
            f"{rate:.1f}/s  {eta} left "
        )
        self.stream.write(line)
        if done >= total:
            self.stream.write("\n")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    hours, rest = divmod(seconds, 3600)
    return f"{hours}:{rest // 60:02d}:{rest % 60:02d}" if hours else f"{rest // 60}:{rest % 60:02d}"


# --- the public entry points ----------------------------------------------------------------------


def _as_scene(scene: Any) -> Scene:
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, pinocchio.Model):
        return Scene(scene)
    if isinstance(scene, (str, os.PathLike)):
        return load_scene(scene_path(scene))
    raise TypeError(
        "scene must be a pinsettle.Scene, a pinocchio.Model or a scene file (path or library "
        f"name), got {type(scene).__name__}"
    )


def _workers(workers: Any) -> int:
    if workers is None:
        return cpu_count()
    if not _is_count(workers, 1):
        raise ValueError(f"workers must be an integer >= 1 (threads), got {workers!r}")
    return int(workers)


@dataclass(frozen=True)
class _Where:
    """Where a sweep's cases run: ``threads`` local threads, or (``threads`` 0) a Dask cluster,
    by its client or its scheduler's address."""

    threads: int
    client: Any
    scheduler: str | None
    connect_timeout: float
    chunk_size: int | None

    @property
    def cluster(self) -> bool:
        return self.client is not None or self.scheduler is not None


def _where(
    workers: Any, client: Any, scheduler: Any, connect_timeout: float, chunk_size: Any
) -> _Where:
    """Where the cases run, the arguments that say it checked."""
    if client is not None and scheduler is not None:
        raise ValueError("give client= or scheduler=, not both")
    cluster = client is not None or scheduler is not None
    if cluster and workers is not None:
        raise ValueError(
            "workers= sets local threads; with client= or scheduler= the cluster's workers run "
            "the cases"
        )
    threads = 0 if cluster else _workers(workers)
    if chunk_size is not None and not _is_count(chunk_size, 1):
        raise ValueError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    return _Where(threads, client, scheduler, connect_timeout, chunk_size)


def _collect(
    table: Table, report: Progress, cases: int, rows: list[tuple[int, dict[str, Any]]]
) -> None:
    """Rows of solved cases into the table, and the progress told."""
    table.add(rows)
    report(len(table.rows), cases)


def _reporter(progress: bool | Progress) -> tuple[Progress, ProgressBar | None]:
    """The function told of the cases done, and the progress bar when it is that."""
    if progress is True:
        bar = ProgressBar()
        return bar, bar
    if callable(progress):
        return progress, None
    return (lambda done, total: None), None


def _run_cases(
    plan: Plan, table: Table, runner: Runner, where: _Where, collect: Collect, stop: Interrupts
) -> int:
    """Run the cases not yet in ``table``; the number of worker threads that ran them."""
    if not where.cluster:
        # Chunks of a few cases: fewer wake-ups of this thread; Ctrl-C still stops
        # between cases.
        chunk = where.chunk_size or min(16, max(1, plan.size // (8 * where.threads)))
        tasks = make_tasks(plan, table.rows, chunk, table.rest_of)
        run_local(runner, tasks, where.threads, collect, stop)
        return where.threads
    from . import _sweep_cluster

    with _sweep_cluster.connect(where.client, where.scheduler, where.connect_timeout) as client:
        threads = _sweep_cluster.total_threads(client)
        chunk = where.chunk_size or max(1, math.ceil(plan.size / (4 * threads)))
        tasks = make_tasks(plan, table.rows, chunk, table.rest_of)
        _sweep_cluster.run(client, runner, tasks, collect, stop)
    return threads


def sweep(  # noqa: PLR0913 (its keyword options are the sweep command's flags)
    scene: Any,
    vary: Mapping[str, Any] | None = None,
    starts: Any = None,
    *,
    zip: bool = False,
    continuation: bool | None = None,
    workers: int | None = None,
    client: Any = None,
    scheduler: str | None = None,
    progress: bool | Progress = True,
    settings: Settings | Mapping[str, Any] | None = None,
    limits: bool | None = None,
    resume: DataFrame | None = None,
    chunk_size: int | None = None,
    connect_timeout: float = 5.0,
    **overrides: Any,
) -> DataFrame:
    # #lizard forgives(length): the docstring is the sweep's reference, 49 of its 110 lines
    """Solve many cases of a scene and return a ``pandas.DataFrame``, one row per case.

    Args:
        scene: a ``pinsettle.Scene``, a ``pinocchio.Model`` or a scene file (path or library
            name).
        vary: scene value -> the values it takes: ``"start.JOINT"``, a field of a force element
            by its index (``"joint_spring[0].stiffness"``, ``"spring[1].rest_length"``,
            ``"load[0].effort"``, ``"load[2].force"``, ``"payload[0].mass"``), ``"gravity"``,
            or ``"payload.FRAME.mass"`` (kg: the [[payload]] on the frame, else a payload at
            the frame's origin). A vector value
            takes vectors, or numbers: a magnitude along the scene's own vector. Several keys
            make the full grid; ``zip=True`` pairs their values instead.
        starts: start configurations (n, model.nq), or ``("random", n, seed)``: uniform inside
            the joints' stops (+-pi where there are none). Every value of ``vary`` is solved
            from each start. None: the scene's start.
        continuation: each case starts from the previous case's rest (one branch per start), and
            the ``jump`` column marks where the rest left its branch (a fold, a snap-through).
            Default: on for a 1-D ``vary`` (one key, or ``zip=True``) without start keys.
        workers: local threads (default: every core); each solve runs in C++ with the GIL
            released. Results are identical, bit for bit, whatever the number.
        client: a ``dask.distributed.Client``: the cases go to its cluster in chunks (needs
            ``pinsettle[cluster]``); ``scheduler``: the address of a scheduler to connect to
            (``"tcp://host:8786"``, within ``connect_timeout`` seconds).
        progress: a progress bar on stderr when it is a terminal (True), none (False), or a
            function called with (cases done, cases) as they finish.
        settings, limits, **overrides: as for ``pinsettle.solve``, for every case.
        resume: the table of an earlier, interrupted run of the same sweep: its cases are kept,
            not solved again.
        chunk_size: cases per task (default: about four tasks per worker thread on a
            cluster, up to 16 cases locally).

    Returns:
        The table: ``case``; ``start`` and the start's joint values (``start.JOINT``) when
        ``starts`` is given; the varied values (one column per key; ``key[k]`` for vectors);
        ``status``; each free joint's value by name; ``residual``; ``stability``;
        ``min_stiffness_eigenvalue``; ``at_limit`` (joints on a stop, where the scene has
        stops); ``steps``; ``wall_time`` (s); ``jump`` (with continuation); ``error`` (why a
        case could not be solved, else empty). ``df.attrs["pinsettle"]`` holds the scene's name,
        the keys, the joints' kinds (for ``distinct_rests``), the workers, the sweep's wall time
        and whether it was interrupted (Ctrl-C: the cases in flight finish, the table holds
        the cases done).

    Raises:
        TypeError, ValueError: an unknown key, an index past the scene's elements, a value of
            the wrong type or size, no values, starts of the wrong shape, a bad setting (the
            message names it). A case whose value the scene refuses (a negative stiffness) is
            not an error of the sweep: its row has status 'error' and the reason.
        ConnectionError: ``scheduler`` does not answer, or the cluster has no worker.
        ImportError: pandas (``pinsettle[sweep]``) or dask (``pinsettle[cluster]``) missing.
    """
    pandas()  # missing pandas: say so before any work
    pair = zip
    base = _as_scene(scene)
    use = make_settings(base.settings if settings is None else settings, overrides)
    use.check()
    if limits is not None and not isinstance(limits, (bool, np.bool_)):
        raise TypeError(f"limits must be True, False or None, got {limits!r}")
    if not (callable(progress) or isinstance(progress, bool)):
        raise TypeError(f"progress must be True, False or a function, got {progress!r}")
    where = _where(workers, client, scheduler, connect_timeout, chunk_size)
    plan = make_plan(base, vary, starts, pair, continuation, limits)
    runner = Runner(scene_data(base), plan.keys, use.to_dict(), limits, plan.continuation)
    table = Table(plan, runner)
    if resume is not None:
        table.load(resume)
    report, bar = _reporter(progress)
    collect = functools.partial(_collect, table, report, plan.size)
    started = time.perf_counter()
    resumed = len(table.rows)
    if bar is not None:
        bar.first = resumed
    with Interrupts() as stop:
        threads = _run_cases(plan, table, runner, where, collect, stop)
    if bar is not None and stop.count > 0:
        bar.close()
    attrs = {
        "scene": base.name,
        "vary": [key.text for key in plan.keys],
        "zip": bool(pair),
        "continuation": plan.continuation,
        "joints": [dataclasses.asdict(joint) for joint in runner.joints],
        "rest_tolerance": REST_TOLERANCE,
        "cases": plan.size,
        "solved": len(table.rows) - resumed,
        "resumed": resumed,
        "interrupted": stop.count > 0,
        "workers": threads,
        "cluster": where.cluster,
        "wall_time": time.perf_counter() - started,
    }
    return table.frame(attrs)


def _table_joints(df: DataFrame, scene: Scene | None) -> list[JointColumns]:
    """The joints of a sweep's table: from ``scene`` (a joint's columns renamed where the table
    has them so), else from ``df.attrs``."""
    meta = df.attrs.get("pinsettle", {})
    if scene is not None:
        return [
            j if all(c in df.columns for c in j.columns) else renamed
            for j, renamed in zip(
                joint_columns(scene), joint_columns(scene, list(scene.model.names)), strict=True
            )
        ]
    if "joints" in meta:
        return [JointColumns(j["name"], j["kind"], tuple(j["columns"])) for j in meta["joints"]]
    raise ValueError(
        "df has no record of its joints (df.attrs['pinsettle'], which a CSV file does not "
        "keep): pass the scene, distinct_rests(df, scene=...)"
    )


def _is_varied(column: str, needed: list[str]) -> bool:
    """Whether a column of a sweep's table holds a varied scene value (not a start's)."""
    if column in needed or column in OUTPUT_COLUMNS or column == "start":
        return False
    return not column.startswith("start.") and column not in (
        "min_stiffness_eigenvalue",
        "residual",
    )


def _group_rests(
    group: DataFrame, joints: list[JointColumns], names: list[str], tol: float
) -> list[dict[str, Any]]:
    """The distinct rests of one group's converged cases, each joined by the later cases
    closer to it than ``tol``, in case order."""
    rests: list[dict[str, Any]] = []
    points: list[np.ndarray] = []
    for _, row in group.sort_values("case").iterrows():
        if row["status"] != "converged":
            continue
        point = row[names].to_numpy(dtype=float)
        near = next(
            (k for k, other in enumerate(points) if rest_distance(joints, point, other) < tol), None
        )
        if near is not None:
            rests[near]["count"] += 1
            continue
        points.append(point)
        rests.append(
            {
                "rest": len(rests),
                **dict(zip(names, point, strict=True)),
                "stability": row["stability"],
                "count": 1,
                "first_case": int(row["case"]),
            }
        )
    for rest in rests:
        rest["fraction"] = rest["count"] / len(group)
    return rests


def _groups(df: DataFrame, varied: list[str]) -> list[tuple[dict[str, Any], DataFrame]]:
    """The rows of a table grouped by their varied values (one group when nothing varies),
    each with its values by column."""
    if not varied:
        return [({}, df)]
    out = []
    for values, group in df.groupby(varied, sort=False, dropna=False):
        values = values if isinstance(values, tuple) else (values,)
        out.append((dict(zip(varied, values, strict=True)), group))
    return out


def distinct_rests(
    df: DataFrame, *, tol: float = REST_TOLERANCE, scene: Scene | None = None
) -> DataFrame:
    """The distinct rests of a sweep and the fraction of its cases that reached each: the
    basins of a multistable mechanism.

    Converged rows are grouped by the varied scene values (starts aside), then, within a
    group, a rest joins the first rest found closer than ``tol`` (rad or m: the largest
    difference of a joint, angles modulo 2 pi, rotations by their angle), in case order.

    Args:
        df: a table of ``pinsettle.sweep``. Its joints' kinds come from ``df.attrs`` (kept by
            Parquet), or from ``scene`` (a table read back from CSV).

    Returns:
        One row per rest: the group's varied values, ``rest`` (0, 1, ... within the group),
        the joint values of its first case, ``stability``, ``count`` (cases that reached it),
        ``fraction`` (of the group's cases, failed ones included) and ``first_case``.
    """
    pd = pandas()
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"df must be a pandas.DataFrame, got {type(df).__name__}")
    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not tol > 0:
        raise ValueError(f"tol must be a number > 0 (rad or m), got {tol!r}")
    joints = _table_joints(df, scene)
    names = [c for joint in joints for c in joint.columns]
    needed = ["case", "status", "stability", *names]
    missing = [c for c in needed if c not in df.columns]
    if missing:
        raise ValueError(f"df is not a sweep table: no column {', '.join(missing)}")
    varied = [c for c in df.columns if _is_varied(c, needed)]
    out = [
        {**at, **rest}
        for at, group in _groups(df, varied)
        for rest in _group_rests(group, joints, names, tol)
    ]
    columns = [*varied, "rest", *names, "stability", "count", "fraction", "first_case"]
    return pd.DataFrame(out, columns=columns)

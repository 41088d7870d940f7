"""Sweeps on a Dask cluster: the cases go to the workers in chunks, the scene as data.

The scene travels as a pickle of plain data (``_sweep_cases.scene_data``: the
``pinocchio.Model``, which pickles, and the element lists), sent to the workers once, as the
result of a task the sweep's tasks depend on (computed again if the workers holding it die); a
worker rebuilds the scene once per sweep and runs its tasks with the same code as the local
threads (``_sweep_cases.Runner``), so the rows are the same. A worker needs only pinsettle
installed.

Dask re-runs the tasks of a worker that dies elsewhere; a task that killed its workers too
often (Dask's ``KilledWorker``) or failed otherwise has its cases marked 'error' with the
reason. Each task's rows are taken once, from its one result.
"""

from __future__ import annotations

import asyncio
import hashlib
import importlib
import pickle
import re
import socket
import threading
import time
from collections import OrderedDict
from collections.abc import Iterator, Sequence
from concurrent.futures import CancelledError
from contextlib import contextmanager
from typing import Any

from ._sweep_cases import Collect, Interrupts, MissingDependencyError, Runner, Task

CLUSTER_EXTRA = "pip install 'pinsettle[cluster]'"

#: How long a cluster may be left without any worker before the cases still to run are marked
#: (Dask would wait for a worker forever).
NO_WORKER_TIMEOUT = 20.0
#: How long to wait for a finished task's rows (longer: its worker left with them).
GATHER_TIMEOUT = 2.0
#: How many times a task the cluster cancels by itself (a worker died around it) is sent again.
RESUBMITS = 3

_ADDRESS = re.compile(r"^(?:(?P<scheme>[a-z]+)://)?(?P<host>\[[^\]]+\]|[^:/\[\]]+):(?P<port>\d+)$")


def _distributed() -> Any:
    try:
        return importlib.import_module("distributed")
    except ImportError:
        raise MissingDependencyError(
            f"a sweep on a Dask cluster needs dask.distributed: {CLUSTER_EXTRA}"
        ) from None


class CaseError(RuntimeError):
    """Why the cluster could not run a case (its row's ``error``)."""

    def __str__(self) -> str:
        return str(self.args[0])


def check_address(address: Any) -> tuple[str, str | None, str, int]:
    """The scheduler address as (address, scheme or None, host, port).

    Raises:
        TypeError, ValueError: not a string, or not of the form [tcp://]HOST:PORT.
    """
    if not isinstance(address, str):
        raise TypeError(
            f"scheduler must be an address string like 'tcp://host:8786', got "
            f"{type(address).__name__} {address!r}"
        )
    match = _ADDRESS.match(address.strip())
    port = int(match.group("port")) if match else 0
    if match is None or not 0 < port < 65536:
        raise ValueError(
            f"scheduler address '{address}': expected tcp://HOST:PORT (e.g. tcp://127.0.0.1:8786)"
        )
    return address.strip(), match.group("scheme"), match.group("host").strip("[]"), port


def _probe(host: str, port: int, timeout: float, address: str) -> None:
    """Fail fast, without a Dask client, when nothing listens at the address or what listens
    does not speak first as a Dask scheduler does (its handshake; a Dask client would wait for
    it for ever)."""
    deadline = time.monotonic() + timeout
    try:
        with socket.create_connection((host, port), timeout=timeout) as probe:
            probe.settimeout(max(0.05, deadline - time.monotonic()))
            first = probe.recv(1)
    except OSError as error:
        reason = "timed out" if isinstance(error, TimeoutError) else str(error)
        raise ConnectionError(
            f"scheduler {address} does not answer ({reason}, waited at most {timeout:g} s)"
        ) from None
    if not first:
        raise ConnectionError(
            f"scheduler {address} does not answer (it closed the connection at once)"
        )


@contextmanager
def connect(client: Any, scheduler: str | None, timeout: float) -> Iterator[Any]:
    """The client to run on: ``client`` as given, or a new one connected to ``scheduler``
    (closed afterwards). Either must have at least one worker within ``timeout`` seconds.

    Raises:
        ConnectionError: the scheduler does not answer, or has no worker.
    """
    distributed = _distributed()
    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not timeout > 0:
        raise ValueError(f"connect_timeout must be a number of seconds > 0, got {timeout!r}")
    if client is not None:
        if not isinstance(client, distributed.Client):
            raise TypeError(
                f"client must be a dask.distributed.Client, got {type(client).__name__}"
            )
        if client.status != "running":
            raise ConnectionError(f"the Dask client is not connected (status '{client.status}')")
        _wait_for_workers(client, timeout, "the client's cluster")
        yield client
        return
    address, scheme, host, port = check_address(scheduler)
    if scheme in (None, "tcp"):
        _probe(host, port, timeout, address)
    try:
        own = distributed.Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as error:
        raise ConnectionError(f"scheduler {address} does not answer: {error}") from None
    try:
        _wait_for_workers(own, timeout, f"the scheduler at {address}")
        yield own
    finally:
        own.close()


def _wait_for_workers(client: Any, timeout: float, what: str) -> None:
    try:
        client.wait_for_workers(1, timeout=timeout)
    except (TimeoutError, OSError):
        raise ConnectionError(f"{what} has no worker (waited {timeout:g} s)") from None


def total_threads(client: Any) -> int:
    """Worker threads of the cluster now."""
    return max(1, int(sum(client.nthreads().values())))


# --- on a worker ----------------------------------------------------------------------------------

_RUNNERS: OrderedDict[str, Runner] = OrderedDict()
_RUNNERS_LOCK = threading.Lock()


def _runner(blob: bytes) -> Runner:
    """The runner of a sweep, built once per worker process (a few sweeps kept)."""
    token = hashlib.sha256(blob).hexdigest()
    with _RUNNERS_LOCK:
        runner = _RUNNERS.get(token)
        if runner is None:
            spec = pickle.loads(blob)
            runner = Runner(
                spec["data"], spec["keys"], spec["settings"], spec["limits"], spec["continuation"]
            )
            _RUNNERS[token] = runner
            while len(_RUNNERS) > 4:
                _RUNNERS.popitem(last=False)
        return runner


def _scene(blob: bytes) -> bytes:
    """The scene's data, held by the workers as a task's result."""
    return blob


def remote_run(blob: bytes, task: Task) -> list[tuple[int, dict[str, Any]]]:
    """A task's rows, computed on a worker."""
    return _runner(blob).run(task)


# --- on the client --------------------------------------------------------------------------------


def _blob(runner: Runner) -> bytes:
    return pickle.dumps(
        {
            "data": runner.data,
            "keys": runner.keys,
            "settings": runner.settings.to_dict(),
            "limits": runner.limits,
            "continuation": runner.continuation,
        },
        protocol=pickle.HIGHEST_PROTOCOL,
    )


def _failed(runner: Runner, task: Task, reason: str) -> list[tuple[int, dict[str, Any]]]:
    rows = []
    for spec in task.specs:
        row = runner.outputs(CaseError(reason))
        if runner.continuation:
            row["jump"] = None
        rows.append((spec.case, row))
    return rows


def _reason(error: BaseException) -> str:
    if type(error).__name__ == "KilledWorker":
        return f"the workers running this case died (Dask gave up on it: {error})"
    return f"the cluster could not run this case: {type(error).__name__}: {error}"


class _Sent:
    """The tasks of one sweep on the cluster: sent (again when the cluster drops one), each
    task's rows taken once."""

    def __init__(self, client: Any, runner: Runner, tasks: Sequence[Task]) -> None:
        self.client = client
        self.runner = runner
        self.tasks = tasks
        self.blob = _blob(runner)
        self.token = hashlib.sha256(self.blob).hexdigest()[:12]
        # The scene as the result of a task, not scattered data: if every worker holding it
        # dies, the scheduler computes it again (scattered data would be lost, and the tasks
        # with it).
        self.shared = client.submit(
            _scene, self.blob, pure=False, key=f"pinsettle-scene-{self.token}"
        )
        self.tries = [0] * len(tasks)
        #: The futures of the tasks not yet taken, and their tasks' indices.
        self.pending: dict[Any, int] = {}

    def submit(self, k: int) -> None:
        """Send task ``k`` (again, after a try that the cluster dropped)."""
        tries, token = self.tries[k], self.token
        if self.shared.status == "cancelled":  # the scene itself was dropped: send it again
            self.shared = self.client.submit(
                _scene, self.blob, pure=False, key=f"pinsettle-scene-{token}-{tries}-{k}"
            )
        key = f"pinsettle-sweep-{token}-{k}" + (f"-try{tries}" if tries else "")
        future = self.client.submit(remote_run, self.shared, self.tasks[k], pure=False, key=key)
        self.pending[future] = k

    def take_done(self, collect: Collect) -> None:
        """Give the rows of each task that ended to ``collect``."""
        for future in list(self.pending):
            # One reading of the status: it changes under us as the cluster reports.
            # 'lost' (its worker died with the result) is not an end: Dask runs it again.
            status = future.status
            if status not in ("finished", "error", "cancelled") or not future.done():
                continue
            k = self.pending.pop(future)
            rows = self._rows(future, status, k)
            if rows is not None:
                collect(rows)

    def _rows(self, future: Any, status: str, k: int) -> list[tuple[int, dict[str, Any]]] | None:
        """The rows of task ``k`` that ended with ``status``, or None: it runs again."""
        try:
            if status == "finished":
                rows: list[tuple[int, dict[str, Any]]] = future.result(timeout=GATHER_TIMEOUT)
                return rows
            if status == "error":
                reason = _reason(future.exception(timeout=GATHER_TIMEOUT))
                return _failed(self.runner, self.tasks[k], reason)
            raise CancelledError
        except TimeoutError:  # its worker left with the result: Dask runs it again
            self.pending[future] = k
            return None
        except (CancelledError, asyncio.CancelledError):
            # Dropped by the cluster (a worker died around it), not by us: again.
            if self.tries[k] < RESUBMITS:
                self.tries[k] += 1
                self.submit(k)
                return None
            reason = f"the cluster dropped this case ({self.tries[k] + 1} times, cancelled)"
            return _failed(self.runner, self.tasks[k], reason)

    def fail_pending(self, collect: Collect, reason: str) -> None:
        """Give up on the tasks not taken: their cases' rows say ``reason``."""
        for k in self.pending.values():
            collect(_failed(self.runner, self.tasks[k], reason))
        self.pending.clear()

    def cancel(self) -> None:
        """Cancel the tasks not taken, and the scene's."""
        if self.pending:
            self.client.cancel(list(self.pending))
        self.client.cancel([self.shared])


class _NoWorker:
    """Whether the cluster has had no worker for over ``NO_WORKER_TIMEOUT``, looked at once a
    second at most."""

    def __init__(self, client: Any) -> None:
        self.client = client
        self.since: float | None = None
        self.checked = time.monotonic()

    def too_long(self) -> bool:
        now = time.monotonic()
        if now - self.checked < 1.0:
            return False
        self.checked = now
        if self.client.nthreads():
            self.since = None
        elif self.since is None:
            self.since = now
        return self.since is not None and now - self.since > NO_WORKER_TIMEOUT


def run(
    client: Any, runner: Runner, tasks: Sequence[Task], collect: Collect, stop: Interrupts
) -> None:
    """Run the tasks on the cluster, giving each task's rows to ``collect`` once. Ctrl-C
    (``stop.count``) cancels the tasks not finished; their cases are left out."""
    if not tasks:
        return
    sent = _Sent(client, runner, tasks)
    for k in range(len(tasks)):
        sent.submit(k)
    no_worker = _NoWorker(client)
    try:
        while sent.pending:
            if stop.count:
                return
            sent.take_done(collect)
            time.sleep(0.02)
            if no_worker.too_long():
                sent.fail_pending(collect, "no worker left on the cluster")
    finally:
        sent.cancel()

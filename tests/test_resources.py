"""Resource bounds: memory stays flat over 10,000 solves, a model too large for Pinocchio's Data
is refused before it takes memory while a large one is solved within its ``max_time``, and
solves from 8 threads on shared models give the serial answers bit for bit.

Memory is measured three ways after a warm-up, each with a bound that a leak per solve breaks
(checked on deliberate leaks): the C heap in use (glibc's ``mallinfo2``: what malloc has
handed out and not had back, exact to the byte: one malloc(1) kept per solve breaks it, where
the resident size would not move if the heap already had the pages), Python's allocated blocks
(``sys.getallocatedblocks``: one Python object kept per solve breaks it) and the resident set
size (``/proc/self/statm``: memory mapped outside malloc, one page per solve breaks it).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import json
import mmap
import os
import subprocess
import sys
import textwrap
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pinsettle
import pytest

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
SOLVES = 10_000
WARM_UP = 300
# Bounds on the growth over SOLVES solves. A leak of one malloc(1) per solve costs a 32-byte
# chunk each, 320,000 bytes; one Python object per solve 10,000 blocks.
HEAP_BOUND = 64 * 1024
BLOCKS_BOUND = 1_000
RSS_BOUND = 256 * 1024


class _MallInfo2(ctypes.Structure):
    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost"
        ).split()
    ]


def _libc() -> ctypes.CDLL:
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    if not hasattr(libc, "mallinfo2"):
        pytest.fail("glibc >= 2.33 (mallinfo2) is needed to measure the heap in use")
    libc.mallinfo2.restype = _MallInfo2
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    return libc


def _heap_in_use(libc: ctypes.CDLL) -> int:
    """Bytes malloc has handed out and not had back (all arenas, mmapped chunks included)."""
    info = libc.mallinfo2()
    return int(info.uordblks + info.hblkhd)


def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _growth(libc: ctypes.CDLL, run: Callable[[int], None], count: int) -> dict[str, int]:
    """Growth of the three measures over run(count) (after a warm-up of WARM_UP)."""
    run(WARM_UP)
    gc.collect()
    before = (_heap_in_use(libc), sys.getallocatedblocks(), _rss())
    run(count)
    gc.collect()
    after = (_heap_in_use(libc), sys.getallocatedblocks(), _rss())
    names = ("heap", "blocks", "rss")
    return {name: a - b for name, a, b in zip(names, after, before, strict=True)}


@pytest.fixture(scope="module")
def libc() -> ctypes.CDLL:
    if os.environ.get("LD_PRELOAD"):
        pytest.fail("an allocator is preloaded (a sanitizer?): the heap measures are glibc's")
    return _libc()


def test_the_measures_see_a_leak_of_one_small_allocation_per_solve(libc):
    """The bounds below are only as good as the measures: SOLVES leaked malloc(1) and SOLVES
    kept Python objects must break them."""
    leaked: list[int] = []
    growth = _growth(libc, lambda n: leaked.extend(libc.malloc(1) for _ in range(n)), SOLVES)
    assert growth["heap"] > HEAP_BOUND, growth
    kept: list[object] = []
    growth = _growth(libc, lambda n: kept.extend(object() for _ in range(n)), SOLVES)
    assert growth["blocks"] > BLOCKS_BOUND, growth
    # Pages mapped outside malloc (what the resident size is for: a small leak through malloc
    # can land in resident pages the heap already had, which only the heap measure sees).
    maps: list[mmap.mmap] = []

    def map_pages(n: int) -> None:
        for _ in range(n):
            page = mmap.mmap(-1, mmap.PAGESIZE)
            page[0] = 1  # touched: resident
            maps.append(page)

    growth = _growth(libc, map_pages, SOLVES)
    assert growth["rss"] > RSS_BOUND, growth
    for block in leaked:
        libc.free(ctypes.c_void_p(block))


def _solves(scene: pinsettle.Scene, check: Callable[[pinsettle.Result], None], **settings):
    calls = {"n": 0}

    def callback() -> bool:
        calls["n"] += 1
        return False

    def run(n: int) -> None:
        for _ in range(n):
            result = pinsettle.solve(scene, callback=callback, **settings)
            check(result)

    return run, calls


@pytest.mark.parametrize(
    "name, loops, takeover",
    [("pendulum", 0, False), ("slider_crank", 1, False), ("slider_crank", 1, True)],
    ids=["tree", "loop", "loop_newton_takeover"],
)
def test_memory_flat_over_10000_solves_with_tracing(libc, name, loops, takeover):
    scene = pinsettle.load_scene(ROBOTS / f"{name}.toml")
    # The callback polled every 20 steps (check_every also paces the step's re-estimates: the
    # same for every solve here); a stopping window of 100 steps, so that a solve is long,
    # unless Newton takes over at a damping event (its own memory checked in the third case).
    settings = {
        "trace_every": 1,
        "trace_configurations": True,
        "check_every": 20,
        "ds": 100,
        "newton_takeover": takeover,
    }
    first = pinsettle.solve(scene, **settings)
    assert first.converged and first.loops == loops and first.trace is not None
    if takeover:  # ended by Newton, sooner than the damping alone
        damped = pinsettle.solve(scene, **{**settings, "newton_takeover": False})
        assert first.steps < damped.steps and first.polish_iterations > 0
    else:
        assert first.steps >= 100 and len(first.trace.step) > 100

    def same_as_first(result: pinsettle.Result) -> None:
        # Each solve does the whole work: its trace of every step, with configurations.
        assert result.status == "converged" and result.steps == first.steps
        assert result.trace is not None and result.trace.q is not None
        assert result.trace.q.shape == (len(first.trace.step), scene.model.nq)

    run, calls = _solves(scene, same_as_first, **settings)
    growth = _growth(libc, run, SOLVES)
    # in every solve: polled at steps 20, 40, ... before the last
    assert calls["n"] >= (WARM_UP + SOLVES) * ((first.steps - 1) // 20)
    print(f"{name}: growth over {SOLVES} solves {growth}")
    assert growth["heap"] < HEAP_BOUND, growth
    assert growth["blocks"] < BLOCKS_BOUND, growth
    assert growth["rss"] < RSS_BOUND, growth


# A child that loads a chain of N links (robots/make_chain.py) and reports what solving it did,
# under an address-space limit: a model that slips past the check then fails to allocate rather
# than taking the machine's memory.
CHAIN_CHILD = textwrap.dedent(
    """
    import json, resource, sys, time
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
    sys.path.insert(0, sys.argv[1])
    from make_chain import chain_urdf
    import numpy as np, pinocchio, pinsettle
    n, max_time = int(sys.argv[2]), float(sys.argv[3])
    model = pinocchio.buildModelFromXML(chain_urdf(n))
    q0 = np.zeros(model.nq)
    q0[0] = 1.0

    class Memory:  # what solver_memory says, as a status
        def __init__(self, need):
            self.status = need

    def resident():
        return int(open("/proc/self/statm").read().split()[1]) * resource.getpagesize()

    class Made:  # a Solver made (its resident memory measured), then one solve
        def __init__(self):
            before = resident()
            solver = pinsettle.Solver(model, max_time=max_time, limits=False)
            self.resident_growth = resident() - before
            r = solver.solve(q0)
            self.status, self.wall_time, self.residual = r.status, r.wall_time, r.residual

    calls = {
        "solve": lambda: pinsettle.solve(model, q0, max_time=max_time, limits=False),
        "scene": lambda: pinsettle.solve(pinsettle.Scene(model), max_time=max_time),
        "static_force": lambda: pinsettle.static_force(model, q0),
        "assess_stability": lambda: pinsettle.assess_stability(model, q0),
        "memory": lambda: Memory(pinsettle.solver_memory(model)),
        "solver": Made,
    }
    out = {}
    for name in sys.argv[4:]:
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        try:
            r = calls[name]()
            out[name] = {"status": getattr(r, "status", "ok"),
                         "wall_time": getattr(r, "wall_time", 0.0),
                         "residual": getattr(r, "residual", 0.0),
                         "resident_growth": getattr(r, "resident_growth", 0)}
        except Exception as e:
            out[name] = {"error": type(e).__name__, "message": str(e)}
        out[name]["peak_growth"] = (
            resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss) * 1024
    print(json.dumps(out))
    """
)


def _chain(n: int, max_time: float, *calls: str) -> dict:
    proc = subprocess.run(
        [sys.executable, "-c", CHAIN_CHILD, str(ROBOTS), str(n), str(max_time), *calls],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.splitlines()[-1])


def _data_bytes(links: int) -> int:
    """One Data of a chain: Pinocchio's four nv^3 tensors, about 30 nv x nv matrices and the
    joints' blocks, as pinsettle.solver_memory counts them (the resident memory a solver adds is
    checked against it)."""
    return 8 * (4 * links**3 + 30 * links**2) + 8192 * (links + 1)


def _available_memory() -> int:
    """MemAvailable of /proc/meminfo (bytes), as the solver reads it."""
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no MemAvailable in /proc/meminfo")


def test_a_1000_link_chain_is_refused_before_it_takes_memory():
    """Pinocchio 4.1's Data holds four nv^3 tensors (32 GB for nv = 1000): where the machine
    has less memory available, refused up front, by every entry point, with a message that
    says how much it needs and how much there is."""
    need = _data_bytes(1000)
    assert _available_memory() < need, "this machine could make the Data: test elsewhere"
    out = _chain(1000, 5.0, "memory", "solve", "scene", "static_force", "assess_stability")
    assert out["memory"]["status"] == need, out["memory"]
    for name, what in out.items():
        if name == "memory":
            continue
        assert what.get("error") == "MemoryLimitError", (name, what)
        message = what["message"]
        assert "model.nv = 1000" in message and "pinocchio.Data of 32.2 GB" in message, message
        assert "GB are available" in message, message
        # Refused before any Data was made: no more than a few MB more at the peak.
        assert what["peak_growth"] < 32 << 20, (name, what)


def test_a_chain_past_the_old_fixed_limit_is_solved_where_it_fits():
    """330 links, past the 322 the solver once refused whatever the machine: its Data (1.15 GB)
    fits here, so the solver is made and runs; the resident memory it adds is what
    pinsettle.solver_memory says, within 5 %."""
    out = _chain(330, 0.5, "memory", "solver")
    need = out["memory"]["status"]
    assert need == _data_bytes(330), need
    made = out["solver"]
    assert "error" not in made, made
    assert abs(made["resident_growth"] - need) < 0.05 * need, (made, need)
    assert made["status"] in ("converged", "time_limit"), made


def test_a_1000_link_chain_file_is_refused_by_the_cli_with_one_line(tmp_path, chain_urdf):
    path = tmp_path / "chain1000.urdf"
    path.write_text(chain_urdf(1000))
    proc = subprocess.run(
        [sys.executable, "-m", "pinsettle", "solve", str(path), "--max-time", "5"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "nv = 1000" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr


def test_a_large_chain_is_solved_within_max_time_with_memory_in_proportion():
    """150 links (Data: 32 nv^3 = 108 MB): the run stops at its max_time (or converges), and
    its peak memory is that of a few Data, not more."""
    n, max_time = 150, 1.0
    out = _chain(n, max_time, "solve")["solve"]
    assert "error" not in out, out
    assert out["status"] in ("converged", "time_limit"), out
    # The run's own clock: it stops at the first check past max_time (not a speed claim).
    assert out["wall_time"] < 2 * max_time, out
    data_bytes = 32 * n**3
    assert out["peak_growth"] < 3 * data_bytes + (64 << 20), out


# Threads on shared models: a pinocchio.Model and scenes read by every thread at once (the C++
# loop runs without the GIL).
THREADS = 8
ROUNDS = 3


def _fingerprint(result: pinsettle.Result) -> tuple:
    """Everything a solve returns except its wall time, as bytes where it is a number."""

    def raw(x: object) -> bytes:
        return np.asarray(x, dtype=float).tobytes()

    trace = result.trace
    return (
        result.status,
        result.steps,
        result.peaks,
        result.pushes,
        result.stability,
        result.neutral_directions,
        result.dt_estimates,
        result.dt_reductions,
        result.scaled_modes,
        raw(result.q),
        raw(result.v),
        raw(
            [
                result.residual,
                result.dt,
                result.sim_time,
                result.kinetic_energy,
                result.simplified_kinetic_energy,
                result.min_stiffness_eigenvalue,
                result.constraint_error,
            ]
        ),
        None
        if trace is None
        else (raw(trace.step), raw(trace.time), raw(trace.kinetic_energy), raw(trace.q)),
        tuple(sorted(result.at_limit.items())),
        raw(sorted(result.limit_reactions.values())),
    )


@pytest.fixture(scope="module")
def shared_cases(ur5) -> list[Callable[..., pinsettle.Result]]:
    """Solves of shared models: a pinocchio.Model from three starts and four scenes (a tree
    with tracing, a loop, force elements, a robot with a spring), each a function taking an
    optional callback."""
    rng = np.random.default_rng(19)
    starts = [rng.uniform(-1.0, 1.0, ur5.nq) for _ in range(3)]
    scenes = {
        name: pinsettle.load_scene(ROBOTS / f"{name}.toml")
        for name in ("pendulum", "fourbar", "double_pendulum_springs", "ur5_tool_spring")
    }
    # Never stopped by the clock (the answers must not depend on the load); the callback is
    # polled every 10 steps.
    settings = {"max_time": 600.0, "check_every": 10}
    cases: list[Callable[..., pinsettle.Result]] = [
        lambda callback=None, q=q: pinsettle.solve(ur5, q, callback=callback, **settings)
        for q in starts
    ]
    cases += [
        lambda callback=None, s=s: pinsettle.solve(
            s, callback=callback, trace_every=7, trace_configurations=True, **settings
        )
        for s in scenes.values()
    ]
    return cases


def test_threads_give_the_serial_answers_bit_for_bit(shared_cases):
    serial = [_fingerprint(case()) for case in shared_cases]
    assert all(f[0] == "converged" for f in serial), [f[0] for f in serial]
    results: dict[tuple[int, int, int], tuple] = {}
    errors: list[BaseException] = []
    # Every thread's first solve waits here from its first callback, inside the solver, until
    # all are: THREADS solves in progress at once (a timeout fails the test).
    rendezvous = threading.Barrier(THREADS, timeout=120)

    def work(t: int) -> None:
        try:
            met = threading.Event()

            def meet() -> bool:
                if not met.is_set():
                    met.set()
                    rendezvous.wait()
                return False

            for r in range(ROUNDS):
                # Each thread in its own order, so different cases run side by side.
                order = np.random.default_rng(100 * t + r).permutation(len(shared_cases))
                for k in order:
                    result = shared_cases[k](meet if r == 0 else None)
                    results[t, r, int(k)] = _fingerprint(result)
            assert met.is_set()
        except BaseException as e:  # reported below, not lost in the thread
            errors.append(e)

    threads = [threading.Thread(target=work, args=(t,)) for t in range(THREADS)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors, errors
    assert len(results) == THREADS * ROUNDS * len(shared_cases)
    for (t, r, k), fingerprint in results.items():
        assert fingerprint == serial[k], f"thread {t}, round {r}, case {k} differs"

"""The timeline of a playback: which poses are shown when, and when events flash."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, overload

import numpy as np

from ._solve import Result

#: A settle longer than this (simulated seconds) is sped up to play in about this long.
PLAYBACK_SECONDS = 6.0
#: A settle shorter than this (simulated seconds) is slowed down to play in this long: a
#: four-bar settles in 0.18 s, a handful of frames in real time, seen as a jump.
MIN_PLAYBACK_SECONDS = 3.0
#: Keyframes per second of playback (at most; fewer when the trace has fewer samples).
FPS = 30
#: A damping event flashes for this long (s of playback).
FLASH_SECONDS = 0.25


#: The kinds of velocity change a trace records (``Trace.event_kind``), in display order.
EVENT_KINDS = ("damping", "push", "rollback", "impact")


@overload
def check_speed(speed: None) -> None: ...
@overload
def check_speed(speed: float) -> float: ...
@overload
def check_speed(speed: object) -> float | None: ...


def check_speed(speed: Any) -> float | None:
    """``speed`` (simulated seconds per second of playback) checked: None (automatic) or a
    positive finite number."""
    if speed is None:
        return None
    if isinstance(speed, (bool, np.bool_)) or not isinstance(speed, (int, float, np.number)):
        raise TypeError(
            "speed must be a positive number (simulated seconds per second of playback) or "
            f"None, got {type(speed).__name__} {speed!r}"
        )
    value = float(speed)
    if not math.isfinite(value) or value <= 0:
        raise ValueError(
            "speed must be a positive finite number (simulated seconds per second of "
            f"playback), got {value}"
        )
    return value


def auto_speed(sim_time: float) -> float:
    """Real time; faster for a settle longer than ``PLAYBACK_SECONDS`` (it plays in that
    long), slower for one shorter than ``MIN_PLAYBACK_SECONDS`` (it plays in that long)."""
    if not math.isfinite(sim_time) or sim_time <= 0:
        return 1.0
    if sim_time < MIN_PLAYBACK_SECONDS:
        return sim_time / MIN_PLAYBACK_SECONDS
    return max(1.0, sim_time / PLAYBACK_SECONDS)


def speed_label(speed: float) -> str:
    """How the page and the command line say the speed: the factor, and what it means."""
    if math.isclose(speed, 1.0, rel_tol=1e-9):
        return "x1 (real time)"
    kind = "slow motion" if speed < 1 else "sped up"
    return f"x{speed:.3g} ({kind})"


@dataclass(frozen=True)
class Timeline:
    """What the animation shows: keyframe times (s of playback) and configurations (the last
    is the final pose, which the viewer then keeps), the event times (s of playback) by kind
    (sorted), the speed and the length of the motion (s of playback). ``impact_joints`` gives
    the joint (index in the scene's model) of each of ``events['impact']``. The viewer's clips
    run in simulated time (``clip_fps`` keyframes a simulated second, played at ``speed``),
    so that its time slider reads simulated seconds."""

    times: np.ndarray
    q: np.ndarray
    speed: float
    duration: float
    sim_time: float
    events: dict[str, np.ndarray]
    impact_joints: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def end(self) -> float:
        """Length of the whole animation (s of playback): ``duration``, or one frame for a
        run that did not move."""
        return float(self.times[-1])

    @property
    def clip_fps(self) -> float:
        """Keyframes (at ``FPS`` a second of playback) per simulated second: the viewer's
        clips are in simulated time."""
        return FPS / self.speed

    def frame_times(self) -> np.ndarray:
        """A uniform grid at ``FPS`` over the whole animation (for the event flashes)."""
        n = int(math.ceil(self.end * FPS)) + 1
        return np.minimum(np.arange(n) / FPS, self.end)


def _trace_of(result: Result, nq: int) -> Any:
    if not isinstance(result, Result):
        raise TypeError(f"result must be a pinsettle.Result, got {type(result).__name__}")
    trace = result.trace
    if trace is None or trace.q is None:
        raise ValueError(
            "result has no recorded configurations to play: solve with trace_every=1 and "
            "trace_configurations=True (pinsettle.solve(scene, **pinsettle.play.TRACE_SETTINGS)),"
            " or call play(scene) without a result to solve with them"
        )
    if trace.q.ndim != 2 or trace.q.shape[1] != nq or result.q.shape != (nq,):
        raise ValueError(
            f"result does not belong to this scene: its configurations have "
            f"{trace.q.shape[-1]} entries, the scene's model has nq = {nq}"
        )
    return trace


def make_timeline(result: Result, nq: int, speed: float | None = None) -> Timeline:
    """Keyframes of the playback of ``result`` (see ``Timeline``): the trace's samples mapped
    to playback time (at most ``FPS`` a second), then the final pose."""
    trace = _trace_of(result, nq)
    speed = check_speed(speed)
    t = np.asarray(trace.time, dtype=float)
    q = np.asarray(trace.q, dtype=float)
    keep = np.isfinite(t) & np.all(np.isfinite(q), axis=1) & (t < result.sim_time)
    t, q = t[keep], q[keep]
    t0 = float(t[0]) if t.size else 0.0
    sim_time = max(float(result.sim_time) - t0, 0.0) if math.isfinite(result.sim_time) else 0.0
    if speed is None:
        speed = auto_speed(sim_time)
    duration = sim_time / speed
    play_t = (t - t0) / speed
    n_frames = int(math.ceil(duration * FPS)) + 1
    if play_t.size > n_frames:  # more samples than frames: the sample nearest each frame
        grid = np.arange(n_frames) / FPS
        idx = np.clip(np.searchsorted(play_t, grid), 0, play_t.size - 1)
        before = np.clip(idx - 1, 0, play_t.size - 1)
        nearer = np.abs(play_t[before] - grid) <= np.abs(play_t[idx] - grid)
        idx = np.unique(np.where(nearer, before, idx))
        play_t, q = play_t[idx], q[idx]
    final = np.asarray(result.q, dtype=float)[None, :]
    if play_t.size and duration - play_t[-1] < 1e-9:
        play_t, q = play_t[:-1], q[:-1]
    # A run that did not move still gets a clip of one frame: a clip of length 0 divides
    # by its length in the viewer.
    ends = [duration] if duration > 0 else [0.0, 1.0 / FPS]
    times = np.concatenate([play_t, ends])
    poses = np.concatenate([q] + [final] * len(ends))
    events: dict[str, np.ndarray] = {}
    kinds = np.asarray(trace.event_kind, dtype=object)
    event_t = (np.asarray(trace.event_time, dtype=float) - t0) / speed
    joints = np.asarray(trace.event_joint, dtype=np.int64)
    if joints.shape != kinds.shape:  # a trace without joints: no link to flash
        joints = np.full(kinds.shape, -1, dtype=np.int64)
    impact_joints = np.zeros(0, dtype=np.int64)
    for kind in EVENT_KINDS:
        chosen = (kinds == kind) & np.isfinite(event_t) if kinds.size else np.zeros(0, dtype=bool)
        order = np.argsort(event_t[chosen], kind="stable")
        events[kind] = event_t[chosen][order]
        if kind == "impact":
            impact_joints = joints[chosen][order]
    return Timeline(times, poses, speed, duration, sim_time, events, impact_joints)


def densify(timeline: Timeline, model: Any) -> Timeline:
    """``timeline`` with a keyframe at least every 1 / ``FPS`` s of the motion: a settle of
    a few steps played in slow motion has keyframes seconds apart, and the viewer would move
    each shape in a straight line between them (a chain's links drifting apart); the frames
    between are Pinocchio's interpolation of the configurations, so that every link stays on
    its joint."""
    import pinocchio

    times, poses = [timeline.times[:1]], [timeline.q[:1]]
    motion = np.flatnonzero(timeline.times <= timeline.duration)
    for i in motion[:-1]:
        gap = timeline.times[i + 1] - timeline.times[i]
        extra = round(gap * FPS) - 1  # a gap of up to 1.5 frames is kept as it is
        u = np.arange(1, extra + 1) / (extra + 1) if extra > 0 else np.zeros(0)
        q0, q1 = timeline.q[i], timeline.q[i + 1]
        between = [pinocchio.interpolate(model, q0, q1, float(x)) for x in u]
        times.append(timeline.times[i] + u * gap)
        times.append(timeline.times[i + 1 : i + 2])
        poses.append(np.reshape(between, (-1, timeline.q.shape[1])))
        poses.append(timeline.q[i + 1 : i + 2])
    rest = slice(motion[-1] + 1, None) if motion.size else slice(1, None)
    times.append(timeline.times[rest])
    poses.append(timeline.q[rest])
    return replace(timeline, times=np.concatenate(times), q=np.concatenate(poses))


def _pulse(grid: np.ndarray, times: np.ndarray, end: float) -> np.ndarray:
    """At each time of ``grid``, how strong the flash of the events at ``times`` is: 1 at an
    event, fading to 0 over ``FLASH_SECONDS`` (the strongest of those under way), and 0 from
    ``end`` on: the final pose, which the viewer holds, shows no flash (the last damping event,
    from which Newton's method finishes, is often the run's last moment)."""
    if not times.size:
        return np.zeros(grid.shape)
    since = grid[:, None] - times[None, :]
    pulse = np.where((since >= 0) & (since < FLASH_SECONDS), 1 - since / FLASH_SECONDS, 0.0)
    return np.where(grid < end, pulse.max(axis=1), 0.0).astype(float)

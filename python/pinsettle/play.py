"""Watch a mechanism settle: playback of a solve in meshcat, and its energy plot.

``pinsettle.play(scene, result)`` draws the scene (its URDF's visual shapes and meshes, or a
stick figure when it has none), its springs following the motion, what holds it (loads, joint
springs, the loops' closure points, the stops' reactions at the end; a legend says which mark
is what), the grounds and the contacts on them with their forces at the end (a scene with
grounds), a flash at each damping event, and plays the recorded trajectory with time scaled so
that a long settle plays in a few seconds (and a short one in slow motion); the final pose is
held. ``plot_energy(result, path)`` draws both energy measures against time with the damping
events (PNG).

meshcat and matplotlib are an optional extra (``pip install 'pinsettle[viz]'``): they are
imported inside the functions, never by ``import pinsettle`` nor by a solve.

This module is the front door (``play``, the visualizer it returns, the public names); the
rooms behind it: ``_play_timeline`` (which pose is shown when), ``_play_meshes`` (the shapes),
``_play_animation`` (the scene and its animation in meshcat), ``_play_forces`` (the marks of
what holds it), ``_play_contacts`` (the grounds, the contacts and their forces),
``_play_server`` (the window meshcat talks to and the live server), ``_play_page`` (the static
and live pages), ``_play_plot`` (the energy plot) and ``_play_extra`` (the optional extra).
"""

from __future__ import annotations

import os
import sys
import types
import webbrowser
from functools import lru_cache
from pathlib import Path
from typing import Any, TypeVar

import pinocchio

from ._play_animation import build_animation, legend
from ._play_extra import VIZ_INSTALL, MissingDependencyError, require
from ._play_meshes import _normal_mesh_class, _stick_figure, _visual_model, dae_mesh, read_stl
from ._play_page import _html, live_page
from ._play_plot import _impact_names as _impact_names  # the legend's names, tested here
from ._play_plot import plot_energy
from ._play_server import SERVER_TIMEOUT, _LiveServer, _Window
from ._play_timeline import (
    EVENT_KINDS,
    FLASH_SECONDS,
    FPS,
    MIN_PLAYBACK_SECONDS,
    PLAYBACK_SECONDS,
    Timeline,
    auto_speed,
    check_speed,
    densify,
    make_timeline,
    speed_label,
)
from ._scene import Scene, load_scene
from ._solve import Result
from ._solver import solve
from .scenes import scene_path

__all__ = [
    "EVENT_KINDS",
    "FLASH_SECONDS",
    "FPS",
    "MIN_PLAYBACK_SECONDS",
    "PLAYBACK_SECONDS",
    "SERVER_TIMEOUT",
    "TRACE_SETTINGS",
    "VIZ_INSTALL",
    "MissingDependencyError",
    "Timeline",
    "auto_speed",
    "check_speed",
    "densify",
    "make_timeline",
    "play",
    "plot_energy",
    "read_stl",
    "require",
    "speed_label",
]

#: Solver settings that record what playback needs (every step, at most 4096 samples kept:
#: the stride doubles when the buffer is full, so memory stays bounded on long runs).
TRACE_SETTINGS: dict[str, Any] = {
    "trace_every": 1,
    "trace_capacity": 4096,
    "trace_configurations": True,
}

_V = TypeVar("_V", bound="_Playback")


class _Playback:
    """What ``play`` returns beside pinocchio's ``MeshcatVisualizer``: ``url`` is the live page
    (None without a server), ``html()`` the self-contained static page, ``save_html(path)``,
    ``save_plot(path)`` the energy plot, ``replay()`` starts the animation again, ``close()``
    (or leaving a ``with`` block) stops the server. ``scene``, ``result`` and ``timeline`` are
    what is played."""

    scene: Scene
    result: Result
    timeline: Timeline
    window: _Window
    viewer: Any  # MeshcatVisualizer's
    animation: Any

    @property
    def url(self) -> str | None:
        return self.window.web_url

    @property
    def speed(self) -> float:
        return self.timeline.speed

    @property
    def duration(self) -> float:
        """Length of the animation (s of playback)."""
        return self.timeline.end

    def html(self) -> str:
        return _html(self.window.commands(), self.window.animation, self._overlay())

    def save_html(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(self.html(), encoding="utf-8")
        return path

    def save_plot(self, path: str | Path) -> Path:
        return plot_energy(self.result, path, title=self.scene.name)

    def replay(self) -> None:
        self.viewer.set_animation(self.animation, play=True, repetitions=1)

    def open(self) -> None:
        if self.url:
            webbrowser.open(self.url, new=2)

    def close(self) -> None:
        self.window.close()

    def __enter__(self: _V) -> _V:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _overlay(self) -> dict[str, Any]:
        return _overlay(self.scene, self.result, self.timeline)


def _overlay(scene: Scene, result: Result, timeline: Timeline) -> dict[str, Any]:
    """What the overlay of both pages shows (see ``_play_page``)."""
    status = f"{result.status}: {result.steps} steps, {result.peaks} damping events"
    return {
        "legend": legend(scene, result, timeline),
        "scene": scene.name,
        "status": status,
        "speed": timeline.speed,
        "speed_label": speed_label(timeline.speed),
        # In simulated time, as the viewer's clips and time slider.
        "duration": timeline.duration * timeline.speed,
        "events": {k: (v * timeline.speed).tolist() for k, v in timeline.events.items()},
    }


@lru_cache(maxsize=1)
def _visualizer_class() -> type:
    from pinocchio.visualize import MeshcatVisualizer

    class PlaybackVisualizer(_Playback, MeshcatVisualizer):  # type: ignore[misc]  # no types
        """Pinocchio's ``MeshcatVisualizer`` holding one playback (see ``pinsettle.play``).

        ``url`` is the live page (None without a server), ``html()`` the self-contained
        static page, ``save_html(path)``, ``save_plot(path)`` the energy plot, ``replay()``
        starts the animation again, ``close()`` (or leaving a ``with`` block) stops the
        server. ``scene``, ``result`` and ``timeline`` are what is played.
        """

        def loadMeshFromFile(self, geometry_object: Any) -> Any:  # noqa: N802  (pinocchio's)
            # STL: our own triangles with normals (meshcat's loader keeps the file's, often
            # zeros: a black mesh); DAE split into one mesh per material (a multi-material
            # mesh is not drawn); OBJ as pinocchio loads it.
            if geometry_object.meshPath.lower().endswith(".stl"):
                return _normal_mesh_class()(*read_stl(geometry_object.meshPath))
            if geometry_object.meshPath.lower().endswith(".dae"):
                return dae_mesh(geometry_object.meshPath)
            return super().loadMeshFromFile(geometry_object)

    return PlaybackVisualizer


def _as_scene(scene: Any) -> Scene:
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, pinocchio.Model):
        return Scene(scene)
    if isinstance(scene, (str, os.PathLike)):
        return load_scene(scene_path(scene))
    raise TypeError(
        "scene must be a pinsettle.Scene, a pinocchio.Model, a scene file or a scene name, "
        f"got {type(scene).__name__}"
    )


def play(
    scene: Any,
    result: Result | None = None,
    *,
    speed: float | None = None,
    html: str | Path | None = None,
    plot: str | Path | None = None,
    live: bool = True,
    open_browser: bool = False,
) -> Any:
    """Play the settling motion of ``scene`` in meshcat; return the visualizer.

    Args:
        scene: a ``pinsettle.Scene`` (its URDF's shapes and meshes are drawn; a stick figure
            when it has none), a scene file or library name, or a ``pinocchio.Model``.
        result: a ``Result`` of ``solve(scene, ...)`` with a trace of configurations
            (``trace_configurations=True``, e.g. ``**TRACE_SETTINGS``); None to solve here
            with the scene's settings and ``TRACE_SETTINGS``.
        speed: simulated seconds per second of playback; None: real time, or faster so that a
            settle longer than ``PLAYBACK_SECONDS`` plays in about that long, or slower (slow
            motion) so that one shorter than ``MIN_PLAYBACK_SECONDS`` plays in that long.
        html: also write the self-contained static page (no server needed to view it).
        plot: also write the energy plot (PNG; see ``plot_energy``).
        live: start a meshcat server on 127.0.0.1 (the returned visualizer's ``url``; stop it
            with ``close()`` or a ``with`` block; it also stops when this process exits).
        open_browser: open the live page (or, without a server, the HTML file) in a browser.

    Returns:
        A ``pinocchio.visualize.MeshcatVisualizer`` (``PlaybackVisualizer``) with ``url``,
        ``html()``, ``save_html()``, ``save_plot()``, ``replay()`` and ``close()``.

    Raises:
        MissingDependencyError (an ImportError): meshcat or matplotlib is missing.
        TypeError, ValueError: a bad argument (named in the message), or a result without a
            trace of configurations.
    """
    require()
    scene = _as_scene(scene)
    speed = check_speed(speed)
    if result is None:
        result = solve(scene, **TRACE_SETTINGS)
    timeline = densify(make_timeline(result, scene.model.nq, speed), scene.model)
    visual = _visual_model(scene) or _stick_figure(scene.model)
    page = live_page(_overlay(scene, result, timeline))
    window = _Window(_LiveServer(page) if live else None)
    try:
        viz = _loaded_visualizer(window, scene, result, timeline, visual)
        if html is not None:
            viz.save_html(html)
        if plot is not None:
            viz.save_plot(plot)
    except BaseException:
        window.close()
        raise
    if open_browser:
        if viz.url:
            viz.open()
        elif html is not None:
            webbrowser.open(Path(html).resolve().as_uri(), new=2)
    return viz


def _loaded_visualizer(
    window: _Window, scene: Scene, result: Result, timeline: Timeline, visual: Any
) -> Any:
    """A ``PlaybackVisualizer`` drawing into ``window``, the playback loaded and started."""
    import meshcat

    viz = _visualizer_class()(scene.model, None, visual)
    viz.window = window
    viz.scene, viz.result, viz.timeline = scene, result, timeline
    viz.initViewer(viewer=meshcat.Visualizer(window=window)["pinsettle"])
    viz.animation = build_animation(viz, scene, timeline, visual, result)
    viz.viewer.set_animation(viz.animation, play=True, repetitions=1)
    return viz


# ``import pinsettle.play`` binds the module to ``pinsettle.play``: make the module callable, so
# that ``pinsettle.play(scene, result)`` works whichever of the two the name holds.
class _CallableModule(types.ModuleType):
    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return play(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule

"""pinsettle: where a mechanism comes to rest.

Static equilibria of Pinocchio models by kinetic damping: the mechanism is simulated with its
true dynamics (Pinocchio's ABA) and its velocity is scaled down at each peak of its kinetic
energy, until the energy stays below a limit.
"""

from __future__ import annotations

import importlib.metadata as _metadata

import pinocchio  # noqa: F401  (registers the converters that pinsettle._core reads models with)

from ._hold import Hold, PayloadCapacity, hold, payload
from ._scene import Scene, SceneError, load_scene
from ._settings import Settings
from ._solve import (
    Contact,
    Progress,
    Result,
    StabilityReport,
    Trace,
    assess_stability,
    kinetic_energies,
    solver_memory,
    static_force,
    static_residual,
)
from ._solver import Solver, solve
from ._sweep import distinct_rests, sweep
from ._sweep_plot import plot_sweep
from .robots import load_robot, load_urdf, robot_names, robot_urdf
from .scenes import scene_names, scene_path, scenes_dir

__version__ = _metadata.version("pinsettle")

__all__ = [
    "Contact",
    "Progress",
    "Result",
    "Scene",
    "SceneError",
    "Settings",
    "StabilityReport",
    "Trace",
    "assess_stability",
    "distinct_rests",
    "get_cmake_dir",
    "hold",
    "Hold",
    "kinetic_energies",
    "load_robot",
    "load_scene",
    "load_urdf",
    "payload",
    "PayloadCapacity",
    "play",
    "plot_sweep",
    "robot_names",
    "robot_urdf",
    "scene_names",
    "scene_path",
    "scenes_dir",
    "Solver",
    "solve",
    "solver_memory",
    "static_force",
    "static_residual",
    "sweep",
]


def get_cmake_dir() -> str:
    """Folder of pinsettleConfig.cmake, for ``-Dpinsettle_DIR=...`` or ``CMAKE_PREFIX_PATH``."""
    from pathlib import Path

    path = Path(__file__).resolve().parent / "lib" / "cmake" / "pinsettle"
    if not path.is_dir():
        raise FileNotFoundError(f"the C++ package of pinsettle is not installed at {path}")
    return str(path)


def __getattr__(name: str) -> object:
    # ``pinsettle.play`` is imported on first use: importing pinsettle (or solving) never
    # imports meshcat or matplotlib, and play.py itself imports them only when it runs.
    if name == "play":
        import importlib

        # The submodule, made callable: pinsettle.play(scene, result) plays, and
        # pinsettle.play.TRACE_SETTINGS, pinsettle.play.plot_energy are at hand.
        return importlib.import_module(".play", __name__)
    raise AttributeError(f"module 'pinsettle' has no attribute '{name}'")

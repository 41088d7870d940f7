"""The scene library: the scene files of the project's robots/ folder, installed with the
package, by name."""

from __future__ import annotations

import difflib
import os
from pathlib import Path


def scenes_dir() -> Path:
    """The folder of the installed scene library (a copy of the project's robots/)."""
    path = Path(__file__).resolve().parent / "robots"
    if not path.is_dir():
        raise FileNotFoundError(f"the scene library is not installed at {path}")
    return path


def scene_names() -> list[str]:
    """Names of the scenes in the library (``pinsettle scenes`` lists them)."""
    return sorted(p.stem for p in scenes_dir().glob("*.toml"))


def scene_path(scene: str | os.PathLike[str]) -> Path:
    """A scene file: ``scene`` itself when it is an existing file, otherwise a scene of the
    library by name (``"pendulum"`` or ``"pendulum.toml"``)."""
    path = Path(scene)
    if path.is_file():
        return path
    name = path.name[:-5] if path.name.endswith(".toml") else path.name
    if path.parent == Path(".") and name in scene_names():
        return scenes_dir() / f"{name}.toml"
    if path.suffix == ".toml" or path.parent != Path("."):
        raise FileNotFoundError(f"scene file not found: {path}")
    names = scene_names()
    close = difflib.get_close_matches(name, names, n=1)
    # The library has 20-odd scenes: the first few, and the command that lists them all.
    shown = ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")
    raise FileNotFoundError(
        f"no scene file '{scene}' here and no such scene in the library: unknown scene "
        f"'{name}'" + (f" (did you mean '{close[0]}'?)" if close else "") + f"; scenes: "
        f"{shown} (`pinsettle scenes` lists them)"
    )

"""The optional extra that playback needs (meshcat, matplotlib): a clear error without it."""

from __future__ import annotations

#: What ``play`` installs: the optional extra.
VIZ_INSTALL = "pip install 'pinsettle[viz]'"


class MissingDependencyError(ImportError):
    """meshcat or matplotlib is not installed; the message says what to install."""


def require(*modules: str) -> None:
    """Import ``modules`` (default: meshcat and matplotlib) or raise MissingDependencyError
    with a one-line message naming what to install."""
    import importlib

    missing = []
    for name in modules or ("meshcat", "matplotlib"):
        try:
            importlib.import_module(name)
        except ImportError:
            missing.append(name)
    if missing:
        raise MissingDependencyError(
            f"pinsettle play needs {' and '.join(missing)}, which "
            + ("is" if len(missing) == 1 else "are")
            + f" not installed: {VIZ_INSTALL}"
        )

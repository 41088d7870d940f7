"""The installed package: the extension finds Pinocchio without LD_LIBRARY_PATH, and ships its
type stubs and C++ package files."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pinsettle
import pytest
from pinsettle import _core

PACKAGE = Path(pinsettle.__file__).resolve().parent


def test_extension_resolves_pinocchio_through_its_rpath():
    if shutil.which("ldd") is None:
        pytest.fail("ldd is needed to inspect the extension's library paths")
    env = {k: v for k, v in os.environ.items() if k != "LD_LIBRARY_PATH"}
    out = subprocess.run(
        ["ldd", _core.__file__], capture_output=True, text=True, env=env, check=True
    ).stdout
    assert "not found" not in out, out
    line = next(line for line in out.splitlines() if "libpinocchio_default" in line)
    assert "cmeel.prefix/lib" in line


def test_installed_files():
    for relative in [
        "py.typed",
        "_core.pyi",
        "lib/libpinsettle.a",
        "lib/cmake/pinsettle/pinsettleConfig.cmake",
        "include/pinsettle/pinsettle.hpp",
        "include/pinsettle/solver.hpp",
    ]:
        assert (PACKAGE / relative).is_file(), relative
    assert Path(pinsettle.get_cmake_dir()) == PACKAGE / "lib" / "cmake" / "pinsettle"

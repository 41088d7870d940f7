"""The installed package: the extension finds Pinocchio without LD_LIBRARY_PATH, ships its type
stubs and C++ package files, and a second build of the same checkout compiles nothing."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pinsettle
import pytest
from pinsettle import _core

PACKAGE = Path(pinsettle.__file__).resolve().parent
ROOT = Path(__file__).resolve().parents[1]


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


CONSUMER_CMAKE = """\
cmake_minimum_required(VERSION 3.22)
project(consumer CXX)
find_package(pinsettle 0.1 REQUIRED)
get_target_property(library pinsettle::pinsettle IMPORTED_LOCATION_RELEASE)
get_target_property(include pinsettle::pinsettle INTERFACE_INCLUDE_DIRECTORIES)
file(WRITE "${CMAKE_BINARY_DIR}/found.txt" "${library}\\n${include}\\n")
add_executable(consumer main.cpp)
target_link_libraries(consumer PRIVATE pinsettle::pinsettle)
"""

# Links the library's settings check (no Pinocchio header: it compiles in seconds).
CONSUMER_MAIN = """\
#include <pinsettle/settings.hpp>
#include <cstdio>
#include <stdexcept>
#include <string>
int main() {
  pinsettle::Settings settings;
  settings.kt = 2.;
  try { pinsettle::checkSettings(settings); }
  catch (const std::invalid_argument & e) {
    std::printf("%s\\n", e.what());
    return std::string(e.what()).find("kt") == std::string::npos;
  }
  return 1;
}
"""


def test_cmake_install_to_a_plain_prefix_gives_a_working_package(tmp_path):
    """`cmake --install . --prefix P` outside a wheel, then a project with find_package(pinsettle)
    and CMAKE_PREFIX_PATH=P;<Pinocchio's prefix> configures, builds and runs against it. (The
    installed config once pointed one folder above P: its destinations began with "./".)

    The library is not compiled again: the wheel's libpinsettle.a, built from the same sources,
    is put where the build would leave it, and the install rules copy it as they would."""
    cmake = shutil.which("cmake")
    if cmake is None:
        pytest.fail("cmake is not installed: pip install '.[test]' brings it")
    root = Path(__file__).resolve().parents[1]
    cmeel_prefix = subprocess.run(
        [sys.executable, "-m", "cmeel", "cmake"], capture_output=True, text=True, check=True
    ).stdout.strip()
    generator = ["-G", "Ninja"] if shutil.which("ninja") else []

    def run(*cmd: str) -> str:
        proc = subprocess.run(cmd, capture_output=True, text=True)
        assert proc.returncode == 0, f"{' '.join(cmd)}:\n{proc.stdout}\n{proc.stderr}"
        return proc.stdout

    build, prefix, consumer = tmp_path / "build", tmp_path / "prefix", tmp_path / "consumer"
    run(
        cmake,
        "-S",
        str(root),
        "-B",
        str(build),
        *generator,
        "-DCMAKE_BUILD_TYPE=Release",
        "-DPINSETTLE_BUILD_PYTHON=OFF",
        f"-DPython_EXECUTABLE={sys.executable}",
    )
    shutil.copy(PACKAGE / "lib" / "libpinsettle.a", build / "libpinsettle.a")
    run(cmake, "--install", str(build), "--prefix", str(prefix))
    configs = list(prefix.glob("lib*/cmake/pinsettle/pinsettleConfig.cmake"))
    assert len(configs) == 1, sorted(p.relative_to(prefix) for p in prefix.rglob("*"))
    assert not (tmp_path / "lib").exists() and not (tmp_path / "include").exists()

    consumer.mkdir()
    (consumer / "CMakeLists.txt").write_text(CONSUMER_CMAKE)
    (consumer / "main.cpp").write_text(CONSUMER_MAIN)
    run(
        cmake,
        "-S",
        str(consumer),
        "-B",
        str(consumer / "build"),
        *generator,
        "-DCMAKE_BUILD_TYPE=Release",
        f"-DCMAKE_PREFIX_PATH={prefix};{cmeel_prefix}",
    )
    library, include = (consumer / "build" / "found.txt").read_text().split()
    assert Path(library).resolve() == (configs[0].parents[2] / "libpinsettle.a").resolve()
    assert (Path(include) / "pinsettle" / "solver.hpp").is_file()
    assert Path(include).resolve().parent == prefix.resolve()
    run(cmake, "--build", str(consumer / "build"))
    out = run(str(consumer / "build" / "consumer"))
    assert "kt" in out


def _kept_build_folder() -> Path | None:
    """This checkout's kept wheel build folder for this Python (pyproject.toml's build-dir), if
    a build has run there."""
    module = f"_core{sysconfig.get_config_var('EXT_SUFFIX')}"
    for core in sorted((ROOT / "build").glob("*/core")):
        if (core / module).is_file() and (core.parent / ".ninja_log").is_file():
            return core.parent
    return None


def _ninja_log(build: Path) -> set[tuple[str, ...]]:
    """ninja's record of the commands it ran: (start, end, mtime, output, command hash)."""
    lines = (build / ".ninja_log").read_text().splitlines()
    return {tuple(line.split("\t")) for line in lines if not line.startswith("#")}


def test_a_second_build_of_the_same_sources_compiles_nothing(tmp_path):
    """After `pip install .` (the README's commands), building the same checkout again with pip
    (its own isolated build environment, at a new path) compiles no file: the kept build folder
    survives scikit-build-core's clearing (cmake/wheel/) and the dependencies keep their paths
    (cmake/stable_deps.py). The rebuilt wheel's module is the installed one, byte for byte.
    About 30 s: pip installs the build requirements again."""
    build = _kept_build_folder()
    if build is None:
        message = (
            f"no kept wheel build of this checkout under {ROOT / 'build'} for this Python: "
            "pinsettle was not installed from it with `pip install .`"
        )
        if os.environ.get("PINSETTLE_REQUIRE_BUILD_DIR") == "1":
            pytest.fail(message + " (PINSETTLE_REQUIRE_BUILD_DIR=1)")
        pytest.skip(message)
    before = _ninja_log(build)
    drop = ("SKBUILD_", "PIP_NO_BUILD_ISOLATION")
    env = {k: v for k, v in os.environ.items() if not k.startswith(drop)}
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", str(tmp_path), str(ROOT)],
        capture_output=True,
        text=True,
        env=env,
    )
    assert proc.returncode == 0, f"pip wheel failed:\n{proc.stdout}\n{proc.stderr}"
    ran = sorted(entry[3] for entry in _ninja_log(build) - before)
    compiled = [output for output in ran if output.endswith(".o")]
    assert not compiled, f"the second build compiled {compiled} (ninja ran {ran})"
    (wheel,) = tmp_path.glob("pinsettle-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        built = archive.read(f"pinsettle/{Path(_core.__file__).name}")
    assert built == Path(_core.__file__).read_bytes()

"""Build the C++ tests and the example against the installed pinsettle package, run them.

This is how `pytest` runs every test, C++ included: tests/cpp/CMakeLists.txt does
find_package(pinsettle) exactly as a user's project would.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pinsettle
import pytest

HERE = Path(__file__).resolve().parent


def _cmake() -> str:
    exe = shutil.which("cmake", path=str(Path(sys.executable).parent)) or shutil.which("cmake")
    if exe is None:
        pytest.fail("cmake is not installed: pip install '.[test]' brings it")
    return exe


def _run(cmd: list[str], **kwargs) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, capture_output=True, text=True, **kwargs)
    if proc.returncode != 0:
        pytest.fail(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return proc


@pytest.fixture(scope="module")
def cpp_build(tmp_path_factory) -> Path:
    import cmeel  # noqa: F401

    prefix = subprocess.run(
        [sys.executable, "-m", "cmeel", "cmake"], capture_output=True, text=True, check=True
    ).stdout.strip()
    build = Path(os.environ.get("PINSETTLE_CPP_TEST_BUILD", tmp_path_factory.mktemp("cpp")))
    generator = (
        ["-G", "Ninja"] if shutil.which("ninja", path=str(Path(sys.executable).parent)) else []
    )
    _run(
        [
            _cmake(),
            "-S",
            str(HERE / "cpp"),
            "-B",
            str(build),
            *generator,
            "-DCMAKE_BUILD_TYPE=Release",
            f"-DCMAKE_PREFIX_PATH={pinsettle.get_cmake_dir()};{prefix}",
            f"-DPINSETTLE_ROBOTS_DIR={pinsettle.robots.robots_dir()}",
        ]
    )
    _run([_cmake(), "--build", str(build), "--parallel", str(os.cpu_count() or 2)])
    return build


@pytest.mark.parametrize(
    "suite",
    [
        "test_core",
        "test_elements",
        "test_loops",
        "test_parts",
        "test_stops",
        "test_models",
        "test_mimic",
        "test_contacts",
    ],
)
def test_cpp_boost_tests(cpp_build: Path, suite: str) -> None:
    proc = _run([str(cpp_build / suite), "--report_level=short"])
    assert "failed" not in proc.stdout.lower() or "0 failed" in proc.stdout.lower()


@pytest.mark.parametrize("name", ["example_ur5", "example_pendulum", "readme_example"])
def test_cpp_example_against_installed_package(cpp_build: Path, name: str) -> None:
    proc = _run(["ctest", "--test-dir", str(cpp_build), "-R", f"^{name}$", "--output-on-failure"])
    assert "100% tests passed" in proc.stdout


def test_readme_cpp_example_as_written(cpp_build: Path) -> None:
    # The README's C++ block (tests/cpp/readme_example.cmake extracts it) given the UR5: it
    # converges, and what it prints is a rest (Pinocchio's gravity at the printed pose, to the
    # 6 digits the stream gives) and the Python solve's own answer with the same settings.
    import numpy as np
    import pinocchio

    urdf = pinsettle.robot_urdf("ur5")
    proc = _run([str(cpp_build / "readme_example"), str(urdf)])
    status, q_line = proc.stdout.splitlines()
    head = status.split()
    assert head[:2] == ["converged", "in"] and head[3:5] == ["steps,", "residual"], status
    assert float(head[5]) < 1e-10, status
    q = np.array([float(x) for x in q_line.removeprefix("q ").split()])
    model = pinsettle.load_robot("ur5")
    expected = pinsettle.solve(model, pinocchio.neutral(model), max_e=1e-16)
    assert int(head[2]) == expected.steps, (status, expected.steps)
    assert q == pytest.approx(expected.q, abs=1e-5)
    g = pinocchio.computeGeneralizedGravity(model, model.createData(), q)
    assert np.abs(g).max() < 1e-3  # 6-digit angles: 1e-6 rad times a stiffness below 65 N m/rad
    # The program's own error path: a missing file is a message and exit 2, not an abort.
    missing = subprocess.run(
        [str(cpp_build / "readme_example"), "no_such.urdf"], capture_output=True, text=True
    )
    assert missing.returncode == 2 and missing.stderr.startswith("error: "), missing

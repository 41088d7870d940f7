"""Shared fixtures of the pinsettle Python tests: models built once per session.

The solver only reads a model (it is passed by const reference to the C++ core), so the
session-scoped models below are shared; a test that needs to change a model works on
``model.copy()``.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import os
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest

PENDULUM_URDF = Path(__file__).parents[1] / "robots" / "pendulum.urdf"
CHECKOUT = Path(__file__).resolve().parents[1]
#: The file MuJoCo appends its warnings and errors to, in the working directory, by default.
MUJOCO_LOG = "MUJOCO_LOG.TXT"


@contextlib.contextmanager
def mujoco_warnings(mujoco) -> Iterator[list[str]]:
    """MuJoCo's warnings while in the block, kept in the list yielded instead of appended to
    MUJOCO_LOG.TXT in the working directory (MuJoCo's default)."""
    caught: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda text: caught.append(str(text).strip()))
    try:
        yield caught
    finally:
        mujoco.set_mju_user_warning(previous)


@pytest.fixture(autouse=True)
def no_mujoco_log():
    """No test leaves MuJoCo's log in the checkout (or the folder it ran in): a warning of a
    run expected to go bad is kept off the log by the code that steps it. The test that made
    MuJoCo write one errors, with the file's first lines."""
    places = {CHECKOUT, Path.cwd().resolve()}
    before = {place for place in places if (place / MUJOCO_LOG).exists()}
    yield
    written = [place / MUJOCO_LOG for place in sorted(places - before)]
    written = [path for path in written if path.exists()]
    if written:
        text = written[0].read_text(errors="replace")[:400]
        pytest.fail(f"MuJoCo wrote {written[0]} during this test: {text}")


@pytest.fixture(scope="session")
def pendulum() -> pinocchio.Model:
    """1 kg bob 1 m below a hinge about y; hanging down (q = 0) is the stable equilibrium."""
    return pinocchio.buildModelFromUrdf(str(PENDULUM_URDF))


@pytest.fixture(scope="session")
def ur5() -> pinocchio.Model:
    return pinsettle.load_robot("ur5")


@pytest.fixture(scope="session")
def panda() -> pinocchio.Model:
    """The full Panda: 7 revolute arm joints and 2 free (unlimited) prismatic fingers."""
    return pinsettle.load_robot("panda")


@pytest.fixture(scope="session")
def panda_arm(panda) -> pinocchio.Model:
    """The Panda with its two finger joints locked at 0 (see test_solve for why)."""
    fingers = [panda.getJointId("panda_finger_joint1"), panda.getJointId("panda_finger_joint2")]
    return pinocchio.buildReducedModel(panda, fingers, pinocchio.neutral(panda))


@pytest.fixture(scope="session")
def double_pendulum() -> pinocchio.Model:
    return pinsettle.load_robot("double_pendulum")


@pytest.fixture(scope="session")
def solo12() -> pinocchio.Model:
    """Quadruped whose root is a free-flyer joint (quaternion in q[3:7])."""
    return pinsettle.load_robot("solo12")


@pytest.fixture(scope="session")
def humanoid() -> pinocchio.Model:
    """Pinocchio's random humanoid (free-flyer root, random inertias); seeded to be stable."""
    if not hasattr(pinocchio, "buildSampleModelHumanoidRandom"):
        pytest.skip("pinocchio.buildSampleModelHumanoidRandom is not available")
    pinocchio.seed(0)
    return pinocchio.buildSampleModelHumanoidRandom()


def make_chain(n: int, massless: tuple[int, ...] = ()) -> pinocchio.Model:
    """A planar chain of ``n`` revolute-y links of 1 m, 1 kg at each link's far end.

    Links whose index is in ``massless`` get ``Inertia.Zero()`` (a bare frame, not a body).
    """
    model = pinocchio.Model()
    parent = 0
    for k in range(n):
        placement = pinocchio.SE3(np.eye(3), np.array([0.0, 0.0, 0.0 if k == 0 else -1.0]))
        parent = model.addJoint(parent, pinocchio.JointModelRY(), placement, f"j{k}")
        if k in massless:
            inertia = pinocchio.Inertia.Zero()
        else:
            inertia = pinocchio.Inertia(
                1.0, np.array([0.0, 0.0, -1.0]), np.diag([1e-3, 2e-3, 3e-3])
            )
        model.appendBodyToJoint(parent, inertia, pinocchio.SE3.Identity())
    return model


@pytest.fixture(scope="session")
def chain_with_massless_link() -> pinocchio.Model:
    """Three links, the middle one massless: the simplified energy must skip it."""
    return make_chain(3, massless=(1,))


@pytest.fixture(scope="session")
def chain_urdf() -> Callable[[int], str]:
    """robots/make_chain.py's ``chain_urdf(n)``: the URDF text of an n-link hanging chain."""
    path = Path(__file__).parents[1] / "robots" / "make_chain.py"
    spec = importlib.util.spec_from_file_location("make_chain", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.chain_urdf


@pytest.fixture(scope="session")
def mujoco():
    """MuJoCo, the reference of the MJCF checks: skipped without it, except where
    PINSETTLE_REQUIRE_MUJOCO=1 (CI), where its absence fails (as PINSETTLE_REQUIRE_CHROMIUM does
    for playback's screenshots)."""
    try:
        return importlib.import_module("mujoco")
    except ImportError as error:
        if os.environ.get("PINSETTLE_REQUIRE_MUJOCO") == "1":
            pytest.fail(
                f"MuJoCo is required here (PINSETTLE_REQUIRE_MUJOCO=1) but does not import: "
                f"{error}; pip install '.[test]' installs it"
            )
        pytest.skip(f"mujoco is not installed ({error}): the MJCF checks against it skip")

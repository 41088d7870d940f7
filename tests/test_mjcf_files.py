"""MJCF files as third-party packages ship them (issue 40), read as MuJoCo reads them.

Each defect found on a real file has a test on that file, found through its installed package
(dm_control, gymnasium_robotics), and one on a reduced copy written here that keeps what
matters; both are judged by MuJoCo's own numbers (``mujoco.MjModel``: body masses, centres of
mass and inertias; the generalized forces of ``mj_forward``), never by pinsettle's:

- several top-level ``<default>`` elements (those of included files too) merge into 'main',
  and a nested class copies its parent as it stands when the class is read;
- masses of mesh geoms, from their volume (binary STL, OBJ, MSH; the mesh ``inertia`` rules
  legacy, exact, convex and shell; scale, refpos, refquat; a geom's mass or density);
- ``<flag limit="disable"/>`` disables tendon ranges too;
- free objects beside a robot: kept (they fall: ``no_equilibrium`` naming them) or locked
  where the file places them (``free_objects``, ``--free-objects``);
- a file's own ``<freejoint>`` floats, ``--floating`` adds one only where the file has none;
- position actuators as joint springs (``actuator_springs``, ``--actuator-springs``), against
  MuJoCo's ``qfrc_actuator``;
- refusals short, with a way forward.

The third-party packages are optional: a test that needs one is skipped when it is missing,
and fails instead when PINSETTLE_REQUIRE_MODELS=1 (as CI sets it).
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pinocchio
import pinsettle
import pytest
from pinsettle._mjcf import MjcfError, load_mjcf


def require(package: str) -> Path:
    """The folder of an installed package (found without importing it). Missing: a skip, or a
    failure when PINSETTLE_REQUIRE_MODELS=1."""
    spec = importlib.util.find_spec(package)
    if spec is None or not spec.submodule_search_locations:
        message = f"the package {package} is not installed (pip install 'pinsettle[models]')"
        if os.environ.get("PINSETTLE_REQUIRE_MODELS") == "1":
            pytest.fail(f"{message} and PINSETTLE_REQUIRE_MODELS=1")
        pytest.skip(message)
    return Path(next(iter(spec.submodule_search_locations)))


def model_file(package: str, *parts: str) -> Path:
    """A model file shipped by a package; a failure if the package lacks it."""
    path = require(package).joinpath(*parts)
    assert path.is_file(), f"{package} has no {'/'.join(parts)} (a newer version?)"
    return path


@pytest.fixture(scope="module")
def mujoco() -> ModuleType:
    require("mujoco")
    return importlib.import_module("mujoco")


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pinsettle", *args], capture_output=True, text=True, timeout=300
    )


def solve_json(*args: str) -> dict:
    proc = run("solve", *args, "--json")
    assert proc.returncode in (0, 1), proc.stderr
    out: dict = json.loads(proc.stdout)
    return out


def one_line_error(proc: subprocess.CompletedProcess[str]) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pinsettle: error: "), proc.stderr
    return lines[0]


# --- MuJoCo's numbers --------------------------------------------------------------------------


def body_name(mj, b: int) -> str:
    """pinsettle names an unnamed body body<k>, k its place in the file: MuJoCo's id."""
    return str(mj.body(b).name) or f"body{b}"


def assert_inertias_are_mujocos(mujoco, path: Path, **options) -> int:
    """Every body's mass, centre of mass and inertia tensor as MuJoCo compiles them. The
    tensors to 1e-7 of the largest: MuJoCo keeps principal moments and axes from its own
    eigen-solver (mjuu_eig3), whose axes are that precise; the moments agree to 1e-14."""
    mj = mujoco.MjModel.from_xml_path(str(path))
    ours = load_mjcf(path, **options).inertias
    compared = 0
    for b in range(1, mj.nbody):
        name = body_name(mj, b)
        if mj.body_mass[b] == 0:
            assert name not in ours or ours[name][0] == 0, name
            continue
        mass, com, inertia = ours[name]
        rotation = np.zeros(9)
        mujoco.mju_quat2Mat(rotation, mj.body_iquat[b])
        rotation = rotation.reshape(3, 3)
        expected = rotation @ np.diag(mj.body_inertia[b]) @ rotation.T
        scale = max(1.0, float(np.abs(mj.body_ipos[b]).max()))
        assert mass == pytest.approx(mj.body_mass[b], rel=1e-12), name
        assert np.abs(com - mj.body_ipos[b]).max() < 1e-12 * scale, name
        assert np.abs(inertia - expected).max() < 1e-7 * np.abs(expected).max(), name
        moments = np.sort(np.linalg.eigvalsh(inertia))
        assert moments == pytest.approx(np.sort(mj.body_inertia[b]), rel=1e-6), name
        compared += 1
    return compared


def to_qpos(mj, model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
    """MuJoCo's qpos of Pinocchio's q, joint by joint (by name; quaternions w first)."""
    qpos = mj.qpos0.copy()
    for j in range(mj.njnt):
        name = mj.joint(j).name
        adr = mj.jnt_qposadr[j]
        iq = model.idx_qs[model.getJointId(name)]
        kind = mj.jnt_type[j]
        if kind == 0:  # free: x y z, then w x y z
            qpos[adr : adr + 7] = [*q[iq : iq + 3], q[iq + 6], *q[iq + 3 : iq + 6]]
        elif kind == 1:  # ball
            qpos[adr : adr + 4] = [q[iq + 3], *q[iq : iq + 3]]
        else:
            qpos[adr] = q[iq]
    return qpos


def static_force(mujoco, mj, qpos: np.ndarray, ctrl: np.ndarray | None = None) -> np.ndarray:
    """MuJoCo's net generalized force on the mechanism at rest at qpos: springs and (with
    ctrl) actuators minus gravity, contacts and constraints off."""
    data = mujoco.MjData(mj)
    data.qpos[:] = qpos
    data.qvel[:] = 0
    if ctrl is not None:
        data.ctrl[:] = ctrl
    mj.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    mj.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    if ctrl is None:
        mj.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_ACTUATION
    mujoco.mj_forward(mj, data)
    return np.array(data.qfrc_passive + data.qfrc_actuator - data.qfrc_bias)


def gravity_scale(mujoco, mj) -> float:
    """The largest gravity torque over a few random poses: the force scale of the model."""
    rng = np.random.default_rng(0)
    data = mujoco.MjData(mj)
    top = 0.0
    for _ in range(5):
        data.qpos[:] = mj.qpos0 + 0.5 * rng.standard_normal(mj.nq)
        mujoco.mj_normalizeQuat(mj, data.qpos)
        mujoco.mj_forward(mj, data)
        top = max(top, float(np.abs(data.qfrc_bias).max()))
    return top


def assert_rest_is_mujocos(mujoco, path: Path, out: dict, **options) -> None:
    """A converged answer is a rest by MuJoCo's forces: the net force is zero off the stops
    (1e-8 of the model's force scale), and pushes into the stop where the answer is at one."""
    assert out["status"] == "converged", out["reason"]
    mj = mujoco.MjModel.from_xml_path(str(path))
    scene = pinsettle.Scene.from_mjcf(path, **options)
    model = scene.model
    q = np.array(out["q"])
    force = static_force(mujoco, mj, to_qpos(mj, model, q))
    bound = 1e-8 * max(gravity_scale(mujoco, mj), 1e-3)
    at_limit = out["at_limit"]
    for j in range(mj.njnt):
        name = mj.joint(j).name
        dof = mj.jnt_dofadr[j]
        if name in at_limit:
            side = at_limit[name]
            # The stop holds the joint: the force pushes into it, never away.
            pushes = force[dof] if "upper" in str(side) else -force[dof]
            assert pushes > -bound, (name, force[dof], side)
        elif mj.jnt_type[j] in (2, 3):
            assert abs(force[dof]) < bound, (name, force[dof])


# --- several top-level <default> -----------------------------------------------------------------

DEFAULTS = """
<mujoco model="defaults">
  <default>
    <joint damping="1" axis="0 1 0" stiffness="2" springref="10"/>
    <geom type="capsule" size="0.03 0.1" density="500"/>
    <default class="early"><joint range="-30 60"/></default>
  </default>
  <default>
    <joint stiffness="5"/>
    <geom density="800"/>
    <default class="late"><joint range="-10 20"/></default>
  </default>
  <worldbody>
    <body name="a" pos="0 0 1">
      <joint name="j0"/>
      <geom fromto="0 0 0 0.2 0 0"/>
      <body name="b" pos="0.2 0 0">
        <joint name="j1" class="early"/>
        <geom class="early" fromto="0 0 0 0.2 0 0"/>
        <body name="c" pos="0.2 0 0">
          <joint name="j2" class="late"/>
          <geom class="late" fromto="0 0 0 0.2 0 0"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_top_level_defaults_merge_as_in_mujoco(tmp_path, mujoco):
    # The second top-level <default> adds to 'main': j0 and the late class see stiffness 5,
    # the early class was copied from 'main' before (stiffness 2, density 500), as in MuJoCo.
    path = tmp_path / "defaults.xml"
    path.write_text(DEFAULTS)
    mj = mujoco.MjModel.from_xml_path(str(path))
    mjcf = load_mjcf(path)
    springs = {joint: (k, rest) for joint, k, rest in mjcf.joint_springs}
    for j in range(mj.njnt):
        name = mj.joint(j).name
        assert springs[name][0] == mj.jnt_stiffness[j], name
        assert springs[name][1] == pytest.approx(mj.qpos_spring[mj.jnt_qposadr[j]], abs=1e-15)
        iq = mjcf.model.idx_qs[mjcf.model.getJointId(name)]
        low, high = mjcf.model.lowerPositionLimit[iq], mjcf.model.upperPositionLimit[iq]
        if mj.jnt_limited[j]:
            assert [low, high] == pytest.approx(mj.jnt_range[j], abs=1e-15), name
        else:
            assert math.isinf(low) and math.isinf(high), name
    assert [springs[n][0] for n in ("j0", "j1", "j2")] == [5, 2, 5]


def test_a_renamed_top_level_default_is_refused_as_mujoco_does(tmp_path, mujoco):
    path = tmp_path / "renamed.xml"
    path.write_text(DEFAULTS.replace("<default>", '<default class="arm">', 1))
    with pytest.raises(ValueError, match="cannot be renamed"):
        mujoco.MjModel.from_xml_path(str(path))
    with pytest.raises(MjcfError, match="top-level class is 'main' and cannot be renamed"):
        load_mjcf(path)

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
        assert np.abs(inertia - expected).max() <= 1e-7 * np.abs(expected).max(), name
        moments = np.sort(np.linalg.eigvalsh(inertia))
        assert moments == pytest.approx(np.sort(mj.body_inertia[b]), rel=1e-6), name
        compared += 1
    return compared


def to_qpos(mj, model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
    """MuJoCo's qpos of Pinocchio's q, joint by joint (by name; quaternions w first); a joint
    pinsettle's model lacks (a locked free object's) stays at qpos0, where the file puts it."""
    qpos = mj.qpos0.copy()
    for j in range(mj.njnt):
        name = mj.joint(j).name
        adr = mj.jnt_qposadr[j]
        if not model.existJointName(name):
            continue
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
        steady_activation(mj, data)
    mj.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    mj.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    if ctrl is None:
        mj.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_ACTUATION
    mujoco.mj_forward(mj, data)
    return np.array(data.qfrc_passive + data.qfrc_actuator - data.qfrc_bias)


def steady_activation(mj, data) -> None:
    """At rest a filtered actuator's activation has reached its control (clamped as MuJoCo
    clamps it): set it there, as mj_forward reads the activation, not the control."""
    for i in range(mj.nu):
        adr = mj.actuator_actadr[i]
        if adr >= 0:
            low, high = mj.actuator_ctrlrange[i]
            data.act[adr] = (
                np.clip(data.ctrl[i], low, high) if mj.actuator_ctrllimited[i] else data.ctrl[i]
            )


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


def assert_rest_is_mujocos(
    mujoco, path: Path, out: dict, ctrl: np.ndarray | None = None, **options
) -> None:
    """A converged answer is a rest by MuJoCo's forces (with the actuators at ctrl, if given):
    the net force is zero off the stops (1e-8 of the model's force scale), and pushes into the
    stop where the answer is at one."""
    assert out["status"] == "converged", out["reason"]
    mj = mujoco.MjModel.from_xml_path(str(path))
    scene = pinsettle.Scene.from_mjcf(path, **options)
    model = scene.model
    q = np.array(out["q"])
    force = static_force(mujoco, mj, to_qpos(mj, model, q), ctrl)
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
    assert assert_inertias_are_mujocos(mujoco, path) == 3


def test_a_renamed_top_level_default_is_refused_as_mujoco_does(tmp_path, mujoco):
    path = tmp_path / "renamed.xml"
    path.write_text(DEFAULTS.replace("<default>", '<default class="arm">', 1))
    with pytest.raises(ValueError, match="cannot be renamed"):
        mujoco.MjModel.from_xml_path(str(path))
    with pytest.raises(MjcfError, match="top-level class is 'main' and cannot be renamed"):
        load_mjcf(path)


@pytest.mark.parametrize(
    "package, parts",
    [
        ("dm_control", ("third_party", "kinova", "jaco_arm.xml")),
        ("dm_control", ("third_party", "kinova", "jaco_hand.xml")),
    ],
)
def test_jaco_files_with_two_top_level_defaults(package, parts, mujoco):
    # jaco_arm.xml and jaco_hand.xml include common.xml, whose <default> is a second top-level
    # one; their masses come from STL meshes (item 2): every body's mass is MuJoCo's, and the
    # rest pinsettle finds is one by MuJoCo's forces.
    path = model_file(package, *parts)
    mj = mujoco.MjModel.from_xml_path(str(path))
    mjcf = load_mjcf(path)
    for j in range(mj.njnt):
        name = mj.joint(j).name
        iq = mjcf.model.idx_qs[mjcf.model.getJointId(name)]
        if mj.jnt_limited[j]:
            assert mjcf.model.lowerPositionLimit[iq] == pytest.approx(mj.jnt_range[j][0])
            assert mjcf.model.upperPositionLimit[iq] == pytest.approx(mj.jnt_range[j][1])
    assert assert_inertias_are_mujocos(mujoco, path) == mj.nbody - 1
    assert_rest_is_mujocos(mujoco, path, solve_json(str(path)))


# --- masses from meshes ----------------------------------------------------------------------


def u_prism() -> tuple[np.ndarray, list[list[int]]]:
    """A closed, outward-facing U-shaped prism whose centre of mass sees the inner faces of
    its posts from behind: MuJoCo's legacy, exact and convex rules give three different
    masses. Side faces are quads, the ends triangles."""
    outline = [(0, 0), (1, 0), (2, 0), (3, 0), (3, 1), (3, 2), (2, 2), (2, 1), (1, 1), (1, 2)]
    outline += [(0, 2), (0, 1)]  # counter-clockwise
    n = len(outline)
    vertices = np.array([(x, y, z) for z in (0.0, 0.5) for x, y in outline], dtype=float)
    vertices = 0.1 * vertices + [0.3, -0.1, 0.05]
    cells = [[0, 1, 8, 11], [11, 8, 9, 10], [1, 2, 7, 8], [2, 3, 4, 7], [7, 4, 5, 6]]
    ends = [t for a, b, c, d in cells for t in ([a, b, c], [a, c, d])]
    faces = [[a, c, b] for a, b, c in ends] + [[n + a, n + b, n + c] for a, b, c in ends]
    faces += [[i, (i + 1) % n, n + (i + 1) % n, n + i] for i in range(n)]
    return vertices, faces


def triangles(faces: list[list[int]]) -> list[list[int]]:
    return [
        t for f in faces for t in ([f] if len(f) == 3 else [[f[0], f[1], f[2]], [f[0], f[2], f[3]]])
    ]


def write_stl(path: Path, vertices: np.ndarray, faces: list[list[int]]) -> Path:
    tris = triangles(faces)
    records = np.zeros(len(tris), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    records["v"] = vertices[np.array(tris)]
    path.write_bytes(b"\0" * 80 + np.uint32(len(tris)).tobytes() + records.tobytes())
    return path


def write_obj(path: Path, vertices: np.ndarray, faces: list[list[int]]) -> Path:
    # Quads as quads; a second object after the first, whose faces MuJoCo does not read.
    lines = ["# a U prism", "o first"]
    lines += ["v " + " ".join(repr(float(c)) for c in v) for v in vertices]
    lines += [
        "f " + " ".join(f"{i + 1}//" if k % 2 else str(i + 1) for i in f)
        for k, f in enumerate(faces)
    ]
    lines += ["o second", "v 5 5 5", "v 6 5 5", "v 5 6 5", "f -1 -2 -3"]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_msh(path: Path, vertices: np.ndarray, faces: list[list[int]]) -> Path:
    tris = np.array(triangles(faces), dtype="<i4")
    header = np.array([len(vertices), 0, 0, len(tris)], dtype="<i4")
    path.write_bytes(header.tobytes() + vertices.astype("<f4").tobytes() + tris.tobytes())
    return path


WRITERS = {"stl": write_stl, "obj": write_obj, "msh": write_msh}


def mesh_mjcf(file: str, mesh_attrs: str = "", geom_attrs: str = "", extra: str = "") -> str:
    return f"""<mujoco model="meshes">
  <compiler angle="radian"/>
  <asset><mesh file="{file}" {mesh_attrs}/></asset>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="shoulder" axis="0 1 0"/>
      <geom name="part" type="mesh" mesh="{Path(file).stem}" pos="0.1 0 0" euler="0.3 0.2 0.1"
        {geom_attrs}/>
      {extra}
      <body name="hand" pos="0.4 0 0"><joint name="wrist" axis="0 1 0"/>
        <geom type="mesh" mesh="{Path(file).stem}" density="300"/>
      </body>
    </body>
  </worldbody>
</mujoco>"""


@pytest.mark.parametrize(
    "rule", ["", 'inertia="legacy"', 'inertia="exact"', 'inertia="convex"', 'inertia="shell"']
)
@pytest.mark.parametrize("kind", ["stl", "obj", "msh"])
def test_mesh_masses_are_mujocos(kind, rule, tmp_path, mujoco):
    vertices, faces = u_prism()
    WRITERS[kind](tmp_path / f"you.{kind}", vertices, faces)
    path = tmp_path / "meshes.xml"
    path.write_text(mesh_mjcf(f"you.{kind}", rule))
    assert assert_inertias_are_mujocos(mujoco, path) == 2
    # The rules differ on this mesh: the test tells them apart.
    masses = {}
    for other in ("legacy", "exact", "convex"):
        path.write_text(mesh_mjcf(f"you.{kind}", f'inertia="{other}"'))
        masses[other] = load_mjcf(path).inertias["hand"][0]
    assert len({round(m, 9) for m in masses.values()}) == 3, masses


@pytest.mark.parametrize(
    "mesh_attrs, geom_attrs, extra",
    [
        ('scale="1 2 -0.5" refpos="0.3 -0.1 0" refquat="0.9 0.1 0.3 -0.2"', "", ""),
        ('scale="2 2 2"', 'mass="3"', '<geom type="box" size="0.1 0.02 0.03" pos="0 0.1 0"/>'),
        (
            'inertia="exact"',
            'density="50" group="4"',
            '<geom type="capsule" fromto="0 0 0 0 0 0.2" size="0.02" shellinertia="true"/>',
        ),
        (
            "",
            'group="2"',
            '<geom type="cylinder" size="0.02 0.1" mass="0.2" shellinertia="true"/>'
            '<geom type="ellipsoid" size="0.02 0.03 0.05" euler="1 0 0" shellinertia="true"/>'
            '<geom type="box" size="0.02 0.03 0.05" shellinertia="true"/>'
            '<geom type="sphere" size="0.04" shellinertia="true" pos="0 0 0.3"/>'
            '<geom type="box" fromto="0 0 0 0.1 0.1 0" size="0.02 0.02 0.02"/>',
        ),
    ],
)
def test_mesh_and_shape_masses_are_mujocos(mesh_attrs, geom_attrs, extra, tmp_path, mujoco):
    # Scale (a mirroring one too), refpos and refquat, a geom's mass instead of its density,
    # groups outside the inertia range, primitives beside the mesh, shells.
    vertices, faces = u_prism()
    write_stl(tmp_path / "you.stl", vertices, faces)
    path = tmp_path / "meshes.xml"
    path.write_text(mesh_mjcf("you.stl", mesh_attrs, geom_attrs, extra))
    assert assert_inertias_are_mujocos(mujoco, path) == 2


def test_mesh_masses_of_the_fused_fruit_fly(mujoco):
    # dm_control's fused fruit fly: 61 bodies whose masses come from MSH meshes and
    # primitives, several geoms a body.
    path = model_file(
        "dm_control",
        "locomotion",
        "walkers",
        "assets",
        "build_fruitfly",
        "assets",
        "drosophila_fused.xml",
    )
    assert assert_inertias_are_mujocos(mujoco, path) == 61


def test_mesh_vertices_in_the_file(tmp_path, mujoco):
    # A mesh given by its vertices only (MuJoCo takes their convex hull) and one with faces.
    vertices, faces = u_prism()
    text = " ".join(repr(float(x)) for x in vertices.ravel())
    face = " ".join(str(i) for t in triangles(faces) for i in t)
    path = tmp_path / "inline.xml"
    path.write_text(
        f"""<mujoco><asset><mesh name="hull" vertex="{text}"/>
        <mesh name="you" vertex="{text}" face="{face}" inertia="exact"/></asset>
        <worldbody><body name="a"><joint axis="0 1 0"/><geom type="mesh" mesh="hull"/>
        <body name="b" pos="0.3 0 0"><joint axis="0 1 0"/><geom type="mesh" mesh="you"/>
        </body></body></worldbody></mujoco>"""
    )
    assert assert_inertias_are_mujocos(mujoco, path) == 2


def test_mesh_refusals_name_the_file_and_a_way_forward(tmp_path):
    body = '<body name="b"><joint name="j"/><geom name="shell" type="mesh" mesh="part"/></body>'

    def refusal(file: str) -> str:
        path = tmp_path / "mesh.xml"
        path.write_text(
            f'<mujoco><asset><mesh name="part" file="{file}"/></asset><worldbody>{body}'
            "</worldbody></mujoco>"
        )
        with pytest.raises(pinsettle.SceneError) as error:
            pinsettle.load_scene(path)
        message = str(error.value)
        assert "<geom name=\"shell\"> of body 'b'" in message and str(tmp_path / file) in message
        assert "<inertial>" in message and len(message) < 600
        return message

    (tmp_path / "ascii.stl").write_text("solid part\n facet normal 0 0 1\nendsolid part\n")
    assert "ASCII STL" in refusal("ascii.stl") and "binary STL" in refusal("ascii.stl")
    (tmp_path / "part.ply").write_text("ply\nformat ascii 1.0\nend_header\n")
    message = refusal("part.ply")
    assert "'.ply'" in message and "STL or OBJ" in message
    vertices, faces = u_prism()
    flat = vertices.copy()
    flat[:, 2] = 0.0  # no volume
    write_stl(tmp_path / "flat.stl", flat, faces)
    assert 'inertia="shell"' in refusal("flat.stl")


# --- <flag limit="disable"/> and tendons ------------------------------------------------------

TENDONS = """<mujoco model="tendons">
  <compiler angle="radian"/>
  {option}
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" axis="0 1 0" range="-0.5 0.5"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02"/>
      <body name="lower" pos="0.3 0 0">
        <joint name="elbow" axis="0 1 0" stiffness="2" springref="0.3"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02"/>
      </body>
    </body>
  </worldbody>
  <tendon>
    <fixed name="coupling" range="-0.1 0.1" stiffness="{stiffness}">
      <joint joint="shoulder" coef="1"/><joint joint="elbow" coef="-1"/>
    </fixed>
  </tendon>
</mujoco>"""


@pytest.mark.parametrize(
    "option, stiffness, refused",
    [
        ("", "0", "tendon limit"),
        ('<option><flag limit="disable"/></option>', "0", None),
        ('<option><flag constraint="disable"/></option>', "0", None),
        ('<option><flag limit="disable"/></option>', "5", "tendon spring"),
        ('<option><flag limit="disable" spring="disable"/></option>', "5", None),
    ],
)
def test_disabled_limits_and_springs_reach_tendons(option, stiffness, refused, tmp_path, mujoco):
    # MuJoCo's limit flag disables tendon ranges as it does joint ranges, its spring flag
    # tendon springs as joint springs; the rest is then the one MuJoCo's forces hold.
    path = tmp_path / "tendons.xml"
    path.write_text(TENDONS.format(option=option, stiffness=stiffness))
    if refused:
        with pytest.raises(MjcfError, match=refused):
            load_mjcf(path)
        return
    notes = " | ".join(load_mjcf(path).notes)
    assert "ranges of tendons coupling not applied: limits are disabled" in notes
    assert ("springs of tendons coupling not applied" in notes) == (stiffness != "0")
    out = solve_json(str(path))
    assert_rest_is_mujocos(mujoco, path, out)
    # Joint ranges are off too: the shoulder hangs past its range's 0.5.
    assert out["at_limit"] == {} and abs(out["joints"]["shoulder"]) > 0.5


def copy_of_assets(tmp_path: Path, assets: Path, folder: str) -> Path:
    """A writable copy of a package's model folder, its shared meshes and textures linked."""
    import shutil

    shutil.copytree(assets / folder, tmp_path / folder)
    for shared in assets.iterdir():
        if shared.is_dir() and shared.name != folder:
            (tmp_path / shared.name).symlink_to(shared, target_is_directory=True)
    return tmp_path / folder


def test_shadow_hand_with_limits_disabled(tmp_path, mujoco):
    # gymnasium_robotics' Shadow hand (hand/reach.xml) has 44 fixed tendons with ranges: with
    # <flag limit="disable"/> added, it loads and rests where MuJoCo's forces hold it.
    assets = require("gymnasium_robotics") / "envs" / "assets"
    original = model_file("gymnasium_robotics", "envs", "assets", "hand", "reach.xml")
    folder = copy_of_assets(tmp_path, assets, "hand")
    text = original.read_text()
    assert 'limit="disable"' not in text  # the file as shipped: its tendon ranges hold
    path = folder / "reach_without_limits.xml"
    flag = '<option><flag limit="disable"/></option>'
    path.write_text(text.replace("</compiler>", f"</compiler>{flag}", 1))
    notes = " | ".join(load_mjcf(path).notes)
    assert "ranges of tendons robot0:T_WRJ1r" in notes and "and 40 more not applied" in notes
    # Judged by MuJoCo's forces without contacts: the file's floor left out.
    assert_rest_is_mujocos(mujoco, path, solve_json(str(path), "--no-contacts"))


# --- free objects beside a robot; a file's own free joint ---------------------------------------

OBJECTS = """<mujoco model="objects">
  <compiler angle="radian"/>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1"/>
    <body name="table" pos="0.6 0 0.2"><geom type="box" size="0.3 0.3 0.2"/></body>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" axis="0 1 0" stiffness="30" springref="0.2"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
      <body name="lower" pos="0.3 0 0">
        <joint name="elbow" axis="0 1 0" stiffness="10"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
      </body>
    </body>
    <body name="crate" pos="0.6 0.1 0.45" euler="0.1 0.2 0.3">
      <freejoint name="crate_free"/>
      <geom type="box" size="0.05 0.05 0.05"/>
    </body>
    <body name="ball" pos="0.5 -0.1 0.45" quat="0.9 0.1 0.2 0.3">
      <joint name="ball_free" type="free"/>
      <geom type="sphere" size="0.04"/>
      <body name="handle" pos="0 0 0.05"><geom type="capsule" size="0.01 0.03"/></body>
    </body>
  </worldbody>
  <keyframe><key name="raised" qpos="0.5 -0.3 0.6 0.1 0.45 1 0 0 0 0.5 -0.1 0.45 1 0 0 0"/>
  </keyframe>
</mujoco>"""


def assert_bodies_where_mujoco_puts_them(mujoco, path: Path, scene, qpos) -> None:
    """Every body's world pose in pinsettle's model at the scene's start equals MuJoCo's at
    qpos (locked objects: where the file places them)."""
    mj = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(mj)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(mj, data)
    model = scene.model
    pdata = model.createData()
    pinocchio.framesForwardKinematics(model, pdata, scene.q0())
    for b in range(1, mj.nbody):
        frame = model.getFrameId(body_name(mj, b), pinocchio.FrameType.BODY)
        placement = pdata.oMf[frame]
        assert np.abs(placement.translation - data.xpos[b]).max() < 1e-12, body_name(mj, b)
        assert np.abs(placement.rotation - data.xmat[b].reshape(3, 3)).max() < 1e-12


def test_free_objects_kept_fall(tmp_path, mujoco):
    # Without the file's floor (contacts "none"), nothing holds the free objects.
    path = tmp_path / "objects.xml"
    path.write_text(OBJECTS)
    scene = pinsettle.load_scene(path, contacts="none")
    kinds = {scene.model.names[j]: scene.model.joints[j].shortname() for j in range(1, 5)}
    assert kinds["crate_free"] == kinds["ball_free"] == "JointModelFreeFlyer"
    notes = " | ".join(scene.notes)
    assert "free objects crate, ball kept free" in notes and "--free-objects lock" in notes
    mj = mujoco.MjModel.from_xml_path(str(path))
    assert_bodies_where_mujoco_puts_them(mujoco, path, scene, mj.qpos0)
    out = solve_json(str(path), "--no-contacts")
    assert out["status"] == "no_equilibrium"
    assert "crate_free" in out["reason"] or "ball_free" in out["reason"], out["reason"]


def test_free_objects_locked_where_the_file_places_them(tmp_path, mujoco):
    path = tmp_path / "objects.xml"
    path.write_text(OBJECTS)
    # Judged by MuJoCo's forces without contacts: the file's floor left out.
    scene = pinsettle.load_scene(path, free_objects="lock", contacts="none")
    assert list(scene.model.names)[1:] == ["shoulder", "elbow"]
    assert "free objects crate, ball locked where the file places them" in scene.notes[-1]
    mj = mujoco.MjModel.from_xml_path(str(path))
    assert_bodies_where_mujoco_puts_them(mujoco, path, scene, mj.qpos0)
    # A keyframe moves the arm; the locked objects stay where the file places them.
    scene.set_pose("raised")
    key = mj.key("raised").qpos.copy()
    key[2:] = mj.qpos0[2:]
    assert_bodies_where_mujoco_puts_them(mujoco, path, scene, key)
    out = solve_json(str(path), "--free-objects", "lock", "--no-contacts")
    assert_rest_is_mujocos(mujoco, path, out, free_objects="lock")
    # The same through a scene file's [model] free_objects.
    toml = tmp_path / "objects.toml"
    toml.write_text('[model]\nmjcf = "objects.xml"\nfree_objects = "lock"\ncontacts = "none"\n')
    assert solve_json(str(toml))["joints"] == out["joints"]


def test_free_objects_errors(tmp_path):
    path = tmp_path / "objects.xml"
    path.write_text(OBJECTS)
    line = one_line_error(run("solve", str(path), "--free-objects", "lock", "--floating"))
    assert "floating: 2 top-level bodies (table, upper) beside the free objects" in line
    toml = tmp_path / "bad.toml"
    toml.write_text('[model]\nmjcf = "objects.xml"\nfree_objects = "hold"\n')
    line = one_line_error(run("solve", str(toml)))
    assert "[model] free_objects must be 'keep'" in line and "'hold'" in line
    only = tmp_path / "only.xml"  # nothing but a free object: locked, nothing is left
    only.write_text(
        '<mujoco><worldbody><body name="box" pos="0 0 1"><freejoint/><geom size="0.1"/>'
        "</body></worldbody></mujoco>"
    )
    line = one_line_error(run("solve", str(only), "--free-objects", "lock"))
    assert "nothing to settle" in line and 'free_objects = "keep"' in line
    urdf = Path(pinsettle.robot_urdf("ur5"))
    line = one_line_error(run("solve", str(urdf), "--free-objects", "lock"))
    assert "free_objects applies to an MJCF file" in line


def test_thrower_with_its_free_object(mujoco):
    # pybullet's thrower.xml: an arm beside a free ball ('object'). Kept, the ball falls and
    # the solve names it; locked, the arm rests where MuJoCo's forces hold it.
    # Without the file's floor (--no-contacts): MuJoCo's forces without contacts judge it.
    path = model_file("pybullet_data", "mjcf", "thrower.xml")
    out = solve_json(str(path), "--no-contacts")
    assert out["status"] == "no_equilibrium" and "'object_free'" in out["reason"]
    locked = solve_json(str(path), "--free-objects", "lock", "--no-contacts")
    assert_rest_is_mujocos(mujoco, path, locked, free_objects="lock")


@pytest.mark.parametrize("task", ["pick_and_place.xml", "push.xml", "slide.xml"])
def test_fetch_tasks_with_a_free_object(task, mujoco):
    # gymnasium_robotics' Fetch tasks: the robot of reach.xml beside a free block. They load;
    # locked, the block is where MuJoCo puts it, and the robot is reach.xml's (same joints,
    # the same masses as MuJoCo's).
    path = model_file("gymnasium_robotics", "envs", "assets", "fetch", task)
    reach = model_file("gymnasium_robotics", "envs", "assets", "fetch", "reach.xml")
    # The models alone: contacts "none" (the file's floor and the meshes' hulls not read).
    kept = pinsettle.load_scene(path, contacts="none")
    assert kept.model.names[-1] == "object0:joint" and "object0 kept free" in kept.notes[-1]
    locked = pinsettle.load_scene(path, free_objects="lock", contacts="none")
    reach_names = pinsettle.load_scene(reach, contacts="none").model.names
    assert list(locked.model.names) == list(reach_names)
    mj = mujoco.MjModel.from_xml_path(str(path))
    assert_bodies_where_mujoco_puts_them(mujoco, path, locked, mj.qpos0)
    assert assert_inertias_are_mujocos(mujoco, path, free_objects="lock") == 20


FREE_ROBOT = """<mujoco model="free">
  <worldbody>
    <body name="torso" pos="0 0 1.2" quat="0.9 0 0.3 0.1">
      <freejoint name="root"/>
      <geom type="capsule" size="0.1 0.2"/>
      <body name="arm" pos="0 0 -0.3"><joint name="shoulder" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.04"/></body>
    </body>
  </worldbody>
</mujoco>"""


def test_a_files_own_free_joint_floats_as_the_help_says(tmp_path, mujoco):
    # The file's <freejoint> floats without --floating (MuJoCo's meaning); --floating adds
    # nothing to it and says so; the help says both.
    path = tmp_path / "free.xml"
    path.write_text(FREE_ROBOT)
    help_text = " ".join(run("solve", "--help").stdout.split())
    assert "free by an MJCF <freejoint>, which floats without this flag" in help_text
    for flags in [(), ("--floating",)]:
        scene = pinsettle.load_scene(path, floating=True if flags else None)
        assert scene.model.names[1] == "root" and scene.model.nq == 8
        mj = mujoco.MjModel.from_xml_path(str(path))
        assert_bodies_where_mujoco_puts_them(mujoco, path, scene, mj.qpos0)
        floats = any("floats by the file's own free joint 'root'" in n for n in scene.notes)
        assert floats == bool(flags)
        out = solve_json(str(path), "--max-steps", "200", *flags)
        assert len(out["joints"]["root"]) == 7 and out["notes"] == scene.notes


# --- position actuators as joint springs ------------------------------------------------------

ACTUATED = """<mujoco model="actuated">
  <compiler angle="degree"/>
  <default>
    <position kp="25"/>
    <default class="stiff"><position kp="60" ctrlrange="-0.3 0.4"/></default>
  </default>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder" axis="0 1 0" stiffness="3" range="-120 120"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
      <body name="lower" pos="0.3 0 0">
        <joint name="elbow" axis="0 1 0" range="-90 150"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
        <body name="slider" pos="0.3 0 0">
          <joint name="slide" type="slide" axis="1 0 1"/>
          <geom type="box" size="0.03 0.03 0.03"/>
          <body name="tip" pos="0.1 0 0">
            <joint name="wrist" axis="0 1 0"/>
            <geom type="capsule" fromto="0 0 0 0.1 0 0" size="0.02"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="shoulder_servo" joint="shoulder" class="stiff" gear="2" kv="3"/>
    <position name="elbow_servo" joint="elbow" timeconst="0.02" inheritrange="0.5"/>
    <general name="slide_servo" joint="slide" gainprm="40" biastype="affine"
      biasprm="1 -40 -2" ctrlrange="-1 1"/>
    <position name="wrist_servo" jointinparent="wrist" kp="2" forcerange="-1 1"/>
    <motor name="wrist_motor" joint="wrist"/>
  </actuator>
  <keyframe>
    <key name="reach" qpos="0.2 0.3 0 0" ctrl="0.9 0.5 0.2 -0.4 0.3"/>
  </keyframe>
</mujoco>"""


def spring_forces(scene, q: np.ndarray) -> dict[str, float]:
    """Each joint's force from pinsettle's joint springs at q."""
    model = scene.model
    out: dict[str, float] = {}
    for spring in scene.joint_springs:
        iq = model.idx_qs[model.getJointId(spring.joint)]
        out[spring.joint] = out.get(spring.joint, 0.0) - spring.stiffness * (q[iq] - spring.rest)
    return out


@pytest.mark.parametrize("pose", [None, "reach"])
def test_position_actuators_are_mujocos_force(pose, tmp_path, mujoco):
    # pinsettle's springs give MuJoCo's qfrc_passive + qfrc_actuator at rest (qvel = 0), at
    # random positions, for ctrl 0 and a keyframe's ctrl (clamped to ctrlrange as MuJoCo
    # clamps it; inheritrange; a general affine actuator; gear; jointinparent).
    path = tmp_path / "actuated.xml"
    path.write_text(ACTUATED)
    scene = pinsettle.Scene.from_mjcf(path, actuator_springs=True)
    mj = mujoco.MjModel.from_xml_path(str(path))
    ctrl = np.zeros(mj.nu)
    if pose:
        scene.set_pose(pose)
        ctrl = mj.key(pose).ctrl.copy()
    ctrl[mj.actuator("wrist_motor").id] = 0  # a motor is no spring: left out
    data = mujoco.MjData(mj)
    rng = np.random.default_rng(7)
    for _ in range(5):
        q = rng.uniform(-0.4, 0.4, mj.nq)
        data.qpos[:] = q
        data.qvel[:] = 0
        data.ctrl[:] = ctrl
        steady_activation(mj, data)
        mujoco.mj_forward(mj, data)
        ours = spring_forces(scene, q)  # Pinocchio's q is MuJoCo's qpos here: hinges, a slide
        for j in range(mj.njnt):
            name = mj.joint(j).name
            expected = data.qfrc_passive[j] + data.qfrc_actuator[j]
            if name == "wrist" and abs(data.actuator_force[mj.actuator("wrist_servo").id]) >= 1:
                continue  # its force range clamps MuJoCo's force: a note says so
            assert ours.get(name, 0.0) == pytest.approx(expected, abs=1e-12), name
    notes = " | ".join(scene.notes)
    assert "shoulder_servo on shoulder (240)" in notes and "wrist_motor" in notes
    assert "forcerange of actuators wrist_servo not applied" in notes


def test_position_actuator_rest_is_mujocos(tmp_path, mujoco):
    path = tmp_path / "actuated.xml"
    path.write_text(ACTUATED)
    mj = mujoco.MjModel.from_xml_path(str(path))
    out = solve_json(str(path), "--actuator-springs")
    assert_rest_is_mujocos(mujoco, path, out, np.zeros(mj.nu), actuator_springs=True)
    # From a scene file, at the keyframe's controls (the motor's left out: no spring).
    toml = tmp_path / "reach.toml"
    toml.write_text(
        '[model]\nmjcf = "actuated.xml"\nactuator_springs = true\n[start]\npose = "reach"\n'
    )
    ctrl = mj.key("reach").ctrl.copy()
    ctrl[mj.actuator("wrist_motor").id] = 0
    assert_rest_is_mujocos(mujoco, path, solve_json(str(toml)), ctrl, actuator_springs=True)
    # Without the option the actuators are left out, and a note says how to keep them.
    notes = " | ".join(pinsettle.load_scene(path).notes)
    assert "--actuator-springs" in notes and "ignored: 5 actuators" in notes


def test_position_actuators_that_cannot_be_springs_are_refused(tmp_path):
    path = tmp_path / "tendon.xml"
    path.write_text(
        TENDONS.format(option='<option><flag limit="disable"/></option>', stiffness="0").replace(
            "</mujoco>",
            '<actuator><position name="pull" tendon="coupling" kp="3"/>'
            '<position name="spot" site="nowhere" kp="3"/></actuator></mujoco>',
        )
    )
    assert "ignored: 2 actuators (pull, spot)" in " | ".join(load_mjcf(path).notes)
    line = one_line_error(run("solve", str(path), "--actuator-springs"))
    assert '<position name="pull"> in <actuator> (a position actuator on a tendon' in line
    assert "a position actuator on a site" in line and "leave actuator_springs off" in line


def test_shadow_hand_position_actuators(tmp_path, mujoco):
    # gymnasium_robotics' Shadow hand (limits disabled as above): its 20 position actuators as
    # springs towards ctrl 0; the rest is one by MuJoCo's forces with the actuators on.
    assets = require("gymnasium_robotics") / "envs" / "assets"
    original = model_file("gymnasium_robotics", "envs", "assets", "hand", "reach.xml")
    folder = copy_of_assets(tmp_path, assets, "hand")
    path = folder / "reach_without_limits.xml"
    flag = '<option><flag limit="disable"/></option>'
    path.write_text(original.read_text().replace("</compiler>", f"</compiler>{flag}", 1))
    out = solve_json(str(path), "--actuator-springs")
    mj = mujoco.MjModel.from_xml_path(str(path))
    assert mj.nu == 20 and "robot0:A_WRJ1 on robot0:WRJ1 (5)" in " | ".join(out["notes"])
    assert_rest_is_mujocos(mujoco, path, out, np.zeros(mj.nu), actuator_springs=True)


# --- refusals: short, with a way forward -------------------------------------------------------


@pytest.mark.parametrize(
    "package, parts, fragments",
    [
        (
            "gymnasium_robotics",
            ("envs", "assets", "hand", "reach.xml"),
            [
                '<fixed name="robot0:T_WRJ1r">',
                "and 41 more in <tendon> with a range",
                '<flag limit="disable"/>',
            ],
        ),
        (
            "dm_control",
            ("suite", "quadruped.xml"),
            ['<tendon name="coupling_front_left"> in <equality>', '<flag equality="disable"/>'],
        ),
        (
            "dm_control",
            ("locomotion", "walkers", "assets", "build_fruitfly", "fruitfly.xml"),
            ["85 asset files not found", "and 83 more (looked for in", "meshdir"],
        ),
    ],
)
def test_refusals_of_real_files_are_short_with_a_way_forward(package, parts, fragments):
    # The Shadow hand's refusal was 3 kB on one line: now a few names, a count, what to do.
    path = model_file(package, *parts)
    line = one_line_error(run("solve", str(path)))
    message = line.removeprefix("pinsettle: error: ").removeprefix(str(path))
    assert len(message) < 400, message
    for fragment in fragments:
        assert fragment in message, message


def test_refusals_group_by_kind(tmp_path):
    joints = (
        "".join(
            f'<body name="b{k}"><joint name="j{k}" type="ball" range="0 30"/><geom size="0.1"/>'
            for k in range(12)
        )
        + "</body>" * 12
    )
    path = tmp_path / "many.xml"
    path.write_text(
        f'<mujoco><option density="1.2"/><worldbody><body name="top" gravcomp="1">'
        f'<joint name="top"/><geom size="0.1"/>{joints}</body></worldbody></mujoco>'
    )
    message = str(pytest.raises(MjcfError, load_mjcf, path).value)
    assert (
        '<joint name="j0">, <joint name="j1">, <joint name="j2"> and 9 more with a range' in message
    )
    assert "<option density> (buoyancy" in message and "gravcomp" in message
    assert message.count("remove the range") == 1 and len(message) < 700


@pytest.mark.parametrize(
    "task", ["manipulate_block.xml", "manipulate_egg.xml", "manipulate_pen.xml"]
)
def test_hand_manipulate_tasks_with_their_free_objects(task, tmp_path, mujoco):
    # gymnasium_robotics' hand manipulate tasks: the Shadow hand beside a free object and a
    # free target. Their tendon ranges are refused with the way forward; with limits disabled,
    # kept objects fall (no_equilibrium naming one), locked ones leave the hand a rest MuJoCo's
    # forces confirm.
    assets = require("gymnasium_robotics") / "envs" / "assets"
    original = model_file("gymnasium_robotics", "envs", "assets", "hand", task)
    line = one_line_error(run("solve", str(original)))
    assert "tendon limit" in line and '<flag limit="disable"/>' in line
    folder = copy_of_assets(tmp_path, assets, "hand")
    path = folder / f"without_limits_{task}"
    flag = '<option><flag limit="disable"/></option>'
    path.write_text(original.read_text().replace("</compiler>", f"</compiler>{flag}", 1))
    # Without the file's floor (--no-contacts), judged by MuJoCo's forces without contacts.
    kept = solve_json(str(path), "--no-contacts")
    assert kept["status"] == "no_equilibrium"
    assert "'object:joint'" in kept["reason"] or "'target:joint'" in kept["reason"]
    locked = solve_json(str(path), "--free-objects", "lock", "--no-contacts")
    assert_rest_is_mujocos(mujoco, path, locked, free_objects="lock")

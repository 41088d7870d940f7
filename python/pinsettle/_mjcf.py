"""MuJoCo MJCF model files: everything MJCF says about statics, honoured or refused by name.

The model (bodies, joints, masses) is built by Pinocchio's MJCF parser
(``pinocchio.buildModelFromMJCF``), but not from the user's file as it is: Pinocchio 4.1 reads
only part of MJCF and drops the rest without a word (the bodies of a ``<frame>``, every
top-level body but the first, ``<include>``, the placement of a fixed root body and of a free
body, ``limited="false"``; it shifts ranges by ``ref``). So the file is read here first, with
MuJoCo's rules (``<include>``, ``<default>`` classes and ``childclass``, ``<frame>``, the five
ways to write an orientation, ``<compiler angle eulerseq autolimits inertiafromgeom>``), and
written again in the plain subset Pinocchio reads right: one joint per body (a body with
several joints becomes a chain of massless bodies, one joint each, as MuJoCo composes them),
positions and quaternions only, no defaults, one root. Pinocchio builds the model from that.

What Pinocchio does not carry is taken from the file here: gravity (``<option gravity>`` and
the ``gravity`` flag), joint ranges as stops (``limited``/``autolimits``, degrees), joint
springs (``stiffness``, ``springref``), the reference pose ``qpos0`` (``ref``, the pose of a
free body) as the start, ``connect`` and ``weld`` equalities as loops, keyframes as named
poses. Each body's mass is computed here as MuJoCo compiles it (its ``<inertial>``, or its
geoms: primitives and meshes, from their volume) and written as an ``<inertial>``. What has
no place in statics with constant loads (damping, friction loss, armature, actuators) is
listed in ``notes``. What changes the statics and cannot be honoured (tendons with springs or
limits, ``joint`` equalities, gravity compensation, buoyancy, ...) is an error that names the
element.
"""

from __future__ import annotations

import math
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio


class MjcfError(ValueError):
    """An MJCF file that cannot be read or whose statics cannot be honoured."""


@dataclass
class MjcfModel:
    """An MJCF file read for statics.

    ``model`` has the file's gravity, its joint ranges as position limits (infinite where a
    joint is not limited) and its keyframes and ``qpos0`` as reference configurations;
    ``joint_springs`` are (joint, stiffness, rest); ``loops`` are (frame_a, point_a, frame_b,
    point_b, kind) as ``Scene.add_loop`` takes them (frames added to the model where an end
    needs an orientation); ``start`` is ``qpos0`` by joint name where it is not the neutral
    configuration; ``notes`` say what was read and left out.
    """

    model: pinocchio.Model
    name: str
    joint_springs: list[tuple[str, float, float]] = field(default_factory=list)
    loops: list[tuple[str, tuple[float, ...], str, tuple[float, ...], str]] = field(
        default_factory=list
    )
    start: dict[str, float | list[float]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    #: Position actuators as joint springs (``actuator_springs``): (joint, stiffness, rest)
    #: at ctrl 0, and for each pose (keyframes, qpos0) the rests at its ctrl, in that order.
    actuator_springs: list[tuple[str, float, float]] = field(default_factory=list)
    actuator_rests: dict[str, list[float]] = field(default_factory=dict)
    #: Each body's mass, centre of mass and rotational inertia about it, in the body's frame,
    #: as MuJoCo compiles them (from its <inertial> or its geoms); massless bodies left out.
    inertias: dict[str, tuple[float, np.ndarray, np.ndarray]] = field(default_factory=dict)


def is_mjcf(path: str | Path) -> bool:
    """Whether the file is XML with a ``<mujoco>`` root element."""
    try:
        return _parse(Path(path)).tag == "mujoco"
    except (MjcfError, OSError):
        return False


# --- small readers ---------------------------------------------------------------------------


def _parse(path: Path) -> ET.Element:
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as error:
        raise MjcfError(f"{path}: not well-formed XML: {error}") from None


def _describe(el: ET.Element) -> str:
    name = el.get("name")
    return f'<{el.tag} name="{name}">' if name else f"<{el.tag}>"


def _floats(text: str, where: str, counts: Sequence[int]) -> np.ndarray:
    """The numbers of an attribute, with one of the allowed counts."""
    try:
        values = [float(x) for x in text.split()]
    except ValueError:
        raise MjcfError(f"{where}: expected numbers, got '{text}'") from None
    if len(values) not in counts:
        expected = " or ".join(str(n) for n in counts)
        raise MjcfError(f"{where}: expected {expected} numbers, got {len(values)} ('{text}')")
    if not all(math.isfinite(x) for x in values):
        raise MjcfError(f"{where}: numbers must be finite, got '{text}'")
    return np.array(values, dtype=float)


def _flag(text: str, where: str, choices: Sequence[str]) -> str:
    if text not in choices:
        raise MjcfError(f"{where}: expected one of {', '.join(choices)}, got '{text}'")
    return text


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    rotation: np.ndarray = pinocchio.AngleAxis(angle, axis).matrix()
    return rotation


def _z_to(vector: np.ndarray, where: str) -> np.ndarray:
    """MuJoCo's minimal rotation taking +z to ``vector`` (``mjuu_z2quat``)."""
    norm = float(np.linalg.norm(vector))
    if norm < 1e-14:
        raise MjcfError(f"{where}: zero-length direction")
    v = vector / norm
    cross = np.cross([0.0, 0.0, 1.0], v)
    s = float(np.linalg.norm(cross))
    axis = np.array([1.0, 0.0, 0.0]) if s < 1e-10 else cross / s
    return _rotation(axis, math.atan2(s, v[2]))


def _to_se3(rotation: np.ndarray, translation: Any) -> pinocchio.SE3:
    return pinocchio.SE3(np.asarray(rotation, float), np.asarray(translation, float))


def _text(values: Any) -> str:
    return " ".join(repr(float(x)) for x in np.ravel(values))


def _quat_wxyz(rotation: np.ndarray) -> np.ndarray:
    x, y, z, w = pinocchio.Quaternion(rotation).coeffs()
    return np.array([w, x, y, z])


# --- the file as MuJoCo reads it -------------------------------------------------------------


@dataclass
class _Compiler:
    degree: bool = True
    eulerseq: str = "xyz"
    autolimits: bool = True
    inertiafromgeom: str = "auto"
    inertiagrouprange: tuple[int, int] = (0, 5)
    boundmass: float = 0.0
    boundinertia: float = 0.0
    meshdir: str | None = None
    texturedir: str | None = None
    assetdir: str | None = None
    strippath: bool = False

    @property
    def angle(self) -> float:
        """Radians per unit of the file's angles."""
        return math.pi / 180.0 if self.degree else 1.0


@dataclass
class _Joint:
    name: str
    kind: str  # hinge, slide, ball, free
    pos: np.ndarray  # in the body frame
    axis: np.ndarray  # unit, in the body frame
    attrs: dict[str, str]
    body: str
    ref: float = 0.0  # rad or m: the joint's value in the file's pose


@dataclass
class _Geom:
    attrs: dict[str, str]
    pose: pinocchio.SE3  # in the body frame
    fromto: np.ndarray | None  # the two end points, in the body frame
    label: str


@dataclass
class _Body:
    name: str
    pose: pinocchio.SE3  # relative to the parent body
    element: ET.Element
    joints: list[_Joint] = field(default_factory=list)
    inertial: ET.Element | None = None
    inertial_pose: pinocchio.SE3 | None = None
    geoms: list[_Geom] = field(default_factory=list)
    sites: dict[str, pinocchio.SE3] = field(default_factory=dict)
    children: list[_Body] = field(default_factory=list)


# Elements of a body or a frame that have no static effect and are skipped.
_SKIPPED_IN_BODY = {"camera", "light"}
# Top-level sections read here, or without static effect.
_TOP_LEVEL = {
    "compiler",
    "option",
    "size",
    "visual",
    "statistic",
    "default",
    "custom",
    "asset",
    "worldbody",
    "contact",
    "equality",
    "tendon",
    "actuator",
    "sensor",
    "keyframe",
    "deformable",
}
# A way forward for what MuJoCo's compiler expands (attached models, composites, replicas, mass
# scaling): MuJoCo writes the model it compiled as plain MJCF, which pinsettle reads.
_EXPAND = (
    "expand it with MuJoCo: save the compiled model (mujoco.MjModel.from_xml_path, then "
    "mujoco.mj_saveLastXML) and solve the saved file"
)
_ORIENTATIONS = ("quat", "axisangle", "euler", "xyaxes", "zaxis")
_JOINT_KINDS = ("hinge", "slide", "ball", "free")
_ACTUATOR_TAGS = (
    "general",
    "motor",
    "position",
    "velocity",
    "damper",
    "intvelocity",
    "orientation",
    "pid",
    "cylinder",
    "muscle",
    "adhesion",
    "dcmotor",
)
_LIMITED = ("true", "false", "auto")
_MASS_SHAPES = {"sphere": 1, "capsule": 2, "cylinder": 2, "box": 3, "ellipsoid": 3}
_ASSET_FILES = {
    "mesh": ("file",),
    "hfield": ("file",),
    "skin": ("file",),
    "texture": ("file", "fileright", "fileleft", "fileup", "filedown", "filefront", "fileback"),
}


# --- masses from meshes, as MuJoCo computes them ----------------------------------------------

# MuJoCo's small numbers (mjMINVAL, mjEPS) and its limit on an STL file's faces.
_MINVAL = 1e-15
_EPS = 1e-14
_STL_MAX_FACES = 200000
_MESH_INERTIA = ("legacy", "exact", "convex", "shell")


@dataclass
class _MeshAsset:
    name: str
    file: Path | None  # None: vertices and faces given in the element
    attrs: dict[str, str]
    label: str


@dataclass
class _MeshMass:
    """A mesh's volume (its area for inertia="shell"), centre of mass and rotational inertia
    about it per unit density, in the mesh's coordinates (after scale, refpos, refquat)."""

    volume: float
    com: np.ndarray
    inertia: np.ndarray  # 3x3


@dataclass
class _GeomMass:
    """A geom's mass, centre of mass and rotational inertia about it, in its body's frame."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray  # 3x3


def _mesh_refusal(mesh: _MeshAsset, what: str) -> MjcfError:
    where = f"mesh '{mesh.name}'" + (f" ({mesh.file})" if mesh.file else "")
    return MjcfError(f"{where}: {what}")


def _read_stl(mesh: _MeshAsset, data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """A binary STL file (MuJoCo reads no other kind): its vertices and faces."""
    ascii_hint = data.lstrip()[:5].lower() == b"solid"
    count = int(np.frombuffer(data[80:84], "<i4")[0]) if len(data) >= 84 else -1
    if len(data) < 84 or count * 50 != len(data) - 84:
        if ascii_hint:
            raise _mesh_refusal(
                mesh,
                "an ASCII STL file; MuJoCo reads binary STL only and refuses it too: save it "
                "as binary STL (or OBJ)",
            )
        raise _mesh_refusal(mesh, "not a binary STL file (its size does not match its header)")
    if not 1 <= count <= _STL_MAX_FACES:
        raise _mesh_refusal(
            mesh,
            f"{count} faces; MuJoCo reads STL files of 1 to {_STL_MAX_FACES} faces: simplify "
            "the mesh",
        )
    records = np.frombuffer(
        data[84:], dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    )
    vertices = records["v"].reshape(-1, 3).astype(np.float64)
    return vertices, np.arange(len(vertices)).reshape(-1, 3)


def _read_obj(mesh: _MeshAsset, text: str) -> tuple[np.ndarray, np.ndarray]:
    """A Wavefront OBJ file as MuJoCo's reader (tinyobjloader) takes it: every vertex (a
    convex hull uses them all), the faces of its first group or object only, polygons split
    into triangles (a quad along its shorter diagonal)."""
    vertices: list[list[float]] = []
    faces: list[list[int]] = []
    first_shape = True  # MuJoCo takes the faces of the first shape and every vertex
    for number, line in enumerate(text.splitlines(), 1):
        parts = line.split("#", 1)[0].split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                vertices.append([float(x) for x in parts[1:4]])
                if len(vertices[-1]) != 3:
                    raise ValueError
            elif parts[0] in ("g", "o") and faces:
                first_shape = False
            elif parts[0] == "f" and first_shape:
                index = [int(p.split("/")[0]) for p in parts[1:]]
                index = [i - 1 if i > 0 else len(vertices) + i for i in index]
                if len(index) < 3:
                    raise ValueError
                faces.extend(_triangles(index, vertices))
        except ValueError:
            shown = line.strip()[:60]
            raise _mesh_refusal(mesh, f"line {number} is not a valid OBJ line: {shown!r}") from None
    points = np.array(vertices, dtype=np.float32).astype(np.float64).reshape(-1, 3)
    triangles = np.array(faces, dtype=np.int64).reshape(-1, 3)
    if triangles.size and (triangles.min() < 0 or triangles.max() >= len(points)):
        raise _mesh_refusal(mesh, "a face names a vertex the file does not have")
    return points, triangles


def _triangles(index: list[int], vertices: list[list[float]]) -> list[list[int]]:
    if len(index) == 3:
        return [index]
    if len(index) == 4 and max(index) < len(vertices):
        v = np.array([vertices[i] for i in index], dtype=np.float32)
        if np.sum((v[2] - v[0]) ** 2) < np.sum((v[3] - v[1]) ** 2):
            return [[index[0], index[1], index[2]], [index[0], index[2], index[3]]]
        return [[index[0], index[1], index[3]], [index[1], index[2], index[3]]]
    # A fan: for a plane polygon every split gives the same integrals.
    return [[index[0], index[k], index[k + 1]] for k in range(1, len(index) - 1)]


def _read_msh(mesh: _MeshAsset, data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo's own binary MSH format: four counts, then vertices, normals, texture
    coordinates (float32) and faces (int32)."""
    if len(data) < 16:
        raise _mesh_refusal(mesh, "an MSH file without its header")
    nv, nn, nt, nf = (int(x) for x in np.frombuffer(data[:16], "<i4"))
    if nv < 4 or min(nn, nt, nf) < 0 or nn not in (0, nv) or nt not in (0, nv):
        raise _mesh_refusal(mesh, "an MSH file with invalid counts in its header")
    if len(data) != 16 + 4 * (3 * nv + 3 * nn + 2 * nt + 3 * nf):
        raise _mesh_refusal(mesh, "an MSH file whose size does not match its header")
    vertices = np.frombuffer(data, "<f4", 3 * nv, 16).astype(np.float64).reshape(-1, 3)
    at = 16 + 4 * (3 * nv + 3 * nn + 2 * nt)
    faces = np.frombuffer(data, "<i4", 3 * nf, at).astype(np.int64).reshape(-1, 3)
    if faces.size and (faces.min() < 0 or faces.max() >= nv):
        raise _mesh_refusal(mesh, "a face names a vertex the file does not have")
    return vertices, faces


def _mesh_geometry(mesh: _MeshAsset) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's vertices and faces as given (file or the element's vertex and face)."""
    if mesh.file is None:
        if "vertex" not in mesh.attrs:
            raise _mesh_refusal(mesh, "neither a file nor vertices")
        where = f"{mesh.label} vertex"
        values = _floats(mesh.attrs["vertex"], where, (len(mesh.attrs["vertex"].split()),))
        if len(values) % 3:
            raise MjcfError(f"{where}: expected 3 numbers per vertex, got {len(values)}")
        vertices = values.astype(np.float32).astype(np.float64).reshape(-1, 3)
        faces = np.zeros((0, 3), dtype=np.int64)
        if "face" in mesh.attrs:
            try:
                faces = np.array([int(x) for x in mesh.attrs["face"].split()]).reshape(-1, 3)
            except ValueError:
                raise MjcfError(f"{mesh.label} face: expected integers, 3 per face") from None
            if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
                raise _mesh_refusal(mesh, "a face names a vertex the mesh does not have")
        return vertices, faces
    suffix = mesh.file.suffix.lower()
    readers = {".stl": _read_stl, ".msh": _read_msh}
    if suffix == ".obj":
        return _read_obj(mesh, mesh.file.read_text(encoding="utf-8", errors="replace"))
    if suffix not in readers:
        raise _mesh_refusal(
            mesh,
            f"pinsettle computes masses from STL, OBJ and MSH meshes, not from a "
            f"'{mesh.file.suffix}' file: convert it to STL or OBJ, or give the body an "
            "<inertial>",
        )
    return readers[suffix](mesh, mesh.file.read_bytes())


def _convex_hull(mesh: _MeshAsset, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices' convex hull, its points and its faces each facing out (qhull through
    coal, Pinocchio's collision library; MuJoCo uses qhull too)."""
    try:
        import coal
    except ImportError:
        raise _mesh_refusal(
            mesh,
            'inertia="convex" needs a convex hull and coal (Pinocchio\'s collision library) is '
            "not importable: give the body an <inertial>",
        ) from None
    points = coal.StdVec_Vec3s()
    for v in vertices:
        points.append(np.asarray(v, dtype=float))
    where = f"{mesh.label} maxhullvert"
    maxhullvert = int(_floats(mesh.attrs.get("maxhullvert", "-1"), where, (1,))[0])
    command = "Qt" + (f" Q9 TA{maxhullvert - 4}" if maxhullvert > -1 else "")
    try:
        hull = coal.ConvexBase.convexHull(points, True, command)
    except Exception as error:  # qhull's own reasons (a flat or degenerate point set)
        raise _mesh_refusal(mesh, f"no convex hull: {error}") from None
    hull_points = np.array(hull.points(), dtype=float).reshape(-1, 3)
    faces = np.array(
        [[hull.polygons(i)[k] for k in range(3)] for i in range(hull.num_polygons)],
        dtype=np.int64,
    ).reshape(-1, 3)
    inside = hull_points.mean(axis=0)
    a, b, c = (hull_points[faces[:, k]] for k in range(3))
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3 - inside) < 0
    faces[inward] = faces[inward][:, [0, 2, 1]]
    return hull_points, faces


def _mesh_mass(mesh: _MeshAsset, where: str) -> _MeshMass:
    """MuJoCo's mass properties of a mesh (user_mesh.cc: ApplyTransformations, ComputeVolume,
    ComputeInertia), for its ``inertia`` rule: legacy (MuJoCo's default: every face's pyramid
    counted positive), exact (signed, a closed mesh), convex (the convex hull), shell (mass on
    the surface)."""
    a = mesh.attrs
    rule = _flag(a.get("inertia", "legacy"), f"{mesh.label} inertia", _MESH_INERTIA)
    vertices, faces = _mesh_geometry(mesh)
    if len(vertices) < 4:
        raise _mesh_refusal(mesh, f"{len(vertices)} vertices; MuJoCo needs at least 4")
    if not np.all(np.isfinite(vertices)):
        raise _mesh_refusal(mesh, "a vertex coordinate is not finite")
    # The user's offset, rotation and scale (MuJoCo: minus refpos, by refquat's inverse,
    # times scale; a mirroring scale turns the faces over).
    refpos = _floats(a.get("refpos", "0 0 0"), f"{mesh.label} refpos", (3,))
    w, x, y, z = _floats(a.get("refquat", "1 0 0 0"), f"{mesh.label} refquat", (4,))
    scale = _floats(a.get("scale", "1 1 1"), f"{mesh.label} scale", (3,))
    vertices = vertices - refpos
    if (w, x, y, z) != (1, 0, 0, 0):
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        if norm < 1e-14:
            raise MjcfError(f"{mesh.label} refquat: zero quaternion")
        rotation = pinocchio.Quaternion(w / norm, x / norm, y / norm, z / norm).matrix()
        vertices = vertices @ rotation
    vertices = vertices * scale
    if scale[0] * scale[1] * scale[2] < 0:
        faces = faces[:, [0, 2, 1]]
    if rule == "convex" or not len(faces):
        vertices, faces = _convex_hull(mesh, vertices)
    if rule == "exact":
        edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        if len(np.unique(edges, axis=0)) < len(edges):
            raise _mesh_refusal(
                mesh,
                'inertia="exact" needs consistently oriented faces and two faces run along '
                "an edge the same way (MuJoCo refuses this too): fix the mesh, or use "
                'inertia="convex"',
            )
    d, e, f = (vertices[faces[:, k]] for k in range(3))
    cross = np.cross(e - d, f - d)
    length = np.linalg.norm(cross, axis=1)
    small = length < _MINVAL
    area = np.where(small, 0.0, 0.5 * length)
    normal = cross / np.where(small, 1.0, length)[:, None]
    center = (d + e + f) / 3
    total_area = float(area.sum())
    if total_area < _MINVAL:
        raise _mesh_refusal(mesh, "its surface area is too small (MuJoCo refuses it too)")
    facecen = (area[:, None] * center).sum(axis=0) / total_area
    if rule == "shell":
        weight = area
    else:
        weight = np.einsum("ij,ij->i", center - facecen, normal) * area / 3
        if rule == "legacy":
            weight = np.abs(weight)
    total = float(weight.sum())
    if rule != "shell" and total < _MINVAL:
        raise _mesh_refusal(
            mesh,
            "its volume is negative (faces turned inwards)"
            if total < 0
            else "its volume is too small; MuJoCo refuses it too unless the mesh has "
            'inertia="shell"',
        )
    com = (
        (weight[:, None] * center).sum(axis=0) / total
        if rule == "shell"
        else (weight[:, None] * (center * 0.75 + facecen / 4)).sum(axis=0) / total
    )
    # Second moments about the centre of mass, per face (MuJoCo's ComputeInertia).
    d, e, f, center = d - com, e - com, f - com, center - com
    if rule == "shell":
        weight, divisor = area, 12.0
    else:
        weight, divisor = np.einsum("ij,ij->i", center, normal) * area / 3, 20.0
        if rule == "legacy":
            weight = np.abs(weight)
    volume = float(weight.sum())
    products = np.zeros((3, 3))
    for i in range(3):
        for j in range(i, 3):
            terms = (
                2 * (d[:, i] * d[:, j] + e[:, i] * e[:, j] + f[:, i] * f[:, j])
                + d[:, i] * e[:, j]
                + d[:, j] * e[:, i]
                + d[:, i] * f[:, j]
                + d[:, j] * f[:, i]
                + e[:, i] * f[:, j]
                + e[:, j] * f[:, i]
            )
            products[i, j] = products[j, i] = float((weight / divisor * terms).sum())
    inertia = np.trace(products) * np.eye(3) - products
    eigen = np.linalg.eigvalsh(inertia)
    if eigen[0] <= 0:
        raise _mesh_refusal(mesh, "its inertia is not positive (MuJoCo refuses it too)")
    return _MeshMass(volume, com, inertia)


class _Reader:
    """One MJCF file read with MuJoCo's rules; refusals are collected, then raised at once."""

    def __init__(self, path: Path) -> None:
        self.path = path
        #: What cannot be honoured: (what it is, its kind, a way forward), grouped by kind.
        self.refusals: list[tuple[str, str, str]] = []
        self.notes: list[str] = []
        self.root = self._expand(path)
        if self.root.tag != "mujoco":
            raise MjcfError(
                f"{path}: not an MJCF file: the root element is <{self.root.tag}>, not <mujoco>"
            )
        for child in self.root:
            if child.tag not in _TOP_LEVEL:
                self.refuse(
                    _describe(child), "(a section pinsettle does not read)", "remove it in a copy"
                )
        self.compiler = self._compiler()
        self.classes, self.main_class = self._defaults()
        self.meshes: dict[str, _MeshAsset] = {}
        self._check_assets()
        self.bodies: list[_Body] = []  # top-level bodies
        self.world_sites: dict[str, pinocchio.SE3] = {}
        self.body_names: dict[str, _Body] = {}
        self.joint_names: set[str] = set()
        self.site_body: dict[str, str] = {}
        self._count = 0
        for world in self.root.findall("worldbody"):
            self._contents(world, None, pinocchio.SE3.Identity(), None)

    def refuse(self, what: str, kind: str, way: str = "") -> None:
        """``what`` (an element) cannot be honoured for ``kind`` (a reason, shared by the
        elements it groups); ``way``: what the user can do instead."""
        self.refusals.append((what, kind, way))

    def check_refusals(self) -> None:
        """One short line for all refusals: per kind the first elements, a count of the rest,
        and the way forward."""
        if not self.refusals:
            return
        kinds: dict[str, list[str]] = {}
        ways: dict[str, str] = {}
        for what, kind, way in self.refusals:
            if what not in kinds.setdefault(kind, []):
                kinds[kind].append(what)
            ways.setdefault(kind, way)
        parts = [
            f"{_names(items, 3)} {kind}" + (f": {ways[kind]}" if ways[kind] else "")
            for kind, items in kinds.items()
        ]
        shown = "; ".join(parts[:4]) + (
            f"; and {len(parts) - 4} more kinds" if len(parts) > 4 else ""
        )
        raise MjcfError(f"{self.path}: cannot be honoured in statics: {shown}")

    # -- includes, compiler, defaults, assets --

    def _expand(self, path: Path) -> ET.Element:
        """The main file with every <include> replaced by the children of the included file's
        root (paths relative to the main file's folder, as MuJoCo takes them)."""
        if not path.is_file():
            raise FileNotFoundError(f"MJCF file not found: {path}")
        root = _parse(path)
        missing: list[str] = []
        seen: set[Path] = set()

        def expand(parent: ET.Element) -> None:
            for child in list(parent):
                if child.tag != "include":
                    expand(child)
                    continue
                name = child.get("file")
                if not name:
                    raise MjcfError(f"{path}: <include> without a 'file' attribute")
                included = path.parent / name
                if not included.is_file():
                    missing.append(f"{name} (looked for {included})")
                    parent.remove(child)
                    continue
                if included.resolve() in seen:
                    raise MjcfError(
                        f'{path}: <include file="{name}"> includes {included} a second time '
                        "(MuJoCo includes a file at most once)"
                    )
                seen.add(included.resolve())
                inserted = _parse(included)
                expand(inserted)
                at = list(parent).index(child)
                parent.remove(child)
                for k, element in enumerate(list(inserted)):
                    parent.insert(at + k, element)

        expand(root)
        if missing:
            raise MjcfError(
                f"{path}: included file{'s' if len(missing) > 1 else ''} not found: "
                + _names(missing, 3, "; ")
                + " (MuJoCo takes include paths from the main file's folder)"
            )
        return root

    def _compiler(self) -> _Compiler:
        c = _Compiler()
        for el in self.root.findall("compiler"):
            where = f"{self.path}: <compiler>"
            a = el.attrib
            if "angle" in a:
                c.degree = _flag(a["angle"], f"{where} angle", ("degree", "radian")) == "degree"
            if "eulerseq" in a:
                seq = a["eulerseq"]
                if len(seq) != 3 or any(ch not in "xyzXYZ" for ch in seq):
                    raise MjcfError(f"{where} eulerseq: three of x y z X Y Z, got '{seq}'")
                c.eulerseq = seq
            if "autolimits" in a:
                c.autolimits = _flag(a["autolimits"], f"{where} autolimits", ("true", "false")) == (
                    "true"
                )
            if "inertiafromgeom" in a:
                c.inertiafromgeom = _flag(
                    a["inertiafromgeom"], f"{where} inertiafromgeom", ("true", "false", "auto")
                )
            if "inertiagrouprange" in a:
                low, high = _floats(a["inertiagrouprange"], f"{where} inertiagrouprange", (2,))
                c.inertiagrouprange = (int(low), int(high))
            if "boundmass" in a:
                c.boundmass = float(_floats(a["boundmass"], f"{where} boundmass", (1,))[0])
            if "boundinertia" in a:
                c.boundinertia = float(_floats(a["boundinertia"], f"{where} boundinertia", (1,))[0])
            if (
                "settotalmass" in a
                and _floats(a["settotalmass"], f"{where} settotalmass", (1,))[0] > 0
            ):
                self.refuse(
                    "<compiler settotalmass>",
                    "(masses scaled to a total)",
                    _EXPAND,
                )
            if a.get("coordinate", "local") != "local":
                self.refuse(
                    f'<compiler coordinate="{a["coordinate"]}">',
                    "(global coordinates; MuJoCo 2.3.4 and later refuse them too)",
                    "load and save the file in MuJoCo 2.3.3 or older, as MuJoCo says",
                )
            for key in ("meshdir", "texturedir", "assetdir"):
                if key in a:
                    setattr(c, key, a[key])
            if "strippath" in a:
                c.strippath = _flag(a["strippath"], f"{where} strippath", ("true", "false")) == (
                    "true"
                )
        return c

    def _defaults(self) -> tuple[dict[str, dict[str, dict[str, str]]], str]:
        """Default classes: class -> element tag -> attributes, as MuJoCo builds them. Every
        top-level <default> (those of included files too) adds to the one class 'main', in
        file order; a nested class starts as a copy of its parent as the parent stands when
        the nested class is read (a later top-level <default> does not reach it)."""
        main = "main"
        classes: dict[str, dict[str, dict[str, str]]] = {main: {}}
        # Every kind of actuator writes MuJoCo's one actuator default of a class, in order.
        actuators: dict[str, list[tuple[str, dict[str, str]]]] = {main: []}
        self.actuator_defaults = actuators

        def visit(el: ET.Element, name: str) -> None:
            own = classes[name]
            for child in el:
                if child.tag in _ACTUATOR_TAGS:
                    actuators[name].append((child.tag, dict(child.attrib)))
                elif child.tag != "default":
                    own.setdefault(child.tag, {}).update(child.attrib)
            for child in el:
                if child.tag == "default":
                    nested = child.get("class")
                    if not nested:
                        raise MjcfError(f"{self.path}: a nested <default> needs a 'class'")
                    if nested in classes:
                        raise MjcfError(f"{self.path}: default class '{nested}' is defined twice")
                    classes[nested] = {tag: dict(attrs) for tag, attrs in own.items()}
                    actuators[nested] = list(actuators[name])
                    visit(child, nested)

        for top in self.root.findall("default"):
            name = top.get("class", main)
            if name != main:
                raise MjcfError(
                    f'{self.path}: <default class="{name}"> at the top level: the top-level '
                    "class is 'main' and cannot be renamed (MuJoCo refuses this too); drop "
                    "its 'class' or nest it in a <default>"
                )
            visit(top, main)
        return classes, main

    def _resolved(
        self, el: ET.Element, childclass: str | None, tag: str | None = None
    ) -> dict[str, str]:
        """An element's attributes with those of its defaults class (its own 'class', else the
        enclosing childclass, else the main class)."""
        cls = el.get("class") or childclass or self.main_class
        if cls not in self.classes:
            raise MjcfError(
                f"{self.path}: {_describe(el)} uses the unknown default class '{cls}'; classes: "
                + _names(list(self.classes), 8)
            )
        attrs = dict(self.classes[cls].get(tag or el.tag, {}))
        attrs.update(el.attrib)
        attrs.pop("class", None)
        return attrs

    def _check_assets(self) -> None:
        """Every file an asset names exists (MuJoCo refuses a model otherwise)."""
        c = self.compiler
        missing: list[str] = []
        folders: dict[str, None] = {}  # in order, once each
        sections = [*self.root.findall("asset"), *self.root.findall("deformable")]
        for section in sections:
            for el in section:
                if el.tag == "model":
                    self.refuse(
                        _describe(el),
                        "in <asset> (models attached with <attach>)",
                        _EXPAND,
                    )
                files: dict[str, Path] = {}
                for key in _ASSET_FILES.get(el.tag, ()):
                    name = el.get(key)
                    if not name:
                        continue
                    file = Path(name)
                    if c.strippath:
                        file = Path(file.name)
                    if not file.is_absolute():
                        folder = c.texturedir if el.tag == "texture" else c.meshdir
                        folder = folder if folder is not None else c.assetdir
                        file = self.path.parent / (folder or "") / file
                    files[key] = file
                    if not file.is_file():
                        missing.append(f"{el.tag} {_describe(el)} file '{name}'")
                        folders.setdefault(str(file.parent), None)
                if el.tag == "mesh" and section.tag == "asset":
                    self._mesh_asset(el, files.get("file"))
        if missing:
            raise MjcfError(
                f"{self.path}: {len(missing)} asset file{'s' if len(missing) > 1 else ''} not "
                f"found: {_names(missing, 2, '; ')} (looked for in {_names(list(folders), 2)}); "
                "paths are taken from the main file's folder and <compiler meshdir, texturedir, "
                "assetdir>: check them, and that the files are there"
            )

    def _mesh_asset(self, el: ET.Element, file: Path | None) -> None:
        """A mesh of <asset>, kept by name for the geoms whose mass comes from it (its name
        defaults to its file's name without the extension, as in MuJoCo)."""
        attrs = self._resolved(el, None)
        name = attrs.get("name") or (Path(attrs.get("file", "")).stem if file else "")
        if not name:
            return  # no geom can use it
        self.meshes[name] = _MeshAsset(name, file, attrs, _describe(el))

    # -- poses --

    def _orientation(self, attrs: Mapping[str, str], where: str) -> np.ndarray:
        given = [key for key in _ORIENTATIONS if key in attrs]
        if len(given) > 1:
            raise MjcfError(f"{where}: more than one orientation ({', '.join(given)})")
        if not given:
            return np.eye(3)
        key = given[0]
        text = attrs[key]
        at = f"{where} {key}"
        if key == "quat":
            w, x, y, z = _floats(text, at, (4,))
            norm = math.sqrt(w * w + x * x + y * y + z * z)
            if norm < 1e-14:
                raise MjcfError(f"{at}: zero quaternion")
            rotation: np.ndarray = pinocchio.Quaternion(
                w / norm, x / norm, y / norm, z / norm
            ).matrix()
            return rotation
        if key == "axisangle":
            values = _floats(text, at, (4,))
            axis = values[:3]
            if np.linalg.norm(axis) < 1e-14:
                raise MjcfError(f"{at}: zero axis")
            return _rotation(axis / np.linalg.norm(axis), values[3] * self.compiler.angle)
        if key == "euler":
            rotation = np.eye(3)
            for angle, letter in zip(_floats(text, at, (3,)), self.compiler.eulerseq, strict=True):
                turn = _rotation(
                    np.eye(3)["xyz".index(letter.lower())], angle * self.compiler.angle
                )
                rotation = rotation @ turn if letter.islower() else turn @ rotation
            return rotation
        if key == "xyaxes":
            values = _floats(text, at, (6,))
            x_axis, y_axis = values[:3], values[3:]
            if np.linalg.norm(x_axis) < 1e-14:
                raise MjcfError(f"{at}: zero x axis")
            x_axis = x_axis / np.linalg.norm(x_axis)
            y_axis = y_axis - x_axis * float(x_axis @ y_axis)
            if np.linalg.norm(y_axis) < 1e-14:
                raise MjcfError(f"{at}: y axis along the x axis")
            y_axis = y_axis / np.linalg.norm(y_axis)
            return np.column_stack([x_axis, y_axis, np.cross(x_axis, y_axis)])
        return _z_to(_floats(text, at, (3,)), at)

    def _pose(self, attrs: Mapping[str, str], where: str) -> pinocchio.SE3:
        pos = _floats(attrs["pos"], f"{where} pos", (3,)) if "pos" in attrs else np.zeros(3)
        return _to_se3(self._orientation(attrs, where), pos)

    # -- the tree --

    def _contents(
        self,
        container: ET.Element,
        body: _Body | None,
        frame: pinocchio.SE3,
        childclass: str | None,
    ) -> None:
        """The children of a body, of the worldbody (body None) or of a <frame> in them, with
        the frames' pose composed in."""
        owner = f"body '{body.name}'" if body is not None else "<worldbody>"
        for el in container:
            tag = el.tag
            where = f"{self.path}: {_describe(el)} in {owner}"
            if tag == "body":
                self._body(el, body, frame, childclass)
            elif tag == "frame":
                self._contents(
                    el,
                    body,
                    frame * self._pose(el.attrib, where),
                    el.get("childclass", childclass),
                )
            elif tag == "inertial" and body is not None and container is body.element:
                body.inertial = el
                body.inertial_pose = self._pose(el.attrib, where)
            elif tag in ("joint", "freejoint") and body is not None:
                self._joint(el, body, frame, childclass, where)
            elif tag == "geom":
                if body is not None:  # world geoms have no mass that counts
                    self._geom(el, body, frame, childclass, where)
            elif tag == "site":
                self._site(el, body, frame, childclass, where)
            elif tag in _SKIPPED_IN_BODY:
                continue
            else:
                self.refuse(
                    f"{_describe(el)} in {owner}",
                    "(an element pinsettle does not read in a body)",
                    _EXPAND,
                )

    def _body(
        self, el: ET.Element, parent: _Body | None, frame: pinocchio.SE3, childclass: str | None
    ) -> None:
        self._count += 1
        name = el.get("name") or f"body{self._count}"
        where = f'{self.path}: <body name="{name}">'
        if name == "world" or name in self.body_names:
            raise MjcfError(f"{where}: the body name '{name}' is used twice")
        if (
            "gravcomp" in el.attrib
            and _floats(el.get("gravcomp", ""), f"{where} gravcomp", (1,))[0]
        ):
            self.refuse(
                f'<body name="{name}" gravcomp>',
                "(gravity compensation)",
                "remove gravcomp in a copy, and give the lift as a [[load]] of a scene file "
                "(gravcomp m g up at the body's centre of mass)",
            )
        body = _Body(name, frame * self._pose(el.attrib, where), el)
        self.body_names[name] = body
        (parent.children if parent is not None else self.bodies).append(body)
        self._contents(el, body, pinocchio.SE3.Identity(), el.get("childclass", childclass))

    def _joint(
        self,
        el: ET.Element,
        body: _Body,
        frame: pinocchio.SE3,
        childclass: str | None,
        where: str,
    ) -> None:
        if el.tag == "freejoint":
            attrs = dict(el.attrib)
            kind = "free"
        else:
            attrs = self._resolved(el, childclass)
            kind = _flag(attrs.get("type", "hinge"), f"{where} type", _JOINT_KINDS)
        name = attrs.get("name") or f"{body.name}_joint{len(body.joints)}"
        if name in self.joint_names:
            raise MjcfError(f"{where}: the joint name '{name}' is used twice")
        self.joint_names.add(name)
        pos = _floats(attrs["pos"], f"{where} pos", (3,)) if "pos" in attrs else np.zeros(3)
        axis = _floats(attrs["axis"], f"{where} axis", (3,)) if "axis" in attrs else np.eye(3)[2]
        if kind in ("hinge", "slide") and np.linalg.norm(axis) < 1e-14:
            raise MjcfError(f"{where} axis: zero-length axis")
        axis = frame.rotation @ (axis / max(float(np.linalg.norm(axis)), 1e-300))
        joint = _Joint(name, kind, frame.act(pos), axis, attrs, body.name)
        if kind in ("hinge", "slide") and "ref" in attrs:
            scale = self.compiler.angle if kind == "hinge" else 1.0
            joint.ref = float(_floats(attrs["ref"], f"{where} ref", (1,))[0]) * scale
        body.joints.append(joint)

    def _geom(
        self,
        el: ET.Element,
        body: _Body,
        frame: pinocchio.SE3,
        childclass: str | None,
        where: str,
    ) -> None:
        attrs = self._resolved(el, childclass)
        fromto = None
        if "fromto" in attrs:
            ends = _floats(attrs["fromto"], f"{where} fromto", (6,))
            fromto = np.concatenate([frame.act(ends[:3]), frame.act(ends[3:])])
        pose = frame * self._pose(attrs, where)
        body.geoms.append(_Geom(attrs, pose, fromto, _describe(el)))

    def _site(
        self,
        el: ET.Element,
        body: _Body | None,
        frame: pinocchio.SE3,
        childclass: str | None,
        where: str,
    ) -> None:
        attrs = self._resolved(el, childclass)
        name = attrs.get("name")
        if not name:
            return  # nothing can refer to it
        if name in self.site_body or name in self.world_sites:
            raise MjcfError(f"{where}: the site name '{name}' is used twice")
        if "fromto" in attrs:
            ends = _floats(attrs["fromto"], f"{where} fromto", (6,))
            local = _to_se3(
                _z_to(ends[3:] - ends[:3], f"{where} fromto"), (ends[:3] + ends[3:]) / 2
            )
        else:
            local = self._pose(attrs, where)
        if body is None:
            self.world_sites[name] = frame * local
        else:
            body.sites[name] = frame * local
            self.site_body[name] = body.name

    def all_bodies(self) -> list[_Body]:
        """Every body, depth first (MuJoCo's body order)."""
        out: list[_Body] = []

        def visit(body: _Body) -> None:
            out.append(body)
            for child in body.children:
                visit(child)

        for body in self.bodies:
            visit(body)
        return out


# --- what the file says about statics ---------------------------------------------------------


@dataclass
class _Statics:
    limits: dict[str, tuple[float, float]]
    springs: list[tuple[str, float, float]]


def _option(reader: _Reader) -> tuple[np.ndarray, dict[str, bool]]:
    """Gravity and the flags of <option> that matter here (enable / disable)."""
    gravity = np.array([0.0, 0.0, -9.81])
    flags = {"gravity": True, "limit": True, "spring": True, "equality": True, "constraint": True}
    flags |= {"actuation": True, "clampctrl": True}
    for el in reader.root.findall("option"):
        where = f"{reader.path}: <option>"
        if "gravity" in el.attrib:
            gravity = _floats(el.attrib["gravity"], f"{where} gravity", (3,))
        density = el.get("density")
        if density is not None and _floats(density, f"{where} density", (1,))[0] != 0:
            reader.refuse(
                "<option density>",
                "(buoyancy of a fluid medium)",
                'set <option density="0"> in a copy for the rest in vacuum',
            )
        viscosity = el.get("viscosity")
        wind = el.get("wind")
        if (
            wind is not None
            and np.any(_floats(wind, f"{where} wind", (3,)))
            and (viscosity is not None and _floats(viscosity, f"{where} viscosity", (1,))[0] != 0)
        ):
            reader.refuse(
                "<option wind>", "(drag of a moving medium)", 'set wind="0 0 0" in a copy'
            )
        for flag in el.findall("flag"):
            for key in flags:
                if key in flag.attrib:
                    value = _flag(flag.attrib[key], f"{where} <flag {key}>", ("enable", "disable"))
                    flags[key] = value == "enable"
    if not flags["gravity"]:
        gravity = np.zeros(3)
        reader.notes.append('gravity off (<option><flag gravity="disable">)')
    return gravity, flags


def _names(items: Sequence[str], limit: int = 4, separator: str = ", ") -> str:
    """The first few items and a count of the rest: a hand has dozens of joints."""
    shown = separator.join(items[:limit])
    return shown + (f" and {len(items) - limit} more" if len(items) > limit else "")


def _joint_statics(reader: _Reader, flags: Mapping[str, bool]) -> _Statics:
    """Ranges, springs and the notes of every joint."""
    limits: dict[str, tuple[float, float]] = {}
    springs: list[tuple[str, float, float]] = []
    ignored: dict[str, list[str]] = {"damping": [], "frictionloss": [], "armature": []}
    limits_off: list[str] = []
    springs_off: list[str] = []
    for body in reader.all_bodies():
        for joint in body.joints:
            a = joint.attrs
            where = f"{reader.path}: <joint name=\"{joint.name}\"> (body '{body.name}')"
            angle = reader.compiler.angle if joint.kind in ("hinge", "ball") else 1.0
            # limited / autolimits, as MuJoCo decides them
            limited = _flag(a.get("limited", "auto"), f"{where} limited", ("true", "false", "auto"))
            if limited == "auto":
                if not reader.compiler.autolimits and "range" in a:
                    raise MjcfError(
                        f'{where}: a range without limited="true" or "false" while <compiler '
                        'autolimits="false"> (MuJoCo refuses this too)'
                    )
                on = "range" in a and reader.compiler.autolimits
            else:
                on = limited == "true"
            if on:
                if joint.kind == "free":
                    reader.refuse(
                        f'<joint name="{joint.name}">',
                        "with a range on a free joint",
                        "remove the range",
                    )
                elif joint.kind == "ball":
                    reader.refuse(
                        f'<joint name="{joint.name}">',
                        "with a range on a ball joint (a cone limit)",
                        'remove the range, or set limited="false" on it',
                    )
                elif "range" not in a:
                    raise MjcfError(f'{where}: limited="true" without a range')
                else:
                    given = _floats(a["range"], f"{where} range", (2,))
                    if not given[0] < given[1]:
                        raise MjcfError(
                            f"{where} range: lower {given[0]:g} must be below upper {given[1]:g}"
                        )
                    low, high = given * angle
                    if flags["limit"] and flags["constraint"]:
                        limits[joint.name] = (float(low), float(high))
                    else:
                        limits_off.append(joint.name)
            # springs
            stiffness = _floats(a.get("stiffness", "0"), f"{where} stiffness", (1, 2, 3))
            if np.any(stiffness[1:]):
                reader.refuse(
                    f'<joint name="{joint.name}" stiffness="{a["stiffness"]}">',
                    "(a polynomial spring)",
                    "keep its first, linear stiffness only",
                )
            if "springdamper" in a and np.all(
                _floats(a["springdamper"], f"{where} springdamper", (2,)) > 0
            ):
                reader.refuse(
                    f'<joint name="{joint.name}" springdamper>',
                    "(a stiffness from the mass matrix)",
                    "give stiffness (and damping) instead of springdamper",
                )
            k = float(stiffness[0])
            if k < 0:
                raise MjcfError(f"{where} stiffness: must be >= 0, got {k:g}")
            if k > 0:
                if joint.kind not in ("hinge", "slide"):
                    reader.refuse(
                        f'<joint name="{joint.name}" stiffness>',
                        f"on a {joint.kind} joint (joint springs on hinge and slide joints only)",
                        'remove the stiffness, or <option><flag spring="disable"/>',
                    )
                elif flags["spring"]:
                    rest = float(_floats(a.get("springref", "0"), f"{where} springref", (1,))[0])
                    springs.append((joint.name, k, rest * angle))
                else:
                    springs_off.append(joint.name)
            for key, names in ignored.items():
                if key in a and np.any(_floats(a[key], f"{where} {key}", (1, 2, 3))):
                    names.append(joint.name)
    for key, names in ignored.items():
        if names:
            reader.notes.append(
                f"ignored: joint {key} of {_names(names)} (no force at rest)"
                if key != "frictionloss"
                else f"ignored: joint friction loss of {_names(names)} (dry friction is not "
                "modelled: the rest is the frictionless one)"
            )
    if limits_off:
        reader.notes.append(
            f"ranges of {_names(limits_off)} not applied: limits are disabled "
            '(<option><flag limit|constraint="disable">)'
        )
    if springs_off:
        reader.notes.append(
            f"springs of {_names(springs_off)} not applied: springs are disabled "
            '(<option><flag spring="disable">)'
        )
    return _Statics(limits, springs)


def _other_sections(reader: _Reader, flags: Mapping[str, bool]) -> None:
    """Tendons, actuators, deformables: refused when they act at rest, else noted. A tendon's
    spring and range are off with MuJoCo's spring and limit flags, as a joint's are."""
    springs_off: list[str] = []
    ranges_off: list[str] = []
    tendons: list[str] = []
    for section in reader.root.findall("tendon"):
        for k, el in enumerate(section):
            attrs = reader._resolved(el, None, "tendon")
            label = el.get("name") or f"{el.tag} tendon {k}"
            tendons.append(label)
            where = f"{reader.path}: {_describe(el)} in <tendon>"
            if np.any(_floats(attrs.get("stiffness", "0"), f"{where} stiffness", (1, 2, 3))):
                if flags["spring"]:
                    reader.refuse(
                        _describe(el),
                        "in <tendon> with a stiffness (a tendon spring)",
                        'remove the stiffness, or <option><flag spring="disable"/> (all springs)',
                    )
                else:
                    springs_off.append(label)
            limited = _flag(attrs.get("limited", "auto"), f"{where} limited", _LIMITED)
            if limited == "true" or (
                limited == "auto" and reader.compiler.autolimits and "range" in attrs
            ):
                if flags["limit"] and flags["constraint"]:
                    reader.refuse(
                        _describe(el),
                        "in <tendon> with a range (a tendon limit)",
                        'remove the ranges, or <option><flag limit="disable"/> (all limits)',
                    )
                else:
                    ranges_off.append(label)
    if tendons:
        reader.notes.append(f"ignored: tendons {_names(tendons)} (no spring, no limit at work)")
    if ranges_off:
        reader.notes.append(
            f"ranges of tendons {_names(ranges_off)} not applied: limits are disabled "
            '(<option><flag limit|constraint="disable">)'
        )
    if springs_off:
        reader.notes.append(
            f"springs of tendons {_names(springs_off)} not applied: springs are disabled "
            '(<option><flag spring="disable">)'
        )
    for section in reader.root.findall("deformable"):
        for el in section:
            if el.tag != "skin":  # a skin is drawn only
                reader.refuse(_describe(el), "in <deformable>", "remove it in a copy")


# --- actuators ----------------------------------------------------------------------------------


@dataclass
class _Actuator:
    """An actuator as MuJoCo compiles it, as far as its force at rest goes: force = gain ctrl +
    bias[0] + bias[1] length (gaintype fixed, biastype affine), length = gear q on a joint."""

    label: str
    element: ET.Element
    gaintype: str = "fixed"
    gain: float = 1.0
    biastype: str = "none"
    bias: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    dyntype: str = "none"
    gear: float = 1.0
    ctrllimited: str = "auto"
    ctrlrange: tuple[float, float] | None = None
    forcelimited: str = "auto"
    forcerange: tuple[float, float] | None = None
    inheritrange: float = 0.0
    group: int = 0

    def apply(self, tag: str, attrs: Mapping[str, str], where: str) -> None:
        """One element's attributes (a default's or the actuator's own), as MuJoCo's
        OneActuator and mjs_setTo* set them."""

        def number(key: str, default: float, counts: Sequence[int] = (1,)) -> float:
            if key not in attrs:
                return default
            return float(_floats(attrs[key], f"{where} {key}", counts)[0])

        def pair(key: str) -> tuple[float, float] | None:
            if key not in attrs:
                return None
            low, high = _floats(attrs[key], f"{where} {key}", (2,))
            return float(low), float(high)

        self.gear = number("gear", self.gear, range(1, 7))
        self.group = int(number("group", self.group))
        self.ctrllimited = attrs.get("ctrllimited", self.ctrllimited)
        self.forcelimited = attrs.get("forcelimited", self.forcelimited)
        self.ctrlrange = pair("ctrlrange") or self.ctrlrange
        self.forcerange = pair("forcerange") or self.forcerange
        if tag == "general":
            self.gaintype = attrs.get("gaintype", self.gaintype)
            self.biastype = attrs.get("biastype", self.biastype)
            self.dyntype = attrs.get("dyntype", self.dyntype)
            if "gainprm" in attrs:
                self.gain = float(_floats(attrs["gainprm"], f"{where} gainprm", range(1, 11))[0])
            if "biasprm" in attrs:
                given = _floats(attrs["biasprm"], f"{where} biasprm", range(1, 11))
                self.bias = [float(x) for x in [*given[:3], 0.0, 0.0, 0.0][:3]]
        elif tag == "motor":
            self.gain, self.gaintype, self.biastype, self.dyntype = 1.0, "fixed", "none", "none"
        elif tag in ("position", "intvelocity"):
            kp = number("kp", self.gain)
            self.gain, self.bias[1] = kp, -kp
            self.gaintype, self.biastype = "fixed", "affine"
            if "timeconst" in attrs:
                self.dyntype = "filterexact" if number("timeconst", 0.0) > 0 else "none"
            self.inheritrange = number("inheritrange", self.inheritrange)
            if tag == "intvelocity":
                self.dyntype = "integrator"
        elif tag == "velocity":
            kv = number("kv", 1.0)
            self.gain, self.bias = kv, [0.0, 0.0, -kv]
            self.gaintype, self.biastype, self.dyntype = "fixed", "affine", "none"
        else:  # forces that no spring stands for (dampers, muscles, cylinders, ...)
            self.gaintype = tag

    def target(self) -> str | None:
        """The joint it acts on (None: another transmission)."""
        attrs = self.element.attrib
        return attrs.get("joint") or attrs.get("jointinparent")


@dataclass
class _ActuatorSprings:
    """Position actuators on hinge and slide joints as joint springs: (joint, stiffness, rest)
    at ctrl 0, and the rests at each keyframe's ctrl, in the same order."""

    springs: list[tuple[str, float, float]] = field(default_factory=list)
    rests: dict[str, list[float]] = field(default_factory=dict)


def _actuators(reader: _Reader, flags: Mapping[str, bool], as_springs: bool) -> _ActuatorSprings:
    """The actuators: with ``as_springs`` each position actuator on a hinge or slide joint (an
    affine force falling with the joint's length: kp (ctrl - gear q) at rest) is a joint spring
    of stiffness gear^2 kp towards the control (clamped to ctrlrange as MuJoCo clamps it):
    ctrl 0, or a keyframe's ctrl when that pose is chosen. Others are noted."""
    out = _ActuatorSprings()
    elements = [el for section in reader.root.findall("actuator") for el in section]
    if not elements:
        return out
    path = reader.path
    if not flags["actuation"]:
        reader.notes.append(
            f"ignored: {len(elements)} actuator{'s' if len(elements) > 1 else ''} "
            f"({_names([el.get('name') or el.tag for el in elements])}): actuation is "
            'disabled (<option><flag actuation="disable">)'
        )
        return out
    kinds = {j.name: j for body in reader.all_bodies() for j in body.joints}
    disabled_groups: set[int] = set()
    for option in reader.root.findall("option"):
        if "actuatorgroupdisable" in option.attrib:
            where = f"{path}: <option> actuatorgroupdisable"
            disabled_groups |= {
                int(x) for x in _floats(option.attrib["actuatorgroupdisable"], where, range(0, 31))
            }
    mapped: list[tuple[int, _Actuator, _Joint]] = []
    others: list[str] = []
    position_like = 0
    force_limited: list[str] = []
    for k, el in enumerate(elements):
        label = el.get("name") or f"actuator {k}"
        where = f"{path}: {_describe(el)} in <actuator>"
        if el.tag not in _ACTUATOR_TAGS:
            reader.refuse(
                _describe(el), "in <actuator> (an actuator pinsettle does not know)", "remove it"
            )
            continue
        cls = el.get("class") or reader.main_class
        if cls not in reader.actuator_defaults:
            raise MjcfError(f"{where}: unknown default class '{cls}'")
        actuator = _Actuator(label, el)
        for tag, attrs in reader.actuator_defaults[cls]:
            actuator.apply(tag, attrs, f'{path}: <default class="{cls}"> <{tag}>')
        actuator.apply(el.tag, el.attrib, where)
        spring_like = (
            actuator.gaintype == "fixed"
            and actuator.biastype == "affine"
            and actuator.bias[1] != 0
            and actuator.dyntype in ("none", "filter", "filterexact")
        )
        if not as_springs or not spring_like or actuator.group in disabled_groups:
            others.append(label)
            position_like += spring_like and actuator.group not in disabled_groups
            continue
        name = actuator.target()
        joint = kinds.get(name or "")
        if joint is None or joint.kind not in ("hinge", "slide"):
            on = (
                f"on {joint.kind} joint '{name}'"
                if joint is not None
                else "on a "
                + next(
                    (t for t in ("tendon", "site", "body", "cranksite") if t in el.attrib),
                    "missing joint",
                )
            )
            reader.refuse(
                f"{_describe(el)} in <actuator>",
                f"(a position actuator {on}; actuator springs are on hinge and slide joints only)",
                "leave actuator_springs off",
            )
            continue
        if actuator.bias[1] > 0:
            reader.refuse(
                f"{_describe(el)} in <actuator>",
                "(its force grows with the joint's position, biasprm[1] > 0: no spring)",
                "leave actuator_springs off",
            )
            continue
        limited = actuator.forcelimited == "true" or (
            actuator.forcelimited == "auto"
            and reader.compiler.autolimits
            and actuator.forcerange is not None
        )
        if limited:
            force_limited.append(label)
        mapped.append((k, actuator, joint))
    if others:
        hint = (
            " (not position actuators: no spring at a constant control)"
            if as_springs
            else "; [model] actuator_springs = true (--actuator-springs) holds the position "
            "actuators as joint springs"
            if position_like
            else ", no control"
        )
        reader.notes.append(
            f"ignored: {len(others)} actuator{'s' if len(others) > 1 else ''} "
            f"({_names(others)}): statics with constant loads only{hint}"
        )
    if not mapped:
        return out
    keys = [
        (key.get("name") or f"key{k}", key)
        for section in reader.root.findall("keyframe")
        for k, key in enumerate(section.findall("key"))
    ]
    controls: dict[str, np.ndarray] = {"qpos0": np.zeros(len(elements))}
    for name, key in keys:
        where = f'{path}: <key name="{name}"> ctrl'
        given = key.get("ctrl")
        controls[name] = (
            _floats(given, where, (len(elements),)) if given else np.zeros(len(elements))
        )
    for k, actuator, joint in mapped:
        ctrlrange = actuator.ctrlrange
        if actuator.inheritrange > 0 and "range" in joint.attrs:
            scale = reader.compiler.angle if joint.kind == "hinge" else 1.0
            low, high = _floats(joint.attrs["range"], f"{path}: joint '{joint.name}' range", (2,))
            middle, half = (low + high) / 2 * scale, (high - low) / 2 * scale
            ctrlrange = (
                middle - actuator.inheritrange * half,
                middle + actuator.inheritrange * half,
            )
        clamped = ctrlrange is not None and (
            actuator.ctrllimited == "true"
            or (actuator.ctrllimited == "auto" and reader.compiler.autolimits)
        )
        stiffness = -(actuator.gear**2) * actuator.bias[1]
        rests: dict[str, float] = {}
        for pose, ctrl in controls.items():
            c = float(ctrl[k])
            if clamped and flags["clampctrl"] and ctrlrange is not None:
                c = min(max(c, ctrlrange[0]), ctrlrange[1])
            rests[pose] = actuator.gear * (actuator.gain * c + actuator.bias[0]) / stiffness
        out.springs.append((joint.name, stiffness, rests["qpos0"]))
        for pose, rest in rests.items():
            out.rests.setdefault(pose, []).append(rest)
    described = [f"{a.label} on {j.name} ({-(a.gear**2) * a.bias[1]:g})" for _, a, j in mapped]
    reader.notes.append(
        f"position actuators as joint springs (actuator_springs = true): {_names(described)}, "
        "towards ctrl 0, or the ctrl of the keyframe [start] pose names"
    )
    if force_limited:
        reader.notes.append(
            f"forcerange of actuators {_names(force_limited)} not applied: their springs are "
            "linear (check that their force at the rest stays in range)"
        )
    return out


# --- the plain MJCF Pinocchio reads ------------------------------------------------------------


def _joint_motion(joint: _Joint, value: float) -> pinocchio.SE3:
    """The body's motion by a hinge or slide joint at ``value`` (MuJoCo: about the anchor)."""
    if joint.kind == "slide":
        return _to_se3(np.eye(3), joint.axis * value)
    rotation = _rotation(joint.axis, value)
    return _to_se3(rotation, joint.pos - rotation @ joint.pos)


class _Writer:
    """The plain MJCF: one root, one joint per body, no defaults, positions and quaternions."""

    def __init__(self, reader: _Reader, structure: _Structure) -> None:
        self.reader = reader
        c = reader.compiler
        self.mesh_masses: dict[str, _MeshMass] = {}
        #: Each body's mass, centre of mass and rotational inertia about it (body frame).
        self.inertias: dict[str, tuple[float, np.ndarray, np.ndarray]] = {}
        self.xml = ET.Element("mujoco", model=reader.root.get("model") or reader.path.stem)
        ET.SubElement(
            self.xml,
            "compiler",
            angle="radian",
            autolimits="true",
            inertiafromgeom="auto",
            boundinertia=repr(c.boundinertia),
        )
        world = ET.SubElement(self.xml, "worldbody")
        if structure.single:
            self._free(world, reader.bodies[0], structure.free[reader.bodies[0].name])
            return
        # A massless root at the world's origin holds the top-level bodies: Pinocchio reads
        # only the first top-level body and drops the placement of a fixed root.
        root = ET.SubElement(world, "body", name="world")
        self._zero_inertial(root)
        for body in reader.bodies:
            if body.name in structure.free:
                self._free(root, body, structure.free[body.name])
            else:  # fixed, or a locked free object (its free joint left out)
                self._body(root, body, body.pose)

    def _free(self, parent: ET.Element, body: _Body, joint: str) -> None:
        """A free body at the origin: Pinocchio misplaces a free body that has a pose of its
        own; its pose in the file becomes the start."""
        el = ET.SubElement(parent, "body", name=body.name)
        ET.SubElement(el, "freejoint", name=joint)
        self._fill(el, body)

    @staticmethod
    def _zero_inertial(el: ET.Element) -> None:
        ET.SubElement(el, "inertial", pos="0 0 0", mass="0", diaginertia="0 0 0")

    @staticmethod
    def _place(el: ET.Element, pose: pinocchio.SE3) -> None:
        el.set("pos", _text(pose.translation))
        el.set("quat", _text(_quat_wxyz(pose.rotation)))

    def _body(self, parent: ET.Element, body: _Body, pose: pinocchio.SE3) -> None:
        joints = [j for j in body.joints if j.kind != "free"]  # free: a locked object's
        el = parent
        for k, joint in enumerate(joints):
            last = k == len(joints) - 1
            # A body with several joints: a chain of massless bodies, one joint each, composed
            # in the body's order as MuJoCo composes them. The pose is the file's pose moved
            # back by the joint's ref, so that Pinocchio's q is MuJoCo's qpos.
            el = ET.SubElement(el, "body", name=body.name if last else f"{body.name}/{joint.name}")
            motion = _joint_motion(joint, -joint.ref) if joint.kind != "ball" else None
            self._place(el, pose * motion if motion is not None else pose)
            ET.SubElement(
                el,
                "joint",
                name=joint.name,
                type=joint.kind,
                pos=_text(joint.pos),
                axis=_text(joint.axis),
            )
            if not last:
                self._zero_inertial(el)
            pose = pinocchio.SE3.Identity()
        if not joints:
            el = ET.SubElement(parent, "body", name=body.name)
            self._place(el, pose)
        self._fill(el, body)

    def _fill(self, el: ET.Element, body: _Body) -> None:
        """Mass, sites and child bodies of a body into its element."""
        self._mass(el, body)
        for name, pose in body.sites.items():
            site = ET.SubElement(el, "site", name=name)
            self._place(site, pose)
        for child in body.children:
            self._body(el, child, child.pose)

    def _mass(self, el: ET.Element, body: _Body) -> None:
        """The body's inertial, or the geoms its mass comes from (MuJoCo's rules: explicit
        unless inertiafromgeom is true or the inertial is missing; geoms in the inertia group
        range with a non-zero mass or density)."""
        reader = self.reader
        c = reader.compiler
        use_geoms = c.inertiafromgeom == "true" or (
            c.inertiafromgeom == "auto" and body.inertial is None
        )
        if not use_geoms:
            if body.inertial is None:
                reader.refuse(
                    f'<body name="{body.name}">',
                    'without <inertial> while <compiler inertiafromgeom="false">',
                    "give it an <inertial>",
                )
                return
            a = body.inertial.attrib
            where = f"{reader.path}: <inertial> of body '{body.name}'"
            mass = max(float(_floats(a.get("mass", ""), f"{where} mass", (1,))[0]), c.boundmass)
            if mass < 0:
                raise MjcfError(f"{where} mass: must be >= 0, got {mass:g}")
            inertial = ET.SubElement(el, "inertial", mass=repr(mass))
            assert body.inertial_pose is not None
            self._place(inertial, body.inertial_pose)
            rotation = body.inertial_pose.rotation
            if "fullinertia" in a:
                full = _floats(a["fullinertia"], f"{where} fullinertia", (6,))
                inertial.set("fullinertia", _text(full))
                xx, yy, zz, xy, xz, yz = full
                tensor = rotation @ np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
            else:
                if "diaginertia" not in a and body.joints:
                    raise MjcfError(
                        f"{where}: neither diaginertia nor fullinertia, and the body moves "
                        "(MuJoCo refuses a moving body without inertia too): give one"
                    )
                diagonal = _floats(a.get("diaginertia", "0 0 0"), f"{where} diaginertia", (3,))
                inertial.set("diaginertia", _text(diagonal))
                tensor = rotation @ np.diag(diagonal)
            self.inertias[body.name] = (
                mass,
                np.array(body.inertial_pose.translation),
                tensor @ rotation.T,
            )
            return
        parts = [part for geom in body.geoms if (part := self._geom_mass(body, geom))]
        if not parts:
            if c.boundmass > 0:
                ET.SubElement(
                    el,
                    "inertial",
                    pos="0 0 0",
                    mass=repr(c.boundmass),
                    diaginertia=_text([c.boundinertia] * 3),
                )
            return
        # MuJoCo's InertiaFromGeom: the geoms' masses, centres and inertias summed, then
        # boundmass and boundinertia on the total and its principal moments.
        mass = sum(part.mass for part in parts)
        com: np.ndarray = np.sum([part.mass * part.com for part in parts], axis=0) / mass
        inertia: np.ndarray = np.sum(
            [
                part.inertia + part.mass * (float(d @ d) * np.eye(3) - np.outer(d, d))
                for part in parts
                for d in [part.com - com]
            ],
            axis=0,
        )
        if c.boundinertia > 0:
            moments, axes = np.linalg.eigh(inertia)
            inertia = axes @ np.diag(np.maximum(moments, c.boundinertia)) @ axes.T
        mass = max(mass, c.boundmass)
        self.inertias[body.name] = (float(mass), com, inertia)
        ET.SubElement(
            el,
            "inertial",
            pos=_text(com),
            mass=repr(float(mass)),
            fullinertia=_text(inertia[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]]),
        )

    def _geom_mass(self, body: _Body, geom: _Geom) -> _GeomMass | None:
        """A geom's part of its body's mass, as MuJoCo computes it (user_objects.cc:
        GetVolume, SetInertia); None for a geom outside the inertia group range or of no
        mass."""
        reader = self.reader
        a = geom.attrs
        where = f"{reader.path}: {geom.label} in body '{body.name}'"
        low, high = reader.compiler.inertiagrouprange
        group = int(_floats(a.get("group", "0"), f"{where} group", (1,))[0])
        if not low <= group <= high:
            return None
        key = "mass" if "mass" in a else "density"
        amount = float(_floats(a.get(key, "1000"), f"{where} {key}", (1,))[0])
        if amount < 0:
            raise MjcfError(f"{where} {key}: must be >= 0, got {amount:g}")
        if amount == 0:
            return None
        kind = a.get("type", "sphere")
        shell = _flag(a.get("shellinertia", "false"), f"{where} shellinertia", ("true", "false"))
        what = f"{geom.label} of body '{body.name}'"
        if kind == "mesh":
            if shell == "true":
                raise MjcfError(
                    f"{where}: shellinertia on a mesh geom (MuJoCo refuses it too): give the "
                    '<mesh> inertia="shell" instead'
                )
            return self._mesh_geom_mass(body, geom, key, amount)
        if "mesh" in a:
            reader.refuse(
                f"{what} (mesh '{a['mesh']}')",
                "sized to fit a mesh (pinsettle does not size geoms from meshes)",
                "give the geom a size and no mesh, or its body an <inertial>",
            )
            return None
        if kind in ("plane", "hfield", "sdf") or kind not in _MASS_SHAPES:
            if kind == "plane":
                return None  # no volume: MuJoCo gives it no mass
            reader.refuse(
                what,
                f"(the mass of a {kind} geom is not computed)",
                "give its body an <inertial>",
            )
            return None
        rotation, center, size = self._shape(geom, kind, where)
        volume, moments = _shape_mass(kind, size, shell == "true")
        if volume <= _EPS:
            return None
        mass = amount if key == "mass" else amount * volume
        inertia = rotation @ np.diag(moments * mass) @ rotation.T
        return _GeomMass(mass, center, inertia)

    def _shape(
        self, geom: _Geom, kind: str, where: str
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A primitive's rotation and centre in the body frame and its sizes (MuJoCo's
        fromto: the z axis from end to end, the half length its last size)."""
        needed = _MASS_SHAPES[kind]
        text = geom.attrs.get("size", "")
        if geom.fromto is not None:
            if kind == "sphere":
                raise MjcfError(f"{where}: fromto needs a capsule, cylinder, box or ellipsoid")
            ends = geom.fromto
            half = float(np.linalg.norm(ends[:3] - ends[3:])) / 2
            if half < _EPS:
                raise MjcfError(f"{where} fromto: the two ends are too close")
            radius = float(_floats(text, f"{where} size", (1, 2, 3))[0])
            size = np.array([radius, half] if needed == 2 else [radius, radius, half])
            rotation = _z_to(ends[:3] - ends[3:], f"{where} fromto")
            center = (ends[:3] + ends[3:]) / 2
        else:
            size = _floats(text, f"{where} size", tuple(range(needed, 4)))[:needed]
            rotation, center = geom.pose.rotation, geom.pose.translation
        if np.any(size <= 0):
            raise MjcfError(f"{where} size: must be positive, got {text}")
        return np.asarray(rotation), np.asarray(center, dtype=float), size

    def _mesh_geom_mass(
        self, body: _Body, geom: _Geom, key: str, amount: float
    ) -> _GeomMass | None:
        reader = self.reader
        where = f"{reader.path}: {geom.label} in body '{body.name}'"
        name = geom.attrs.get("mesh")
        if not name or name not in reader.meshes:
            known = _names(sorted(reader.meshes), 6) if reader.meshes else "none"
            raise MjcfError(f"{where}: unknown mesh '{name}' (meshes of <asset>: {known})")
        if name not in self.mesh_masses:
            mesh = reader.meshes[name]
            try:
                self.mesh_masses[name] = _mesh_mass(mesh, where)
            except MjcfError as error:
                reader.refuse(
                    f"{geom.label} of body '{body.name}'",
                    f"(its mass comes from {error})",
                    "or give the body an <inertial>",
                )
                return None
            except OSError as error:
                raise MjcfError(f"{where}: mesh '{name}': {error}") from None
        props = self.mesh_masses[name]
        if props.volume <= _EPS:
            return None
        density = amount / props.volume if key == "mass" else amount
        rotation = np.asarray(geom.pose.rotation)
        return _GeomMass(
            density * props.volume,
            geom.pose.act(props.com),
            rotation @ (density * props.inertia) @ rotation.T,
        )


def _shape_mass(kind: str, size: np.ndarray, shell: bool) -> tuple[float, np.ndarray]:
    """A primitive's volume (its area for a shell) and its principal moments per unit mass,
    MuJoCo's formulas."""
    pi = math.pi
    if kind == "sphere":
        r = size[0]
        if shell:
            return 4 * pi * r**2, np.full(3, 2 * r**2 / 3)
        return 4 * pi * r**3 / 3, np.full(3, 2 * r**2 / 5)
    if kind in ("capsule", "cylinder"):
        r, half = size
        h = 2 * half
        if kind == "cylinder" and not shell:
            return pi * r * r * h, np.array([(3 * r * r + h * h) / 12] * 2 + [r * r / 2])
        if kind == "cylinder":
            disk, side = pi * r * r, 2 * pi * r * h
            m_disk = disk / (2 * disk + side)
            m_side = 1 - 2 * m_disk
            across = m_side * (6 * r * r + h * h) / 12 + 2 * (m_disk * r * r / 4 + m_disk * half**2)
            along = m_side * r * r + 2 * m_disk * r * r / 2
            return 2 * disk + side, np.array([across, across, along])
        if not shell:
            m_sphere = 4 * r / (4 * r + 3 * h)
            m_cyl = 1 - m_sphere
            across = (
                m_cyl * (3 * r * r + h * h) / 12
                + 2 * m_sphere * r * r / 5
                + m_sphere * h * (3 * r + 2 * h) / 8
            )
            along = m_cyl * r * r / 2 + 2 * m_sphere * r * r / 5
            return pi * (r * r * h + 4 * r**3 / 3), np.array([across, across, along])
        a_sphere, a_cyl = 4 * pi * r * r, 2 * pi * r * h
        m_sphere = a_sphere / (a_sphere + a_cyl)
        m_cyl = 1 - m_sphere
        hs_com, hs_pos = r / 2, half + r / 2
        across = (
            m_cyl * (6 * r * r + h * h) / 12
            + 2 * m_sphere * r * r / 3
            + m_sphere * (hs_pos**2 - hs_com**2)
        )
        along = m_cyl * r * r + 2 * m_sphere * r * r / 3
        return a_sphere + a_cyl, np.array([across, across, along])
    s2 = size**2
    if kind == "ellipsoid":
        solid = np.array([s2[1] + s2[2], s2[0] + s2[2], s2[0] + s2[1]]) / 5
        if not shell:
            return 4 * pi * size.prod() / 3, solid
        p = 1.6075
        area = (
            4
            * pi
            * (((size[0] * size[1]) ** p + (size[1] * size[2]) ** p + (size[2] * size[0]) ** p) / 3)
            ** (1 / p)
        )
        # MuJoCo's approximation: the solid grown by 1e-6 minus the solid, at one density.
        grown = size + 1e-6
        v_a, v_b = 4 * pi * size.prod() / 3, 4 * pi * grown.prod() / 3
        g2 = grown**2
        outer = np.array([g2[1] + g2[2], g2[0] + g2[2], g2[0] + g2[1]]) / 5
        return area, (v_b * outer - v_a * solid) / (v_b - v_a)
    # box
    if not shell:
        return 8 * size.prod(), np.array([s2[1] + s2[2], s2[0] + s2[2], s2[0] + s2[1]]) / 3
    lx, ly, lz = 2 * size
    a0, a1, a2 = lx * ly, ly * lz, lz * lx
    total = 2 * (a0 + a1 + a2)
    m0, m1, m2 = a0 / total, a1 / total, a2 / total
    ix = 2 * (
        m0 * s2[2] + m2 * s2[1] + m0 * ly**2 / 12 + m1 * (ly**2 + lz**2) / 12 + m2 * lz**2 / 12
    )
    iy = 2 * (
        m0 * s2[2] + m1 * s2[0] + m0 * lx**2 / 12 + m1 * lz**2 / 12 + m2 * (lx**2 + lz**2) / 12
    )
    iz = 2 * (
        m1 * s2[0] + m2 * s2[1] + m0 * (lx**2 + ly**2) / 12 + m1 * ly**2 / 12 + m2 * lx**2 / 12
    )
    return total, np.array([ix, iy, iz])


FREE_OBJECTS = ("keep", "lock")


@dataclass
class _Structure:
    """Which top-level bodies float, and how."""

    #: Top-level bodies with a free joint in the model: body -> the joint's name (the file's
    #: own, or ``added``).
    free: dict[str, str]
    #: The free joint ``floating`` adds to the root body, if any.
    added: str | None = None
    #: Free objects locked where the file places them (their free joint left out).
    locked: list[str] = field(default_factory=list)
    #: The model is a single free body and its subtree (written as Pinocchio's root).
    single: bool = False


def _has_joints(body: _Body) -> bool:
    return bool(body.joints) or any(_has_joints(child) for child in body.children)


def _structure(reader: _Reader, floating: bool, free_objects: str) -> _Structure:
    """The file's free bodies and free objects, and the free joint ``floating`` adds.

    A free object is a top-level body whose only joint (in its subtree too) is its free joint:
    a box or a ball beside a robot. ``free_objects`` 'keep' leaves it free (nothing holds it:
    it falls), 'lock' fixes it where the file places it. A free body with joints below it (a
    humanoid) floats, as in MuJoCo. ``floating`` adds a free joint to the root body of a file
    that has none: the single top-level body other than the free objects, without a joint of
    its own."""
    path = reader.path
    if free_objects not in FREE_OBJECTS:
        raise MjcfError(
            f"free_objects: expected 'keep' or 'lock', got {free_objects!r} ('keep': free "
            "objects stay free and fall; 'lock': they are fixed where the file places them)"
        )
    top = reader.bodies
    for body in reader.all_bodies():
        if any(j.kind == "free" for j in body.joints):
            if len(body.joints) > 1:
                raise MjcfError(f"{path}: body '{body.name}' has a free joint and other joints")
            if body not in top:
                raise MjcfError(
                    f"{path}: body '{body.name}' has a free joint but is not a top-level body "
                    "(MuJoCo refuses this too): move it to <worldbody>"
                )
    free_top = [b for b in top if b.joints]
    free_top = [b for b in free_top if b.joints[0].kind == "free"]
    objects = [b for b in free_top if not any(_has_joints(c) for c in b.children)]
    structure = _Structure({b.name: b.joints[0].name for b in free_top})
    if objects:
        names = _names([b.name for b in objects])
        plural = len(objects) > 1
        if free_objects == "lock":
            structure.locked = [b.name for b in objects]
            for b in objects:
                del structure.free[b.name]
            reader.notes.append(
                f"free object{'s' if plural else ''} {names} locked where the file places "
                f'{"them" if plural else "it"} (free_objects = "lock")'
            )
        else:
            reader.notes.append(
                f"free object{'s' if plural else ''} {names} kept free (free_objects = "
                f'"keep"): nothing holds {"them" if plural else "it"} (contacts play no '
                f"part): under gravity {'they fall' if plural else 'it falls'} and the solve "
                'ends no_equilibrium; free_objects = "lock" (--free-objects lock) fixes '
                f"{'them' if plural else 'it'} where the file places {'them' if plural else 'it'}"
            )
    if floating:
        robots = [b for b in top if b not in objects]
        own = [b for b in robots if b.name in structure.free]
        if own:
            reader.notes.append(
                f"floating: body '{own[0].name}' floats by the file's own free joint "
                f"'{structure.free[own[0].name]}'; nothing added"
            )
        elif len(robots) != 1:
            raise MjcfError(
                f"{path}: floating: {len(robots)} top-level bodies ("
                + _names([b.name for b in robots])
                + ")"
                + (
                    f" beside the free objects ({_names([b.name for b in objects])})"
                    if objects
                    else ""
                )
                + "; a free joint goes on a single root body: give one a <freejoint/> in the "
                "file instead"
            )
        elif robots[0].joints:
            raise MjcfError(
                f"{path}: floating: the root body '{robots[0].name}' is attached by joint "
                f"'{robots[0].joints[0].name}' already; give it a <freejoint/> in the file "
                "instead"
            )
        else:
            structure.added = "root_joint"
            structure.free[robots[0].name] = "root_joint"
    structure.single = len(top) == 1 and top[0].name in structure.free
    return structure


def _build(xml: ET.Element, path: Path) -> pinocchio.Model:
    with tempfile.TemporaryDirectory(prefix="pinsettle-mjcf-") as folder:
        plain = Path(folder) / "model.xml"
        ET.ElementTree(xml).write(plain, encoding="utf-8", xml_declaration=True)
        try:
            return pinocchio.buildModelFromMJCF(str(plain))
        except (RuntimeError, ValueError) as error:
            message = str(error).split("message:")[-1].strip()
            raise MjcfError(f"{path}: Pinocchio's MJCF parser: {message}") from None


def _qpos_order(reader: _Reader, structure: _Structure) -> list[_Joint]:
    """The file's joints in MuJoCo's qpos order (depth first, in body order), a free joint
    added by ``floating`` first; locked free objects' joints included (keyframes hold them)."""
    joints = [j for body in reader.all_bodies() for j in body.joints]
    if structure.added is not None:
        body = next(b for b, j in structure.free.items() if j == structure.added)
        joints.insert(0, _Joint(structure.added, "free", np.zeros(3), np.zeros(3), {}, body))
    return joints


def _world_pose(reader: _Reader, body: _Body) -> pinocchio.SE3:
    chain: list[_Body] = []

    def find(nodes: list[_Body]) -> bool:
        for node in nodes:
            chain.append(node)
            if node is body or find(node.children):
                return True
            chain.pop()
        return False

    find(reader.bodies)
    pose = pinocchio.SE3.Identity()
    for node in chain:
        pose = pose * node.pose
    return pose


def _reference(
    reader: _Reader,
    model: pinocchio.Model,
    joints: list[_Joint],
    structure: _Structure,
) -> tuple[np.ndarray, dict[str, float | list[float]]]:
    """MuJoCo's qpos0 in Pinocchio's configuration, and by joint name where not neutral (a
    free joint's value as its configuration entries, Pinocchio's order)."""
    q: np.ndarray = pinocchio.neutral(model)
    start: dict[str, float | list[float]] = {}
    floats = {joint: body for body, joint in structure.free.items()}
    for joint in joints:
        if not model.existJointName(joint.name):
            continue  # a locked free object's
        j = model.getJointId(joint.name)
        iq = model.idx_qs[j]
        if joint.kind == "free" and joint.name in floats:
            pose = _world_pose(reader, reader.body_names[floats[joint.name]])
            value = [*pose.translation, *pinocchio.Quaternion(pose.rotation).coeffs()]
            q[iq : iq + 7] = value
            start[joint.name] = [float(x) for x in value]
        elif joint.kind in ("hinge", "slide") and joint.ref != 0.0:
            q[iq] = joint.ref
            start[joint.name] = joint.ref
    return q, start


def _keyframes(
    reader: _Reader, model: pinocchio.Model, joints: list[_Joint], q0: np.ndarray, added: bool
) -> dict[str, np.ndarray]:
    """The keyframes' qpos in Pinocchio's configuration (quaternions w x y z -> x y z w)."""
    sizes = {"hinge": 1, "slide": 1, "ball": 4, "free": 7}
    file_joints = joints[1:] if added else joints
    nq = sum(sizes[j.kind] for j in file_joints)
    poses: dict[str, np.ndarray] = {}
    mocap: list[str] = []
    for section in reader.root.findall("keyframe"):
        for k, key in enumerate(section.findall("key")):
            name = key.get("name") or f"key{k}"
            where = f'{reader.path}: <key name="{name}">'
            if "mpos" in key.attrib or "mquat" in key.attrib:
                mocap.append(name)
            if "qpos" not in key.attrib:
                poses[name] = q0.copy()
                continue
            qpos = _floats(key.attrib["qpos"], f"{where} qpos", (nq,))
            q = q0.copy()
            at = 0
            for joint in file_joints:
                n = sizes[joint.kind]
                values = qpos[at : at + n]
                at += n
                if not model.existJointName(joint.name):
                    continue  # a locked free object stays where the file places it
                iq = model.idx_qs[model.getJointId(joint.name)]
                if n == 7:
                    values = np.concatenate([values[:3], values[4:], values[3:4]])
                elif n == 4:
                    values = np.concatenate([values[1:], values[:1]])
                q[iq : iq + n] = values
            poses[name] = pinocchio.normalize(model, q)
    if mocap:
        reader.notes.append(
            f"keyframe{'s' if len(mocap) > 1 else ''} {_names(mocap)}: the poses of mocap bodies "
            "(mpos, mquat) are not applied"
        )
    return poses


class _Ends:
    """Loop ends: a frame name and a point, frames added to the model where an end needs its
    own orientation."""

    def __init__(self, reader: _Reader, model: pinocchio.Model, q0: np.ndarray) -> None:
        self.reader = reader
        self.model = model
        self.data = model.createData()
        pinocchio.framesForwardKinematics(model, self.data, q0)

    def body(self, name: str, where: str) -> str:
        """The frame of a body ('universe' for the world)."""
        if name == "world":
            return "universe"
        if name not in self.reader.body_names:
            raise MjcfError(f"{where}: unknown body '{name}'")
        return name

    def placement(self, frame: str) -> pinocchio.SE3:
        """The frame's pose at qpos0."""
        return self.data.oMf[self.frame_id(frame)]

    def frame_id(self, frame: str) -> int:
        for i, f in enumerate(self.model.frames):
            if f.name == frame and (frame == "universe" or f.type == pinocchio.FrameType.BODY):
                return i
        raise MjcfError(f"{self.reader.path}: frame '{frame}' is missing from the model")

    def site(self, name: str, where: str) -> tuple[str, pinocchio.SE3]:
        """A site as (frame of its body, its pose in that frame)."""
        if name in self.reader.world_sites:
            return "universe", self.reader.world_sites[name]
        if name not in self.reader.site_body:
            raise MjcfError(f"{where}: unknown site '{name}'")
        body = self.reader.site_body[name]
        return body, self.reader.body_names[body].sites[name]

    def add(self, name: str, frame: str, local: pinocchio.SE3) -> str:
        """A frame on the body of ``frame`` at ``local`` in it; returns its name."""
        parent = self.model.frames[self.frame_id(frame)]
        fid = self.frame_id(frame)
        self.model.addFrame(
            pinocchio.Frame(
                name,
                parent.parentJoint,
                fid,
                parent.placement * local,
                pinocchio.FrameType.OP_FRAME,
            )
        )
        return name


def _loops(
    reader: _Reader,
    model: pinocchio.Model,
    q0: np.ndarray,
    flags: Mapping[str, bool],
) -> list[tuple[str, tuple[float, ...], str, tuple[float, ...], str]]:
    """The connect and weld equalities as loops (frame_a, point_a, frame_b, point_b, kind)."""
    loops: list[tuple[str, tuple[float, ...], str, tuple[float, ...], str]] = []
    ends = _Ends(reader, model, q0)
    inactive: list[str] = []
    disabled: list[str] = []
    zero = (0.0, 0.0, 0.0)
    for section in reader.root.findall("equality"):
        for k, el in enumerate(section):
            a = reader._resolved(el, None)
            label = a.get("name") or f"equality{k}"
            where = f"{reader.path}: {_describe(el)} in <equality>"
            if el.tag not in ("connect", "weld"):
                reader.refuse(
                    f"{_describe(el)} in <equality>",
                    f"(a {el.tag} equality: connect and weld equalities are honoured, as loops)",
                    "remove it in a copy (its joints or bodies then settle independently), "
                    'or <option><flag equality="disable"/>',
                )
                continue
            if _flag(a.get("active", "true"), f"{where} active", ("true", "false")) == "false":
                inactive.append(label)
                continue
            if not (flags["equality"] and flags["constraint"]):
                disabled.append(label)
                continue
            sites = "site1" in a or "site2" in a
            if sites:
                if not ("site1" in a and "site2" in a) or "body1" in a or "body2" in a:
                    raise MjcfError(f"{where}: give site1 and site2, or body1 (and body2)")
                fa, pa = ends.site(a["site1"], where)
                fb, pb = ends.site(a["site2"], where)
                if el.tag == "connect" or _weld_as_point(a, where):
                    loops.append((fa, tuple(pa.translation), fb, tuple(pb.translation), "point"))
                else:
                    loops.append(
                        (
                            ends.add(f"{label}/site1", fa, pa),
                            zero,
                            ends.add(f"{label}/site2", fb, pb),
                            zero,
                            "frame",
                        )
                    )
                continue
            if "body1" not in a:
                raise MjcfError(f"{where}: needs body1 (or site1 and site2)")
            fa = ends.body(a["body1"], where)
            fb = ends.body(a.get("body2", "world"), where)
            x_a, x_b = ends.placement(fa), ends.placement(fb)
            if el.tag == "connect":
                if "anchor" not in a:
                    raise MjcfError(f"{where}: a connect by bodies needs an anchor")
                anchor = _floats(a["anchor"], f"{where} anchor", (3,))
                # The point on body2 is where the anchor is at qpos0 (MuJoCo's rule).
                on_b = x_b.actInv(x_a.act(anchor))
                loops.append((fa, tuple(anchor), fb, tuple(on_b), "point"))
                continue
            anchor = _floats(a.get("anchor", "0 0 0"), f"{where} anchor", (3,))
            relpose = _floats(a.get("relpose", "0 1 0 0 0 0 0"), f"{where} relpose", (7,))
            if np.any(relpose[3:]):
                w, x, y, z = relpose[3:] / np.linalg.norm(relpose[3:])
                on_a = _to_se3(pinocchio.Quaternion(w, x, y, z).matrix(), relpose[:3])
            else:  # the relative pose of qpos0
                on_a = x_a.actInv(x_b) * _to_se3(np.eye(3), anchor)
            if _weld_as_point(a, where):
                loops.append((fa, tuple(on_a.translation), fb, tuple(anchor), "point"))
            else:
                loops.append(
                    (ends.add(f"{label}/body1", fa, on_a), zero, fb, tuple(anchor), "frame")
                )
    if inactive:
        reader.notes.append(f'ignored: inactive equalities {_names(inactive)} (active="false")')
    if disabled:
        reader.notes.append(f"ignored: equalities {_names(disabled)}: disabled by <option><flag>")
    return loops


def _weld_as_point(attrs: Mapping[str, str], where: str) -> bool:
    """A weld with torquescale 0 holds no rotation: MuJoCo says it acts as a connect."""
    return float(_floats(attrs.get("torquescale", "1"), f"{where} torquescale", (1,))[0]) == 0.0


# --- the entry point ---------------------------------------------------------------------------


def load_mjcf(
    path: str | Path,
    floating: bool = False,
    free_objects: str = "keep",
    actuator_springs: bool = False,
) -> MjcfModel:
    """Read an MJCF file for statics (see the module docstring).

    A body with a ``<freejoint>`` floats, as in MuJoCo. ``floating``: a free joint added to
    the root body of a file that has none (the single top-level body beside the free objects,
    which must have no joint; a note says so when the file's own free joint floats it
    already). ``free_objects``: the free objects (top-level bodies whose only joint is their
    free joint, a box beside a robot) stay free and fall ('keep') or are fixed where the file
    places them ('lock'). ``actuator_springs``: each position actuator on a hinge or slide
    joint (force kp (ctrl - gear q) at rest) becomes a joint spring of stiffness gear^2 kp
    towards ctrl / gear: ctrl 0, or a keyframe's ctrl (``actuator_rests``, for the scene's
    pose).

    Raises:
        FileNotFoundError: no such file.
        MjcfError (a ValueError): not MJCF, a missing include or asset, or something with a
            static effect that cannot be honoured (the message names the elements).
    """
    path = Path(path)
    reader = _Reader(path)
    gravity, flags = _option(reader)
    statics = _joint_statics(reader, flags)
    _other_sections(reader, flags)
    actuators = _actuators(reader, flags, actuator_springs)
    structure = _structure(reader, floating, free_objects)
    writer = _Writer(reader, structure)
    reader.check_refusals()
    if not reader.bodies:
        raise MjcfError(f"{path}: no body in <worldbody>: nothing to settle")
    model = _build(writer.xml, path)
    joints = _qpos_order(reader, structure)
    locked = {j.name for j in joints if j.body in structure.locked}
    expected = [j for j in joints if j.name not in locked]
    missing = [j.name for j in expected if not model.existJointName(j.name)]
    if missing or model.njoints - 1 != len(expected):
        raise MjcfError(
            f"{path}: Pinocchio's model has {model.njoints - 1} joints for the file's "
            f"{len(expected)}" + (f"; missing: {_names(missing)}" if missing else "")
        )
    if model.nv == 0:
        raise MjcfError(
            f"{path}: no joint: every body is fixed, nothing to settle"
            + ('; free_objects = "keep" lets the free objects fall' if locked else "")
        )
    lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    for joint in joints:
        if joint.kind in ("hinge", "slide"):
            iq = model.idx_qs[model.getJointId(joint.name)]
            lower[iq], upper[iq] = statics.limits.get(joint.name, (-math.inf, math.inf))
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper
    model.gravity = pinocchio.Motion(gravity, np.zeros(3))
    q0, start = _reference(reader, model, joints, structure)
    for name, q in _keyframes(reader, model, joints, q0, structure.added is not None).items():
        model.referenceConfigurations[name] = q
    model.referenceConfigurations["qpos0"] = q0
    loops = _loops(reader, model, q0, flags)
    reader.check_refusals()
    return MjcfModel(
        model=model,
        name=str(writer.xml.get("model")),
        joint_springs=statics.springs,
        loops=loops,
        start=start,
        notes=reader.notes,
        inertias=writer.inertias,
        actuator_springs=actuators.springs,
        actuator_rests=actuators.rests,
    )

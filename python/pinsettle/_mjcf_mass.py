"""Masses of MJCF geoms as MuJoCo compiles them: primitives from their formulas, meshes
(STL, OBJ, MSH) from their volume or surface, for each of MuJoCo's inertia rules."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio

from ._mjcf_parse import _MASS_SHAPES, MjcfError, _flag, _floats, _Geom, _MeshAsset, _z_to

# --- masses from meshes, as MuJoCo computes them ----------------------------------------------

# MuJoCo's small numbers (mjMINVAL, mjEPS) and its limit on an STL file's faces.
_MINVAL = 1e-15
_EPS = 1e-14
_STL_MAX_FACES = 200000
_MESH_INERTIA = ("legacy", "exact", "convex", "shell")


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


def _primitive(geom: _Geom, kind: str, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A primitive's rotation and centre in the body frame and its sizes (MuJoCo's fromto: the
    z axis from end to end, the half length its last size)."""
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
                vertices.append(_obj_vertex(parts))
            elif parts[0] in ("g", "o") and faces:
                first_shape = False
            elif parts[0] == "f" and first_shape:
                faces.extend(_obj_face(parts, vertices))
        except ValueError:
            shown = line.strip()[:60]
            raise _mesh_refusal(mesh, f"line {number} is not a valid OBJ line: {shown!r}") from None
    points = np.array(vertices, dtype=np.float32).astype(np.float64).reshape(-1, 3)
    triangles = np.array(faces, dtype=np.int64).reshape(-1, 3)
    if triangles.size and (triangles.min() < 0 or triangles.max() >= len(points)):
        raise _mesh_refusal(mesh, "a face names a vertex the file does not have")
    return points, triangles


def _obj_vertex(parts: list[str]) -> list[float]:
    """A 'v' line's point (ValueError: not three numbers)."""
    point = [float(x) for x in parts[1:4]]
    if len(point) != 3:
        raise ValueError
    return point


def _obj_face(parts: list[str], vertices: list[list[float]]) -> list[list[int]]:
    """An 'f' line's triangles, indices from 0 (a negative one counts back from the last
    vertex read); ValueError: not a face."""
    index = [int(p.split("/")[0]) for p in parts[1:]]
    index = [i - 1 if i > 0 else len(vertices) + i for i in index]
    if len(index) < 3:
        raise ValueError
    return _triangles(index, vertices)


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
    rule = _flag(mesh.attrs.get("inertia", "legacy"), f"{mesh.label} inertia", _MESH_INERTIA)
    vertices, faces = _placed_geometry(mesh)
    if rule == "convex" or not len(faces):
        vertices, faces = _convex_hull(mesh, vertices)
    if rule == "exact":
        _check_oriented(mesh, faces)
    d, e, f = (vertices[faces[:, k]] for k in range(3))
    surface = _Faces.of(mesh, d, e, f)
    com = _mesh_com(mesh, rule, surface)
    # Second moments about the centre of mass, per face (MuJoCo's ComputeInertia).
    weight = _face_weights(rule, surface.center - com, surface)
    volume = float(weight.sum())
    divisor = 12.0 if rule == "shell" else 20.0
    products = _second_moments(d - com, e - com, f - com, weight / divisor)
    inertia = np.trace(products) * np.eye(3) - products
    eigen = np.linalg.eigvalsh(inertia)
    if eigen[0] <= 0:
        raise _mesh_refusal(mesh, "its inertia is not positive (MuJoCo refuses it too)")
    return _MeshMass(volume, com, inertia)


def _placed_geometry(mesh: _MeshAsset) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's vertices and faces after the user's offset, rotation and scale (MuJoCo:
    minus refpos, by refquat's inverse, times scale; a mirroring scale turns the faces
    over)."""
    a = mesh.attrs
    vertices, faces = _mesh_geometry(mesh)
    if len(vertices) < 4:
        raise _mesh_refusal(mesh, f"{len(vertices)} vertices; MuJoCo needs at least 4")
    if not np.all(np.isfinite(vertices)):
        raise _mesh_refusal(mesh, "a vertex coordinate is not finite")
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
    return vertices, faces


def _check_oriented(mesh: _MeshAsset, faces: np.ndarray) -> None:
    """inertia="exact": no two faces run along an edge the same way."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    if len(np.unique(edges, axis=0)) < len(edges):
        raise _mesh_refusal(
            mesh,
            'inertia="exact" needs consistently oriented faces and two faces run along '
            "an edge the same way (MuJoCo refuses this too): fix the mesh, or use "
            'inertia="convex"',
        )


@dataclass
class _Faces:
    """Each face's area (0 for a degenerate one), unit normal and centre."""

    area: np.ndarray
    normal: np.ndarray
    center: np.ndarray

    @staticmethod
    def of(mesh: _MeshAsset, d: np.ndarray, e: np.ndarray, f: np.ndarray) -> _Faces:
        cross = np.cross(e - d, f - d)
        length = np.linalg.norm(cross, axis=1)
        small = length < _MINVAL
        area = np.where(small, 0.0, 0.5 * length)
        if float(area.sum()) < _MINVAL:
            raise _mesh_refusal(mesh, "its surface area is too small (MuJoCo refuses it too)")
        return _Faces(area, cross / np.where(small, 1.0, length)[:, None], (d + e + f) / 3)


def _face_weights(rule: str, offset: np.ndarray, faces: _Faces) -> np.ndarray:
    """Each face's share: its area for a shell, else the volume of its pyramid from a point
    (``offset``: the face's centre from that point), positive under the legacy rule."""
    if rule == "shell":
        return faces.area
    weight: np.ndarray = np.einsum("ij,ij->i", offset, faces.normal) * faces.area / 3
    return np.abs(weight) if rule == "legacy" else weight


def _mesh_com(mesh: _MeshAsset, rule: str, faces: _Faces) -> np.ndarray:
    """The centre of mass (MuJoCo's ComputeVolume: pyramids from the faces' mean centre)."""
    facecen = (faces.area[:, None] * faces.center).sum(axis=0) / float(faces.area.sum())
    weight = _face_weights(rule, faces.center - facecen, faces)
    total = float(weight.sum())
    if rule != "shell" and total < _MINVAL:
        raise _mesh_refusal(
            mesh,
            "its volume is negative (faces turned inwards)"
            if total < 0
            else "its volume is too small; MuJoCo refuses it too unless the mesh has "
            'inertia="shell"',
        )
    if rule == "shell":
        com: np.ndarray = (weight[:, None] * faces.center).sum(axis=0) / total
    else:
        com = (weight[:, None] * (faces.center * 0.75 + facecen / 4)).sum(axis=0) / total
    return com


def _second_moments(d: np.ndarray, e: np.ndarray, f: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The weighted sum of the faces' second moments (vertices about the centre of mass)."""
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
            products[i, j] = products[j, i] = float((weight * terms).sum())
    return products


def _shape_mass(kind: str, size: np.ndarray, shell: bool) -> tuple[float, np.ndarray]:
    """A primitive's volume (its area for a shell) and its principal moments per unit mass,
    MuJoCo's formulas."""
    return _SHAPE_MASS[kind](size, shell)


def _sphere_mass(size: np.ndarray, shell: bool) -> tuple[float, np.ndarray]:
    r = size[0]
    if shell:
        return 4 * math.pi * r**2, np.full(3, 2 * r**2 / 3)
    return 4 * math.pi * r**3 / 3, np.full(3, 2 * r**2 / 5)


def _cylinder_mass(size: np.ndarray, shell: bool) -> tuple[float, np.ndarray]:
    r, half = size
    h = 2 * half
    if not shell:
        return math.pi * r * r * h, np.array([(3 * r * r + h * h) / 12] * 2 + [r * r / 2])
    disk, side = math.pi * r * r, 2 * math.pi * r * h
    m_disk = disk / (2 * disk + side)
    m_side = 1 - 2 * m_disk
    across = m_side * (6 * r * r + h * h) / 12 + 2 * (m_disk * r * r / 4 + m_disk * half**2)
    along = m_side * r * r + 2 * m_disk * r * r / 2
    return 2 * disk + side, np.array([across, across, along])


def _capsule_mass(size: np.ndarray, shell: bool) -> tuple[float, np.ndarray]:
    r, half = size
    h = 2 * half
    if not shell:
        m_sphere = 4 * r / (4 * r + 3 * h)
        m_cyl = 1 - m_sphere
        across = (
            m_cyl * (3 * r * r + h * h) / 12
            + 2 * m_sphere * r * r / 5
            + m_sphere * h * (3 * r + 2 * h) / 8
        )
        along = m_cyl * r * r / 2 + 2 * m_sphere * r * r / 5
        return math.pi * (r * r * h + 4 * r**3 / 3), np.array([across, across, along])
    a_sphere, a_cyl = 4 * math.pi * r * r, 2 * math.pi * r * h
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


def _ellipsoid_mass(size: np.ndarray, shell: bool) -> tuple[float, np.ndarray]:
    pi = math.pi
    s2 = size**2
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


def _box_mass(size: np.ndarray, shell: bool) -> tuple[float, np.ndarray]:
    s2 = size**2
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


# The primitives whose mass MuJoCo computes (the keys of _MASS_SHAPES).
_SHAPE_MASS: dict[str, Callable[[np.ndarray, bool], tuple[float, np.ndarray]]] = {
    "sphere": _sphere_mass,
    "capsule": _capsule_mass,
    "cylinder": _cylinder_mass,
    "ellipsoid": _ellipsoid_mass,
    "box": _box_mass,
}

"""The shapes a playback draws: a URDF's visual shapes and meshes (STL read with normals), a
stick figure for a model without them, a coil for a spring, and their bounding boxes.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio

from ._scene import Scene
from .robots import robots_dir

_DEFAULT_MESH_COLOR = (0.9, 0.9, 0.9, 1.0)  # what pinocchio gives a URDF shape without material
_LINK_COLORS = ((0.16, 0.42, 0.74, 1.0), (0.33, 0.60, 0.86, 1.0))
_BASE_COLOR = (0.35, 0.36, 0.38, 1.0)
#: An STL mesh without a URDF material (pinocchio's 0.9 grey would vanish on the background).
_MESH_GREY = (0.62, 0.64, 0.67, 1.0)


def _visual_model(scene: Scene) -> pinocchio.GeometryModel | None:
    """The visual shapes and meshes of the scene's URDF (``package://`` resolved against
    example-robot-data and the URDF's folders), or None when it has none."""
    urdf = getattr(scene, "urdf", None)
    if urdf is None or not Path(urdf).is_file():
        return None
    package_dirs = [str(Path(urdf).resolve().parent), str(Path(urdf).resolve().parent.parent)]
    try:
        package_dirs.insert(0, str(robots_dir().parents[1]))  # .../share: example-robot-data/...
    except FileNotFoundError:
        pass
    try:
        geometry = pinocchio.buildGeomFromUrdf(
            scene.model, str(urdf), pinocchio.GeometryType.VISUAL, package_dirs=package_dirs
        )
    except (RuntimeError, ValueError) as error:
        raise ValueError(f"{urdf}: cannot load its visual geometry: {error}") from None
    if geometry.ngeoms == 0:
        return None
    for k, obj in enumerate(geometry.geometryObjects):
        if not np.allclose(obj.meshColor, _DEFAULT_MESH_COLOR):
            continue  # the URDF's <material> colour
        path = obj.meshPath.lower()
        if path.endswith(".stl"):
            # STL carries no colour (a DAE or OBJ brings its own materials): a lit grey.
            obj.meshColor = np.array(_MESH_GREY)
        elif not path.endswith((".dae", ".obj")):
            # URDF shapes without a material: the base dark, the links in alternating blues.
            color = _BASE_COLOR if obj.parentJoint == 0 else _LINK_COLORS[obj.parentJoint % 2]
            obj.meshColor = np.array(color)
        geometry.geometryObjects[k] = obj
    return geometry


def read_stl(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The triangles of an STL file (binary or ASCII) as (vertices, faces, normals): three
    vertices per triangle, each with its triangle's unit normal computed from the vertices
    (counter-clockwise seen from outside, as STL orders them). The file's own normals are not
    used: many exporters write zeros there, which drew such meshes black."""
    data = Path(path).read_bytes()
    count = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
    if count >= 0 and len(data) == 84 + 50 * count:
        record = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("extra", "<u2")])
        triangles = np.frombuffer(data, dtype=record, count=count, offset=84)["vertices"]
    else:
        words = data.decode("ascii", errors="replace").split()
        try:
            values = [
                [float(x) for x in words[i + 1 : i + 4]]
                for i, word in enumerate(words)
                if word.lower() == "vertex"
            ]
        except ValueError as error:
            raise ValueError(f"{path}: not a readable STL file ({error})") from None
        if not values or len(values) % 3:
            raise ValueError(
                f"{path}: not a readable STL file (neither binary with {count} triangles in "
                f"{len(data)} bytes nor ASCII with whole facets)"
            )
        triangles = np.array(values).reshape(-1, 3, 3)
    triangles = np.asarray(triangles, dtype=float)
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    # A degenerate triangle draws nothing; any unit normal keeps the shader finite.
    normal = np.where(length > 0, normal / np.where(length > 0, length, 1.0), [0.0, 0.0, 1.0])
    vertices = triangles.reshape(-1, 3)
    faces = np.arange(vertices.shape[0]).reshape(-1, 3)
    return vertices, faces, np.repeat(normal, 3, axis=0)


def _stick_figure(model: pinocchio.Model) -> pinocchio.GeometryModel:
    """Shapes for a model without visuals: a rod from each joint to its children, a ball at
    each joint and at each body's centre of mass."""
    import coal

    data = model.createData()
    pinocchio.forwardKinematics(model, data, pinocchio.neutral(model))
    points = [data.oMi[j].translation for j in range(model.njoints)]
    points += [data.oMi[j].act(model.inertias[j].lever) for j in range(model.njoints)]
    size = float(np.ptp(np.array(points), axis=0).max()) if len(points) > 1 else 1.0
    size = size if size > 1e-6 else 1.0
    rod, ball = 0.012 * size, 0.03 * size
    geometry = pinocchio.GeometryModel()
    ez = np.array([0.0, 0.0, 1.0])
    for j in range(1, model.njoints):
        parent = model.parents[j]
        offset = model.jointPlacements[j].translation
        color = _LINK_COLORS[parent % 2] if parent else _BASE_COLOR
        length = float(np.linalg.norm(offset))
        if length > 1e-9:
            rotation = pinocchio.Quaternion.FromTwoVectors(ez, offset / length).matrix()
            placement = pinocchio.SE3(rotation, offset / 2)
            obj = pinocchio.GeometryObject(
                f"rod_{j}", parent, placement, coal.Cylinder(rod, length)
            )
            obj.meshColor = np.array(color)
            geometry.addGeometryObject(obj)
        obj = pinocchio.GeometryObject(
            f"joint_{j}", j, pinocchio.SE3.Identity(), coal.Sphere(1.5 * rod)
        )
        obj.meshColor = np.array(_BASE_COLOR)
        geometry.addGeometryObject(obj)
        if model.inertias[j].mass > 0:
            placement = pinocchio.SE3(np.eye(3), model.inertias[j].lever)
            obj = pinocchio.GeometryObject(f"mass_{j}", j, placement, coal.Sphere(ball))
            obj.meshColor = np.array(_LINK_COLORS[j % 2])
            geometry.addGeometryObject(obj)
    return geometry


def _local_corners(visual: pinocchio.GeometryModel) -> np.ndarray:
    """The 8 corners of each shape's bounding box in its own frame (a mesh's scale included,
    as pinocchio loads it); a point at the origin for a shape without one."""
    out = np.zeros((visual.ngeoms, 8, 3))
    signs = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=float)
    for g, obj in enumerate(visual.geometryObjects):
        try:
            obj.geometry.computeLocalAABB()
            low = np.array(obj.geometry.aabb_local.min_)
            high = np.array(obj.geometry.aabb_local.max_)
        except (AttributeError, RuntimeError):
            continue
        if np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(high >= low):
            out[g] = low + signs * (high - low)
    return out


def _frame_id(model: pinocchio.Model, name: str) -> int:
    body = [i for i, f in enumerate(model.frames) if f.name == name]
    bodies = [i for i in body if model.frames[i].type == pinocchio.FrameType.BODY]
    if not body:
        raise ValueError(f"frame '{name}' is not in the scene's model")
    return (bodies or body)[0]


def _decompose(matrix: np.ndarray) -> tuple[list[float], list[float], list[float]]:
    """Position, quaternion (x, y, z, w as three.js wants) and scale of a homogeneous matrix
    whose 3x3 part is a rotation times a diagonal scaling."""
    linear = matrix[:3, :3]
    scale = np.linalg.norm(linear, axis=0)
    scale = np.where(scale > 1e-12, scale, 1.0)
    rotation = linear / scale
    if np.linalg.det(rotation) < 0:
        scale[0], rotation[:, 0] = -scale[0], -rotation[:, 0]
    quat = pinocchio.Quaternion(rotation).normalized().coeffs()
    return matrix[:3, 3].tolist(), quat.tolist(), scale.tolist()


def _helix(
    coil_radius: float, wire_radius: float, nominal_length: float, coils: int = 9
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A coil spring along +z from z = 0 to z = 1 (vertices, faces, normals): stretched along
    z by the length of the spring; its wire looks round at ``nominal_length``."""
    per_coil, sides = 20, 6
    n = coils * per_coil + 1
    s = np.linspace(0.0, 1.0, n)
    theta = 2 * np.pi * coils * s
    phi = 2 * np.pi * np.arange(sides) / sides
    radial = np.stack([np.cos(theta), np.sin(theta), np.zeros(n)], axis=1)
    center = coil_radius * radial + np.stack([np.zeros(n), np.zeros(n), s], axis=1)
    ez = np.array([0.0, 0.0, 1.0])
    normals = np.cos(phi)[None, :, None] * radial[:, None, :] + np.sin(phi)[None, :, None] * ez
    offset = wire_radius * normals * np.array([1.0, 1.0, 1.0 / max(nominal_length, 1e-6)])
    vertices = (center[:, None, :] + offset).reshape(-1, 3)
    faces = []
    for i in range(n - 1):
        for k in range(sides):
            a, b = i * sides + k, i * sides + (k + 1) % sides
            c, d = a + sides, b + sides
            faces += [(a, c, b), (b, c, d)]
    return vertices, np.array(faces), normals.reshape(-1, 3)


@lru_cache(maxsize=1)
def _normal_mesh_class() -> type:
    import meshcat.geometry as mg

    class MeshWithNormals(mg.TriangularMeshGeometry):  # type: ignore[misc]  # meshcat: no types
        """meshcat's triangle mesh with vertex normals (for a lit material)."""

        __slots__ = ["normals"]

        def __init__(self, vertices: Any, faces: Any, normals: Any) -> None:
            super().__init__(vertices, faces)
            self.normals = np.asarray(normals, dtype=np.float32)

        def lower(self, object_data: Any) -> dict[str, Any]:
            data: dict[str, Any] = super().lower(object_data)
            data["data"]["attributes"]["normal"] = mg.pack_numpy_array(self.normals.T)
            return data

    return MeshWithNormals

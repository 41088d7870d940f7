"""The shapes a playback draws: a URDF's visual shapes and meshes (STL read with normals, DAE
split into one mesh per material), a stick figure for a model without them, a coil for a spring,
and their bounding boxes.
"""

from __future__ import annotations

import copy
import xml.etree.ElementTree as ET
from collections import Counter
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio

from ._memory import new_data
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


#: The primitives of a COLLADA <mesh>. three.js's ColladaLoader makes one mesh of the
#: primitives of one kind (with one material each), LineSegments of the lines.
_DAE_PRIMITIVES = frozenset(
    "triangles polylist polygons trifans tristrips lines linestrips".split()
)


def _dae_tag(element: ET.Element) -> str:
    return element.tag.rpartition("}")[2]


def _mesh_of(geometry: ET.Element) -> ET.Element | None:
    return next((child for child in geometry if _dae_tag(child) == "mesh"), None)


def _split_geometry(geometry: ET.Element) -> list[ET.Element]:
    """Copies of a COLLADA <geometry> whose <mesh> has several primitives of one kind (several
    <triangles>, each in its material), the k-th copy keeping the k-th primitive of each kind,
    the ids inside renamed; the first is the original element, under its id. [geometry] when
    each kind has one primitive at most."""
    mesh = _mesh_of(geometry)
    kinds = Counter(_dae_tag(c) for c in ([] if mesh is None else mesh))
    pieces = max((n for kind, n in kinds.items() if kind in _DAE_PRIMITIVES), default=0)
    if pieces < 2:
        return [geometry]
    out = [geometry] + [copy.deepcopy(geometry) for _ in range(pieces - 1)]
    for k, piece in enumerate(out):
        if k:
            _rename_ids(piece, f"-pinsettle-{k}")
        _keep_primitives(piece, k)
        _compact_sources(piece)
    return out


def _keep_primitives(geometry: ET.Element, k: int) -> None:
    """Remove from the geometry's mesh all primitives but the k-th one of each kind."""
    mesh = _mesh_of(geometry)
    if mesh is None:
        return
    seen: Counter[str] = Counter()
    for child in list(mesh):
        kind = _dae_tag(child)
        if kind in _DAE_PRIMITIVES:
            seen[kind] += 1
            if seen[kind] != k + 1:
                mesh.remove(child)


@dataclass
class _Column:
    """The indices at one offset of a primitive's <p> elements, and the sources they index."""

    lists: list[tuple[ET.Element, np.ndarray]]  # each <p> and all of its indices
    offset: int
    stride: int
    sources: list[str]

    def values(self) -> np.ndarray:
        return np.concatenate([a[self.offset :: self.stride] for _, a in self.lists])


def _columns(mesh: ET.Element) -> list[_Column]:
    """The index columns of the mesh's primitives; ValueError where they cannot be read."""
    vertices = {
        node.get("id"): [i.get("source", "")[1:] for i in node if _dae_tag(i) == "input"]
        for node in mesh
        if _dae_tag(node) == "vertices"
    }
    primitives = [node for node in mesh if _dae_tag(node) in _DAE_PRIMITIVES]
    return [column for p in primitives for column in _primitive_columns(p, vertices)]


def _primitive_columns(primitive: ET.Element, vertices: dict[Any, list[str]]) -> list[_Column]:
    """One column per offset of the primitive's inputs (a VERTEX input indexes the sources
    of its <vertices>)."""
    inputs = [node for node in primitive if _dae_tag(node) == "input"]
    if not inputs or any(_dae_tag(node) == "ph" for node in primitive):
        raise ValueError("a primitive without inputs, or a polygon with holes")
    lists = [
        (node, np.array((node.text or "").split(), dtype=np.int64))
        for node in primitive
        if _dae_tag(node) == "p"
    ]
    offsets = [int(node.get("offset", "0")) for node in inputs]
    out = []
    for offset in sorted(set(offsets)):
        refs = [
            i.get("source", "")[1:] for i, o in zip(inputs, offsets, strict=True) if o == offset
        ]
        names = [name for ref in refs for name in vertices.get(ref, [ref])]
        out.append(_Column(lists, offset, max(offsets) + 1, names))
    return out


def _used_rows(columns: list[_Column]) -> dict[str, np.ndarray]:
    """The rows of each source that the columns index (sorted); ValueError when the sources
    one column indexes are not indexed alike elsewhere (no one numbering would fit)."""
    used: dict[str, np.ndarray] = {}
    for column in columns:
        for name in column.sources:
            used[name] = np.union1d(used.get(name, np.zeros(0, np.int64)), column.values())
    for column in columns:
        if any(not np.array_equal(used[n], used[column.sources[0]]) for n in column.sources):
            raise ValueError("the sources of one column indexed differently")
    return used


def _kept_rows(source: ET.Element, rows: np.ndarray) -> tuple[ET.Element, ET.Element, str]:
    """The source's data array, its accessor and the text of the array with only ``rows``."""
    array = next(node for node in source if _dae_tag(node).endswith("_array"))
    accessor = next(node for node in source.iter() if _dae_tag(node) == "accessor")
    stride, count = int(accessor.get("stride", "1")), int(accessor.get("count", "0"))
    words = (array.text or "").split()
    if (
        int(accessor.get("offset", "0"))
        or len(words) < stride * count
        or not (0 <= rows.min() and rows.max() < count)
    ):
        raise ValueError("an accessor that does not read its array from the start")
    table = np.array(words[: stride * count], dtype=object).reshape(count, stride)
    return array, accessor, " ".join(table[rows].ravel())


def _compact_sources(geometry: ET.Element) -> None:
    """Keep in the geometry's sources only the rows its primitives index, renumbered: a piece
    of a split mesh would otherwise carry a copy of all of the mesh's data. Left as it is
    where the mesh is not plain enough to be sure of it."""
    mesh = _mesh_of(geometry)
    if mesh is None:
        return
    try:
        columns = _columns(mesh)
        used = _used_rows(columns)
        sources = {node.get("id"): node for node in mesh if _dae_tag(node) == "source"}
        kept = {name: _kept_rows(sources[name], rows) for name, rows in used.items()}
    except (ValueError, KeyError, IndexError, StopIteration):
        return
    for name, (array, accessor, text) in kept.items():
        array.text = text
        array.set("count", str(used[name].size * int(accessor.get("stride", "1"))))
        accessor.set("count", str(used[name].size))
    written = {}
    for column in columns:
        for node, values in column.lists:
            part = values[column.offset :: column.stride]
            values[column.offset :: column.stride] = np.searchsorted(used[column.sources[0]], part)
            written[id(node)] = (node, values)
    for node, values in written.values():
        node.text = " ".join(map(str, values.tolist()))


def _rename_ids(element: ET.Element, suffix: str) -> None:
    """Every id inside ``element`` (itself included) suffixed, the references to them too."""
    renamed = {}
    for node in element.iter():
        if "id" in node.attrib:
            renamed[node.attrib["id"]] = node.attrib["id"] + suffix
            node.attrib["id"] += suffix
    for node in element.iter():
        source = node.get("source", "")
        if source.startswith("#") and source[1:] in renamed:
            node.set("source", "#" + renamed[source[1:]])


def split_dae_materials(text: str) -> str:
    """COLLADA text in which every <geometry> with several primitives of one kind (several
    <triangles>, each in its material) is split into geometries of one primitive each, drawn
    where the original was (its <instance_geometry> repeated). meshcat's viewer merges a DAE's
    meshes into one with a list of materials, and a mesh with several materials becomes one
    entry of that list, which three.js skips without an error (the UR5's shoulder, upper arm
    and wrists drew in pieces). The text is returned as it
    is when nothing needs splitting, or when it is not COLLADA XML that can be rewritten."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return text  # assimp read it for pinocchio: ColladaLoader is left to try it as it is
    skinned = {
        node.get("source", "")[1:] for node in root.iter() if _dae_tag(node) in ("skin", "morph")
    }
    split: dict[str, list[str]] = {}
    for library in [node for node in root.iter() if _dae_tag(node) == "library_geometries"]:
        for at, geometry in reversed(list(enumerate(library))):
            if _dae_tag(geometry) != "geometry" or geometry.get("id") in skinned:
                continue
            pieces = _split_geometry(geometry)
            if len(pieces) > 1:
                split[str(geometry.get("id"))] = [str(p.get("id")) for p in pieces[1:]]
                for offset, piece in enumerate(pieces[1:], start=1):
                    library.insert(at + offset, piece)
    if not split:
        return text
    _repeat_instances(root, split)
    return _unqualified_xml(root)


def _unqualified_xml(root: ET.Element) -> str:
    """The document as text, COLLADA's namespace the default one (ElementTree would write it
    as a prefix, ``ns0:geometry``, which ColladaLoader does not read as ``geometry``)."""
    if root.tag.startswith("{"):
        namespace = root.tag[1:].partition("}")[0]
        for node in root.iter():
            if node.tag.startswith("{" + namespace + "}"):
                node.tag = _dae_tag(node)
        root.set("xmlns", namespace)
    return ET.tostring(root, encoding="unicode")


def _repeat_instances(root: ET.Element, split: dict[str, list[str]]) -> None:
    """After each <instance_geometry> of a split geometry, one for each of its other pieces."""
    for parent in list(root.iter()):
        for at, child in reversed(list(enumerate(parent))):
            url = child.get("url", "")
            if _dae_tag(child) != "instance_geometry" or url[1:] not in split:
                continue
            for offset, piece in enumerate(split[url[1:]], start=1):
                instance = copy.deepcopy(child)
                instance.set("url", "#" + piece)
                parent.insert(at + offset, instance)


def dae_mesh(path: str | Path) -> Any:
    """pinocchio's meshcat element for the DAE file at ``path`` (the file's own materials,
    textures inlined), its multi-material meshes split by ``split_dae_materials``."""
    from pinocchio.visualize.meshcat_visualizer import DaeMeshGeometry

    mesh = DaeMeshGeometry(str(path))
    mesh.dae_raw = split_dae_materials(mesh.dae_raw)
    return mesh


def _stick_figure(model: pinocchio.Model) -> pinocchio.GeometryModel:
    """Shapes for a model without visuals: a rod from each joint to its children, a ball at
    each joint and at each body's centre of mass."""
    import coal

    data = new_data(model, "playback")
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

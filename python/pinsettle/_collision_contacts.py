"""Contact points from a model's own collision geometry (``Scene.add_collision_contacts``,
``[model] contacts = "collision"``).

The C++ core takes contacts as spheres fixed to bodies (radius 0: a point). A convex shape rests
on a plane on the points of it that lie lowest along the plane's normal, and for the shapes
below those points are known in advance: a sphere touches by its centre's sphere, a capsule by
one of the spheres at the ends of its segment, a box by its corners, a mesh by the vertices of
its convex hull. A cylinder touches by a point of its rim circles, which a ring of points stands
for (``RIM_POINTS`` on each). A hull with more vertices than ``hull_points`` is thinned by
farthest-point sampling: every contact is a candidate row of each step's impulse solve, and the
thinned hull lies inside the full one by at most the largest distance from a dropped vertex to
the kept ones (reported in the scene's notes).

The shapes come from a URDF's ``<collision>`` elements (Pinocchio's ``buildGeomFromUrdf``, the
meshes loaded by coal), from a ``pinocchio.GeometryModel`` given by the caller, or from an MJCF
file's geoms (``_mjcf_contacts``).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio

from ._scene_values import SceneError

#: Points on each rim circle of a cylinder.
RIM_POINTS = 8
#: Most vertices of a mesh's convex hull taken as contact points, by default.
HULL_POINTS = 16
#: Directions along which a thinned hull is kept close to the full one.
DIRECTIONS = 1000
#: How far an ellipsoid's contact spheres may fall short of it, in any direction, relative to
#: its smallest semi-axis.
ELLIPSOID_TOL = 0.02
#: Directions along which an ellipsoid's contact spheres are measured against it.
ELLIPSOID_DIRECTIONS = 4000
#: The largest lattice of an ellipsoid's contact spheres (six more on its axes).
ELLIPSOID_MOST = 1024
#: The shapes contacts are taken from.
SHAPES = "sphere, capsule, box, cylinder, ellipsoid, mesh (its convex hull)"


@dataclass(frozen=True)
class Shape:
    """A collision shape of a body, in ``frame`` at ``placement``: ``kind`` 'sphere' (size:
    radius), 'capsule' or 'cylinder' (radius, half length along the shape's z axis), 'box' (half
    sides), 'ellipsoid' (semi-axes along the shape's x, y, z) or 'mesh' (``vertices`` in the
    shape's frame, any count: the hull is taken here).
    ``what`` names it in messages (its kind as the source calls it)."""

    name: str
    frame: str
    placement: pinocchio.SE3
    kind: str
    size: tuple[float, ...] = ()
    vertices: np.ndarray | None = None
    what: str = ""


@dataclass(frozen=True)
class Thinned:
    """A mesh whose hull was thinned: vertices kept of the hull's, and how far (m) the thinned
    hull lies inside the full one at most."""

    name: str
    kept: int
    hull: int
    deviation: float


@dataclass(frozen=True)
class FileGround:
    """A ground a model file gives, in ``Scene.add_ground``'s terms: a plane through ``point``
    with ``normal``, or (``box``: its full sizes, m) a box centred at ``point`` turned by
    ``rpy`` (roll, pitch, yaw, rad), its ``normal`` None (add_ground refuses both)."""

    name: str
    point: tuple[float, float, float]
    normal: tuple[float, float, float] | None
    friction: float
    box: tuple[float, float, float] | None = None
    rpy: tuple[float, float, float] | None = None


@dataclass
class Collision:
    """The collision geometry a source gives: the shapes of moving bodies, the names of shapes
    left out (fixed to the world, or not colliding with the floors), grounds and notes."""

    shapes: list[Shape]
    fixed: list[str] = field(default_factory=list)
    grounds: list[FileGround] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: Names of the shapes of the source, for the names ``exclude`` may give.
    names: list[str] = field(default_factory=list)


def box_corners(half: Sequence[float]) -> np.ndarray:
    """The 8 corners of a box of half sides ``half`` centred at the origin."""
    hx, hy, hz = half
    return np.array([(x, y, z) for x in (-hx, hx) for y in (-hy, hy) for z in (-hz, hz)])


def rim_points(radius: float, half_length: float, count: int = RIM_POINTS) -> np.ndarray:
    """``count`` points evenly on each rim circle of a cylinder along z (the lower rim first)."""
    angles = 2.0 * math.pi * np.arange(count) / count
    ring = np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
    return np.array([(x, y, z) for z in (-half_length, half_length) for x, y in ring])


def _lattice(count: int) -> np.ndarray:
    """``count`` unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    k = np.arange(count) + 0.5
    z = 1.0 - 2.0 * k / count
    phi = math.pi * (1.0 + math.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


@dataclass(frozen=True)
class Rounded:
    """An ellipsoid as contact spheres: how many, their radius (m), and how far (m) they fall
    short of the ellipsoid at most (along ``ELLIPSOID_DIRECTIONS`` directions)."""

    name: str
    count: int
    radius: float
    shortfall: float


def ellipsoid_points(semi_axes: Sequence[float]) -> tuple[np.ndarray, float, float]:
    """Contact spheres whose convex hull lies inside an ellipsoid and falls short of it by at
    most ``ELLIPSOID_TOL`` times its smallest semi-axis: their centres (rows, in the
    ellipsoid's frame), their radius and the largest shortfall measured (m).

    The radius is the ellipsoid's smallest radius of curvature, c^2 / a (c its smallest, a its
    largest semi-axis): the ellipsoid is then exactly the inner body that lies that far inside
    it, grown by a sphere of that radius. The centres are points of that inner body: for each
    direction u of a Fibonacci lattice (the six axis directions first: an ellipsoid lying on an
    axis end rests on a centre exactly below it), the point of the inner body whose outward
    normal is A^-1 u, A the semi-axes. The lattice doubles from 8 until the spheres fall short
    of the ellipsoid by at most 0.8 times the tolerance along ``ELLIPSOID_DIRECTIONS``
    directions, or
    reaches ``ELLIPSOID_MOST`` (a needle of 1:30 or thinner may fall short by more: the
    shortfall returned says by how much)."""
    axes = np.asarray(semi_axes, dtype=float)
    radius = float(axes.min() ** 2 / axes.max())
    check = directions(ELLIPSOID_DIRECTIONS)
    exact = np.linalg.norm(check * axes, axis=1)  # the ellipsoid's support in each direction
    count = 8
    while True:
        normals = np.vstack([np.eye(3), -np.eye(3), _lattice(count)]) / axes
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        touching = normals * axes**2 / np.linalg.norm(normals * axes, axis=1)[:, None]
        # Centres that coincide (all of them on a sphere) are one.
        centres = np.unique(np.round(touching - radius * normals, 15), axis=0)
        shortfall = float(np.max(exact - (check @ centres.T).max(axis=1) - radius))
        # A fifth of the tolerance kept for the directions between those measured.
        if shortfall <= 0.8 * ELLIPSOID_TOL * axes.min() or count >= ELLIPSOID_MOST:
            return centres, radius, max(shortfall, 0.0)
        count *= 2


def convex_hull(vertices: np.ndarray, what: str) -> np.ndarray:
    """The vertices of the convex hull of a point set (qhull, through coal: Pinocchio's
    collision library).

    Raises:
        SceneError: fewer than 4 points, or a flat or degenerate set (qhull's reason).
    """
    import coal

    vertices = np.asarray(vertices, dtype=float).reshape(-1, 3)
    if len(vertices) < 4 or not np.all(np.isfinite(vertices)):
        raise SceneError(
            f"{what}: a mesh needs at least 4 finite vertices for its convex hull, got "
            f"{len(vertices)}"
        )
    points = coal.StdVec_Vec3s()
    for v in vertices:
        points.append(v)
    try:
        hull = coal.ConvexBase.convexHull(points, False, "Qt")
    except Exception as error:  # qhull's own reasons (a flat or degenerate point set)
        raise SceneError(f"{what}: no convex hull of its vertices: {error}") from None
    return np.array(hull.points(), dtype=float).reshape(-1, 3)


def directions(count: int = DIRECTIONS) -> np.ndarray:
    """``count`` unit vectors spread evenly over the sphere (a Fibonacci lattice), with the six
    axis directions first."""
    return np.vstack([np.eye(3), -np.eye(3), _lattice(count)])


def thin(points: np.ndarray, count: int) -> tuple[np.ndarray, float]:
    """A hull's vertices, or ``count`` of them that keep its extent in every direction when it
    has more: each pick is the vertex that lies farthest out along the direction (of
    ``directions()``) in which the vertices kept so far fall shortest of the hull (once none
    falls short, the vertex farthest from those kept). Returns them and the largest shortfall
    left along those directions (m): how much deeper a body resting on the thinned hull can
    sink into a plane."""
    if len(points) <= count:
        return points, 0.0
    support = points @ directions().T  # vertex x direction
    full = support.max(axis=0)
    kept: list[int] = []
    reach = np.full(full.shape, -np.inf)
    while len(kept) < count:
        shortfall = full - reach
        d = int(np.argmax(shortfall))
        if shortfall[d] > 0:
            k = int(np.argmax(support[:, d]))
        else:
            gaps = np.min(np.linalg.norm(points[:, None] - points[kept][None], axis=2), axis=1)
            k = int(np.argmax(gaps))
        kept.append(k)
        reach = np.maximum(reach, support[k])
    return points[sorted(kept)], float(np.max(full - reach))


def _a(kind: str) -> str:
    return ("an " if kind[:1] in "aeiou" else "a ") + kind


def _positive(shape: Shape, count: int) -> tuple[float, ...]:
    """The shape's sizes, checked: ``count`` finite numbers > 0."""
    size = tuple(float(x) for x in shape.size)
    if len(size) != count or not all(math.isfinite(x) and x > 0 for x in size):
        raise SceneError(
            f"{shape.what or shape.kind} '{shape.name}' (frame '{shape.frame}'): its size must be "
            f"{count} positive number{'s' if count > 1 else ''} (m), got {list(size)}"
        )
    return size


def shape_points(
    shape: Shape, hull_points: int
) -> tuple[np.ndarray, float, Thinned | Rounded | None]:
    """The contact points of a shape in its own frame (rows), their common radius, and how a
    mesh's hull was thinned or an ellipsoid rounded into spheres (None otherwise).

    Raises:
        SceneError: a shape of another kind, or a size that is not positive (names the shape).
    """
    kind = shape.kind
    if kind == "sphere":
        return np.zeros((1, 3)), _positive(shape, 1)[0], None
    if kind == "capsule":
        radius, half = _positive(shape, 2)
        return np.array([(0.0, 0.0, -half), (0.0, 0.0, half)]), radius, None
    if kind == "cylinder":
        radius, half = _positive(shape, 2)
        return rim_points(radius, half), 0.0, None
    if kind == "box":
        return box_corners(_positive(shape, 3)), 0.0, None
    if kind == "ellipsoid":
        centres, radius, shortfall = ellipsoid_points(_positive(shape, 3))
        return centres, radius, Rounded(shape.name, len(centres), radius, shortfall)
    if kind == "mesh":
        assert shape.vertices is not None
        what = f"{shape.what or 'mesh'} '{shape.name}' (frame '{shape.frame}')"
        hull = convex_hull(shape.vertices, what)
        kept, deviation = thin(hull, hull_points)
        thinned = (
            Thinned(shape.name, len(kept), len(hull), deviation) if len(kept) < len(hull) else None
        )
        return kept, 0.0, thinned
    raise SceneError(
        f"{shape.what or kind} '{shape.name}' (frame '{shape.frame}') is {_a(kind)}: contacts are "
        f"taken from a {SHAPES}; leave it out (exclude) and give its points as [[contact]]"
    )


@dataclass
class ShapeContacts:
    """What a set of shapes gives: contacts (name, frame, point in the frame, radius) and the
    meshes whose hulls were thinned."""

    contacts: list[tuple[str, str, tuple[float, float, float], float]]
    thinned: list[Thinned]
    rounded: list[Rounded] = field(default_factory=list)


def shape_contacts(shapes: Iterable[Shape], hull_points: int) -> ShapeContacts:
    """Each shape's contact points in its frame, named after it (``name``: one point;
    ``name#1``, ``name#2``, ...: several)."""
    out = ShapeContacts([], [])
    for shape in shapes:
        local, radius, how = shape_points(shape, hull_points)
        if isinstance(how, Thinned):
            out.thinned.append(how)
        elif isinstance(how, Rounded):
            out.rounded.append(how)
        for k, p in enumerate(local, start=1):
            name = shape.name if len(local) == 1 else f"{shape.name}#{k}"
            x, y, z = (float(c) for c in shape.placement.act(p))
            out.contacts.append((name, shape.frame, (x, y, z), radius))
    return out


def thinning_note(thinned: Sequence[Thinned], hull_points: int) -> str | None:
    """The note on meshes whose hull was thinned: how many, and by how much at most."""
    if not thinned:
        return None
    worst = max(thinned, key=lambda t: t.deviation)
    kept = sum(t.kept for t in thinned)
    return (
        f"collision contacts: the convex hulls of {len(thinned)} mesh"
        f"{'es' if len(thinned) > 1 else ''} thinned to {kept} of their "
        f"{sum(t.hull for t in thinned)} vertices (at most {hull_points} each, hull_points); "
        f"a thinned hull falls short of the full one by at most {worst.deviation * 1e3:.3g} mm "
        f"along {DIRECTIONS} directions ('{worst.name}')"
    )


def rounding_note(rounded: Sequence[Rounded]) -> str | None:
    """The note on ellipsoids taken as spheres: how many, and how far short at most."""
    if not rounded:
        return None
    worst = max(rounded, key=lambda r: r.shortfall)
    s, them = ("s", "them") if len(rounded) > 1 else ("", "it")
    return (
        f"collision contacts: {len(rounded)} ellipsoid{s} as {sum(r.count for r in rounded)} "
        f"spheres inside {them}, each of its smallest radius of curvature; they fall short of "
        f"the ellipsoid{s} by at most {worst.shortfall * 1e3:.3g} mm along "
        f"{ELLIPSOID_DIRECTIONS} directions ('{worst.name}'; at most {ELLIPSOID_TOL:.0%} of "
        "the smallest semi-axis)"
    )


# --- pinocchio's geometry ------------------------------------------------------------------------


def _geometry_kind(geometry: Any) -> tuple[str, tuple[float, ...], np.ndarray | None]:
    """A coal shape as (kind, sizes, mesh vertices); kind is coal's class name for a shape
    that gives no contacts (``shape_points`` refuses it)."""
    import coal

    if isinstance(geometry, coal.Sphere):
        return "sphere", (geometry.radius,), None
    if isinstance(geometry, coal.Capsule):
        return "capsule", (geometry.radius, geometry.halfLength), None
    if isinstance(geometry, coal.Cylinder):
        return "cylinder", (geometry.radius, geometry.halfLength), None
    if isinstance(geometry, coal.Box):
        return "box", tuple(float(x) for x in geometry.halfSide), None
    if isinstance(geometry, coal.Ellipsoid):
        return "ellipsoid", tuple(float(x) for x in geometry.radii), None
    if isinstance(geometry, coal.ConvexBase):
        return "mesh", (), np.array(geometry.points(), dtype=float).reshape(-1, 3)
    if isinstance(geometry, coal.BVHModelBase):
        return "mesh", (), np.array(geometry.vertices(), dtype=float).reshape(-1, 3)
    return type(geometry).__name__.lower(), (), None


def geometry_collision(
    model: pinocchio.Model,
    geometry: pinocchio.GeometryModel,
    where: str,
    exclude: Collection[str] = (),
) -> Collision:
    """The shapes of a ``GeometryModel`` built on ``model``, each in its parent frame; those
    named in ``exclude`` (or whose frame is) left out, those fixed to the world set apart.

    Raises:
        SceneError: a geometry object whose frame or joint the model does not have.
    """
    out = Collision([])
    for obj in geometry.geometryObjects:
        if not 0 <= obj.parentFrame < model.nframes or obj.parentJoint >= model.njoints:
            raise SceneError(
                f"{where}: geometry '{obj.name}' names frame {obj.parentFrame} and joint "
                f"{obj.parentJoint}, which the model does not have (build the GeometryModel on "
                "the scene's model)"
            )
        frame = model.frames[obj.parentFrame]
        out.names += [str(obj.name), str(frame.name)]
        if obj.name in exclude or frame.name in exclude:
            continue
        if obj.parentJoint == 0:
            out.fixed.append(str(obj.name))
            continue
        # The placement is in the joint's frame; the contact's point is in the frame's.
        if frame.parentJoint != obj.parentJoint:
            frame = next(f for f in model.frames if f.parentJoint == obj.parentJoint)
        kind, size, vertices = _geometry_kind(obj.geometry)
        out.shapes.append(
            Shape(
                str(obj.name),
                str(frame.name),
                frame.placement.actInv(obj.placement),
                kind,
                size,
                vertices,
                f"geometry ({type(obj.geometry).__name__})",
            )
        )
    return out


def urdf_geometry(model: pinocchio.Model, urdf: Path) -> pinocchio.GeometryModel:
    """The collision geometry of a URDF on ``model`` (``package://`` resolved against
    example-robot-data and the URDF's folders; meshes loaded by coal).

    Raises:
        SceneError: a mesh that cannot be found or read (Pinocchio's reason).
    """
    from .robots import robots_dir

    folder = Path(urdf).resolve().parent
    package_dirs = [str(folder), str(folder.parent)]
    try:
        package_dirs.insert(0, str(robots_dir().parents[1]))  # .../share: example-robot-data/...
    except FileNotFoundError:
        pass
    try:
        return pinocchio.buildGeomFromUrdf(
            model, str(urdf), pinocchio.GeometryType.COLLISION, package_dirs=package_dirs
        )
    except (RuntimeError, ValueError) as error:
        raise SceneError(f"{urdf}: cannot load its collision geometry: {error}") from None


def moves_after_locking(model: pinocchio.Model, joint: int, locked: Iterable[str]) -> bool:
    """Whether a body on ``joint`` still moves once the ``locked`` joints are held: some joint
    between it and the world is free."""
    held = set(locked)
    while joint > 0:
        if model.names[joint] not in held:
            return True
        joint = model.parents[joint]
    return False


def _frame_joint(model: pinocchio.Model, frame: str) -> int:
    """The joint that moves a frame (a body's frame of that name first)."""
    for kind in (pinocchio.FrameType.BODY, None):
        for f in model.frames:
            if f.name == frame and (kind is None or f.type == kind):
                return int(f.parentJoint)
    raise SceneError(f"frame '{frame}' is missing from the model")


def take_contacts(
    collision: Collision,
    model: pinocchio.Model,
    locked: Sequence[str],
    hull_points: int,
    where: str,
) -> tuple[ShapeContacts, list[str]]:
    """The contacts of the shapes whose bodies move (the locked joints held), and the notes
    that say what was taken and left out.

    Raises:
        SceneError: the source has no collision geometry, or none that can touch a ground.
    """
    if not collision.names:
        raise SceneError(
            f"{where} has no collision geometry: no contact points to take from it; give them "
            "with [[contact]] (Scene.add_contact)"
        )
    moving = [
        s
        for s in collision.shapes
        if moves_after_locking(model, _frame_joint(model, s.frame), locked)
    ]
    held = len(collision.shapes) - len(moving)
    if not moving:
        raise SceneError(
            f"{where}: none of its collision shapes is on a body that moves"
            + (" and touches the floors" if collision.grounds else "")
            + f" ({len(collision.fixed) + held} fixed to the world, the rest excluded or not "
            "colliding): no contact points to take"
        )
    made = shape_contacts(moving, hull_points)
    kinds = ", ".join(
        f"{n} {k}{('es' if k in ('box', 'mesh') else 's') if n > 1 else ''}"
        for k in ("sphere", "capsule", "box", "cylinder", "ellipsoid", "mesh")
        if (n := sum(s.kind == k for s in moving))
    )
    left = len(collision.fixed) + held
    notes = [
        f"collision contacts: {len(made.contacts)} points from {len(moving)} shapes of {where} "
        f"({kinds})" + (f"; {left} shapes fixed to the world left out" if left else "")
    ]
    extra = [thinning_note(made.thinned, hull_points), rounding_note(made.rounded)]
    return made, [*collision.notes, *notes, *(note for note in extra if note)]

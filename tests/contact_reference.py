"""The conditions of a rest on the ground, recomputed without pinsettle's code.

A rest with ground contacts is right when the reported contact forces balance gravity and the
applied efforts (``rnea(q, 0, 0) = sum J_c^T f_c``, each ``J_c`` the world Jacobian of the
body's point at the contact, from Pinocchio's frame Jacobian), each force lies in its friction
cone and presses (``f_n >= 0``, ``|f_t| <= mu f_n``, ``f_t`` in the ground's plane), no contact
point sinks into a ground, and the points that carry a force touch it (force times gap zero).
The scene's grounds and contact points are read again from its TOML file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

#: The library scenes with ground contacts (robots/), checked by tests/test_contacts.py.
CONTACT_SCENES = ["box_on_floor", "box_on_incline", "go1_motors_off", "go1_standing"]
CONTACT_SCENES += ["talos_standing", "vehicle"]  # also tests/test_contact_scenes.py


@dataclass
class Plane:
    name: str
    point: np.ndarray
    normal: np.ndarray  # unit
    friction: float

    def touch(self, centre: np.ndarray, radius: float) -> tuple[float, np.ndarray]:
        """The gap (m) of a sphere and the unit normal out of the ground where it touches."""
        return float(self.normal @ (centre - self.point) - radius), self.normal


@dataclass
class Box:
    name: str
    centre: np.ndarray
    rotation: np.ndarray  # its axes (columns) in the world
    size: np.ndarray  # full, along its axes (m)
    friction: float

    def touch(self, centre: np.ndarray, radius: float) -> tuple[float, np.ndarray]:
        """The gap of a sphere and the normal: from the box's closest point to the sphere's
        centre outside the box; inside it, out of the face with the least depth."""
        x = self.rotation.T @ (centre - self.centre)
        half = self.size / 2
        outside = x - np.clip(x, -half, half)
        if np.linalg.norm(outside) > 0:
            distance = np.linalg.norm(outside)
            return float(distance - radius), self.rotation @ (outside / distance)
        depths = half - np.abs(x)
        face = int(np.argmin(depths))
        n = np.zeros(3)
        n[face] = 1.0 if x[face] >= 0 else -1.0
        return float(-depths[face] - radius), self.rotation @ n


@dataclass
class Sphere:
    name: str
    frame: str
    point: np.ndarray
    radius: float


def read_joint_springs(path: Path) -> list[tuple[str, float, float]]:
    """The scene's joint springs: (joint, stiffness, rest)."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    return [
        (s["joint"], float(s["stiffness"]), float(s.get("rest", 0.0)))
        for s in data.get("joint_spring", [])
    ]


def read_listed_contacts(path: Path) -> tuple[list[Plane | Box], list[Sphere]]:
    """The [[ground]] and [[contact]] tables of a scene file, named as pinsettle names them
    (read_contacts adds an MJCF file's own floors and geoms)."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    planes: list[Plane | Box] = []
    for k, g in enumerate(data.get("ground", []), start=1):
        name, point = g.get("name", f"ground{k}"), np.array(g.get("point", (0, 0, 0)), float)
        friction = float(g.get("friction", 0.5))
        if "box" in g:
            rotation = pinocchio.rpy.rpyToMatrix(*map(float, g.get("rpy", (0.0, 0.0, 0.0))))
            planes.append(Box(name, point, rotation, np.array(g["box"], float), friction))
            continue
        n = np.array(g.get("normal", (0.0, 0.0, 1.0)), float)
        planes.append(Plane(name, point, n / np.linalg.norm(n), friction))
    spheres: list[Sphere] = []
    for c in data.get("contact", []):
        same = sum(1 for s in spheres if s.frame == c["frame"])
        default = c["frame"] if same == 0 else f"{c['frame']}#{same + 1}"
        spheres.append(
            Sphere(
                c.get("name", default),
                c["frame"],
                np.array(c.get("point", (0.0, 0.0, 0.0)), float),
                float(c.get("radius", 0.0)),
            )
        )
    return planes, spheres


def frame_id(model, frame: str) -> int:
    """A frame by name, a body's first (an MJCF joint often has its body's name)."""
    if model.existFrame(frame, pinocchio.FrameType.BODY):
        return int(model.getFrameId(frame, pinocchio.FrameType.BODY))
    return int(model.getFrameId(frame))


def point_jacobian(model, data, frame: str, x: np.ndarray) -> np.ndarray:
    """3 x nv: the world velocity of the point of frame's body at the world point x."""
    fid = frame_id(model, frame)
    J = pinocchio.getFrameJacobian(model, data, fid, pinocchio.LOCAL_WORLD_ALIGNED)
    r = x - data.oMf[fid].translation
    skew = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    return J[:3] - skew @ J[3:]


@dataclass
class RestCheck:
    balance: float  # |rnea(q, 0, 0) - sum J^T f|_inf (N m or N)
    scale: float  # |rnea(q, 0, 0)|_inf
    worst_cone: float  # max(|f_t| - mu f_n, -f_n, |f_t . n|) over the contacts (N)
    min_gap: float  # over every point and ground (m)
    worst_touch: float  # max |gap| of the contacts that carry a force (m)
    total_normal: np.ndarray  # sum of f_n n (world, N)
    total_tangential: np.ndarray  # sum of f_t (world, N)


def check_rest(model, q, planes, spheres, contacts, springs=(), stops=None) -> RestCheck:
    """The rest conditions at q with the reported contacts (pinsettle.Contact), joint springs
    (joint, stiffness, rest) and the stops' reactions ({joint: (side, reaction)}: a reaction
    pushes off its stop, >= 0, and the joint sits on it)."""
    data = model.createData()
    pinocchio.computeJointJacobians(model, data, q)
    pinocchio.updateFramePlacements(model, data)
    by_plane = {p.name: p for p in planes}
    by_point = {s.name: s for s in spheres}
    tau = pinocchio.rnea(model, data, q, np.zeros(model.nv), np.zeros(model.nv))
    for joint, stiffness, rest in springs:
        j = model.getJointId(joint)
        tau[model.idx_vs[j]] += stiffness * (q[model.idx_qs[j]] - rest)
    left = tau.copy()
    worst_stop = 0.0
    for joint, (side, reaction) in (stops or {}).items():
        j = model.getJointId(joint)
        iq, iv = model.idx_qs[j], model.idx_vs[j]
        limit = model.lowerPositionLimit[iq] if side == "lower" else model.upperPositionLimit[iq]
        worst_stop = max(worst_stop, -reaction, abs(q[iq] - limit))
        left[iv] -= reaction if side == "lower" else -reaction
    worst_cone, worst_touch = -np.inf, 0.0
    total_n, total_t = np.zeros(3), np.zeros(3)
    for c in contacts:
        plane, sphere = by_plane[c.ground], by_point[c.name]
        centre = data.oMf[frame_id(model, sphere.frame)].act(sphere.point)
        gap, normal = plane.touch(centre, sphere.radius)
        x = centre - sphere.radius * normal
        assert np.allclose(x, c.point, atol=1e-12) and abs(gap - c.gap) < 1e-12
        assert np.allclose(normal, c.normal, atol=1e-12)
        f = c.normal_force * normal + c.tangential_force
        left -= point_jacobian(model, data, sphere.frame, x).T @ f
        ft = np.linalg.norm(c.tangential_force)
        worst_cone = max(
            worst_cone,
            ft - plane.friction * c.normal_force,
            -c.normal_force,
            abs(c.tangential_force @ normal),
        )
        if c.normal_force > 0:
            worst_touch = max(worst_touch, abs(gap))
        total_n += c.normal_force * normal
        total_t += c.tangential_force
    gaps = [
        plane.touch(data.oMf[frame_id(model, s.frame)].act(s.point), s.radius)[0]
        for s in spheres
        for plane in planes
    ]
    return RestCheck(
        float(np.max(np.abs(left))),
        float(np.max(np.abs(tau))),
        float(max(worst_cone, worst_stop)),
        float(min(gaps)),
        float(worst_touch),
        total_n,
        total_t,
    )


def add_stance_springs(scene, stiffness: float) -> list[tuple[str, float, float]]:
    """A spring of `stiffness` on every 1-DoF joint of the scene towards its start pose (the
    stance), added to the scene and returned as (joint, stiffness, rest)."""
    model, q = scene.model, scene.q0()
    springs = []
    for j in range(2, model.njoints):
        if model.nqs[j] == 1:
            rest = float(q[model.idx_qs[j]])
            scene.add_joint_spring(model.names[j], stiffness, rest)
            springs.append((model.names[j], stiffness, rest))
    return springs


def scene_parts(scene) -> tuple[list[Plane | Box], list[Sphere]]:
    """A pinsettle.Scene's grounds and contact points, as this module's planes (or boxes) and
    spheres."""
    planes: list[Plane | Box] = [
        Plane(g.name, np.array(g.point), np.array(g.normal), g.friction)
        if g.box is None
        else Box(
            g.name,
            np.array(g.point),
            pinocchio.rpy.rpyToMatrix(*g.rpy),
            np.array(g.box),
            g.friction,
        )
        for g in scene.grounds
    ]
    spheres = [Sphere(c.name, c.frame, np.array(c.point), c.radius) for c in scene.contacts]
    return planes, spheres


def weight(model: pinocchio.Model) -> float:
    """The model's weight (N) under its own gravity."""
    return sum(inertia.mass for inertia in model.inertias) * -model.gravity.linear[2]


def assert_rests_on_the_floor(scene, result, springs=()) -> RestCheck:
    """The rest conditions, independently (balance to round-off, forces in their cones, nothing
    sunk in, the loaded points touching), and the floor carrying the weight to 1e-9."""
    assert result.status == "converged", result.reason
    planes, spheres = scene_parts(scene)
    stops = {j: (side, result.limit_reactions[j]) for j, side in result.at_limit.items()}
    check = check_rest(scene.model, result.q, planes, spheres, result.contacts, springs, stops)
    assert check.balance <= 1e-9 * check.scale
    assert check.worst_cone <= 1e-9 * check.scale
    assert check.min_gap >= -1e-6 and check.worst_touch <= 1e-6
    lift = check.total_normal + check.total_tangential
    assert np.allclose(lift, [0.0, 0.0, weight(scene.model)], rtol=1e-9, atol=1e-9)
    return check


# --- scenes whose contacts come from the model's collision geometry ---------------------------

#: The library scene of an MJCF file's floor and geoms ([model] contacts = "collision").
CONTACT_SCENES += ["mjcf_ant"]


def _mjcf_defaults(root) -> dict[str, dict[str, str]]:
    """The geom attributes of each default class (nested classes inherit), 'main' at the top."""
    classes: dict[str, dict[str, str]] = {}

    def visit(element, name: str, inherited: dict[str, str]) -> None:
        own = dict(inherited)
        for geom in element.findall("geom"):
            own.update(geom.attrib)
        classes[name] = own
        for child in element.findall("default"):
            visit(child, child.get("class"), own)

    for top in root.findall("default"):
        visit(top, "main", {})
    return classes


def read_mjcf_collision(path: Path) -> tuple[list[Plane], list[Sphere]]:
    """An MJCF file's floors (plane geoms of the world body, not turned) and the spheres of the
    geoms that collide with them (contype/conaffinity): spheres at their centre, capsules
    given by fromto at their two ends. Only what the library's files use: anything else is an
    error here."""
    import xml.etree.ElementTree as ET

    root = ET.parse(path).getroot()
    classes = _mjcf_defaults(root)

    def attrs(geom, childclass="main"):
        return {**classes[geom.get("class", childclass)], **geom.attrib}

    def collides(a, b) -> bool:
        bits = {k: int(a.get(k, "1")) for k in ("contype", "conaffinity")}
        return bool(
            bits["contype"] & int(b.get("conaffinity", "1"))
            or int(b.get("contype", "1")) & bits["conaffinity"]
        )

    planes, floors = [], []
    for geom in root.find("worldbody").findall("geom"):
        a = attrs(geom)
        assert a.get("type") == "plane" and not {"quat", "euler", "axisangle"} & set(a)
        pos = np.array([float(x) for x in a.get("pos", "0 0 0").split()])
        mu = float(a.get("friction", "1").split()[0])
        planes.append(Plane(a["name"], pos, np.array([0.0, 0.0, 1.0]), mu))
        floors.append(a)
    spheres = []
    for body in root.find("worldbody").iter("body"):
        for geom in body.findall("geom"):
            a = attrs(geom)
            if not any(collides(f, a) for f in floors):
                continue
            radius = float(a["size"].split()[0])
            if a.get("type", "sphere") == "sphere":
                centre = [float(x) for x in a.get("pos", "0 0 0").split()]
                spheres.append(Sphere(a["name"], body.get("name"), np.array(centre), radius))
                continue
            assert a.get("type") == "capsule" and "fromto" in a
            ends = np.array([float(x) for x in a["fromto"].split()])
            # pinsettle numbers a capsule's end spheres along its z axis, which MuJoCo points
            # from the 'to' end to the 'from' end.
            for k, end in enumerate((ends[3:], ends[:3]), start=1):
                spheres.append(Sphere(f"{a['name']}#{k}", body.get("name"), end, radius))
    return planes, spheres


def read_contacts(path: Path) -> tuple[list[Plane], list[Sphere]]:
    """The grounds and contact points of a scene file: its [[ground]] and [[contact]] tables
    (above), and with [model] contacts = "collision" on an MJCF file, the file's floors (where
    the scene gives no [[ground]]) and its colliding geoms."""
    planes, spheres = read_listed_contacts(path)
    model = tomllib.loads(path.read_text(encoding="utf-8"))["model"]
    if model.get("contacts") != "collision":
        return planes, spheres
    floors, geoms = read_mjcf_collision(path.parent / model["mjcf"])
    return planes or floors, spheres + geoms

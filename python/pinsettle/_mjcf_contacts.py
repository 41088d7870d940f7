"""An MJCF file's floors and the geoms MuJoCo would collide with them, as grounds and contact
shapes (``Scene.add_collision_contacts`` on an MJCF scene).

A ``<geom type="plane">`` of the world body is a floor: a ground through the geom's position
with the geom's z axis as its normal (MuJoCo's planes are infinite for collisions, whatever their
size). A ``<geom type="box">`` of the world body that collides with something is a floor too: a
box ground of its size (MuJoCo's are half sizes), at its position and orientation. A geom of a
moving body is a contact shape where MuJoCo would collide it with the floors: an explicit
``<contact><pair>`` with the floor, or else its ``contype``/``conaffinity`` against the floor's
(``(contype1 & conaffinity2) | (contype2 & conaffinity1)``) unless a ``<contact><exclude>`` of
its body and the world leaves it out; geoms of bodies fixed to the world never collide with
it. The friction of a pair is MuJoCo's: the ``<pair>``'s own, else the geom of higher
``priority``'s, else the larger of the two, and none with ``condim="1"``. The core takes one
friction per ground: each floor takes the smallest of its pairs' (a note names the geoms that
would grip more in MuJoCo).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import dataclass
from pathlib import Path

import pinocchio

from ._collision_contacts import SHAPES, Collision, FileGround, Shape, _a
from ._mjcf_mass import _convex_hull, _placed_geometry, _primitive
from ._mjcf_parse import MjcfError, _floats, _Geom, _MeshAsset, _names, _Reader, _to_se3

#: MuJoCo's default friction (sliding, torsional, rolling) and contact dimension.
_FRICTION = "1 0.005 0.0001"


@dataclass(frozen=True)
class Floor:
    """A plane geom of the world body, or (``box``: its full sizes, m; ``rpy``: its orientation,
    rad) a box geom of it: a ground. ``normal`` is the plane's, or the box's z axis."""

    name: str
    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    geom: _Geom
    box: tuple[float, float, float] | None = None
    rpy: tuple[float, float, float] | None = None

    def ground(self, friction: float) -> FileGround:
        """The floor as ``Scene.add_ground`` takes it (a box without a normal)."""
        if self.box is None:
            return FileGround(self.name, self.point, self.normal, friction)
        return FileGround(self.name, self.point, None, friction, self.box, self.rpy)


def _int(geom: _Geom, key: str, default: str, where: str) -> int:
    return int(_floats(geom.attrs.get(key, default), f"{where} {key}", (1,))[0])


def _friction(attrs: dict[str, str], where: str) -> float:
    """The sliding friction (the first value) of a geom or pair; >= 0."""
    text = attrs.get("friction", _FRICTION)
    value = float(_floats(text, f"{where} friction", (1, 2, 3, 4, 5))[0])
    if value < 0:
        raise MjcfError(f"{where} friction: the sliding friction must be >= 0, got {value:g}")
    return value


def _mixed(floor: _Geom, geom: _Geom, where_floor: str, where: str) -> float:
    """MuJoCo's friction of a dynamic pair: the higher priority's, else the larger; 0 with
    condim 1 (frictionless)."""
    pf, pg = _int(floor, "priority", "0", where_floor), _int(geom, "priority", "0", where)
    cf, cg = _int(floor, "condim", "3", where_floor), _int(geom, "condim", "3", where)
    mf, mg = _friction(floor.attrs, where_floor), _friction(geom.attrs, where)
    if pf != pg:
        condim, mu = (cf, mf) if pf > pg else (cg, mg)
    else:
        condim, mu = max(cf, cg), max(mf, mg)
    return 0.0 if condim == 1 else mu


def _collides(floor: _Geom, geom: _Geom, where_floor: str, where: str) -> bool:
    """MuJoCo's bitmask test of a dynamic pair."""
    a_type, a_aff = _int(floor, "contype", "1", where_floor), _int(floor, "conaffinity", "1", "")
    b_type, b_aff = _int(geom, "contype", "1", where), _int(geom, "conaffinity", "1", where)
    return bool((a_type & b_aff) or (b_type & a_aff))


def _geom_name(body: str, geom: _Geom, k: int) -> str:
    return geom.attrs.get("name") or f"{body}:geom{k}"


@dataclass
class MjcfCollision:
    """What an MJCF file says about contacts with its floors, kept from the reading for
    ``contacts`` (nothing is computed until a scene asks for it)."""

    path: Path
    #: Each body's name and geoms, in MuJoCo's body order.
    bodies: list[tuple[str, list[_Geom]]]
    floors: list[Floor]
    #: Geoms of the world body other than planes and boxes that collide with something.
    other_world: list[str]
    meshes: dict[str, _MeshAsset]
    #: Bodies a <contact><exclude> keeps from the world.
    excluded: set[str]
    #: Explicit <contact><pair>s: (geom1, geom2, attributes).
    pairs: list[tuple[str, str, dict[str, str]]]
    #: MuJoCo's contact and constraint flags of <option><flag>.
    enabled: bool

    def pair_of(self, floor: Floor, name: str) -> dict[str, str] | None:
        for a, b, attrs in self.pairs:
            if {a, b} == {floor.name, name}:
                return attrs
        return None

    def floor_note(self) -> str | None:
        """The note for a scene that takes no contacts: the floors play no part."""
        if not self.floors:
            return None
        kinds = " and ".join(
            dict.fromkeys("plane" if f.box is None else "box" for f in self.floors)
        )
        return (
            f"floor{'s' if len(self.floors) > 1 else ''} "
            f"{_names([f.name for f in self.floors])} ({kinds} geoms) and the geoms that touch "
            'them play no part: no contacts taken (contacts = "none", --no-contacts; '
            "Scene.add_collision_contacts takes them)"
        )

    def collision(self, model: pinocchio.Model, exclude: Collection[str] = ()) -> Collision:
        """The floors as grounds and the colliding geoms of moving bodies as shapes; geoms
        named in ``exclude``, or of bodies named there, left out.

        Raises:
            MjcfError: a geom that collides with some floors and not others, a shape contacts
                cannot be taken from, a bad size (the message names the geom).
        """
        out = Collision([])
        if not self.enabled:
            out.notes.append(
                'contacts off in the file (<option><flag contact|constraint="disable">)'
            )
            return out
        frictions: dict[str, dict[str, float]] = {f.name: {} for f in self.floors}
        for body, geoms in self.bodies:
            moving = _moves(model, body)
            out.names.append(body)
            for k, geom in enumerate(geoms, start=1):
                name = _geom_name(body, geom, k)
                out.names.append(name)
                where = f"{self.path}: {geom.label} in body '{body}'"
                if body in exclude or name in exclude:
                    continue
                if not self._touches(body, geom, name, where, frictions):
                    continue
                if not moving:
                    out.fixed.append(name)
                    continue
                out.shapes.append(self._shape(body, geom, name, where))
        self._grounds(out, frictions)
        if self.other_world:
            out.notes.append(
                f"world geoms {_names(self.other_world)} are not planes or boxes: not grounds "
                "(bodies pass through them)"
            )
        return out

    def _touches(
        self, body: str, geom: _Geom, name: str, where: str, frictions: dict[str, dict[str, float]]
    ) -> bool:
        """Whether MuJoCo collides the geom with the floors (every one, or none: the core pairs
        each contact with each ground), each pair's friction recorded; without floors, whether
        it collides with a default plane (contype = conaffinity = 1)."""
        if geom.attrs.get("type", "sphere") == "plane":
            return False  # planes do not collide with planes
        if not self.floors:
            bits = _int(geom, "contype", "1", where) | _int(geom, "conaffinity", "1", where)
            return bool(bits & 1)
        touching = []
        for floor in self.floors:
            at = f"{self.path}: {floor.geom.label} in <worldbody>"
            pair = self.pair_of(floor, name)
            if pair is not None:
                mu = _friction(pair, f"{self.path}: <pair>") if "friction" in pair else None
                frictions[floor.name][name] = (
                    _mixed(floor.geom, geom, at, where) if mu is None else mu
                )
                touching.append(floor.name)
            elif body not in self.excluded and _collides(floor.geom, geom, at, where):
                frictions[floor.name][name] = _mixed(floor.geom, geom, at, where)
                touching.append(floor.name)
        if touching and len(touching) < len(self.floors):
            missed = [f.name for f in self.floors if f.name not in touching]
            raise MjcfError(
                f"{where}: collides with floor {_names(touching)} but not with {_names(missed)} "
                "(contype/conaffinity, <contact>): pinsettle pairs every contact with every "
                "ground; make its collisions the same with each floor"
            )
        return bool(touching)

    def _shape(self, body: str, geom: _Geom, name: str, where: str) -> Shape:
        """A geom as a contact shape in its body's frame."""
        kind = geom.attrs.get("type", "sphere")
        what = f"{geom.label} ({kind} geom) of body '{body}'"
        if (
            kind in ("sphere", "capsule", "cylinder", "box", "ellipsoid")
            and "mesh" not in geom.attrs
        ):
            rotation, center, size = _primitive(geom, kind, where)
            return Shape(name, body, _to_se3(rotation, center), kind, tuple(size), what=what)
        if kind == "mesh":
            mesh = self.meshes.get(geom.attrs.get("mesh", ""))
            if mesh is None:
                raise MjcfError(f"{where}: unknown mesh '{geom.attrs.get('mesh')}'")
            try:
                vertices, _ = _convex_hull(mesh, _placed_geometry(mesh)[0])
            except OSError as error:
                raise MjcfError(f"{where}: mesh '{mesh.name}': {error}") from None
            return Shape(name, body, geom.pose, "mesh", vertices=vertices, what=what)
        shape = "a primitive sized to fit a mesh" if "mesh" in geom.attrs else _a(kind)
        raise MjcfError(
            f"{where}: {shape}: contacts are taken from a {SHAPES}; keep it from the floor "
            '(contype="0" conaffinity="0" in a copy) or leave it out (exclude)'
        )

    def _grounds(self, out: Collision, frictions: dict[str, dict[str, float]]) -> None:
        """Each floor as a ground with the smallest friction of its pairs (its own where no
        geom touches it), and a note where the pairs differ."""
        for floor in self.floors:
            pairs = frictions[floor.name]
            own = _friction(floor.geom.attrs, f"{self.path}: {floor.geom.label}")
            mu = min(pairs.values()) if pairs else own
            out.grounds.append(floor.ground(mu))
            more = sorted(name for name, value in pairs.items() if value > mu)
            if more:
                out.notes.append(
                    f"floor '{floor.name}': friction {mu:g}, the smallest of its pairs; in MuJoCo "
                    f"{_names(more)} grip more (up to {max(pairs.values()):g}: the higher "
                    "priority's, else the larger friction of the pair)"
                )


def _moves(model: pinocchio.Model, body: str) -> bool:
    """Whether the body's frame is moved by a joint (not welded to the world)."""
    for f in model.frames:
        if f.name == body and f.type == pinocchio.FrameType.BODY:
            return bool(f.parentJoint != 0)
    return False  # a locked free object's bodies are not in the model


def _triple(values: Iterable[float]) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in values)
    return x, y, z


def _floor(geom: _Geom, name: str, where: str) -> Floor:
    """A world plane or box geom as a floor (its friction checked)."""
    _friction(geom.attrs, where)
    if geom.attrs.get("type", "sphere") == "plane":
        pose = geom.pose
        return Floor(name, _triple(pose.translation), _triple(pose.rotation[:, 2]), geom)
    # _primitive reads the pose as the shapes' does (fromto included) and checks the sizes.
    rotation, center, half = _primitive(geom, "box", where)
    rpy = _triple(pinocchio.rpy.matrixToRpy(rotation))
    return Floor(name, _triple(center), _triple(rotation[:, 2]), geom, _triple(2 * half), rpy)


def _floors(reader: _Reader, paired: Collection[str]) -> tuple[list[Floor], list[str]]:
    """The world's plane geoms, and its box geoms that collide with something (a visual box,
    contype = conaffinity = 0 and in no ``paired``, is scenery); its other geoms that collide."""
    floors, others = [], []
    for k, geom in enumerate(reader.world_geoms, start=1):
        where = f"{reader.path}: {geom.label} in <worldbody>"
        name = geom.attrs.get("name") or f"world:geom{k}"
        kind = geom.attrs.get("type", "sphere")
        collides = name in paired or bool(
            _int(geom, "contype", "1", where) or _int(geom, "conaffinity", "1", where)
        )
        if kind == "plane" or (kind == "box" and collides and "mesh" not in geom.attrs):
            floors.append(_floor(geom, name, where))
        elif collides:
            others.append(name)
    return floors, others


def _contact_section(reader: _Reader) -> tuple[set[str], list[tuple[str, str, dict[str, str]]]]:
    """The bodies a <contact><exclude> keeps from the world, and the explicit pairs."""
    excluded: set[str] = set()
    pairs: list[tuple[str, str, dict[str, str]]] = []
    for section in reader.root.findall("contact"):
        for el in section:
            attrs = reader._resolved(el, None, "pair" if el.tag == "pair" else None)
            if el.tag == "exclude":
                a, b = attrs.get("body1", ""), attrs.get("body2", "")
                if "world" in (a, b):
                    excluded.add(b if a == "world" else a)
            elif el.tag == "pair":
                pairs.append((attrs.get("geom1", ""), attrs.get("geom2", ""), attrs))
    return excluded, pairs


def mjcf_collision(reader: _Reader, flags: dict[str, bool]) -> MjcfCollision:
    """What the file says about contacts with its floors, for later."""
    excluded, pairs = _contact_section(reader)
    floors, others = _floors(reader, {name for a, b, _ in pairs for name in (a, b)})
    return MjcfCollision(
        path=reader.path,
        bodies=[(body.name, body.geoms) for body in reader.all_bodies()],
        floors=floors,
        other_world=others,
        meshes=reader.meshes,
        excluded=excluded,
        pairs=pairs,
        enabled=flags.get("contact", True) and flags.get("constraint", True),
    )

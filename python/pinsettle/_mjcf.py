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

The parts: ``_mjcf_parse`` reads the file into plain data (the body tree, compiler, defaults,
assets); ``_mjcf_statics`` and ``_mjcf_actuators`` read what it says about statics;
``_mjcf_mass`` computes masses as MuJoCo does; this module writes the plain MJCF, has
Pinocchio build the model and adds the rest to it.
"""

from __future__ import annotations

import math
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio

from ._checks import negative_moments
from ._memory import new_data
from ._mjcf_actuators import _actuators, _ActuatorSprings
from ._mjcf_contacts import MjcfCollision, mjcf_collision
from ._mjcf_mass import _EPS, _MINVAL, _GeomMass, _mesh_mass, _MeshMass, _primitive, _shape_mass
from ._mjcf_parse import (
    _MASS_SHAPES,
    MjcfError,
    _Body,
    _describe,
    _flag,
    _floats,
    _Geom,
    _Joint,
    _names,
    _parse,
    _Reader,
    _rotation,
    _to_se3,
)
from ._mjcf_statics import _joint_statics, _option, _other_sections, _Statics, springdamper_gains

__all__ = ["FREE_OBJECTS", "MjcfError", "MjcfModel", "is_mjcf", "load_mjcf"]


def _check_inertia(tensor: np.ndarray, where: str) -> None:
    """Refuse a given inertia no rigid body has (before boundinertia would lift a negative
    moment to its bound: diaginertia="0.1 -0.1 0.1" was solved as "0.1 0 0.1")."""
    if not np.isfinite(tensor).all():
        raise MjcfError(f"{where}: its inertia must be finite")
    moments = negative_moments(tensor)
    if moments is not None:
        raise MjcfError(
            f"{where}: its inertia has principal moments {np.array2string(moments, precision=4)} "
            "kg m^2; an inertia must be positive semidefinite"
        )


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
    #: The file's floors and geoms, for contacts (``Scene.add_collision_contacts``).
    collision: MjcfCollision | None = None
    #: The joints with a ``springdamper``: (stiffness, damping) as MuJoCo's compiler sets them
    #: (the stiffness is their spring in ``joint_springs``; damping has no force at rest).
    springdampers: dict[str, tuple[float, float]] = field(default_factory=dict)


def is_mjcf(path: str | Path) -> bool:
    """Whether the file is XML with a ``<mujoco>`` root element."""
    try:
        return _parse(Path(path)).tag == "mujoco"
    except (MjcfError, OSError):
        return False


def _text(values: Any) -> str:
    return " ".join(repr(float(x)) for x in np.ravel(values))


def _quat_wxyz(rotation: np.ndarray) -> np.ndarray:
    x, y, z, w = pinocchio.Quaternion(rotation).coeffs()
    return np.array([w, x, y, z])


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
        self._tree(ET.SubElement(self.xml, "worldbody"), structure)
        if c.settotalmass > 0:
            self._scale_masses(c.settotalmass)

    def _tree(self, world: ET.Element, structure: _Structure) -> None:
        reader = self.reader
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

    def _scale_masses(self, total: float) -> None:
        """<compiler settotalmass>: every body's mass and inertia times one factor, so that
        the masses add up to ``total`` (MuJoCo's mj_setTotalmass, applied last: after
        boundmass and boundinertia; a locked free object counts, as it is a body in MuJoCo)."""
        elements = [el for el in self.xml.iter("inertial") if float(el.get("mass", "0")) > 0]
        given = sum(float(el.get("mass", "0")) for el in elements)
        scale = max(_MINVAL, total / max(_MINVAL, given))
        for el in elements:
            for key in ("mass", "diaginertia", "fullinertia"):
                if key in el.attrib:
                    el.set(key, _text(np.array(el.get(key, "").split(), float) * scale))
        self.inertias = {
            name: (mass * scale, com, inertia * scale)
            for name, (mass, com, inertia) in self.inertias.items()
        }
        self.reader.notes.append(
            f"masses and inertias scaled by {scale:.6g}: from {given:.6g} to a total of "
            f"{total:g} (<compiler settotalmass>)"
        )

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
        c = self.reader.compiler
        use_geoms = c.inertiafromgeom == "true" or (
            c.inertiafromgeom == "auto" and body.inertial is None
        )
        if use_geoms:
            self._mass_from_geoms(el, body)
        elif body.inertial is None:
            self.reader.refuse(
                f'<body name="{body.name}">',
                'without <inertial> while <compiler inertiafromgeom="false">',
                "give it an <inertial>",
            )
        else:
            self._given_mass(el, body, body.inertial)

    def _given_mass(self, el: ET.Element, body: _Body, given: ET.Element) -> None:
        """The body's own <inertial> (boundmass applied, as MuJoCo does)."""
        reader = self.reader
        a = given.attrib
        where = f"{reader.path}: <inertial> of body '{body.name}'"
        given_mass = float(_floats(a.get("mass", ""), f"{where} mass", (1,))[0])
        # Checked before boundmass lifts it (to 0 by default: mass="-1" was solved as a
        # massless body; MuJoCo refuses it).
        if not np.isfinite(given_mass) or given_mass < 0:
            raise MjcfError(f"{where} mass: must be finite and >= 0, got {given_mass:g}")
        mass = max(given_mass, reader.compiler.boundmass)
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
        _check_inertia(tensor @ rotation.T, where)
        self.inertias[body.name] = (
            mass,
            np.array(body.inertial_pose.translation),
            tensor @ rotation.T,
        )

    def _mass_from_geoms(self, el: ET.Element, body: _Body) -> None:
        """MuJoCo's InertiaFromGeom: the geoms' masses, centres and inertias summed, then
        boundmass and boundinertia on the total and its principal moments."""
        c = self.reader.compiler
        parts = [part for geom in body.geoms if (part := self._geom_mass(body, geom))]
        if not parts:
            if c.boundmass > 0:
                # MuJoCo (4.0, measured) puts the bounded mass at the body's own pos attribute,
                # as written, taken in the body's frame; its inertia is round.
                where = f'{self.reader.path}: <body name="{body.name}"> pos'
                at = _floats(body.element.get("pos", "0 0 0"), where, (3,))
                ET.SubElement(
                    el,
                    "inertial",
                    pos=_text(at),
                    mass=repr(c.boundmass),
                    diaginertia=_text([c.boundinertia] * 3),
                )
                self.inertias[body.name] = (c.boundmass, at, c.boundinertia * np.eye(3))
            return
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
        rotation, center, size = _primitive(geom, kind, where)
        volume, moments = _shape_mass(kind, size, shell == "true")
        if volume <= _EPS:
            return None
        mass = amount if key == "mass" else amount * volume
        inertia = rotation @ np.diag(moments * mass) @ rotation.T
        return _GeomMass(mass, center, inertia)

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
    if free_objects not in FREE_OBJECTS:
        raise MjcfError(
            f"free_objects: expected 'keep' or 'lock', got {free_objects!r} ('keep': free "
            "objects stay free and fall; 'lock': they are fixed where the file places them)"
        )
    _check_free_joints(reader)
    top = reader.bodies
    free_top = [b for b in top if b.joints and b.joints[0].kind == "free"]
    objects = [b for b in free_top if not any(_has_joints(c) for c in b.children)]
    structure = _Structure({b.name: b.joints[0].name for b in free_top})
    if objects:
        _free_objects(reader, structure, objects, free_objects)
    if floating:
        _add_floating(reader, structure, objects)
    structure.single = len(top) == 1 and top[0].name in structure.free
    return structure


def _check_free_joints(reader: _Reader) -> None:
    """A free joint is a top-level body's only joint (MuJoCo's rule)."""
    top = reader.bodies
    for body in reader.all_bodies():
        if any(j.kind == "free" for j in body.joints):
            if len(body.joints) > 1:
                raise MjcfError(
                    f"{reader.path}: body '{body.name}' has a free joint and other joints"
                )
            if body not in top:
                raise MjcfError(
                    f"{reader.path}: body '{body.name}' has a free joint but is not a top-level "
                    "body (MuJoCo refuses this too): move it to <worldbody>"
                )


def _free_objects(
    reader: _Reader, structure: _Structure, objects: list[_Body], free_objects: str
) -> None:
    """The free objects kept free or locked (their free joints taken out), and a note."""
    names = _names([b.name for b in objects])
    s, them = ("s", "them") if len(objects) > 1 else ("", "it")
    if free_objects == "lock":
        structure.locked = [b.name for b in objects]
        for b in objects:
            del structure.free[b.name]
        reader.notes.append(
            f'free object{s} {names} locked where the file places {them} (free_objects = "lock")'
        )
        return
    falls = "they fall" if len(objects) > 1 else "it falls"
    reader.notes.append(
        f'free object{s} {names} kept free (free_objects = "keep"): unless contacts hold {them} '
        f'(the file\'s floors, taken unless contacts = "none"), under gravity {falls} and '
        "the solve ends no_equilibrium; "
        f'free_objects = "lock" (--free-objects lock) fixes {them} where the file places {them}'
    )


def _add_floating(reader: _Reader, structure: _Structure, objects: list[_Body]) -> None:
    """``floating``: a free joint on the single root body beside the free objects, or a note
    that the file's own free joint floats it already."""
    path = reader.path
    robots = [b for b in reader.bodies if b not in objects]
    own = [b for b in robots if b.name in structure.free]
    if own:
        reader.notes.append(
            f"floating: body '{own[0].name}' floats by the file's own free joint "
            f"'{structure.free[own[0].name]}'; nothing added"
        )
        return
    if len(robots) != 1:
        beside = f" beside the free objects ({_names([b.name for b in objects])})"
        raise MjcfError(
            f"{path}: floating: {len(robots)} top-level bodies ("
            + _names([b.name for b in robots])
            + ")"
            + (beside if objects else "")
            + "; a free joint goes on a single root body: give one a <freejoint/> in the "
            "file instead"
        )
    if robots[0].joints:
        raise MjcfError(
            f"{path}: floating: the root body '{robots[0].name}' is attached by joint "
            f"'{robots[0].joints[0].name}' already; give it a <freejoint/> in the file "
            "instead"
        )
    structure.added = "root_joint"
    structure.free[robots[0].name] = "root_joint"


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
        self.data = new_data(model, "reading the MJCF file")
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


_Loop = tuple[str, tuple[float, ...], str, tuple[float, ...], str]
_ZERO = (0.0, 0.0, 0.0)


def _loops(
    reader: _Reader,
    model: pinocchio.Model,
    q0: np.ndarray,
    flags: Mapping[str, bool],
) -> list[_Loop]:
    """The connect and weld equalities as loops (frame_a, point_a, frame_b, point_b, kind)."""
    loops: list[_Loop] = []
    ends = _Ends(reader, model, q0)
    inactive: list[str] = []
    disabled: list[str] = []
    for section in reader.root.findall("equality"):
        for k, el in enumerate(section):
            a = reader._resolved(el, None)
            label = a.get("name") or f"equality{k}"
            where = f"{reader.path}: {_describe(el)} in <equality>"
            if _flag(a.get("active", "true"), f"{where} active", ("true", "false")) == "false":
                inactive.append(label)
            elif not (flags["equality"] and flags["constraint"]):
                disabled.append(label)
            elif el.tag not in ("connect", "weld"):
                reader.refuse(
                    f"{_describe(el)} in <equality>",
                    f"(a {el.tag} equality: connect and weld equalities are honoured, as loops)",
                    "remove it in a copy (its joints or bodies then settle independently), "
                    'or <option><flag equality="disable"/>',
                )
            elif "site1" in a or "site2" in a:
                loops.append(_site_loop(ends, el.tag, a, label, where))
            else:
                loops.append(_body_loop(ends, el.tag, a, label, where))
    if inactive:
        reader.notes.append(f'ignored: inactive equalities {_names(inactive)} (active="false")')
    if disabled:
        reader.notes.append(f"ignored: equalities {_names(disabled)}: disabled by <option><flag>")
    return loops


def _site_loop(ends: _Ends, tag: str, a: Mapping[str, str], label: str, where: str) -> _Loop:
    """A connect or weld between two sites: their points, or frames at their poses."""
    if not ("site1" in a and "site2" in a) or "body1" in a or "body2" in a:
        raise MjcfError(f"{where}: give site1 and site2, or body1 (and body2)")
    fa, pa = ends.site(a["site1"], where)
    fb, pb = ends.site(a["site2"], where)
    if tag == "connect" or _weld_as_point(a, where):
        return fa, tuple(pa.translation), fb, tuple(pb.translation), "point"
    return (
        ends.add(f"{label}/site1", fa, pa),
        _ZERO,
        ends.add(f"{label}/site2", fb, pb),
        _ZERO,
        "frame",
    )


def _body_loop(ends: _Ends, tag: str, a: Mapping[str, str], label: str, where: str) -> _Loop:
    """A connect or weld between two bodies (body2: the world where not given), as MuJoCo
    places its ends at qpos0."""
    if "body1" not in a:
        raise MjcfError(f"{where}: needs body1 (or site1 and site2)")
    fa = ends.body(a["body1"], where)
    fb = ends.body(a.get("body2", "world"), where)
    x_a, x_b = ends.placement(fa), ends.placement(fb)
    if tag == "connect":
        if "anchor" not in a:
            raise MjcfError(f"{where}: a connect by bodies needs an anchor")
        anchor = _floats(a["anchor"], f"{where} anchor", (3,))
        # The point on body2 is where the anchor is at qpos0 (MuJoCo's rule).
        on_b = x_b.actInv(x_a.act(anchor))
        return fa, tuple(anchor), fb, tuple(on_b), "point"
    anchor = _floats(a.get("anchor", "0 0 0"), f"{where} anchor", (3,))
    relpose = _floats(a.get("relpose", "0 1 0 0 0 0 0"), f"{where} relpose", (7,))
    if np.any(relpose[3:]):
        w, x, y, z = relpose[3:] / np.linalg.norm(relpose[3:])
        on_a = _to_se3(pinocchio.Quaternion(w, x, y, z).matrix(), relpose[:3])
    else:  # the relative pose of qpos0
        on_a = x_a.actInv(x_b) * _to_se3(np.eye(3), anchor)
    if _weld_as_point(a, where):
        return fa, tuple(on_a.translation), fb, tuple(anchor), "point"
    return ends.add(f"{label}/body1", fa, on_a), _ZERO, fb, tuple(anchor), "frame"


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
    read = _read_file(path, floating, free_objects, actuator_springs)
    reader, structure = read.reader, read.structure
    writer = _Writer(reader, structure)
    reader.check_refusals()
    if not reader.bodies:
        raise MjcfError(f"{path}: no body in <worldbody>: nothing to settle")
    model = _build(writer.xml, path)
    joints = _qpos_order(reader, structure)
    _check_joints(path, model, joints, structure)
    _set_limits(model, joints, read.statics.limits)
    model.gravity = pinocchio.Motion(read.gravity, np.zeros(3))
    q0, start = _reference(reader, model, joints, structure)
    for name, q in _keyframes(reader, model, joints, q0, structure.added is not None).items():
        model.referenceConfigurations[name] = q
    model.referenceConfigurations["qpos0"] = q0
    loops = _loops(reader, model, q0, read.flags)
    springs, gains = _springs(read, model, q0, writer.inertias)
    reader.check_refusals()
    return MjcfModel(
        model=model,
        name=str(writer.xml.get("model")),
        joint_springs=springs,
        springdampers=gains,
        loops=loops,
        start=start,
        notes=reader.notes,
        inertias=writer.inertias,
        actuator_springs=read.actuators.springs,
        actuator_rests=read.actuators.rests,
        collision=read.collision,
    )


@dataclass
class _FileRead:
    """What the file says, read before any model is built."""

    reader: _Reader
    gravity: np.ndarray
    flags: dict[str, bool]
    statics: _Statics
    actuators: _ActuatorSprings
    structure: _Structure
    collision: MjcfCollision


def _read_file(path: Path, floating: bool, free_objects: str, actuator_springs: bool) -> _FileRead:
    reader = _Reader(path)
    gravity, flags = _option(reader)
    statics = _joint_statics(reader, flags)
    _other_sections(reader, flags)
    actuators = _actuators(reader, flags, actuator_springs)
    collision = mjcf_collision(reader, flags)
    floor_note = collision.floor_note()
    if floor_note is not None:
        reader.notes.append(floor_note)
    structure = _structure(reader, floating, free_objects)
    return _FileRead(reader, gravity, flags, statics, actuators, structure, collision)


def _springs(
    read: _FileRead,
    model: pinocchio.Model,
    q0: np.ndarray,
    inertias: Mapping[str, tuple[float, np.ndarray, np.ndarray]],
) -> tuple[list[tuple[str, float, float]], dict[str, tuple[float, float]]]:
    """The joint springs, those of springdamper joints with MuJoCo's stiffness (from the built
    model at qpos0), and each springdamper joint's stiffness and damping."""
    items = read.statics.springdampers
    gains = springdamper_gains(read.reader, model, q0, items, read.structure.added, inertias)
    if gains:
        read.reader.notes.append(
            f"springdamper of {_names(list(gains))}: stiffness and damping from the joint's "
            "inertia at qpos0, as MuJoCo compiles them"
        )
    springs = read.statics.springs + [
        (item.joint.name, gains[item.joint.name][0], item.rest) for item in items if item.spring
    ]
    return springs, gains


def _check_joints(
    path: Path, model: pinocchio.Model, joints: list[_Joint], structure: _Structure
) -> None:
    """Pinocchio's model has the file's joints (a locked free object's left out), and one
    of them moves."""
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


def _set_limits(
    model: pinocchio.Model, joints: list[_Joint], limits: Mapping[str, tuple[float, float]]
) -> None:
    """The hinge and slide joints' ranges as position limits, infinite where not limited."""
    lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    for joint in joints:
        if joint.kind in ("hinge", "slide"):
            iq = model.idx_qs[model.getJointId(joint.name)]
            lower[iq], upper[iq] = limits.get(joint.name, (-math.inf, math.inf))
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper

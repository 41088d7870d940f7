"""MJCF files read as MuJoCo reads them, into plain data; nothing here builds a model.

``<include>``, ``<compiler>``, ``<default>`` classes and ``childclass``, ``<frame>``, the five
ways to write an orientation, and the file names of ``<asset>``: the tree of bodies, joints,
geoms and sites comes out as dataclasses (``_Body``, ``_Joint``, ``_Geom``) in the body's
frame, with each element's attributes resolved through its default class. ``_mjcf`` builds
Pinocchio's model from them; what cannot be honoured is collected as refusals, raised at once.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio


class MjcfError(ValueError):
    """An MJCF file that cannot be read or whose statics cannot be honoured."""


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


def _names(items: Sequence[str], limit: int = 4, separator: str = ", ") -> str:
    """The first few items and a count of the rest: a hand has dozens of joints."""
    shown = separator.join(items[:limit])
    return shown + (f" and {len(items) - limit} more" if len(items) > limit else "")


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
    #: The total mass every body's mass and inertia are scaled to (<= 0: none).
    settotalmass: float = -1.0
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
# A way forward for what MuJoCo's compiler expands (attached models, composites, replicas):
# MuJoCo writes the model it compiled as plain MJCF, which pinsettle reads.
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


@dataclass
class _MeshAsset:
    name: str
    file: Path | None  # None: vertices and faces given in the element
    attrs: dict[str, str]
    label: str


def _choice(choices: tuple[str, ...]) -> Callable[[str, str], str]:
    return lambda text, where: _flag(text, where, choices)


def _is(choices: tuple[str, ...], yes: str) -> Callable[[str, str], bool]:
    return lambda text, where: _flag(text, where, choices) == yes


def _number(text: str, where: str) -> float:
    return float(_floats(text, where, (1,))[0])


def _as_text(text: str, where: str) -> str:
    return text


def _group_range(text: str, where: str) -> tuple[int, int]:
    low, high = _floats(text, where, (2,))
    return int(low), int(high)


def _eulerseq(text: str, where: str) -> str:
    if len(text) != 3 or any(ch not in "xyzXYZ" for ch in text):
        raise MjcfError(f"{where}: three of x y z X Y Z, got '{text}'")
    return text


# The <compiler> attributes read, in the order they are checked: (attribute, the _Compiler
# field it sets or None for one that is refused by its value, the reader of its text).
_COMPILER_ATTRIBUTES: tuple[tuple[str, str | None, Callable[[str, str], Any]], ...] = (
    ("angle", "degree", _is(("degree", "radian"), "degree")),
    ("eulerseq", "eulerseq", _eulerseq),
    ("autolimits", "autolimits", _is(("true", "false"), "true")),
    ("inertiafromgeom", "inertiafromgeom", _choice(("true", "false", "auto"))),
    ("inertiagrouprange", "inertiagrouprange", _group_range),
    ("boundmass", "boundmass", _number),
    ("boundinertia", "boundinertia", _number),
    ("settotalmass", "settotalmass", _number),
    ("coordinate", None, _as_text),
    ("meshdir", "meshdir", _as_text),
    ("texturedir", "texturedir", _as_text),
    ("assetdir", "assetdir", _as_text),
    ("strippath", "strippath", _is(("true", "false"), "true")),
)


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
        #: Geoms of the world body (frames composed in): floors for contacts.
        self.world_geoms: list[_Geom] = []
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
            for key, name, read in _COMPILER_ATTRIBUTES:
                if key not in el.attrib:
                    continue
                value = read(el.attrib[key], f"{where} {key}")
                if name is not None:
                    setattr(c, name, value)
                elif key == "coordinate" and value != "local":
                    self.refuse(
                        f'<compiler coordinate="{value}">',
                        "(global coordinates; MuJoCo 2.3.4 and later refuse them too)",
                        "load and save the file in MuJoCo 2.3.3 or older, as MuJoCo says",
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
                files = self._asset_files(el)
                for key, file in files.items():
                    if not file.is_file():
                        missing.append(f"{el.tag} {_describe(el)} file '{el.get(key)}'")
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

    def _asset_files(self, el: ET.Element) -> dict[str, Path]:
        """The files an asset names, by attribute, where MuJoCo looks for them: from the main
        file's folder and <compiler meshdir, texturedir, assetdir>, strippath applied."""
        c = self.compiler
        files: dict[str, Path] = {}
        for key in _ASSET_FILES.get(el.tag, ()):
            name = el.get(key)
            if not name:
                continue
            file = Path(Path(name).name) if c.strippath else Path(name)
            if not file.is_absolute():
                folder = c.texturedir if el.tag == "texture" else c.meshdir
                folder = folder if folder is not None else c.assetdir
                file = self.path.parent / (folder or "") / file
            files[key] = file
        return files

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
            unknown = sorted(set(attrs) - {"name", "group", "align"})
            if unknown:
                raise MjcfError(
                    f"{where}: <freejoint> takes name, group and align only, not "
                    f"{', '.join(unknown)} (MuJoCo refuses it too): remove "
                    f"{'them' if len(unknown) > 1 else 'it'}"
                )
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
        body: _Body | None,
        frame: pinocchio.SE3,
        childclass: str | None,
        where: str,
    ) -> None:
        """A geom of a body, or of the world (body None: a floor, for contacts; no mass)."""
        attrs = self._resolved(el, childclass)
        fromto = None
        if "fromto" in attrs:
            ends = _floats(attrs["fromto"], f"{where} fromto", (6,))
            fromto = np.concatenate([frame.act(ends[:3]), frame.act(ends[3:])])
        pose = frame * self._pose(attrs, where)
        (body.geoms if body is not None else self.world_geoms).append(
            _Geom(attrs, pose, fromto, _describe(el))
        )

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

"""What an MJCF file says about statics besides its bodies: gravity and the flags of
``<option>``, joint ranges and springs, tendons and deformables (refused where they act at
rest, else noted)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pinocchio

from ._memory import new_data
from ._mjcf_parse import _LIMITED, MjcfError, _describe, _flag, _floats, _Joint, _names, _Reader

# --- what the file says about statics ---------------------------------------------------------


@dataclass
class _SpringDamper:
    """A joint's ``springdamper="timeconst dampratio"``: MuJoCo's compiler turns it into a
    stiffness and a damping from the joint's inertia at qpos0 (``spring``: whether its
    stiffness is a spring here, springs on and the joint a hinge or slide; ``rest``: its
    springref, rad or m)."""

    joint: _Joint
    timeconst: float
    dampratio: float
    spring: bool
    rest: float


@dataclass
class _Statics:
    limits: dict[str, tuple[float, float]]
    springs: list[tuple[str, float, float]]
    #: Joints whose stiffness and damping come from the mass matrix, once it is built.
    springdampers: list[_SpringDamper] = field(default_factory=list)


def _option(reader: _Reader) -> tuple[np.ndarray, dict[str, bool]]:
    """Gravity and the flags of <option> that matter here (enable / disable)."""
    gravity = np.array([0.0, 0.0, -9.81])
    flags = {"gravity": True, "limit": True, "spring": True, "equality": True, "constraint": True}
    flags |= {"actuation": True, "clampctrl": True, "contact": True}
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


# Joint attributes that exert no force at rest: noted as ignored.
_IGNORED_JOINT_KEYS = ("damping", "frictionloss", "armature")


@dataclass
class _LeftOut:
    """What is read and left out, by name, for the notes: joints' (or tendons') attributes
    with no force at rest, and ranges and springs that a disabled flag turns off."""

    ignored: dict[str, list[str]] = field(
        default_factory=lambda: {key: [] for key in _IGNORED_JOINT_KEYS}
    )
    ranges_off: list[str] = field(default_factory=list)
    springs_off: list[str] = field(default_factory=list)
    #: Free joints given a range or limited (from a default class): MuJoCo ignores both.
    free_ranges: list[str] = field(default_factory=list)

    def notes(self, of: str = "") -> list[str]:
        """``of``: what the names are ("tendons " for tendons, nothing for joints)."""
        out = [
            f"ignored: joint {key} of {_names(names)} (no force at rest)"
            if key != "frictionloss"
            else f"ignored: joint friction loss of {_names(names)} (dry friction is not "
            "modelled: the rest is the frictionless one)"
            for key, names in self.ignored.items()
            if names
        ]
        if self.ranges_off:
            out.append(
                f"ranges of {of}{_names(self.ranges_off)} not applied: limits are disabled "
                '(<option><flag limit|constraint="disable">)'
            )
        if self.springs_off:
            out.append(
                f"springs of {of}{_names(self.springs_off)} not applied: springs are disabled "
                '(<option><flag spring="disable">)'
            )
        if self.free_ranges:
            out.append(
                f"ignored: the range and limited of free joint{'s' * (len(self.free_ranges) > 1)}"
                f" {_names(self.free_ranges)} (MuJoCo compiles a free joint unlimited)"
            )
        return out


def _joint_statics(reader: _Reader, flags: Mapping[str, bool]) -> _Statics:
    """Ranges, springs and the notes of every joint."""
    statics = _Statics({}, [])
    left_out = _LeftOut()
    for body in reader.all_bodies():
        for joint in body.joints:
            a = joint.attrs
            where = f"{reader.path}: <joint name=\"{joint.name}\"> (body '{body.name}')"
            angle = reader.compiler.angle if joint.kind in ("hinge", "ball") else 1.0
            window = _joint_range(reader, joint, where, left_out)
            if window is not None and flags["limit"] and flags["constraint"]:
                statics.limits[joint.name] = (window[0] * angle, window[1] * angle)
            elif window is not None:
                left_out.ranges_off.append(joint.name)
            auto = _spring_of(reader, joint, where, flags["spring"], left_out, statics)
            for key, names in left_out.ignored.items():
                given = key in a and np.any(_floats(a[key], f"{where} {key}", (1, 2, 3)))
                if given or (key == "damping" and auto):
                    names.append(joint.name)
    reader.notes.extend(left_out.notes())
    return statics


def _spring_of(
    reader: _Reader, joint: _Joint, where: str, on: bool, left_out: _LeftOut, statics: _Statics
) -> bool:
    """The joint's spring into ``statics``: from its springdamper (True: it has one, its
    stiffness and damping computed once the model is built), else from its stiffness."""
    auto = _springdamper(reader, joint, where, on, left_out)
    if auto is not None:
        statics.springdampers.append(auto)
        return True
    spring = _joint_spring(reader, joint, where, on, left_out)
    if spring is not None:
        statics.springs.append(spring)
    return False


def _is_limited(reader: _Reader, attrs: Mapping[str, str], where: str) -> bool:
    """Whether a joint or tendon is limited, as MuJoCo decides (limited, autolimits)."""
    limited = _flag(attrs.get("limited", "auto"), f"{where} limited", _LIMITED)
    if limited != "auto":
        return limited == "true"
    if not reader.compiler.autolimits and "range" in attrs:
        raise MjcfError(
            f'{where}: a range without limited="true" or "false" while <compiler '
            'autolimits="false"> (MuJoCo refuses this too)'
        )
    return "range" in attrs


def _joint_range(
    reader: _Reader, joint: _Joint, where: str, left_out: _LeftOut
) -> tuple[float, float] | None:
    """A limited hinge or slide joint's range, in the file's units; None for a joint that is
    not limited or a free joint (MuJoCo compiles a free joint unlimited, whatever its range
    and limited say: both are read, checked as MuJoCo checks them, and noted), and a refusal
    for a limited ball joint."""
    if joint.kind == "free":
        limited = _flag(joint.attrs.get("limited", "auto"), f"{where} limited", _LIMITED)
        if "range" in joint.attrs:
            _floats(joint.attrs["range"], f"{where} range", (2,))
        if limited == "true" or "range" in joint.attrs:
            left_out.free_ranges.append(joint.name)
        return None
    if not _is_limited(reader, joint.attrs, where):
        return None
    if joint.kind == "ball":
        reader.refuse(
            f'<joint name="{joint.name}">',
            "with a range on a ball joint (a cone limit)",
            'remove the range, or set limited="false" on it',
        )
        return None
    if "range" not in joint.attrs:
        raise MjcfError(f'{where}: limited="true" without a range')
    given = _floats(joint.attrs["range"], f"{where} range", (2,))
    if not given[0] < given[1]:
        raise MjcfError(f"{where} range: lower {given[0]:g} must be below upper {given[1]:g}")
    return float(given[0]), float(given[1])


def _joint_spring(
    reader: _Reader, joint: _Joint, where: str, on: bool, left_out: _LeftOut
) -> tuple[str, float, float] | None:
    """A joint's spring (joint, stiffness, rest), None where it has none; left out where
    springs are off (``on`` false), refused on a ball or free joint."""
    k = _joint_stiffness(reader, joint, where)
    if k == 0:
        return None
    if joint.kind not in ("hinge", "slide"):
        reader.refuse(
            f'<joint name="{joint.name}" stiffness>',
            f"on a {joint.kind} joint (joint springs on hinge and slide joints only)",
            'remove the stiffness, or <option><flag spring="disable"/>',
        )
        return None
    if not on:
        left_out.springs_off.append(joint.name)
        return None
    where_rest = f"{where} springref"
    rest = float(_floats(joint.attrs.get("springref", "0"), where_rest, (1,))[0])
    angle = reader.compiler.angle if joint.kind == "hinge" else 1.0
    return joint.name, k, rest * angle


def _springdamper(
    reader: _Reader, joint: _Joint, where: str, on: bool, left_out: _LeftOut
) -> _SpringDamper | None:
    """A joint's springdamper, None where it has none ("0 0", MuJoCo's default). MuJoCo's
    stiffness from it replaces the joint's own, and is refused on a ball or free joint as a
    stiffness is."""
    text = joint.attrs.get("springdamper")
    if text is None:
        return None
    timeconst, dampratio = _floats(text, f"{where} springdamper", (2,))
    if timeconst == 0 and dampratio == 0:
        return None
    if timeconst <= 0 or dampratio <= 0:
        raise MjcfError(
            f"{where} springdamper: both values (timeconst, dampratio) must be positive when "
            f"given, got '{text}' (MuJoCo refuses this too)"
        )
    _joint_stiffness(reader, joint, where)  # checked as MuJoCo reads it, then replaced
    if joint.kind not in ("hinge", "slide"):
        reader.refuse(
            f'<joint name="{joint.name}" springdamper>',
            f"on a {joint.kind} joint (a stiffness; joint springs on hinge and slide joints only)",
            'remove the springdamper, or <option><flag spring="disable"/>',
        )
    elif not on:
        left_out.springs_off.append(joint.name)
    rest = float(_floats(joint.attrs.get("springref", "0"), f"{where} springref", (1,))[0])
    angle = reader.compiler.angle if joint.kind == "hinge" else 1.0
    spring = on and joint.kind in ("hinge", "slide")
    return _SpringDamper(joint, float(timeconst), float(dampratio), spring, rest * angle)


def _joint_stiffness(reader: _Reader, joint: _Joint, where: str) -> float:
    """A joint's linear stiffness (>= 0); polynomial springs refused."""
    a = joint.attrs
    stiffness = _floats(a.get("stiffness", "0"), f"{where} stiffness", (1, 2, 3))
    if np.any(stiffness[1:]):
        reader.refuse(
            f'<joint name="{joint.name}" stiffness="{a["stiffness"]}">',
            "(a polynomial spring)",
            "keep its first, linear stiffness only",
        )
    k = float(stiffness[0])
    if k < 0:
        raise MjcfError(f"{where} stiffness: must be >= 0, got {k:g}")
    return k


def _other_sections(reader: _Reader, flags: Mapping[str, bool]) -> None:
    """Tendons, actuators, deformables: refused when they act at rest, else noted. A tendon's
    spring and range are off with MuJoCo's spring and limit flags, as a joint's are."""
    left_out = _LeftOut()
    tendons: list[str] = []
    for section in reader.root.findall("tendon"):
        for k, el in enumerate(section):
            label = el.get("name") or f"{el.tag} tendon {k}"
            tendons.append(label)
            _tendon(reader, el, label, flags, left_out)
    if tendons:
        reader.notes.append(f"ignored: tendons {_names(tendons)} (no spring, no limit at work)")
    reader.notes.extend(left_out.notes("tendons "))
    for section in reader.root.findall("deformable"):
        for el in section:
            if el.tag != "skin":  # a skin is drawn only
                reader.refuse(_describe(el), "in <deformable>", "remove it in a copy")


def _tendon(
    reader: _Reader, el: ET.Element, label: str, flags: Mapping[str, bool], left_out: _LeftOut
) -> None:
    """A tendon's spring and range: refused where they act, else left out by their flag."""
    attrs = reader._resolved(el, None, "tendon")
    where = f"{reader.path}: {_describe(el)} in <tendon>"
    if np.any(_floats(attrs.get("stiffness", "0"), f"{where} stiffness", (1, 2, 3))):
        if flags["spring"]:
            reader.refuse(
                _describe(el),
                "in <tendon> with a stiffness (a tendon spring)",
                'remove the stiffness, or <option><flag spring="disable"/> (all springs)',
            )
        else:
            left_out.springs_off.append(label)
    limited = _flag(attrs.get("limited", "auto"), f"{where} limited", _LIMITED)
    if limited == "true" or (limited == "auto" and reader.compiler.autolimits and "range" in attrs):
        if flags["limit"] and flags["constraint"]:
            reader.refuse(
                _describe(el),
                "in <tendon> with a range (a tendon limit)",
                'remove the ranges, or <option><flag limit="disable"/> (all limits)',
            )
        else:
            left_out.ranges_off.append(label)


# MuJoCo's mjMINVAL (the floor of its divisions) and mjEPS (its tolerance of a null pose).
_MINVAL = 1e-15
_EPS = 1e-14


def springdamper_gains(
    reader: _Reader,
    model: pinocchio.Model,
    q0: np.ndarray,
    items: list[_SpringDamper],
    added: str | None,
    inertias: Mapping[str, tuple[float, np.ndarray, np.ndarray]],
) -> dict[str, tuple[float, float]]:
    """Each springdamper joint's stiffness and damping as MuJoCo's compiler sets them
    (user_model.cc, AutoSpringDamper): from the joint's inertia at qpos0, the number of its
    dofs over the trace of its block of the inverse mass matrix (``dof_invweight0``, the
    joint's armature in the mass matrix as in MuJoCo's), stiffness = inertia / (timeconst
    dampratio)^2 and damping = 2 inertia / timeconst; on one of MuJoCo's simple bodies of
    sliders the inertia is the body's mass (its armature left out, as MuJoCo does). ``added``:
    the free joint ``floating`` adds, which is not MuJoCo's and is held still here;
    ``inertias``: each body's mass, centre of mass and inertia (body frame)."""
    if not items:
        return {}
    _check_tendon_armature(reader, items)
    armature = {j.name: j.attrs.get("armature", "0") for b in reader.all_bodies() for j in b.joints}
    data = new_data(model, "reading the MJCF file")
    mass = pinocchio.crba(model, data, q0)
    mass = np.triu(mass) + np.triu(mass, 1).T - np.diag(model.armature)
    keep = np.ones(model.nv, dtype=bool)
    for j in range(1, model.njoints):
        where = f'{reader.path}: <joint name="{model.names[j]}">'
        at, n = model.idx_vs[j], model.nvs[j]
        if model.names[j] == added:
            keep[at : at + n] = False
        elif model.names[j] in armature:
            text = armature[model.names[j]]
            mass[range(at, at + n), range(at, at + n)] += _floats(text, f"{where} armature", (1,))[
                0
            ]
    index = np.cumsum(keep) - 1
    inverse = np.linalg.inv(mass[np.ix_(keep, keep)])
    gains: dict[str, tuple[float, float]] = {}
    for item in items:
        j = model.getJointId(item.joint.name)
        at, n = index[model.idx_vs[j]], model.nvs[j]
        inertia = _simple_slider_mass(reader, item.joint.body, inertias)
        if inertia is None:
            inertia = n / max(_MINVAL, float(np.trace(inverse[at : at + n, at : at + n])))
        stiffness = inertia / max(_MINVAL, (item.timeconst * item.dampratio) ** 2)
        gains[item.joint.name] = (stiffness, 2 * inertia / max(_MINVAL, item.timeconst))
    return gains


def _check_tendon_armature(reader: _Reader, items: list[_SpringDamper]) -> None:
    """A tendon's armature is in MuJoCo's mass matrix: springdamper refused beside one."""
    for section in reader.root.findall("tendon"):
        for el in section:
            attrs = reader._resolved(el, None, "tendon")
            where = f"{reader.path}: {_describe(el)} in <tendon>"
            if _floats(attrs.get("armature", "0"), f"{where} armature", (1,))[0] != 0:
                reader.refuse(
                    f'<joint name="{items[0].joint.name}" springdamper>',
                    f"beside {_describe(el)} with an armature (in the mass matrix the stiffness "
                    "comes from)",
                    "give stiffness instead of springdamper, or remove the tendon's armature",
                )


def _simple_slider_mass(
    reader: _Reader, name: str, inertias: Mapping[str, tuple[float, np.ndarray, np.ndarray]]
) -> float | None:
    """The mass of a body MuJoCo compiles as simple with sliders only (body_simple 2:
    user_model.cc), whose dof_invweight0 is 1 / mass; None for any other body. Such a body has
    no child, is on the world (or on a body without joints that is), has its centre of mass
    and principal axes on its frame, and has slide joints only, at its origin, each along an
    axis of its frame."""
    body = reader.body_names[name]
    parents = {id(c): b for b in reader.all_bodies() for c in b.children}
    parent = parents.get(id(body))
    on_world = parent is None or (id(parent) not in parents and not parent.joints)
    if body.children or not on_world or name not in inertias:
        return None
    mass, com, inertia = inertias[name]
    if np.abs(com).max() > _EPS or np.abs(inertia - np.diag(np.diag(inertia))).max() > _EPS:
        return None
    return mass if mass > 0 and all(map(_simple_slide, body.joints)) else None


def _simple_slide(joint: _Joint) -> bool:
    """A slide joint at its body's origin along an axis of the body's frame."""
    aligned = int(np.sum(np.abs(joint.axis) > _EPS)) == 1
    return joint.kind == "slide" and aligned and np.abs(joint.pos).max() <= _EPS

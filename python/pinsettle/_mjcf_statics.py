"""What an MJCF file says about statics besides its bodies: gravity and the flags of
``<option>``, joint ranges and springs, tendons and deformables (refused where they act at
rest, else noted)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from ._mjcf_parse import _LIMITED, MjcfError, _describe, _flag, _floats, _Joint, _names, _Reader

# --- what the file says about statics ---------------------------------------------------------


@dataclass
class _Statics:
    limits: dict[str, tuple[float, float]]
    springs: list[tuple[str, float, float]]


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
        return out


def _joint_statics(reader: _Reader, flags: Mapping[str, bool]) -> _Statics:
    """Ranges, springs and the notes of every joint."""
    limits: dict[str, tuple[float, float]] = {}
    springs: list[tuple[str, float, float]] = []
    left_out = _LeftOut()
    for body in reader.all_bodies():
        for joint in body.joints:
            a = joint.attrs
            where = f"{reader.path}: <joint name=\"{joint.name}\"> (body '{body.name}')"
            angle = reader.compiler.angle if joint.kind in ("hinge", "ball") else 1.0
            window = _joint_range(reader, joint, where)
            if window is not None and flags["limit"] and flags["constraint"]:
                limits[joint.name] = (window[0] * angle, window[1] * angle)
            elif window is not None:
                left_out.ranges_off.append(joint.name)
            spring = _joint_spring(reader, joint, where, flags["spring"], left_out)
            if spring is not None:
                springs.append(spring)
            for key, names in left_out.ignored.items():
                if key in a and np.any(_floats(a[key], f"{where} {key}", (1, 2, 3))):
                    names.append(joint.name)
    reader.notes.extend(left_out.notes())
    return _Statics(limits, springs)


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


def _joint_range(reader: _Reader, joint: _Joint, where: str) -> tuple[float, float] | None:
    """A limited hinge or slide joint's range, in the file's units; None for a joint that is
    not limited, and a refusal for a limited ball or free joint."""
    if not _is_limited(reader, joint.attrs, where):
        return None
    if joint.kind == "free":
        reader.refuse(
            f'<joint name="{joint.name}">', "with a range on a free joint", "remove the range"
        )
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


def _joint_stiffness(reader: _Reader, joint: _Joint, where: str) -> float:
    """A joint's linear stiffness (>= 0); polynomial springs and springdamper refused."""
    a = joint.attrs
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

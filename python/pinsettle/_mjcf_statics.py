"""What an MJCF file says about statics besides its bodies: gravity and the flags of
``<option>``, joint ranges and springs, tendons and deformables (refused where they act at
rest, else noted)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ._mjcf_parse import _LIMITED, MjcfError, _describe, _flag, _floats, _names, _Reader

# --- what the file says about statics ---------------------------------------------------------


@dataclass
class _Statics:
    limits: dict[str, tuple[float, float]]
    springs: list[tuple[str, float, float]]


def _option(reader: _Reader) -> tuple[np.ndarray, dict[str, bool]]:
    """Gravity and the flags of <option> that matter here (enable / disable)."""
    gravity = np.array([0.0, 0.0, -9.81])
    flags = {"gravity": True, "limit": True, "spring": True, "equality": True, "constraint": True}
    flags |= {"actuation": True, "clampctrl": True}
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


def _joint_statics(reader: _Reader, flags: Mapping[str, bool]) -> _Statics:
    """Ranges, springs and the notes of every joint."""
    limits: dict[str, tuple[float, float]] = {}
    springs: list[tuple[str, float, float]] = []
    ignored: dict[str, list[str]] = {"damping": [], "frictionloss": [], "armature": []}
    limits_off: list[str] = []
    springs_off: list[str] = []
    for body in reader.all_bodies():
        for joint in body.joints:
            a = joint.attrs
            where = f"{reader.path}: <joint name=\"{joint.name}\"> (body '{body.name}')"
            angle = reader.compiler.angle if joint.kind in ("hinge", "ball") else 1.0
            # limited / autolimits, as MuJoCo decides them
            limited = _flag(a.get("limited", "auto"), f"{where} limited", ("true", "false", "auto"))
            if limited == "auto":
                if not reader.compiler.autolimits and "range" in a:
                    raise MjcfError(
                        f'{where}: a range without limited="true" or "false" while <compiler '
                        'autolimits="false"> (MuJoCo refuses this too)'
                    )
                on = "range" in a and reader.compiler.autolimits
            else:
                on = limited == "true"
            if on:
                if joint.kind == "free":
                    reader.refuse(
                        f'<joint name="{joint.name}">',
                        "with a range on a free joint",
                        "remove the range",
                    )
                elif joint.kind == "ball":
                    reader.refuse(
                        f'<joint name="{joint.name}">',
                        "with a range on a ball joint (a cone limit)",
                        'remove the range, or set limited="false" on it',
                    )
                elif "range" not in a:
                    raise MjcfError(f'{where}: limited="true" without a range')
                else:
                    given = _floats(a["range"], f"{where} range", (2,))
                    if not given[0] < given[1]:
                        raise MjcfError(
                            f"{where} range: lower {given[0]:g} must be below upper {given[1]:g}"
                        )
                    low, high = given * angle
                    if flags["limit"] and flags["constraint"]:
                        limits[joint.name] = (float(low), float(high))
                    else:
                        limits_off.append(joint.name)
            # springs
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
            if k > 0:
                if joint.kind not in ("hinge", "slide"):
                    reader.refuse(
                        f'<joint name="{joint.name}" stiffness>',
                        f"on a {joint.kind} joint (joint springs on hinge and slide joints only)",
                        'remove the stiffness, or <option><flag spring="disable"/>',
                    )
                elif flags["spring"]:
                    rest = float(_floats(a.get("springref", "0"), f"{where} springref", (1,))[0])
                    springs.append((joint.name, k, rest * angle))
                else:
                    springs_off.append(joint.name)
            for key, names in ignored.items():
                if key in a and np.any(_floats(a[key], f"{where} {key}", (1, 2, 3))):
                    names.append(joint.name)
    for key, names in ignored.items():
        if names:
            reader.notes.append(
                f"ignored: joint {key} of {_names(names)} (no force at rest)"
                if key != "frictionloss"
                else f"ignored: joint friction loss of {_names(names)} (dry friction is not "
                "modelled: the rest is the frictionless one)"
            )
    if limits_off:
        reader.notes.append(
            f"ranges of {_names(limits_off)} not applied: limits are disabled "
            '(<option><flag limit|constraint="disable">)'
        )
    if springs_off:
        reader.notes.append(
            f"springs of {_names(springs_off)} not applied: springs are disabled "
            '(<option><flag spring="disable">)'
        )
    return _Statics(limits, springs)


def _other_sections(reader: _Reader, flags: Mapping[str, bool]) -> None:
    """Tendons, actuators, deformables: refused when they act at rest, else noted. A tendon's
    spring and range are off with MuJoCo's spring and limit flags, as a joint's are."""
    springs_off: list[str] = []
    ranges_off: list[str] = []
    tendons: list[str] = []
    for section in reader.root.findall("tendon"):
        for k, el in enumerate(section):
            attrs = reader._resolved(el, None, "tendon")
            label = el.get("name") or f"{el.tag} tendon {k}"
            tendons.append(label)
            where = f"{reader.path}: {_describe(el)} in <tendon>"
            if np.any(_floats(attrs.get("stiffness", "0"), f"{where} stiffness", (1, 2, 3))):
                if flags["spring"]:
                    reader.refuse(
                        _describe(el),
                        "in <tendon> with a stiffness (a tendon spring)",
                        'remove the stiffness, or <option><flag spring="disable"/> (all springs)',
                    )
                else:
                    springs_off.append(label)
            limited = _flag(attrs.get("limited", "auto"), f"{where} limited", _LIMITED)
            if limited == "true" or (
                limited == "auto" and reader.compiler.autolimits and "range" in attrs
            ):
                if flags["limit"] and flags["constraint"]:
                    reader.refuse(
                        _describe(el),
                        "in <tendon> with a range (a tendon limit)",
                        'remove the ranges, or <option><flag limit="disable"/> (all limits)',
                    )
                else:
                    ranges_off.append(label)
    if tendons:
        reader.notes.append(f"ignored: tendons {_names(tendons)} (no spring, no limit at work)")
    if ranges_off:
        reader.notes.append(
            f"ranges of tendons {_names(ranges_off)} not applied: limits are disabled "
            '(<option><flag limit|constraint="disable">)'
        )
    if springs_off:
        reader.notes.append(
            f"springs of tendons {_names(springs_off)} not applied: springs are disabled "
            '(<option><flag spring="disable">)'
        )
    for section in reader.root.findall("deformable"):
        for el in section:
            if el.tag != "skin":  # a skin is drawn only
                reader.refuse(_describe(el), "in <deformable>", "remove it in a copy")

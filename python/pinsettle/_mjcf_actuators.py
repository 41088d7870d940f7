"""MJCF actuators as MuJoCo compiles them, as far as their force at rest goes: position
actuators on hinge and slide joints as joint springs, the rest noted."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ._mjcf_parse import _ACTUATOR_TAGS, MjcfError, _describe, _floats, _Joint, _names, _Reader

# --- actuators ----------------------------------------------------------------------------------


@dataclass
class _Actuator:
    """An actuator as MuJoCo compiles it, as far as its force at rest goes: force = gain ctrl +
    bias[0] + bias[1] length (gaintype fixed, biastype affine), length = gear q on a joint."""

    label: str
    element: ET.Element
    gaintype: str = "fixed"
    gain: float = 1.0
    biastype: str = "none"
    bias: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    dyntype: str = "none"
    gear: float = 1.0
    ctrllimited: str = "auto"
    ctrlrange: tuple[float, float] | None = None
    forcelimited: str = "auto"
    forcerange: tuple[float, float] | None = None
    inheritrange: float = 0.0
    group: int = 0

    def apply(self, tag: str, attrs: Mapping[str, str], where: str) -> None:
        """One element's attributes (a default's or the actuator's own), as MuJoCo's
        OneActuator and mjs_setTo* set them."""

        def number(key: str, default: float, counts: Sequence[int] = (1,)) -> float:
            if key not in attrs:
                return default
            return float(_floats(attrs[key], f"{where} {key}", counts)[0])

        def pair(key: str) -> tuple[float, float] | None:
            if key not in attrs:
                return None
            low, high = _floats(attrs[key], f"{where} {key}", (2,))
            return float(low), float(high)

        self.gear = number("gear", self.gear, range(1, 7))
        self.group = int(number("group", self.group))
        self.ctrllimited = attrs.get("ctrllimited", self.ctrllimited)
        self.forcelimited = attrs.get("forcelimited", self.forcelimited)
        self.ctrlrange = pair("ctrlrange") or self.ctrlrange
        self.forcerange = pair("forcerange") or self.forcerange
        if tag == "general":
            self.gaintype = attrs.get("gaintype", self.gaintype)
            self.biastype = attrs.get("biastype", self.biastype)
            self.dyntype = attrs.get("dyntype", self.dyntype)
            if "gainprm" in attrs:
                self.gain = float(_floats(attrs["gainprm"], f"{where} gainprm", range(1, 11))[0])
            if "biasprm" in attrs:
                given = _floats(attrs["biasprm"], f"{where} biasprm", range(1, 11))
                self.bias = [float(x) for x in [*given[:3], 0.0, 0.0, 0.0][:3]]
        elif tag == "motor":
            self.gain, self.gaintype, self.biastype, self.dyntype = 1.0, "fixed", "none", "none"
        elif tag in ("position", "intvelocity"):
            kp = number("kp", self.gain)
            self.gain, self.bias[1] = kp, -kp
            self.gaintype, self.biastype = "fixed", "affine"
            if "timeconst" in attrs:
                self.dyntype = "filterexact" if number("timeconst", 0.0) > 0 else "none"
            self.inheritrange = number("inheritrange", self.inheritrange)
            if tag == "intvelocity":
                self.dyntype = "integrator"
        elif tag == "velocity":
            kv = number("kv", 1.0)
            self.gain, self.bias = kv, [0.0, 0.0, -kv]
            self.gaintype, self.biastype, self.dyntype = "fixed", "affine", "none"
        else:  # forces that no spring stands for (dampers, muscles, cylinders, ...)
            self.gaintype = tag

    def target(self) -> str | None:
        """The joint it acts on (None: another transmission)."""
        attrs = self.element.attrib
        return attrs.get("joint") or attrs.get("jointinparent")

    def spring_like(self) -> bool:
        """An affine force falling with the length and no dynamics that changes it at rest:
        kp (ctrl - gear q) at rest, a position actuator."""
        return (
            self.gaintype == "fixed"
            and self.biastype == "affine"
            and self.bias[1] != 0
            and self.dyntype in ("none", "filter", "filterexact")
        )

    def force_limited(self, autolimits: bool) -> bool:
        return self.forcelimited == "true" or (
            self.forcelimited == "auto" and autolimits and self.forcerange is not None
        )

    def stiffness(self) -> float:
        """The joint spring's stiffness: gear^2 kp."""
        return -(self.gear**2) * self.bias[1]


@dataclass
class _ActuatorSprings:
    """Position actuators on hinge and slide joints as joint springs: (joint, stiffness, rest)
    at ctrl 0, and the rests at each keyframe's ctrl, in the same order."""

    springs: list[tuple[str, float, float]] = field(default_factory=list)
    rests: dict[str, list[float]] = field(default_factory=dict)


def _actuators(reader: _Reader, flags: Mapping[str, bool], as_springs: bool) -> _ActuatorSprings:
    """The actuators: with ``as_springs`` each position actuator on a hinge or slide joint (an
    affine force falling with the joint's length: kp (ctrl - gear q) at rest) is a joint spring
    of stiffness gear^2 kp towards the control (clamped to ctrlrange as MuJoCo clamps it):
    ctrl 0, or a keyframe's ctrl when that pose is chosen. Others are noted."""
    out = _ActuatorSprings()
    elements = [el for section in reader.root.findall("actuator") for el in section]
    if not elements:
        return out
    if not flags["actuation"]:
        reader.notes.append(
            f"ignored: {len(elements)} actuator{'s' if len(elements) > 1 else ''} "
            f"({_names([el.get('name') or el.tag for el in elements])}): actuation is "
            'disabled (<option><flag actuation="disable">)'
        )
        return out
    sorted_out = _sort(reader, elements, as_springs)
    if sorted_out.others:
        reader.notes.append(sorted_out.others_note(as_springs))
    if not sorted_out.mapped:
        return out
    controls = _controls(reader, len(elements))
    for k, actuator, joint in sorted_out.mapped:
        ctrlrange = _ctrl_range(reader, actuator, joint)
        stiffness = actuator.stiffness()
        rests: dict[str, float] = {}
        for pose, ctrl in controls.items():
            c = float(ctrl[k])
            if ctrlrange is not None and flags["clampctrl"]:
                c = min(max(c, ctrlrange[0]), ctrlrange[1])
            rests[pose] = actuator.gear * (actuator.gain * c + actuator.bias[0]) / stiffness
        out.springs.append((joint.name, stiffness, rests["qpos0"]))
        for pose, rest in rests.items():
            out.rests.setdefault(pose, []).append(rest)
    reader.notes.extend(sorted_out.springs_notes())
    return out


@dataclass
class _Sorted:
    """The actuators sorted: those held as joint springs (index, actuator, joint), and the
    labels of the others, for the notes."""

    mapped: list[tuple[int, _Actuator, _Joint]] = field(default_factory=list)
    others: list[str] = field(default_factory=list)
    #: Position actuators among the others (enabled, but actuator_springs is off).
    position_like: int = 0
    force_limited: list[str] = field(default_factory=list)

    def others_note(self, as_springs: bool) -> str:
        hint = (
            " (not position actuators: no spring at a constant control)"
            if as_springs
            else "; [model] actuator_springs = true (--actuator-springs) holds the position "
            "actuators as joint springs"
            if self.position_like
            else ", no control"
        )
        return (
            f"ignored: {len(self.others)} actuator{'s' if len(self.others) > 1 else ''} "
            f"({_names(self.others)}): statics with constant loads only{hint}"
        )

    def springs_notes(self) -> list[str]:
        described = [f"{a.label} on {j.name} ({a.stiffness():g})" for _, a, j in self.mapped]
        notes = [
            f"position actuators as joint springs (actuator_springs = true): "
            f"{_names(described)}, towards ctrl 0, or the ctrl of the keyframe [start] pose names"
        ]
        if self.force_limited:
            notes.append(
                f"forcerange of actuators {_names(self.force_limited)} not applied: their "
                "springs are linear (check that their force at the rest stays in range)"
            )
        return notes


def _sort(reader: _Reader, elements: list[ET.Element], as_springs: bool) -> _Sorted:
    """Which actuators become joint springs (``as_springs``: enabled position actuators on
    hinge and slide joints; refused on other transmissions) and which are noted."""
    joints = {j.name: j for body in reader.all_bodies() for j in body.joints}
    disabled_groups = _disabled_groups(reader)
    out = _Sorted()
    for k, el in enumerate(elements):
        actuator = _compiled(reader, k, el)
        if actuator is None:
            continue
        spring_like = actuator.spring_like()
        enabled = actuator.group not in disabled_groups
        if not as_springs or not spring_like or not enabled:
            out.others.append(actuator.label)
            out.position_like += spring_like and enabled
            continue
        joint = _spring_joint(reader, actuator, joints)
        if joint is None:
            continue
        if actuator.force_limited(reader.compiler.autolimits):
            out.force_limited.append(actuator.label)
        out.mapped.append((k, actuator, joint))
    return out


def _disabled_groups(reader: _Reader) -> set[int]:
    """The actuator groups <option actuatorgroupdisable> turns off."""
    disabled_groups: set[int] = set()
    for option in reader.root.findall("option"):
        if "actuatorgroupdisable" in option.attrib:
            where = f"{reader.path}: <option> actuatorgroupdisable"
            disabled_groups |= {
                int(x) for x in _floats(option.attrib["actuatorgroupdisable"], where, range(0, 31))
            }
    return disabled_groups


def _compiled(reader: _Reader, k: int, el: ET.Element) -> _Actuator | None:
    """The ``k``-th actuator with its class's defaults applied (None: refused, unknown)."""
    path = reader.path
    where = f"{path}: {_describe(el)} in <actuator>"
    if el.tag not in _ACTUATOR_TAGS:
        reader.refuse(
            _describe(el), "in <actuator> (an actuator pinsettle does not know)", "remove it"
        )
        return None
    cls = el.get("class") or reader.main_class
    if cls not in reader.actuator_defaults:
        raise MjcfError(f"{where}: unknown default class '{cls}'")
    actuator = _Actuator(el.get("name") or f"actuator {k}", el)
    for tag, attrs in reader.actuator_defaults[cls]:
        actuator.apply(tag, attrs, f'{path}: <default class="{cls}"> <{tag}>')
    actuator.apply(el.tag, el.attrib, where)
    return actuator


def _spring_joint(
    reader: _Reader, actuator: _Actuator, joints: Mapping[str, _Joint]
) -> _Joint | None:
    """The hinge or slide joint a position actuator holds as a spring; None (refused) for
    another transmission or a force that grows with the position."""
    el = actuator.element
    name = actuator.target()
    joint = joints.get(name or "")
    if joint is None or joint.kind not in ("hinge", "slide"):
        on = (
            f"on {joint.kind} joint '{name}'"
            if joint is not None
            else "on a "
            + next(
                (t for t in ("tendon", "site", "body", "cranksite") if t in el.attrib),
                "missing joint",
            )
        )
        reader.refuse(
            f"{_describe(el)} in <actuator>",
            f"(a position actuator {on}; actuator springs are on hinge and slide joints only)",
            "leave actuator_springs off",
        )
        return None
    if actuator.bias[1] > 0:
        reader.refuse(
            f"{_describe(el)} in <actuator>",
            "(its force grows with the joint's position, biasprm[1] > 0: no spring)",
            "leave actuator_springs off",
        )
        return None
    return joint


def _controls(reader: _Reader, count: int) -> dict[str, np.ndarray]:
    """The controls of each pose: 0 at qpos0, each keyframe's ctrl (0 where it has none)."""
    controls: dict[str, np.ndarray] = {"qpos0": np.zeros(count)}
    for section in reader.root.findall("keyframe"):
        for k, key in enumerate(section.findall("key")):
            name = key.get("name") or f"key{k}"
            where = f'{reader.path}: <key name="{name}"> ctrl'
            given = key.get("ctrl")
            controls[name] = _floats(given, where, (count,)) if given else np.zeros(count)
    return controls


def _ctrl_range(reader: _Reader, actuator: _Actuator, joint: _Joint) -> tuple[float, float] | None:
    """The range MuJoCo clamps the control to (its own, or inheritrange of the joint's
    range), None where it is not clamped."""
    ctrlrange = actuator.ctrlrange
    if actuator.inheritrange > 0 and "range" in joint.attrs:
        scale = reader.compiler.angle if joint.kind == "hinge" else 1.0
        where = f"{reader.path}: joint '{joint.name}' range"
        low, high = _floats(joint.attrs["range"], where, (2,))
        middle, half = (low + high) / 2 * scale, (high - low) / 2 * scale
        ctrlrange = (
            middle - actuator.inheritrange * half,
            middle + actuator.inheritrange * half,
        )
    clamped = actuator.ctrllimited == "true" or (
        actuator.ctrllimited == "auto" and reader.compiler.autolimits
    )
    return ctrlrange if clamped else None

"""The ``<mimic>`` tags of a URDF file, which ``pinocchio.buildModelFromUrdf(path)`` (its
default, ``mimic=False``) ignores: the joints they couple, read from the file itself."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class MimicTag:
    """``<joint name=follower><mimic joint=leader multiplier=.. offset=../>``: q[follower] =
    multiplier * q[leader] + offset (URDF defaults: multiplier 1, offset 0)."""

    follower: str
    leader: str
    multiplier: float = 1.0
    offset: float = 0.0
    follower_type: str = ""


def _number(text: str | None, default: float, where: str) -> float:
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{where} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"{where} must be finite, got {text!r}")
    return value


def urdf_mimic_tags(path: str | Path) -> list[MimicTag]:
    """Every ``<mimic>`` tag of the URDF file whose joint moves, in file order (a fixed joint's
    tag couples no motion; it is still checked).

    Raises:
        ValueError: the file is not XML (naming it), or a tag without its ``joint`` attribute
            or with a multiplier or offset that is not a finite number (naming the joint).
    """
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as error:
        raise ValueError(f"{path}: cannot read its <mimic> tags: {error}") from None
    tags = []
    for joint in root.iter("joint"):
        mimic = joint.find("mimic")
        if mimic is None:
            continue
        name = joint.get("name", "")
        leader = mimic.get("joint")
        where = f"{path}: the <mimic> tag of joint '{name}'"
        if not leader:
            raise ValueError(f"{where} has no 'joint' attribute (the joint it follows)")
        tags.append(
            MimicTag(
                name,
                leader,
                _number(mimic.get("multiplier"), 1.0, f"{where}: multiplier"),
                _number(mimic.get("offset"), 0.0, f"{where}: offset"),
                joint.get("type", ""),
            )
        )
    return [tag for tag in tags if tag.follower_type != "fixed"]

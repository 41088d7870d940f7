"""The ``<mimic>`` tags of a URDF file, which ``pinocchio.buildModelFromUrdf(path)`` (its
default, ``mimic=False``) ignores: the joints they couple, read from the file itself; and the
XML reading that the model files share (``xml_bytes``, ``parse_xml``)."""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

# Whitespace or comments before the XML declaration (a blank line first: pybullet_data's
# differential/diff_ring.urdf). Not well-formed XML, refused by ElementTree, though urdfdom and
# MuJoCo read such files.
_PROLOGUE = re.compile(rb"^((?:\xef\xbb\xbf)?(?:\s|<!--.*?-->)*)(<\?xml\b.*?\?>)", re.S)


def xml_bytes(path: str | Path) -> bytes:
    """The bytes of an XML file, with its XML declaration moved first when whitespace or
    comments precede it (whitespace dropped, comments kept after it).

    Raises:
        OSError: the file cannot be read.
    """
    data = Path(path).read_bytes()
    found = _PROLOGUE.match(data)
    if found is None or not found.group(1).lstrip(b"\xef\xbb\xbf"):
        return data
    comments = found.group(1).lstrip(b"\xef\xbb\xbf").strip()
    return found.group(2) + (b"\n" + comments if comments else b"") + data[found.end() :]


def parse_xml(path: str | Path) -> ET.Element:
    """The root element of an XML file, read as ``xml_bytes`` gives it.

    Raises:
        ET.ParseError: not well-formed XML (the declaration's place aside).
        OSError: the file cannot be read.
    """
    return ET.fromstring(xml_bytes(path))


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
        ValueError: the file is not well-formed XML or cannot be read (the message says where
            and why), or a tag without its ``joint`` attribute or with a multiplier or offset
            that is not a finite number (naming the joint).
    """
    try:
        root = parse_xml(path)
    except ET.ParseError as error:
        # urdfdom (Pinocchio's URDF reader) reads past some faults ElementTree refuses: an
        # unescaped '&', text after the root element.
        raise ValueError(
            f"{path}: not well-formed XML ({error}), although urdfdom reads past it: correct "
            "the file there (an '&' written '&amp;', a '<' in a value written '&lt;', one root "
            "element)"
        ) from None
    except OSError as error:
        raise ValueError(f"{path}: cannot read the file: {error}") from None
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

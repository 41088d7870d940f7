"""Model files where a scene goes: which kind a file is, and SRDF poses.

``file_kind`` tells a scene (TOML) from a URDF and an MJCF file by content (the XML root
element), the suffix deciding only for ``.toml``; a file that is none of them is an error that
says which parsers were tried and each parser's own reason. ``load_srdf_poses`` reads the named
poses (``group_state``) of an SRDF file with Pinocchio's ``loadReferenceConfigurations`` after
checking them against the model, since Pinocchio skips unknown joints and reads a malformed
value as zeros without a word.
"""

from __future__ import annotations

import math
import os
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pinocchio

from ._urdf_mimic import parse_xml
from .robots import build_urdf_model, robots_dir

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

# The SRDF example-robot-data's own loader pairs with each robot of pinsettle.robot_names()
# (below example-robot-data/robots). talos_left_arm has none here: its loader takes the SRDF of
# the whole Talos, whose poses name joints the arm does not have.
ROBOT_SRDF: dict[str, str] = {
    "ur5": "ur_description/srdf/ur5.srdf",
    "panda": "panda_description/srdf/panda.srdf",
    "z1": "z1_description/srdf/z1.srdf",
    "kinova": "kinova_description/srdf/kinova.srdf",
    "xarm7": "xarm_description/srdf/xarm7.srdf",
    "finger_edu": "finger_edu_description/srdf/finger_edu.srdf",
    "solo12": "solo_description/srdf/solo.srdf",
    "anymal": "anymal_b_simple_description/srdf/anymal.srdf",
    "go1": "go1_description/srdf/go1.srdf",
    "talos": "talos_data/srdf/talos.srdf",
}


def robot_srdf(name: str) -> Path | None:
    """The SRDF example-robot-data ships for a robot, or None."""
    sub = ROBOT_SRDF.get(name)
    return None if sub is None else robots_dir() / sub


def _first_reason(error: BaseException) -> str:
    text = str(error)
    if "message:" in text:  # Pinocchio's exceptions: file, function, line, then the message
        text = text.split("message:")[-1]
    return " ".join(text.split()) or type(error).__name__


def file_kind(path: Path) -> str:
    """'scene', 'urdf' or 'mjcf' for an existing file.

    Raises:
        ValueError: none of them; the message says which parsers were tried and why each
            refused the file.
    """
    if path.suffix.lower() == ".toml":
        return "scene"
    xml_error = ""
    try:
        root = parse_xml(path).tag
    except ET.ParseError as error:
        root, xml_error = None, f"not well-formed XML: {error}"
    except OSError as error:
        raise ValueError(f"{path}: cannot read the file: {error}") from None
    if root is None:
        # Not well-formed XML that opens as a URDF or an MJCF file: that reader's reasons.
        head = path.read_bytes()[:4096].decode("utf-8", errors="replace")
        opening = re.search(
            r"<\s*(robot|mujoco)[\s>/]", re.sub(r"<!--.*?-->", "", head, flags=re.S)
        )
        root = opening.group(1) if opening else None
    if root == "robot":
        return "urdf"
    if root == "mujoco":
        return "mjcf"
    reasons = []
    if root is None and path.suffix.lower() not in (".urdf", ".xml"):
        try:
            tomllib.loads(path.read_text(encoding="utf-8"))
            return "scene"
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
            reasons.append(f"as a scene (TOML): {_first_reason(error)}")
    try:
        build_urdf_model(path)  # urdfdom's XML reader is more lenient than ElementTree
        return "urdf"
    except (ValueError, RuntimeError) as error:
        reasons.append(f"as a URDF (urdfdom): {_first_reason(error).split('does not parse: ')[-1]}")
    # MJCF is read by pinsettle's own reader (ElementTree first): its reason is the XML's.
    # Pinocchio's MJCF parser is never run on a file that is not well-formed XML: its XML
    # reader accepts more, and its MJCF reader can fail hard on what it then finds.
    reason = f"the root element is <{root}>, not <mujoco>" if root is not None else xml_error
    reasons.append(f"as MJCF: {reason}")
    hint = (
        ": it is a part of an MJCF file (<include>d by one): solve the file that includes it"
        if root == "mujocoinclude"
        else ""
    )
    raise ValueError(
        f"{path}: neither a scene, a URDF nor an MJCF file; read " + "; read ".join(reasons) + hint
    )


def _group_states(path: Path) -> list[tuple[str, list[tuple[str, str | None]]]]:
    """(pose name, [(joint name, value text)]) of each group_state of an SRDF file."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as error:
        raise ValueError(f"{path}: the SRDF is not well-formed XML: {error}") from None
    if root.tag != "robot":
        raise ValueError(f"{path}: not an SRDF file: the root element is <{root.tag}>, not <robot>")
    states = []
    for state in root.iter("group_state"):
        name = state.get("name")
        if not name:
            raise ValueError(f"{path}: a <group_state> without a name")
        states.append(
            (name, [(j.get("name") or "", j.get("value")) for j in state.findall("joint")])
        )
    return states


def _srdf_values(where: str, value: str | None) -> list[float]:
    """The numbers of a pose's joint value."""
    if value is None:
        raise ValueError(f"{where}: missing 'value'")
    try:
        values = [float(x) for x in value.split()]
    except ValueError:
        raise ValueError(f"{where}: value must be numbers, got '{value}'") from None
    if not all(math.isfinite(x) for x in values):
        raise ValueError(f"{where}: value must be finite, got '{value}'")
    return values


def _check_srdf_pose(
    model: pinocchio.Model, path: Path, pose: str, joints: list[tuple[str, str | None]]
) -> list[str]:
    """Checks a pose's values against the model's joints; returns the free-flyer joints it
    gives that the model does not have (left out)."""
    names = list(model.names)
    unknown: list[str] = []
    left_out: list[str] = []
    for joint, value in joints:
        where = f"{path}: pose '{pose}', joint '{joint}'"
        values = _srdf_values(where, value)
        if joint not in names:
            # A free-flyer's pose (x y z qx qy qz qw) for a root the model has fixed (or
            # frees under another name): nothing of the model to put it on.
            (left_out if len(values) == 7 else unknown).append(joint)
            continue
        j = model.getJointId(joint)
        expected = 1 if model.nqs[j] == 2 and model.nvs[j] == 1 else model.nqs[j]
        if len(values) != expected:
            raise ValueError(
                f"{where}: {len(values)} value{'s' if len(values) != 1 else ''} for a joint "
                f"({model.joints[j].shortname()}) that takes {expected}"
            )
    if unknown:
        raise ValueError(
            f"{path}: pose '{pose}' names joint{'s' if len(unknown) > 1 else ''} the model "
            f"does not have: {', '.join(unknown[:6])}"
            + (f" and {len(unknown) - 6} more" if len(unknown) > 6 else "")
            + f" (the model has {model.njoints - 1} joints: "
            + ", ".join(names[1:7])
            + (", ..." if model.njoints > 7 else "")
            + "): this SRDF does not match the model"
        )
    return left_out


def load_srdf_poses(model: pinocchio.Model, path: str | Path) -> dict[str, str]:
    """Add the SRDF's named poses to ``model.referenceConfigurations`` (Pinocchio's
    ``loadReferenceConfigurations``; ``disable_collisions`` and the rest of the SRDF play no
    part). Returns a note by pose name where a pose's root free-flyer was left out (a model
    with a fixed root).

    Raises:
        FileNotFoundError: no such file.
        ValueError: not an SRDF, or a pose naming a joint the model does not have, or a value
            that is not a number or has the wrong count for its joint.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"path must be an SRDF file's path (str or Path), got {path!r}")
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"SRDF file not found: {path}")
    notes: dict[str, str] = {}
    for pose, joints in _group_states(path):
        left_out = _check_srdf_pose(model, path, pose, joints)
        if left_out:
            notes[pose] = (
                f"pose '{pose}': the free-flyer pose of {', '.join(left_out)} left out (the "
                "model has no such joint: its root is fixed, or its free-flyer is named "
                "otherwise)"
            )
    try:
        pinocchio.loadReferenceConfigurations(model, str(path), False)
    except (RuntimeError, ValueError) as error:
        raise ValueError(f"{path}: Pinocchio's SRDF reader: {_first_reason(error)}") from None
    return notes

"""Robots shipped by the ``example-robot-data`` wheel, by name, as ``pinocchio.Model``.

Only the kinematic and inertial model is built: meshes are never loaded for solving.
"""

from __future__ import annotations

import math
import os
import re
import site
import sys
import tempfile
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio

from ._checks import negative_moments, unknown_key_message
from ._urdf_mimic import parse_xml, urdf_mimic_tags, xml_bytes

# name -> (URDF path below example-robot-data/robots, root attached by a free-flyer joint)
ROBOTS: dict[str, tuple[str, bool]] = {
    "ur3": ("ur_description/urdf/ur3_robot.urdf", False),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", False),
    "ur10": ("ur_description/urdf/ur10_robot.urdf", False),
    "panda": ("panda_description/urdf/panda.urdf", False),
    "z1": ("z1_description/urdf/z1.urdf", False),
    "kinova": ("kinova_description/robots/kinova.urdf", False),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", False),
    "so_arm100": ("so_arm_description/urdf/so100.urdf", False),
    "so_arm101": ("so_arm_description/urdf/so101.urdf", False),
    "double_pendulum": ("double_pendulum_description/urdf/double_pendulum.urdf", False),
    "double_pendulum_continuous": (
        "double_pendulum_description/urdf/double_pendulum_continuous.urdf",
        False,
    ),
    "double_pendulum_simple": (
        "double_pendulum_description/urdf/double_pendulum_simple.urdf",
        False,
    ),
    "asr_twodof": ("asr_twodof_description/urdf/TwoDofs.urdf", False),
    "finger_edu": ("finger_edu_description/robots/finger_edu.urdf", False),
    "baxter": ("baxter_description/urdf/baxter.urdf", False),
    "allegro_right_hand": ("allegro_hand_description/urdf/allegro_right_hand.urdf", False),
    "talos_left_arm": ("talos_data/robots/talos_left_arm.urdf", False),
    "solo12": ("solo_description/robots/solo12.urdf", True),
    "anymal": ("anymal_b_simple_description/robots/anymal.urdf", True),
    "go1": ("go1_description/urdf/go1.urdf", True),
    "talos": ("talos_data/robots/talos_reduced.urdf", True),
}


def robots_dir() -> Path:
    """The folder of the example-robot-data URDFs installed in this environment."""
    roots = [*sys.path, *site.getsitepackages(), site.getusersitepackages()]
    # pinocchio itself lives below site-packages/cmeel.prefix: look next to it first.
    roots.insert(0, str(Path(pinocchio.__file__).resolve().parents[4].parent))
    for root in roots:
        candidate = Path(root) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
        if candidate.is_dir():
            return candidate
    raise FileNotFoundError(
        "example-robot-data is not installed in this environment (pip install example-robot-data)"
    )


def robot_names() -> list[str]:
    """Names accepted by :func:`load_robot`."""
    return sorted(ROBOTS)


def robot_urdf(name: str) -> Path:
    """Path of the URDF of a robot of example-robot-data, by name."""
    if not isinstance(name, str) or name not in ROBOTS:
        raise ValueError(unknown_key_message("robot", str(name), robot_names()))
    return robots_dir() / ROBOTS[name][0]


def load_robot(name: str, floating: bool | None = None) -> pinocchio.Model:
    """The ``pinocchio.Model`` of a robot of example-robot-data (no meshes loaded).

    ``floating`` overrides whether the root gets a free-flyer joint (legged robots and
    humanoids have one by default). Its URDF's ``<mimic>`` tags are left out, with a warning,
    as :func:`load_urdf` does.
    """
    model = build_robot_model(name, floating)
    warn_of_mimic_tags(robot_urdf(name), f"pinsettle.Scene.from_robot({name!r})")
    return model


def build_robot_model(name: str, floating: bool | None = None) -> pinocchio.Model:
    """:func:`load_robot` without the warning (for callers that apply the tags)."""
    path = robot_urdf(name)
    if floating is None:
        floating = ROBOTS[name][1]
    return build_urdf_model(path, floating=floating)


def load_urdf(path: str | Path, floating: bool = False) -> pinocchio.Model:
    """The ``pinocchio.Model`` of a URDF file (meshes are not loaded).

    Like ``pinocchio.buildModelFromUrdf`` by default, it leaves the file's ``<mimic>`` tags out
    (each joint moves on its own) and warns when there are any: ``pinsettle.Scene.from_urdf``
    couples them.

    Raises:
        FileNotFoundError: no such file.
        ValueError: the URDF does not parse; the message names the file and the parser's reason.
    """
    model = build_urdf_model(path, floating)
    warn_of_mimic_tags(Path(path), f"pinsettle.Scene.from_urdf('{path}')")
    return model


def warn_of_mimic_tags(path: Path, instead: str) -> None:
    """A UserWarning naming the joints of the URDF's ``<mimic>`` tags, which the model just
    built leaves uncoupled, and ``instead``, the call that couples them."""
    try:
        tags = urdf_mimic_tags(path)
    except ValueError:  # not XML to ElementTree (urdfdom is more lenient): nothing to say
        return
    if tags:
        joints = ", ".join(f"'{tag.follower}' (follows '{tag.leader}')" for tag in tags)
        warnings.warn(
            f"{path}: <mimic> tags left out, as pinocchio.buildModelFromUrdf does by default: "
            f"{joints} move{'s' if len(tags) == 1 else ''} on "
            f"{'its' if len(tags) == 1 else 'their'} own in this model; {instead} couples them",
            UserWarning,
            stacklevel=3,
        )


# The URDF joint types urdfdom knows (PyBullet reads 'spherical' too; urdfdom does not).
URDF_JOINT_TYPES = "revolute, continuous, prismatic, fixed, floating, planar"


def _merge(reasons: list[str]) -> list[str]:
    """urdfdom's reasons, repeats of one reason on several elements merged into one line
    ("Could not parse collision element for Link [a] (and on [b], [c] and 5 more)")."""
    groups: dict[str, list[str]] = {}
    for reason in reasons:
        groups.setdefault(re.sub(r"\[[^\]]*\]", "[]", reason), []).append(reason)
    merged = []
    for items in groups.values():
        if len(items) == 1:
            merged.append(items[0])
            continue
        names = [m.group(0) for item in items[1:] for m in [re.search(r"\[[^\]]*\]", item)] if m]
        more = f" and {len(names) - 2} more" if len(names) > 2 else ""
        merged.append(f"{items[0]} (and on {', '.join(names[:2])}{more})")
    return merged


def _xml_reasons(path: Path, reasons: list[str]) -> list[str]:
    """TinyXML's codes name no cause: ElementTree's reason does, when it has one."""
    if not any("XML_ERROR" in reason for reason in reasons):
        return reasons
    try:
        parse_xml(path)
    except ET.ParseError as xml_error:
        return [f"not well-formed XML ({xml_error})"]
    except OSError:
        pass
    return reasons


# What to do, by a phrase of urdfdom's reasons (the first that matches wins).
_URDF_HINTS: tuple[tuple[tuple[str, ...], str], ...] = (
    (("no known type",), f"change the joint's type to one of URDF's ({URDF_JOINT_TYPES})"),
    (("$(", "${"), "the file holds xacro substitutions: expand it with xacro first"),
    (
        ("visual element", "collision element"),
        "urdfdom checks <visual> and <collision> (pinsettle never uses them): fix or drop them",
    ),
)


def _urdf_hint(joined: str) -> str:
    for phrases, hint in _URDF_HINTS:
        if any(phrase in joined for phrase in phrases):
            return hint
    return "correct the file there"


def _urdf_fault(path: Path, reasons: list[str], error: BaseException | None) -> str:
    """One short line for a URDF urdfdom refuses: its first reasons (repeats merged, the
    consequences of a joint's fault left out) and what to do."""
    reasons = [" ".join(r.split()).removeprefix("Error:").strip() for r in reasons]
    reasons = _xml_reasons(path, reasons)
    reasons = [r for r in reasons if r != "joint xml is not initialized correctly"]
    merged = _merge(reasons) or [str(error) if error is not None else "no reason given"]
    text = "; ".join(merged[:2]) + (
        f" (and {len(merged) - 2} more fault{'s' if len(merged) > 3 else ''})"
        if len(merged) > 2
        else ""
    )
    return f"{path}: the URDF does not parse: {text}; {_urdf_hint(' '.join(reasons))}"


def _urdf_text(path: Path) -> str | None:
    """The file as text with its XML declaration first, where a comment comes before it
    (urdfdom refuses that; Pinocchio's XML-string builder takes the text); else None."""
    try:
        data = xml_bytes(path)
        return data.decode("utf-8") if data != path.read_bytes() else None
    except UnicodeDecodeError:
        return None
    except OSError as os_error:
        raise ValueError(f"{path}: cannot read the file: {os_error}") from None


def _build_capturing_stderr(
    path: Path, text: str | None, floating: bool
) -> tuple[pinocchio.Model | None, BaseException | None, str]:
    """The model (or the error), and what the URDF parser (urdfdom, C++) printed on the
    process's stderr meanwhile: its reasons, for the message on failure or passed on."""
    model = None
    error: BaseException | None = None
    with tempfile.TemporaryFile(mode="w+b") as captured:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(captured.fileno(), 2)
        try:
            root = [pinocchio.JointModelFreeFlyer()] if floating else []
            if text is not None:
                model = pinocchio.buildModelFromXML(text, *root)
            else:
                model = pinocchio.buildModelFromUrdf(str(path), *root)
        except (RuntimeError, ValueError) as e:
            error = e
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        parser_says = captured.read().decode(errors="replace").strip()
    return model, error, parser_says


def _link_inertia_fault(inertial: ET.Element) -> str | None:
    """What no rigid body has in a link's <inertial>: a negative or non-finite mass, an inertia
    that is not finite or not positive semidefinite; None when it is sound (or unreadable:
    urdfdom has judged those already)."""
    try:
        mass_tag = inertial.find("mass")
        mass = float(mass_tag.get("value", "0")) if mass_tag is not None else 0.0
        tag = inertial.find("inertia")
        keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
        i = {k: float(tag.get(k, "0")) if tag is not None else 0.0 for k in keys}
    except ValueError:
        return None
    if not math.isfinite(mass) or mass < 0:
        return f"mass {mass} kg; a mass must be finite and >= 0"
    matrix = np.array(
        [
            [i["ixx"], i["ixy"], i["ixz"]],
            [i["ixy"], i["iyy"], i["iyz"]],
            [i["ixz"], i["iyz"], i["izz"]],
        ]
    )
    if not np.isfinite(matrix).all():
        return "an inertia that is not finite"
    moments = negative_moments(matrix)
    if moments is not None:
        return (
            f"an inertia with principal moments {np.array2string(moments, precision=4)} kg m^2; "
            "an inertia must be positive semidefinite"
        )
    return None


def _check_link_inertias(path: Path) -> None:
    """Refuse a URDF link whose <inertial> no rigid body has, naming the link (Pinocchio sums
    the links a fixed joint welds together, which can hide a negative mass in a positive sum)."""
    try:
        root = parse_xml(path)
    except (ET.ParseError, OSError):
        return  # urdfdom read it; the solver's model check still sees the summed inertias
    for link in root.iter("link"):
        inertial = link.find("inertial")
        fault = _link_inertia_fault(inertial) if inertial is not None else None
        if fault is not None:
            raise ValueError(f"{path}: link '{link.get('name')}' has {fault}")


def build_urdf_model(path: str | Path, floating: bool = False) -> pinocchio.Model:
    """:func:`load_urdf` without the warning (for callers that apply the tags)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"URDF file not found: {path}")
    model, error, parser_says = _build_capturing_stderr(path, _urdf_text(path), floating)
    reasons = [
        line.strip()
        for line in parser_says.splitlines()
        if line.strip() and not line.strip().startswith("at line")
    ]
    # urdfdom reports an element it cannot read (a mass of "nan", an inertia of "abc", an
    # origin with two numbers) as an error and drops it, and Pinocchio builds the model
    # anyway: without that link's inertia, say. Such a file is refused as one that does not
    # parse, not solved as a different mechanism.
    dropped = any(reason.startswith("Error:") for reason in reasons)
    if model is None or error is not None or dropped:
        raise ValueError(_urdf_fault(path, reasons, error))
    _check_link_inertias(path)
    if parser_says:
        print(parser_says, file=sys.stderr)
    return model

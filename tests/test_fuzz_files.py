"""Fuzzing the file readers: mutated scene files, URDFs and MJCF files never crash, hang or
traceback.

1,000 cases, each a scene of robots/ (with its URDF, or the URDF of its example-robot-data robot
in place of ``robot = ...``) with one to three seeded random mutations: lines deleted,
duplicated or cut short, garbage and non-UTF-8 bytes, broken XML, NaN, infinities and huge or
negative numbers in origins, inertias, limits and TOML values, inertials removed, joints naming
missing links, cycles, unknown joint types, mimic tags, wrong types in TOML values, unknown
keys, names of joints and frames that do not exist, missing files. 300 more cases are MuJoCo
MJCF files (written below with default classes, frames, several joints in a body, ranges,
springs, refs, equalities, keyframes and an include), solved directly or from a scene's
``[model] mjcf``, with the same kinds of mutations and MJCF's own: weird numbers in poses,
orientations, ranges, springs, masses, sizes, anchors and keyframes, unknown classes and bodies,
elements renamed (a body made a frame, a joint a free joint, ...), enumerations made wrong,
missing includes and meshes. Each case goes through
``pinsettle.__main__.main(["solve", ...])``, the function the ``pinsettle solve`` command
runs, with a small step and time budget, and must either run (exit 0 or 1) or end with exit 2
and one line ``pinsettle: error: ...``: no traceback, no crash, no hang. All cases run in one
child interpreter (a crash fails this test with the case named, instead of ending pytest);
every 50th case also runs through the real command line, ``python -m pinsettle solve``, in a
process of its own with a timeout.

A failure names the case number, its mutations and the folder its files are in; the cases are
made from SEED alone, so ``make_case(i)`` rebuilds any of them.
"""

from __future__ import annotations

import json
import os
import random
import re
import subprocess
import sys
import textwrap
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pinsettle
import pytest

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
SEED = 20261123
CASES = 1000
MJCF_CASES = 300  # after the 1,000: cases 1000 to 1299
SUBPROCESS_EVERY = 50  # 20 of the 1,000 through the real command line
SOLVE_FLAGS = ["--max-steps", "200", "--max-time", "1"]
CASE_BUDGET = 10.0  # s per case in process: max_time 1 s plus loading; more is a hang
BATCH_TIMEOUT = 300.0  # s for all cases in process
PROCESS_TIMEOUT = 60.0  # s per command-line run

WEIRD_NUMBERS = [
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e-320",
    "0",
    "-0.0",
    "-1",
    "-1e6",
    "1e30",
    "1e400",
    "-1e400",
    "abc",
    "",
    "1,0",
    "0x10",
]
WEIRD_TOML_VALUES = [
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "1e308",
    "-1e308",
    "1e-320",
    "1e400",
    "123456789012345678901234567890",
    '"1.0"',
    '"nan"',
    '""',
    "true",
    "[]",
    "[1.0, 2.0]",
    "[[1.0], [2.0]]",
    '["a", 1]',
    "{ x = 1 }",
    "{}",
    '"no_such_joint"',
    '"universe"',
    '"../no/such/file.urdf"',
    '"."',
    "1979-05-27T07:32:00Z",
]
JOINT_TYPES = ["revolute", "continuous", "prismatic", "fixed", "floating", "planar", "spherical"]
JOINT_TYPES += ["bogus", ""]
GARBAGE_LINES = [
    "[model",
    "= 1",
    "x =",
    "[[spring]]",
    "[[loop]]",
    "[solver]\nkt = 5.0",
    "[start]\nno_such_joint = 1.0",
    'urdf = "other.urdf"',
    "<link name=",
    "</robot>",
    "<joint name='j' type='revolute'><parent link='nowhere'/><child link='base'/></joint>",
    "<!--",
    "]]>",
    "\t\t\t",
]


@dataclass
class Case:
    index: int
    folder: Path
    scene: Path
    mutations: list[str] = field(default_factory=list)


def _lines(text: str) -> list[str]:
    return text.split("\n")


def _delete_line(rng: random.Random, text: str) -> tuple[str, str]:
    lines = _lines(text)
    i = rng.randrange(len(lines))
    del lines[i]
    return "\n".join(lines), f"deleted line {i + 1}"


def _duplicate_line(rng: random.Random, text: str) -> tuple[str, str]:
    lines = _lines(text)
    i = rng.randrange(len(lines))
    lines.insert(i, lines[i])
    return "\n".join(lines), f"duplicated line {i + 1}"


def _truncate(rng: random.Random, text: str) -> tuple[str, str]:
    n = rng.randrange(len(text) + 1)
    return text[:n], f"cut at character {n}"


def _insert_garbage(rng: random.Random, text: str) -> tuple[str, str]:
    lines = _lines(text)
    i = rng.randrange(len(lines) + 1)
    if rng.random() < 0.3:
        garbage = "".join(chr(rng.randrange(1, 0x3000)) for _ in range(rng.randrange(1, 12)))
    else:
        garbage = rng.choice(GARBAGE_LINES)
    lines.insert(i, garbage)
    return "\n".join(lines), f"inserted {garbage!r} at line {i + 1}"


NUMBER = re.compile(r"(?<![\w.])-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")


def _toml_number(rng: random.Random, text: str) -> tuple[str, str]:
    """A number of a value (not in a comment) replaced by a weird TOML value."""
    lines = _lines(text)
    candidates = [
        i for i, line in enumerate(lines) if "=" in line and not line.lstrip().startswith("#")
    ]
    candidates = [i for i in candidates if NUMBER.search(lines[i].split("=", 1)[1])]
    if not candidates:
        return _insert_garbage(rng, text)
    i = rng.choice(candidates)
    key, value = lines[i].split("=", 1)
    matches = list(NUMBER.finditer(value))
    m = rng.choice(matches)
    new = rng.choice(WEIRD_TOML_VALUES)
    lines[i] = f"{key}={value[: m.start()]}{new}{value[m.end() :]}"
    return "\n".join(lines), f"line {i + 1}: {m.group()} -> {new}"


def _toml_value(rng: random.Random, text: str) -> tuple[str, str]:
    """The whole value of a key replaced (wrong types, missing names)."""
    lines = _lines(text)
    candidates = [
        i
        for i, line in enumerate(lines)
        if re.match(r"\s*[\w\"]+\s*=", line) and not line.lstrip().startswith("#")
    ]
    if not candidates:
        return _insert_garbage(rng, text)
    i = rng.choice(candidates)
    key = lines[i].split("=", 1)[0]
    new = rng.choice(WEIRD_TOML_VALUES)
    lines[i] = f"{key}= {new}"
    return "\n".join(lines), f"line {i + 1}: {key.strip()} = {new}"


def _toml_unknown_key(rng: random.Random, text: str) -> tuple[str, str]:
    lines = _lines(text)
    headers = [i for i, line in enumerate(lines) if line.startswith("[")]
    i = rng.choice(headers) if headers else -1
    key = rng.choice(["bogus_key = 1", "stifness = 2.0", "kt2 = 0.5", "urdf_path = 'x.urdf'"])
    lines.insert(i + 1, key)
    return "\n".join(lines), f"unknown key {key!r} after line {i + 1}"


def _toml_table(rng: random.Random, text: str) -> tuple[str, str]:
    """A table header changed: array of tables <-> table, a name misspelt, a table repeated."""
    lines = _lines(text)
    headers = [i for i, line in enumerate(lines) if line.startswith("[")]
    if not headers:
        return _insert_garbage(rng, text)
    i = rng.choice(headers)
    old = lines[i]
    name = old.strip("[] ")
    lines[i] = rng.choice(
        [f"[{name}]" if old.startswith("[[") else f"[[{name}]]", f"[{name}s]", f"[{name}]\n{old}"]
    )
    return "\n".join(lines), f"line {i + 1}: {old} -> {lines[i]!r}"


ATTRIBUTE = re.compile(r'(\w+)="([^"]*)"')
NUMERIC_ATTRIBUTES = {"xyz", "rpy", "value", "ixx", "ixy", "ixz", "iyy", "iyz", "izz", "lower"}
NUMERIC_ATTRIBUTES |= {"upper", "effort", "velocity", "multiplier", "offset", "size", "radius"}


def _urdf_number(rng: random.Random, text: str) -> tuple[str, str]:
    """One component of a numeric attribute (origin, mass, inertia, axis, limit) made weird."""
    matches = [m for m in ATTRIBUTE.finditer(text) if m.group(1) in NUMERIC_ATTRIBUTES]
    if not matches:
        return _insert_garbage(rng, text)
    m = rng.choice(matches)
    parts = m.group(2).split()
    new = rng.choice(WEIRD_NUMBERS)
    if parts:
        parts[rng.randrange(len(parts))] = new
    else:
        parts = [new]
    value = " ".join(parts)
    start, end = m.span(2)
    return text[:start] + value + text[end:], f"{m.group(1)}={m.group(2)!r} -> {value!r}"


def _urdf_axis(rng: random.Random, text: str) -> tuple[str, str]:
    matches = list(re.finditer(r'<axis xyz="([^"]*)"', text))
    if not matches:
        return _urdf_number(rng, text)
    m = rng.choice(matches)
    new = rng.choice(["0 0 0", "1 1", "nan 0 0", "1e-300 0 0", "1 0 0 0"])
    return text[: m.start(1)] + new + text[m.end(1) :], f"axis {m.group(1)!r} -> {new!r}"


def _urdf_remove_inertial(rng: random.Random, text: str) -> tuple[str, str]:
    matches = list(re.finditer(r"<inertial>.*?</inertial>", text, re.DOTALL))
    if not matches:
        return _delete_line(rng, text)
    m = rng.choice(matches)
    return text[: m.start()] + text[m.end() :], "removed an <inertial>"


def _urdf_links(text: str) -> tuple[list[str], list[re.Match[str]], list[re.Match[str]]]:
    links = re.findall(r'<link\s+name="([^"]*)"', text)
    parents = list(re.finditer(r'<parent\s+link="([^"]*)"', text))
    children = list(re.finditer(r'<child\s+link="([^"]*)"', text))
    return links, parents, children


def _urdf_missing_link(rng: random.Random, text: str) -> tuple[str, str]:
    _, parents, children = _urdf_links(text)
    if not parents and not children:
        return _delete_line(rng, text)
    m = rng.choice(parents + children)
    return text[: m.start(1)] + "no_such_link" + text[m.end(1) :], f"{m.group()} -> no_such_link"


def _urdf_cycle(rng: random.Random, text: str) -> tuple[str, str]:
    """A joint's child made the root link, or its parent made its own child: a cycle or a link
    with two parents."""
    links, parents, children = _urdf_links(text)
    if not children or not links:
        return _delete_line(rng, text)
    child_names = {m.group(1) for m in children}
    roots = [name for name in links if name not in child_names] or links
    if rng.random() < 0.5:
        m = rng.choice(children)
        new = roots[0]
    else:
        m = rng.choice(parents)
        new = rng.choice(children).group(1)
    return text[: m.start(1)] + new + text[m.end(1) :], f"{m.group()} -> {new}"


def _urdf_joint_type(rng: random.Random, text: str) -> tuple[str, str]:
    matches = list(re.finditer(r'<joint\s+name="[^"]*"\s+type="([^"]*)"', text))
    if not matches:
        return _delete_line(rng, text)
    m = rng.choice(matches)
    new = rng.choice(JOINT_TYPES)
    return text[: m.start(1)] + new + text[m.end(1) :], f"joint type {m.group(1)} -> {new!r}"


def _urdf_mimic(rng: random.Random, text: str) -> tuple[str, str]:
    names = re.findall(r'<joint\s+name="([^"]*)"', text)
    ends = [m.start() for m in re.finditer(r"</joint>", text)]
    if not names or not ends:
        return _delete_line(rng, text)
    leader = rng.choice([*names, "no_such_joint"])
    multiplier = rng.choice(["1", "-1", "nan", "0", "abc"])
    tag = f'<mimic joint="{leader}" multiplier="{multiplier}" offset="0"/>'
    at = rng.choice(ends)
    return text[:at] + tag + text[at:], f"inserted {tag}"


def _urdf_limit(rng: random.Random, text: str) -> tuple[str, str]:
    matches = list(re.finditer(r"<limit[^>]*/>", text))
    if not matches:
        return _urdf_number(rng, text)
    m = rng.choice(matches)
    new = rng.choice(
        ["", '<limit lower="1" upper="-1" effort="1" velocity="1"/>', '<limit lower="0"/>']
    )
    return text[: m.start()] + new + text[m.end() :], f"{m.group()} -> {new!r}"


MJCF_NUMERIC = {"pos", "quat", "euler", "axisangle", "xyaxes", "zaxis", "axis", "range", "ref"}
MJCF_NUMERIC |= {"stiffness", "springref", "damping", "mass", "diaginertia", "fullinertia"}
MJCF_NUMERIC |= {"size", "fromto", "anchor", "relpose", "gravity", "qpos", "torquescale"}
MJCF_NUMERIC |= {"density", "group", "springdamper", "inertiagrouprange", "boundmass"}
MJCF_NAMES = {"name", "class", "childclass", "body1", "body2", "site1", "site2", "joint", "mesh"}
MJCF_ENUMS = {
    "type": ["hinge", "slide", "ball", "free", "capsule", "mesh", "plane", "bogus", ""],
    "limited": ["true", "false", "auto", "yes", ""],
    "angle": ["degree", "radian", "grad"],
    "autolimits": ["true", "false", "maybe"],
    "inertiafromgeom": ["true", "false", "auto", "no"],
    "eulerseq": ["xyz", "ZYX", "xxz", "ab", "xyzx"],
    "active": ["true", "false", "0"],
}
MJCF_TAGS = ["body", "frame", "joint", "freejoint", "geom", "site", "inertial", "include"]
MJCF_TAGS += ["default", "connect", "weld", "fixed", "worldbody", "bogus"]
MJCF_GARBAGE = [
    "<body>",
    "</body>",
    "<frame>",
    '<joint type="free"/>',
    '<joint name="j1"/>',
    '<include file="missing.xml"/>',
    '<geom type="mesh" mesh="none"/>',
    '<tendon><fixed name="t" stiffness="1"/></tendon>',
    '<equality><weld body1="nowhere"/></equality>',
    '<equality><joint joint1="j1"/></equality>',
    '<body name="extra"><joint/><geom size="0.1"/></body>',
    '<default class="main"><joint/></default>',
    '<asset><mesh name="m" file="gone.stl"/></asset>',
    "<!--",
]


def _mjcf_attribute(
    rng: random.Random, text: str, names: set[str], new: str | None
) -> tuple[str, str]:
    matches = [m for m in ATTRIBUTE.finditer(text) if m.group(1) in names]
    if not matches:
        return _delete_line(rng, text)
    m = rng.choice(matches)
    if new is None:  # a number made weird
        parts = m.group(2).split() or [""]
        parts[rng.randrange(len(parts))] = rng.choice(WEIRD_NUMBERS)
        new = " ".join(parts)
    start, end = m.span(2)
    return text[:start] + new + text[end:], f"{m.group(1)}={m.group(2)!r} -> {new!r}"


def _mjcf_number(rng: random.Random, text: str) -> tuple[str, str]:
    return _mjcf_attribute(rng, text, MJCF_NUMERIC, None)


def _mjcf_name(rng: random.Random, text: str) -> tuple[str, str]:
    names = re.findall(r'name="([^"]*)"', text) or ["x"]
    return _mjcf_attribute(rng, text, MJCF_NAMES, rng.choice(["no_such", "", *names]))


def _mjcf_enum(rng: random.Random, text: str) -> tuple[str, str]:
    key = rng.choice(sorted(MJCF_ENUMS))
    return _mjcf_attribute(rng, text, {key}, rng.choice(MJCF_ENUMS[key]))


def _mjcf_tag(rng: random.Random, text: str) -> tuple[str, str]:
    """An element renamed (its closing tag too, when it has one)."""
    matches = list(re.finditer(r"<(\w+)[\s>/]", text))
    if not matches:
        return _delete_line(rng, text)
    m = rng.choice(matches)
    old, new = m.group(1), rng.choice(MJCF_TAGS)
    text = text[: m.start(1)] + new + text[m.end(1) :]
    close = text.find(f"</{old}>", m.start())
    if close >= 0 and rng.random() < 0.8:
        text = text[:close] + f"</{new}>" + text[close + len(old) + 3 :]
    return text, f"<{old}> -> <{new}>"


def _mjcf_garbage(rng: random.Random, text: str) -> tuple[str, str]:
    lines = _lines(text)
    i = rng.randrange(len(lines) + 1)
    garbage = rng.choice(MJCF_GARBAGE)
    lines.insert(i, garbage)
    return "\n".join(lines), f"inserted {garbage!r} at line {i + 1}"


# Line-level mutations mostly break the XML; the others reach the MJCF reader's rules.
MJCF_MUTATIONS = [
    _delete_line,
    _duplicate_line,
    _truncate,
    _insert_garbage,
    _mjcf_garbage,
    _mjcf_garbage,
    *[_mjcf_number] * 5,
    _mjcf_name,
    _mjcf_name,
    _mjcf_enum,
    _mjcf_enum,
    _mjcf_tag,
]

# MJCF files to mutate: (main file, included part or None). Small and fast to solve.
MJCF_ARM = """<mujoco model="arm">
  <compiler angle="degree" eulerseq="zyx"/>
  <option gravity="0 0 -9.81"/>
  <default>
    <joint damping="0.1"/>
    <default class="hinge">
      <joint type="hinge" axis="0 1 0" stiffness="2" springref="10" range="-120 120"/>
      <geom type="capsule" size="0.03 0.1"/>
    </default>
  </default>
  <worldbody>
    <geom type="plane" size="1 1 0.1"/>
    <frame pos="0 0 0.5" euler="0 0 20">
      <body name="upper" childclass="hinge">
        <joint name="shoulder" ref="10"/>
        <joint name="roll" axis="1 0 0" limited="false"/>
        <inertial pos="0.2 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
        <body name="lower" pos="0.4 0 0" euler="0 30 0">
          <joint name="elbow" range="-90 10"/>
          <geom fromto="0 0 0 0.3 0 0"/>
          <site name="tip" pos="0.3 0 0"/>
          <body name="slider" pos="0.3 0 0">
            <joint name="slide" type="slide" axis="1 0 0" range="-0.1 0.1" stiffness="50"/>
            <geom type="sphere" size="0.04" mass="0.2"/>
          </body>
        </body>
      </body>
    </frame>
  </worldbody>
  <actuator><motor name="m" joint="shoulder"/></actuator>
  <keyframe><key name="home" qpos="0.1 0 -0.5 0"/></keyframe>
</mujoco>
"""
MJCF_FOURBAR = """<mujoco model="fourbar">
  <compiler angle="radian"/>
  <default><joint axis="0 1 0"/></default>
  <worldbody>
    <body name="crank" axisangle="0 1 0 -1.4">
      <joint name="crank_joint" ref="-1.4" stiffness="4" springref="-1.2"/>
      <inertial pos="0.075 0 0" mass="0.5" diaginertia="0.001 0.001 0.00005"/>
      <body name="coupler" pos="0.15 0 0" axisangle="0 1 0 1.0">
        <joint name="coupler_joint" ref="1.0"/>
        <inertial pos="0.2 0 0" mass="1" diaginertia="0.013 0.013 0.0001"/>
        <site name="coupler_end" pos="0.4 0 0"/>
      </body>
    </body>
    <body name="rocker" pos="0.4 0 0" axisangle="0 1 0 -1.6">
      <joint name="rocker_joint" ref="-1.6"/>
      <inertial pos="0.15 0 0" mass="0.8" diaginertia="0.006 0.006 0.00008"/>
      <site name="rocker_end" pos="0.3 0 0"/>
    </body>
  </worldbody>
  <equality>
    <connect name="loop" site1="coupler_end" site2="rocker_end"/>
  </equality>
</mujoco>
"""
MJCF_FREE = """<mujoco model="free">
  <include file="part.xml"/>
  <worldbody>
    <body name="torso" pos="0 0 1" quat="1 0 0.1 0">
      <freejoint name="root"/>
      <inertial pos="0 0 0" mass="5" diaginertia="0.1 0.1 0.1"/>
      <body name="arm" pos="0 0 -0.3">
        <joint name="ball" type="ball"/>
        <geom class="limb" fromto="0 0 0 0 0 -0.3"/>
      </body>
    </body>
  </worldbody>
  <equality><weld name="hold" body1="torso"/></equality>
</mujoco>
"""
MJCF_PART = """<mujoco>
  <default><default class="limb"><geom type="capsule" size="0.03" density="500"/></default>
  </default>
</mujoco>
"""
MJCF_BASES = [("arm", MJCF_ARM, None), ("fourbar", MJCF_FOURBAR, None)]
MJCF_BASES += [("free", MJCF_FREE, MJCF_PART)]


def make_mjcf_case(index: int, root: Path) -> Case:
    """Case ``index`` (from CASES on): a folder with a mutated MJCF file (and its included
    part), solved directly or from a scene file around it."""
    rng = random.Random(f"{SEED}-mjcf-{index}")
    name, text, part = rng.choice(MJCF_BASES)
    folder = root / f"case{index:04d}_mjcf_{name}"
    folder.mkdir(parents=True)
    model = folder / "model.xml"
    case = Case(index, folder, model, [f"from MJCF {name}"])
    for _ in range(rng.choice([1, 1, 2, 3])):
        if part is not None and rng.random() < 0.2:
            part, what = rng.choice(MJCF_MUTATIONS)(rng, part)
            case.mutations.append(f"part.xml: {what}")
        else:
            text, what = rng.choice(MJCF_MUTATIONS)(rng, text)
            case.mutations.append(f"model.xml: {what}")
    model.write_text(text, encoding="utf-8", errors="surrogatepass")
    if part is not None:
        (folder / "part.xml").write_text(part, encoding="utf-8", errors="surrogatepass")
    if rng.random() < 0.4:
        extra = rng.choice(["", '[start]\npose = "home"\n', "floating = true\n"])
        case.scene = folder / "scene.toml"
        case.scene.write_text(f'[model]\nmjcf = "model.xml"\n{extra}')
        case.mutations.append(f"solved from scene.toml: {extra!r}")
    return case


TOML_MUTATIONS = [
    _delete_line,
    _duplicate_line,
    _truncate,
    _insert_garbage,
    _toml_number,
    _toml_number,
    _toml_value,
    _toml_value,
    _toml_unknown_key,
    _toml_table,
]
URDF_MUTATIONS = [
    _delete_line,
    _duplicate_line,
    _truncate,
    _insert_garbage,
    _urdf_number,
    _urdf_number,
    _urdf_number,
    _urdf_axis,
    _urdf_remove_inertial,
    _urdf_missing_link,
    _urdf_cycle,
    _urdf_joint_type,
    _urdf_mimic,
    _urdf_limit,
]


def _bases() -> list[tuple[str, str]]:
    return [(p.stem, p.read_text(encoding="utf-8")) for p in sorted(ROBOTS.glob("*.toml"))]


BASES = _bases()


def make_case(index: int, root: Path) -> Case:
    """Case ``index``: a folder with a mutated scene file and its (maybe mutated) URDF."""
    rng = random.Random(f"{SEED}-{index}")
    name, toml = rng.choice(BASES)
    folder = root / f"case{index:04d}_{name}"
    folder.mkdir(parents=True)
    case = Case(index, folder, folder / "scene.toml", [f"from {name}"])
    urdf_name = None
    urdf_text = None
    match = re.search(r'^urdf\s*=\s*"([^"]*)"', toml, re.MULTILINE)
    robot = re.search(r'^robot\s*=\s*"([^"]*)"', toml, re.MULTILINE)
    if match:
        urdf_name = match.group(1)
        urdf_text = (ROBOTS / urdf_name).read_text(encoding="utf-8")
    elif robot and rng.random() < 0.5:
        # The robot's URDF as a file of the scene, to mutate it too.
        urdf_name = "robot.urdf"
        urdf_text = pinsettle.robot_urdf(robot.group(1)).read_text(encoding="utf-8")
        toml = toml.replace(robot.group(0), f'urdf = "{urdf_name}"')
        case.mutations.append(f"robot {robot.group(1)} as {urdf_name}")
    for _ in range(rng.choice([1, 1, 2, 3])):
        if urdf_text is not None and rng.random() < 0.6:
            urdf_text, what = rng.choice(URDF_MUTATIONS)(rng, urdf_text)
            case.mutations.append(f"urdf: {what}")
        else:
            toml, what = rng.choice(TOML_MUTATIONS)(rng, toml)
            case.mutations.append(f"toml: {what}")
    data = toml.encode("utf-8", errors="surrogatepass")
    if rng.random() < 0.03:  # bytes that are not UTF-8
        at = rng.randrange(len(data) + 1)
        data = data[:at] + b"\xff\xfe\xc3" + data[at:]
        case.mutations.append(f"toml: non-UTF-8 bytes at {at}")
    case.scene.write_bytes(data)
    if urdf_name is not None and urdf_text is not None:
        (folder / urdf_name).write_text(urdf_text, encoding="utf-8", errors="surrogatepass")
    return case


# The in-process run: every case through pinsettle.__main__.main in one child interpreter.
WORKER = """
import contextlib, faulthandler, io, json, sys, time, traceback
from pinsettle.__main__ import main

cases, flags, progress = json.loads(sys.argv[1]), json.loads(sys.argv[2]), sys.argv[3]
with open(progress, "w", buffering=1) as out:
    faulthandler.enable(out)
    for index, scene in cases:
        out.write(json.dumps({"start": index}) + "\\n")
        stdout, stderr = io.StringIO(), io.StringIO()
        begin = time.perf_counter()
        escaped = None
        try:
            with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
                code = main(["solve", scene, *flags])
        except SystemExit as e:
            code = e.code
        except BaseException:
            code, escaped = None, traceback.format_exc()
        out.write(json.dumps({
            "index": index, "code": code, "stderr": stderr.getvalue(), "escaped": escaped,
            "seconds": time.perf_counter() - begin,
        }) + "\\n")
"""


def _acceptable(code: object, stderr: str) -> str | None:
    """Why an outcome is not acceptable, or None: it ran (0, 1), or it ended with exit 2 and
    one line of error from pinsettle as the last thing on stderr, without a traceback."""
    if "Traceback" in stderr:
        return "a traceback"
    if code in (0, 1):
        return None
    if code != 2:
        return f"exit status {code}"
    lines = [line for line in stderr.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("pinsettle: error: ")]
    if len(errors) != 1 or lines[-1] != errors[0]:
        return f"not one line of error: {stderr!r}"
    if len(lines) != 1:
        return f"more than the error on stderr: {stderr!r}"
    return None


def _describe(case: Case, why: str) -> str:
    return f"case {case.index} ({case.folder}): {why}\n  " + "\n  ".join(case.mutations)


@pytest.fixture(scope="module")
def fuzzed(tmp_path_factory) -> list[Case]:
    root = tmp_path_factory.mktemp("fuzz")
    cases = [make_case(i, root) for i in range(CASES)]
    return cases + [make_mjcf_case(i, root) for i in range(CASES, CASES + MJCF_CASES)]


def test_mutated_files_through_the_cli_code_path(fuzzed, tmp_path):
    begin = time.perf_counter()
    progress = tmp_path / "progress.jsonl"
    cases = [(case.index, str(case.scene)) for case in fuzzed]
    try:
        proc = subprocess.run(
            [
                sys.executable,
                "-c",
                textwrap.dedent(WORKER),
                json.dumps(cases),
                json.dumps(SOLVE_FLAGS),
                str(progress),
            ],
            capture_output=True,
            text=True,
            timeout=BATCH_TIMEOUT,
        )
        returncode: int | None = proc.returncode
        worker_stderr = proc.stderr
    except subprocess.TimeoutExpired as timeout:
        returncode = None
        worker_stderr = str(timeout.stderr)
    records = [json.loads(line) for line in progress.read_text().splitlines() if line[:1] == "{"]
    started = [r["start"] for r in records if "start" in r]
    done = {r["index"]: r for r in records if "index" in r}
    if len(done) < len(fuzzed):
        last = fuzzed[started[-1]] if started else fuzzed[0]
        how = "hung (the batch timed out)" if returncode is None else f"crashed ({returncode})"
        crash = progress.read_text()[-3000:]
        pytest.fail(_describe(last, f"the process {how}\n{crash}\n{worker_stderr[-2000:]}"))
    failures = []
    for case in fuzzed:
        record = done[case.index]
        why = (
            f"an exception escaped main():\n{record['escaped']}"
            if record["escaped"]
            else _acceptable(record["code"], record["stderr"])
        )
        if why is None and record["seconds"] > CASE_BUDGET:
            why = f"took {record['seconds']:.1f} s"
        if why:
            failures.append(_describe(case, why))
    codes = [done[case.index]["code"] for case in fuzzed]
    print(
        f"{len(fuzzed)} cases in {time.perf_counter() - begin:.1f} s: "
        f"{codes.count(2)} refused (exit 2), {codes.count(0) + codes.count(1)} ran"
    )
    assert not failures, f"{len(failures)} of {len(fuzzed)} cases:\n" + "\n".join(failures[:30])
    # Both kinds are exercised: most mutations break the files, some leave them usable.
    assert codes.count(2) > len(fuzzed) // 4 and codes.count(0) + codes.count(1) > 20


def _cli(case: Case) -> tuple[Case, int | None, str]:
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "pinsettle", "solve", str(case.scene), *SOLVE_FLAGS],
            capture_output=True,
            text=True,
            timeout=PROCESS_TIMEOUT,
            env={**os.environ, "PYTHONFAULTHANDLER": "1"},
        )
    except subprocess.TimeoutExpired:
        return case, None, f"no answer in {PROCESS_TIMEOUT} s"
    return case, proc.returncode, proc.stderr


def test_a_sample_through_the_real_command_line(fuzzed):
    sample = fuzzed[::SUBPROCESS_EVERY]
    with ThreadPoolExecutor(max_workers=2) as pool:
        outcomes = list(pool.map(_cli, sample))
    failures = []
    for case, code, stderr in outcomes:
        why = "a hang: " + stderr if code is None else _acceptable(code, stderr)
        if why:
            failures.append(_describe(case, why))
    assert not failures, "\n".join(failures)
    assert len(sample) == (CASES + MJCF_CASES) // SUBPROCESS_EVERY


def test_the_cases_are_reproducible(tmp_path):
    # The same seed makes the same files: a failing case number rebuilds its files.
    a = make_case(7, tmp_path / "a")
    b = make_case(7, tmp_path / "b")
    assert a.mutations == b.mutations
    assert a.scene.read_bytes() == b.scene.read_bytes()


@pytest.mark.parametrize(
    "old, new, why",
    [
        ('<mass value="1.0"/>', '<mass value="nan"/>', "mass [nan] is not a float"),
        ('ixx="1e-3"', 'ixx="abc"', "ixx is not a valid double"),
        (
            '<origin xyz="0 0 -1" rpy="0 0 0"/>\n      <mass',
            '<origin xyz="0 -1" rpy="0 0 0"/>\n      <mass',
            "2 elements",
        ),
    ],
)
def test_an_element_the_urdf_parser_drops_is_an_error(tmp_path, old, new, why):
    # urdfdom reports an inertial it cannot read and drops it, and Pinocchio builds the model
    # anyway (the bob without its mass): found by the fuzzing above, where such a file was
    # solved as another mechanism or refused for a "singular mass matrix" instead.
    text = (ROBOTS / "pendulum.urdf").read_text(encoding="utf-8")
    assert text.count(old) == 1
    urdf = tmp_path / "pendulum.urdf"
    urdf.write_text(text.replace(old, new), encoding="utf-8")
    with pytest.raises(ValueError, match="the URDF does not parse") as error:
        pinsettle.load_urdf(urdf)
    assert why in str(error.value) and "Could not parse inertial element for Link [arm]" in str(
        error.value
    )
    scene = tmp_path / "scene.toml"
    scene.write_text('[model]\nurdf = "pendulum.urdf"\n', encoding="utf-8")
    proc = subprocess.run(
        [sys.executable, "-m", "pinsettle", "solve", str(scene)],
        capture_output=True,
        text=True,
        timeout=PROCESS_TIMEOUT,
    )
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and why in proc.stderr, proc.stderr

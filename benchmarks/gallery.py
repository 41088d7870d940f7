"""The robot gallery of the benchmark report: every robot of example-robot-data that
``pinsettle robots`` lists, root fixed, released at rest from neutral with the default settings,
side by side with MuJoCo's damped settle of the same URDF (issue 18's gallery, issue 20's goal 3:
one harness); and the floating-base robots with their free-flyer, which fall.

Both answers are checked with the same independent physics (tests/scene_reference.py: the
conditions of a rest against stops recomputed from Pinocchio's generalized gravity), nothing of
pinsettle's.

MuJoCo (``pip install ".[bench]"``, never needed to install or test pinsettle) loads the URDF with
its visual and collision elements removed (no meshes, no contacts) and its ``<mimic>`` tags too
(MuJoCo would couple the joints by an equality; pinsettle's model of the robot, like
``pinocchio.buildModelFromUrdf`` by default, moves them freely: the Panda's and Baxter's
fingers, Talos' grippers), so that both settle the same mechanism; it honours the URDF's position
limits as it does by default (a joint whose limits are equal has none, as in pinsettle), and
steps it as its users let a robot settle: joint damping MUJOCO_DAMPING on every degree of freedom
and a MUJOCO_TIMESTEP step, its default (Euler) integrator, from qpos = 0 (pinsettle's neutral).
It has *settled* once max |qvel| <= MUJOCO_QVEL and max |qacc| <= MUJOCO_QACC at every check
(every MUJOCO_CHUNK steps) for MUJOCO_QUIET s of simulated time in a row; its wall time is then
that of stepping the same number of steps again in one ``mj_step(model, data, nstep)`` call (no
checks, no Python between steps: MuJoCo is charged nothing but its steps).
"""

from __future__ import annotations

import math
import statistics
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio
import pinsettle
from independent import VERDICT_TOLERANCE, CachedReference
from report_data import (
    GALLERY_KD_REPEATS,
    GALLERY_MAX_TIME,
    MUJOCO_CHUNK,
    MUJOCO_DAMPING,
    MUJOCO_QACC,
    MUJOCO_QUIET,
    MUJOCO_QVEL,
    MUJOCO_TIMESTEP,
    REPEAT_BUDGET,
)

try:  # optional: the bench extra
    import mujoco
except ImportError:  # pragma: no cover - reported in the gallery
    mujoco = None

MISSING = "mujoco is not installed (pip install '.[bench]')"


def mujoco_info() -> dict[str, Any]:
    if mujoco is None:
        return {"missing": MISSING}
    return {"version": mujoco.__version__}


def is_floating(name: str) -> bool:
    """Whether pinsettle gives the robot a free-flyer root by default."""
    return bool(pinsettle.load_robot(name).joints[1].shortname() == "JointModelFreeFlyer")


# --- pinsettle --------------------------------------------------------------------------------


def _solves(model: pinocchio.Model, repeats: int) -> list[pinsettle.Result]:
    """Up to max(repeats, GALLERY_KD_REPEATS) default solves (no more once they took
    REPEAT_BUDGET)."""
    repeats = max(repeats, GALLERY_KD_REPEATS)
    solves = [pinsettle.solve(model, max_time=GALLERY_MAX_TIME)]
    while len(solves) < repeats and sum(r.wall_time for r in solves) < REPEAT_BUDGET:
        solves.append(pinsettle.solve(model, max_time=GALLERY_MAX_TIME))
    return solves


def rest_check(ref: CachedReference, q: np.ndarray) -> dict[str, Any]:
    """The conditions of a rest against the URDF's stops at q, recomputed independently: the
    largest violation (N m or N), the joints on a stop, and how far the worst joint is outside
    its limits (rad or m; 0 inside)."""
    model = ref.full
    force = ref.force_reduced(model, q)
    violation, contacts, _ = ref.rest_conditions(model, q, force)
    outside = 0.0
    for name, (low, high) in ref.stops(model).items():
        x = q[model.idx_qs[model.getJointId(name)]]
        outside = max(outside, low - x, x - high)
    return {
        "residual": float(np.max(violation)) if violation.size else 0.0,
        "contacts": {name: side for name, (side, _) in contacts.items()},
        "outside": outside,
        "stability": verdict(ref, q, force, contacts),
    }


def verdict(
    ref: CachedReference, q: np.ndarray, force: np.ndarray, contacts: dict[str, Any]
) -> str:
    """Stable, neutral or unstable at q: the eigenvalues of the symmetric part of the
    central-difference stiffness of the independent force, restricted to the joints not pressed
    on a stop (a reaction within 1e-9 of the largest static force counts as free)."""
    model = ref.full
    pressed = {
        model.idx_vs[model.getJointId(name)]
        for name, (_, reaction) in contacts.items()
        if reaction > 1e-9 * max(float(np.max(np.abs(force), initial=0.0)), 1e-300)
    }
    free = [i for i in range(model.nv) if i not in pressed]
    if not free:
        return "stable"
    h = 1e-6
    K = np.empty((model.nv, len(free)))
    for k, i in enumerate(free):
        e = np.zeros(model.nv)
        e[i] = h
        plus = ref.force_reduced(model, pinocchio.integrate(model, q, e))
        minus = ref.force_reduced(model, pinocchio.integrate(model, q, -e))
        K[:, k] = (plus - minus) / (2 * h)
    K = K[free]
    w = np.linalg.eigvalsh(0.5 * (K + K.T))
    tol = VERDICT_TOLERANCE * max(float(np.max(np.abs(w))), 1e-300)
    if w[0] < -tol:
        return "unstable"
    return "neutral" if np.any(np.abs(w) <= tol) else "stable"


def distance(model: pinocchio.Model, qa: np.ndarray, qb: np.ndarray) -> float:
    """max |qb - qa| on the tangent, revolute angles modulo 2 pi."""
    d = pinocchio.difference(model, qa, qb)
    for j in range(1, model.njoints):
        if model.nvs[j] == 1 and model.joints[j].shortname().startswith("JointModelR"):
            i = model.idx_vs[j]
            d[i] = math.remainder(d[i], 2 * math.pi)
    return float(np.max(np.abs(d))) if d.size else 0.0


# --- MuJoCo -----------------------------------------------------------------------------------


def stripped_urdf(path: Path) -> str:
    """The URDF without its visual and collision elements (no meshes, no contacts) and without
    its <mimic> tags, compiled by MuJoCo with its visuals discarded and fixed links kept as
    bodies."""
    root = ET.parse(path).getroot()
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
    for joint in root.iter("joint"):  # see the top of the file
        for element in joint.findall("mimic"):
            joint.remove(element)
    for element in root.findall("mujoco"):
        root.remove(element)
    extension = ET.SubElement(root, "mujoco")
    ET.SubElement(extension, "compiler", discardvisual="true", fusestatic="false")
    return ET.tostring(root, encoding="unicode")


def load_mujoco(path: Path) -> tuple[object | None, str, list[str]]:
    """(model or None, why not, MuJoCo's warnings)."""
    warnings: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda text: warnings.append(str(text).strip()))
    try:
        model = mujoco.MjModel.from_xml_string(stripped_urdf(path))
    except ValueError as e:
        lines = [line.strip() for line in str(e).splitlines() if line.strip()]
        return None, "; ".join(lines), warnings
    finally:
        mujoco.set_mju_user_warning(previous)
    model.dof_damping[:] = MUJOCO_DAMPING
    model.opt.timestep = MUJOCO_TIMESTEP
    return model, "", warnings


def mujoco_q(mj_model: Any, qpos: np.ndarray, model: pinocchio.Model) -> np.ndarray:
    """MuJoCo's hinge and slide joints by name into a Pinocchio configuration."""
    q: np.ndarray = pinocchio.neutral(model)
    seen = set()
    for j in range(mj_model.njnt):
        name = mj_model.joint(j).name
        value = float(qpos[mj_model.jnt_qposadr[j]])
        jid = model.getJointId(name)
        if jid >= model.njoints:
            raise RuntimeError(f"MuJoCo's joint {name!r} is not in the Pinocchio model")
        iq = model.idx_qs[jid]
        if model.nqs[jid] == 2:  # continuous: (cos, sin)
            q[iq : iq + 2] = [math.cos(value), math.sin(value)]
        else:
            q[iq] = value
        seen.add(name)
    missing = [model.names[j] for j in range(1, model.njoints) if model.names[j] not in seen]
    if missing:
        raise RuntimeError(f"joints MuJoCo does not have: {', '.join(missing)}")
    return q


def mujoco_settle(path: Path, max_sim: float, repeats: int) -> dict[str, Any]:
    """MuJoCo's damped settle of the URDF (see the top of the file)."""
    if mujoco is None:
        return {"status": "not installed", "reason": MISSING}
    mj_model, why, warnings = load_mujoco(path)
    if mj_model is None:
        return {"status": "cannot load", "reason": why, "warnings": warnings}
    data = mujoco.MjData(mj_model)
    needed = math.ceil(MUJOCO_QUIET / (MUJOCO_TIMESTEP * MUJOCO_CHUNK))
    max_steps = int(round(max_sim / MUJOCO_TIMESTEP))
    steps, quiet, status = 0, 0, "not settled"
    began = time.perf_counter()
    while steps < max_steps:
        mujoco.mj_step(mj_model, data, nstep=MUJOCO_CHUNK)
        steps += MUJOCO_CHUNK
        if not (np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))):
            status = "diverged"
            break
        if (
            np.max(np.abs(data.qvel), initial=0.0) <= MUJOCO_QVEL
            and np.max(np.abs(data.qacc), initial=0.0) <= MUJOCO_QACC
        ):
            quiet += 1
            if quiet >= needed:
                status = "settled"
                break
        else:
            quiet = 0
    detection = time.perf_counter() - began
    qpos = data.qpos.copy()
    out = {
        "status": status,
        "steps": steps,
        "sim_time": steps * MUJOCO_TIMESTEP,
        "qpos": qpos,
        "max_qvel": float(np.max(np.abs(data.qvel), initial=0.0)),
        "detection_seconds": detection,
        "warnings": warnings,
        "model": mj_model,
    }
    if status != "settled":
        out["seconds"] = [detection]
        return out
    # The same steps again, timed alone (the trajectory is deterministic: checked).
    seconds: list[float] = []
    while not seconds or (len(seconds) < repeats and sum(seconds) < REPEAT_BUDGET):
        mujoco.mj_resetData(mj_model, data)
        began = time.perf_counter()
        mujoco.mj_step(mj_model, data, nstep=steps)
        seconds.append(time.perf_counter() - began)
        if not np.array_equal(data.qpos, qpos):
            raise RuntimeError(f"{path.name}: MuJoCo's timed run took another path")
    out["seconds"] = seconds
    return out


# --- one robot ----------------------------------------------------------------------------------


def measure_robot(name: str, repeats: int, mujoco_max_sim: float) -> dict[str, Any]:
    """pinsettle (default settings, root fixed) and MuJoCo on one robot, both checked with the
    independent rest conditions."""
    urdf = pinsettle.robot_urdf(name)
    model = pinsettle.load_robot(name, floating=False)
    solves = _solves(model, repeats)
    r = solves[-1]
    ref = CachedReference(pinocchio.buildModelFromUrdf(str(urdf)))
    if list(ref.full.names) != list(model.names):
        raise RuntimeError(f"{name}: the reference's joints differ from the solver's model")
    # The force scale: the largest static force at the start, moved into the limits.
    q0 = pinocchio.neutral(ref.full)
    for joint, (low, high) in ref.stops(ref.full).items():
        iq = ref.full.idx_qs[ref.full.getJointId(joint)]
        q0[iq] = min(max(q0[iq], low), high)
    scale = float(np.max(np.abs(ref.force_reduced(ref.full, q0)), initial=0.0))
    kd = rest_check(ref, r.q)
    row = {
        "name": name,
        "nv": model.nv,
        "status": r.status,
        "steps": r.steps,
        "seconds": [s.wall_time for s in solves],
        "stability": r.stability,
        "at_limit": dict(r.at_limit),
        "start_clamped": dict(r.start_clamped),
        "equal_limits": list(r.equal_limits),
        "solver_residual": r.residual,
        "residual": kd["residual"],
        "contacts": kd["contacts"],
        "outside": kd["outside"],
        "verdict": kd["stability"],
        "force_scale": scale,
    }
    settle = mujoco_settle(urdf, mujoco_max_sim, repeats)
    mj_model = settle.pop("model", None)
    if "qpos" in settle:
        q_mj = mujoco_q(mj_model, settle.pop("qpos"), ref.full)
        check = rest_check(ref, q_mj)
        settle |= {
            "residual": check["residual"],
            "contacts": check["contacts"],
            "outside": check["outside"],
            "stability": check["stability"],
            "distance": distance(ref.full, r.q, q_mj),
        }
    row["mujoco"] = settle
    return row


def measure_floating(name: str, repeats: int) -> dict[str, Any]:
    """The robot with its free-flyer root and the default settings: it falls."""
    model = pinsettle.load_robot(name, floating=True)
    solves = _solves(model, repeats)
    r = solves[-1]
    return {
        "name": name,
        "nv": model.nv,
        "status": r.status,
        "reason": r.reason,
        "steps": r.steps,
        "seconds": [s.wall_time for s in solves],
        "median": statistics.median(s.wall_time for s in solves),
    }

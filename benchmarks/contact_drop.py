"""The contact part of the benchmark report: go1 dropped on a floor (the library scenes
robots/go1_standing.toml and robots/go1_motors_off.toml), pinsettle's solve against MuJoCo
stepping the same model to rest, at its best over a sweep of its time step, integrator and
joint damping; and the cost of one of pinsettle's steps on the contacts against a free one.

MuJoCo (``pip install ".[bench]"``, never needed to install or test pinsettle) loads the scene's
URDF without its visual and collision elements (``stripped_urdf``); a link whose inertia matrix
is not positive definite (go1's ``base``: 1e-6 kg m^2 in every entry) keeps its mass with its
products of inertia dropped, which MuJoCo refuses otherwise (a rest depends on the masses and
their centres only). The scene is then added with MjSpec edits: a free joint on the root body,
the ground as a plane of the scene's friction, each contact point as a sphere of its radius at
its frame (a point, radius 0, as a sphere of POINT_RADIUS: its own gap is the sphere's distance
plus that radius), the only geoms that collide (each sphere with the floor only), the joint
springs as joint stiffness with springref at their rest angle, the URDF's joint damping and
friction loss replaced by the swept damping and none, its joint limits kept (pinsettle's stops).
``model_check`` compares it with pinocchio's model at the start: total mass, joint axes, contact
centres and centre of mass.

MuJoCo is *at rest* once its static residual ``max |qfrc_bias - qfrc_spring - qfrc_constraint|``
(gravity against springs, contacts and limits; qfrc_bias also holds the velocity products, of
order m v^2 at rest) is at most LEVEL times the weight and ``max |qvel|`` at most MUJOCO_QVEL
(the gallery's), at every check (every MUJOCO_CHUNK steps, after ``mj_forward`` of the state
reached) for MUJOCO_QUIET s of simulated time in a row. Its time to rest is that of the steps
to the first check of that stretch (the stretch only confirms it), stepped again in one
``mj_step(model, data, nstep)`` call and checked to reach the same state, timed in rounds
interleaved with pinsettle's warm solves (``Solver.solve`` of a solver made once), medians.
MuJoCo *at its best* is the setting at rest on the floor (its centre of mass above it) in the
least time; a rest below the floor (the trunk fell between the legs, which touch the floor only
at their contact points, and hangs from the feet) is another answer, listed apart.
"""

from __future__ import annotations

import math
import statistics
import time
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio
import pinsettle
from report_data import MUJOCO_CHUNK, MUJOCO_QUIET, MUJOCO_QVEL
from report_format import fmt_time, table

try:  # optional: the bench extra
    import mujoco
except ImportError:  # pragma: no cover - reported in the section
    mujoco = None

Record = dict[str, Any]
MISSING = "mujoco is not installed (pip install '.[bench]')"

SCENES = ("go1_standing", "go1_motors_off")
#: MuJoCo is at rest once its static residual is at most LEVEL times the weight (see the top).
LEVEL = 1e-6
#: The radius (m) of MuJoCo's sphere for a contact point of radius 0.
POINT_RADIUS = 1e-4
#: pinsettle's rest: a closed contact's gap is within this (m; docs/contacts.md).
GAP_TOLERANCE = 1e-6
INTEGRATORS = ("Euler", "implicitfast", "implicit")
#: pinsettle's solves in each timed round (they take milliseconds; MuJoCo's runs up to seconds).
OURS_PER_ROUND = 5


@dataclass(frozen=True)
class Sweep:
    """MuJoCo's settings tried on each scene (every combination), its budget, the timed
    repeats, and the step counts of the step-cost runs."""

    timesteps: tuple[float, ...] = (5e-4, 1e-3, 2e-3, 5e-3, 1e-2)
    integrators: tuple[str, ...] = INTEGRATORS
    dampings: tuple[float, ...] = (0.01, 0.1, 1.0, 10.0)
    max_sim: float = 60.0  # simulated seconds
    repeats: int = 3
    scenes: tuple[str, ...] = SCENES
    cost_steps: tuple[int, int] = (1000, 4000)
    cost_repeats: int = 5


FULL = Sweep()
QUICK = Sweep(
    timesteps=(2e-3,),
    integrators=("implicitfast",),
    dampings=(1.0, 10.0),
    max_sim=20.0,
    repeats=3,
    scenes=("go1_standing",),
    cost_steps=(200, 800),
    cost_repeats=3,
)


def mujoco_info() -> Record:
    if mujoco is None:
        return {"missing": MISSING}
    return {"version": mujoco.__version__}


# --- the MuJoCo model ----------------------------------------------------------------------------


def _positive_definite(inertia: ET.Element) -> bool:
    a = {k: float(inertia.get(k, "0")) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
    matrix = np.array(
        [
            [a["ixx"], a["ixy"], a["ixz"]],
            [a["ixy"], a["iyy"], a["iyz"]],
            [a["ixz"], a["iyz"], a["izz"]],
        ]
    )
    return bool(np.linalg.eigvalsh(matrix)[0] > 0)


def stripped_urdf(path: Path) -> tuple[str, list[str]]:
    """The URDF without visual and collision elements, its inertia matrices that are not
    positive definite reduced to their diagonals (links of positive mass), fixed links kept as
    bodies; and the names of the links so changed."""
    root = ET.parse(path).getroot()
    changed = []
    for link in root.iter("link"):
        for tag in ("visual", "collision"):
            for element in link.findall(tag):
                link.remove(element)
        inertia, mass = link.find("inertial/inertia"), link.find("inertial/mass")
        if inertia is None or mass is None or not float(mass.get("value", "0")) > 0:
            continue
        if not _positive_definite(inertia):
            for key in ("ixy", "ixz", "iyz"):
                inertia.set(key, "0")
            changed.append(str(link.get("name")))
    for element in root.findall("mujoco"):
        root.remove(element)
    extension = ET.SubElement(root, "mujoco")
    ET.SubElement(extension, "compiler", discardvisual="true", fusestatic="false")
    return ET.tostring(root, encoding="unicode"), changed


def _check_scene(scene: pinsettle.Scene) -> None:
    """What this MuJoCo model holds: a URDF robot on a free root, joint springs, grounds and
    contact points; anything else is refused rather than left out."""
    if scene.urdf is None or scene.model.joints[1].shortname() != "JointModelFreeFlyer":
        raise ValueError(f"{scene.name}: needs a URDF robot with a free-flyer root")
    extra = [
        kind
        for kind, items in (
            ("springs", scene.springs),
            ("loads", scene.loads),
            ("loops", scene.loops),
            ("locked", scene.locked),
            ("couplings", scene.couplings),
            ("joint_limits", scene.joint_limits),
        )
        if items
    ]
    if extra or len(scene.grounds) != 1 or not scene.contacts:
        raise ValueError(
            f"{scene.name}: MuJoCo's model takes one ground, contacts and joint springs; "
            f"the scene has {', '.join(extra) or f'{len(scene.grounds)} grounds'}"
        )


def _add_floor(spec: Any, ground: Any) -> None:
    quat = np.zeros(4)
    mujoco.mju_quatZ2Vec(quat, np.array(ground.normal, dtype=float))
    spec.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0.0, 0.0, 1.0],
        pos=list(ground.point),
        quat=list(quat),
        friction=[ground.friction, 0.0, 0.0],
        contype=0,
        conaffinity=1,
    )


def _add_contacts(spec: Any, scene: pinsettle.Scene) -> None:
    friction = scene.grounds[0].friction
    for c in scene.contacts:
        body = spec.body(c.frame)
        if body is None:
            raise ValueError(f"{scene.name}: contact {c.name!r}: no MuJoCo body {c.frame!r}")
        body.add_geom(
            name=c.name,
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[c.radius if c.radius > 0 else POINT_RADIUS, 0.0, 0.0],
            pos=list(c.point),
            friction=[friction, 0.0, 0.0],
            contype=1,
            conaffinity=0,
            density=0.0,
        )


def _linear(value: float, like: Any) -> Any:
    """A joint's stiffness or damping as MjSpec takes it: a number (MuJoCo 3) or a polynomial's
    coefficients, linear first (MuJoCo 4)."""
    return [value, *([0.0] * (len(like) - 1))] if np.ndim(like) else value


def mujoco_model(scene: pinsettle.Scene) -> tuple[Any, list[str]]:
    """MuJoCo's model of the scene (see the top of the file) and the links whose inertia was
    reduced to its diagonal."""
    _check_scene(scene)
    xml, changed = stripped_urdf(Path(str(scene.urdf)))
    spec = mujoco.MjSpec.from_string(xml)
    spec.worldbody.first_body().add_freejoint(name=scene.model.names[1])
    _add_floor(spec, scene.grounds[0])
    _add_contacts(spec, scene)
    for joint in spec.joints:
        joint.frictionloss = 0.0
        joint.damping = _linear(0.0, joint.damping)  # the swept damping is set when compiled
        if not scene.limits:
            joint.limited = mujoco.mjtLimited.mjLIMITED_FALSE
    for s in scene.joint_springs:
        joint = spec.joint(s.joint)
        joint.stiffness = _linear(s.stiffness, joint.stiffness)
        joint.springref = s.rest
        joint.damping = _linear(s.damping, joint.damping)
    return spec.compile(), changed


def mujoco_qpos(mj: Any, model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
    """A Pinocchio configuration as MuJoCo's qpos, joints by name (quaternions w first)."""
    qpos = np.zeros(mj.nq)
    for j in range(mj.njnt):
        name, adr = mj.joint(j).name, mj.jnt_qposadr[j]
        jid = model.getJointId(name)
        if jid >= model.njoints:
            raise RuntimeError(f"MuJoCo's joint {name!r} is not in the Pinocchio model")
        iq = model.idx_qs[jid]
        if mj.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            qpos[adr : adr + 3] = q[iq : iq + 3]
            qpos[adr + 3] = q[iq + 6]
            qpos[adr + 4 : adr + 7] = q[iq + 3 : iq + 6]
        elif model.nqs[jid] == 2:  # continuous: (cos, sin)
            qpos[adr] = math.atan2(q[iq + 1], q[iq])
        else:
            qpos[adr] = q[iq]
    return qpos


def model_check(mj: Any, scene: pinsettle.Scene) -> Record:
    """MuJoCo's model against pinocchio's at the scene's start: total masses, the largest
    difference of a joint's axis in world axes, of a contact centre (m) and of the centre of
    mass (m)."""
    model = scene.model
    data = model.createData()
    q = scene.q0()
    d = mujoco.MjData(mj)
    d.qpos[:] = mujoco_qpos(mj, model, q)
    mujoco.mj_forward(mj, d)
    pinocchio.computeJointJacobians(model, data, q)
    pinocchio.framesForwardKinematics(model, data, q)
    axis = 0.0
    for j in range(mj.njnt):
        if mj.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
            continue
        jid = model.getJointId(mj.joint(j).name)
        J = pinocchio.getJointJacobian(model, data, jid, pinocchio.LOCAL_WORLD_ALIGNED)
        axis = max(axis, float(np.max(np.abs(J[3:, model.idx_vs[jid]] - d.xaxis[j]))))
    centre = 0.0
    for c in scene.contacts:
        ours = data.oMf[model.getFrameId(c.frame)].act(np.array(c.point, dtype=float))
        centre = max(centre, float(np.max(np.abs(ours - d.geom(c.name).xpos))))
    com = pinocchio.centerOfMass(model, data, q)
    spring = 0.0
    for sp in scene.joint_springs:
        j = mj.joint(sp.joint).id
        k, rest = mj.jnt_stiffness[j], mj.qpos_spring[mj.jnt_qposadr[j]]
        spring = max(spring, abs(k - sp.stiffness) / sp.stiffness, abs(rest - sp.rest))
    return {
        "mass_mujoco": float(np.sum(mj.body_mass)),
        "mass_pinocchio": float(pinocchio.computeTotalMass(model)),
        "axis": axis,
        "contact_centre": centre,
        "com": float(np.max(np.abs(com - d.subtree_com[0]))),
        "springs": len(scene.joint_springs),
        "spring": float(spring),  # stiffness (relative) or rest (rad), the larger
        "hinges": int(np.sum(mj.jnt_type == mujoco.mjtJoint.mjJNT_HINGE)),
        "joints_pinocchio": model.njoints - 2,  # less the universe and the free root
    }


def weight(scene: pinsettle.Scene) -> float:
    """m |g| from pinocchio's model (N)."""
    model = scene.model
    return float(pinocchio.computeTotalMass(model) * np.linalg.norm(model.gravity.linear))


# --- MuJoCo's settle ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Setting:
    timestep: float
    integrator: str
    damping: float

    def label(self) -> str:
        return f"{self.timestep * 1e3:g} ms, {self.integrator}, damping {self.damping:g}"


def configure(mj: Any, setting: Setting, spring_damping: np.ndarray) -> None:
    """The setting on the compiled model: step, integrator, damping on every degree of
    freedom (on top of the springs' own)."""
    mj.opt.timestep = setting.timestep
    mj.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{setting.integrator.upper()}")
    mj.dof_damping[:] = spring_damping + setting.damping


def static_residual(d: Any) -> float:
    """max |qfrc_bias - qfrc_spring - qfrc_constraint| after mj_forward (N or N m)."""
    return float(np.max(np.abs(d.qfrc_bias - d.qfrc_spring - d.qfrc_constraint)))


def contact_state(mj: Any, d: Any) -> tuple[float, float, float]:
    """(the deepest penetration of a contact point, m; the sum of the contact normal forces, N;
    the largest ratio of a contact's tangential force to its normal force) of MuJoCo's active
    contacts after mj_forward. A point's sphere (POINT_RADIUS) counts from its centre."""
    deepest, normal, shear = -math.inf, 0.0, 0.0
    force = np.zeros(6)
    for i in range(d.ncon):
        contact = d.contact[i]
        sphere = contact.geom[1] if contact.geom[0] == mj.geom("floor").id else contact.geom[0]
        radius = float(mj.geom_size[sphere][0])
        point = contact.dist + (radius if radius == POINT_RADIUS else 0.0)
        deepest = max(deepest, -point)
        mujoco.mj_contactForce(mj, d, i, force)
        normal += float(force[0])
        shear = max(shear, float(np.linalg.norm(force[1:3]) / max(force[0], 1e-300)))
    return deepest, normal, shear


def rest_state(mj: Any, d: Any, w: float) -> Record:
    """What a rest of MuJoCo's is, after mj_forward: its state, contacts, the root's height and
    the centre of mass's height above the floor (m; below it, < 0, the trunk fell between the
    legs, which only touch the floor at their contact points)."""
    penetration, normal, shear = contact_state(mj, d)
    floor = mj.geom("floor").id
    n = d.geom_xmat[floor].reshape(3, 3)[:, 2]
    return {
        "qpos": d.qpos.copy(),
        "max_qvel": float(np.max(np.abs(d.qvel))),
        "penetration": penetration,
        "normal_force": normal / w,
        "shear": shear,
        "height": float(d.qpos[2]),
        "com_height": float(n @ (d.subtree_com[0] - d.geom_xpos[floor])),
    }


def _broke(d: Any) -> bool:
    """MuJoCo blew up: a non-finite state or a bad acceleration it reset the data for."""
    bad = d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0
    return bool(bad or not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))))


def settle(mj: Any, qpos0: np.ndarray, setting: Setting, max_sim: float, w: float) -> Record:
    """MuJoCo stepped from qpos0 at rest until it is at rest (see the top of the file), it
    blows up, or max_sim simulated seconds."""
    d = mujoco.MjData(mj)
    d.qpos[:] = qpos0
    max_steps = int(round(max_sim / setting.timestep))
    needed = math.ceil(MUJOCO_QUIET / setting.timestep)
    steps, status, rest = 0, "not at rest", None
    residual = qvel = math.inf
    while steps < max_steps:
        mujoco.mj_step(mj, d, nstep=MUJOCO_CHUNK)
        steps += MUJOCO_CHUNK
        if _broke(d):
            status, rest = "diverged", None
            break
        mujoco.mj_forward(mj, d)  # the forces of the state reached
        residual, qvel = static_residual(d), float(np.max(np.abs(d.qvel)))
        if not (residual <= LEVEL * w and qvel <= MUJOCO_QVEL):
            rest = None
            continue
        if rest is None:
            rest = rest_state(mj, d, w) | {"steps": steps, "residual": residual / w}
        if steps - rest["steps"] >= needed:
            status = "at rest"
            break
    out: Record = asdict(setting) | {"status": status, "checked_steps": steps}
    out |= {"last_residual": residual / w, "last_qvel": qvel}
    if status == "at rest" and rest is not None:
        out |= rest | {"sim_time": rest["steps"] * setting.timestep, "seconds": []}
    return out


def time_mujoco(m: Mujoco, d: Any, run: Record) -> float:
    """One timed mj_step over the run's steps to rest, checked to reach the same state."""
    setting = Setting(run["timestep"], run["integrator"], run["damping"])
    configure(m.model, setting, m.spring_damping)
    mujoco.mj_resetData(m.model, d)
    d.qpos[:] = m.qpos0
    began = time.perf_counter()
    mujoco.mj_step(m.model, d, nstep=run["steps"])
    seconds = time.perf_counter() - began
    if not np.array_equal(d.qpos, run["qpos"]):
        raise RuntimeError(f"MuJoCo's timed run ({setting.label()}) took another path")
    return seconds


# --- pinsettle ------------------------------------------------------------------------------------


def independent_gaps(scene: pinsettle.Scene, q: np.ndarray) -> list[float]:
    """Each contact point's gap to the scene's ground at q (m), from Pinocchio's frames."""
    model = scene.model
    data = model.createData()
    pinocchio.framesForwardKinematics(model, data, q)
    ground = scene.grounds[0]
    n, o = np.array(ground.normal, dtype=float), np.array(ground.point, dtype=float)
    gaps = []
    for c in scene.contacts:
        centre = data.oMf[model.getFrameId(c.frame)].act(np.array(c.point, dtype=float))
        gaps.append(float(n @ (centre - o) - c.radius))
    return gaps


def ours_record(scene: pinsettle.Scene, r: pinsettle.Result, w: float) -> Record:
    """pinsettle's rest, checked: gaps recomputed with Pinocchio, the floor's normal forces
    summed against the weight."""
    shear = max(
        (float(np.linalg.norm(c.tangential_force)) / c.normal_force for c in r.contacts),
        default=0.0,
    )
    ground = scene.grounds[0]
    com = pinocchio.centerOfMass(scene.model, scene.model.createData(), r.q)
    com_height = float(np.array(ground.normal) @ (com - np.array(ground.point)))
    return {
        "status": r.status,
        "stability": r.stability,
        "steps": r.steps,
        "residual": r.residual / w,
        "gaps": independent_gaps(scene, r.q),
        "closed": len(r.contacts),
        "normal_force": sum(c.normal_force for c in r.contacts) / w,
        "shear": shear,
        "height": float(r.q[2]),
        "com_height": com_height,
        "seconds": [],
        "wall_times": [],
    }


# --- the cost of a step ---------------------------------------------------------------------------


def _falling(scene: pinsettle.Scene, depth: float) -> pinsettle.Scene:
    """The scene's robot, springs and contacts with its floor ``depth`` (m) below: it falls
    free, the contacts checked at every step, none closing. (Without a ground pinsettle refuses
    it at once: nothing would hold its root.)"""
    other = pinsettle.Scene.from_urdf(Path(str(scene.urdf)), floating=True, limits=scene.limits)
    if list(other.model.names) != list(scene.model.names):
        raise RuntimeError(f"{scene.name}: the URDF's model differs from the scene's")
    for s in scene.joint_springs:
        other.add_joint_spring(s.joint, s.stiffness, s.rest, s.damping)
    g = scene.grounds[0]
    other.add_ground((0.0, 0.0, -depth), g.normal, g.friction, name=g.name)
    for c in scene.contacts:
        other.add_contact(c.frame, c.point, c.radius, name=c.name)
    return other


def step_cost(scene: pinsettle.Scene, rest: pinsettle.Result, sweep: Sweep) -> Record:
    """pinsettle's time per step from its rest, at the rest's final step (fixed), with no
    polish, no Newton and max_e = 0 (the run goes on to its step budget): resting on its
    contacts (the scene itself) and falling free (``_falling``, the floor twice the longest
    run's fall below). Per step: the difference of the wall times of two step budgets over the
    difference of their steps (the set-up and the final assessment cancel), medians of
    interleaved repeats."""
    fall = 0.5 * float(np.linalg.norm(scene.gravity)) * (max(sweep.cost_steps) * rest.dt) ** 2
    variants = {"resting": scene, "free": _falling(scene, max(2 * fall, 1e3))}
    settings: Record = {"dt": rest.dt, "max_e": 0.0, "polish": False, "newton_takeover": False}
    solvers = {
        (key, n): pinsettle.Solver(s, max_steps=n, **settings)
        for key, s in variants.items()
        for n in sweep.cost_steps
    }
    per_step: dict[str, list[float]] = {key: [] for key in variants}
    record: Record = {"dt": rest.dt, "steps": list(sweep.cost_steps), "fall": fall}
    for _ in range(sweep.cost_repeats):
        for key in variants:
            short, long = (solvers[key, n].solve(rest.q) for n in sweep.cost_steps)
            if (short.status, long.status) != ("max_steps", "max_steps"):
                raise RuntimeError(f"{scene.name}, {key}: ended {long.status} before its budget")
            per_step[key].append((long.wall_time - short.wall_time) / (long.steps - short.steps))
            record[f"{key}_closed"] = len(long.contacts)
            record[f"{key}_peaks"] = long.peaks
    return record | {key: statistics.median(v) for key, v in per_step.items()}


# --- one scene ------------------------------------------------------------------------------------


def sweep_settings(sweep: Sweep) -> list[Setting]:
    return [
        Setting(dt, integrator, damping)
        for integrator in sweep.integrators
        for damping in sweep.dampings
        for dt in sweep.timesteps
    ]


@dataclass
class Mujoco:
    """MuJoCo's model of a scene, its joint springs' own damping and the scene's start."""

    model: Any
    spring_damping: np.ndarray
    qpos0: np.ndarray


def mujoco_runs(
    scene: pinsettle.Scene, sweep: Sweep, w: float
) -> tuple[Mujoco, Record, list[Record]]:
    """MuJoCo's model of the scene, its check, and its settle with every setting of the sweep
    (MuJoCo's warnings silenced: a run that blows up is told by its state)."""
    mj, changed = mujoco_model(scene)
    check = model_check(mj, scene) | {"diagonal_inertia": changed}
    m = Mujoco(mj, mj.dof_damping.copy(), mujoco_qpos(mj, scene.model, scene.q0()))
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda text: None)
    try:
        runs = []
        for setting in sweep_settings(sweep):
            configure(mj, setting, m.spring_damping)
            runs.append(settle(mj, m.qpos0, setting, sweep.max_sim, w))
    finally:
        mujoco.set_mju_user_warning(previous)
    return m, check, runs


def timed_rounds(
    scene: pinsettle.Scene, m: Mujoco | None, runs: list[Record], ours: Record, sweep: Sweep
) -> None:
    """Rounds of pinsettle's warm solve then each MuJoCo run at rest stepped again, so that a
    slow moment of the shared machine falls on both."""
    solver = pinsettle.Solver(scene)
    solver.solve()  # warm: the caches, and anything made on the first call
    at_rest = [run for run in runs if run["status"] == "at rest"]
    d = None if m is None else mujoco.MjData(m.model)
    for _ in range(sweep.repeats):
        for _ in range(OURS_PER_ROUND):
            began = time.perf_counter()
            r = solver.solve()
            ours["seconds"].append(time.perf_counter() - began)
            ours["wall_times"].append(r.wall_time)
        for run in at_rest:
            assert m is not None  # runs come from MuJoCo
            run["seconds"].append(time_mujoco(m, d, run))
    for run in at_rest:
        run["time"] = statistics.median(run["seconds"])
        del run["qpos"]
    ours["time"] = statistics.median(ours["seconds"])


def pose_distance(mj: Any, qpos: np.ndarray, model: pinocchio.Model, q: np.ndarray) -> float:
    """The largest difference of a hinge's angle between MuJoCo's rest and pinsettle's (rad)."""
    return max(
        abs(float(qpos[mj.jnt_qposadr[j]] - q[model.idx_qs[model.getJointId(mj.joint(j).name)]]))
        for j in range(mj.njnt)
        if mj.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE
    )


def measure_scene(name: str, sweep: Sweep) -> Record:
    """pinsettle and MuJoCo (when installed) on one library scene, and the step cost."""
    scene = pinsettle.load_scene(name)
    w = weight(scene)
    rest = pinsettle.Solver(scene).solve()
    ours = ours_record(scene, rest, w)
    m, check, runs = (None, {}, []) if mujoco is None else mujoco_runs(scene, sweep, w)
    for run in runs:
        if m is not None and run["status"] == "at rest":
            run["distance"] = pose_distance(m.model, run["qpos"], scene.model, rest.q)
    timed_rounds(scene, m, runs, ours, sweep)
    return {
        "name": name,
        "description": scene.description,
        "weight": w,
        "contacts": len(scene.contacts),
        "ours": ours,
        "model_check": check,
        "runs": runs,
        "step_cost": step_cost(scene, rest, sweep),
    }


def empty_record(sweep: Sweep) -> Record:
    """The contact part's record before its scenes are measured."""
    sweep_record = asdict(sweep) | {"level": LEVEL, "point_radius": POINT_RADIUS}
    return {"mujoco": mujoco_info(), "sweep": sweep_record, "scenes": []}


def measure(sweep: Sweep = FULL) -> Record:
    """The contact part: every scene of the sweep."""
    record = empty_record(sweep)
    record["scenes"] = [measure_scene(name, sweep) for name in sweep.scenes]
    return record


# --- the report's section -------------------------------------------------------------------------


def at_rest(runs: list[Record]) -> list[Record]:
    return [run for run in runs if run["status"] == "at rest"]


def below(runs: list[Record]) -> list[Record]:
    """The runs at rest with their centre of mass below the floor."""
    return [run for run in at_rest(runs) if run["com_height"] < 0]


def best(runs: list[Record]) -> Record | None:
    """MuJoCo at its best: the run at rest on the floor (centre of mass above it) in the least
    time (None: none came to rest there)."""
    done = [run for run in at_rest(runs) if run["com_height"] >= 0]
    return min(done, key=lambda run: run["time"]) if done else None


def label(run: Record) -> str:
    return Setting(run["timestep"], run["integrator"], run["damping"]).label()


SCENE_WORDS = {
    "go1_standing": "each joint on a 40 N m/rad spring to the stance",
    "go1_motors_off": "no springs: the legs give way until the trunk's four lower corners, "
    "points, land too",
}


def intro(record: Record) -> str:
    sweep = record["sweep"]
    version = record["mujoco"].get("version", "-")
    names = [scene["name"] for scene in record["scenes"]]
    scenes = " and ".join(f"`{name}` ({SCENE_WORDS.get(name, '')})" for name in names)
    return (
        f"pinsettle's solve of the library {'scene' if len(names) == 1 else 'scenes'} "
        f"{scenes}, go1 released 3 cm above a floor of friction 0.8, landing on four foot "
        "spheres of 0.02 m, against MuJoCo "
        f"{version} stepping the same model from the same start until it is at rest, "
        "at its best over every combination of its time step ("
        + ", ".join(f"{dt * 1e3:g}" for dt in sweep["timesteps"])
        + " ms), integrator ("
        + ", ".join(sweep["integrators"])
        + ") and joint damping on every degree of freedom ("
        + ", ".join(f"{x:g}" for x in sweep["dampings"])
        + " N m s/rad or N s/m), each within "
        f"{sweep['max_sim']:g} s simulated. MuJoCo's model (`benchmarks/contact_drop.py`): the "
        "scene's URDF without visual and collision elements, a free joint on its root, the "
        "floor as a plane of the same friction, each contact point a sphere of its radius at "
        f"its frame (a point as a sphere of {sweep['point_radius']:g} m, its gap counted from "
        "the centre) and the only geoms that collide, the joint springs as joint stiffness with "
        "`springref` at their rest, the URDF's joint damping and friction loss replaced by the "
        "swept damping and none, its joint limits kept (pinsettle's stops); `base`'s inertia, "
        "1e-6 kg m^2 in every entry and not positive definite, which MuJoCo refuses, keeps its "
        "diagonal (a rest depends on masses and their centres only). **At rest** (MuJoCo): its "
        "static residual `max |qfrc_bias - qfrc_spring - qfrc_constraint|` (gravity against its "
        f"springs, contacts and limits, after `mj_forward` of the state reached) at most "
        f"{sweep['level']:g} of the weight and max |qvel| <= {MUJOCO_QVEL:g} at every check "
        f"(every {MUJOCO_CHUNK} steps) for {MUJOCO_QUIET:g} s simulated in a row; its time to "
        "rest is that of the steps to the first check of that stretch, stepped again in one "
        "`mj_step(model, data, nstep)` call (checked to reach the same state), in "
        f"{sweep['repeats']} rounds interleaved with pinsettle's warm solves "
        f"(`Solver.solve` of a solver made once, timed around the call, {OURS_PER_ROUND} "
        "solves a round), medians. **At its best**: the setting that came to rest on the floor "
        "(its centre of mass above it) in the least time. Penetration: "
        "the deepest contact, from MuJoCo's contact distances; normal force: the contacts' "
        "normal forces summed, over the weight. pinsettle's contacts are hard: its penetration, "
        "the deepest gap below 0, is recomputed from Pinocchio's frames (a closed contact is "
        "within 1e-6 m), its normal forces summed over the weight. Columns: the contact points, "
        "pinsettle's status and steps, time, penetration and normal force; MuJoCo's best "
        "setting, its steps to rest (simulated time), time, penetration and normal force; "
        "MuJoCo's time over pinsettle's.\n\n"
    )


def model_line(scene: Record) -> str:
    c = scene["model_check"]
    if not c:
        return ""
    mass = abs(c["mass_mujoco"] - c["mass_pinocchio"]) / c["mass_pinocchio"]
    return (
        f"`{scene['name']}`: MuJoCo's model against Pinocchio's at the start: total mass "
        f"{c['mass_mujoco']:.6f} against {c['mass_pinocchio']:.6f} kg (relative difference "
        f"{mass:.1e}), {c['hinges']} hinges for {c['joints_pinocchio']} joints, joint axes in "
        f"world axes within {c['axis']:.1e}, contact centres within {c['contact_centre']:.1e} "
        f"m, centre of mass within {c['com']:.1e} m"
        + (f", {c['springs']} joint springs within {c['spring']:.1e}." if c["springs"] else ".")
    )


def scene_row(scene: Record) -> list[str]:
    ours = scene["ours"]
    gap = min(ours["gaps"])
    cells = [
        f"`{scene['name']}`",
        str(scene["contacts"]),
        f"{ours['status']}, {ours['steps']:,}",
        fmt_time(ours["time"]),
        f"{max(-gap, 0.0):.1e} m",
        f"{ours['normal_force']:.10f}",
    ]
    run = best(scene["runs"])
    if run is None:
        no = "not installed" if not scene["model_check"] else "none at rest"
        return cells + [no, "-", "-", "-", "-", "-"]
    return cells + [
        label(run),
        f"{run['steps']:,} ({run['sim_time']:.3g} s)",
        fmt_time(run["time"]),
        f"{run['penetration'] * 1e3:.2f} mm",
        f"{run['normal_force']:.6f}",
        f"**{run['time'] / ours['time']:.0f}**",
    ]


COLUMNS = (
    "scene",
    "contacts",
    "pinsettle",
    "time",
    "penetration",
    "normal force / weight",
    "MuJoCo at its best",
    "steps (simulated)",
    "MuJoCo time",
    "MuJoCo penetration",
    "MuJoCo normal force / weight",
    "MuJoCo / pinsettle",
)


def _listed(runs: list[Record], what: str, most: int = 4) -> str:
    """'label (what), ...' for at most ``most`` runs, then how many more."""
    shown = [f"{label(run)} ({what.format(**run)})" for run in runs[:most]]
    more = len(runs) - most
    return "; ".join(shown) + (f"; and {more} more" if more > 0 else "")


def _which(subset: list[Record], runs: list[Record], what: str) -> str:
    """The settings of ``subset`` in words: the damping values it holds every setting of, then
    the others as ``_listed``."""
    ids = {id(run) for run in subset}
    values = dict.fromkeys(run["damping"] for run in runs)
    whole = [x for x in values if all(id(r) in ids for r in runs if r["damping"] == x)]
    rest = [run for run in subset if run["damping"] not in whole]
    parts = [f"every setting with damping {', '.join(f'{x:g}' for x in whole)}"] if whole else []
    return "; ".join(parts + ([_listed(rest, what, most=3)] if rest else []))


def _best_by(scene: Record, key: str, values: list[Any]) -> str:
    ours = scene["ours"]["time"]
    parts = []
    for value in values:
        run = best([r for r in scene["runs"] if r[key] == value])
        shown = f"{value:g}" if isinstance(value, float) else value
        if run is None:
            rested = at_rest([r for r in scene["runs"] if r[key] == value])
            parts.append(f"{shown}: none " + ("on the floor" if rested else "at rest"))
        else:
            parts.append(f"{shown}: {fmt_time(run['time'])} ({run['time'] / ours:.0f} x)")
    return ", ".join(parts)


def what_lost(scene: Record, sweep: Record) -> str:
    """MuJoCo's sweep on the scene: how many settings came to rest, its best per integrator and
    per damping, the slowest, and those that did not come to rest or rested below the floor."""
    runs = scene["runs"]
    if not runs:
        return ""
    done = sorted(at_rest(runs), key=lambda run: run["time"])
    under = below(runs)
    text = (
        f"**`{scene['name']}`**: {len(done)} of MuJoCo's {len(runs)} settings came to rest "
        f"within {sweep['max_sim']:g} s simulated"
        + (f", {len(under)} of them below the floor" if under else "")
        + ". Best per integrator: "
        + _best_by(scene, "integrator", list(sweep["integrators"]))
        + "; per damping: "
        + _best_by(scene, "damping", list(sweep["dampings"]))
        + " (MuJoCo's time, and over pinsettle's)."
    )
    on_floor = [run for run in done if run["com_height"] >= 0]
    if on_floor:
        worst = on_floor[-1]
        text += (
            f" The slowest at rest on the floor: {label(worst)}, {fmt_time(worst['time'])} "
            f"({worst['time'] / scene['ours']['time']:.0f} times pinsettle's)."
        )
    if under:
        text += (
            f" At rest below the floor ({len(under)}; the trunk fell between the legs, which "
            "touch the floor only at their contact points, and hangs from the feet under it, "
            "centre of mass {:.2f} m below the floor): ".format(-under[0]["com_height"])
            + _which(under, runs, "{time:.3g} s")
            + "."
        )
    text += not_at_rest([run for run in runs if run["status"] == "not at rest"], runs)
    broke = [run for run in runs if run["status"] == "diverged"]
    if broke:
        text += f" Blew up ({len(broke)}): " + _listed(broke, "at step {checked_steps:,}") + "."
    return text + rests_line(scene)


def not_at_rest(slow: list[Record], runs: list[Record]) -> str:
    """The runs that did not come to rest: how far they were, and the first few."""
    if not slow:
        return ""
    qvel = [run["last_qvel"] for run in slow]
    residual = [run["last_residual"] for run in slow]
    what = "max |qvel| {last_qvel:.1e}, residual {last_residual:.1e}"
    return (
        f" Not at rest within the budget ({len(slow)}): at its end max |qvel| "
        f"{min(qvel):.1e} to {max(qvel):.1e} (rad/s or m/s) and a residual of "
        f"{min(residual):.1e} to {max(residual):.1e} of the weight; "
        + _which(slow, runs, what)
        + "."
    )


def rests_line(scene: Record) -> str:
    """How MuJoCo's best rest differs from pinsettle's."""
    run, ours = best(scene["runs"]), scene["ours"]
    if run is None:
        return ""
    drop = (ours["height"] - run["height"]) * 1e3
    return (
        f" MuJoCo at its best rests with its root {abs(drop):.2f} mm "
        f"{'lower' if drop >= 0 else 'higher'} than pinsettle's (its contacts "
        f"{run['penetration'] * 1e3:.2f} mm deep at most), its joints up to "
        f"{run['distance']:.3f} rad from pinsettle's; the largest ratio of a contact's "
        f"tangential to normal force is {run['shear']:.1e} in MuJoCo's rest, "
        f"{ours['shear']:.2f} in pinsettle's (the sideways forces the landing locked in: "
        "[contacts.md](contacts.md#the-rest-and-its-check))."
    )


def cost_table(scenes: list[Record]) -> str:
    rows = []
    for scene in scenes:
        c = scene["step_cost"]
        rows.append(
            [
                f"`{scene['name']}`",
                f"{c['dt'] * 1e3:.3g} ms",
                f"{c['resting_closed']}",
                fmt_time(c["resting"]),
                fmt_time(c["free"]),
                f"{c['resting'] / c['free']:.2f}",
            ]
        )
    steps = scenes[0]["step_cost"]["steps"]
    return (
        "**A step on the contacts.** pinsettle's time per step from its rest at the rest's "
        "final step, fixed, with no polish, no Newton and `max_e = 0` (the run goes on to its "
        "step budget, kinetic damping and its events as usual): resting on its contacts (the "
        "impulses solved at every step) against falling free with the floor twice its fall "
        "below (the contacts checked at every step, none closing; without a ground pinsettle "
        "refuses a free root at once). Per step: the difference of the wall times of "
        f"{steps[1]:,} and {steps[0]:,} steps over the difference of their steps (the set-up "
        "and the final assessment cancel), medians of interleaved repeats.\n\n"
        + table(
            ["scene", "dt", "closed contacts", "step resting", "step falling free", "ratio"],
            rows,
            right=(1, 2, 3, 4, 5),
        )
    )


def section(record: Record) -> str:
    """The report's contact part from ``measure``'s record."""
    scenes = record["scenes"]
    text = intro(record)
    if "missing" in record["mujoco"]:
        text += f"MuJoCo was not measured: {record['mujoco']['missing']}.\n\n"
    text += table(COLUMNS, [scene_row(s) for s in scenes], right=(1, 3, 4, 5, 7, 8, 9, 10, 11))
    checks = " ".join(filter(None, (model_line(s) for s in scenes)))
    text += "\n" + (checks + "\n\n" if checks else "")
    for scene in scenes:
        lost = what_lost(scene, record["sweep"])
        if lost:
            text += lost + "\n\n"
    return text + cost_table(scenes)

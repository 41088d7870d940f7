"""The scene physics written again with pinocchio and numpy only, for the tests: a scene file
read again with tomllib, its model built again with ``pinocchio.buildModelFromUrdf`` (and
``buildReducedModel`` for locked joints), and the net static generalized force of gravity,
springs and loads, the potential and the stiffness recomputed from Jacobians. Nothing of
pinsettle's physics: ``tests/test_scenes.py`` and ``tests/test_loops.py`` check pinsettle
against it.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def wrap(angle: float) -> float:
    """An angle difference wrapped to [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def skew(r: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


@dataclass
class Reference:
    """A scene as plain data plus its static force, potential and stiffness.

    ``full`` is the whole model (gravity set); joints named in ``locked`` are removed with
    ``pinocchio.buildReducedModel`` at their value in the full configuration. Springs are
    ``(frame_a, point_a, frame_b, point_b, stiffness, rest_length)``; joint springs
    ``(joint, stiffness, rest)``; joint loads ``(joint, effort)``; point loads
    ``(frame, point, force, torque)``; loop closures ``(frame_a, point_a, frame_b, point_b,
    kind)``. Joint stops: the model's position limits when ``limits`` (a revolute or prismatic
    joint of one coordinate; equal limits, non-finite or huge ones are none), and
    ``limit_entries`` ``(joint, lower or None, upper or None)`` on top (None: the model's own on
    that side while ``limits``, else none).
    """

    full: pinocchio.Model
    locked: list[str] = field(default_factory=list)
    joint_springs: list[tuple] = field(default_factory=list)
    springs: list[tuple] = field(default_factory=list)
    joint_loads: list[tuple] = field(default_factory=list)
    point_loads: list[tuple] = field(default_factory=list)
    loops: list[tuple] = field(default_factory=list)
    start: dict = field(default_factory=dict)
    limits: bool = True
    limit_entries: list[tuple] = field(default_factory=list)
    _reduced: dict = field(default_factory=dict, repr=False)

    # -- construction --

    @classmethod
    def from_toml(cls, path: Path) -> Reference:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        m = data["model"]
        if "urdf" in m:
            urdf = path.parent / m["urdf"]
        else:
            urdf = pinsettle.robot_urdf(m["robot"])  # only the path of the shipped URDF
        if m.get("floating", False):
            full = pinocchio.buildModelFromUrdf(str(urdf), pinocchio.JointModelFreeFlyer())
        else:
            full = pinocchio.buildModelFromUrdf(str(urdf))
        if "gravity" in m:
            full.gravity = pinocchio.Motion(np.array(m["gravity"], float), np.zeros(3))

        def end(e):
            return e["frame"], np.array(e.get("point", [0.0, 0.0, 0.0]), float)

        ref = cls(
            full,
            locked=list(m.get("locked", [])),
            start=dict(data.get("start", {})),
            limits=m.get("limits", True),
        )
        for s in data.get("limit", []):
            ref.limit_entries.append((s["joint"], s.get("lower"), s.get("upper")))
        for s in data.get("joint_spring", []):
            ref.joint_springs.append((s["joint"], s["stiffness"], s.get("rest", 0.0)))
        for s in data.get("spring", []):
            ref.springs.append(
                (*end(s["a"]), *end(s["b"]), s["stiffness"], s.get("rest_length", 0.0))
            )
        for s in data.get("load", []):
            if "joint" in s:
                ref.joint_loads.append((s["joint"], np.atleast_1d(np.array(s["effort"], float))))
            else:
                ref.point_loads.append(
                    (
                        s["frame"],
                        np.array(s.get("point", [0.0, 0.0, 0.0]), float),
                        np.array(s["force"], float),
                        np.array(s.get("torque", [0.0, 0.0, 0.0]), float),
                    )
                )
        for s in data.get("loop", []):
            ref.loops.append((*end(s["a"]), *end(s["b"]), s.get("kind", "point")))
        return ref

    def q_start(self) -> np.ndarray:
        q = pinocchio.neutral(self.full)
        for name, value in self.start.items():
            j = self.full.getJointId(name)
            iq, nq = self.full.idx_qs[j], self.full.nqs[j]
            if nq == 2 and self.full.nvs[j] == 1:
                q[iq : iq + 2] = [math.cos(value), math.sin(value)]
            else:
                q[iq : iq + nq] = value
        return q

    # -- full <-> reduced configurations, by joint name --

    def reduced(self, q_full: np.ndarray) -> pinocchio.Model:
        """The model with the locked joints removed at their value in q_full."""
        if not self.locked:
            return self.full
        ids = sorted(self.full.getJointId(name) for name in self.locked)
        key = tuple(
            float(x)
            for j in ids
            for x in q_full[self.full.idx_qs[j] : self.full.idx_qs[j] + self.full.nqs[j]]
        )
        if key not in self._reduced:
            self._reduced[key] = pinocchio.buildReducedModel(self.full, ids, q_full)
        return self._reduced[key]

    def to_reduced(self, model: pinocchio.Model, q_full: np.ndarray) -> np.ndarray:
        q = np.zeros(model.nq)
        for j in range(1, model.njoints):
            jf = self.full.getJointId(model.names[j])
            q[model.idx_qs[j] : model.idx_qs[j] + model.nqs[j]] = q_full[
                self.full.idx_qs[jf] : self.full.idx_qs[jf] + self.full.nqs[jf]
            ]
        return q

    def to_full(self, model: pinocchio.Model, q: np.ndarray, q_full: np.ndarray) -> np.ndarray:
        out = np.array(q_full, float)
        for j in range(1, model.njoints):
            jf = self.full.getJointId(model.names[j])
            out[self.full.idx_qs[jf] : self.full.idx_qs[jf] + self.full.nqs[jf]] = q[
                model.idx_qs[j] : model.idx_qs[j] + model.nqs[j]
            ]
        return out

    # -- physics on the reduced model --

    @staticmethod
    def _frame(model: pinocchio.Model, name: str) -> int:
        bodies = [
            i
            for i, f in enumerate(model.frames)
            if f.name == name and f.type == pinocchio.FrameType.BODY
        ]
        if bodies:
            return bodies[0]
        return [i for i, f in enumerate(model.frames) if f.name == name][0]

    @staticmethod
    def _point(model, data, name, point):
        """World position and world-aligned (linear, angular) Jacobians of a frame's point."""
        fid = Reference._frame(model, name)
        placement = data.oMf[fid]
        p = placement.act(np.asarray(point, float))
        jac = pinocchio.getFrameJacobian(model, data, fid, pinocchio.LOCAL_WORLD_ALIGNED)
        j_ang = jac[3:]
        j_lin = jac[:3] - skew(p - placement.translation) @ j_ang
        return p, j_lin, j_ang

    def _kinematics(self, model, q):
        data = model.createData()
        pinocchio.computeJointJacobians(model, data, q)  # also the forward kinematics
        pinocchio.updateFramePlacements(model, data)
        return data

    def _joint_delta(self, model, q, name, rest):
        j = model.getJointId(name)
        iq = model.idx_qs[j]
        if model.nqs[j] == 2:  # continuous joint: (cos, sin)
            return model.idx_vs[j], wrap(math.atan2(q[iq + 1], q[iq]) - rest)
        return model.idx_vs[j], q[iq] - rest

    def force_reduced(self, model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
        """g(q) + joint springs - J^T (spring forces) - loads, on the reduced model."""
        f = pinocchio.computeGeneralizedGravity(model, model.createData(), q).copy()
        for name, k, rest in self.joint_springs:
            iv, delta = self._joint_delta(model, q, name, rest)
            f[iv] += k * delta
        data = self._kinematics(model, q)
        for fa, pa, fb, pb, k, rest_length in self.springs:
            a, ja, _ = self._point(model, data, fa, pa)
            b, jb, _ = self._point(model, data, fb, pb)
            d = b - a
            length = np.linalg.norm(d)
            force_a = k * (length - rest_length) * d / length
            f -= ja.T @ force_a + jb.T @ (-force_a)
        for name, effort in self.joint_loads:
            j = model.getJointId(name)
            f[model.idx_vs[j] : model.idx_vs[j] + model.nvs[j]] -= effort
        for name, point, force, torque in self.point_loads:
            _, j_lin, j_ang = self._point(model, data, name, point)
            f -= j_lin.T @ force + j_ang.T @ torque
        return f

    def potential_reduced(
        self, model: pinocchio.Model, q: np.ndarray, loads: bool = False
    ) -> float:
        """Gravity potential plus spring energies, and with ``loads`` the constant loads'
        potential (minus their work: efforts on one-coordinate joints, forces without torque,
        which have one)."""
        data = model.createData()
        com = pinocchio.centerOfMass(model, data, q)
        v = -data.mass[0] * float(np.dot(model.gravity.linear, com))
        for name, k, rest in self.joint_springs:
            v += 0.5 * k * self._joint_delta(model, q, name, rest)[1] ** 2
        data = self._kinematics(model, q)
        for fa, pa, fb, pb, k, rest_length in self.springs:
            a = self._point(model, data, fa, pa)[0]
            b = self._point(model, data, fb, pb)[0]
            v += 0.5 * k * (np.linalg.norm(b - a) - rest_length) ** 2
        if loads:
            for name, effort in self.joint_loads:
                j = model.getJointId(name)
                assert model.nqs[j] == 1, "an effort on this joint has no potential written here"
                v -= float(np.dot(effort, q[model.idx_qs[j] : model.idx_qs[j] + 1]))
            for name, point, force, torque in self.point_loads:
                assert not np.any(torque), "a torque load has no potential written here"
                v -= float(force @ self._point(model, data, name, point)[0])
        return v

    def loop_jacobian(self, model: pinocchio.Model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Loop errors (m; rad for a frame loop's rotation) and their Jacobian along the
        tangent (world axes): the two points' relative position and, for a frame loop, the
        relative rotation log3(R_a R_b^T)."""
        data = self._kinematics(model, q)
        errors, rows = [], []
        for fa, pa, fb, pb, kind in self.loops:
            xa, ja, wa = self._point(model, data, fa, pa)
            xb, jb, wb = self._point(model, data, fb, pb)
            errors.append(xa - xb)
            rows.append(ja - jb)
            if kind == "frame":
                ra = data.oMf[self._frame(model, fa)].rotation
                rb = data.oMf[self._frame(model, fb)].rotation
                errors.append(pinocchio.log3(ra @ rb.T))
                rows.append(wa - wb)
        return np.concatenate(errors), np.vstack(rows)

    def stiffness_reduced(self, model, q, h=1e-6) -> np.ndarray:
        """K = d(force)/dq by central differences along the tangent (pinocchio.integrate)."""
        k = np.zeros((model.nv, model.nv))
        for i in range(model.nv):
            step = np.zeros(model.nv)
            step[i] = h
            plus = self.force_reduced(model, pinocchio.integrate(model, q, step))
            minus = self.force_reduced(model, pinocchio.integrate(model, q, -step))
            k[:, i] = (plus - minus) / (2 * h)
        return k

    # -- joint stops --

    def stops(self, model: pinocchio.Model) -> dict[str, tuple[float, float]]:
        """The stops of the joints of ``model`` (the full or a reduced model) by name:
        (lower, upper) with -inf / +inf where a side has none."""
        out = {}
        own = {}
        for j in range(1, model.njoints):
            if model.nqs[j] != 1 or model.nvs[j] != 1:
                continue  # continuous, spherical, planar, free-flyer: no stop of their own
            iq = model.idx_qs[j]
            low, high = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
            if low == high:  # a URDF's default when the limits are left out: none
                continue
            low = low if math.isfinite(low) and abs(low) < 1e10 else -math.inf
            high = high if math.isfinite(high) and abs(high) < 1e10 else math.inf
            own[model.names[j]] = (low, high)
            if self.limits and (math.isfinite(low) or math.isfinite(high)):
                out[model.names[j]] = (low, high)
        for name, low, high in self.limit_entries:
            if name not in model.names:
                continue  # a locked joint
            kept = own if self.limits else {}
            model_low, model_high = kept.get(name, (-math.inf, math.inf))
            out[name] = (
                model_low if low is None else float(low),
                model_high if high is None else float(high),
            )
        return {k: v for k, v in out.items() if math.isfinite(v[0]) or math.isfinite(v[1])}

    def rest_conditions(
        self, model: pinocchio.Model, q: np.ndarray, force: np.ndarray
    ) -> tuple[np.ndarray, dict[str, tuple[str, float]], bool]:
        """The conditions of a rest against stops at the reduced configuration q given the net
        static force there: the violation per velocity index (|force| off the stops; at a lower
        stop max(0, -force), at an upper max(0, force): a stop only pushes), the joints on a stop
        with (side, reaction >= 0), and whether every stopped joint is within its range."""
        violation = np.abs(force)
        contacts = {}
        inside = True
        for name, (low, high) in self.stops(model).items():
            j = model.getJointId(name)
            x, iv = q[model.idx_qs[j]], model.idx_vs[j]
            inside = inside and low <= x <= high
            if x <= low:
                violation[iv] = max(0.0, -force[iv])
                contacts[name] = ("lower", max(0.0, force[iv]))
            elif x >= high:
                violation[iv] = max(0.0, force[iv])
                contacts[name] = ("upper", max(0.0, -force[iv]))
        return violation, contacts, inside

    def rest_residual(self, q_full: np.ndarray) -> float:
        """The residual of a rest against the stops (the plain residual without any)."""
        model = self.reduced(q_full)
        q = self.to_reduced(model, q_full)
        violation = self.rest_conditions(model, q, self.force_reduced(model, q))[0]
        return float(np.max(violation)) if violation.size else 0.0

    def contacts(self, q_full: np.ndarray) -> dict[str, tuple[str, float]]:
        """The joints resting on a stop at q_full: (side, reaction)."""
        model = self.reduced(q_full)
        q = self.to_reduced(model, q_full)
        return self.rest_conditions(model, q, self.force_reduced(model, q))[1]

    # -- the same on full configurations --

    def force(self, q_full: np.ndarray) -> np.ndarray:
        model = self.reduced(q_full)
        return self.force_reduced(model, self.to_reduced(model, q_full))

    def residual(self, q_full: np.ndarray) -> float:
        return float(np.max(np.abs(self.force(q_full))))

    def eigenvalues(self, q_full: np.ndarray) -> np.ndarray:
        """Eigenvalues of the symmetric part of the stiffness (ascending)."""
        model = self.reduced(q_full)
        k = self.stiffness_reduced(model, self.to_reduced(model, q_full))
        return np.linalg.eigvalsh(0.5 * (k + k.T))

    def random_configuration(self, rng: np.random.Generator, scale: float = 2.0) -> np.ndarray:
        """A random full configuration; locked joints keep their start value."""
        q_start = self.q_start()
        model = self.reduced(q_start)
        q = pinocchio.integrate(
            model, self.to_reduced(model, q_start), rng.uniform(-scale, scale, model.nv)
        )
        return self.to_full(model, q, q_start)

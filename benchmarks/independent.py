"""The benchmark report's physics, independent of pinsettle's: the scene reference of the tests
(tests/scene_reference.py: the static force of gravity, springs and loads from Pinocchio's
frames and Jacobians, the loops' Jacobian) on the report's scenes, and from it the residual, the
stiffness by central differences, its verdict, Newton's step and the projection onto the loops.
Nothing here calls pinsettle's static force, stiffness, stability verdict or loop code.

``CachedReference`` keeps one ``pinocchio.Data`` per model: building one costs 30 ms on a
100-link chain, and the report evaluates the force thousands of times.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
from scene_reference import Reference  # noqa: E402  (tests/scene_reference.py)

#: Finite-difference step of the stiffness (rad or m along the tangent).
FD_STEP = 1e-6
#: Eigenvalues within this fraction of the largest absolute one count as zero (central
#: differences: their error is far below it; a 300-link chain's softest mode is 1e-7 of its
#: stiffest, so the tolerance must be far below that too).
VERDICT_TOLERANCE = 1e-10
#: Loop errors below this (m) count as closed.
LOOP_TOLERANCE = 1e-13


@dataclass
class CachedReference(Reference):
    """tests/scene_reference.py's Reference with one pinocchio.Data per model."""

    _datas: dict[int, pinocchio.Data] = field(default_factory=dict, repr=False)

    def data_of(self, model: pinocchio.Model) -> pinocchio.Data:
        data = self._datas.get(id(model))
        if data is None:
            data = self._datas[id(model)] = model.createData()
        return data

    def _kinematics(self, model: pinocchio.Model, q: np.ndarray) -> pinocchio.Data:
        data = self.data_of(model)
        pinocchio.computeJointJacobians(model, data, q)  # also the forward kinematics
        pinocchio.updateFramePlacements(model, data)
        return data

    def has_elements(self) -> bool:
        return bool(self.joint_springs or self.springs or self.joint_loads or self.point_loads)

    def force_reduced(self, model: pinocchio.Model, q: np.ndarray) -> np.ndarray:
        if not self.has_elements():  # gravity alone: Pinocchio's generalized gravity
            data = self.data_of(model)
            gravity: np.ndarray = pinocchio.computeGeneralizedGravity(model, data, q).copy()
            return gravity
        force: np.ndarray = super().force_reduced(model, q)
        return force


class Physics:
    """A scene's independent statics on its reduced model (locked joints removed at their start
    value): configurations are full ones (dim full.nq), forces and tangents reduced (dim nv).

    With loops, the force is the static force's component along the motions the loops allow
    (``P f``, P the orthogonal projector onto the null space of the loops' Jacobian), the
    stiffness is restricted to those motions and differenced along them, each side moved back
    onto the loops (Gauss-Newton on the loop errors)."""

    def __init__(self, ref: CachedReference, q_start: np.ndarray) -> None:
        self.ref = ref
        self.full = ref.full
        self.q_start = np.asarray(q_start, dtype=float)
        self.model = ref.reduced(self.q_start)
        self.loops = bool(ref.loops)
        self.whole = not ref.locked  # the reduced model is the full one

    # -- configurations --

    def reduced_q(self, q_full: np.ndarray) -> np.ndarray:
        if self.whole:
            return np.array(q_full, dtype=float)
        return self.ref.to_reduced(self.model, q_full)

    def full_q(self, q: np.ndarray) -> np.ndarray:
        if self.whole:
            return np.array(q, dtype=float)
        return self.ref.to_full(self.model, q, self.q_start)

    def integrate(self, q_full: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """q_full moved by the reduced tangent dq (not projected onto the loops)."""
        return self.full_q(pinocchio.integrate(self.model, self.reduced_q(q_full), dq))

    # -- loops --

    def loop_jacobian(self, q_full: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.ref.loop_jacobian(self.model, self.reduced_q(q_full))

    def basis(self, q_full: np.ndarray) -> np.ndarray:
        """Orthonormal basis (nv x mobility) of the motions the loops allow (numpy's SVD of
        their Jacobian); the identity for a tree."""
        if not self.loops:
            return np.eye(self.model.nv)
        _, J = self.loop_jacobian(q_full)
        _, s, vt = np.linalg.svd(J)
        rank = int(np.sum(s > 1e-9 * s[0])) if s.size else 0
        basis: np.ndarray = vt[rank:].T
        return basis

    def project(self, q_full: np.ndarray, iterations: int = 50) -> np.ndarray:
        """q_full moved onto the loops (least-norm Gauss-Newton); all nan when they cannot be
        closed from there; q_full itself for a tree."""
        if not self.loops or not np.all(np.isfinite(q_full)):
            return q_full
        q = self.reduced_q(q_full)
        for _ in range(iterations):
            e, J = self.ref.loop_jacobian(self.model, q)
            if np.max(np.abs(e)) <= LOOP_TOLERANCE:
                return self.full_q(q)
            q = pinocchio.integrate(self.model, q, -np.linalg.lstsq(J, e, rcond=1e-10)[0])
        return np.full_like(q_full, math.nan)

    # -- statics --

    def force(self, q_full: np.ndarray) -> np.ndarray:
        """The net static generalized force (gravity minus springs and loads, dim nv); with
        loops its component along the motions they allow."""
        f = self.ref.force_reduced(self.model, self.reduced_q(q_full))
        if self.loops:
            B = self.basis(q_full)
            f = B @ (B.T @ f)
        return f

    def stiffness(self, q_full: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(K, B): K = B^T d(force)/dq B by central differences along the columns of B (each side
        moved back onto the loops), B the basis of ``basis``."""
        B = self.basis(q_full)
        K = np.empty((self.model.nv, B.shape[1]))
        for i in range(B.shape[1]):
            e = FD_STEP * B[:, i]
            plus = self.force(self.project(self.integrate(q_full, e)))
            minus = self.force(self.project(self.integrate(q_full, -e)))
            K[:, i] = (plus - minus) / (2 * FD_STEP)
        return B.T @ K, B

    def verdict(self, q_full: np.ndarray) -> tuple[str, int, float]:
        """(stable / neutral / unstable, neutral directions, smallest eigenvalue) from the
        eigenvalues of the symmetric part of ``stiffness``."""
        K, _ = self.stiffness(q_full)
        if K.size == 0:
            return "stable", 0, math.nan
        w = np.linalg.eigvalsh(0.5 * (K + K.T))
        tol = VERDICT_TOLERANCE * max(float(np.max(np.abs(w))), 1e-300)
        neutral = int(np.sum(np.abs(w) <= tol))
        kind = "unstable" if w[0] < -tol else "neutral" if neutral else "stable"
        return kind, neutral, float(w[0])

    def newton_step(self, q_full: np.ndarray, f: np.ndarray | None = None) -> np.ndarray:
        """Newton's step (reduced tangent): dq = B lstsq(K, -B^T f) with the finite-difference
        K of ``stiffness``, rank cut 1e-8 (neutral directions are left alone)."""
        f = self.force(q_full) if f is None else f
        K, B = self.stiffness(q_full)
        step: np.ndarray = B @ np.linalg.lstsq(K, -(B.T @ f), rcond=1e-8)[0]
        return step

"""A scene's static force, distances between its poses and its loops, as the benchmark report
measures them (benchmarks/report.py; the records of benchmarks/report_data.py keep one per
scene). The force, the residual, the stiffness, its verdict and the projection onto the loops
are the independent physics of benchmarks/independent.py (tests/scene_reference.py's), never
pinsettle's; pinsettle's stiffness is used only by the Newton *method* the report measures
(``solver_newton_step``)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio
import pinsettle
from independent import CachedReference, Physics
from pinsettle import _core


class Statics:
    """A scene's static force on its free joints and distances between poses.

    ``scene`` is what the solver runs; ``reference`` the same scene written independently
    (tests/scene_reference.py). With closed loops: ``q0`` is the start moved onto the loops, the
    force is projected onto the motions the loops allow, and ``step`` moves its result back
    onto the loops."""

    def __init__(self, scene: pinsettle.Scene, reference: CachedReference) -> None:
        self.scene = scene
        self.full = scene.model
        self.compiled = scene.compile()
        self.model = self.compiled.model
        self.elements = self.compiled.elements
        self.loops = self.compiled.loops  # None for a tree
        self.physics = Physics(reference, scene.q0())
        if list(self.physics.model.names) != list(self.model.names):
            raise RuntimeError(f"{scene.name}: the reference's joints differ from the scene's")
        self.data = self.model.createData()
        # Tangent entries that are angles of revolute joints: compared modulo 2 pi.
        angle = np.zeros(self.full.nv, dtype=bool)
        for j in range(1, self.full.njoints):
            if self.full.nvs[j] == 1 and self.full.joints[j].shortname().startswith("JointModelR"):
                angle[self.full.idx_vs[j]] = True
        self.angle = angle[self.compiled.v_index]
        self.simple = self.full.nq == self.full.nv  # difference is a plain subtraction
        self.q0 = self.physics.project(scene.q0())
        if not np.all(np.isfinite(self.q0)):
            raise RuntimeError(f"{scene.name}: the loops cannot be closed from the start")
        self.assembly_distance = self.distance(scene.q0(), self.q0)
        self.mobility = self.basis(self.q0).shape[1]
        self.force_scale = float(np.max(np.abs(self.force(self.q0))))

    # -- the independent physics --

    def force(self, q: np.ndarray) -> np.ndarray:
        """tau_static(q) on the free joints (with loops: projected onto the motions they allow
        at q), benchmarks/independent.py."""
        return self.physics.force(q)

    def residual(self, q: np.ndarray) -> float:
        """Relative residual: max |tau_static(q)| / force scale."""
        return float(np.max(np.abs(self.force(q)))) / self.force_scale

    def verdict(self, q: np.ndarray) -> tuple[str, int, float]:
        """Stability at q from the eigenvalues of the finite-difference stiffness of the
        independent force: (verdict, neutral directions, smallest eigenvalue)."""
        return self.physics.verdict(q)

    def newton_step(self, q: np.ndarray, f: np.ndarray | None = None) -> np.ndarray:
        """Newton's step from q with the independent finite-difference stiffness."""
        return self.physics.newton_step(q, f)

    def step(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """q moved by dq (free joints), then back onto the loops; all nan when the loops cannot
        be closed from there."""
        return self.physics.project(self.physics.integrate(q, dq))

    def project(self, q: np.ndarray) -> np.ndarray:
        """q moved onto the loops; q itself for a tree."""
        return self.physics.project(q)

    def basis(self, q: np.ndarray) -> np.ndarray:
        """Orthonormal basis (nv x mobility) of the motions the loops allow at q; the identity
        for a tree."""
        return self.physics.basis(q)

    # -- distances --

    def tangent(self, qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
        """qb - qa on the free joints (dim model.nv of the reduced model)."""
        dq: np.ndarray = pinocchio.difference(self.full, qa, qb)[self.compiled.v_index]
        return dq

    def distances(self, q_ref: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """max |q - q_ref| over the free joints for each row of ``rows`` (angles modulo 2 pi)."""
        if self.simple:
            d = (rows - q_ref)[:, self.compiled.v_index]
        else:
            d = np.array([self.tangent(q_ref, row) for row in rows])
        d[:, self.angle] = np.remainder(d[:, self.angle] + math.pi, 2 * math.pi) - math.pi
        worst: np.ndarray = np.max(np.abs(d), axis=1)
        return worst

    def distance(self, qa: np.ndarray, qb: np.ndarray) -> float:
        return float(self.distances(qa, qb[None, :])[0])

    def loop_error(self, q: np.ndarray) -> float:
        """Largest loop error at q (m; rad for the rotation of a frame loop), from Pinocchio's
        frame placements on the full model: nothing of pinsettle's loop code. 0 for a tree."""
        if not self.scene.loops:
            return 0.0
        if not np.all(np.isfinite(q)):
            return math.inf
        data = self.physics.ref.data_of(self.full)
        pinocchio.framesForwardKinematics(self.full, data, q)
        errors = []
        for loop in self.scene.loops:
            a = data.oMf[self.full.getFrameId(loop.a_frame)]
            b = data.oMf[self.full.getFrameId(loop.b_frame)]
            errors.append(a.act(np.asarray(loop.a_point)) - b.act(np.asarray(loop.b_point)))
            if loop.kind == "frame":
                errors.append(pinocchio.log3(a.rotation @ b.rotation.T))
        return float(np.max(np.abs(np.concatenate(errors))))

    # -- pinsettle's own tools, for the methods the report measures --

    def stiffness(self, q: np.ndarray) -> pinsettle.StabilityReport:
        """pinsettle.assess_stability: K (with loops reduced, mobility x mobility, in the
        coordinates of its basis)."""
        return pinsettle.assess_stability(self.scene, q)

    def solver_newton_step(self, q: np.ndarray, f: np.ndarray | None = None) -> np.ndarray:
        """Newton's step as a user writes it with pinsettle: dq = B lstsq(K, -B^T f), K and B
        from ``pinsettle.assess_stability``, rank cut 1e-10 (neutral directions left alone)."""
        f = self.force(q) if f is None else f
        report = self.stiffness(q)
        B = report.basis
        step: np.ndarray = B @ np.linalg.lstsq(report.stiffness_matrix, -(B.T @ f), rcond=1e-10)[0]
        return step

    def time_scale(self, q: np.ndarray, scale_stiff_modes: bool = False) -> _core._TimeScale:
        return pinsettle._core.time_scale(
            self.model, q[self.compiled.q_index], self.elements, scale_stiff_modes, self.loops
        )

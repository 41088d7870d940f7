"""A scene's static force, distances between its poses and its loops, as the benchmark report
measures them (benchmarks/report.py; the records of benchmarks/report_data.py keep one per
scene)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio
import pinsettle
from pinsettle import _core


class Statics:
    """A scene's static force on its free joints, compiled once (``Scene.static_force`` compiles
    the scene again for every q when joints are locked), and distances between poses.

    With closed loops: ``q0`` is the start moved onto the loops (where the solver starts), the
    force is projected onto the motions the loops allow, and ``step`` moves its result back onto
    the loops."""

    def __init__(self, scene: pinsettle.Scene) -> None:
        self.scene = scene
        self.full = scene.model
        self.compiled = scene.compile()
        self.model = self.compiled.model
        self.elements = self.compiled.elements
        self.loops = self.compiled.loops  # None for a tree
        self.data = self.model.createData()
        self.full_data = self.full.createData()
        self.q0, self.assembly_distance = scene.assemble(scene.q0())
        self.mobility = scene.mobility(self.q0) if self.loops else self.model.nv
        self.force_scale = float(np.max(np.abs(self.force(self.q0))))
        # Tangent entries that are angles of revolute joints: compared modulo 2 pi.
        angle = np.zeros(self.full.nv, dtype=bool)
        for j in range(1, self.full.njoints):
            if self.full.nvs[j] == 1 and self.full.joints[j].shortname().startswith("JointModelR"):
                angle[self.full.idx_vs[j]] = True
        self.angle = angle[self.compiled.v_index]
        self.simple = self.full.nq == self.full.nv  # difference is a plain subtraction

    def force(self, q: np.ndarray) -> np.ndarray:
        """tau_static(q) on the free joints, as ``Scene.static_force`` (with loops: projected
        onto the motions they allow at q). Without elements and loops it is Pinocchio's
        generalized gravity, as in pinsettle::computeStaticForce, on a Data kept here
        (pinsettle's binding builds a pinocchio::Data per call, which on a 200-link chain costs
        0.1 s)."""
        if self.loops:
            return _core.static_force(
                self.model, q[self.compiled.q_index], self.elements, self.loops
            )
        if self.elements is None:
            return pinocchio.computeGeneralizedGravity(
                self.model, self.data, q[self.compiled.q_index]
            ).copy()
        return _core.static_force(self.model, q[self.compiled.q_index], self.elements)

    def residual(self, q: np.ndarray) -> float:
        """Relative residual: max |tau_static(q)| / force scale."""
        return float(np.max(np.abs(self.force(q)))) / self.force_scale

    def tangent(self, qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
        """qb - qa on the free joints (dim model.nv of the reduced model)."""
        return pinocchio.difference(self.full, qa, qb)[self.compiled.v_index]

    def distances(self, q_ref: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """max |q - q_ref| over the free joints for each row of ``rows`` (angles modulo 2 pi)."""
        if self.simple:
            d = (rows - q_ref)[:, self.compiled.v_index]
        else:
            d = np.array([self.tangent(q_ref, row) for row in rows])
        d[:, self.angle] = np.remainder(d[:, self.angle] + math.pi, 2 * math.pi) - math.pi
        return np.max(np.abs(d), axis=1)

    def distance(self, qa: np.ndarray, qb: np.ndarray) -> float:
        return float(self.distances(qa, qb[None, :])[0])

    def step(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """q moved by dq (free joints), then back onto the loops; all nan when the loops cannot
        be closed from there."""
        full = np.zeros(self.full.nv)
        full[self.compiled.v_index] = dq
        return self.project(pinocchio.integrate(self.full, q, full))

    def project(self, q: np.ndarray) -> np.ndarray:
        """q moved onto the loops (``Scene.assemble``); q itself for a tree."""
        if not self.loops or not np.all(np.isfinite(q)):
            return q
        try:
            reduced, _ = _core.assemble_loops(self.model, q[self.compiled.q_index], self.loops)
        except ValueError:
            return np.full_like(q, math.nan)
        return self.compiled.full_q(np.asarray(reduced))

    def basis(self, q: np.ndarray) -> np.ndarray:
        """Orthonormal basis (nv x mobility) of the motions the loops allow at q (the loops'
        Jacobian's null space); the identity for a tree."""
        if not self.loops:
            return np.eye(self.model.nv)
        return _core.loops(self.model, q[self.compiled.q_index], self.loops)["basis"]

    def loop_error(self, q: np.ndarray) -> float:
        """Largest loop error at q (m; rad for the rotation of a frame loop), from Pinocchio's
        frame placements on the full model: nothing of pinsettle's loop code. 0 for a tree."""
        if not self.scene.loops:
            return 0.0
        if not np.all(np.isfinite(q)):
            return math.inf
        pinocchio.framesForwardKinematics(self.full, self.full_data, q)
        errors = []
        for loop in self.scene.loops:
            a = self.full_data.oMf[self.full.getFrameId(loop.a_frame)]
            b = self.full_data.oMf[self.full.getFrameId(loop.b_frame)]
            errors.append(a.act(np.asarray(loop.a_point)) - b.act(np.asarray(loop.b_point)))
            if loop.kind == "frame":
                errors.append(pinocchio.log3(a.rotation @ b.rotation.T))
        return float(np.max(np.abs(np.concatenate(errors))))

    def stiffness(self, q: np.ndarray) -> pinsettle.StabilityReport:
        """K (with loops: reduced, mobility x mobility, in the coordinates of ``basis``)."""
        return pinsettle.assess_stability(self.scene, q)

    def newton_step(self, q: np.ndarray, f: np.ndarray | None = None) -> np.ndarray:
        """Newton's step from q (dim nv of the free joints): dq = B lstsq(K, -B^T f), K and B
        from ``pinsettle.assess_stability`` (K reduced to the motions the loops allow, B their
        basis; the identity for a tree), rank cut 1e-10 so that neutral directions are left
        alone."""
        f = self.force(q) if f is None else f
        report = self.stiffness(q)
        B = report.basis
        return B @ np.linalg.lstsq(report.stiffness_matrix, -(B.T @ f), rcond=1e-10)[0]

    def time_scale(self, q: np.ndarray, scale_stiff_modes: bool = False) -> dict:
        return _core.time_scale(
            self.model, q[self.compiled.q_index], self.elements, scale_stiff_modes, self.loops
        )

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        M = pinocchio.crba(self.model, self.data, q[self.compiled.q_index])
        return np.triu(M) + np.triu(M, 1).T

"""The stability verdict recomputed for the tests, with numpy and pinocchio only: the stiffness
by central finite differences of a static force written outside pinsettle
(``pinocchio.computeGeneralizedGravity``, and a scene's springs and loads through
tests/scene_reference.py), restricted to the joints off their stops and, with loops or
couplings, to the motions they allow (a chart of the closed mechanism, differenced), then its
eigenvalues classified with the solver's own rule (README, "Stability verdict"): unstable when
the smallest is below -tol, neutral when one is within tol, stable otherwise, tol the larger of
1e-9 (1e-7 where the solver differences its stiffness) times the largest eigenvalue's size and
an absolute floor of round-off of the model's gravity scale.

An eigenvalue within the differences' error of a boundary can honestly go either way: the
verdicts the reference cannot tell apart are all returned, and a test accepts any of them.
Elsewhere exactly one is possible, and the solver's verdict must be that one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio
from scene_reference import Reference

Force = Callable[[np.ndarray], np.ndarray]

# Joint types whose motion subspace turns with their own configuration: the solver differences
# gravity's stiffness there (README: "by central finite differences on a model with a
# universal, ZYX-spherical or ellipsoid joint"), with the wider relative tolerance 1e-7.
VARYING = {
    "JointModelUniversal",
    "JointModelSphericalZYX",
    "JointModelEllipsoid",
    "JointModelComposite",
}


def has_varying_joints(model: pinocchio.Model) -> bool:
    return any(joint.shortname() in VARYING for joint in model.joints)


def gravity_scale(model: pinocchio.Model) -> float:
    """sum_i m_i |g| times the longest lever the model can have (its joint offsets summed, plus
    the largest centre-of-mass offset), in J: the size of the terms gravity's stiffness is summed
    from, hence of its round-off."""
    mass = sum(model.inertias[j].mass for j in range(1, model.njoints))
    reach = sum(
        np.linalg.norm(model.jointPlacements[j].translation) for j in range(1, model.njoints)
    )
    lever = max(
        (np.linalg.norm(model.inertias[j].lever) for j in range(1, model.njoints)), default=0
    )
    return float(mass * np.linalg.norm(model.gravity.linear) * (reach + lever))


def _differences(force: Force, move: Callable[[np.ndarray, float], np.ndarray], n: int, h: float):
    """Central differences of force along n directions: column k is
    (force(move(e_k, h)) - force(move(e_k, -h))) / 2h."""
    columns = []
    for k in range(n):
        e = np.zeros(n)
        e[k] = 1.0
        columns.append((force(move(e, h)) - force(move(e, -h))) / (2.0 * h))
    return np.array(columns).T


def richardson_jacobian(
    force: Force, move: Callable[[np.ndarray, float], np.ndarray], n: int, h: float = 1e-3
) -> tuple[np.ndarray, float]:
    """d force / d s along n directions (move(e, t): the configuration t along e), by central
    differences extrapolated (Richardson: the h^2 error cancels), and an estimate of its error
    (spectral norm): ten times the gap between the extrapolations from (h, 2h) and (h/2, h).
    With h = 1e-3 the error is ~1e-12 of the force's terms (round-off over h, the h^4 term),
    far below the 1e-6 step's ~2e-10 (round-off alone)."""
    d_half, d_one, d_two = (_differences(force, move, n, t) for t in (h / 2, h, 2 * h))
    fine = (4.0 * d_half - d_one) / 3.0
    coarse = (4.0 * d_one - d_two) / 3.0
    gap = float(np.linalg.norm(fine - coarse, 2)) if n else 0.0
    return fine, 10.0 * gap


@dataclass
class Verdict:
    """The reference's eigenvalues (ascending, of the symmetric part of the stiffness on the
    motions left free), their error bound, the band of tolerances the solver may use, and the
    verdicts consistent with them."""

    eigenvalues: np.ndarray
    noise: float
    tolerances: tuple[float, float]
    possible: set[str]
    stiffness: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    force: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: The largest pull a stop would have to exert (N m or N; 0 when every stop pushes).
    pull: float = 0.0

    @property
    def decided(self) -> bool:
        return len(self.possible) == 1

    @property
    def residual(self) -> float:
        """The residual of a rest: the largest static force along the free motions and the
        largest pull asked of a stop (N m or N)."""
        return max(float(np.max(np.abs(self.force), initial=0.0)), self.pull)

    def stiff_residual(self) -> float:
        """The largest component of the static force along the eigenvectors whose stiffness is
        clear of the solver's widest tolerance (plus the noise): what Newton's step removes
        (N m or N). Along the others a rest may keep a force its energy bounds."""
        if self.force.size == 0:
            return 0.0
        values, vectors = np.linalg.eigh(self.stiffness)
        stiff = np.abs(values) > self.tolerances[1] + self.noise
        return float(np.max(np.abs(vectors[:, stiff].T @ self.force), initial=0.0))

    def rest_energy(self) -> float:
        """Potential energy left to release before the rest: 1/2 f^T K^-1 f over the
        eigenvectors of the stiffness, each eigenvalue taken at least the solver's widest
        tolerance plus the noise (J; infinity where the force pulls along a direction of
        negative stiffness beyond that)."""
        if self.force.size == 0:
            return 0.0
        values, vectors = np.linalg.eigh(self.stiffness)
        along = vectors.T @ self.force
        floor = self.tolerances[1] + self.noise
        if np.any((values < -floor) & (along != 0.0)):
            return math.inf
        return float(0.5 * np.sum(along**2 / np.maximum(values, floor)))

    def check(self, verdict: str, min_eigenvalue: float | None = None) -> None:
        """The solver's verdict is one of the possible ones, and its smallest eigenvalue (when
        given, with motions left) is the reference's within the noise and the solver's own
        band."""
        assert str(verdict) in self.possible, (str(verdict), self)
        if min_eigenvalue is not None and self.eigenvalues.size:
            allowed = self.noise + self.tolerances[1]
            assert abs(min_eigenvalue - self.eigenvalues[0]) <= allowed, (min_eigenvalue, self)


def classify(
    eigenvalues: np.ndarray,
    noise: float,
    relative: tuple[float, float],
    floor: tuple[float, float],
    stiffness: np.ndarray | None = None,
    force: np.ndarray | None = None,
) -> Verdict:
    """The verdicts the solver's rule can give for eigenvalues known within noise, with a
    relative tolerance and an absolute floor anywhere in the given (low, high) bands. No motion
    left (every joint held): stable, as the solver says."""
    eigenvalues = np.sort(np.asarray(eigenvalues, float))
    n = eigenvalues.size
    stiffness = np.diag(eigenvalues) if stiffness is None else stiffness
    force = np.zeros(n) if force is None else np.asarray(force, float)
    if n == 0:
        return Verdict(eigenvalues, noise, (0.0, 0.0), {"stable"}, stiffness, force)
    top = float(np.max(np.abs(eigenvalues)))
    low = max(relative[0] * max(top - noise, 0.0), floor[0])
    high = max(relative[1] * (top + noise), floor[1])
    smallest = float(eigenvalues[0])
    nearest_zero = float(np.min(np.abs(eigenvalues)))
    possible = set()
    # The verdict moves from stable or unstable to neutral as the tolerance grows: the two ends
    # of the band and the eigenvalues' error bound every case.
    if smallest - noise < -low:
        possible.add("unstable")
    if smallest + noise > low:
        possible.add("stable")
    if smallest + noise >= -high and nearest_zero - noise <= high:
        possible.add("neutral")
    return Verdict(eigenvalues, noise, (low, high), possible, stiffness, force)


def solver_bands(
    model: pinocchio.Model, differenced: bool, extra_scale: float = 0.0
) -> tuple[tuple[float, float], tuple[float, float]]:
    """(relative band, absolute floor band) of the solver's tolerance: relative 1e-9, or up to
    1e-7 where it may difference its stiffness (joints whose axes turn, scene elements, loops
    and couplings); an absolute floor of 1e-13 of the gravity scale, round-off of the terms K
    is summed from, up to 1e-7 of the scale with the elements' share (extra_scale, J) where it
    may difference (a central difference of step 1e-6 divides the round-off by it)."""
    low = 1e-13 * gravity_scale(model) + 1e-300
    if differenced or has_varying_joints(model):
        return (1e-9, 1e-7), (low, 1e-7 * (gravity_scale(model) + extra_scale) + 1e-300)
    return (1e-9, 1e-9), (low, 1e-13 * (gravity_scale(model) + extra_scale) + 1e-300)


def tree_verdict(
    model: pinocchio.Model,
    force: Force,
    q: np.ndarray,
    free: Sequence[int] | None = None,
    differenced: bool = False,
    extra_scale: float = 0.0,
) -> Verdict:
    """The verdict of a tree at q: K = d force / dq along each tangent direction
    (pinocchio.integrate), its symmetric part restricted to the velocity indices ``free``."""

    def move(e: np.ndarray, t: float) -> np.ndarray:
        return pinocchio.integrate(model, q, t * e)

    k, noise = richardson_jacobian(force, move, model.nv)
    free = list(range(model.nv)) if free is None else list(free)
    k = k[np.ix_(free, free)]
    symmetric = 0.5 * (k + k.T)
    eigenvalues = np.linalg.eigvalsh(symmetric)
    # The solver's own stiffness: gravity's analytic derivatives and the elements' closed form
    # are exact to round-off (2e-16 of the terms' size, 1e-14 here); on joints whose axes turn
    # it differences with a 1e-6 step, whose error (~2e-10 of the terms' size) counts too.
    scale = gravity_scale(model) + extra_scale
    noise += (3e-10 if has_varying_joints(model) else 1e-14) * scale
    relative, floor = solver_bands(model, differenced, extra_scale)
    return classify(eigenvalues, noise, relative, floor, symmetric, force(q)[free])


def null_space(a: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(orthonormal basis of a's null space, of its row space), rank cut at 1e-9 of the largest
    singular value (as the solver cuts its loop Jacobian)."""
    if a.size == 0:
        return np.eye(n), np.zeros((n, 0))
    _, sigma, vt = np.linalg.svd(a)
    rank = int(np.sum(sigma > 1e-9 * sigma[0])) if sigma.size else 0
    return vt[rank:].T, vt[:rank].T


def manifold_verdict(
    model: pinocchio.Model,
    force: Force,
    constraints: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    q: np.ndarray,
    extra_scale: float = 0.0,
) -> Verdict:
    """The verdict of a rest q of a closed mechanism: constraints(q) gives the errors c(q) and
    their Jacobian along the tangent; the allowed motions N (orthonormal) are its null space. A
    chart phi(s) = integrate(q, N s + R y(s)) with R the row space and y(s) solved by Newton so
    that c(phi(s)) = 0; the gradient of the potential along it, phi'(s)^T force(phi(s)) with
    phi' from J (dIntegrate (N + R y')) = 0, differenced in s. At a rest this is N^T K N minus
    the reactions' curvature, the solver's reduced stiffness in the same basis."""
    _, jacobian = constraints(q)
    basis, rows = null_space(jacobian, model.nv)

    def chart(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        y = np.zeros(rows.shape[1])
        best = math.inf
        for _ in range(50):
            w = basis @ s + rows @ y
            point = pinocchio.integrate(model, q, w)
            error, jac = constraints(point)
            size = float(np.max(np.abs(error), initial=0.0))
            if size < 1e-15 or (size < 1e-12 and size >= best):
                break  # closed, or round-off stops Newton
            best = min(best, size)
            d_int = pinocchio.dIntegrate(model, q, w, pinocchio.ARG1)
            y -= np.linalg.lstsq(jac @ d_int @ rows, error, rcond=None)[0]
        else:
            raise AssertionError(f"the chart does not close at s = {s}: error {error}")
        d_int = pinocchio.dIntegrate(model, q, w, pinocchio.ARG1)
        along = jac @ d_int
        y_prime = -np.linalg.lstsq(along @ rows, along @ basis, rcond=None)[0]
        return point, d_int @ (basis + rows @ y_prime)

    def gradient(s: np.ndarray) -> np.ndarray:
        point, tangent = chart(s)
        return tangent.T @ force(point)

    k, noise = richardson_jacobian(gradient, lambda e, t: t * e, basis.shape[1])
    symmetric = 0.5 * (k + k.T)
    eigenvalues = np.linalg.eigvalsh(symmetric) if k.size else np.zeros(0)
    scale = gravity_scale(model) + extra_scale
    noise += 1e-9 * scale
    relative, floor = solver_bands(model, True, extra_scale)
    return classify(eigenvalues, noise, relative, floor, symmetric, basis.T @ force(q))


# --- scenes ------------------------------------------------------------------------------------


def element_scale(ref: Reference, model: pinocchio.Model, q: np.ndarray) -> float:
    """The elements' share of the force terms' size (J): what the springs and loads add to the
    static force at q, over the model's reach."""
    gravity = pinocchio.computeGeneralizedGravity(model, model.createData(), q)
    applied = np.max(np.abs(ref.force_reduced(model, q) - gravity), initial=0.0)
    reach = 1.0 + sum(np.linalg.norm(p.translation) for p in model.jointPlacements)
    springs = sum(s[4] for s in ref.springs) * reach**2 + sum(s[1] for s in ref.joint_springs)
    return float(applied * reach + springs)


def _stop_rows(
    model: pinocchio.Model, ref: Reference, q: np.ndarray
) -> list[tuple[str, int, float]]:
    """The joints at a stop at q: (name, velocity index, side: +1 lower, -1 upper)."""
    out = []
    for name, (low, high) in ref.stops(model).items():
        j = model.getJointId(name)
        x = q[model.idx_qs[j]]
        if x <= low:
            out.append((name, model.idx_vs[j], 1.0))
        elif x >= high:
            out.append((name, model.idx_vs[j], -1.0))
    return out


def scene_verdict(
    ref: Reference,
    q_full: np.ndarray,
    couplings: Sequence[tuple[str, str, float, float]] = (),
) -> Verdict:
    """The verdict of a scene at a rest q_full (the reference's physics): joints pressed on a
    stop (reaction beyond 1e-9 of the largest static force, as the solver counts them) held;
    with loops or couplings (follower, leader, multiplier, offset) the motions they allow."""
    model = ref.reduced(q_full)
    q = ref.to_reduced(model, q_full)

    def force(x: np.ndarray) -> np.ndarray:
        return ref.force_reduced(model, x)

    tau = force(q)
    tolerance = 1e-9 * float(np.max(np.abs(tau), initial=0.0))
    on_stops = _stop_rows(model, ref, q)
    closed = bool(ref.loops or couplings)
    extra = element_scale(ref, model, q)
    elements = bool(ref.springs or ref.joint_springs or ref.joint_loads or ref.point_loads)

    def coupling_rows(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        errors, rows = [], []
        for follower, leader, multiplier, offset in couplings:
            jf, jl = model.getJointId(follower), model.getJointId(leader)
            errors.append(x[model.idx_qs[jf]] - multiplier * x[model.idx_qs[jl]] - offset)
            row = np.zeros(model.nv)
            row[model.idx_vs[jf]] = 1.0
            row[model.idx_vs[jl]] = -multiplier
            rows.append(row)
        return np.array(errors), np.array(rows).reshape(len(rows), model.nv)

    def closure(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        parts = [coupling_rows(x)]
        if ref.loops:
            parts.append(ref.loop_jacobian(model, x))
        return (
            np.concatenate([p[0] for p in parts]),
            np.vstack([p[1] for p in parts]).reshape(-1, model.nv),
        )

    if not closed:
        held = set()
        for _, iv, side in on_stops:
            if side * tau[iv] > tolerance:  # the stop pushes: its reaction
                held.add(iv)
        free = [i for i in range(model.nv) if i not in held]
        differenced = elements  # the solver may difference the elements' share
        return tree_verdict(model, force, q, free, differenced, extra)
    # Closed: the stops' reactions mu and the closure's lambda balance tau together
    # (least squares, J^T lambda + E^T mu = tau); a stop pushing beyond the tolerance holds its
    # joint still.
    _, jacobian = closure(q)
    e = np.zeros((len(on_stops), model.nv))
    for k, (_, iv, _) in enumerate(on_stops):
        e[k, iv] = 1.0
    stacked = np.vstack([jacobian, e])
    multipliers = np.linalg.lstsq(stacked.T, tau, rcond=None)[0]
    mu = multipliers[jacobian.shape[0] :]
    held = [iv for k, (_, iv, side) in enumerate(on_stops) if side * mu[k] > tolerance]
    pull = max((-side * mu[k] for k, (_, _, side) in enumerate(on_stops)), default=0.0)

    def constraints(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        errors, rows = closure(x)
        for iv in held:
            # A 1-DoF joint of one coordinate: held at its value at the rest.
            j = next(j for j in range(1, model.njoints) if model.idx_vs[j] == iv)
            errors = np.append(errors, x[model.idx_qs[j]] - q[model.idx_qs[j]])
            row = np.zeros(model.nv)
            row[iv] = 1.0
            rows = np.vstack([rows, row])
        return errors, rows

    verdict = manifold_verdict(model, force, constraints, q, extra)
    verdict.pull = max(pull, 0.0)
    return verdict


def gravity_force(model: pinocchio.Model) -> Force:
    data = model.createData()
    return lambda q: pinocchio.computeGeneralizedGravity(model, data, q).copy()


def model_verdict(model: pinocchio.Model, q: np.ndarray, limits: bool = True) -> Verdict:
    """The verdict of a bare pinocchio.Model under gravity at q (with its own position limits as
    stops when ``limits``)."""
    return scene_verdict(Reference(model, limits=limits), q)


def describe(verdict: Verdict) -> str:
    return (
        f"possible {sorted(verdict.possible)}, eigenvalues {verdict.eigenvalues}, "
        f"noise {verdict.noise:.3g}, tolerance {verdict.tolerances[0]:.3g}.."
        f"{verdict.tolerances[1]:.3g}"
    )


__all__ = [
    "Verdict",
    "classify",
    "describe",
    "gravity_force",
    "gravity_scale",
    "manifold_verdict",
    "model_verdict",
    "scene_verdict",
    "solver_bands",
    "tree_verdict",
]

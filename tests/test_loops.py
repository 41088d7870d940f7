"""Closed loops: the robots/ loop scenes against independent answers, the constrained residual
and stiffness recomputed outside the solver, and bad loop definitions."""

from __future__ import annotations

import functools
import math
import re
from pathlib import Path

import loop_reference  # tests/loop_reference.py (pytest puts tests/ on sys.path)
import numpy as np
import pinocchio
import pinsettle
import pytest
from scene_reference import Reference
from scipy.optimize import minimize

ROBOTS = Path(__file__).resolve().parent.parent / "robots"
LOOP_SCENES = list(loop_reference.MECHANISMS)


def load(name: str) -> pinsettle.Scene:
    return pinsettle.load_scene(ROBOTS / f"{name}.toml")


# --- the physics written out with Pinocchio's frames (tests/scene_reference.py) ---------------


def reference(name: str) -> Reference:
    return Reference.from_toml(ROBOTS / f"{name}.toml")


def loop_jacobian(ref: Reference, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return ref.loop_jacobian(ref.full, q)


def allowed_motions(ref: Reference, q: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the null space of the loop Jacobian (numpy's SVD)."""
    _, J = loop_jacobian(ref, q)
    _, s, vt = np.linalg.svd(J)
    rank = int(np.sum(s > 1e-9 * s[0]))
    return vt[rank:].T


def reduced_residual(ref: Reference, q: np.ndarray) -> float:
    N = allowed_motions(ref, q)
    return float(np.max(np.abs(N.T @ ref.force(q))))


def potential(ref: Reference, q: np.ndarray) -> float:
    """Gravity, springs, and the constant loads' potential (conservative here)."""
    return ref.potential_reduced(ref.full, q, loads=True)


def slsqp_equilibrium(
    ref: Reference, q_start: np.ndarray, free: np.ndarray | None = None
) -> np.ndarray:
    """Minimum of the potential subject to the loops (scipy SLSQP) from q_start, over the
    configuration entries ``free`` (all by default; the others stay as in q_start)."""
    free = np.arange(q_start.size) if free is None else free

    def full(x: np.ndarray) -> np.ndarray:
        q = q_start.copy()
        q[free] = x
        return q

    # SLSQP needs independent equations: drop the rows no motion changes (the out-of-plane
    # rows of a planar loop).
    rows = np.linalg.norm(loop_jacobian(ref, q_start)[1][:, free], axis=1) > 1e-9
    result = minimize(
        lambda x: potential(ref, full(x)),
        q_start[free],
        constraints=[{"type": "eq", "fun": lambda x: loop_jacobian(ref, full(x))[0][rows]}],
        method="SLSQP",
        options={"ftol": 1e-16, "maxiter": 1000},
    )
    return full(result.x)


# --- the robots/ loop scenes ------------------------------------------------------------------


@pytest.fixture(scope="module", params=LOOP_SCENES)
def solved(request):
    scene = load(request.param)
    return scene, pinsettle.solve(scene, polish=True), reference(request.param)


def test_loop_scene_converges_on_its_loops(solved) -> None:
    scene, r, ref = solved
    assert r.converged, r.summary()
    assert r.loops == len(scene.loops) >= 1
    assert r.mobility == 1
    assert r.constraint_error < 1e-10
    # Recomputed outside the solver: the loops close and the static force has no component
    # along the motions they allow, although the tree alone is far from balanced.
    assert np.max(np.abs(loop_jacobian(ref, r.q)[0])) < 1e-10
    scale = np.max(np.abs(ref.force(scene.assemble()[0])))
    assert reduced_residual(ref, r.q) < 1e-9 * scale
    assert np.max(np.abs(ref.force(r.q))) > 1e-3 * scale
    assert r.stability == "stable"


def test_loop_scene_matches_closed_form(solved) -> None:
    """Planar position analysis and the potential's stationary point in one angle
    (tests/loop_reference.py: numpy and scipy only)."""
    scene, r, _ = solved
    mechanism = loop_reference.MECHANISMS[scene.name]()
    ref = mechanism.equilibrium(r.joints[mechanism.driver], 0.1)
    assert ref.pop("stable") is True
    for joint, value in ref.items():
        assert r.joints[joint] == pytest.approx(value, abs=1e-8), joint
    # The reference's potential curvature in the driving angle against the solver's reduced
    # stiffness: K_r is the curvature per unit of the allowed motion n, the driving angle
    # moves n[driver] per unit.
    report = pinsettle.assess_stability(scene, r.q)
    driver = scene.model.idx_vs[scene.model.getJointId(mechanism.driver)]
    n_driver = report.basis[driver, 0]
    curvature = mechanism.curvature(ref[mechanism.driver])
    assert report.stiffness_matrix[0, 0] == pytest.approx(curvature * n_driver**2, rel=1e-4)


@pytest.mark.parametrize("name", LOOP_SCENES)
def test_loop_scene_header_states_the_closed_form(name: str) -> None:
    """The numbers in the scene file's "Expected:" header are the closed form's."""
    header = (ROBOTS / f"{name}.toml").read_text().split("[model]")[0]
    assert "Expected: converged, stable" in header
    mechanism = loop_reference.MECHANISMS[name]()
    stated = {
        joint: float(value)
        for joint, value in re.findall(r"(\w+_joint) = (-?\d+\.\d+)", header.split("Another")[0])
    }
    ref = mechanism.equilibrium(stated[mechanism.driver], 0.01)
    assert set(stated) == set(ref) - {"stable"}
    for joint, value in stated.items():
        assert value == pytest.approx(ref[joint], abs=1e-6), joint


def test_loop_scene_matches_constrained_minimisation(solved) -> None:
    """An independent route: scipy's SLSQP on the potential with the loop equations."""
    _, r, ref = solved
    q_ref = slsqp_equilibrium(ref, r.q + 0.02)
    assert np.max(np.abs(q_ref - r.q)) < 1e-5


def test_loop_reduced_stiffness_is_the_potentials_curvature(solved) -> None:
    """K restricted to the loops against the second difference of the potential along the
    path projected onto the loops (a different route from the solver's reactions)."""
    scene, r, ref = solved
    report = pinsettle.assess_stability(scene, r.q)
    assert report.stiffness_matrix.shape == (1, 1)
    n = report.basis[:, 0]
    theirs = allowed_motions(ref, r.q)[:, 0]
    assert np.allclose(n, theirs * np.sign(n @ theirs), atol=1e-9)

    def along(s: float) -> float:
        q = pinocchio.integrate(scene.model, r.q, s * n)
        return potential(ref, scene.assemble(q)[0])

    # h = 1e-3: the assembled path carries the assembly's round-off (about 1e-12 J of potential),
    # which a second difference divides by h^2 (at 1e-4 that is already 1e-4 relative on the
    # four-bar); the truncation error at 1e-3 is 1e-6 relative.
    h = 1e-3
    curvature = (along(h) - 2 * along(0.0) + along(-h)) / h**2
    assert curvature > 0
    assert report.stiffness_matrix[0, 0] == pytest.approx(curvature, rel=1e-5)


@functools.cache
def polished(name: str) -> np.ndarray:
    return pinsettle.solve(load(name), polish=True).q


@pytest.mark.parametrize("name", LOOP_SCENES)
@pytest.mark.parametrize("energy", ["exact", "simplified"])
@pytest.mark.parametrize("kt", [0.0, 0.5, 0.9])
def test_loop_scene_settings(name: str, energy: str, kt: float) -> None:
    r = pinsettle.solve(load(name), energy=energy, kt=kt)
    assert r.converged, r.summary()
    assert r.constraint_error < 1e-10
    assert np.max(np.abs(r.q - polished(name))) < 1e-5


def test_loop_scene_start_is_assembled_and_reported() -> None:
    scene = load("fourbar")
    q_start = scene.q0()
    assert np.max(np.abs(scene.loop_error(q_start))) > 1e-6  # the file's start is approximate
    q, moved = scene.assemble()
    assert np.max(np.abs(scene.loop_error(q))) < 1e-12
    assert moved == pytest.approx(np.max(np.abs(pinocchio.difference(scene.model, q_start, q))))
    r = pinsettle.solve(scene)
    assert r.assembly_distance == pytest.approx(moved, rel=1e-9)
    assert "loops" in r.summary() and "to assemble" in r.summary()
    assert r.to_dict()["constraint_error"] == r.constraint_error


def test_redundant_point_loop_rank() -> None:
    """A planar loop closed by a 3-D point constraint: 3 equations, 2 independent."""
    scene = load("fourbar")
    q = scene.assemble()[0]
    _, J = loop_jacobian(reference("fourbar"), q)
    assert J.shape == (3, 3)
    assert np.linalg.matrix_rank(J, tol=1e-9 * np.linalg.norm(J)) == 2
    assert scene.mobility() == 1


def test_weld_loop_against_constrained_minimisation(tmp_path: Path) -> None:
    """A 'frame' loop: a planar 5-link chain whose last link is welded to the world where it
    starts, so that two degrees of freedom remain; gravity pulls it into a sagging pose."""
    model = pinocchio.buildModelFromUrdf(str(ROBOTS / "chain20.urdf"))
    q_weld = np.zeros(model.nq)
    q_weld[:5] = [1.2, -0.6, -0.5, -0.4, 0.3]  # joint5 makes link5 level with the world
    q_weld[4] = -sum(q_weld[:4])
    locked = [f"joint{k}" for k in range(6, 21)]
    scene = pinsettle.Scene(model, limits=False)  # the URDF's +-100 rad limits are no stops
    scene.lock(*locked)
    data = model.createData()
    pinocchio.framesForwardKinematics(model, data, q_weld)
    where = data.oMf[model.getFrameId("link5")].translation
    scene.add_loop({"frame": "link5"}, {"frame": "universe", "point": list(where)}, "frame")
    scene.set_start({f"joint{k}": q_weld[k - 1] + 0.01 for k in range(1, 6)})
    assert scene.mobility() == 2
    r = pinsettle.solve(scene, polish=True)
    assert r.converged and r.mobility == 2, r.summary()
    assert r.constraint_error < 1e-10
    ref = Reference(
        model, locked=locked, loops=[("link5", np.zeros(3), "universe", where, "frame")]
    )
    q_ref = slsqp_equilibrium(ref, r.q, free=np.arange(5))
    assert np.max(np.abs(q_ref - r.q)) < 1e-5
    assert r.stability in ("stable", "neutral")


# --- bad loop definitions ---------------------------------------------------------------------


def _scene_file(tmp_path: Path, loop: str, start: str = "") -> Path:
    path = tmp_path / "bad.toml"
    path.write_text(
        f'[model]\nurdf = "{ROBOTS / "fourbar.urdf"}"\n'
        + (f"[start]\n{start}\n" if start else "")
        + f"[[loop]]\n{loop}\n"
    )
    return path


GOOD_ENDS = (
    'a = { frame = "coupler", point = [0.4, 0.0, 0.0] }\n'
    'b = { frame = "rocker", point = [0.3, 0.0, 0.0] }'
)


@pytest.mark.parametrize(
    "loop, expected",
    [
        (
            'a = { frame = "coupler", point = [0.4, 0.0, 0.0] }\n'
            'b = { frame = "rockr", point = [0.3, 0.0, 0.0] }',
            ["[[loop]] #1", "b.frame", "unknown frame 'rockr'", "did you mean 'rocker'"],
        ),
        (GOOD_ENDS + '\nkind = "hinge"', ["[[loop]] #1", "kind", "'point' or 'frame'", "hinge"]),
        (GOOD_ENDS + "\nstiffness = 3.0", ["[[loop]] #1", "unknown key 'stiffness'"]),
        ('a = { frame = "coupler" }', ["[[loop]] #1", "missing key 'b'"]),
        ('a = "coupler"\nb = "rocker"', ["[[loop]] #1", "a must be an inline table"]),
        (
            'a = { frame = "coupler", point = [0.4, 0.0] }\nb = { frame = "rocker" }',
            ["[[loop]] #1", "a.point", "3 entries"],
        ),
        (
            'a = { frame = "crank" }\nb = { frame = "crank", point = [0.1, 0.0, 0.0] }',
            ["[[loop]] #1", "same rigid body"],
        ),
        (
            # The coupler's end cannot reach a point 2 m away.
            'a = { frame = "coupler", point = [0.4, 0.0, 0.0] }\n'
            'b = { frame = "universe", point = [2.0, 0.0, 0.0] }',
            ["cannot assemble", "[[loop]] #1", "apart"],
        ),
        (
            # The four-bar with its crank welded to the world: a structure.
            GOOD_ENDS + '\n[[loop]]\na = { frame = "crank" }\nb = { frame = "universe" }\n'
            'kind = "frame"',
            ["no degree of freedom"],
        ),
    ],
)
def test_bad_loop_definitions(tmp_path: Path, loop: str, expected: list[str]) -> None:
    start = "crank_joint = 0.0\ncoupler_joint = 1.0\nrocker_joint = 1.9"
    path = _scene_file(tmp_path, loop, start=start)
    with pytest.raises(pinsettle.SceneError) as info:
        pinsettle.load_scene(path)
    message = str(info.value)
    assert str(path) in message
    for part in expected:
        assert part in message, message


def test_bad_loops_from_python() -> None:
    # The URDF's +-100 rad limits off: they are no stops.
    scene = pinsettle.Scene.from_urdf(ROBOTS / "fourbar.urdf", limits=False)
    with pytest.raises(pinsettle.SceneError, match="kind must be 'point' or 'frame'"):
        scene.add_loop("coupler", "rocker", kind="weld")
    with pytest.raises(pinsettle.SceneError, match="unknown frame 'nope'"):
        scene.add_loop("nope", "rocker")
    scene.add_loop(("coupler", [0.4, 0, 0]), ("universe", [5.0, 0, 0]))
    with pytest.raises(ValueError, match="cannot assemble"):
        pinsettle.solve(scene)
    with pytest.raises(pinsettle.SceneError, match="cannot assemble"):
        scene.assemble()


def test_tree_scene_pays_nothing_for_loops() -> None:
    """A scene without loops reports no loop fields and steps exactly as before (same steps
    and pose as the pendulum's plain model)."""
    scene = pinsettle.load_scene(ROBOTS / "pendulum.toml")
    r = pinsettle.solve(scene)
    plain = pinsettle.solve(scene.model, scene.q0(), scene.settings)
    assert r.loops == 0 and r.constraint_error == 0.0 and r.assembly_distance == 0.0
    assert r.steps == plain.steps and np.array_equal(r.q, plain.q)
    assert "loops" not in r.summary()
    assert math.isclose(r.mobility, scene.model.nv)

"""Mimic joints (URDF ``<mimic>`` tags) solved as what they are: a linear coupling
q_follower = multiplier * q_leader + offset of the coupled mechanism.

The reference is independent of pinsettle's code: the coupled mechanism's potential
V(theta) = V_free(theta, multiplier * theta + offset), from Pinocchio's potential energy of the
model without the coupling (``mimic=False``), whose stationary points are found by scipy on a
finite-difference derivative; a rest is stable where V'' > 0. A second check is Pinocchio's own
rnea on the ``mimic=True`` model (it supports mimic joints: the chain rule
tau_leader + multiplier * tau_follower), which must vanish at a rest.
"""

from __future__ import annotations

import math
import subprocess
import sys
import warnings
from pathlib import Path

import loop_reference  # tests/loop_reference.py (pytest puts tests/ on sys.path)
import numpy as np
import pinocchio
import pinsettle
import pytest
from pinsettle import Scene, SceneError, load_scene
from scipy.optimize import brentq

MULTIPLIER, OFFSET = -1.5, 0.25
ROBOTS = Path(__file__).parents[1] / "robots"

# A two-link arm in the x-z plane, hanging under gravity; joint2 follows joint1. The second
# link's mass is off its axis so that the coupled potential has several wells.
ARM_URDF = """<?xml version="1.0"?>
<robot name="mimic_arm">
  <link name="base"/>
  <link name="link1">
    <inertial>
      <origin xyz="0.05 0 -0.25"/>
      <mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
    </inertial>
  </link>
  <link name="link2">
    <inertial>
      <origin xyz="0.1 0 -0.3"/>
      <mass value="2.0"/>
      <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/>
    </inertial>
  </link>
  <joint name="joint1" type="revolute">
    <parent link="base"/>
    <child link="link1"/>
    <axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/>
  </joint>
  <joint name="follower" type="revolute">
    <parent link="link1"/>
    <child link="link2"/>
    <origin xyz="0 0 -0.5"/>
    <axis xyz="0 1 0"/>
    <limit lower="-6" upper="6" effort="10" velocity="1"/>
    <mimic joint="joint1" multiplier="{multiplier}" offset="{offset}"/>
  </joint>
</robot>
"""


@pytest.fixture(scope="module")
def arm_urdf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("mimic") / "mimic_arm.urdf"
    path.write_text(ARM_URDF.format(multiplier=MULTIPLIER, offset=OFFSET), encoding="utf-8")
    return path


def _potential(free: pinocchio.Model, theta: float) -> float:
    """V of the coupled arm at leader angle theta (Pinocchio's potential energy, mimic=False)."""
    data = free.createData()
    return float(
        pinocchio.computePotentialEnergy(free, data, np.array([theta, MULTIPLIER * theta + OFFSET]))
    )


def _dv(free: pinocchio.Model, theta: float, h: float = 1e-5) -> float:
    return (_potential(free, theta + h) - _potential(free, theta - h)) / (2 * h)


def _d2v(free: pinocchio.Model, theta: float, h: float = 1e-4) -> float:
    return (
        _potential(free, theta + h) - 2 * _potential(free, theta) + _potential(free, theta - h)
    ) / h**2


# With multiplier -1.5 the coupled arm's configuration repeats every 4 pi of its leader.
PERIOD = 4 * np.pi


def _reference_rests(free: pinocchio.Model) -> list[tuple[float, bool]]:
    """Every stationary point of the coupled potential over one period: (theta, stable)."""
    grid = np.linspace(-PERIOD / 2, PERIOD / 2, 1441)
    slope = [_dv(free, t) for t in grid]
    rests = []
    for a, b, fa, fb in zip(grid[:-1], grid[1:], slope[:-1], slope[1:], strict=True):
        if fa == 0.0 or fa * fb < 0:
            theta = brentq(lambda t: _dv(free, t), a, b, xtol=1e-13)
            rests.append((theta, _d2v(free, theta) > 0))
    return rests


def _wrap(angle: float) -> float:
    return float((angle + PERIOD / 2) % PERIOD - PERIOD / 2)


def test_mimic_model_settles_at_a_minimum_of_the_coupled_potential(arm_urdf: Path) -> None:
    mimic = pinocchio.buildModelFromUrdf(str(arm_urdf), mimic=True)
    free = pinocchio.buildModelFromUrdf(str(arm_urdf))
    assert mimic.nq == 1 and free.nq == 2
    rests = _reference_rests(free)
    assert sum(stable for _, stable in rests) >= 1 and len(rests) >= 2  # wells and a hill

    for start in (-2.0, 0.0, 0.4, 2.0):
        result = pinsettle.solve(mimic, np.array([start]), limits=False)
        assert result.status == "converged", (start, result.status, result.reason)
        assert result.q.shape == (mimic.nq,) and result.v.shape == (mimic.nv,)
        theta = float(result.q[0])
        # Pinocchio's own rnea on the mimic model (the chain rule) vanishes there.
        g = pinocchio.computeGeneralizedGravity(mimic, mimic.createData(), result.q)
        scale = (
            float(
                np.max(
                    np.abs(
                        pinocchio.computeGeneralizedGravity(
                            mimic, mimic.createData(), np.array([start])
                        )
                    )
                )
            )
            or 1.0
        )
        assert abs(g[0]) <= 1e-8 * max(scale, 1.0), (start, g)
        # One of the reference's minima, found independently.
        nearest = min(rests, key=lambda r: abs(_wrap(r[0] - theta)))
        assert abs(_wrap(nearest[0] - theta)) < 1e-6, (start, theta, rests)
        assert nearest[1], f"from {start}: rest {theta} is not a minimum of V"
        assert result.stability == "stable"
        # The follower's value is consistent with the coupling.
        assert result.joints["follower"] == pytest.approx(MULTIPLIER * theta + OFFSET, abs=1e-12)
        assert result.joints["joint1"] == pytest.approx(theta, abs=0)


def test_stability_verdict_matches_the_curvature_of_the_coupled_potential(arm_urdf: Path) -> None:
    mimic = pinocchio.buildModelFromUrdf(str(arm_urdf), mimic=True)
    free = pinocchio.buildModelFromUrdf(str(arm_urdf))
    for theta, stable in _reference_rests(free):
        report = pinsettle.assess_stability(mimic, np.array([theta]), limits=False)
        assert report.verdict == ("stable" if stable else "unstable"), (theta, report)
        # The coupled stiffness is V'' (one motion: leader and follower together).
        assert report.eigenvalues.size == 1
        direction = report.basis[:, 0]
        assert direction.shape == (1,) and abs(direction[0]) > 0
        # basis is unit in the released coordinates: (1, multiplier) / norm.
        curvature = report.eigenvalues[0] * (1 + MULTIPLIER**2)
        assert curvature == pytest.approx(_d2v(free, theta), rel=1e-4, abs=1e-6)


def test_static_force_of_a_mimic_model_is_pinocchios_own(arm_urdf: Path) -> None:
    mimic = pinocchio.buildModelFromUrdf(str(arm_urdf), mimic=True)
    free = pinocchio.buildModelFromUrdf(str(arm_urdf))
    for theta in (-1.0, 0.3, 2.5):
        q = np.array([theta])
        ours = pinsettle.static_force(mimic, q)
        theirs = pinocchio.computeGeneralizedGravity(mimic, mimic.createData(), q)
        np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-12)
        # and the chain rule on the free model, and the potential's slope
        tau = pinocchio.computeGeneralizedGravity(
            free, free.createData(), np.array([theta, MULTIPLIER * theta + OFFSET])
        )
        assert ours[0] == pytest.approx(tau[0] + MULTIPLIER * tau[1], abs=1e-12)
        assert ours[0] == pytest.approx(_dv(free, theta), rel=1e-6, abs=1e-8)


def test_mimic_model_with_its_limits_rests_against_them_correctly(arm_urdf: Path) -> None:
    """The leader's limits (the mimic model keeps none for the follower): a rest is inside
    them with no force, or on one with the stop pushing, checked with Pinocchio's rnea."""
    mimic = pinocchio.buildModelFromUrdf(str(arm_urdf), mimic=True)
    for start in (-2.9, 2.9):
        result = pinsettle.solve(mimic, np.array([start]))
        assert result.converged, result.status
        theta = float(result.q[0])
        assert -3.0 <= theta <= 3.0
        g = float(pinocchio.computeGeneralizedGravity(mimic, mimic.createData(), result.q)[0])
        if theta <= -3.0:
            assert result.at_limit == {"joint1": "lower"} and g >= -1e-9
        elif theta >= 3.0:
            assert result.at_limit == {"joint1": "upper"} and g <= 1e-9
        else:
            assert result.at_limit == {} and abs(g) < 1e-8


def test_scene_of_a_mimic_model_keeps_the_coupling(arm_urdf: Path) -> None:
    mimic = pinocchio.buildModelFromUrdf(str(arm_urdf), mimic=True)
    scene = Scene(mimic, limits=False)
    assert scene.mimic_model is not None and scene.model.nq == 2
    assert [c.text() for c in scene.couplings] == [
        f"'follower' = {MULTIPLIER:g} * 'joint1' + {OFFSET:g}"
    ]
    assert any("mimic joints honoured as couplings" in note for note in scene.notes)
    result = pinsettle.solve(scene)
    assert result.converged and result.q.shape == (2,)
    assert result.q[1] == pytest.approx(MULTIPLIER * result.q[0] + OFFSET, abs=1e-12)
    g = pinocchio.computeGeneralizedGravity(mimic, mimic.createData(), result.q[:1])
    assert abs(g[0]) < 1e-8
    # The scene's residual and its static force (along the coupled motion) agree.
    assert scene.residual(result.q) < 1e-8


def test_urdf_scene_honours_mimic_tags_by_default_and_says_so(arm_urdf: Path) -> None:
    scene = Scene.from_urdf(arm_urdf, limits=False)
    assert len(scene.couplings) == 1
    assert any("honoured as joint couplings (mimic = true)" in note for note in scene.notes)
    # The start puts the follower where its leader says.
    q0 = scene.q0()
    assert q0[1] == pytest.approx(MULTIPLIER * q0[0] + OFFSET)
    result = pinsettle.solve(scene)
    assert result.converged
    assert result.q[1] == pytest.approx(MULTIPLIER * result.q[0] + OFFSET, abs=1e-12)
    free = scene.model
    tau = pinocchio.computeGeneralizedGravity(free, free.createData(), result.q)
    assert abs(tau[0] + MULTIPLIER * tau[1]) < 1e-8  # the chain rule, independently


def test_urdf_scene_with_mimic_false_ignores_the_tags_and_says_so(arm_urdf: Path) -> None:
    scene = Scene.from_urdf(arm_urdf, limits=False, mimic=False)
    assert scene.couplings == []
    assert any(
        "tags ignored (mimic = false" in note and "'follower'" in note for note in scene.notes
    )
    result = pinsettle.solve(scene, np.array([0.3, -1.0]))
    assert result.converged
    tau = pinocchio.computeGeneralizedGravity(scene.model, scene.model.createData(), result.q)
    assert np.max(np.abs(tau)) < 1e-8  # each joint at rest on its own


def test_load_urdf_warns_that_it_leaves_the_mimic_tags_out(arm_urdf: Path) -> None:
    # The plain model (each joint free, pinocchio.buildModelFromUrdf's default) is what
    # load_urdf returns: not silently, the warning names the follower and what couples it.
    with pytest.warns(UserWarning, match=r"'follower' \(follows 'joint1'\).*Scene\.from_urdf"):
        model = pinsettle.load_urdf(arm_urdf)
    assert model.nv == 2
    with pytest.warns(UserWarning, match=r"'panda_finger_joint2'.*Scene\.from_robot\('panda'\)"):
        pinsettle.load_robot("panda")


def test_what_couples_the_mimic_tags_or_has_none_does_not_warn(arm_urdf: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        Scene.from_urdf(arm_urdf, limits=False)
        Scene.from_robot("panda")
        pinsettle.load_robot("ur5")
        pinsettle.load_urdf(ROBOTS / "pendulum.urdf")


def _scene_file(tmp: Path, urdf: Path, mimic_line: str) -> Path:
    path = tmp / f"mimic_scene_{abs(hash(mimic_line))}.toml"
    path.write_text(
        f'# mimic arm\n[model]\nurdf = "{urdf.name}"\nlimits = false\n{mimic_line}\n',
        encoding="utf-8",
    )
    return path


def test_scene_file_mimic_key(arm_urdf: Path) -> None:
    tmp = arm_urdf.parent
    on = load_scene(_scene_file(tmp, arm_urdf, ""))
    assert len(on.couplings) == 1 and any("mimic = true" in n for n in on.notes)
    explicit = load_scene(_scene_file(tmp, arm_urdf, "mimic = true"))
    assert len(explicit.couplings) == 1
    off = load_scene(_scene_file(tmp, arm_urdf, "mimic = false"))
    assert off.couplings == [] and any("mimic = false" in n for n in off.notes)
    with pytest.raises(SceneError, match=r"\[model\] mimic must be true or false, got 'yes'"):
        load_scene(_scene_file(tmp, arm_urdf, 'mimic = "yes"'))


def test_cli_solve_of_a_urdf_says_which_it_chose(arm_urdf: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "pinsettle", "solve", str(arm_urdf), "--no-limits"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "<mimic> tags honoured as joint couplings" in out


def test_panda_fingers_move_together() -> None:
    """example-robot-data's Panda with mimic=True (finger_joint2 follows finger_joint1): the
    rest against the stops checked with Pinocchio's rnea on the mimic model."""
    path = pinsettle.robots.robot_urdf("panda")
    model = pinocchio.buildModelFromUrdf(str(path), mimic=True)
    assert any("Mimic" in j.shortname() for j in model.joints)
    result = pinsettle.solve(model)
    assert result.converged, (result.status, result.reason)
    assert result.q.shape == (model.nq,)
    assert result.joints["panda_finger_joint2"] == pytest.approx(
        result.joints["panda_finger_joint1"], abs=1e-12
    )
    g = pinocchio.computeGeneralizedGravity(model, model.createData(), result.q)
    scale = float(np.max(np.abs(g))) + 1.0
    for j in range(1, model.njoints):
        if model.nvs[j] == 0:
            continue
        iq, iv, name = model.idx_qs[j], model.idx_vs[j], model.names[j]
        lower, upper = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
        if result.q[iq] <= lower:
            assert g[iv] >= -1e-9 * scale, name  # the stop pushes up
        elif result.q[iq] >= upper:
            assert g[iv] <= 1e-9 * scale, name
        else:
            assert abs(g[iv]) <= 1e-8 * scale, (name, g[iv])


PENDULUM = """
  <link name="pendulum">
    <inertial>
      <origin xyz="0.125 0 0"/>
      <mass value="0.7"/>
      <inertia ixx="1e-5" ixy="0" ixz="0" iyy="0.0036458" iyz="0" izz="0.0036458"/>
    </inertial>
  </link>
  <joint name="pendulum_joint" type="revolute">
    <parent link="base"/>
    <child link="pendulum"/>
    <origin xyz="-0.3 0 0"/>
    <axis xyz="0 1 0"/>
    <limit lower="-100" upper="100" effort="10" velocity="1"/>
    <mimic joint="crank_joint" multiplier="0.5" offset="0.3"/>
  </joint>
</robot>"""


def test_mimic_joint_with_a_loop_rests_at_the_minimum_of_the_potential(tmp_path: Path) -> None:
    """robots/fourbar (crank spring, coupler load, a loop) with a pendulum whose joint follows
    the crank (0.5 crank + 0.3): the rest is the minimum of the four-bar's closed-form potential
    (tests/loop_reference.py) plus the pendulum's, m g z of its centre at that crank angle."""
    urdf = (ROBOTS / "fourbar.urdf").read_text(encoding="utf-8").replace("</robot>", PENDULUM)
    (tmp_path / "fourbar_pendulum.urdf").write_text(urdf, encoding="utf-8")
    toml = (ROBOTS / "fourbar.toml").read_text(encoding="utf-8")
    (tmp_path / "fourbar_pendulum.toml").write_text(
        toml.replace('"fourbar.urdf"', '"fourbar_pendulum.urdf"'), encoding="utf-8"
    )
    scene = load_scene(tmp_path / "fourbar_pendulum.toml")
    assert len(scene.couplings) == 1 and len(scene.loops) == 1
    result = pinsettle.solve(scene)
    assert result.converged, (result.status, result.reason)
    assert result.mobility == 1
    crank, pendulum = result.joints["crank_joint"], result.joints["pendulum_joint"]
    assert isinstance(crank, float) and isinstance(pendulum, float)
    assert pendulum == pytest.approx(0.5 * crank + 0.3, abs=1e-12)

    fourbar = loop_reference.fourbar()

    def potential(t: float) -> float:
        return fourbar.potential(t) + 0.7 * loop_reference.G * 0.125 * -math.sin(0.5 * t + 0.3)

    reference = loop_reference.Mechanism(fourbar.joints, potential, "crank_joint")
    rest = reference.equilibrium(crank)
    assert rest["stable"] and result.stability == "stable"
    for joint in ("crank_joint", "coupler_joint", "rocker_joint"):
        assert result.joints[joint] == pytest.approx(rest[joint], abs=1e-7), joint


def test_bad_couplings_are_refused_with_names(arm_urdf: Path) -> None:
    scene = Scene.from_urdf(arm_urdf, limits=False, mimic=False)
    with pytest.raises(SceneError, match="unknown joint 'nope'"):
        scene.add_coupling("nope", "joint1")
    with pytest.raises(SceneError, match="cannot follow itself"):
        scene.add_coupling("joint1", "joint1")
    with pytest.raises(SceneError, match="multiplier must be finite"):
        scene.add_coupling("follower", "joint1", float("nan"))
    scene.add_coupling("follower", "joint1", 2.0)
    with pytest.raises(SceneError, match="follows another joint already"):
        scene.add_coupling("follower", "joint1")
    scene.lock("joint1")
    with pytest.raises(SceneError, match="'joint1' is locked and the other is not"):
        pinsettle.solve(scene)


def test_continuous_mimic_joint_is_refused_with_its_name(tmp_path: Path) -> None:
    """A continuous joint stores its angle as (cos, sin): no linear coupling of q; refused
    naming the joint, from a mimic model and from a URDF scene alike."""
    text = ARM_URDF.format(multiplier=1.0, offset=0.0).replace(
        'type="revolute"', 'type="continuous"'
    )
    path = tmp_path / "continuous_mimic.urdf"
    path.write_text(text, encoding="utf-8")
    model = pinocchio.buildModelFromUrdf(str(path), mimic=True)  # a RUBY leader, follower
    with pytest.raises(ValueError, match="'follower'.*1-DoF joints"):
        pinsettle.solve(model, max_steps=10)
    with pytest.raises(SceneError, match="<mimic> tag of joint 'follower'.*2 configuration"):
        Scene.from_urdf(path)

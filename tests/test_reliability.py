"""Models the algorithms pinsettle runs do not support are refused, never crash the process.

A two-link arm whose second joint has a URDF ``<mimic>`` tag (as in most parallel grippers),
loaded with ``pinocchio.buildModelFromUrdf(path, mimic=True)``, holds a ``JointModelMimic``:
``pinocchio::aba`` does not support it and only asserts so (a segmentation fault in a release
build). ``solve``, ``assess_stability``, ``static_force`` and ``Scene`` answer for the coupled
mechanism (tests/test_mimic.py checks the answers against an independent reference; here the
residual and the verdict against Pinocchio's own gravity on the mimic model); every other entry
point that takes a model must refuse it with a ValueError that names the joint.
Each call runs in a subprocess of its own, so that a crash is a failing test here rather than
the end of pytest.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

MIMIC_URDF = """<?xml version="1.0"?>
<robot name="mimic_arm">
  <link name="base"/>
  <link name="link1">
    <inertial>
      <origin xyz="0 0 -0.25"/>
      <mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
    </inertial>
  </link>
  <link name="link2">
    <inertial>
      <origin xyz="0 0 -0.25"/>
      <mass value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>
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
    <limit lower="-3" upper="3" effort="10" velocity="1"/>
    <mimic joint="joint1" multiplier="-1.0" offset="0.0"/>
  </joint>
</robot>
"""

# Each call on the mimic model; `model` and `q` are defined in the child before it runs. Those
# that answer for the coupled arm, with what the child checks of their answer (Pinocchio's own
# rnea on the mimic model: the chain rule), and those that refuse it.
# The coupled arm's stiffness at a configuration x, by central differences of Pinocchio's own
# gravity on the mimic model (the chain rule tau_leader + multiplier * tau_follower, 1-DoF): its
# sign is the verdict (clear of the solver's band at the configurations used here), its value
# (1 + multiplier^2) times the solver's eigenvalue along the unit coupled direction.
STIFFNESS = (
    "stiffness = lambda x, h=1e-4: ("
    "pinocchio.computeGeneralizedGravity(model, model.createData(), x + h)[0] "
    "- pinocchio.computeGeneralizedGravity(model, model.createData(), x - h)[0]) / (2 * h); "
)
ANSWERED = {
    "solve": STIFFNESS + "r = pinsettle.solve(model, q); assert r.converged and r.q.shape == (1,); "
    "assert abs(pinocchio.computeGeneralizedGravity(model, model.createData(), r.q)[0]) < 1e-8; "
    "k = stiffness(r.q); assert k > 1e-3 and r.stability == 'stable', (k, r.stability)",
    "assess_stability": STIFFNESS + "k = stiffness(q); r = pinsettle.assess_stability(model, q); "
    "assert abs(k) > 1e-3, k; "
    "assert r.verdict == ('stable' if k > 0 else 'unstable'), (r.verdict, k); "
    "assert abs(2.0 * r.min_eigenvalue - k) <= 1e-6 * abs(k), (r.min_eigenvalue, k)",
    "static_force": "assert np.allclose(pinsettle.static_force(model, q), "
    "pinocchio.computeGeneralizedGravity(model, model.createData(), q), atol=1e-12)",
    "scene_solve": "r = pinsettle.solve(pinsettle.Scene(model)); "
    "assert r.converged and abs(r.q[1] + r.q[0]) < 1e-12",
}
REFUSED = {
    "kinetic_energies": "pinsettle.kinetic_energies(model, q, np.zeros(1))",
}
CALLS = {**ANSWERED, **REFUSED}

CHILD = """
import json, sys
import numpy as np
import pinocchio
import pinsettle

model = pinocchio.buildModelFromUrdf(sys.argv[1], mimic=True)
assert [j.shortname() for j in model.joints][2] == "JointModelMimic"
q = np.array([0.3])
try:
    {call}
except Exception as error:
    raised = type(error).__name__, isinstance(error, ValueError)
    print(json.dumps({{"raised": raised, "message": str(error)}}))
else:
    print(json.dumps({{"raised": None, "message": ""}}))
"""


@pytest.fixture(scope="module")
def mimic_urdf(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("mimic") / "mimic_arm.urdf"
    path.write_text(MIMIC_URDF, encoding="utf-8")
    return path


@pytest.mark.parametrize("call", sorted(CALLS))
def test_mimic_joint_is_answered_or_refused_not_a_crash(mimic_urdf: Path, call: str) -> None:
    code = textwrap.dedent(CHILD).format(call=CALLS[call])
    proc = subprocess.run(
        [sys.executable, "-c", code, str(mimic_urdf)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, (
        f"{call} on a model with a mimic joint ended the process with {proc.returncode} "
        f"(a negative code is a signal: {-proc.returncode} = SIGSEGV when 11)\n{proc.stderr}"
    )
    outcome = json.loads(proc.stdout.strip().splitlines()[-1])
    if call in ANSWERED:
        assert outcome["raised"] is None, outcome
        return
    assert outcome["raised"] is not None and outcome["raised"][1], outcome  # a ValueError
    message = outcome["message"]
    assert "'follower'" in message  # the joint, by name
    assert "mimic" in message and "joint1" in message  # why, and which joint it follows
    assert "mimic=False" in message  # what to do about it

"""Bad input: each raises the documented exception, whose message names the culprit."""

from __future__ import annotations

import math

import numpy as np
import pinocchio
import pinsettle
import pytest

NAN, INF = math.nan, math.inf

# (override, message pattern naming the field); out of range -> ValueError when solving.
OUT_OF_RANGE = [
    ({"dt": 0.0}, r"^dt must be 'auto' or a finite number > 0"),
    ({"dt": "fast"}, r"^dt must be 'auto' or a finite number > 0 \(seconds\), got 'fast'"),
    ({"dt": -1e-3}, r"^dt must be"),
    ({"dt": NAN}, r"^dt must be .*got nan"),
    ({"dt": INF}, r"^dt must be .*got inf"),
    ({"kt": 1}, r"^kt must be in \[0, 1\), got 1"),
    ({"kt": 1.0}, r"^kt must be in \[0, 1\)"),
    ({"kt": -0.1}, r"^kt must be in \[0, 1\), got -0\.1"),
    ({"kt": NAN}, r"^kt must be in \[0, 1\), got nan"),
    ({"err": -1e-9}, r"^err must be a finite number >= 0"),
    ({"err": NAN}, r"^err must be"),
    ({"ds": 0}, r"^ds must be an integer >= 1"),
    ({"ds": -5}, r"^ds must be an integer >= 1"),
    ({"max_e": -1e-12}, r"^max_e must be a finite number >= 0"),
    ({"max_e": NAN}, r"^max_e must be .*got nan"),
    ({"max_e": INF}, r"^max_e must be"),
    ({"max_steps": 0}, r"^max_steps must be an integer >= 1"),
    ({"max_time": 0.0}, r"^max_time must be a number > 0"),
    ({"max_time": NAN}, r"^max_time must be"),
    ({"trace_every": -1}, r"^trace_every must be an integer >= 0"),
    ({"trace_capacity": 1}, r"^trace_capacity must be an integer >= 2"),
    ({"check_every": 0}, r"^check_every must be an integer >= 1"),
    ({"dt_growth": 0.5}, r"^dt_growth must be 'auto' or a finite number >= 1, got 0.5"),
    ({"dt_growth": 0.0}, r"^dt_growth must be 'auto' or a finite number >= 1, got 0"),
    ({"dt_growth": NAN}, r"^dt_growth must be 'auto' or a finite number >= 1, got nan"),
    ({"dt_growth": INF}, r"^dt_growth must be 'auto' or a finite number >= 1, got inf"),
    ({"dt_growth": "fast"}, r"^dt_growth must be 'auto' or a finite number >= 1, got 'fast'"),
    ({"dt_safety": 0.0}, r"^dt_safety must be 'auto' or a number in \(0, 1\], got 0"),
    ({"dt_safety": 1.5}, r"^dt_safety must be 'auto' or a number in \(0, 1\], got 1.5"),
    ({"dt_safety": NAN}, r"^dt_safety must be 'auto' or a number in \(0, 1\], got nan"),
    ({"dt_safety": "fast"}, r"^dt_safety must be 'auto' or a number in \(0, 1\], got 'fast'"),
]


@pytest.mark.parametrize("override, pattern", OUT_OF_RANGE, ids=lambda x: str(x))
def test_setting_out_of_range(pendulum, override, pattern):
    with pytest.raises(ValueError, match=pattern):
        pinsettle.solve(pendulum, [1.0], **override)
    if "dt" in override or "dt_safety" in override or "dt_growth" in override:
        # 'auto' or a number: refused when set, so that no number can mean 'auto'.
        with pytest.raises(ValueError, match=pattern):
            pinsettle.Settings(**override)
        return
    # The same value is accepted by the constructor and caught by check().
    settings = pinsettle.Settings(**override)
    with pytest.raises(ValueError, match=pattern):
        settings.check()
    with pytest.raises(ValueError, match=pattern):
        pinsettle.solve(pendulum, [1.0], settings)


# Values of a wrong type: TypeError naming the field, at construction already.
WRONG_TYPE = [
    ("kt", "a"),
    ("kt", None),
    ("dt", True),  # a bool is not taken for a number
    ("ds", 1.5),
    ("ds", "3"),
    ("max_steps", 1e3),
    ("energy", 1),
    ("backtrack", "yes"),
    ("scale_joint_inertia", 1),
    ("trace_every", [1]),
]


@pytest.mark.parametrize("key, value", WRONG_TYPE)
def test_setting_of_wrong_type(pendulum, key, value):
    pattern = rf"^setting '{key}' expects"
    with pytest.raises(TypeError, match=pattern):
        pinsettle.Settings(**{key: value})
    with pytest.raises(TypeError, match=pattern):
        pinsettle.solve(pendulum, [1.0], **{key: value})
    with pytest.raises(TypeError, match=pattern):
        pinsettle.Settings().replace(**{key: value})


def test_setting_overflowing_int(pendulum):
    # Larger than int64: the right type, out of range; the message names the field.
    with pytest.raises(ValueError, match=r"^setting 'max_steps' must fit in a 64-bit integer"):
        pinsettle.solve(pendulum, [1.0], max_steps=2**70)


@pytest.mark.parametrize("key", ["stifness", "kk"])
def test_unknown_setting_lists_the_known_ones(pendulum, key):
    with pytest.raises(
        TypeError, match=rf"unknown setting '{key}'.*known settings: dt, dt_safety, dt_growth, kt, "
    ):
        pinsettle.solve(pendulum, [1.0], **{key: 1})
    with pytest.raises(TypeError, match=rf"unknown setting '{key}'"):
        pinsettle.Settings(**{key: 1})
    with pytest.raises(TypeError, match=rf"unknown setting '{key}'"):
        pinsettle.solve(pendulum, [1.0], {key: 1})  # in a dict of settings too


@pytest.mark.parametrize(
    "typo, meant", [("max_step", "max_steps"), ("k_t", "kt"), ("trace_evry", "trace_every")]
)
def test_unknown_setting_suggests_a_close_match(pendulum, typo, meant):
    with pytest.raises(TypeError, match=rf"unknown setting '{typo}' \(did you mean '{meant}'\?\)"):
        pinsettle.solve(pendulum, [1.0], **{typo: 1})


def test_unknown_energy_measure(pendulum):
    with pytest.raises(ValueError, match=r'^energy must be "exact" or "simplified", got "fast"'):
        pinsettle.solve(pendulum, [1.0], energy="fast")
    with pytest.raises(ValueError, match=r"^energy must be"):
        pinsettle.Settings(energy="Exact")  # case matters


def test_unknown_joint_inertia_choice(pendulum):
    # True, False or 'auto': another string is refused when set, naming the field.
    pattern = r"^scale_joint_inertia must be true, false or 'auto', got 'on'"
    with pytest.raises(ValueError, match=pattern):
        pinsettle.solve(pendulum, [1.0], scale_joint_inertia="on")
    with pytest.raises(ValueError, match=r"^scale_joint_inertia must be .*got 'Auto'"):
        pinsettle.Settings(scale_joint_inertia="Auto")  # case matters


@pytest.mark.parametrize(
    "settings", [3, "kt=0.5", [("kt", 0.5)], pinocchio.Model()], ids=["int", "str", "list", "model"]
)
def test_settings_of_wrong_type(pendulum, settings):
    with pytest.raises(TypeError, match=r"^settings must be a pinsettle.Settings, a dict or None"):
        pinsettle.solve(pendulum, [1.0], settings)


# --- q0 and v0 ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "q0, error, pattern",
    [
        ([1.0, 2.0], ValueError, r"^q0 must have shape \(1,\) \(model.nq\), got \(2,\)"),
        ([], ValueError, r"^q0 must have shape \(1,\)"),
        ([NAN], ValueError, r"^q0\[0\] is nan; every entry must be finite"),
        ([-INF], ValueError, r"^q0\[0\] is -inf"),
        ([[1.0]], ValueError, r"^q0 must have shape \(1,\) .*got \(1, 1\)"),
        (["a"], TypeError, r"^q0 must be a 1-D array of model.nq = 1 real numbers"),
        ("1.0", TypeError, r"^q0 must be a 1-D array"),
        (np.array([1.0 + 1.0j]), TypeError, r"^q0 must be a 1-D array"),
        ({"hinge": 1.0}, TypeError, r"^q0 must be a 1-D array"),
    ],
    ids=["too-long", "empty", "nan", "inf", "2-D", "strings", "str", "complex", "dict"],
)
def test_bad_q0(pendulum, q0, error, pattern):
    with pytest.raises(error, match=pattern):
        pinsettle.solve(pendulum, q0)


def test_q0_with_nan_on_a_robot_names_the_index(ur5):
    q0 = np.zeros(ur5.nq)
    q0[4] = NAN
    with pytest.raises(ValueError, match=r"^q0\[4\] is nan"):
        pinsettle.solve(ur5, q0)


def test_non_normalised_quaternion(solo12):
    q0 = pinocchio.neutral(solo12)
    q0[3:7] *= 2.0
    pattern = r"^q0\[0:7\] \(joint 'root_joint', JointModelFreeFlyer\) .* norm 2\b"
    with pytest.raises(ValueError, match=pattern):
        pinsettle.solve(solo12, q0)
    # The helper functions check their configuration the same way.
    with pytest.raises(ValueError, match=r"^q\[0:7\] \(joint 'root_joint'"):
        pinsettle.static_residual(solo12, q0)
    with pytest.raises(ValueError, match=r"^q\[0:7\] \(joint 'root_joint'"):
        pinsettle.kinetic_energies(solo12, q0, np.zeros(solo12.nv))


def test_nearly_normalised_quaternion_is_accepted(solo12):
    # Within the documented 1e-6, and made exactly unit by the solver.
    q0 = pinocchio.neutral(solo12)
    q0[3:7] *= 1.0 + 1e-8
    result = pinsettle.solve(solo12, q0, max_steps=10)
    assert abs(np.linalg.norm(result.q[3:7]) - 1.0) < 1e-12


def test_non_normalised_cos_sin_pair():
    # A continuous joint stores (cos, sin): it must be a unit vector too.
    model = pinsettle.load_robot("double_pendulum_continuous")
    q0 = pinocchio.neutral(model)
    q0[0:2] *= 2.0
    with pytest.raises(ValueError, match=rf"joint '{model.names[1]}'"):
        pinsettle.solve(model, q0)


@pytest.mark.parametrize(
    "v0, error, pattern",
    [
        ([1.0, 2.0], ValueError, r"^v0 must have shape \(1,\) \(model.nv\), got \(2,\)"),
        ([[1.0]], ValueError, r"^v0 must have shape"),
        ([INF], ValueError, r"^v0\[0\] is inf"),
        (["fast"], TypeError, r"^v0 must be a 1-D array of model.nv = 1 real numbers"),
    ],
    ids=["too-long", "2-D", "inf", "strings"],
)
def test_bad_v0(pendulum, v0, error, pattern):
    with pytest.raises(error, match=pattern):
        pinsettle.solve(pendulum, [1.0], v0=v0)


def test_v0_of_a_free_flyer_has_nv_entries(solo12):
    # nq = 19 but nv = 18: a v0 of nq entries is wrong.
    with pytest.raises(ValueError, match=r"^v0 must have shape \(18,\)"):
        pinsettle.solve(solo12, v0=np.zeros(solo12.nq))


# --- model, callback, robot names -------------------------------------------------------


@pytest.mark.parametrize(
    "model", [{}, None, "ur5", pinocchio.Model().createData()], ids=["dict", "None", "str", "Data"]
)
def test_model_of_wrong_type(model):
    with pytest.raises(
        TypeError, match=r"^model must be a pinocchio.Model or a pinsettle.Scene, got "
    ):
        pinsettle.solve(model)


@pytest.mark.parametrize("model", [{}, None, pinocchio.Model().createData()])
def test_helpers_reject_a_model_of_wrong_type(model):
    with pytest.raises(TypeError, match=r"^model must be a pinocchio.Model"):
        pinsettle.static_residual(model, np.zeros(1))
    with pytest.raises(TypeError, match=r"^model must be a pinocchio.Model"):
        pinsettle.kinetic_energies(model, np.zeros(1), np.zeros(1))


def test_model_without_joints():
    with pytest.raises(ValueError, match=r"^model has no degree of freedom"):
        pinsettle.solve(pinocchio.Model())


def test_helpers_check_sizes(pendulum):
    with pytest.raises(ValueError, match=r"^q must have shape \(1,\) \(model.nq\), got \(2,\)"):
        pinsettle.static_residual(pendulum, np.zeros(2))
    with pytest.raises(ValueError, match=r"^v must have shape \(1,\) \(model.nv\), got \(3,\)"):
        pinsettle.kinetic_energies(pendulum, np.zeros(1), np.zeros(3))
    with pytest.raises(ValueError, match=r"^q\[0\] is nan"):
        pinsettle.kinetic_energies(pendulum, np.array([NAN]), np.zeros(1))


@pytest.mark.parametrize("callback", [3, "stop", [lambda: True]], ids=["int", "str", "list"])
def test_callback_not_callable(pendulum, callback):
    with pytest.raises(TypeError, match=r"^callback must be callable or None"):
        pinsettle.solve(pendulum, [1.0], callback=callback)


@pytest.mark.parametrize("name", ["nosuchrobot", "UR5", "", None])
def test_unknown_robot(name):
    pattern = r"unknown robot .*known robots: .*\bpanda\b.*\bur5\b"
    with pytest.raises(ValueError, match=pattern):
        pinsettle.load_robot(name)
    with pytest.raises(ValueError, match=pattern):
        pinsettle.robot_urdf(name)


def test_unknown_robot_suggests_a_close_match():
    with pytest.raises(ValueError, match=r"did you mean 'ur5'\?"):
        pinsettle.load_robot("ur6")


def test_errors_leave_the_interpreter_usable(pendulum):
    # After all of the above (and a C++ exception right here) solving still works.
    with pytest.raises(ValueError):
        pinsettle.solve(pendulum, [1.0], kt=2.0)
    assert pinsettle.solve(pendulum, [1.0], max_steps=3).steps == 3


# --- Once package bugs, kept as regression tests ------------------------------------------


@pytest.mark.parametrize("function", ["solve", "static_residual"])
def test_zero_quaternion_is_rejected(solo12, function):
    q0 = pinocchio.neutral(solo12)
    q0[3:7] = 0.0
    with pytest.raises(ValueError, match=r"joint 'root_joint'"):
        if function == "solve":
            pinsettle.solve(solo12, q0, max_steps=10)
        else:
            pinsettle.static_residual(solo12, q0)


def test_large_trace_capacity_is_only_a_bound(pendulum):
    result = pinsettle.solve(
        pendulum, [1.0], trace_every=1, trace_capacity=2**62, max_steps=10, newton_takeover=False
    )
    assert len(result.trace.step) == 10


def test_massless_motion_is_named_not_diverged():
    # pendulum.urdf's root link has no inertial: on a floating base, turning the base one way
    # and the hinge the other moves no mass. ABA would produce NaN; the solver says why.
    model = pinsettle.load_urdf(
        pinsettle.scene_path("pendulum").parent / "pendulum.urdf", floating=True
    )
    with pytest.raises(ValueError, match=r"inertia matrix M\(q0\) is singular") as info:
        pinsettle.solve(model)
    message = str(info.value)
    assert "'root_joint'" in message and "'hinge'" in message and "<inertial>" in message
    # The same URDF fixed to the world moves fine.
    fixed = pinsettle.load_urdf(pinsettle.scene_path("pendulum").parent / "pendulum.urdf")
    assert pinsettle.solve(fixed, np.array([0.3])).converged

"""Closed-form references for the loop scenes of robots/: planar position analysis, the
potential as a function of one angle, and its stationary point. numpy and scipy only: nothing
of Pinocchio or pinsettle, so that the tests compare two independent routes.

Planar conventions of the URDFs: the mechanisms move in the x-z plane on hinges about +y, and a
joint angle theta turns a body's x axis to u(theta) = (cos theta, -sin theta) in (x, z).
Absolute angles add along a chain. Gravity is -9.81 along z.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

G = 9.81


def u(angle: float) -> np.ndarray:
    return np.array([math.cos(angle), -math.sin(angle)])


def circles(c1: np.ndarray, r1: float, c2: np.ndarray, r2: float, sign: float) -> np.ndarray:
    """The intersection of two circles on the side ``sign`` (+1 or -1) of the line c1 -> c2."""
    d = c2 - c1
    dist = float(np.linalg.norm(d))
    if not abs(r1 - r2) <= dist <= r1 + r2:
        raise ValueError("the loop cannot close at this angle")
    along = (r1 * r1 - r2 * r2 + dist * dist) / (2 * dist)
    height = math.sqrt(max(r1 * r1 - along * along, 0.0))
    e = d / dist
    normal = np.array([-e[1], e[0]])
    return c1 + along * e + sign * height * normal


def angle_of(v: np.ndarray) -> float:
    """The joint-convention angle of a planar direction v: u(angle) is along v."""
    return math.atan2(-v[1], v[0])


@dataclass
class Mechanism:
    """A one-degree-of-freedom closed mechanism: joint values and the potential as functions of
    the driving angle, and the equilibrium as the stationary point of the potential."""

    joints: Callable[[float], dict[str, float]]
    potential: Callable[[float], float]
    driver: str

    def slope(self, t: float, h: float = 1e-6) -> float:
        return (self.potential(t + h) - self.potential(t - h)) / (2 * h)

    def curvature(self, t: float, h: float = 1e-4) -> float:
        return (self.potential(t + h) - 2 * self.potential(t) + self.potential(t - h)) / h**2

    def equilibrium(self, near: float, half_width: float = 0.3) -> dict[str, float]:
        """The stationary point of the potential bracketed around ``near``, with its joint
        values by name and 'stable' (the potential's curvature there is positive)."""
        a, b = near - half_width, near + half_width
        t = brentq(self.slope, a, b, xtol=1e-14, rtol=1e-15)
        return {**self.joints(t), "stable": bool(self.curvature(t) > 0)}


# --- robots/fourbar: crank spring and a load on the coupler ----------------------------------

FOURBAR = {
    "o4": np.array([0.4, 0.0]),
    "crank": (0.15, 0.5),  # length (m), mass (kg) of uniform rods
    "coupler": (0.4, 1.0),
    "rocker": (0.3, 0.8),
    "spring": (4.0, -1.2),  # crank_joint stiffness (N m/rad), rest (rad)
    "load_point": 0.2,  # m along the coupler
    "load": np.array([0.0, -10.0]),  # (x, z) N
    "branch": 1.0,  # side of the crank-end -> rocker-pivot line the joint sits on
}


def fourbar(p: dict = FOURBAR) -> Mechanism:
    a, m1 = p["crank"]
    b, m2 = p["coupler"]
    c, m3 = p["rocker"]
    k, rest = p["spring"]

    def pose(t: float):
        A = a * u(t)
        B = circles(A, b, p["o4"], c, p["branch"])
        return A, B

    def joints(t: float) -> dict[str, float]:
        A, B = pose(t)
        coupler = angle_of(B - A)
        rocker = angle_of(B - p["o4"])
        return {
            "crank_joint": t,
            "coupler_joint": math.remainder(coupler - t, 2 * math.pi),
            "rocker_joint": rocker,
        }

    def potential(t: float) -> float:
        A, B = pose(t)
        heights = m1 * A[1] / 2 + m2 * (A[1] + B[1]) / 2 + m3 * (p["o4"][1] + B[1]) / 2
        load_at = A + p["load_point"] / b * (B - A)
        return 0.5 * k * (t - rest) ** 2 + G * heights - float(p["load"] @ load_at)

    return Mechanism(joints, potential, "crank_joint")


# --- robots/slider_crank: spring on the slider, torque on the crank --------------------------

SLIDER_CRANK = {
    "crank": (0.1, 0.3),
    "rod": (0.3, 0.4),
    "spring": (200.0, 0.3),  # slider_joint stiffness (N/m), rest (m)
    "torque": 0.5,  # N m on crank_joint
}


def slider_crank(p: dict = SLIDER_CRANK) -> Mechanism:
    r, m1 = p["crank"]
    length, m2 = p["rod"]
    k, rest = p["spring"]

    def pose(t: float):
        A = r * u(t)
        x = A[0] + math.sqrt(length * length - A[1] * A[1])  # slider on the +x side
        return A, np.array([x, 0.0])

    def joints(t: float) -> dict[str, float]:
        A, S = pose(t)
        rod = angle_of(S - A)
        return {
            "crank_joint": t,
            "rod_joint": math.remainder(rod - t, 2 * math.pi),
            "slider_joint": float(S[0]),
        }

    def potential(t: float) -> float:
        A, S = pose(t)
        heights = m1 * A[1] / 2 + m2 * (A[1] + S[1]) / 2
        return 0.5 * k * (S[0] - rest) ** 2 - p["torque"] * t + G * heights

    return Mechanism(joints, potential, "crank_joint")


# --- robots/parallel_gripper: a parallelogram finger on a spring, holding a weight -----------

PARALLEL_GRIPPER = {
    "length": 0.12,  # both links (m)
    "gap": 0.05,  # between the ground pivots, and on the jaw (m)
    "link_mass": 0.05,
    "jaw_mass": 0.1,
    "jaw_com": np.array([0.02, -0.025]),  # from the jaw joint, jaw level (m)
    "spring": (200.0, 0.05),  # N/m, rest length (m)
    "spring_jaw": np.array([0.02, -0.025]),  # on the jaw, from its joint (m)
    "spring_ground": np.array([0.3, -0.025]),  # (x, z) m
    "load_jaw": np.array([0.04, -0.05]),  # the fingertip, from the jaw joint (m)
    "load": np.array([0.0, -3.0]),  # (x, z) N
}


def parallel_gripper(p: dict = PARALLEL_GRIPPER) -> Mechanism:
    L, h = p["length"], p["gap"]
    k, rest = p["spring"]

    def jaw_origin(t: float) -> np.ndarray:
        return L * u(t)

    def joints(t: float) -> dict[str, float]:
        return {"upper_joint": t, "jaw_joint": -t, "lower_joint": t}

    def potential(t: float) -> float:
        J = jaw_origin(t)
        lower = np.array([0.0, -h])
        heights = (
            p["link_mass"] * J[1] / 2
            + p["link_mass"] * (lower[1] + L * u(t)[1] / 2)
            + p["jaw_mass"] * (J + p["jaw_com"])[1]
        )
        spring = np.linalg.norm(J + p["spring_jaw"] - p["spring_ground"]) - rest
        return 0.5 * k * spring**2 + G * heights - float(p["load"] @ (J + p["load_jaw"]))

    return Mechanism(joints, potential, "upper_joint")


MECHANISMS = {
    "fourbar": fourbar,
    "slider_crank": slider_crank,
    "parallel_gripper": parallel_gripper,
}

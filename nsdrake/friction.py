"""Gear friction, smooth through zero velocity (the realism ladder's ``friction`` rung).

    τ_f(v) = −(τ_c tanh(v / v_s) + b v)

τ_c the Coulomb torque, b the viscous coefficient, v_s the speed over which the
Coulomb part changes sign. τ_f always opposes v (v τ_f ≤ 0), is odd in v, tends to
−(τ_c sign(v) + b v) for |v| ≫ v_s, and has the slope −(τ_c/v_s + b) at v = 0: the
discrete plant applies it explicitly (from the state at the start of each step), so
v_s must keep (τ_c/v_s + b) h / I well below 2 for the smallest inertia I a joint
moves (checked in :func:`friction_slope`'s callers' tests).
"""

from __future__ import annotations

import numpy as np


def friction_torque(v: np.ndarray, coulomb: float, viscous: float, smoothing_speed: float) -> np.ndarray:
    """τ_f = −(τ_c tanh(v/v_s) + b v), element-wise. [N m] for v [rad/s]."""
    v = np.asarray(v, dtype=float)
    return -(coulomb * np.tanh(v / smoothing_speed) + viscous * v)


def friction_slope(coulomb: float, viscous: float, smoothing_speed: float) -> float:
    """|dτ_f/dv| at v = 0, the largest slope: τ_c/v_s + b [N m s/rad]."""
    return coulomb / smoothing_speed + viscous

"""Gear friction, smooth through zero velocity (the realism ladder's ``friction`` rung).

    τ_f(v) = −(τ_c tanh(v / v_s) + b v)

τ_c the Coulomb torque, b the viscous coefficient, v_s the speed over which the
Coulomb part changes sign. τ_f always opposes v (v τ_f ≤ 0), is odd in v, tends to
−(τ_c sign(v) + b v) for |v| ≫ v_s, and has the slope −(τ_c/v_s + b) at v = 0: the
discrete plant applies it explicitly (from the state at the start of each step), so
v_s must keep (τ_c/v_s + b) h / I well below 2 for the smallest inertia I a joint
moves (:func:`explicit_friction_margin`, checked before a run).
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


def largest_inverse_inertia(plant, dofs, samples: int = 500, seed: int = 0) -> float:
    """max over seeded random poses (within the joint limits, ±π where there are none) of
    the largest eigenvalue of (H⁻¹)[dofs, dofs], the most a unit torque on those
    coordinates can accelerate them [1/(kg m²)]."""
    context = plant.CreateDefaultContext()
    lower = np.maximum(plant.GetPositionLowerLimits(), -np.pi)
    upper = np.minimum(plant.GetPositionUpperLimits(), np.pi)
    rng = np.random.default_rng(seed)
    dofs = np.asarray(dofs, dtype=int)
    largest = 0.0
    for q in rng.uniform(lower, upper, (samples, plant.num_positions())):
        plant.SetPositions(context, q)
        H_inv = np.linalg.inv(plant.CalcMassMatrix(context))
        largest = max(largest, float(np.linalg.eigvalsh(H_inv[np.ix_(dofs, dofs)]).max()))
    return largest


def explicit_friction_margin(slope: float, step: float, inverse_inertia: float) -> float:
    """slope × h × max λ(H⁻¹): the friction's own loop gain over one explicit plant step,
    stable (no stick-slip chatter) well below 1 and below 2 at most [-]."""
    return slope * step * inverse_inertia

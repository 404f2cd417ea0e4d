"""Joint-limit avoidance: a criterion that is zero far from the limits.

A real arm's joints stop at q_min and q_max. With the margins to them,
δ⁻_i = q_i − q_min,i and δ⁺_i = q_max,i − q_i, and an influence distance ρ [rad],

    p = −⅓ Σ_i [ max(0, ρ − δ⁻_i)³ + max(0, ρ − δ⁺_i)³ ]          (maximise: K > 0 in Eq. 30)
    Φ_i = ∂p/∂q_i = max(0, ρ − δ⁻_i)² − max(0, ρ − δ⁺_i)²

p is exactly zero while every joint is more than ρ from both of its limits, so the
criterion leaves the arm alone there; inside, the gradient pushes the joint back
toward the middle of its range, harder the deeper it is. The cube makes Φ
continuously differentiable where a joint enters the zone (as for the obstacle
potential, :mod:`nsdrake.control.criteria.obstacle`): with a square, Φ would have a kink
there, and the feed-forward of q̈_dⁿ would turn it into a torque step. Joints
without limits (±∞, e.g. the paper's continuous joints) never contribute.

The smallest margin min_i min(δ⁻_i, δ⁺_i) is what Fig. 1's extended tree compares
with its limit q_lim (:mod:`nsdrake.control.priority`), and
:func:`nsdrake.control.smoothing.activation` weighs the
criterion's level in the projection of the levels below it.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def joint_limits_criterion(
    q: np.ndarray, lower: np.ndarray, upper: np.ndarray, influence: float
) -> tuple[float, np.ndarray, float]:
    """(p, Φ, margin) of the module docstring.

    Args:
        q: (n,) joint positions [rad] (metres for a prismatic joint).
        lower, upper: (n,) joint limits, ±inf where a joint has none.
        influence: ρ > 0, the distance from a limit within which the criterion acts.

    Returns:
        p [rad³], Φ (n,) [rad²], and the smallest margin to any limit [rad] (inf if none).
    """
    n = q.shape[0]
    p, margin = 0.0, np.inf
    Phi = np.zeros(n)
    for i in range(n):
        below, above = q[i] - lower[i], upper[i] - q[i]
        margin = min(margin, below, above)
        depth_lower, depth_upper = influence - below, influence - above
        if depth_lower > 0.0:
            p -= depth_lower**3 / 3.0
            Phi[i] += depth_lower * depth_lower
        if depth_upper > 0.0:
            p -= depth_upper**3 / 3.0
            Phi[i] -= depth_upper * depth_upper
    return p, Phi, margin

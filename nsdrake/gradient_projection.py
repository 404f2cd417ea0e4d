"""The desired null-space velocity by gradient projection (Section 3.4, Eqs. 28–30).

For a criterion p(q) with gradient Φ = ∂p/∂q (Eq. 29) and step gain K
(K > 0 maximises p, K < 0 minimises it):

    q̇_dⁿ = (I − J⁺ J) K Φ          Moore–Penrose (Eq. 28): Φᵀ N Φ ≥ 0, so the step improves p;
    q̇_dⁿ = (I − J̄ J) K H⁻¹ Φ       dynamically consistent (Eq. 30).

With J̄ the form Φᵀ (I − J̄ J) Φ is not symmetric and can be negative, so Eq. 28's
step with J̄ can worsen p. Rotating Φ by H⁻¹ first restores the sign:
(I − J̄ J) H⁻¹ = H⁻¹ − H⁻¹ Jᵀ Λ J H⁻¹ is symmetric positive semi-definite, so
ṗ = Φᵀ q̇_dⁿ = K Φᵀ (I − J̄ J) H⁻¹ Φ has the sign of K.

:func:`scale_to_speed_limits` scales q̇_dⁿ, keeping its direction, so that no
joint exceeds its speed limit (end of Section 3.3).
"""

from __future__ import annotations

import numpy as np


def gradient_step(N: np.ndarray, H_inv: np.ndarray, Phi: np.ndarray, K: float, rotate: bool) -> np.ndarray:
    """q̇_dⁿ = N K H⁻¹ Φ (Eq. 30, ``rotate``) or N K Φ (Eq. 28's form). (n,) [rad/s]."""
    direction = H_inv @ Phi if rotate else Phi
    return K * (N @ direction)


def scale_to_speed_limits(qdot: np.ndarray, limits: np.ndarray) -> tuple[np.ndarray, float]:
    """(s q̇, s) with the largest s ≤ 1 such that |s q̇_i| ≤ limits_i. Infinite limits never bind."""
    ratio = float(np.max(np.abs(qdot) / limits))  # inf limits give 0
    if ratio <= 1.0:
        return qdot, 1.0
    return qdot / ratio, 1.0 / ratio

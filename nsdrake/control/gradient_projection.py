"""The desired null-space velocity by gradient projection (Section 3.4, Eqs. 28–30).

For a criterion p(q) with gradient Φ = ∂p/∂q (Eq. 29) and step gain K
(K > 0 maximises p, K < 0 minimises it):

    q̇_dⁿ = (I − J⁺ J) K Φ          Moore–Penrose (Eq. 28): Φᵀ N Φ ≥ 0, so the step improves p;
    q̇_dⁿ = (I − J̄ J) K H⁻¹ Φ       dynamically consistent (Eq. 30).

With J̄ the form Φᵀ (I − J̄ J) Φ is not symmetric and can be negative, so Eq. 28's
step with J̄ can worsen p. Rotating Φ by H⁻¹ first restores the sign:
(I − J̄ J) H⁻¹ = H⁻¹ − H⁻¹ Jᵀ Λ J H⁻¹ is symmetric positive semi-definite, so
ṗ = Φᵀ q̇_dⁿ = K Φᵀ (I − J̄ J) H⁻¹ Φ has the sign of K.

With more than one criterion, :mod:`nsdrake.control.priority` stacks these steps level
by level, and scales the result to the joint-speed limits (end of Section 3.3).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def projected_direction(N: np.ndarray, W_inv: np.ndarray, Phi: np.ndarray) -> np.ndarray:
    """N W⁻¹ Φ: Eq. 30's direction, the gradient rotated by the metric W⁻¹ of the
    generalised inverse behind N (H⁻¹ for J̄, I for J⁺) and projected into its null
    space. (n,). :mod:`nsdrake.control.priority` also removes this direction from the
    levels below a criterion."""
    return N @ (W_inv @ Phi)


@njit(cache=True, inline="always")
def gradient_step(N: np.ndarray, W_inv: np.ndarray, Phi: np.ndarray, K: float, rotate: bool) -> np.ndarray:
    """q̇_dⁿ = K N W⁻¹ Φ (``rotate``, Eq. 30 for J̄; :func:`projected_direction`) or
    K N Φ (Eq. 28's form). (n,) [rad/s]."""
    if rotate:
        return K * projected_direction(N, W_inv, Phi)
    return K * (N @ Phi)

"""Manipulability (Yoshikawa): w = √det(J Jᵀ) and its analytic gradient.

    ∂w/∂q_j = ½ w tr((J Jᵀ)⁻¹ ∂(J Jᵀ)/∂q_j) = w tr(J⁺ ∂J/∂q_j),   J⁺ = Jᵀ (J Jᵀ)⁻¹,

so Φ_j = w ⟨J⁺ᵀ, ∂J/∂q_j⟩ (Frobenius product). At a singular pose w = 0 and its
gradient is not defined; near one (w > 0) the formula holds. Maximising w (K > 0
in Eq. 30) keeps the arm away from singular poses (Section 3.5).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from nsdrake.control.pseudo_inverse import gram_and_inverse


@njit(cache=True)
def manipulability(J: np.ndarray, dJ_dq: np.ndarray) -> tuple[float, np.ndarray]:
    """(w, Φ) for w = √det(J Jᵀ).

    Args:
        J: (m, n) task Jacobian [m/rad].
        dJ_dq: (n, m, n) with dJ_dq[j] = ∂J/∂q_j [m/rad²].

    Returns:
        w [mᵐ per radᵐ, m the number of task axes: m² for the planar task] and
        Φ (n,) [w's unit per rad].
    """
    A, A_inv = gram_and_inverse(J, 0.0)
    w = np.sqrt(max(np.linalg.det(A), 0.0))
    n, m = dJ_dq.shape[0], J.shape[0]
    if w == 0.0:
        return 0.0, np.zeros(n)
    J_pinv_T = A_inv @ J  # (J⁺)ᵀ, (m, n)
    return w, w * (np.ascontiguousarray(dJ_dq).reshape(n, m * J.shape[1]) @ J_pinv_T.ravel())

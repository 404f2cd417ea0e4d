"""A posture criterion for Eq. 30: the distance to a desired posture q_d.

    p = ½ (q − q_d)ᵀ W (q − q_d),     Φ = ∂p/∂q = W (q − q_d)

W = diag(w) a constant weight per joint [1/rad² of p's unit]. Minimised (K < 0 in Eq. 30),
q̇_dⁿ = K N H⁻¹ W (q − q_d) moves the arm toward q_d through its self-motion only. Near
q_d in the null space, with J̄ and a one-dimensional null space spanned by the unit
vector z, N H⁻¹ = z zᵀ / h_n (h_n = zᵀ H z, the null-space inertia), so the commanded
null-space speed is K w s / h_n for a posture error s along z; with Eq. 21's velocity
loop of gain K_n this is a second-order loop of natural frequency ω² = K_n |K| w / h_n and
damping 2 ζ ω = K_n (:mod:`nsdrake.control.null_space_laws` compares it with the
posture PD laws).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def posture_criterion(q: np.ndarray, q_d: np.ndarray, weight: np.ndarray) -> tuple[float, np.ndarray]:
    """(p, Φ) of the module docstring. p [rad² × weight], Φ (n,)."""
    e = q - q_d
    Phi = weight * e
    return 0.5 * float(e @ Phi), Phi

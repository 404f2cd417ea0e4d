"""Joint torque due to the desired end-effector force (Eqs. 32–33).

    p = τᵀ τ,   τ = Jᵀ F_d,
    ∂p/∂q_j = 2 τᵀ (∂J/∂q_j)ᵀ F_d,   i.e.  Φ = 2 ∇τᵀ τ with column j of ∇τ = (∂J/∂q_j)ᵀ F_d.

F_d is the *desired* contact force, so the pose can be optimised before contact.
∂J/∂q comes analytically from :class:`nsdrake.control.dynamics.RobotTerms`.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def joint_torque_criterion(J: np.ndarray, dJ_dq: np.ndarray, F_d: np.ndarray) -> tuple[float, np.ndarray]:
    """(p, Φ) for p = ‖Jᵀ F_d‖².

    Args:
        J: (m, n) task Jacobian [m/rad].
        dJ_dq: (n, m, n) with dJ_dq[j] = ∂J/∂q_j [m/rad²].
        F_d: (m,) desired force the tool exerts [N].

    Returns:
        p [N² m²] and Φ (n,) [N² m²/rad].
    """
    tau = J.T @ F_d  # (n,) [N m]
    n = J.shape[1]
    Phi = np.empty(n)
    for j in range(n):  # Φ_j = 2 τᵀ (∂J/∂q_j)ᵀ F_d
        Phi[j] = 2.0 * (F_d @ (dJ_dq[j] @ tau))
    return float(tau @ tau), Phi

"""The null-space velocity controller (Section 3.3, Eqs. 14–24).

With a generalised inverse J^# (Eq. 13's J̄ by default) and N = I − J^# J:

    eⁿ = q̇_dⁿ − N q̇                                                    (Eq. 14)
    τ₀ = H N ( q̈_dⁿ + (J̇^# J + J^# J̇) q̇ + K_n eⁿ + H⁻¹ C eⁿ )          (Eq. 21)
    ν  = ½ eⁿᵀ H eⁿ                                                      (Eq. 23)

(J̇^# J + J^# J̇) q̇ = −Ṅ q̇ is the task-velocity compensation and H⁻¹ C eⁿ the
Coriolis compensation; both can be switched off (Section 4 omits them). With
J̄, both on and C the Christoffel matrix, ν̇ = −K_n eⁿᵀ H eⁿ ≤ 0 (Eq. 24).

Whatever right inverse J^# is used, J H⁻¹ τ₀ = J N (…) = 0 (Eq. 11): τ₀ never
accelerates the task. A damped inverse is not a right inverse, so with damping
τ₀ leaks into the task.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .dynamics import RobotTerms
from .pseudo_inverse import GeneralizedInverse, InverseAtState


@dataclass(frozen=True)
class NullSpaceResult:
    tau0: np.ndarray  # (n,) null-space torque τ₀ [N m]
    e_n: np.ndarray  # (n,) null-space velocity error eⁿ [rad/s]
    nu: float  # Lyapunov function ν [J]
    N: np.ndarray  # (n, n) the projector used


def null_space_velocity_error(qdot_ns_d: np.ndarray, N: np.ndarray, v: np.ndarray) -> np.ndarray:
    """eⁿ = q̇_dⁿ − N q̇ (Eq. 14). (n,) [rad/s]."""
    return qdot_ns_d - N @ v


def lyapunov(H: np.ndarray, e_n: np.ndarray) -> float:
    """ν = ½ eⁿᵀ H eⁿ (Eq. 23) [J]."""
    return 0.5 * float(e_n @ H @ e_n)


def task_velocity_compensation_at(
    terms: RobotTerms, pinv: InverseAtState, inertia_weighted: bool
) -> np.ndarray:
    """(J̇^# J + J^# J̇) q̇ without forming J̇^#: the same quantity as
    the J̇^# matrix form in vector operations (tests/reference_math.py has the matrix form).

    With J^# = W⁻¹ Jᵀ A⁻¹, A = J W⁻¹ Jᵀ + λ² I, y = A⁻¹ ẋ and u = J^# ẋ:
    J̇^# ẋ = Ẇ⁻¹ Jᵀ y + W⁻¹ J̇ᵀ y − J^# Ȧ y, with
    Ȧ y = J̇ u + J Ẇ⁻¹ Jᵀ y + J W⁻¹ J̇ᵀ y, and Ẇ⁻¹ z = −H⁻¹ Ḣ H⁻¹ z for W = H
    (Ḣ = C + Cᵀ), 0 for W = I.
    """
    J, Jdot = terms.J, terms.Jdot
    y = pinv.A_inv @ terms.xdot
    u = pinv.J_pinv @ terms.xdot
    s = pinv.W_inv @ (Jdot.T @ y)
    if inertia_weighted:
        Hdot_u = terms.C @ u + terms.C.T @ u  # H⁻¹ Jᵀ y = u for W = H
        r = -(terms.H_inv @ Hdot_u)
    else:
        r = np.zeros(terms.n)
    A_dot_y = Jdot @ u + J @ (r + s)
    return r + s - pinv.J_pinv @ A_dot_y + pinv.J_pinv @ terms.Jdot_v


def null_space_torque(
    terms: RobotTerms,
    inverse: GeneralizedInverse,
    qdot_ns_d: np.ndarray,
    qddot_ns_d: np.ndarray,
    K_n: float,
    task_velocity_comp: bool = True,
    coriolis_comp: bool = True,
) -> NullSpaceResult:
    """τ₀ of Eq. 21, with eⁿ (Eq. 14) and ν (Eq. 23).

    ``terms`` must carry C when either compensation is on (with the
    dynamically consistent inverse, for the task-velocity one).
    """
    H, v = terms.H, terms.v
    pinv = inverse.at(terms)
    N = pinv.N
    e_n = null_space_velocity_error(qdot_ns_d, N, v)
    a = qddot_ns_d + K_n * e_n
    if task_velocity_comp:
        a = a + task_velocity_compensation_at(terms, pinv, inverse.inertia_weighted)
    if coriolis_comp:
        if terms.C is None:
            raise ValueError("the Coriolis compensation needs C in the robot terms")
        a = a + terms.H_inv @ (terms.C @ e_n)
    tau0 = H @ (N @ a)
    return NullSpaceResult(tau0=tau0, e_n=e_n, nu=lyapunov(H, e_n), N=N)

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
from numba import njit

from nsdrake.control.dynamics import RobotTerms
from nsdrake.control.pseudo_inverse import GeneralizedInverse, InverseAtState


@dataclass(frozen=True)
class NullSpaceResult:
    tau0: np.ndarray  # (n,) null-space torque τ₀ [N m]
    e_n: np.ndarray  # (n,) null-space velocity error eⁿ [rad/s]
    nu: float  # Lyapunov function ν [J]
    N: np.ndarray  # (n, n) the projector used


@njit(cache=True)
def null_space_velocity_error(qdot_ns_d: np.ndarray, N: np.ndarray, v: np.ndarray) -> np.ndarray:
    """eⁿ = q̇_dⁿ − N q̇ (Eq. 14). (n,) [rad/s]."""
    return qdot_ns_d - N @ v


@njit(cache=True)
def lyapunov(H: np.ndarray, e_n: np.ndarray) -> float:
    """ν = ½ eⁿᵀ H eⁿ (Eq. 23) [J]."""
    return 0.5 * (e_n @ (H @ e_n))


@njit(cache=True)
def _task_velocity_compensation(J, Jdot, xdot, Jdot_v, C, H_inv, A_inv, J_pinv, W_inv, inertia_weighted):
    y = A_inv @ xdot
    u = J_pinv @ xdot
    s = W_inv @ (Jdot.T @ y)
    if inertia_weighted:
        r = -(H_inv @ (C @ u + C.T @ u))  # Ẇ⁻¹ Jᵀ y = −H⁻¹ Ḣ u with H⁻¹ Jᵀ y = u, Ḣ = C + Cᵀ
    else:
        r = np.zeros(J.shape[1])
    A_dot_y = Jdot @ u + J @ (r + s)
    return r + s - J_pinv @ A_dot_y + J_pinv @ Jdot_v


def task_velocity_compensation_at(
    terms: RobotTerms, pinv: InverseAtState, inertia_weighted: bool
) -> np.ndarray:
    """(J̇^# J + J^# J̇) q̇ = −Ṅ q̇ (Eqs. 15, 21) without forming J̇^#, in vector operations.

    With J^# = W⁻¹ Jᵀ A⁻¹, A = J W⁻¹ Jᵀ + λ² I, y = A⁻¹ ẋ and u = J^# ẋ:
    J̇^# ẋ = Ẇ⁻¹ Jᵀ y + W⁻¹ J̇ᵀ y − J^# Ȧ y, with
    Ȧ y = J̇ u + J Ẇ⁻¹ Jᵀ y + J W⁻¹ J̇ᵀ y, and Ẇ⁻¹ z = −H⁻¹ Ḣ H⁻¹ z for W = H
    (Ḣ = C + Cᵀ), 0 for W = I. (tests/reference_math.py has the matrix form.)
    """
    C = terms.C if inertia_weighted else _NO_C
    return _task_velocity_compensation(
        terms.J,
        terms.Jdot,
        terms.xdot,
        terms.Jdot_v,
        C,
        terms.H_inv,
        pinv.A_inv,
        pinv.J_pinv,
        pinv.W_inv,
        inertia_weighted,
    )


_NO_C = np.zeros((0, 0))  # stands for an absent C in the compiled kernels


@njit(cache=True)
def _null_space_law(
    H,
    H_inv,
    C,
    J,
    Jdot,
    v,
    xdot,
    Jdot_v,
    J_pinv,
    N,
    A_inv,
    W_inv,
    qdot_ns_d,
    qddot_ns_d,
    K_n,
    task_velocity_comp,
    coriolis_comp,
    inertia_weighted,
):
    """(τ₀, eⁿ, ν) of Eqs. 21, 14, 23 (the module docstring)."""
    e_n = null_space_velocity_error(qdot_ns_d, N, v)
    a = qddot_ns_d + K_n * e_n
    if task_velocity_comp:
        a = a + _task_velocity_compensation(
            J, Jdot, xdot, Jdot_v, C, H_inv, A_inv, J_pinv, W_inv, inertia_weighted
        )
    if coriolis_comp:
        a = a + H_inv @ (C @ e_n)
    return H @ (N @ a), e_n, lyapunov(H, e_n)


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
    pinv = inverse.at(terms)
    needs_C = coriolis_comp or (task_velocity_comp and inverse.inertia_weighted)
    if needs_C and terms.C is None:
        raise ValueError("the Coriolis compensation needs C in the robot terms")
    tau0, e_n, nu = _null_space_law(
        terms.H,
        terms.H_inv,
        terms.C if needs_C else _NO_C,
        terms.J,
        terms.Jdot,
        terms.v,
        terms.xdot,
        terms.Jdot_v,
        pinv.J_pinv,
        pinv.N,
        pinv.A_inv,
        pinv.W_inv,
        qdot_ns_d,
        qddot_ns_d,
        float(K_n),
        task_velocity_comp,
        coriolis_comp,
        inverse.inertia_weighted,
    )
    return NullSpaceResult(tau0=tau0, e_n=e_n, nu=nu, N=pinv.N)

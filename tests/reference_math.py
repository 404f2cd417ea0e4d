"""Reference math for the tests: the matrix forms of what nsdrake computes in
vector form or by memoised shortcuts (the weighted inverse and its derivative, the
projector, the task-velocity compensation through J̇^#), written from the formulas
in nsdrake/pseudo_inverse.py and nsdrake/null_space.py. The package never calls them."""

from __future__ import annotations

import numpy as np

from nsdrake.control.pseudo_inverse import GeneralizedInverse


def weighted_inverse(J: np.ndarray, W_inv: np.ndarray, damping: float = 0.0) -> np.ndarray:
    """J^# = W⁻¹ Jᵀ (J W⁻¹ Jᵀ + λ² I)⁻¹ for a symmetric positive-definite W."""
    A = J @ W_inv @ J.T
    if damping:
        A = A + damping**2 * np.eye(J.shape[0])
    # A is symmetric, so J^# = (A⁻¹ J W⁻¹)ᵀ.
    return np.linalg.solve(A, J @ W_inv).T


def weighted_inverse_derivative(
    J: np.ndarray,
    Jdot: np.ndarray,
    W_inv: np.ndarray,
    W_inv_dot: np.ndarray | None,
    damping: float = 0.0,
) -> np.ndarray:
    """d/dt J^# for J^# = W⁻¹ Jᵀ A⁻¹, A = J W⁻¹ Jᵀ + λ² I.

    d(J^#) = Ẇ⁻¹ Jᵀ A⁻¹ + W⁻¹ J̇ᵀ A⁻¹ − W⁻¹ Jᵀ A⁻¹ Ȧ A⁻¹, with
    Ȧ = J̇ W⁻¹ Jᵀ + J Ẇ⁻¹ Jᵀ + J W⁻¹ J̇ᵀ. ``W_inv_dot`` None means W is constant.
    """
    m = J.shape[0]
    A = J @ W_inv @ J.T
    if damping:
        A = A + damping**2 * np.eye(m)
    A_inv = np.linalg.inv(A)
    WJt = W_inv @ J.T
    A_dot = Jdot @ WJt
    A_dot = A_dot + A_dot.T
    term = W_inv @ Jdot.T
    if W_inv_dot is not None:
        A_dot = A_dot + J @ W_inv_dot @ J.T
        term = term + W_inv_dot @ J.T
    return (term - WJt @ A_inv @ A_dot) @ A_inv


def pinv_of(inverse: GeneralizedInverse, J: np.ndarray, H_inv: np.ndarray) -> np.ndarray:
    """J^# (n, m) for ``inverse``."""
    W_inv = H_inv if inverse.inertia_weighted else np.eye(J.shape[1])
    return weighted_inverse(J, W_inv, inverse.damping)


def pinv_derivative(
    inverse: GeneralizedInverse, J: np.ndarray, Jdot: np.ndarray, H_inv: np.ndarray, H_inv_dot: np.ndarray
) -> np.ndarray:
    """d/dt J^# (n, m); H_inv_dot = d/dt H⁻¹ = −H⁻¹ Ḣ H⁻¹."""
    if inverse.inertia_weighted:
        return weighted_inverse_derivative(J, Jdot, H_inv, H_inv_dot, inverse.damping)
    return weighted_inverse_derivative(J, Jdot, np.eye(J.shape[1]), None, inverse.damping)


def H_inv_dot(T) -> np.ndarray:
    """d/dt H⁻¹ = −H⁻¹ Ḣ H⁻¹ with Ḣ = C + Cᵀ, for RobotTerms ``T`` (needs C)."""
    return -T.H_inv @ T.Hdot @ T.H_inv


def task_velocity_compensation(
    J: np.ndarray, Jdot: np.ndarray, J_pinv: np.ndarray, J_pinv_dot: np.ndarray, v: np.ndarray
) -> np.ndarray:
    """(J̇^# J + J^# J̇) q̇ = −Ṅ q̇ (Eqs. 15, 21), from the matrix J̇^#. (n,) [rad/s²]."""
    return J_pinv_dot @ (J @ v) + J_pinv @ (Jdot @ v)


def task_space_inertia(J: np.ndarray, H_inv: np.ndarray) -> np.ndarray:
    """Λ = (J H⁻¹ Jᵀ)⁻¹ (Eq. 13), the task-space inertia, without any cap. (m, m)."""
    return np.linalg.inv(J @ H_inv @ J.T)


def dynamically_consistent_inverse(J: np.ndarray, H_inv: np.ndarray) -> np.ndarray:
    """J̄ = H⁻¹ Jᵀ Λ (Eq. 13), the inertia-weighted pseudo-inverse. (n, m)."""
    return weighted_inverse(J, H_inv)


def moore_penrose_inverse(J: np.ndarray) -> np.ndarray:
    """J⁺ = Jᵀ (J Jᵀ)⁻¹ for a full-row-rank J. (n, m)."""
    return weighted_inverse(J, np.eye(J.shape[1]))


def null_space_projector(J: np.ndarray, J_pinv: np.ndarray) -> np.ndarray:
    """N = I − J^# J (Eq. 4). (n, n)."""
    return np.eye(J.shape[1]) - J_pinv @ J

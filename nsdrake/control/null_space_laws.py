"""The null-space laws people run today, beside the paper's (issue 19): the one home of
their torques. Each is a pure function of the model terms; the controller's null-space
stage (:mod:`nsdrake.control.stages`) calls the one ``null_space.law`` names.

All share the secondary objective of a posture q_d (:func:`posture_target`) and leave
the task law of Eqs. 6–8 untouched; only τ₀ differs.

- ``paper`` (:mod:`nsdrake.control.null_space`): null-space *velocity* control, Eq. 21,
  τ₀ = H N (q̈_dⁿ + (J̇^# J + J^# J̇) q̇ + K_n eⁿ + H⁻¹ C eⁿ), with q̇_dⁿ from the posture
  criterion p = ½ (q − q_d)ᵀ W (q − q_d) through Eq. 30
  (:mod:`nsdrake.control.criteria.posture`). With ``pseudo_inverse: moore_penrose`` the
  same law through J⁺ (no dynamic consistency).
- ``kinematic_posture_pd``: the form of the common Cartesian impedance examples for the
  Panda and the controllers derived from them:

      τ₀ = (I − Jᵀ (Jᵀ)⁺_λ) τ_p,   τ_p = K_ns (q_d − q) − D_ns q̇,

  K_ns a joint stiffness [N m/rad], D_ns a joint damping [N m s/rad] (the examples fix it at
  2 √K_ns; here it is free), no inertia terms. (Jᵀ)⁺_λ = (J Jᵀ + λ² I)⁻¹ J is the damped
  least-squares inverse, the Moore–Penrose inverse at λ = 0; franka_ros's example damps it
  with λ = 0.2. At λ = 0 the projector is orthogonal in the Euclidean metric:
  (Jᵀ)⁺ τ₀ = 0 (no task *force*), but J H⁻¹ τ₀ ≠ 0 in general: τ₀ accelerates the task.
  At λ > 0 it also passes part of τ_p into the task's force directions, most along the
  weakest: by σ_i² / (σ_i² + λ²) → λ² / (σ_i² + λ²) of τ_p's share along Jᵀ's i-th left
  singular vector (singular value σ_i) is left in τ₀.
- ``dynamically_consistent_posture_pd``: operational-space control in Khatib's form (as
  in the common OSC libraries):

      τ₀ = (I − Jᵀ J̄ᵀ) H (K_ns (q_d − q) − D_ns q̇),   J̄ = H⁻¹ Jᵀ Λ,  Λ = (J H⁻¹ Jᵀ)⁻¹,

  K_ns [1/s²], D_ns [1/s] in acceleration units. J H⁻¹ (I − Jᵀ J̄ᵀ) = J H⁻¹ − Λ⁻¹ Λ J H⁻¹ = 0:
  τ₀ causes no task acceleration. Its equilibrium (q̇ = 0, q_d off the self-motion) is
  Zᵀ H (q − q_d) = 0, Z a basis of J's null space: the posture is held in the inertia metric.
- ``dynamically_consistent_torque_pd``: the same projector on a joint-space PD torque, not
  multiplied by H (as in mjctrl's operational-space example):

      τ₀ = (I − Jᵀ J̄ᵀ) (K_ns (q_d − q) − D_ns q̇),

  K_ns [N m/rad], D_ns [N m s/rad]. No task acceleration, as above; its equilibrium is
  Zᵀ (q − q_d) = 0: the posture is held in joint space.

Here Λ is the exact task inertia (no cap, unlike the task law's): the projector is the
law as its users write it, and near a singular pose it grows as they see it grow.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from nsdrake.control.smoothing import compiled_smoothstep

PAPER, KINEMATIC_POSTURE_PD, DYNAMICALLY_CONSISTENT_POSTURE_PD, DYNAMICALLY_CONSISTENT_TORQUE_PD = range(4)
# The choices of ``null_space.law``, by their code in the controller's plan.
LAWS = {"paper": PAPER, "kinematic_posture_pd": KINEMATIC_POSTURE_PD,
        "dynamically_consistent_posture_pd": DYNAMICALLY_CONSISTENT_POSTURE_PD,
        "dynamically_consistent_torque_pd": DYNAMICALLY_CONSISTENT_TORQUE_PD}  # fmt: skip


@njit(cache=True, inline="always")
def kinematic_projector(J: np.ndarray, damping: float) -> np.ndarray:
    """I − Jᵀ (Jᵀ)⁺_λ, λ = ``damping``: (Jᵀ)⁺ the Moore–Penrose inverse (by SVD) at λ = 0,
    else (J Jᵀ + λ² I)⁻¹ J (module docstring). (n, n), symmetric."""
    n = J.shape[1]
    if damping == 0.0:
        return np.eye(n) - J.T @ np.linalg.pinv(np.ascontiguousarray(J.T))
    A = J @ J.T + damping * damping * np.eye(J.shape[0])
    return np.eye(n) - J.T @ np.linalg.solve(A, J)


@njit(cache=True, inline="always")
def dynamically_consistent_projector_transpose(H_inv: np.ndarray, J: np.ndarray) -> np.ndarray:
    """I − Jᵀ J̄ᵀ with J̄ = H⁻¹ Jᵀ Λ, Λ = (J H⁻¹ Jᵀ)⁻¹ (exact, Eq. 13's J̄). (n, n)."""
    H_inv_Jt = H_inv @ J.T
    Lambda = np.linalg.inv(J @ H_inv_Jt)
    J_bar = H_inv_Jt @ Lambda
    return np.eye(J.shape[1]) - J.T @ J_bar.T


@njit(cache=True)
def kinematic_posture_torque(J, q, v, q_d, K_ns, D_ns, damping) -> np.ndarray:
    """τ₀ = (I − Jᵀ (Jᵀ)⁺_λ)(K_ns (q_d − q) − D_ns q̇), λ = ``damping`` (module docstring).
    (n,) [N m]."""
    return kinematic_projector(J, damping) @ (K_ns * (q_d - q) - D_ns * v)


@njit(cache=True)
def dynamically_consistent_posture_torque(H, H_inv, J, q, v, q_d, K_ns, D_ns) -> np.ndarray:
    """τ₀ = (I − Jᵀ J̄ᵀ) H (K_ns (q_d − q) − D_ns q̇) (module docstring). (n,) [N m]."""
    return dynamically_consistent_projector_transpose(H_inv, J) @ (H @ (K_ns * (q_d - q) - D_ns * v))


@njit(cache=True)
def dynamically_consistent_torque_pd(H_inv, J, q, v, q_d, K_ns, D_ns) -> np.ndarray:
    """τ₀ = (I − Jᵀ J̄ᵀ)(K_ns (q_d − q) − D_ns q̇) (module docstring). (n,) [N m]."""
    return dynamically_consistent_projector_transpose(H_inv, J) @ (K_ns * (q_d - q) - D_ns * v)


@njit(cache=True, inline="always")
def posture_target(q_d, offset, t, offset_time, ramp_time) -> np.ndarray:
    """q_d(t) = q_d + smoothstep((t − t_o)/T_r) Δq: the posture, moved by the offset Δq
    from t_o over the ramp T_r (a step at t_o for T_r = 0). (n,) [rad]."""
    if t < offset_time:
        return q_d.copy()
    rise = compiled_smoothstep((t - offset_time) / ramp_time) if ramp_time > 0 else 1.0
    return q_d + rise * offset

"""The primary task: task-space impedance control of position and force (Eqs. 6–8, 10).

Control law, Eqs. 6–7 (τ₀ is added by the null-space controller):

    τ = Jᵀ ( Λ (ẍ_c − J̇ q̇) + F ) + C q̇ + g + τ₀

with F the measured force the tool exerts on the environment (Eq. 5's sign) and
Λ = (J H⁻¹ Jᵀ)⁻¹. With an exact model and J H⁻¹ τ₀ = 0 (Eq. 11), the task
closed loop is ẍ = ẍ_c.

Eq. 5 treats the tool as a point. nsdrake's tool is a sphere of radius r: the
friction force acts on its surface, r away from the task point T, and its
moment r × f_t loads every joint (1.5 cm × 3 N on the fig3 arm gave a 10%
normal-force error when left out). The sensor under the plate is a six-axis
sensor, as the paper's JR3, so :func:`primary_torque` compensates the whole
measured wrench W_T = [M_T; f] transported to T, with the spatial Jacobian J_T
of T: the term Jᵀ F becomes J_Tᵀ W_T, which is Jᵀ F when the contact is a pure
force through T.

The paper says x_d "includes position and force" but leaves the force part of
the command open. nsdrake's command acceleration, with n the unit task-space
direction in which the tool pushes on the plate and f_n = nᵀF:

    ẍ_c = ẍ_d + K_v (ẋ_d − ẋ) + K_p (x_d − x) + n K_f (f_d − f_n)      (Eq. 8 + force term)

K_p = k_p,t (I − n nᵀ) + k_p,n n nᵀ and likewise K_v: stiffness and damping
along the plate (t) and normal to it (n). Eq. 8 is written with the signs of
Eq. 10 (the printed text's (ẋ − ẋ_d), (x − x_d) in Eq. 8 are sign slips of its OCR).

Along the plate this is Eq. 8: the friction force μ f_n is part of F, so the
Jᵀ F term cancels it and it leaves no position error.

Pose tasks. With rotational task axes (``rx``, ``ry``, ``rz``) x stacks the tool
position on the translational axes and the tool's orientation; ẋ = J q̇ is
[v_T; ω] on those axes, Λ = (J H⁻¹ Jᵀ)⁻¹ is 6 × 6 for the full pose and J̇ q̇ is
the spatial acceleration bias. x_d − x becomes the pose error
e = [x_d − x; e_o], e_o = log(R_d R_WTᵀ) the rotation vector from the measured to
the desired tool frame (:mod:`nsdrake.control.orientation` says why the closed loop is
still Eq. 10's), the rotational gains are scalars k_p,r I and k_v,r I, and n has
zeros on the rotational rows: the force is pushed along a translational direction,
and the measured moment enters only through J_Tᵀ W_T.

Normal to the plate, in contact with a surface of stiffness k_c (a point
contact: f_n ≈ k_c × penetration), and with x_d,n held fixed after contact,
the steady state of ẍ = ẍ_c is

    0 = k_p,n (x_d,n − x_n) + K_f (f_d − f_n)   ⇒   f_n − f_d = (k_p,n / K_f)(x_d,n − x_n).

The normal position loop pulls the tool back toward x_d,n while the force loop
pushes it in; each extra millimetre of penetration beyond x_d,n costs
k_p,n/K_f × 1 mm of force. With x_d,n frozen where contact was detected,
x_n − x_d,n ≈ (f_n − f_contact)/k_c, so the relative steady-state error is
≈ −k_p,n / (k_p,n + K_f k_c): small when K_f k_c ≫ k_p,n (0.2% for the fig3
gains), zero for k_p,n = 0. This is the paper's observation that the position
loop stabilises force tracking but leaves a steady-state force error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from nsdrake.control.dynamics import RobotTerms
from nsdrake.control.orientation import orientation_error


@dataclass(frozen=True)
class ImpedanceGains:
    """Gains of Eq. 8 and the force term, as task-space matrices. m task axes."""

    K_p: np.ndarray  # (m, m) position gain [1/s²]
    K_v: np.ndarray  # (m, m) velocity gain [1/s]
    K_f: float  # force gain [m/(s² N)]
    normal: np.ndarray  # (m,) unit direction in which the tool pushes (zero on rotational rows)

    @classmethod
    def along_surface(
        cls,
        normal: np.ndarray,
        K_p_tangent: float,
        K_p_normal: float,
        K_v_tangent: float,
        K_v_normal: float,
        K_f: float,
        K_p_rotation: float = 0.0,
        K_v_rotation: float = 0.0,
        rotational_axes: int = 0,
    ) -> ImpedanceGains:
        """Gains diagonal in the frame of a surface with unit normal ``normal`` (on the
        translational axes), and, for ``rotational_axes`` rotational rows after them,
        the scalar rotational gains k_p,r I and k_v,r I [1/s², 1/s]. A zero ``normal`` is
        no force axis (a free-space task): every translational axis takes the tangent
        gains, and the force term n K_f (f_d − nᵀF) vanishes with n."""
        n = np.asarray(normal, dtype=float)
        if np.linalg.norm(n) > 0:
            n = n / np.linalg.norm(n)
        P_n = np.outer(n, n)
        P_t = np.eye(n.shape[0]) - P_n
        K_p = K_p_tangent * P_t + K_p_normal * P_n
        K_v = K_v_tangent * P_t + K_v_normal * P_n
        if rotational_axes:
            K_p = _block_diagonal(K_p, K_p_rotation * np.eye(rotational_axes))
            K_v = _block_diagonal(K_v, K_v_rotation * np.eye(rotational_axes))
            n = np.concatenate([n, np.zeros(rotational_axes)])
        return cls(K_p=K_p, K_v=K_v, K_f=K_f, normal=n)


def _block_diagonal(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    out = np.zeros((A.shape[0] + B.shape[0], A.shape[1] + B.shape[1]))
    out[: A.shape[0], : A.shape[1]] = A
    out[A.shape[0] :, A.shape[1] :] = B
    return out


def command_acceleration(
    x: np.ndarray,
    xdot: np.ndarray,
    x_d: np.ndarray,
    xdot_d: np.ndarray,
    xddot_d: np.ndarray,
    F: np.ndarray,
    f_d: float,
    gains: ImpedanceGains,
) -> np.ndarray:
    """ẍ_c = ẍ_d + K_v (ẋ_d − ẋ) + K_p (x_d − x) + n K_f (f_d − nᵀF). (m,) [m/s²]."""
    return command_acceleration_from_error(x_d - x, xdot, xdot_d, xddot_d, F, f_d, gains)


def command_acceleration_from_error(
    error: np.ndarray,
    xdot: np.ndarray,
    xdot_d: np.ndarray,
    xddot_d: np.ndarray,
    F: np.ndarray,
    f_d: float,
    gains: ImpedanceGains,
) -> np.ndarray:
    """ẍ_c = ẍ_d + K_v (ẋ_d − ẋ) + K_p e + n K_f (f_d − nᵀF) for a task error e (x_d − x,
    or the pose error of :func:`pose_error`). (m,) [m/s², rad/s² on rotational rows]."""
    return _command_acceleration(
        error, xdot, xdot_d, xddot_d, F, float(f_d), gains.K_p, gains.K_v, gains.K_f, gains.normal
    )


@njit(cache=True)
def _command_acceleration(error, xdot, xdot_d, xddot_d, F, f_d, K_p, K_v, K_f, normal):
    f_n = normal @ F
    return xddot_d + K_v @ (xdot_d - xdot) + K_p @ error + normal * (K_f * (f_d - f_n))


@njit(cache=True)
def pose_error(
    x: np.ndarray, x_d: np.ndarray, R_WT: np.ndarray, R_d: np.ndarray, rot_rows: np.ndarray
) -> np.ndarray:
    """e = [x_d − x; e_o[rot_rows]], e_o = log(R_d R_WTᵀ) (:mod:`nsdrake.control.orientation`).
    (m,) [m, rad]."""
    return np.concatenate((x_d - x, orientation_error(R_d, R_WT)[rot_rows]))


@njit(cache=True)
def task_wrench(W_T: np.ndarray, rows: np.ndarray, rot_rows: np.ndarray) -> np.ndarray:
    """F on the task axes from the wrench [M_T; f] at the tool point: the force on the
    translational rows, the moment on the rotational ones. (m,) [N, N m]."""
    return np.concatenate((W_T[3:][rows], W_T[:3][rot_rows]))


@njit(cache=True)
def wrench_at_tool(wrench_So: np.ndarray, p_WSo: np.ndarray, p_WT: np.ndarray) -> np.ndarray:
    """[M_T; f] from [M_So; f]: the moment moves from the sensor origin So to the
    tool point T, M_T = M_So + (p_So − p_T) × f. (6,) world [N m, N]."""
    f = wrench_So[3:]
    r = p_WSo - p_WT
    out = wrench_So.copy()
    out[0] += r[1] * f[2] - r[2] * f[1]
    out[1] += r[2] * f[0] - r[0] * f[2]
    out[2] += r[0] * f[1] - r[1] * f[0]
    return out


def primary_torque(
    terms: RobotTerms, xddot_c: np.ndarray, W_T: np.ndarray, gravity_compensation: bool = True
) -> np.ndarray:
    """τ − τ₀ = Jᵀ Λ (ẍ_c − J̇ q̇) + J_Tᵀ W_T + C q̇ + g (Eqs. 6–7). (n,) [N m].

    W_T = [M_T; f] (6) is the wrench the tool exerts on the environment, about
    the tool point, in world coordinates; for a pure force, J_Tᵀ W_T = Jᵀ F.
    ``gravity_compensation`` False drops g (harmless in the horizontal plane).
    """
    return _primary_torque(*_model_terms(terms), xddot_c, W_T, gravity_compensation)


def _model_terms(terms: RobotTerms) -> tuple:
    """The terms Eqs. 6–7 need, as the compiled kernels take them: J, Λ, J̇ q̇, J_T, C q̇, g."""
    return terms.J, terms.Lambda, terms.Jdot_v, terms.J_spatial, terms.Cv, terms.g


@njit(cache=True)
def _primary_torque(J, Lambda, Jdot_v, J_spatial, Cv, g, xddot_c, W_T, gravity_compensation):
    tau = J.T @ (Lambda @ (xddot_c - Jdot_v)) + J_spatial.T @ W_T + Cv
    if gravity_compensation:
        tau = tau + g
    return tau


def position_task_torque(
    terms: RobotTerms,
    x_d: np.ndarray,
    xdot_d: np.ndarray,
    xddot_d: np.ndarray,
    f_d: float,
    W_T: np.ndarray,
    rows: np.ndarray,
    gains: ImpedanceGains,
    gravity_compensation: bool = True,
) -> np.ndarray:
    """τ − τ₀ of a position task in one compiled call: :func:`command_acceleration` with F
    the force of the wrench W_T = [M_T; f] on the task ``rows``, then :func:`primary_torque`.
    (n,) [N m]."""
    g = gains
    return _position_task_torque(
        terms.x, terms.xdot, x_d, xdot_d, xddot_d, float(f_d), W_T, rows, g.K_p, g.K_v, g.K_f, g.normal,
        *_model_terms(terms), gravity_compensation,
    )  # fmt: skip


@njit(cache=True)
def _position_task_torque(
    x, xdot, x_d, xdot_d, xddot_d, f_d, W_T, rows, K_p, K_v, K_f, normal, J, Lambda, Jdot_v, J_spatial, Cv, g,
    gravity_compensation,
):  # fmt: skip
    F = W_T[3:][rows]
    xddot_c = _command_acceleration(x_d - x, xdot, xdot_d, xddot_d, F, f_d, K_p, K_v, K_f, normal)
    return _primary_torque(J, Lambda, Jdot_v, J_spatial, Cv, g, xddot_c, W_T, gravity_compensation)


@njit(cache=True)
def pose_task_torque(
    x, xdot, R_WT, x_d, xdot_d, xddot_d, f_d, R_d, omega_d, omegadot_d, W_T, rows, rot_rows,
    K_p, K_v, K_f, normal, J, Lambda, Jdot_v, J_spatial, Cv, g, gravity_compensation,
):  # fmt: skip
    """τ − τ₀ of a pose task in one compiled call: :func:`command_acceleration_from_error`
    with the pose error (:func:`pose_error`), ẋ_d = [ẋ_d; ω_d], ẍ_d = [ẍ_d; ω̇_d] on the
    rotational rows and F = :func:`task_wrench`, then :func:`primary_torque`. (n,) [N m]."""
    error = pose_error(x, x_d, R_WT, R_d, rot_rows)
    xdot_d_task = np.concatenate((xdot_d, omega_d[rot_rows]))
    xddot_d_task = np.concatenate((xddot_d, omegadot_d[rot_rows]))
    F = task_wrench(W_T, rows, rot_rows)
    xddot_c = _command_acceleration(error, xdot, xdot_d_task, xddot_d_task, F, f_d, K_p, K_v, K_f, normal)
    return _primary_torque(J, Lambda, Jdot_v, J_spatial, Cv, g, xddot_c, W_T, gravity_compensation)

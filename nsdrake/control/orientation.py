"""The orientation part of a pose task: the error between desired and measured tool frames.

A pose task (task axes ``x, y, z, rx, ry, rz``) has the tool's angular velocity ω
(world frame) as the rotational part of ẋ = J q̇, but no orientation coordinates
whose derivative ω would be. Eq. 8's x_d − x is replaced on the rotational rows by

    e_o = log(R_d R_WTᵀ)^∨ = θ u                                             (world frame)

the rotation vector (axis-angle) of the rotation that carries the measured tool
frame R_WT onto the desired one R_d: u its unit axis, θ ∈ [0, π] its angle. So
e_o = 0 exactly when the frames are aligned, and ‖e_o‖ = θ is the angle between
them (the ``rot_err`` trace). The command acceleration's rotational rows are

    ω̇_c = ω̇_d + k_v (ω_d − ω) + k_p e_o                                    (Eq. 8, rotational rows)

and, as for the translational rows, the law of Eqs. 6–7 makes ω̇ = ω̇_c (Λ is the
6 × 6 operational-space inertia of the spatial Jacobian, J̇ q̇ its spatial bias), so
the closed loop is Eq. 10 with the pose error in place of x_d − x:

    (ω̇_d − ω̇) + k_v (ω_d − ω) + k_p e_o = 0.                               (Eq. 10, rotational rows)

Why this is still the stable second-order system Eq. 10 promises, although ω_d − ω
is not the derivative of e_o: with R_e = R_d R_WTᵀ, Ṙ_e = [ω_d − R_e ω]× R_e, and
since R_e and the (left) Jacobian of the logarithm leave e_o's own axis unchanged,

    e_oᵀ ė_o = e_oᵀ (ω_d − ω),   i.e.  θ̇ = uᵀ (ω_d − ω),

exactly, at any angle below π: the error angle changes at the rate of the angular
velocity error along its axis (tests/control/test_pose_task.py checks both the derivative
and this identity). With scalar gains k_p, k_v > 0 the energy
V = ½ ‖ω_d − ω‖² + ½ k_p ‖e_o‖² then decreases along the closed loop, V̇ = −k_v
‖ω_d − ω‖², for any desired motion, and by LaSalle ω → ω_d and e_o → 0: the same
spring–damper behaviour Eq. 10 gives the translational rows, with θ as the
spring's extension. Near alignment ė_o = (ω_d − ω) + O(θ ‖ω_d − ω‖), so for small
errors the rotational rows are the linear Eq. 10 itself. The logarithm is chosen
over other error measures (quaternion vector part sin(θ/2) u, ½ vee(R_e − R_eᵀ) =
sin θ u) because its size is the angle itself and its stiffness does not fade as
the error grows (sin θ peaks at 90°). A task with only some rotational axes keeps
those rows of e_o, exact when the rotation stays about them (a planar arm's rz).

Quaternions are [w, x, y, z] (Drake's order), unit length, normalised on input.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from pydrake.math import RotationMatrix


@njit(cache=True)
def quaternion_to_rotation(quaternion: np.ndarray) -> np.ndarray:
    """R (3, 3) of the quaternion [w, x, y, z] (normalised first; zero gives I)."""
    w, x, y, z = quaternion[0], quaternion[1], quaternion[2], quaternion[3]
    s = w * w + x * x + y * y + z * z
    if s == 0.0:
        return np.eye(3)
    s = 2.0 / s
    R = np.empty((3, 3))
    R[0, 0], R[0, 1], R[0, 2] = 1.0 - s * (y * y + z * z), s * (x * y - w * z), s * (x * z + w * y)
    R[1, 0], R[1, 1], R[1, 2] = s * (x * y + w * z), 1.0 - s * (x * x + z * z), s * (y * z - w * x)
    R[2, 0], R[2, 1], R[2, 2] = s * (x * z - w * y), s * (y * z + w * x), 1.0 - s * (x * x + y * y)
    return R


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """The unit quaternion [w, x, y, z] of a rotation matrix, with w ≥ 0. (4,)."""
    q = RotationMatrix(np.asarray(R, dtype=float)).ToQuaternion()
    out = np.array([q.w(), q.x(), q.y(), q.z()])
    return out if out[0] >= 0 else -out


# Below this angle the rotation vector uses the series of θ / (2 sin θ) [rad].
_SMALL_ANGLE = 1e-4
# Above this angle the axis comes from the symmetric part of R (sin θ is too small) [rad].
_NEAR_PI = 3.0


@njit(cache=True)
def rotation_log(R: np.ndarray) -> np.ndarray:
    """The rotation vector θ u of R = exp([θ u]×), θ ∈ [0, π]. (3,) [rad].

    θ = atan2(½‖w‖, ½(tr R − 1)) with w = vee(R − Rᵀ) = 2 sin θ u, which keeps full
    precision at small angles (arccos would lose half the digits); the axis is w/‖w‖,
    except near π where sin θ → 0 and it comes from R + Rᵀ = 2 I + 2(1 − cos θ)(u uᵀ − I)
    (its sign from w).
    """
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    s = 0.5 * math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    theta = math.atan2(s, c)
    if theta < _SMALL_ANGLE:
        return w * (0.5 * (1.0 + theta * theta / 6.0))  # θ / (2 sin θ) ≈ ½ (1 + θ²/6)
    if theta < _NEAR_PI:
        return w * (theta / (2.0 * s))
    B = np.empty((3, 3))  # u uᵀ = (½(R + Rᵀ) − cos θ I) / (1 − cos θ)
    for i in range(3):
        for j in range(3):
            B[i, j] = 0.5 * (R[i, j] + R[j, i]) - (c if i == j else 0.0)
    k = 0
    for i in range(1, 3):
        if B[i, i] > B[k, k]:
            k = i
    u = B[:, k] / math.sqrt(B[k, k] * (1.0 - c))
    u = u / math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    if u[0] * w[0] + u[1] * w[1] + u[2] * w[2] < 0.0:
        u = -u
    return theta * u


@njit(cache=True)
def orientation_error(R_d: np.ndarray, R_WT: np.ndarray) -> np.ndarray:
    """e_o = log(R_d R_WTᵀ)^∨, world frame (module docstring). (3,) [rad]."""
    return rotation_log(R_d @ R_WT.T)


def orientation_error_angle(R_d: np.ndarray, R_WT: np.ndarray) -> float:
    """θ = ‖e_o‖, the angle between the desired and the measured tool frames [rad]."""
    # C-contiguous float arrays: the one list of types the kernel is compiled for
    R_d, R_WT = np.ascontiguousarray(R_d, dtype=float), np.ascontiguousarray(R_WT, dtype=float)
    return float(np.linalg.norm(orientation_error(R_d, R_WT)))

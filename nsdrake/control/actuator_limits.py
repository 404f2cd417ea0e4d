"""Actuator limits that keep the primary task's priority.

A real arm's drives saturate: each joint's torque stays within ±τ_max and changes by
at most ρ_max T per control period T. Clipping the summed torque τ = τ_task + τ₀
joint by joint would let the null-space torque τ₀ push the task torque out of the
actuators' range. So τ₀ gives way first:

    τ = τ_task + s τ₀,   s ∈ [0, 1] the largest with lo ≤ τ_task + s τ₀ ≤ hi,

for each joint's window [lo, hi] = [−τ_max, τ_max] ∩ [τ_prev − ρ_max T, τ_prev + ρ_max T].
Since J H⁻¹ τ₀ = 0 (Eq. 11), scaling τ₀ leaves the task untouched; only the
null-space velocity tracking slows down. Only when τ_task alone leaves a window
(s = 0) is τ_task clipped to it, joint by joint, and then the primary task itself
is degraded: the number of such joints is reported.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def limit_torque(tau_task, tau0, lower, upper):
    """(τ, s, clipped): τ = τ_task + s τ₀ within [lower, upper] per joint (module docstring);
    ``clipped`` counts the joints where τ_task itself had to be clipped."""
    s = 1.0
    clipped = 0
    for i in range(tau_task.shape[0]):
        a, b = tau_task[i], tau0[i]
        if a < lower[i] or a > upper[i]:
            s = 0.0
            clipped += 1
        elif b > 0.0 and a + b > upper[i]:
            s = min(s, (upper[i] - a) / b)
        elif b < 0.0 and a + b < lower[i]:
            s = min(s, (lower[i] - a) / b)
    tau = np.minimum(upper, np.maximum(lower, tau_task + s * tau0))
    return tau, s, clipped


@njit(cache=True)
def torque_window(tau_max, rate_max, period, tau_prev, has_previous):
    """(lower, upper) per joint: ±τ_max, narrowed to τ_prev ± ρ_max T when a previous
    torque exists (``has_previous`` False: the first period, no rate limit, ``tau_prev``
    ignored). [N m]."""
    if not has_previous:
        return -tau_max, tau_max.copy()
    step = rate_max * period
    return np.maximum(-tau_max, tau_prev - step), np.minimum(tau_max, tau_prev + step)


@njit(cache=True)
def limited_torque(tau_task, tau0, tau_max, rate_max, period, tau_prev, has_previous):
    """[τ; s; clipped] (n + 2): :func:`limit_torque` within :func:`torque_window`, in one
    compiled call (``has_previous`` False: no previous torque, ``tau_prev`` ignored)."""
    lower, upper = torque_window(tau_max, rate_max, period, tau_prev, has_previous)
    tau, s, clipped = limit_torque(tau_task, tau0, lower, upper)
    out = np.empty(tau.shape[0] + 2)
    out[: tau.shape[0]] = tau
    out[-2], out[-1] = s, clipped
    return out

"""Actuator limits that keep the primary task's priority.

A real arm's drives saturate: each joint's torque stays within ±τ_max and changes by
at most ρ_max T per control period T. Clipping the summed torque τ = τ_task + τ₀
joint by joint would let the null-space torque τ₀ push the task torque out of the
actuators' range. So τ₀ gives way first:

    τ = τ_task + s τ₀,   s = max S,   S = {s ∈ [0, 1] : lo_j ≤ τ_task,j + s τ₀,j ≤ hi_j ∀ j},

for each joint's window [lo_j, hi_j] = [c − τ_max, c + τ_max] ∩ [τ_prev − ρ_max T, τ_prev + ρ_max T]
(:func:`torque_window`). The centre c is 0 for actuators that apply τ; for a robot that adds
its own g(q) to the command it is sent (Franka's torque interface), what its joints are
asked for is τ − g(q), and its limits bound that: c = g(q), so that τ − g(q) ∈ ±τ_max by
the limiter's own guarantee (:class:`nsdrake.control.step.ControllerStep`'s
``robot_adds_gravity``). Each joint allows an interval of s (:func:`scale_interval`),
S is their intersection with [0, 1], an interval too. For a τ₀ with J H⁻¹ τ₀ = 0 (Eq. 11:
the paper's law, the dynamically consistent posture PDs) scaling τ₀ leaves the task
untouched; only the null-space velocity tracking slows down. A τ₀ outside that null space
(the kinematic posture PD's, projected with I − Jᵀ(Jᵀ)⁺) accelerates the task, and scaling it
changes that disturbance too.

S may hold only positive s: the rate window is centred on the previous torque, which
already holds s τ₀, so when |τ₀_j| > ρ_max T the task torque alone lies outside joint
j's window while a positive s is inside it. (Taking s = 0 there, as a limiter that
treats s = 0 as always feasible does, drops τ₀ for one period and takes it back the
next: a square wave of ±ρ_max T at half the control rate.)

Only when S is empty is the task torque itself out of reach in this period, and then it
is changed: s = 0 and τ is τ_task clipped joint by joint to the windows, the primary task
degraded; the joints clipped are counted (at least one; none while S is not empty).

Why s = 0 there, not the s of the least violation: with τ_task and τ₀ held, s then never
decreases, so every joint's τ turns back at most once, and never chatters. (While S is
empty, each joint moves towards its τ_task, at the full rate where it is out of reach;
once S holds an s it holds it in the next period too, the previous torque τ_task + s τ₀
being inside the next window, so s only grows from there, every joint moving the way of
its τ₀.) An s > 0 while S is empty puts the joints that can follow at τ_task + s τ₀ while
the clipped ones lag behind it, and when these arrive, the next window admits only a
smaller s: s falls back and the others turn twice. Brute-force trials with held inputs
(1500 random cases, ρ_max T = 1 N m) turned a joint back and forth by at least ρ_max T / 2
two or three times in 22 cases with the least total violation and in 4 with the least
largest violation then the least total; in none with s = 0. The cost: while the task
torque is out of reach (a few periods at a contact), τ₀ pauses.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# Relative rounding of τ_task + s τ₀ at an end of a window with s = (bound − τ_task)/τ₀:
# a few units of the last place of the magnitudes involved. S is taken as not empty when
# its largest candidate s is inside every window to this rounding.
ROUNDING = 8.0 * np.finfo(np.float64).eps


@njit(cache=True, inline="always")
def scale_interval(a, b, lo, hi):
    """(s_min, s_max): the s with lo ≤ a + s b ≤ hi, one joint's part of S (module
    docstring); s_min > s_max when none (b = 0 and a outside the window). Unbounded
    ends are ±inf."""
    if b > 0.0:
        return (lo - a) / b, (hi - a) / b
    if b < 0.0:
        return (hi - a) / b, (lo - a) / b
    if lo <= a <= hi:
        return -np.inf, np.inf
    return np.inf, -np.inf


@njit(cache=True, inline="always")
def _fits(x, lo, hi):
    """Whether x is inside [lo, hi] to :data:`ROUNDING`."""
    return lo - ROUNDING * (abs(x) + abs(lo)) <= x <= hi + ROUNDING * (abs(x) + abs(hi))


@njit(cache=True)
def limit_torque(tau_task, tau0, lower, upper):
    """(τ, s, clipped): τ = τ_task + s τ₀ with s the largest in S, else (S empty) s = 0 and
    τ_task clipped joint by joint (module docstring); ``clipped`` counts the joints whose
    τ_task is outside its window then, 0 while S is not empty. Windows with lower ≤ upper."""
    n = tau_task.shape[0]
    s_min, s_max = 0.0, 1.0
    for j in range(n):
        lo, hi = scale_interval(tau_task[j], tau0[j], lower[j], upper[j])
        s_min, s_max = max(s_min, lo), min(s_max, hi)
    s, clipped = s_max, 0
    empty = s_min > s_max and s_max < 0.0
    if s_min > s_max and not empty:  # S is empty, or a single point that rounding split
        for j in range(n):
            if not _fits(tau_task[j] + s * tau0[j], lower[j], upper[j]):
                empty = True
    if empty:
        s = 0.0
        for j in range(n):
            if tau_task[j] < lower[j] or tau_task[j] > upper[j]:
                clipped += 1
    # While S is not empty the clip only takes off the rounding of a + s b at a window's end.
    tau = np.minimum(upper, np.maximum(lower, tau_task + s * tau0))
    return tau, s, clipped


@njit(cache=True)
def torque_window(tau_max, rate_max, period, tau_prev, has_previous, centre):
    """(lower, upper) per joint: ``centre`` ± τ_max (the centre c of the module docstring:
    zeros, or g(q) for a robot that adds g(q) itself), narrowed to τ_prev ± ρ_max T when a
    previous torque exists (``has_previous`` False: the first period, no rate limit,
    ``tau_prev`` ignored). [N m]."""
    lower, upper = centre - tau_max, centre + tau_max
    if not has_previous:
        return lower, upper
    step = rate_max * period
    return np.maximum(lower, tau_prev - step), np.minimum(upper, tau_prev + step)


@njit(cache=True)
def limited_torque(tau_task, tau0, tau_max, rate_max, period, tau_prev, has_previous, centre):
    """[τ; s; clipped] (n + 2): :func:`limit_torque` within :func:`torque_window` (about
    ``centre``), in one compiled call (``has_previous`` False: no previous torque,
    ``tau_prev`` ignored)."""
    lower, upper = torque_window(tau_max, rate_max, period, tau_prev, has_previous, centre)
    tau, s, clipped = limit_torque(tau_task, tau0, lower, upper)
    out = np.empty(tau.shape[0] + 2)
    out[: tau.shape[0]] = tau
    out[-2], out[-1] = s, clipped
    return out

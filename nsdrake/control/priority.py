"""Switching task priorities (Section 3.5, Fig. 1) and multi-level task priority.

Fig. 1's decision tree (its drawing is missing from the text; docs/decision_tree.md describes it):
level 1 is always the primary task (position and force). Then

- a link closer to an obstacle than d_lim      → obstacle avoidance on level 2 (mode 1);
- else, a joint closer to a limit than q_lim   → joint-limit avoidance on level 2 (mode 4);
- else, manipulability w above its limit w_lim → joint-torque minimisation on level 2 (mode 2);
- else                                          → manipulability maximisation on level 2 (mode 3).

The other criteria take the lower levels in a fixed order per mode
(:data:`ORDERINGS`). Mode 0 means no criterion is configured.

Joint-limit avoidance (:mod:`nsdrake.control.criteria.joint_limits`) is not in the paper,
whose arm has no joint limits. It joins the tree as the second test, after the
obstacle and before the two optimisation criteria, and it follows the obstacle in
every ordering, because both guard against damage while joint torque and
manipulability only improve the pose: running into a joint's mechanical stop is, like
a collision, something a lower-priority preference must never cause. A collision is
checked first because it hurts the surroundings too, and because the arm's own
controller brakes a joint at its limit anyway (a real Panda stops), while nothing
stops a link at an obstacle. With q_lim = 0 (the default) the branch never fires
and, with a zero gain, the level does nothing: the paper's three-branch tree.

Each level is resolved in the null space of every level above it, as in the
multi-level task-priority method of Baerlocher & Boulic (1998), here in the
metric of the generalised inverse (H for Eq. 13) and with the gradient-projection
step of Eq. 30 on each level. A criterion level k has the 1 × n "Jacobian" Φ_kᵀ;
with N_1 = I − J^# J and W⁻¹ the inverse's metric (H⁻¹ or I):

    u_k      = N_k W⁻¹ Φ_k   (Eq. 30's rotated, projected gradient; N_k Φ_k unrotated;
                              :func:`nsdrake.control.gradient_projection.gradient_step`)
    q̇_dⁿ    = Σ_k K_k u_k
    N_{k+1} = N_k − v_k v_kᵀ W / (Φ_kᵀ v_k),   v_k = N_k W⁻¹ Φ_k,

the W-weighted projector onto the null space of [J; Φ_2ᵀ; …; Φ_kᵀ]: level k+1
changes neither the task nor any criterion above it to first order, and because
N_k W⁻¹ is symmetric positive semi-definite, each level's step still improves its
own criterion (Φ_kᵀ u_k ≥ 0).

Algorithmic singularities: when a level's gradient has (almost) no component left
in the null space of the levels above (Φ_kᵀ v_k → 0), removing its row hands the
lower levels a whole extra direction at once, and q̇_dⁿ would jump. The update is
therefore damped (Chiaverini's remedy):

    N_{k+1} = N_k − v_k v_kᵀ W / (Φ_kᵀ v_k + δ_k),   δ_k = ρ ‖Φ_k‖² max|W⁻¹|,

which is the exact projection while Φ_kᵀ v_k ≫ δ_k and fades smoothly as it
vanishes. Φ_kᵀ v_k / (‖Φ_k‖² max|W⁻¹|) ∈ [0, 1] is the share of level k's gradient
still free; ρ = 1e-2 (:data:`RANK_DAMPING`).

Levels that switch on and off: obstacle avoidance has no gradient until a link
enters the influence distance. Removing its row the moment its gradient becomes
non-zero would take a direction from the levels below at once, so each level's
row is weighted by an activation a_k ∈ [0, 1] (Mansard et al. 2009):
N_{k+1} = N_k − a_k v_k v_kᵀ W / (Φ_kᵀ v_k + δ_k). A criterion that is always
defined has a_k = 1; the obstacle criterion's activation rises smoothly as links
enter its influence zone (:func:`nsdrake.control.criteria.obstacle.activation`).

Switching: the mode has hysteresis (it leaves mode 1 only once d_min exceeds
d_lim + d_band, and mode 3 only once w exceeds w_lim + w_band), and after every
switch the commanded null-space velocity blends from the old ordering's to the new
ordering's over ``blend_time`` with a smoothstep, so q̇_dⁿ, and with it τ₀, stay
continuous. (A second switch during a blend restarts it from the mode that was
being left, which can leave a small step; hysteresis makes that rare.)
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from numba import njit

from nsdrake.control.gradient_projection import gradient_step, projected_direction
from nsdrake.control.smoothing import compiled_smoothstep


class Criterion(str, enum.Enum):
    obstacle = "obstacle"
    joint_torque = "joint_torque"
    manipulability = "manipulability"
    joint_limits = "joint_limits"


class Mode(enum.IntEnum):
    none = 0
    obstacle_avoidance = 1
    joint_torque = 2
    manipulability = 3
    joint_limits = 4


_O, _L, _T, _M = Criterion.obstacle, Criterion.joint_limits, Criterion.joint_torque, Criterion.manipulability
ORDERINGS: dict[Mode, tuple[Criterion, ...]] = {
    Mode.none: (),
    Mode.obstacle_avoidance: (_O, _L, _T, _M),
    Mode.joint_limits: (_L, _O, _T, _M),
    Mode.joint_torque: (_T, _O, _L, _M),
    Mode.manipulability: (_M, _O, _L, _T),
}


@dataclass(frozen=True)
class SelectorLimits:
    d_lim: float  # [m] a link closer than this to an obstacle puts obstacle avoidance on level 2
    w_lim: float  # manipulability below which its maximisation goes on level 2
    d_band: float = 0.0  # [m] hysteresis on d_lim
    w_band: float = 0.0  # hysteresis on w_lim
    q_lim: float = 0.0  # [rad] a joint closer than this to a limit puts joint-limit avoidance on level 2
    q_band: float = 0.0  # [rad] hysteresis on q_lim

    def as_array(self) -> np.ndarray:
        """[d_lim, d_band, w_lim, w_band, q_lim, q_band], as the compiled selector takes them."""
        limits = (self.d_lim, self.d_band, self.w_lim, self.w_band, self.q_lim, self.q_band)
        return np.array(limits, dtype=float)


def select_mode(
    d_min: float, w: float, previous: Mode, limits: SelectorLimits, margin: float = np.inf
) -> Mode:
    """Fig. 1's decision tree, extended by the joint-limit branch, with hysteresis (see
    the module docstring); ``margin`` is the smallest distance of a joint to its limits."""
    return Mode(select_mode_code(float(d_min), float(w), float(margin), int(previous), limits.as_array()))


@njit(cache=True, inline="always")
def select_mode_code(d_min: float, w: float, margin: float, previous: int, limits: np.ndarray) -> int:
    """:func:`select_mode` on plain numbers: modes as their ints, ``limits`` as
    :meth:`SelectorLimits.as_array`."""
    d_lim, d_band, w_lim, w_band = limits[0], limits[1], limits[2], limits[3]
    q_lim, q_band = limits[4], limits[5]
    staying = previous == 1 and d_min < d_lim + d_band
    if d_min < d_lim or staying:
        return 1  # Mode.obstacle_avoidance
    staying = previous == 4 and margin < q_lim + q_band
    if margin < q_lim or staying:
        return 4  # Mode.joint_limits
    low = w < w_lim or (previous == 3 and w < w_lim + w_band)
    return 3 if low else 2  # Mode.manipulability, Mode.joint_torque


@dataclass(frozen=True)
class Level:
    """One criterion on one level: its gradient Φ (n,), step gain K (> 0 maximises) and
    activation a ∈ [0, 1], the weight of its row in the projection of the levels below."""

    gradient: np.ndarray
    gain: float
    activation: float = 1.0


RANK_DAMPING = 1e-2  # ρ of the damped level projection (module docstring)


def prioritized_velocity(
    N: np.ndarray,
    W: np.ndarray,
    W_inv: np.ndarray,
    levels: list[Level],
    rotate: bool = True,
    rank_damping: float = RANK_DAMPING,
) -> np.ndarray:
    """q̇_dⁿ = Σ_k K_k u_k with each level in the null space of all levels above it
    (module docstring). N is the task's projector N_1 (n, n), W the inverse's
    metric (H for the dynamically consistent inverse, I otherwise) and W_inv its inverse."""
    if not levels:
        return np.zeros(N.shape[0])
    return stacked_prioritized_velocity(
        N,
        W,
        W_inv,
        np.array([level.gradient for level in levels]),
        np.array([level.gain for level in levels], dtype=float),
        np.array([level.activation for level in levels], dtype=float),
        rotate,
        rank_damping,
    )


@njit(cache=True)
def stacked_prioritized_velocity(N, W, W_inv, gradients, gains, activations, rotate, rank_damping):
    """:func:`prioritized_velocity` with the levels stacked: gradients (k, n), gains and
    activations (k,), highest priority first."""
    qdot = np.zeros(N.shape[0])
    metric_scale = np.max(np.abs(W_inv))
    last = gradients.shape[0] - 1
    for k in range(gradients.shape[0]):
        Phi = np.ascontiguousarray(gradients[k])
        if gains[k] != 0.0:
            qdot = qdot + gradient_step(N, W_inv, Phi, gains[k], rotate)  # Eq. 30 (or 28)
        if k == last or activations[k] <= 0.0:
            continue
        v = projected_direction(N, W_inv, Phi)  # the row this level removes from the levels below
        denom = Phi @ v + rank_damping * (Phi @ Phi) * metric_scale
        if denom > 0.0:
            N = N - (activations[k] / denom) * np.outer(v, v @ W)
    return qdot


@njit(cache=True, inline="always")
def _ordering_velocity(N, W, W_inv, gradients, gains, activations, rows, rotate, rank_damping):
    """One ordering's q̇_dⁿ: the levels ``rows`` of the stacked criteria, in that order."""
    if rows.shape[0] == 0:
        return np.zeros(N.shape[0])
    return stacked_prioritized_velocity(
        N, W, W_inv, gradients[rows], gains[rows], activations[rows], rotate, rank_damping
    )


@njit(cache=True)
def selected_velocity(
    N, W, W_inv, gradients, gains, activations, rows, previous_rows, sigma, rotate, task_part, limits
):
    """(q̇_dⁿ, s): the ordering ``rows`` of the stacked criteria (gradients (k, n), gains and
    activations (k,)), blended with the ordering ``previous_rows`` by σ (σ new + (1 − σ)
    old, while σ < 1), then scaled by s = :func:`joint_speed_scale` for the task part
    J^# J q̇ and the joint-speed ``limits``."""
    qdot = _ordering_velocity(N, W, W_inv, gradients, gains, activations, rows, rotate, RANK_DAMPING)
    if sigma < 1.0:
        old = _ordering_velocity(
            N, W, W_inv, gradients, gains, activations, previous_rows, rotate, RANK_DAMPING
        )
        qdot = sigma * qdot + (1.0 - sigma) * old
    scale = joint_speed_scale(task_part, qdot, limits)
    return qdot * scale, scale


SPEED_SCALE_SMOOTHNESS = 8  # the p of the p-norm soft minimum in joint_speed_scale


@njit(cache=True)
def joint_speed_scale(
    task_part: np.ndarray, qdot_ns: np.ndarray, limits: np.ndarray, p: int = SPEED_SCALE_SMOOTHNESS
) -> float:
    """A scale s in [0, 1] for q̇ⁿ with |task_part_i + s q̇ⁿ_i| ≤ limits_i for every joint.

    Scaling q̇ⁿ keeps its direction (end of Section 3.3); ``task_part`` is the
    velocity the task needs, J^# J q̇. Each joint allows s ≤ b_i, the largest
    scale that keeps it within its limit; the hard choice min(1, b_1, …, b_n)
    has kinks where a limit engages, which the feed-forward of q̈_dⁿ would turn
    into torque steps. So s is their p-norm soft minimum,

        s = (1 + Σ_i b_i^(−p))^(−1/p)  ≤  min(1, b_1, …, b_n),

    smooth in the joint velocities, equal to 1 far from every limit and never
    above the hard bound. Where the task alone uses up a limit (b_i ≤ 0), s = 0.
    """
    total = 1.0
    for i in range(task_part.shape[0]):
        a, b, lim = task_part[i], qdot_ns[i], limits[i]
        if b == 0.0 or not np.isfinite(lim):
            continue
        room = lim - a if b > 0 else lim + a  # distance to the limit on b's side
        if room <= 0.0:
            return 0.0
        total += (abs(b) / room) ** p
    return total ** (-1.0 / p)


@dataclass(frozen=True)
class SwitchState:
    """The selector's discrete state."""

    mode: Mode
    previous: Mode  # the mode being blended away from
    switch_time: float  # [s] time of the last switch (−∞ if none)

    def as_array(self) -> np.ndarray:
        """[mode, previous, switch_time], the selector's discrete state as the kernels take it."""
        return np.array([float(self.mode), float(self.previous), self.switch_time])

    @classmethod
    def from_array(cls, x) -> SwitchState:
        return cls(Mode(int(x[0])), Mode(int(x[1])), float(x[2]))


# The selector's discrete state before the first selection: mode 0, so that the first
# selection blends in from rest.
INITIAL_SWITCH_STATE = (0.0, 0.0, -np.inf)  # [mode, previous, switch time]


def update_switch_state(state: SwitchState, t: float, new_mode: Mode) -> SwitchState:
    out = np.empty(3)
    switch_state_update(state.as_array(), float(t), int(new_mode), out)
    return SwitchState.from_array(out)


@njit(cache=True, inline="always")
def switch_state_update(state: np.ndarray, t: float, new_mode: int, out: np.ndarray) -> None:
    """out = the switch state [mode, previous, switch time] after selecting ``new_mode`` at
    time t: unchanged if it is the current mode, else (new, current, t)."""
    if new_mode == int(state[0]):
        out[:] = state
    else:
        out[0], out[1], out[2] = float(new_mode), state[0], t


def blend_weight(state: SwitchState, t: float, blend_time: float) -> float:
    """σ ∈ [0, 1]: the share of the current mode's ordering (1 once the blend is over)."""
    return blend_weight_code(float(state.switch_time), float(t), float(blend_time))


@njit(cache=True, inline="always")
def blend_weight_code(switch_time: float, t: float, blend_time: float) -> float:
    """:func:`blend_weight` from the time of the last switch."""
    if blend_time <= 0.0 or not np.isfinite(switch_time):
        return 1.0
    return compiled_smoothstep((t - switch_time) / blend_time)


def ordering_table() -> tuple[np.ndarray, np.ndarray]:
    """:data:`ORDERINGS` for the compiled selector: (rows, counts), rows[mode, :counts[mode]]
    the indices in ``list(Criterion)`` of the mode's levels, highest priority first."""
    order = list(Criterion)
    rows = np.zeros((len(Mode), len(order)), dtype=np.int64)
    counts = np.zeros(len(Mode), dtype=np.int64)
    for mode, levels in ORDERINGS.items():
        counts[mode] = len(levels)
        rows[mode, : len(levels)] = [order.index(c) for c in levels]
    return rows, counts

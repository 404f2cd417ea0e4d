"""PrioritySelector: Fig. 1's switching priorities and the multi-level null-space velocity."""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from nsdrake.control.dynamics import RobotTerms
from nsdrake.control.priority import (
    ORDERINGS,
    Criterion,
    Mode,
    SelectorLimits,
    SwitchState,
    blend_weight,
    select_mode,
    selected_velocity,
    update_switch_state,
)
from nsdrake.control.pseudo_inverse import GeneralizedInverse
from nsdrake.control.systems.criteria import criterion_size

# Entries of the ``selection`` port after its n entries of q̇_dⁿ.
MODE, SPEED_SCALE = 0, 1


class PrioritySelector(LeafSystem):
    """The desired null-space velocity q̇_dⁿ from the criteria, ordered by Fig. 1's
    decision tree and resolved level by level (:mod:`nsdrake.control.priority`): hysteresis
    on the limits, a smoothstep blend of q̇_dⁿ over ``blend_time`` after each switch,
    and scaling so that no joint exceeds its speed limit.

    .. pydrake_system::

        name: PrioritySelector
        input_ports:
        - robot_terms
        - obstacle
        - joint_torque
        - manipulability
        - joint_limits
        output_ports:
        - selection

    Each criterion input is its system's packed [Φ (n); p; s; a]
    (:data:`nsdrake.control.systems.criteria.CRITERION_LAYOUT`): the tree compares the
    obstacle's s (d_min [m]) with d_lim, the joint limits' s (the smallest margin
    [rad]) with q_lim and the manipulability's s (w) with w_lim; the obstacle and
    joint-limit levels are weighted by their activation a. ``selection`` is
    [q̇_dⁿ (n) [rad/s]; mode; speed_scale]: mode 0 (no criterion), 1 (obstacle
    avoidance on level 2), 2 (joint torque), 3 (manipulability) or 4 (joint limits),
    and the factor the joint-speed limits put on q̇_dⁿ. The discrete state is (mode,
    mode blended from, switch time).

    The commanded joint speed, task part J^# J q̇ plus q̇_dⁿ, is kept within
    (1 − ``speed_headroom``) of each joint's limit: the measured speed is the
    command minus the null-space error eⁿ, and the headroom absorbs that error.
    """

    def __init__(
        self,
        *,
        inverse: GeneralizedInverse,
        gains: dict[Criterion, float],
        limits: SelectorLimits,
        blend_time: float,
        rotate_gradient: bool,
        speed_limits: np.ndarray,
        speed_headroom: float,
        period: float,
        model_terms: RobotTerms,
    ):
        super().__init__()
        n = model_terms.n
        self._n = n
        self._inverse = inverse
        gains = {Criterion(c): float(k) for c, k in gains.items()}
        self._active = any(gains.values())
        self._order = list(Criterion)  # rows of the stacked criteria
        self._row = {c: i for i, c in enumerate(self._order)}
        self._gain_vector = np.array([gains.get(c, 0.0) for c in self._order])
        self._rows_of = {mode: np.array([self._row[c] for c in ORDERINGS[mode]], dtype=int) for mode in Mode}
        self._limits = limits
        self._blend_time = blend_time
        self._rotate = rotate_gradient
        self._command_limits = (1.0 - speed_headroom) * np.asarray(speed_limits, dtype=float)
        self._eye = np.eye(n)
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        self._criteria = [self.DeclareVectorInputPort(c.value, criterion_size(n)) for c in self._order]
        # [mode, mode blended from, switch time]; starts in mode 0 so the first
        # selection blends in from rest.
        self._state = self.DeclareDiscreteState(BasicVector([0.0, 0.0, -math.inf]))
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        deps = {self.input_port_ticket(p.get_index()) for p in (self._terms, *self._criteria)}
        deps |= {self.discrete_state_ticket(self._state), self.time_ticket()}
        self.DeclareVectorOutputPort("selection", n + 2, self._calc, prerequisites_of_calc=deps)

    def output_parts(self) -> dict[str, int]:
        """The parts of the ``selection`` port and their sizes, in order."""
        return {"desired_null_space_velocity": self._n, "mode": 1, "speed_scale": 1}

    def _stacked(self, context) -> np.ndarray:
        """The criteria ports, one row each in Criterion order. (k, n + 3)."""
        return np.array([port.Eval(context) for port in self._criteria])

    def _switch_state(self, context, criteria: np.ndarray) -> SwitchState:
        mode, previous, switch_time = context.get_discrete_state(self._state).value()
        state = SwitchState(Mode(int(mode)), Mode(int(previous)), switch_time)
        if not self._active:
            return state
        s = criteria[:, -2]
        new = select_mode(
            s[self._row[Criterion.obstacle]],
            s[self._row[Criterion.manipulability]],
            state.mode,
            self._limits,
            s[self._row[Criterion.joint_limits]],
        )
        return update_switch_state(state, context.get_time(), new)

    def _calc(self, context, output):
        criteria = self._stacked(context)
        state = self._switch_state(context, criteria)
        out = np.zeros(self._n + 2)
        out[self._n + MODE] = float(state.mode)
        out[self._n + SPEED_SCALE] = 1.0
        if self._active and state.mode != Mode.none:
            out[: self._n], out[self._n + SPEED_SCALE] = self._velocity(context, criteria, state)
        output.SetFromVector(out)

    def _velocity(self, context, criteria, state) -> tuple[np.ndarray, float]:
        terms = self._terms.Eval(context)
        pinv = self._inverse.at(terms)
        W, W_inv = (terms.H, terms.H_inv) if self._inverse.inertia_weighted else (self._eye, self._eye)
        # A level counts in the projection with its activation; a level without gain, not at all.
        activations = np.where(self._gain_vector != 0.0, criteria[:, -1], 0.0)
        return selected_velocity(
            pinv.N,
            W,
            W_inv,
            np.ascontiguousarray(criteria[:, : self._n]),
            self._gain_vector,
            activations,
            self._rows_of[state.mode],
            self._rows_of[state.previous],
            blend_weight(state, context.get_time(), self._blend_time),
            self._rotate,
            pinv.J_pinv @ terms.xdot,
            self._command_limits,
        )

    def _update(self, context, discrete_state):
        # Only the switch state: evaluating the whole result here, at the state the
        # plant has just stepped to, would compute q̇_dⁿ a second time per period.
        state = self._switch_state(context, self._stacked(context))
        discrete_state.get_mutable_vector(self._state).SetFromVector(
            [float(state.mode), float(state.previous), state.switch_time]
        )

"""PrioritySelector: Fig. 1's switching priorities and the multi-level null-space velocity."""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from ..dynamics import RobotTerms
from ..priority import (
    ORDERINGS,
    RANK_DAMPING,
    Criterion,
    Mode,
    SelectorLimits,
    SwitchState,
    blend_weight,
    joint_speed_scale,
    select_mode,
    stacked_prioritized_velocity,
    update_switch_state,
)
from ..pseudo_inverse import GeneralizedInverse
from ._util import python_value_producer


class PrioritySelector(LeafSystem):
    """The desired null-space velocity q̇_dⁿ from the three criteria, ordered by
    Fig. 1's decision tree and resolved level by level (:mod:`nsdrake.priority`):
    hysteresis on the limits, a smoothstep blend of q̇_dⁿ over ``blend_time``
    after each switch, and scaling so that no joint exceeds its speed limit.

    .. pydrake_system::

        name: PrioritySelector
        input_ports:
        - robot_terms
        - obstacle_gradient
        - joint_torque_gradient
        - manipulability_gradient
        - joint_limits_gradient
        - d_min
        - manipulability
        - obstacle_activation
        - joint_limit_margin
        - joint_limits_activation
        output_ports:
        - desired_null_space_velocity
        - mode
        - speed_scale

    Gradients are Φ (n); ``d_min`` [m], ``manipulability`` (w) and
    ``obstacle_activation`` come from the obstacle and manipulability criteria,
    ``joint_limit_margin`` [rad] and ``joint_limits_activation`` from the joint-limit
    criterion. ``mode`` is 0 (no criterion), 1 (obstacle avoidance on level 2), 2
    (joint torque), 3 (manipulability) or 4 (joint limits); the discrete state is
    (mode, mode blended from, switch time).

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
        self._inverse = inverse
        self._gains = {Criterion(c): float(k) for c, k in gains.items()}
        self._active = any(self._gains.values())
        self._order = [c for c in Criterion if c in self._gains]
        self._row = {c: i for i, c in enumerate(self._order)}
        self._gain_vector = np.array([self._gains[c] for c in self._order])
        self._rows_of = {mode: [self._row[c] for c in ORDERINGS[mode] if c in self._row] for mode in Mode}
        self._limits = limits
        self._blend_time = blend_time
        self._rotate = rotate_gradient
        self._command_limits = (1.0 - speed_headroom) * np.asarray(speed_limits, dtype=float)
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        self._gradients = {c: self.DeclareVectorInputPort(f"{c.value}_gradient", n) for c in Criterion}
        self._d_min = self.DeclareVectorInputPort("d_min", 1)
        self._w = self.DeclareVectorInputPort("manipulability", 1)
        self._obstacle_activation = self.DeclareVectorInputPort("obstacle_activation", 1)
        self._margin = self.DeclareVectorInputPort("joint_limit_margin", 1)
        self._joint_limits_activation = self.DeclareVectorInputPort("joint_limits_activation", 1)
        # [mode, mode blended from, switch time]; starts in mode 0 so the first
        # selection blends in from rest.
        self._state = self.DeclareDiscreteState(BasicVector([0.0, 0.0, -math.inf]))
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        inputs = [
            self._terms,
            *self._gradients.values(),
            self._d_min,
            self._w,
            self._obstacle_activation,
            self._margin,
            self._joint_limits_activation,
        ]
        deps = {self.input_port_ticket(p.get_index()) for p in inputs}
        deps |= {self.discrete_state_ticket(self._state), self.time_ticket()}
        self._result = self.DeclareCacheEntry(
            description="prioritised null-space velocity",
            value_producer=python_value_producer(self._compute),
            prerequisites_of_calc=deps,
        )
        self.DeclareVectorOutputPort(
            "desired_null_space_velocity",
            n,
            lambda c, o: o.SetFromVector(self._result.Eval(c)[0]),
            prerequisites_of_calc=deps,
        )
        self.DeclareVectorOutputPort(
            "mode",
            1,
            lambda c, o: o.SetAtIndex(0, float(self._result.Eval(c)[1].mode)),
            prerequisites_of_calc=deps,
        )
        self.DeclareVectorOutputPort(
            "speed_scale",
            1,
            lambda c, o: o.SetAtIndex(0, self._result.Eval(c)[2]),
            prerequisites_of_calc=deps,
        )

    def _switch_state(self, context) -> SwitchState:
        t = context.get_time()
        mode, previous, switch_time = context.get_discrete_state(self._state).value()
        state = SwitchState(Mode(int(mode)), Mode(int(previous)), switch_time)
        if not self._active:
            return state
        new = select_mode(
            self._d_min.Eval(context)[0],
            self._w.Eval(context)[0],
            state.mode,
            self._limits,
            self._margin.Eval(context)[0],
        )
        return update_switch_state(state, t, new)

    def _levels(self, context) -> tuple[dict, np.ndarray, np.ndarray]:
        """The criteria's gradients Φ (rows, in Criterion order) read from the ports once,
        their gains and activations (the obstacle and joint-limit levels fade in; a zero
        gain, none)."""
        gradients = np.array([self._gradients[c].Eval(context) for c in self._order])
        activations = np.array([float(gain != 0.0) for gain in self._gain_vector])
        for c, port in (
            (Criterion.obstacle, self._obstacle_activation),
            (Criterion.joint_limits, self._joint_limits_activation),
        ):
            if c in self._order and activations[self._row[c]]:
                activations[self._row[c]] = port.Eval(context)[0]
        return gradients, self._gain_vector, activations

    def _ordering_velocity(self, mode: Mode, levels, N, W, W_inv) -> np.ndarray:
        rows = self._rows_of[mode]
        if not rows:
            return np.zeros(N.shape[0])
        gradients, gains, activations = levels
        return stacked_prioritized_velocity(
            N, W, W_inv, gradients[rows], gains[rows], activations[rows], self._rotate, RANK_DAMPING
        )

    def _compute(self, context):
        terms = self._terms.Eval(context)
        state = self._switch_state(context)
        n = terms.n
        if not self._active or state.mode == Mode.none:
            return np.zeros(n), state, 1.0
        pinv = self._inverse.at(terms)
        W, W_inv = (terms.H, terms.H_inv) if self._inverse.inertia_weighted else (np.eye(n), np.eye(n))
        levels = self._levels(context)
        qdot = self._ordering_velocity(state.mode, levels, pinv.N, W, W_inv)
        sigma = blend_weight(state, context.get_time(), self._blend_time)
        if sigma < 1.0:
            old = self._ordering_velocity(state.previous, levels, pinv.N, W, W_inv)
            qdot = sigma * qdot + (1.0 - sigma) * old
        task_part = pinv.J_pinv @ terms.xdot
        scale = joint_speed_scale(task_part, qdot, self._command_limits)
        return qdot * scale, state, scale

    def _update(self, context, discrete_state):
        # Only the switch state: evaluating the whole result here, at the state the
        # plant has just stepped to, would compute q̇_dⁿ a second time per period.
        state = self._switch_state(context)
        discrete_state.get_mutable_vector(self._state).SetFromVector(
            [float(state.mode), float(state.previous), state.switch_time]
        )

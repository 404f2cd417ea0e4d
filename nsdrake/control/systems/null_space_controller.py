"""NullSpaceController: the null-space velocity controller of Eq. 21."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from nsdrake.control.dynamics import RobotTerms
from nsdrake.control.null_space import null_space_torque
from nsdrake.control.pseudo_inverse import GeneralizedInverse


class NullSpaceController(LeafSystem):
    """τ₀ = H N (q̈_dⁿ + (J̇^# J + J^# J̇) q̇ + K_n eⁿ + H⁻¹ C eⁿ), eⁿ = q̇_dⁿ − N q̇,
    ν = ½ eⁿᵀ H eⁿ (Eqs. 14, 21, 23; :mod:`nsdrake.control.null_space`).

    q̈_dⁿ is the backward difference of q̇_dⁿ over one control period, as the
    paper did ("numerical differentiation was sufficient"): the discrete state
    holds the previous sample of q̇_dⁿ. Each compensation term and the q̈_dⁿ
    feedforward can be switched off.

    .. pydrake_system::

        name: NullSpaceController
        input_ports:
        - robot_terms
        - desired_null_space_velocity
        output_ports:
        - null_space

    ``desired_null_space_velocity`` is q̇_dⁿ (n) [rad/s]; ``null_space`` is
    [τ₀ (n) [N m]; eⁿ (n) [rad/s]; ν [J]], one port so that the law is evaluated
    once per tick (the controller splits it with a C++ ``Demultiplexer``).
    """

    def __init__(
        self,
        *,
        inverse: GeneralizedInverse,
        K_n: float,
        period: float,
        task_velocity_compensation: bool,
        coriolis_compensation: bool,
        acceleration_feedforward: bool,
        model_terms: RobotTerms,
    ):
        super().__init__()
        n = model_terms.n
        self._n = n
        self._inverse = inverse
        self._K_n = K_n
        self._period = period
        self._task_velocity_compensation = task_velocity_compensation
        self._coriolis_compensation = coriolis_compensation
        self._feedforward = acceleration_feedforward
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        self._qdot_ns_d = self.DeclareVectorInputPort("desired_null_space_velocity", n)
        # [previous q̇_dⁿ (n), 1 if that sample exists]
        self._previous = self.DeclareDiscreteState(BasicVector(np.zeros(n + 1)))
        # An unrestricted update, so that it runs alongside the discrete plant's own
        # step (Drake advances a discrete MultibodyPlant in an unrestricted update,
        # before any discrete update) and stores the q̇_dⁿ the torque was computed from.
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._store)
        deps = {self.input_port_ticket(p.get_index()) for p in (self._terms, self._qdot_ns_d)}
        deps.add(self.discrete_state_ticket(self._previous))
        self.DeclareVectorOutputPort("null_space", 2 * n + 1, self._calc, prerequisites_of_calc=deps)

    def output_parts(self) -> dict[str, int]:
        """The parts of the ``null_space`` port and their sizes, in order."""
        return {"generalized_force": self._n, "null_space_velocity_error": self._n, "lyapunov": 1}

    def desired_acceleration(self, context) -> np.ndarray:
        """q̈_dⁿ: (q̇_dⁿ(t) − q̇_dⁿ(t − T)) / T, or zero without a previous sample or feedforward."""
        previous = context.get_discrete_state(self._previous).value()
        if not self._feedforward or previous[self._n] == 0.0:
            return np.zeros(self._n)
        return (self._qdot_ns_d.Eval(context) - previous[: self._n]) / self._period

    def _calc(self, context, output):
        result = null_space_torque(
            self._terms.Eval(context),
            self._inverse,
            self._qdot_ns_d.Eval(context),
            self.desired_acceleration(context),
            self._K_n,
            self._task_velocity_compensation,
            self._coriolis_compensation,
        )
        output.SetFromVector(np.concatenate([result.tau0, result.e_n, [result.nu]]))

    def _store(self, context, state):
        sample = np.append(self._qdot_ns_d.Eval(context), 1.0)
        state.get_mutable_discrete_state(self._previous).SetFromVector(sample)

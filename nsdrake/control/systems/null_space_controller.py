"""NullSpaceController: stage 5, the null-space velocity controller of Eq. 21."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector

from nsdrake.control.plan import ControllerPlan
from nsdrake.control.stages import NULL_SPACE
from nsdrake.control.systems._values import StageSystem


class NullSpaceController(StageSystem):
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

    def __init__(self, *, plan: ControllerPlan):
        super().__init__(plan)
        n = plan.n
        self._qdot_ns_d = self.DeclareVectorInputPort("desired_null_space_velocity", n)
        # [previous q̇_dⁿ (n), 1 if that sample exists]
        self._previous = self.DeclareDiscreteState(BasicVector(np.zeros(n + 1)))
        # An unrestricted update, so that it runs alongside the discrete plant's own
        # step (Drake advances a discrete MultibodyPlant in an unrestricted update,
        # before any discrete update) and stores the q̇_dⁿ the torque was computed from.
        self.DeclarePeriodicUnrestrictedUpdateEvent(plan.config.period, 0.0, self._store)
        deps = {self.input_port_ticket(p.get_index()) for p in (self._terms, self._qdot_ns_d)}
        deps.add(self.discrete_state_ticket(self._previous))
        deps.add(self.time_ticket())  # a posture law's q_d(t) (nsdrake.control.null_space_laws)
        self.DeclareVectorOutputPort("null_space", 2 * n + 1, self._calc, prerequisites_of_calc=deps)

    def output_parts(self) -> dict[str, int]:
        """The parts of the ``null_space`` port and their sizes, in order."""
        return {"generalized_force": self._n, "null_space_velocity_error": self._n, "lyapunov": 1}

    def _calc(self, context, output):
        b = self.buffers(context)
        b.part("qdot")[:] = self._qdot_ns_d.Eval(context)
        b.previous_qdot[:] = context.get_discrete_state(self._previous).get_value()
        self.run(context, NULL_SPACE, b)
        output.SetFromVector(b.part("null_space"))

    def _store(self, context, state):
        sample = state.get_mutable_discrete_state(self._previous).get_mutable_value()
        sample[: self._n], sample[self._n] = self._qdot_ns_d.Eval(context), 1.0

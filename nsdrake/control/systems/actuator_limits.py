"""ActuatorLimitsSystem: stage 6, torque and torque-rate limits with the primary task first."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector

from nsdrake.control.plan import ControllerPlan
from nsdrake.control.stages import LIMITS
from nsdrake.control.systems._values import StageSystem


class ActuatorLimitsSystem(StageSystem):
    """τ = τ_task + s τ₀ within each joint's torque and torque-rate limits, τ₀ reduced
    first (:mod:`nsdrake.control.actuator_limits`).

    .. pydrake_system::

        name: ActuatorLimitsSystem
        input_ports:
        - task_torque
        - null_space_torque
        output_ports:
        - limited
        - limited_null_space_torque

    ``task_torque`` is τ − τ₀ of Eq. 7, ``null_space_torque`` τ₀ of Eq. 21 (n each)
    [N m]; ``limited`` is [τ (n) [N m]; s; clipped]: the torque, the share s of τ₀
    kept (1: no limit binds) and the number of joints whose task torque had to be
    clipped (the controller splits it into ``generalized_force`` and ``saturation``);
    ``limited_null_space_torque`` is s τ₀ (n) [N m], the null-space torque in τ.
    The discrete state holds the torque applied over the last period, stored in an
    unrestricted update alongside the plant's step (as the null-space controller's
    q̇_dⁿ), for the rate limit.
    """

    def __init__(self, *, plan: ControllerPlan):
        super().__init__(plan, terms=False)
        n = plan.n
        self._task = self.DeclareVectorInputPort("task_torque", n)
        self._tau0 = self.DeclareVectorInputPort("null_space_torque", n)
        self._previous = self.DeclareDiscreteState(BasicVector(np.zeros(n + 1)))  # [τ, 1 if it exists]
        deps = {self.input_port_ticket(p.get_index()) for p in (self._task, self._tau0)}
        deps.add(self.discrete_state_ticket(self._previous))
        self._limited = self.DeclareVectorOutputPort("limited", n + 2, self._calc, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort(
            "limited_null_space_torque", n, self._calc_tau0, prerequisites_of_calc={self.all_sources_ticket()}
        )
        if np.isfinite(plan.rate_limits).any():  # else nothing narrows the window
            self.DeclarePeriodicUnrestrictedUpdateEvent(plan.config.period, 0.0, self._store)

    def output_parts(self) -> dict[str, int]:
        """The parts of the ``limited`` port and their sizes, in order."""
        return {"generalized_force": self._n, "saturation": 2}

    def _calc(self, context, output):
        b, n = self.buffers(context), self._n
        b.part("task")[:] = self._task.Eval(context)
        b.part("null_space")[:n] = self._tau0.Eval(context)
        b.previous_tau[:] = context.get_discrete_state(self._previous).get_value()
        self.run(context, LIMITS, b)
        output.SetFromVector(b.part("limited"))

    def _calc_tau0(self, context, output):
        output.SetFromVector(self._limited.Eval(context)[self._n] * self._tau0.Eval(context))

    def _store(self, context, state):
        sample = state.get_mutable_discrete_state(self._previous).get_mutable_value()
        sample[: self._n], sample[self._n] = self._limited.Eval(context)[: self._n], 1.0

"""FusedController: the whole controller tick in one LeafSystem."""

from __future__ import annotations

from pydrake.systems.framework import BasicVector, LeafSystem

from nsdrake.control.layout import tick_size
from nsdrake.control.plan import ControllerPlan
from nsdrake.control.stages import initial_state, store_stage, switch_update_stage, tick_back
from nsdrake.control.systems._values import FrontValue, declare_value_cache


class FusedController(LeafSystem):
    """The stages of :mod:`nsdrake.control.stages` in one system: stages 1–2 in a cache entry
    that depends on the measured state alone, stages 3–6 in the output, and the three
    pieces of discrete state with the named systems' events (the same τ, tick by tick).

    .. pydrake_system::

        name: FusedController
        input_ports:
        - estimated_state
        - commands
        output_ports:
        - tick

    ``estimated_state`` is [q; q̇] (2n); ``commands`` is [measured wrench (6); x_d, ẋ_d,
    ẍ_d (m_t each); f_d; with rotational task axes R_d (4), ω_d (3), ω̇_d (3)]
    (:func:`nsdrake.control.stages.commands_views`; the controller's Multiplexer packs it
    from its named input ports); ``tick`` is every stage's output
    (:func:`nsdrake.control.layout.tick_parts`; the controller's Demultiplexer splits it
    into its named output ports).

    Events, as the named systems': every period an unrestricted update stores the q̇_dⁿ
    and τ of the output (the previous values of Eq. 21's q̈_dⁿ and of the rate limit),
    then a discrete update commits the selector's switch from the state the plant has
    just stepped to. The criteria at that state are kept for the next output (the cache
    entry's state has not changed), so stages 1–2 run once per period.
    """

    def __init__(self, *, plan: ControllerPlan, commands_size: int):
        super().__init__()
        self._plan = plan
        n = plan.n
        self._n = n
        self._state = self.DeclareVectorInputPort("estimated_state", 2 * n)
        self._commands = self.DeclareVectorInputPort("commands", commands_size)
        self._front = declare_value_cache(
            self, "stages 1-2", lambda: FrontValue(plan), self._calc_front,
            {self.input_port_ticket(self._state.get_index())},
        )  # fmt: skip
        # [switch (3); previous q̇_dⁿ (n + 1); previous τ (n + 1)] (stages.state_parts)
        self._discrete = self.DeclareDiscreteState(BasicVector(initial_state(n)))
        self.DeclarePeriodicUnrestrictedUpdateEvent(plan.config.period, 0.0, self._store)
        self.DeclarePeriodicDiscreteUpdateEvent(plan.config.period, 0.0, self._update_switch)
        deps = {self.input_port_ticket(p.get_index()) for p in (self._state, self._commands)}
        deps |= {self.all_state_ticket(), self.time_ticket()}
        self._tick = self.DeclareVectorOutputPort(
            "tick", tick_size(plan.dims), self._calc, prerequisites_of_calc=deps
        )

    def _calc_front(self, context, front: FrontValue):
        state = self._state.Eval(context)
        n = self._n
        self._plan.front(front.scratch, state[:n], state[n:], front.terms, front.criteria)

    def _calc(self, context, output):
        p, front = self._plan, self._front.Eval(context)
        tick_back(
            front.terms, p.plan, p.index, p.dims, front.criteria,
            context.get_discrete_state(self._discrete).CopyToVector(), context.get_time(),
            self._commands.Eval(context), output.get_mutable_value(),
        )  # fmt: skip

    def _store(self, context, state):
        discrete = state.get_mutable_discrete_state(self._discrete).get_mutable_value()
        store_stage(self._tick.Eval(context), self._plan.dims, discrete)

    def _update_switch(self, context, discrete_state):
        p = self._plan
        switch_update_stage(
            p.plan, p.dims, self._front.Eval(context).criteria,
            discrete_state.get_mutable_vector(self._discrete).get_mutable_value(), context.get_time(),
        )  # fmt: skip

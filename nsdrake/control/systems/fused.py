"""FusedController: the whole controller tick in one LeafSystem."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector

from nsdrake.control.layout import tick_parts
from nsdrake.control.leaf_system import LeafSystem
from nsdrake.control.plan import ControllerPlan, StageBuffers
from nsdrake.control.stages import COMMIT, DESIRED, SELECTION, STORE, TICK, commands_size, initial_state
from nsdrake.control.systems._values import check_inputs, declare_value_cache, evaluated, evaluated_commands


class FrontValue:
    """Stages 1 and 2 at one state (the fused system's cache entry): the terms and the
    buffers whose criteria they filled (with the model scratch they were computed in)."""

    def __init__(self, plan: ControllerPlan):
        self.plan = plan
        self.terms = plan.allocate_terms()
        self.buffers = StageBuffers(plan, scratch=plan.create_scratch())

    def __deepcopy__(self, memo):
        out = FrontValue(self.plan)
        out.terms[:], out.buffers.criteria[:] = self.terms, self.buffers.criteria
        return out


class FusedController(LeafSystem):
    """The stages of :mod:`nsdrake.control.stages` in one system: stages 1–2 in a cache entry
    that depends on the measured state alone, stages 3–6 in the output, and the discrete
    state with the named systems' events (the same τ, tick by tick).

    .. pydrake_system::

        name: FusedController
        input_ports:
        - estimated_state
        - commands
        - desired_null_space_velocity
        output_ports:
        - tick
        - limited_null_space_torque

    ``estimated_state`` is [q; q̇] (2n); ``commands`` is [measured wrench (6); x_d, ẋ_d,
    ẍ_d (m_t each); f_d; with rotational task axes R_d (4), ω_d (3), ω̇_d (3)]
    (:func:`nsdrake.control.stages.commands_views`; the controller's Multiplexer packs it
    from its named input ports); ``tick`` is every stage's output
    (:func:`nsdrake.control.layout.tick_parts`; the controller's Demultiplexer splits it
    into its named output ports). ``desired_null_space_velocity`` (n) [rad/s], when
    connected, is the q̇_dⁿ the null-space stage uses instead of the configured source's;
    ``limited_null_space_torque`` is s τ₀ (n) [N m], the null-space torque in τ. An input
    that is not finite, or a zero quaternion, raises
    :class:`nsdrake.control.validation.ControllerInputError` naming the controller's input
    port and entry; so does an input of the controller never connected nor fixed.

    Events, as the named systems': every period an unrestricted update stores the q̇_dⁿ
    and τ of the output (the previous values of Eq. 21's q̈_dⁿ and of the rate limit),
    then a discrete update commits the selector's switch from the state the plant has
    just stepped to. The criteria at that state are kept for the next output (the cache
    entry's input has not changed), so stages 1–2 run once per period. The discrete
    state is [switch (3); previous q̇_dⁿ (n + 1); previous τ (n + 1)].
    """

    def __init__(self, *, plan: ControllerPlan):
        super().__init__()
        self._plan = plan
        n = plan.n
        self._n = n
        self._state = self.DeclareVectorInputPort("estimated_state", 2 * n)
        self._commands = self.DeclareVectorInputPort("commands", commands_size(plan.m_t, plan.m_r))
        self._external = self.DeclareVectorInputPort("desired_null_space_velocity", n)
        self._offsets = _offsets(tick_parts(n, plan.m_t))
        self._front = declare_value_cache(
            self, "stages 1-2", lambda: FrontValue(plan), self._calc_front,
            {self.input_port_ticket(self._state.get_index())},
        )  # fmt: skip
        self._discrete = self.DeclareDiscreteState(BasicVector(initial_state(n)))
        self.DeclarePeriodicUnrestrictedUpdateEvent(plan.config.period, 0.0, self._store)
        self.DeclarePeriodicDiscreteUpdateEvent(plan.config.period, 0.0, self._commit)
        inputs = (self._state, self._commands, self._external)
        deps = {self.input_port_ticket(p.get_index()) for p in inputs}
        deps |= {self.all_state_ticket(), self.time_ticket()}
        self._tick = self.DeclareVectorOutputPort(
            "tick", plan.tick_length, self._calc, prerequisites_of_calc=deps
        )
        self.DeclareVectorOutputPort(
            "limited_null_space_torque", n, self._calc_tau0, prerequisites_of_calc={self.all_sources_ticket()}
        )
        self._scratch_tick = plan.allocate_tick()  # COMMIT reads and writes no tick

    def _calc_front(self, context, front: FrontValue):
        state = evaluated(self, context, self._state, "estimated_state")
        check_inputs(self, context, state, self._plan.input_names["estimated_state"])
        n = self._n
        self._plan.front(front.buffers.scratch, state[:n], state[n:], front.terms, front.buffers)

    def _run(self, context, stages, t_previous, state, tick, commands=None) -> None:
        front, n = self._front.Eval(context), self._n
        b = front.buffers
        commands = evaluated_commands(self, context, self._commands) if commands is None else commands
        self._plan.run_arrays(
            stages, context.get_time(), t_previous, front.terms, b.criteria, state[:3], state[3 : n + 4],
            state[n + 4 :], commands, tick, b.scratch,
        )  # fmt: skip

    def _calc(self, context, output):
        state = context.get_discrete_state(self._discrete).CopyToVector()
        tick = output.get_mutable_value()
        plan, commands = self._plan, evaluated_commands(self, context, self._commands)
        check_inputs(self, context, commands, plan.input_names["commands"], plan.commands_quaternion)
        if not self._external.HasValue(context):
            self._run(context, TICK, 0.0, state, tick, commands)
            return
        # q̇_dⁿ from outside: the selector still runs (its mode and scale are reported),
        # then its q̇_dⁿ is replaced before the stages that use it.
        external = self._external.Eval(context)
        check_inputs(self, context, external, plan.input_names["desired_null_space_velocity"])
        self._run(context, SELECTION | DESIRED, 0.0, state, tick, commands)
        start, size = self._offsets["desired_null_space_velocity"]
        tick[start : start + size] = external
        self._run(context, TICK & ~(SELECTION | DESIRED), 0.0, state, tick, commands)

    def _calc_tau0(self, context, output):
        tick, (s, _), (t0, n) = (
            self._tick.Eval(context),
            self._offsets["saturation"],
            self._offsets["null_space_torque"],
        )
        output.SetFromVector(tick[s] * tick[t0 : t0 + n])

    def _store(self, context, state):
        discrete = state.get_mutable_discrete_state(self._discrete).get_mutable_value()
        self._run(context, STORE, 0.0, discrete, self._tick.Eval(context))

    def _commit(self, context, discrete_state):
        discrete = discrete_state.get_mutable_vector(self._discrete).get_mutable_value()
        self._run(context, COMMIT, context.get_time(), discrete, self._scratch_tick)


def _offsets(parts: dict[str, int]) -> dict[str, tuple[int, int]]:
    """{part: (start, size)} of a packed port's parts, in order."""
    starts = np.cumsum([0, *parts.values()])
    return {name: (int(starts[k]), size) for k, (name, size) in enumerate(parts.items())}

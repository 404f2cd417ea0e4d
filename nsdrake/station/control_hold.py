"""ControlHold: a digital controller's torque, sampled and held at the control period."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import BasicVector

from nsdrake.control.leaf_system import LeafSystem
from nsdrake.control.validation import positive_problem, show, switch_problem
from nsdrake.station.config import StationError


def _arguments_problem(size, period, delay_periods, direct_feedthrough) -> str | None:
    """Why ControlHold cannot take its arguments, naming the first wrong one, or None:
    ``size`` and ``delay_periods`` counts (integers, not booleans), ``period`` a positive
    finite number [s], ``direct_feedthrough`` true or false."""
    for name, value, least in (("size", size, 1), ("delay_periods", delay_periods, 0)):
        if not isinstance(value, (int, np.integer)) or isinstance(value, (bool, np.bool_)) or value < least:
            return f"{name} must be an integer >= {least}, got {show(value)}"
    problem = positive_problem(period)
    if problem:
        return f"period {problem} [s]"
    problem = switch_problem(direct_feedthrough)
    return f"direct_feedthrough {problem}" if problem else None


class ControlHold(LeafSystem):
    """The torque of a controller sampled every control period T and held, with
    ``delay_periods`` whole periods between a sample and its application, for a plant
    that may step several times per period.

    .. pydrake_system::

        name: ControlHold
        input_ports:
        - commanded
        output_ports:
        - applied

    ``commanded`` (n) is the controller's output, a function of the state at the
    current time; ``applied`` (n) is what the plant receives. At a control instant
    t_k = k T, ``applied`` is the commanded value at t_k itself (no delay) or the one
    sampled ``delay_periods`` instants earlier (zero before the first); between
    instants it holds the value applied at the last one. So the torque over
    [t_k, t_{k+1}) is u(t_k), or u(t_{k−d}).

    Why not Drake's ``ZeroOrderHold``: Drake advances a discrete plant in an
    unrestricted update, before every discrete update at the same instant, and a
    ``ZeroOrderHold`` samples in a discrete update, so its sample at t_k would be
    computed from the state one plant step later, while the controller's own
    unrestricted stores (the null-space controller's previous q̇_dⁿ, the previous
    torque of the rate limit) see the state at t_k. Here the sample is taken in an
    unrestricted update too, from the same context as the plant's step and the
    controller's stores, and at the control instant the output is the commanded
    value itself: with one plant step per period and no delay the plant receives
    exactly what a direct connection gives. Between instants the output does not
    read its input, so the controller is evaluated once per period, not at every
    plant step or sensor sample in between.

    With ``direct_feedthrough`` False, ``applied`` is always the held value, never the
    input: a sample taken at t_k reaches the output once the instant's updates are done.
    That is what a *continuous* plant needs: it integrates over [t_k, t_{k+1}) after
    every update at t_k, so it still receives u(t_k), and no algebraic loop closes
    through the hold (with a force sensor on the plant's reaction forces, which depend
    on the actuation, the default hold's feedthrough makes one). On a discrete plant,
    which steps in the instant's own unrestricted update, it would add a period of delay.

    The discrete state is [held (n); pending samples (d n); time of the last sample].
    """

    def __init__(self, *, size: int, period: float, delay_periods: int = 0, direct_feedthrough: bool = True):
        problem = _arguments_problem(size, period, delay_periods, direct_feedthrough)
        if problem:
            raise StationError(f"ControlHold: {problem}")
        super().__init__()
        self._n = size
        self._d = delay_periods
        self._feedthrough = direct_feedthrough
        # A control instant comes a period after the last sample, up to the rounding of
        # event times; every other event (plant steps, sensor samples) falls at least a
        # power-of-two fraction of the period earlier.
        self._instant_gap = period * (1.0 - 1e-6)
        self._input = self.DeclareVectorInputPort("commanded", size)
        initial = np.concatenate([np.zeros(size * (1 + delay_periods)), [-math.inf]])
        self._state = self.DeclareDiscreteState(BasicVector(initial))
        deps = {self.time_ticket(), self.discrete_state_ticket(self._state)}
        if delay_periods == 0 and direct_feedthrough:
            deps.add(self.input_port_ticket(self._input.get_index()))
        self.DeclareVectorOutputPort(
            "applied", size, lambda c, o: o.SetFromVector(self._applied(c)), prerequisites_of_calc=deps
        )
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._sample)

    def is_control_instant(self, context) -> bool:
        """Whether the context's time is a sampling instant not yet sampled."""
        t_last = context.get_discrete_state(self._state).value()[-1]
        return context.get_time() - t_last > self._instant_gap

    def _applied(self, context) -> np.ndarray:
        if self._feedthrough and self.is_control_instant(context):
            return self._due(context)
        return context.get_discrete_state(self._state).value()[: self._n].copy()

    def _due(self, context) -> np.ndarray:
        """The value applied from this control instant on: u(t_k), or the oldest pending sample."""
        if self._d == 0:
            return self._input.Eval(context).copy()
        return context.get_discrete_state(self._state).value()[self._n : 2 * self._n].copy()

    def _sample(self, context, state):
        n, d = self._n, self._d
        x = context.get_discrete_state(self._state).value()
        held = self._due(context) if self.is_control_instant(context) else x[:n].copy()
        pending = x[n : n * (1 + d)]
        if d:
            pending = np.concatenate([pending[n:], self._input.Eval(context)])
        state.get_mutable_discrete_state(self._state).SetFromVector(
            np.concatenate([held, pending, [context.get_time()]])
        )

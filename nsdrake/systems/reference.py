"""Task references with contact detection and loss: the Fig. 3 task, and a circle on the surface."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from ..reference import CircleOnSurface, ContactState, SlideAndPress, update_contact
from ._util import python_value_producer


class SurfaceReference(LeafSystem):
    """Desired position, velocity, acceleration and normal force of a task on a surface
    whose reference (``reference.at(t, state=…)``) depends on the contact state. The
    contact state, from the measured normal force alone (as on a real robot: contact
    when it reaches ``contact_threshold``, lost when it stays below for ``loss_time``),
    is the discrete state, updated every ``period``
    (:func:`nsdrake.reference.update_contact`), with the time of the first contact.

    .. pydrake_system::

        name: SurfaceReference
        input_ports:
        - measured_force
        output_ports:
        - x_d
        - xdot_d
        - xddot_d
        - f_d
        - in_contact

    ``measured_force`` is the sensor's world force (3) [N]; the outputs are in
    task coordinates (m) [m, m/s, m/s²], f_d [N], and ``in_contact`` (1): 1 while
    in contact, 0 before it and after it was lost.
    """

    def __init__(
        self,
        *,
        reference: SlideAndPress | CircleOnSurface,
        task_rows: np.ndarray,
        contact_threshold: float,
        period: float,
        loss_time: float = 0.05,
    ):
        super().__init__()
        self._ref = reference
        self._rows = np.asarray(task_rows)
        self._threshold = contact_threshold
        self._loss_time = loss_time
        m = reference.x0.shape[0]
        self._force = self.DeclareVectorInputPort("measured_force", 3)
        # [t_contact, r_contact, t_lost, t_low] of ContactState, then the first contact's time
        self._state = self.DeclareDiscreteState(
            BasicVector([math.inf, math.nan, math.inf, math.inf, math.inf])
        )
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        deps = {self.time_ticket(), self.discrete_state_ticket(self._state)}
        self._value = self.DeclareCacheEntry(
            description="reference at t",
            value_producer=python_value_producer(self._eval),
            prerequisites_of_calc=deps,
        )
        for name, k in (("x_d", 0), ("xdot_d", 1), ("xddot_d", 2)):
            self.DeclareVectorOutputPort(
                name, m, lambda c, o, k=k: o.SetFromVector(self._value.Eval(c)[k]), prerequisites_of_calc=deps
            )
        self.DeclareVectorOutputPort(
            "f_d", 1, lambda c, o: o.SetAtIndex(0, self._value.Eval(c)[3]), prerequisites_of_calc=deps
        )
        self.DeclareVectorOutputPort(
            "in_contact",
            1,
            lambda c, o: o.SetAtIndex(0, float(self._contact(c).in_contact)),
            prerequisites_of_calc={self.discrete_state_ticket(self._state)},
        )

    def _contact(self, context) -> ContactState:
        return ContactState(*context.get_discrete_state(self._state).value()[:4])

    def _first_contact(self, context) -> float:
        return context.get_discrete_state(self._state).GetAtIndex(4)

    def _eval(self, context):
        return self._ref.at(context.get_time(), state=self._contact(context))

    def _update(self, context, discrete_state):
        state = self._contact(context)
        f_n = float(self._ref.normal @ self._force.Eval(context)[self._rows])
        r_now = self._ref.offset(context.get_time(), state)
        new = update_contact(state, context.get_time(), f_n, self._threshold, self._loss_time, r_now)
        first = self._first_contact(context)
        discrete_state.get_mutable_vector(self._state).SetFromVector(
            [new.t_contact, new.r_contact, new.t_lost, new.t_low, min(first, new.t_contact)]
        )


class SlideAndPressReference(SurfaceReference):
    """The Fig. 3 task (:class:`nsdrake.reference.SlideAndPress`): ramp along the plate,
    approach, press. Ports as :class:`SurfaceReference`."""

    def __init__(
        self,
        *,
        reference: SlideAndPress,
        task_rows: np.ndarray,
        contact_threshold: float,
        period: float,
        loss_time: float = 0.05,
    ):
        super().__init__(
            reference=reference,
            task_rows=task_rows,
            contact_threshold=contact_threshold,
            period=period,
            loss_time=loss_time,
        )


class CircleReference(SurfaceReference):
    """The wiping task (:class:`nsdrake.reference.CircleOnSurface`): approach, press, then
    a circle on the surface, timed from the first contact. Ports as :class:`SurfaceReference`."""

    def __init__(
        self,
        *,
        reference: CircleOnSurface,
        task_rows: np.ndarray,
        contact_threshold: float,
        period: float,
        loss_time: float = 0.05,
    ):
        super().__init__(
            reference=reference,
            task_rows=task_rows,
            contact_threshold=contact_threshold,
            period=period,
            loss_time=loss_time,
        )

    def _eval(self, context):
        return self._ref.at(
            context.get_time(), state=self._contact(context), t_first=self._first_contact(context)
        )

"""Task references with contact detection: the Fig. 3 task, and a circle on the surface."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from ..reference import CircleOnSurface, SlideAndPress, detect_contact
from ._util import python_value_producer


class SurfaceReference(LeafSystem):
    """Desired position, velocity, acceleration and normal force of a task on a surface
    whose reference (``reference.at(t, t_contact)``) depends on the contact time.
    Contact is detected once, when the measured normal force reaches
    ``contact_threshold``; its time is the discrete state, updated every ``period``.

    .. pydrake_system::

        name: SurfaceReference
        input_ports:
        - measured_force
        output_ports:
        - x_d
        - xdot_d
        - xddot_d
        - f_d
        - contact_time

    ``measured_force`` is the sensor's world force (3) [N]; the outputs are in
    task coordinates (m) [m, m/s, m/s²], f_d [N], and the contact time [s]
    (+∞ before contact).
    """

    def __init__(
        self,
        *,
        reference: SlideAndPress | CircleOnSurface,
        task_rows: np.ndarray,
        contact_threshold: float,
        period: float,
    ):
        super().__init__()
        self._ref = reference
        self._rows = np.asarray(task_rows)
        self._threshold = contact_threshold
        m = reference.x0.shape[0]
        self._force = self.DeclareVectorInputPort("measured_force", 3)
        self._t_contact = self.DeclareDiscreteState(BasicVector([math.inf]))
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        deps = {self.time_ticket(), self.discrete_state_ticket(self._t_contact)}
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
        self.DeclareStateOutputPort("contact_time", self._t_contact)

    def _eval(self, context):
        t_contact = context.get_discrete_state(self._t_contact).GetAtIndex(0)
        return self._ref.at(context.get_time(), t_contact)

    def _update(self, context, discrete_state):
        t_contact = context.get_discrete_state(self._t_contact).GetAtIndex(0)
        f_n = float(self._ref.normal @ self._force.Eval(context)[self._rows])
        discrete_state.get_mutable_vector(self._t_contact).SetAtIndex(
            0, detect_contact(context.get_time(), t_contact, f_n, self._threshold)
        )


class SlideAndPressReference(SurfaceReference):
    """The Fig. 3 task (:class:`nsdrake.reference.SlideAndPress`): ramp along the plate,
    approach, press. Ports as :class:`SurfaceReference`."""

    def __init__(
        self, *, reference: SlideAndPress, task_rows: np.ndarray, contact_threshold: float, period: float
    ):
        super().__init__(
            reference=reference, task_rows=task_rows, contact_threshold=contact_threshold, period=period
        )


class CircleReference(SurfaceReference):
    """The wiping task (:class:`nsdrake.reference.CircleOnSurface`): approach, press, then
    a circle on the surface. Ports as :class:`SurfaceReference`."""

    def __init__(
        self, *, reference: CircleOnSurface, task_rows: np.ndarray, contact_threshold: float, period: float
    ):
        super().__init__(
            reference=reference, task_rows=task_rows, contact_threshold=contact_threshold, period=period
        )

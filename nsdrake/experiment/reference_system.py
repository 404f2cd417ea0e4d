"""Task references with contact detection and loss: the Fig. 3 task, and a circle on the surface."""

from __future__ import annotations

import math

import numpy as np
from pydrake.systems.framework import BasicVector, Diagram, DiagramBuilder
from pydrake.systems.primitives import Demultiplexer

from nsdrake.control.leaf_system import LeafSystem
from nsdrake.control.validation import entry_names, inputs_problem
from nsdrake.experiment.reference import (
    CircleOnSurface,
    ContactState,
    SlideAndPress,
    TaskReferenceError,
    reference_problem,
    update_contact,
)

WRENCH_NAMES = entry_names([("measured_wrench", 6)])


class SurfaceReferenceSystem(LeafSystem):
    """Desired position, velocity, acceleration and normal force of a task on a surface
    whose reference (``reference.at(t, state=…)``) depends on the contact state. The
    contact state, from the measured normal force alone (as on a real robot: contact
    when it reaches ``contact_threshold``, lost when it stays below for ``loss_time``),
    is the discrete state, updated every ``period``
    (:func:`nsdrake.experiment.reference.update_contact`), with the time of the first contact.

    .. pydrake_system::

        name: SurfaceReferenceSystem
        input_ports:
        - measured_wrench
        output_ports:
        - reference

    ``measured_wrench`` is the sensor's [M; f] (6), world [N m, N]; only its force
    f enters. ``reference`` is [x_d; ẋ_d; ẍ_d; f_d; in_contact]: the desired motion
    in task coordinates (m each) [m, m/s, m/s²], the desired normal force f_d [N],
    and 1 while in contact, 0 before it and after it was lost (one port, evaluated
    once per tick; :class:`SurfaceReference` splits it into named ports, :meth:`output_parts`).
    Arguments it cannot take (:func:`nsdrake.experiment.reference.reference_problem`) raise
    :class:`nsdrake.experiment.reference.TaskReferenceError` (a ValueError) in one line, as
    does a ``measured_wrench`` not connected or not finite at an update.
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
        problem = reference_problem(reference, task_rows, contact_threshold, period, loss_time)
        if problem is not None:
            raise TaskReferenceError(f"SurfaceReference.{problem[0]}", problem[1])
        super().__init__()
        self._ref = reference
        self._rows = np.asarray(task_rows, dtype=int)
        self._threshold = contact_threshold
        self._loss_time = loss_time
        m = reference.x0.shape[0]
        self._m = m
        self._wrench = self.DeclareVectorInputPort("measured_wrench", 6)
        # [t_contact, r_contact, t_lost, t_low] of ContactState, then the first contact's time
        self._state = self.DeclareDiscreteState(
            BasicVector([math.inf, math.nan, math.inf, math.inf, math.inf])
        )
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self._reference = self.DeclareVectorOutputPort(
            "reference",
            3 * m + 2,
            self._calc,
            prerequisites_of_calc={self.time_ticket(), self.discrete_state_ticket(self._state)},
        )

    def output_parts(self) -> dict[str, int]:
        """The parts of the ``reference`` port and their sizes, in order."""
        return {"x_d": self._m, "xdot_d": self._m, "xddot_d": self._m, "f_d": 1, "in_contact": 1}

    def _contact(self, context) -> tuple[ContactState, float]:
        """The contact state and the first contact's time."""
        t_contact, r_contact, t_lost, t_low, first = context.get_discrete_state(self._state).value()
        return ContactState(t_contact, r_contact, t_lost, t_low), first

    def _measured_wrench(self, context) -> np.ndarray:
        """The measured wrench, refused in one line naming the reference and the port when
        it is not connected or not finite (a NaN force never reaches the threshold: contact
        would silently never be detected)."""
        where = (
            f"{self.GetSystemPathname().rsplit('::', 1)[0] or 'reference'} at t = {context.get_time():g} s"
        )
        if not self._wrench.HasValue(context):
            raise TaskReferenceError(
                where, "measured_wrench is not connected (connect the force sensor's wrench)"
            )
        wrench = self._wrench.Eval(context)
        problem = inputs_problem(wrench, WRENCH_NAMES)
        if problem is not None:
            raise TaskReferenceError(where, problem)
        return wrench

    def _calc(self, context, output):
        state, first = self._contact(context)
        x_d, xdot_d, xddot_d, f_d = self._ref.at(context.get_time(), state=state, t_first=first)
        output.SetFromVector(np.concatenate([x_d, xdot_d, xddot_d, [f_d, float(state.in_contact)]]))

    def _update(self, context, discrete_state):
        state, first = self._contact(context)
        f_n = float(self._ref.normal @ self._measured_wrench(context)[3:][self._rows])
        # r, the normal offset of x_d now, from the output: computed (and cached) for this
        # instant's torque already, so the path is not evaluated a second time.
        x_d = self._reference.Eval(context)[: self._m]
        r_now = x_d @ self._ref.normal - self._ref.x0 @ self._ref.normal
        new = update_contact(state, context.get_time(), f_n, self._threshold, self._loss_time, r_now)
        discrete_state.get_mutable_vector(self._state).SetFromVector(
            [new.t_contact, new.r_contact, new.t_lost, new.t_low, min(first, new.t_contact)]
        )


class SurfaceReference(Diagram):
    """The task reference of a task on a surface, with contact detection and loss
    (:class:`SurfaceReferenceSystem`), its packed output split into named ports.

    .. pydrake_system::

        name: SurfaceReference
        input_ports:
        - measured_wrench
        output_ports:
        - x_d
        - xdot_d
        - xddot_d
        - f_d
        - in_contact

    ``measured_wrench`` is the sensor's [M; f] (6), world [N m, N]. x_d, xdot_d,
    xddot_d are the desired motion in task coordinates (m each) [m, m/s, m/s²], f_d
    (1) the desired normal force [N], ``in_contact`` (1) 1 while in contact, 0 before
    it and after it was lost. ``reference`` is a :class:`nsdrake.experiment.reference.SlideAndPress`
    (Fig. 3) or a :class:`nsdrake.experiment.reference.CircleOnSurface` (the wiping task, timed
    from the first contact); the other arguments are :class:`SurfaceReferenceSystem`'s.
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
        builder = DiagramBuilder()
        leaf = builder.AddNamedSystem(
            "contact_and_reference",
            SurfaceReferenceSystem(
                reference=reference,
                task_rows=task_rows,
                contact_threshold=contact_threshold,
                period=period,
                loss_time=loss_time,
            ),
        )
        parts = builder.AddNamedSystem("parts", Demultiplexer(list(leaf.output_parts().values())))
        builder.Connect(leaf.GetOutputPort("reference"), parts.get_input_port())
        builder.ExportInput(leaf.GetInputPort("measured_wrench"), "measured_wrench")
        for k, name in enumerate(leaf.output_parts()):
            builder.ExportOutput(parts.get_output_port(k), name)
        builder.BuildInto(self)

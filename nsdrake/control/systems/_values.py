"""What the controller's systems share: per-context memory (the values of their abstract
ports and cache entries) and the call of their stage.

Drake copies a context's values with ``copy.deepcopy``, so each value here says what a
copy is (numbers copied, model scratch made anew, never shared between contexts).
"""

from __future__ import annotations

import re

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import ValueProducer

from nsdrake.control.leaf_system import LeafSystem, released_on_error
from nsdrake.control.plan import ControllerPlan, StageBuffers
from nsdrake.control.validation import ControllerInputError, inputs_problem


class TermsValue:
    """The model terms at one state (:func:`nsdrake.control.layout.terms_views`): the value
    of the ``robot_terms`` port, one flat buffer rewritten in place at every state."""

    def __init__(self, buffer):
        self.buffer = buffer


class ScratchValue:
    """Model scratch memory (:meth:`nsdrake.control.model.ControllerModel.create_scratch`):
    a copy is a fresh scratch of the same model, as a copy needs no stale numbers."""

    def __init__(self, plan: ControllerPlan):
        self.plan = plan
        self.scratch = plan.create_scratch()

    def __deepcopy__(self, memo):
        return ScratchValue(self.plan)


def declare_value_cache(system, description: str, create, calc=None, prerequisites=None):
    """A cache entry holding ``create()``, allocated per context, that ``calc(context, value)``
    rewrites in place (``value`` the object itself) when one of ``prerequisites`` changed;
    without ``calc`` it is scratch memory, never recomputed (read it with :func:`scratch`)."""
    if calc is None:
        producer = ValueProducer(allocate=lambda: AbstractValue.Make(create()), calc=lambda c, v: None)
        prerequisites = {system.nothing_ticket()}
    else:
        producer = ValueProducer(
            allocate=lambda: AbstractValue.Make(create()),
            calc=released_on_error(lambda context, value: calc(context, value.get_mutable_value())),
        )
    return system.DeclareCacheEntry(
        description=description, value_producer=producer, prerequisites_of_calc=prerequisites
    )


def check_inputs(system, context, values, names, quaternion: int = -1) -> None:
    """Raises :class:`ControllerInputError` when ``values`` (an input port's value, or the
    packed commands; entries named ``names``) give no torque: a value that is not finite
    (a diverged plant, a broken reference) or a zero desired quaternion. Named by the
    controller's path in the user's diagram, the time, the input port and its entry."""
    problem = inputs_problem(values, names, quaternion)
    if problem is not None:
        raise ControllerInputError(f"{controller_path(system)} at t = {context.get_time():g} s", problem)


# The controller's input ports packed into its commands, in their order (the named
# ImpedanceController's inputs, the fused system's Multiplexer): the names a user wires.
COMMAND_PORTS = (
    "measured_wrench", "desired_position", "desired_velocity", "desired_acceleration", "desired_force",
    "desired_orientation", "desired_angular_velocity", "desired_angular_acceleration",
)  # fmt: skip


def controller_path(system) -> str:
    """The controller's path in the user's diagram (``::user::controller``), from one of its
    systems."""
    return system.GetSystemPathname().rsplit("::", 1)[0] or "controller"


def evaluated(system, context, port, name: str):
    """``port``'s value; an input the user never connected nor fixed (Drake names the inner
    system's port: "InputPort[6] (R_d) of … impedance_controller") is refused as
    :class:`ControllerInputError` naming the controller's own port ``name``. Costs nothing
    until it fails."""
    try:
        return port.Eval(context)
    except RuntimeError:
        if port.HasValue(context):
            raise  # something upstream failed: the user's system, named by Drake
        raise unconnected(system, name) from None


def unconnected(system, name: str) -> ControllerInputError:
    """The error for the controller's input ``name`` left unconnected."""
    return ControllerInputError(
        f"{controller_path(system)} input {name}",
        "not connected: the controller needs it at every tick (connect it, or fix its value)",
    )


def evaluated_commands(system, context, port):
    """The fused system's packed commands (the Multiplexer of the controller's inputs in
    COMMAND_PORTS order); an input of it left unconnected is refused naming the
    controller's port, read from Drake's message about the Multiplexer's input."""
    try:
        return port.Eval(context)
    except RuntimeError as e:
        multiplexer = f"of System {controller_path(system)}::commands (Multiplexer"
        found = re.search(r"InputPort\[(\d+)\] \(u\d+\) " + re.escape(multiplexer), str(e))
        if found is None or "is not connected" not in str(e):
            raise
        raise unconnected(system, COMMAND_PORTS[int(found.group(1))]) from None


def scratch(entry, context):
    """The object in a scratch entry of :func:`declare_value_cache` (never computed)."""
    return entry.get_mutable_cache_entry_value(context).GetMutableValueOrThrow()


class StageSystem(LeafSystem):
    """A system that runs one stage of :mod:`nsdrake.control.stages`: it has the plan, a
    ``robot_terms`` input (unless ``terms`` is False) and per-context :class:`StageBuffers`
    for the stage's other arrays."""

    def __init__(self, plan: ControllerPlan, *, terms: bool = True):
        super().__init__()
        self._plan = plan
        self._n = plan.n
        self._stage_buffers = declare_value_cache(self, "stage buffers", lambda: StageBuffers(plan))
        if terms:
            self._terms = self.DeclareAbstractInputPort(
                "robot_terms", AbstractValue.Make(TermsValue(plan.allocate_terms()))
            )
        self._no_terms = plan.allocate_terms()

    def buffers(self, context) -> StageBuffers:
        return scratch(self._stage_buffers, context)

    def run(self, context, stages: int, buffers: StageBuffers, t_previous: float = 0.0) -> None:
        terms = self._terms.Eval(context).buffer if hasattr(self, "_terms") else self._no_terms
        self._plan.run(stages, context.get_time(), t_previous, terms, buffers)

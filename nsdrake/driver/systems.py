"""Two small systems of the controller side: the measurement hold and the command stamp."""

from __future__ import annotations

import numpy as np
from drake import lcmt_panda_command, lcmt_panda_status
from pydrake.systems.framework import BasicVector, LeafSystem
from pydrake.systems.lcm import _Serializer_


class MeasurementHold(LeafSystem):
    """The measurements the controller reads, sampled once per control period and held, so
    that the controller meets them in the order it meets a discrete plant's state.

    .. pydrake_system::

        name: MeasurementHold
        input_ports:
        - sample
        output_ports:
        - state
        - wrench

    ``sample`` is the parts one after the other; each output is one part of the held
    sample (``parts``: name and size, in order; the controller side's are ``state`` [q; q̇]
    and ``wrench``), and depends on the held value alone: not on time, so that what the
    controller computes from the state stays cached while its clock advances (a Drake
    ``Demultiplexer`` after the hold made every tick compute the model terms twice).

    The held value is the discrete state; a periodic unrestricted update at every control
    instant t_k copies ``sample`` into it. Why: in the direct simulation Drake steps the
    plant in an unrestricted update at t_k, alongside the controller's own unrestricted
    stores (the null-space controller's previous q̇_dⁿ, the previous torque of the rate
    limit), which therefore see the state at t_k, while the discrete updates after them
    (the selector's switch, the reference's contact state) see the state at t_{k+1}. The
    controller side receives the status of t_{k+1} before it advances its clock past t_k;
    sampled here in the same unrestricted batch as those stores, it reaches the stores one
    period later and the discrete updates at once, exactly as the plant's state does.
    (Drake's ``ZeroOrderHold`` samples in a discrete update, after the stores.)
    """

    def __init__(self, *, parts: dict[str, int], period: float):
        super().__init__()
        size = sum(parts.values())
        self._input = self.DeclareVectorInputPort("sample", size)
        self._state = self.DeclareDiscreteState(BasicVector(np.zeros(size)))
        held = {self.discrete_state_ticket(self._state)}
        start = 0
        for name, part_size in parts.items():
            self.DeclareVectorOutputPort(name, part_size, self._part_calc(start, part_size), held)
            start += part_size
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._sample)

    def set_held(self, context, value: np.ndarray) -> None:
        """Sets the held value (the first status, before the run starts)."""
        context.SetDiscreteState(self._state, np.asarray(value, dtype=float))

    def _part_calc(self, start: int, size: int):
        def calc(context, output):
            output.SetFromVector(context.get_discrete_state(self._state).value()[start : start + size])

        return calc

    def _sample(self, context, state):
        state.get_mutable_discrete_state(self._state).SetFromVector(self._input.Eval(context))


class CommandStamp(LeafSystem):
    """Drake's ``PandaCommandSender``'s message with the ``utime`` of the status it answers.

    .. pydrake_system::

        name: CommandStamp
        input_ports:
        - lcmt_panda_command
        - lcmt_panda_status
        output_ports:
        - lcmt_panda_command

    ``PandaCommandSender`` stamps ``utime`` with the context time (here the time since
    the first status), but a Panda's LCM driver (drake-franka-driver) drops every
    command whose ``utime`` lies further than its ``--expire_sec`` from its own clock,
    the clock it stamps each status with. The command therefore carries the ``utime`` of
    the status it answers, which also lets a driver pair each command with its status.
    Both messages are Drake's C++ types (read and written through Drake's serializers).
    The stamp is ``utime`` asserted in ``lcmt_panda_command``'s and ``lcmt_panda_status``'s
    first field (tests/driver/test_wire_faults.py checks every command's).
    """

    def __init__(self):
        super().__init__()
        self._command_serializer = _Serializer_[lcmt_panda_command]()
        self._status_serializer = _Serializer_[lcmt_panda_status]()
        self._command = self.DeclareAbstractInputPort(
            "lcmt_panda_command", self._command_serializer.CreateDefaultValue()
        )
        self._status = self.DeclareAbstractInputPort(
            "lcmt_panda_status", self._status_serializer.CreateDefaultValue()
        )
        deps = {self.input_port_ticket(p.get_index()) for p in (self._command, self._status)}
        self.DeclareAbstractOutputPort(
            "lcmt_panda_command",
            alloc=self._command_serializer.CreateDefaultValue,
            calc=self._calc,
            prerequisites_of_calc=deps,
        )

    def _calc(self, context, output):
        # Each encoding is LCM's 8-byte type fingerprint, then the message's first field,
        # ``utime`` (int64, big-endian) in both types: the status's 8 bytes replace the
        # command's, with no Python decode and encode of either message.
        command = self._command_serializer.Serialize(self._command.EvalAbstract(context))
        status = self._status_serializer.Serialize(self._status.EvalAbstract(context))
        self._command_serializer.Deserialize(command[:8] + status[8:16] + command[16:], output)

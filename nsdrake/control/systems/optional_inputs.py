"""The controller's optional inputs: q̇_dⁿ from outside, and zeros for the force inputs of
a task without a force axis."""

from __future__ import annotations

import numpy as np

from nsdrake.control.leaf_system import LeafSystem
from nsdrake.control.systems._values import check_inputs
from nsdrake.control.validation import ControllerInputError, entry_names


class NullSpaceVelocitySource(LeafSystem):
    """q̇_dⁿ for the null-space controller: the ``desired_null_space_velocity`` input when it
    is connected (or fixed), which then wins over the configured source; else the
    configured source's (the priority selector's or the sweep's).

    .. pydrake_system::

        name: NullSpaceVelocitySource
        input_ports:
        - configured
        - desired_null_space_velocity
        output_ports:
        - desired_null_space_velocity

    All three are n [rad/s]. The input is used as given: no joint-speed scaling, no blend;
    a value that is not finite raises :class:`nsdrake.control.validation.ControllerInputError`
    naming the entry (``joints``: the joints' names, velocity order).
    """

    def __init__(self, n: int, joints=None):
        super().__init__()
        self._names = entry_names([("desired_null_space_velocity", n if joints is None else list(joints))])
        self._configured = self.DeclareVectorInputPort("configured", n)
        self._external = self.DeclareVectorInputPort("desired_null_space_velocity", n)
        self.DeclareVectorOutputPort(
            "desired_null_space_velocity",
            n,
            self._calc,
            prerequisites_of_calc={self.all_input_ports_ticket()},
        )

    def _calc(self, context, output):
        if not self._external.HasValue(context):
            output.SetFromVector(self._configured.Eval(context))
            return
        value = self._external.Eval(context)
        check_inputs(self, context, value, self._names)
        output.SetFromVector(value)


class ZeroIfUnconnected(LeafSystem):
    """Its input, or zeros when the input is not connected: ``measured_wrench`` and
    ``desired_force`` of a task without a force axis (nothing to press, so a user need
    not wire a sensor or a force command). With ``refuse`` (a reason), a connected input is
    refused instead (:class:`nsdrake.control.validation.ControllerInputError`, ``name`` the
    controller's port): ``desired_force`` without a force axis, which would do nothing.

    .. pydrake_system::

        name: ZeroIfUnconnected
        input_ports:
        - u0
        output_ports:
        - y0
    """

    def __init__(self, size: int, name: str = "u0", refuse: str | None = None):
        super().__init__()
        self._name, self._refuse = name, refuse
        self._u = self.DeclareVectorInputPort("u0", size)
        self._zeros = np.zeros(size)
        self.DeclareVectorOutputPort(
            "y0", size, self._calc, prerequisites_of_calc={self.all_input_ports_ticket()}
        )

    def _calc(self, context, output):
        if not self._u.HasValue(context):
            output.SetFromVector(self._zeros)
            return
        if self._refuse is not None:
            controller = self.GetSystemPathname().rsplit("::", 1)[0] or "controller"
            raise ControllerInputError(f"{controller} input {self._name}", self._refuse)
        output.SetFromVector(self._u.Eval(context))

"""The controller's optional inputs: q̇_dⁿ from outside, and zeros for the force inputs of
a task without a force axis."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem


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

    All three are n [rad/s]. The input is used as given: no joint-speed scaling, no blend.
    """

    def __init__(self, n: int):
        super().__init__()
        self._configured = self.DeclareVectorInputPort("configured", n)
        self._external = self.DeclareVectorInputPort("desired_null_space_velocity", n)
        self.DeclareVectorOutputPort(
            "desired_null_space_velocity",
            n,
            self._calc,
            prerequisites_of_calc={self.all_input_ports_ticket()},
        )

    def _calc(self, context, output):
        port = self._external if self._external.HasValue(context) else self._configured
        output.SetFromVector(port.Eval(context))


class ZeroIfUnconnected(LeafSystem):
    """Its input, or zeros when the input is not connected: ``measured_wrench`` and
    ``desired_force`` of a task without a force axis (nothing to press, so a user need
    not wire a sensor or a force command).

    .. pydrake_system::

        name: ZeroIfUnconnected
        input_ports:
        - u0
        output_ports:
        - y0
    """

    def __init__(self, size: int):
        super().__init__()
        self._u = self.DeclareVectorInputPort("u0", size)
        self._zeros = np.zeros(size)
        self.DeclareVectorOutputPort(
            "y0", size, self._calc, prerequisites_of_calc={self.all_input_ports_ticket()}
        )

    def _calc(self, context, output):
        output.SetFromVector(self._u.Eval(context) if self._u.HasValue(context) else self._zeros)

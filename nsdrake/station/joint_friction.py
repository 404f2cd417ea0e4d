"""JointFriction: gear friction as a generalized force on the plant."""

from __future__ import annotations

import numpy as np

from nsdrake.control.leaf_system import LeafSystem
from nsdrake.station.friction import friction_torque


class JointFriction(LeafSystem):
    """τ_f = −(τ_c tanh(v/v_s) + b v) on the plant's velocities ``dofs``
    (:mod:`nsdrake.station.friction`), zero on the others.

    .. pydrake_system::

        name: JointFriction
        input_ports:
        - state
        output_ports:
        - generalized_force

    ``state`` is the plant's [q; v] (nq + nv); ``generalized_force`` (nv) [N m] goes
    to the plant's ``applied_generalized_force`` input.
    """

    def __init__(self, *, nq: int, nv: int, dofs, coulomb: float, viscous: float, smoothing_speed: float):
        super().__init__()
        self._nq = nq
        self._dofs = np.asarray(dofs, dtype=int)
        self._params = (coulomb, viscous, smoothing_speed)
        self._state = self.DeclareVectorInputPort("state", nq + nv)
        self._nv = nv
        self.DeclareVectorOutputPort(
            "generalized_force",
            nv,
            self._calc,
            prerequisites_of_calc={self.input_port_ticket(self._state.get_index())},
        )

    def _calc(self, context, output):
        v = self._state.Eval(context)[self._nq :]
        tau = np.zeros(self._nv)
        tau[self._dofs] = friction_torque(v[self._dofs], *self._params)
        output.SetFromVector(tau)

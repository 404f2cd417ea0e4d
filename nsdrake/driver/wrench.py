"""The measured contact wrench on the wire: a force-torque sensor's ``lcmt_force_torque``
messages, or the estimate from the Panda's external joint torques.

Conventions (the controller's ``measured_wrench``): W = [M; f], the wrench the tool
exerts on the work piece, world axes [N m, N]; the moment is about a stated point.

- **Sensor** messages carry f = (fx, fy, fz) and M = (tx, ty, tz) in that convention,
  the moment about the sensor origin (the simulated station's table sensor publishes
  exactly what it reads); ``timestamp`` in milliseconds, as the message defines it
  (read in place by :class:`nsdrake.driver.wire.ForceTorqueBuffer`).
- **External joint torques**: the status's ``joint_torque_external`` is read as
  τ_ext = Jᵀ W_T, the joint torques with which the arm holds the wrench W_T it exerts
  at the tool point T (for the simulated driver: minus the generalized contact forces
  the plant applies to the arm). With J the (6 × n) spatial Jacobian of T in the
  world, [angular; translational], the estimate is the least-squares solution of
  Jᵀ W_T = τ_ext, W_T = (J Jᵀ)⁻¹ J τ_ext when J has full row rank (7 joints, 6 rows):
  exact for a wrench applied at the tool alone; any load elsewhere on the arm, and the
  robot's own estimation error, is attributed to the tool.
"""

from __future__ import annotations

import numpy as np
from drake import lcmt_force_torque
from pydrake.systems.lcm import _Serializer_

from nsdrake.control.leaf_system import LeafSystem


def wrench_from_external_torques(J_spatial: np.ndarray, tau_ext: np.ndarray) -> np.ndarray:
    """W_T = [M_T; f], the least-squares solution of Jᵀ W_T = τ_ext (module docstring).
    J_spatial (6, n) [angular; translational]; τ_ext (n,) [N m]. (6,) [N m, N]."""
    return np.linalg.lstsq(J_spatial.T, tau_ext, rcond=None)[0]


def force_torque_message(wrench: np.ndarray, time: float) -> lcmt_force_torque:
    """An lcmt_force_torque carrying W = [M; f] (6,) [N m, N] at ``time`` [s]."""
    message = lcmt_force_torque()
    message.timestamp = round(time * 1e3)
    message.tx, message.ty, message.tz, message.fx, message.fy, message.fz = (float(w) for w in wrench)
    return message


def wrench_of(message: lcmt_force_torque) -> np.ndarray:
    """W = [M; f] (6,) [N m, N] from an lcmt_force_torque."""
    return np.array([message.tx, message.ty, message.tz, message.fx, message.fy, message.fz])


class ForceTorqueSender(LeafSystem):
    """A wrench as lcmt_force_torque messages (the simulated driver's sensor).

    .. pydrake_system::

        name: ForceTorqueSender
        input_ports:
        - wrench
        output_ports:
        - lcmt_force_torque

    ``wrench`` is [M; f] (6) [N m, N]; the message carries it with the context time
    in milliseconds. The message is Drake's C++ type (an ``LcmPublisherSystem`` made with
    ``use_cpp_serializer=True`` takes it): a Python message held in a system's state is
    deep-copied by Python's ``copy`` each time Drake copies that state.
    """

    def __init__(self):
        super().__init__()
        self._serializer = _Serializer_[lcmt_force_torque]()
        self._wrench = self.DeclareVectorInputPort("wrench", 6)
        self.DeclareAbstractOutputPort(
            "lcmt_force_torque",
            alloc=self._serializer.CreateDefaultValue,
            calc=self._calc,
            prerequisites_of_calc={self.time_ticket(), self.input_port_ticket(self._wrench.get_index())},
        )

    def _calc(self, context, output):
        message = force_torque_message(self._wrench.Eval(context), context.get_time())
        self._serializer.Deserialize(message.encode(), output)

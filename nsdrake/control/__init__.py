"""The controller: everything a user's own Drake diagram needs, and nothing about plates,
scenarios or reports. It imports nothing else of nsdrake.

- the math, each formula in one home and named after its equation: ``dynamics`` (Eq. 5's
  terms), ``pseudo_inverse`` (Eq. 13, Eq. 4), ``impedance`` (Eqs. 6–8), ``null_space``
  (Eqs. 14, 21, 23), ``gradient_projection`` (Eqs. 28–30), ``criteria/`` (Eqs. 31–33 and
  more), ``priority`` (Fig. 1), ``actuator_limits``, ``orientation``, ``smoothing``;
- ``config`` (ControllerConfig) and ``model`` (ControllerModel: the controller's own model
  of the arm and its obstacles);
- ``systems/``, the LeafSystems over that math, and ``controller``
  (NullSpaceImpedanceController), the Diagram that wires them.
"""

from nsdrake.control.config import ControllerConfig
from nsdrake.control.controller import (
    ControllerConfigError,
    NullSpaceImpedanceController,
    without_null_space_task,
)
from nsdrake.control.model import ControllerModel, Obstacle

__all__ = [
    "ControllerConfig",
    "ControllerConfigError",
    "ControllerModel",
    "NullSpaceImpedanceController",
    "Obstacle",
    "without_null_space_task",
]

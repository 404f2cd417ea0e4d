"""The controller: everything a user's own Drake diagram needs, and nothing about plates,
scenarios or reports. It imports nothing else of nsdrake.

- the math, each formula in one home and named after its equation: ``dynamics`` (Eq. 5's
  terms), ``pseudo_inverse`` (Eq. 13, Eq. 4), ``impedance`` (Eqs. 6–8), ``null_space``
  (Eqs. 14, 21, 23), ``gradient_projection`` (Eqs. 28–30), ``criteria/`` (Eqs. 31–33 and
  more), ``priority`` (Fig. 1), ``actuator_limits``, ``orientation``, ``smoothing``;
- ``config`` (ControllerConfig) and ``model`` (ControllerModel: the controller's own model
  of the arm and its obstacles), ``model_files`` (model files as vendors ship them, a tool
  Payload) and ``pinocchio_tree`` (Pinocchio's model from the plant Drake parsed);
- ``stages`` (the controller's tick as one ordered sequence of compiled stages), ``layout``
  and ``plan`` (its arrays and constants), ``kernels`` (the compiled code's cache);
- ``systems/``, the LeafSystems over those stages, ``controller``
  (NullSpaceImpedanceController), the Diagram that wires them (named systems or one fused
  system), and ``step`` (ControllerStep, the same tick as one plain call).
"""

from nsdrake.control.kernels import announce_compiling, refresh_cache

refresh_cache()  # before any kernel loads from numba's cache (nsdrake.control.kernels)
announce_compiling()

from nsdrake.control.config import ControllerConfig  # noqa: E402
from nsdrake.control.controller import (  # noqa: E402
    ControllerConfigError,
    NullSpaceImpedanceController,
    without_null_space_task,
)
from nsdrake.control.model import ControllerModel, Obstacle  # noqa: E402
from nsdrake.control.model_files import Payload  # noqa: E402
from nsdrake.control.step import ControllerStep, StepResult  # noqa: E402
from nsdrake.control.validation import ControllerInputError  # noqa: E402

__all__ = [
    "ControllerConfig",
    "ControllerConfigError",
    "ControllerInputError",
    "ControllerModel",
    "ControllerStep",
    "NullSpaceImpedanceController",
    "Obstacle",
    "Payload",
    "StepResult",
    "without_null_space_task",
]

"""nsdrake: null-space velocity control with the dynamically consistent pseudo-inverse, on Drake.

Nemec, B. and Žlajpah, L. (2000), "Null space velocity control with dynamically
consistent pseudo-inverse", Robotica 18, 513–518.
"""

__version__ = "0.1.0"

from nsdrake.control import (
    ControllerConfig,
    ControllerConfigError,
    ControllerModel,
    ControllerStep,
    NullSpaceImpedanceController,
    Obstacle,
)
from nsdrake.station.control_hold import ControlHold

__all__ = [
    "ControlHold",
    "ControllerConfig",
    "ControllerConfigError",
    "ControllerModel",
    "ControllerStep",
    "NullSpaceImpedanceController",
    "Obstacle",
]

"""nsdrake: null-space velocity control with the dynamically consistent pseudo-inverse, on Drake.

Nemec, B. and Žlajpah, L. (2000), "Null space velocity control with dynamically
consistent pseudo-inverse", Robotica 18, 513–518.
"""

__version__ = "0.1.0"

from nsdrake.control import (
    ControllerConfig,
    ControllerConfigError,
    ControllerInputError,
    ControllerModel,
    ControllerStep,
    NullSpaceImpedanceController,
    Obstacle,
    Payload,
)
from nsdrake.experiment.reference import CircleOnSurface, SlideAndPress, TaskReferenceError
from nsdrake.experiment.reference_system import SurfaceReference
from nsdrake.station.control_hold import ControlHold
from nsdrake.station.force_sensor import ForceSensor

# The controller (nsdrake.control) and, for a contact set-up of your own, the pieces the
# shipped scenarios use: a wrench sensor from a weld's reaction force (ForceSensor), the
# surface reference that freezes the normal where contact is detected (SurfaceReference)
# and its trajectories (SlideAndPress, CircleOnSurface), and the hold for a plant that
# steps faster than the controller (ControlHold). docs/own_diagram.md: "Use the
# controller in your own diagram".
__all__ = [
    "CircleOnSurface",
    "ControlHold",
    "ControllerConfig",
    "ControllerConfigError",
    "ControllerInputError",
    "ControllerModel",
    "ControllerStep",
    "NullSpaceImpedanceController",
    "ForceSensor",
    "Obstacle",
    "Payload",
    "SlideAndPress",
    "SurfaceReference",
    "TaskReferenceError",
]

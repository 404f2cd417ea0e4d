"""Drake LeafSystems: thin shells that read ports, call nsdrake's math, write outputs."""

from .actuator_limits import ActuatorLimitsSystem
from .contact_monitor import ContactMonitor
from .criteria import (
    JointLimitsCriterionSystem,
    JointTorqueCriterionSystem,
    ManipulabilityCriterionSystem,
    ObstacleCriterionSystem,
)
from .force_sensor import ForceSensor
from .impedance_controller import ImpedanceController
from .null_space_controller import NullSpaceController
from .priority_selector import PrioritySelector
from .reference import SurfaceReference, SurfaceReferenceSystem
from .robot_terms import RobotTermsSystem
from .self_motion import SelfMotionSweep

__all__ = [
    "ActuatorLimitsSystem",
    "ContactMonitor",
    "ForceSensor",
    "ImpedanceController",
    "JointLimitsCriterionSystem",
    "JointTorqueCriterionSystem",
    "ManipulabilityCriterionSystem",
    "NullSpaceController",
    "ObstacleCriterionSystem",
    "PrioritySelector",
    "RobotTermsSystem",
    "SelfMotionSweep",
    "SurfaceReference",
    "SurfaceReferenceSystem",
]

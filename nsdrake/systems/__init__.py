"""Drake LeafSystems: thin shells that read ports, call nsdrake's math, write outputs."""

from .contact_monitor import ContactMonitor
from .criteria import JointTorqueCriterionSystem
from .desired_null_space_velocity import GradientProjectionSystem
from .force_sensor import ForceSensor
from .impedance_controller import ImpedanceController
from .null_space_controller import NullSpaceController
from .reference import SlideAndPressReference
from .robot_terms import RobotTermsSystem

__all__ = [
    "ContactMonitor",
    "ForceSensor",
    "GradientProjectionSystem",
    "ImpedanceController",
    "JointTorqueCriterionSystem",
    "NullSpaceController",
    "RobotTermsSystem",
    "SlideAndPressReference",
]

"""The controller's Drake LeafSystems: thin shells that read ports, call one stage of
:mod:`nsdrake.control.stages`, and write one packed output each; and the fused system
that runs every stage in one."""

from nsdrake.control.systems.actuator_limits import ActuatorLimitsSystem
from nsdrake.control.systems.criteria import CriteriaSystem
from nsdrake.control.systems.fused import FusedController
from nsdrake.control.systems.impedance_controller import ImpedanceController
from nsdrake.control.systems.null_space_controller import NullSpaceController
from nsdrake.control.systems.optional_inputs import NullSpaceVelocitySource, ZeroIfUnconnected
from nsdrake.control.systems.priority_selector import PrioritySelector
from nsdrake.control.systems.robot_terms import RobotTermsSystem
from nsdrake.control.systems.self_motion import SelfMotionSweep

__all__ = [
    "ActuatorLimitsSystem",
    "CriteriaSystem",
    "FusedController",
    "ImpedanceController",
    "NullSpaceController",
    "NullSpaceVelocitySource",
    "PrioritySelector",
    "RobotTermsSystem",
    "SelfMotionSweep",
    "ZeroIfUnconnected",
]

"""The controller's Drake LeafSystems: thin shells that read ports, call the math of
:mod:`nsdrake.control`, and write one packed output each."""

from nsdrake.control.systems.actuator_limits import ActuatorLimitsSystem
from nsdrake.control.systems.criteria import (
    JointLimitsCriterionSystem,
    JointTorqueCriterionSystem,
    ManipulabilityCriterionSystem,
    ObstacleCriterionSystem,
)
from nsdrake.control.systems.impedance_controller import ImpedanceController
from nsdrake.control.systems.null_space_controller import NullSpaceController
from nsdrake.control.systems.priority_selector import PrioritySelector
from nsdrake.control.systems.robot_terms import RobotTermsSystem
from nsdrake.control.systems.self_motion import SelfMotionSweep

__all__ = [
    "ActuatorLimitsSystem",
    "ImpedanceController",
    "JointLimitsCriterionSystem",
    "JointTorqueCriterionSystem",
    "ManipulabilityCriterionSystem",
    "NullSpaceController",
    "ObstacleCriterionSystem",
    "PrioritySelector",
    "RobotTermsSystem",
    "SelfMotionSweep",
]

"""Optimisation criteria of Section 3.5: each returns its value p and gradient Φ = ∂p/∂q."""

from nsdrake.control.criteria.joint_torque import joint_torque_criterion
from nsdrake.control.criteria.manipulability import manipulability
from nsdrake.control.criteria.obstacle import DistancePair, ObstacleDistances, obstacle_potential

__all__ = [
    "DistancePair",
    "ObstacleDistances",
    "joint_torque_criterion",
    "manipulability",
    "obstacle_potential",
]

"""Optimisation criteria of Section 3.5: each returns its value p and gradient Φ = ∂p/∂q."""

from .joint_torque import joint_torque_criterion
from .manipulability import manipulability
from .obstacle import DistancePair, ObstacleDistances, obstacle_potential

__all__ = [
    "DistancePair",
    "ObstacleDistances",
    "joint_torque_criterion",
    "manipulability",
    "obstacle_potential",
]

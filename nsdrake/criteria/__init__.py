"""Optimisation criteria of Section 3.5: each returns its value p and gradient Φ = ∂p/∂q."""

from .joint_torque import joint_torque_criterion

__all__ = ["joint_torque_criterion"]

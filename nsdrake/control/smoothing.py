"""Smooth switches: the one home of the smoothstep that fades activations, blends
priority switches and shapes reference profiles without a step in the torque."""

from __future__ import annotations


def smoothstep(u: float) -> float:
    """3u² − 2u³ on [0, 1], 0 below, 1 above."""
    if u <= 0.0:
        return 0.0
    if u >= 1.0:
        return 1.0
    return u * u * (3.0 - 2.0 * u)

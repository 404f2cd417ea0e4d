"""Smooth switches: the one home of the smoothstep that fades activations, blends
priority switches and shapes reference profiles without a step in the torque."""

from __future__ import annotations

from numba import njit


def smoothstep(u: float) -> float:
    """3u² − 2u³ on [0, 1], 0 below, 1 above."""
    if u <= 0.0:
        return 0.0
    if u >= 1.0:
        return 1.0
    return u * u * (3.0 - 2.0 * u)


# The same function compiled, for the controller's kernels (numba calls only compiled code).
compiled_smoothstep = njit(cache=True, inline="always")(smoothstep)


@njit(cache=True, inline="always")
def activation(distance: float, influence: float) -> float:
    """How much a criterion that switches on near a boundary counts in the projection of
    the levels below it (:mod:`nsdrake.control.priority`): 0 while the distance to the
    boundary (a link to an obstacle [m], a joint to its limit [rad]) is at least the
    criterion's influence distance ρ, rising with a smoothstep to 1 once it is ρ/2 or less."""
    return compiled_smoothstep(2.0 * (influence - distance) / influence)

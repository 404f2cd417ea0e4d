"""A prescribed self-motion: q̇_dⁿ along the projection of a fixed joint-space direction.

    q̇_dⁿ = a(t) N d / ‖N d‖,   a(t) = a₀ · smoothstep((t − t₀)/t_r) · sin(2π f (t − t₀))

with d a fixed joint-space direction, N the projector of the controller's generalised
inverse, a₀ the amplitude [rad/s], t₀ the start and t_r the ramp time; f = 0 holds a
constant speed. The arm is swept through its self-motion at the commanded speed a(t),
for the experiments of ``nsdrake compare`` (``desired_null_space.source: sweep``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from nsdrake.control.smoothing import compiled_smoothstep


@njit(cache=True)
def sweep_amplitude(t: float, amplitude: float, frequency: float, start: float, ramp: float) -> float:
    """a(t) = amplitude · smoothstep((t − start)/ramp) · sin(2π f (t − start)), or
    amplitude · smoothstep(…) for f = 0 [rad/s]."""
    if t < start:
        return 0.0
    rise = compiled_smoothstep((t - start) / ramp) if ramp > 0 else 1.0
    wave = math.sin(2.0 * math.pi * frequency * (t - start)) if frequency > 0 else 1.0
    return amplitude * rise * wave


@njit(cache=True)
def sweep_velocity(N: np.ndarray, direction: np.ndarray, a: float) -> np.ndarray:
    """q̇_dⁿ = a N d / ‖N d‖ (zero where N d = 0). (n,) [rad/s]."""
    u = N @ direction
    norm = math.sqrt(u @ u)
    if norm > 0.0:
        return a * u / norm
    return np.zeros_like(u)

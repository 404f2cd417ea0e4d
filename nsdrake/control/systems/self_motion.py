"""SelfMotionSweep: a prescribed desired null-space velocity, for experiments."""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from nsdrake.control.dynamics import RobotTerms
from nsdrake.control.pseudo_inverse import GeneralizedInverse
from nsdrake.control.smoothing import smoothstep


def sweep_amplitude(t: float, amplitude: float, frequency: float, start: float, ramp: float) -> float:
    """a(t) = amplitude · smoothstep((t − start)/ramp) · sin(2π f (t − start)), or
    amplitude · smoothstep(…) for f = 0 [rad/s]."""
    if t < start:
        return 0.0
    rise = smoothstep((t - start) / ramp) if ramp > 0 else 1.0
    wave = math.sin(2.0 * math.pi * frequency * (t - start)) if frequency > 0 else 1.0
    return amplitude * rise * wave


class SelfMotionSweep(LeafSystem):
    """q̇_dⁿ = a(t) N d / ‖N d‖: the arm swept through its self-motion along the
    projection of a fixed joint-space direction d, at the commanded speed a(t)
    (:func:`sweep_amplitude`). N is the projector of the same generalised inverse
    as the null-space controller.

    .. pydrake_system::

        name: SelfMotionSweep
        input_ports:
        - robot_terms
        output_ports:
        - desired_null_space_velocity

    ``desired_null_space_velocity`` is q̇_dⁿ (n) [rad/s].
    """

    def __init__(
        self,
        *,
        inverse: GeneralizedInverse,
        direction: np.ndarray,
        amplitude: float,
        frequency: float,
        start_time: float,
        ramp_time: float,
        model_terms: RobotTerms,
    ):
        super().__init__()
        self._inverse = inverse
        self._direction = np.asarray(direction, dtype=float)
        self._wave = (amplitude, frequency, start_time, ramp_time)
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        self.DeclareVectorOutputPort(
            "desired_null_space_velocity",
            model_terms.n,
            self._calc,
            prerequisites_of_calc={self.input_port_ticket(self._terms.get_index()), self.time_ticket()},
        )

    def _calc(self, context, output):
        terms = self._terms.Eval(context)
        u = self._inverse.at(terms).N @ self._direction
        norm = float(np.linalg.norm(u))
        a = sweep_amplitude(context.get_time(), *self._wave)
        output.SetFromVector(a * u / norm if norm > 0 else np.zeros_like(u))

"""GradientProjectionSystem: the desired null-space velocity of Eqs. 28–30."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from ..dynamics import RobotTerms
from ..gradient_projection import gradient_step, scale_to_speed_limits
from ..pseudo_inverse import GeneralizedInverse
from ._util import python_value_producer


class GradientProjectionSystem(LeafSystem):
    """q̇_dⁿ = N K H⁻¹ Φ (Eq. 30) or N K Φ (``rotate_gradient`` False), with
    N = I − J^# J for the same generalised inverse as the null-space
    controller, scaled so that no joint exceeds its speed limit.

    .. pydrake_system::

        name: GradientProjectionSystem
        input_ports:
        - robot_terms
        - gradient
        output_ports:
        - desired_null_space_velocity
        - speed_scale

    ``gradient`` is Φ (n); ``desired_null_space_velocity`` is q̇_dⁿ (n)
    [rad/s]; ``speed_scale`` (1) is the factor the speed limits applied (1 when
    none binds).
    """

    def __init__(
        self,
        *,
        inverse: GeneralizedInverse,
        gain: float,
        rotate_gradient: bool,
        speed_limits: np.ndarray,
        model_terms: RobotTerms,
    ):
        super().__init__()
        n = model_terms.n
        self._inverse = inverse
        self._gain = gain
        self._rotate = rotate_gradient
        self._limits = np.asarray(speed_limits, dtype=float)
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        self._gradient = self.DeclareVectorInputPort("gradient", n)
        deps = {self.input_port_ticket(p.get_index()) for p in (self._terms, self._gradient)}
        self._result = self.DeclareCacheEntry(
            description="scaled gradient step",
            value_producer=python_value_producer(self._compute),
            prerequisites_of_calc=deps,
        )
        self.DeclareVectorOutputPort(
            "desired_null_space_velocity",
            n,
            lambda c, o: o.SetFromVector(self._result.Eval(c)[0]),
            prerequisites_of_calc=deps,
        )
        self.DeclareVectorOutputPort(
            "speed_scale",
            1,
            lambda c, o: o.SetAtIndex(0, self._result.Eval(c)[1]),
            prerequisites_of_calc=deps,
        )

    def _compute(self, context):
        terms = self._terms.Eval(context)
        N = self._inverse.at(terms).N
        step = gradient_step(N, terms.H_inv, self._gradient.Eval(context), self._gain, self._rotate)
        return scale_to_speed_limits(step, self._limits)

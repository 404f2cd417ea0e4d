"""JointLimitsCriterionSystem: joint-limit avoidance as a criterion of the priority selector."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from ..criteria.joint_limits import activation, joint_limits_criterion
from ..dynamics import RobotTerms
from ._util import python_value_producer


class JointLimitsCriterionSystem(LeafSystem):
    """p = −⅓ Σ max(0, ρ − margin)³ over both limits of every joint, its gradient, the
    smallest margin and the level's activation (:mod:`nsdrake.criteria.joint_limits`).

    .. pydrake_system::

        name: JointLimitsCriterionSystem
        input_ports:
        - robot_terms
        output_ports:
        - value
        - gradient
        - margin
        - activation

    ``value`` (1) [rad³]; ``gradient`` (n) [rad²]; ``margin`` (1) [rad], the smallest
    distance of a joint to one of its limits (inf without limits); ``activation`` (1)
    ∈ [0, 1], the weight of this level in the priority stack.
    """

    def __init__(self, *, lower: np.ndarray, upper: np.ndarray, influence: float, model_terms: RobotTerms):
        super().__init__()
        self._lower = np.asarray(lower, dtype=float)
        self._upper = np.asarray(upper, dtype=float)
        self._influence = float(influence)
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        deps = {self.input_port_ticket(self._terms.get_index())}
        self._result = self.DeclareCacheEntry(
            description="joint-limit criterion",
            value_producer=python_value_producer(
                lambda c: joint_limits_criterion(
                    self._terms.Eval(c).q, self._lower, self._upper, self._influence
                )
            ),
            prerequisites_of_calc=deps,
        )
        self.DeclareVectorOutputPort(
            "value", 1, lambda c, o: o.SetAtIndex(0, self._result.Eval(c)[0]), prerequisites_of_calc=deps
        )
        self.DeclareVectorOutputPort(
            "gradient",
            model_terms.n,
            lambda c, o: o.SetFromVector(self._result.Eval(c)[1]),
            prerequisites_of_calc=deps,
        )
        self.DeclareVectorOutputPort(
            "margin", 1, lambda c, o: o.SetAtIndex(0, self._result.Eval(c)[2]), prerequisites_of_calc=deps
        )
        self.DeclareVectorOutputPort(
            "activation",
            1,
            lambda c, o: o.SetAtIndex(0, activation(self._result.Eval(c)[2], self._influence)),
            prerequisites_of_calc=deps,
        )

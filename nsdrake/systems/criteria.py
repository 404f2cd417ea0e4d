"""Criterion systems: each outputs a criterion value p and its gradient Φ = ∂p/∂q."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from ..criteria.joint_torque import joint_torque_criterion
from ..dynamics import RobotTerms
from ._util import python_value_producer


class JointTorqueCriterionSystem(LeafSystem):
    """p = ‖Jᵀ F_d‖² and Φ = ∂p/∂q (Eqs. 32–33) for a fixed desired force F_d.

    .. pydrake_system::

        name: JointTorqueCriterionSystem
        input_ports:
        - robot_terms
        output_ports:
        - value
        - gradient

    ``value`` (1) [N² m²]; ``gradient`` (n) [N² m²/rad].
    """

    def __init__(self, *, F_d: np.ndarray, model_terms: RobotTerms):
        super().__init__()
        self._F_d = np.asarray(F_d, dtype=float)
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        deps = {self.input_port_ticket(self._terms.get_index())}
        self._result = self.DeclareCacheEntry(
            description="joint-torque criterion",
            value_producer=python_value_producer(lambda c: joint_torque_criterion(*self._inputs(c))),
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

    def _inputs(self, context):
        terms = self._terms.Eval(context)
        return terms.J, terms.dJ_dq, self._F_d

"""RobotTermsSystem: evaluates the plant once per control period for every controller."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from ..dynamics import ArmModel
from ._util import declare_scratch_plant_context


class RobotTermsSystem(LeafSystem):
    """Publishes :class:`nsdrake.dynamics.RobotTerms` (H, H⁻¹, C q̇, g, J, ∂J/∂q, and C
    when asked) for the measured state, so the controllers downstream share one
    evaluation of the model. Also outputs the task position x = p(q) (Eq. 1).

    .. pydrake_system::

        name: RobotTermsSystem
        input_ports:
        - estimated_state
        output_ports:
        - robot_terms
        - task_position

    ``estimated_state`` is [q; q̇] (2n); ``robot_terms`` is an abstract
    RobotTerms; ``task_position`` is x (m) [m].

    The plant context this system writes q and q̇ into is scratch memory owned by
    each context (a cache entry with no prerequisites), never shared between
    contexts.
    """

    def __init__(self, *, arm_model: ArmModel, coriolis_matrix: bool):
        super().__init__()
        self._arm = arm_model
        self._coriolis = coriolis_matrix
        n = arm_model.n
        self._n = n
        plant = arm_model.plant
        self._state = self.DeclareVectorInputPort("estimated_state", 2 * n)
        self._scratch = declare_scratch_plant_context(self, plant)
        on_state = {self.input_port_ticket(self._state.get_index())}
        zero = np.zeros(n)
        plant_context = plant.CreateDefaultContext()
        model_value = arm_model.terms(plant_context, zero, zero, coriolis_matrix)
        self._terms = self.DeclareAbstractOutputPort(
            "robot_terms",
            alloc=lambda: AbstractValue.Make(model_value),
            calc=self._calc_terms,
            prerequisites_of_calc=on_state,
        )
        self.DeclareVectorOutputPort(
            "task_position", arm_model.m, self._calc_task_position, prerequisites_of_calc=on_state
        )

    def _calc_terms(self, context, output):
        state = self._state.Eval(context)
        plant_context = self._scratch.get_mutable_cache_entry_value(context).GetMutableValueOrThrow()
        n = self._n
        output.set_value(self._arm.terms(plant_context, state[:n], state[n:], self._coriolis))

    def _calc_task_position(self, context, output):
        output.SetFromVector(self._terms.Eval(context).x)

"""RobotTermsSystem: evaluates the plant once per control period for every controller."""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from nsdrake.control.model import ControllerModel
from nsdrake.control.systems._util import declare_scratch


class RobotTermsSystem(LeafSystem):
    """Publishes :class:`nsdrake.control.dynamics.RobotTerms` (H, H⁻¹, C q̇, g, J, ∂J/∂q, and C
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
    RobotTerms; ``task_position`` is x (m_t, the translational task axes) [m].

    The terms come from the controller's own model (:class:`nsdrake.ControllerModel`),
    never from the simulated plant; the model context it writes q and q̇ into is
    scratch memory owned by each context (a cache entry with no prerequisites),
    never shared between contexts.
    """

    def __init__(self, *, model: ControllerModel, coriolis_matrix: bool, max_task_inertia: float = math.inf):
        super().__init__()
        self._model = model
        self._coriolis = coriolis_matrix
        self._max_task_inertia = max_task_inertia
        n = model.n
        self._n = n
        self._state = self.DeclareVectorInputPort("estimated_state", 2 * n)
        self._scratch = declare_scratch(self, model.create_scratch)
        on_state = {self.input_port_ticket(self._state.get_index())}
        zero = np.zeros(n)
        model_value = model.terms(model.create_scratch(), zero, zero, coriolis_matrix)
        self._terms = self.DeclareAbstractOutputPort(
            "robot_terms",
            alloc=lambda: AbstractValue.Make(model_value),
            calc=self._calc_terms,
            prerequisites_of_calc=on_state,
        )
        self.DeclareVectorOutputPort(
            "task_position", model.arm.m_t, self._calc_task_position, prerequisites_of_calc=on_state
        )

    def _calc_terms(self, context, output):
        state = self._state.Eval(context)
        scratch = self._scratch.get_mutable_cache_entry_value(context).GetMutableValueOrThrow()
        n = self._n
        output.set_value(
            self._model.terms(scratch, state[:n], state[n:], self._coriolis, self._max_task_inertia)
        )

    def _calc_task_position(self, context, output):
        output.SetFromVector(self._terms.Eval(context).x)

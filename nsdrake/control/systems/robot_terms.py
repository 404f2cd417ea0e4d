"""RobotTermsSystem: stage 1, the model terms at the measured state, for every system downstream."""

from __future__ import annotations

from pydrake.common.value import AbstractValue

from nsdrake.control.leaf_system import LeafSystem
from nsdrake.control.plan import ControllerPlan
from nsdrake.control.systems._values import (
    ScratchValue,
    TermsValue,
    check_inputs,
    declare_value_cache,
    evaluated,
    scratch,
)


class RobotTermsSystem(LeafSystem):
    """Publishes the model terms (H, H⁻¹, C q̇, g, C, J, ∂J/∂q, J̇ q̇, ẋ, Λ, J^#, N; stage 1 of
    :mod:`nsdrake.control.stages`) for the measured state, so the systems downstream share
    one evaluation of the model. Also outputs the task position x = p(q) (Eq. 1).

    .. pydrake_system::

        name: RobotTermsSystem
        input_ports:
        - estimated_state
        output_ports:
        - robot_terms
        - task_position

    ``estimated_state`` is [q; q̇] (2n); ``robot_terms`` is a :class:`TermsValue` (its
    buffer read by :func:`nsdrake.control.layout.terms_views`); ``task_position`` is x
    (m_t, the translational task axes) [m].

    The terms come from the controller's own model, never from the simulated plant; the
    model scratch memory (a Pinocchio Data, a model context) is per context (a cache
    entry with no prerequisites), never shared between contexts. A state that is not
    finite raises :class:`nsdrake.control.validation.ControllerInputError` naming the entry.
    """

    def __init__(self, *, plan: ControllerPlan):
        super().__init__()
        self._plan = plan
        n = plan.n
        self._n = n
        self._state = self.DeclareVectorInputPort("estimated_state", 2 * n)
        self._scratch = declare_value_cache(self, "model scratch", lambda: ScratchValue(plan))
        on_state = {self.input_port_ticket(self._state.get_index())}
        self._terms = self.DeclareAbstractOutputPort(
            "robot_terms",
            alloc=lambda: AbstractValue.Make(TermsValue(plan.allocate_terms())),
            calc=self._calc_terms,
            prerequisites_of_calc=on_state,
        )
        self.DeclareVectorOutputPort(
            "task_position", plan.m_t, self._calc_task_position, prerequisites_of_calc=on_state
        )

    def _calc_terms(self, context, output):
        state = evaluated(self, context, self._state, "estimated_state")
        check_inputs(self, context, state, self._plan.input_names["estimated_state"])
        n = self._n
        self._plan.terms(
            scratch(self._scratch, context).scratch, state[:n], state[n:], output.get_mutable_value().buffer
        )

    def _calc_task_position(self, context, output):
        output.SetFromVector(self._plan.terms_field(self._terms.Eval(context).buffer, "x"))

"""PrioritySelector: stage 3, Fig. 1's switching priorities and the multi-level null-space velocity."""

from __future__ import annotations

from pydrake.systems.framework import BasicVector

from nsdrake.control.layout import CRITERIA
from nsdrake.control.plan import ControllerPlan
from nsdrake.control.priority import INITIAL_SWITCH_STATE
from nsdrake.control.stages import COMMIT, SELECTION
from nsdrake.control.systems._values import StageSystem


class PrioritySelector(StageSystem):
    """The desired null-space velocity q̇_dⁿ from the criteria, ordered by Fig. 1's
    decision tree and resolved level by level (:mod:`nsdrake.control.priority`): hysteresis
    on the limits, a smoothstep blend of q̇_dⁿ over ``blend_time`` after each switch,
    and scaling so that no joint exceeds its speed limit.

    .. pydrake_system::

        name: PrioritySelector
        input_ports:
        - robot_terms
        - criteria
        output_ports:
        - selection

    ``criteria`` is the :class:`CriteriaSystem`'s packed port: the tree compares the
    obstacle's switching quantity (d_min [m]) with d_lim, the joint limits' (the smallest
    margin [rad]) with q_lim and the manipulability w with w_lim; the obstacle and
    joint-limit levels are weighted by their activation. ``selection`` is [q̇_dⁿ (n)
    [rad/s]; mode; speed_scale]: mode 0 (no criterion), 1 (obstacle avoidance on level
    2), 2 (joint torque), 3 (manipulability) or 4 (joint limits), and the factor the
    joint-speed limits put on q̇_dⁿ.

    The discrete state is the switch state [mode, mode blended from, switch time],
    committed every period in a discrete update, so from the state the plant has just
    stepped to (:mod:`nsdrake.control.stages` on the event order); the output evaluates
    the tree again on the committed state at its own time.

    The commanded joint speed, task part J^# J q̇ plus q̇_dⁿ, is kept within
    (1 − ``speed_headroom``) of each joint's limit: the measured speed is the command
    minus the null-space error eⁿ, and the headroom absorbs that error.
    """

    def __init__(self, *, plan: ControllerPlan):
        super().__init__(plan)
        n = plan.n
        self._shape = (CRITERIA, n + 3)
        self._criteria = self.DeclareVectorInputPort("criteria", CRITERIA * (n + 3))
        self._state = self.DeclareDiscreteState(BasicVector(list(INITIAL_SWITCH_STATE)))
        self.DeclarePeriodicDiscreteUpdateEvent(plan.config.period, 0.0, self._update)
        deps = {self.input_port_ticket(p.get_index()) for p in (self._terms, self._criteria)}
        deps |= {self.discrete_state_ticket(self._state), self.time_ticket()}
        self.DeclareVectorOutputPort("selection", n + 2, self._calc, prerequisites_of_calc=deps)

    def output_parts(self) -> dict[str, int]:
        """The parts of the ``selection`` port and their sizes, in order."""
        return {"desired_null_space_velocity": self._n, "mode": 1, "speed_scale": 1}

    def _calc(self, context, output):
        b = self.buffers(context)
        b.criteria[:] = self._criteria.Eval(context).reshape(self._shape)
        b.switch[:] = context.get_discrete_state(self._state).get_value()
        self.run(context, SELECTION, b)
        output.SetFromVector(b.part("selection"))

    def _update(self, context, discrete_state):
        b = self.buffers(context)
        b.criteria[:] = self._criteria.Eval(context).reshape(self._shape)
        b.switch[:] = context.get_discrete_state(self._state).get_value()
        self.run(context, COMMIT, b, t_previous=context.get_time())
        discrete_state.get_mutable_vector(self._state).SetFromVector(b.switch)

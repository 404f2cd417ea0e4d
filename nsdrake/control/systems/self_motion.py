"""SelfMotionSweep: stage 3 with a prescribed desired null-space velocity, for experiments."""

from __future__ import annotations

from nsdrake.control.plan import ControllerPlan
from nsdrake.control.stages import SWEEP
from nsdrake.control.systems._values import StageSystem


class SelfMotionSweep(StageSystem):
    """q̇_dⁿ = a(t) N d / ‖N d‖: the arm swept through its self-motion along the
    projection of a fixed joint-space direction d, at the commanded speed a(t)
    (:mod:`nsdrake.control.self_motion`). N is the projector of the same generalised
    inverse as the null-space controller.

    .. pydrake_system::

        name: SelfMotionSweep
        input_ports:
        - robot_terms
        output_ports:
        - desired_null_space_velocity

    ``desired_null_space_velocity`` is q̇_dⁿ (n) [rad/s].
    """

    def __init__(self, *, plan: ControllerPlan):
        super().__init__(plan)
        self.DeclareVectorOutputPort(
            "desired_null_space_velocity",
            plan.n,
            self._calc,
            prerequisites_of_calc={self.input_port_ticket(self._terms.get_index()), self.time_ticket()},
        )

    def _calc(self, context, output):
        b = self.buffers(context)
        self.run(context, SWEEP, b)
        output.SetFromVector(b.part("qdot"))

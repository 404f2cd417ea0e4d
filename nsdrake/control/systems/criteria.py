"""CriteriaSystem: stage 2, every criterion's gradient, value, switching quantity and activation.

Every criterion of Section 3.5 gives the priority selector the same four things: its
gradient Φ = ∂p/∂q (Eq. 29), its value p, the quantity s that Fig. 1's tree compares
with the criterion's limit, and the activation a ∈ [0, 1] that weighs its level in the
projection of the levels below (:mod:`nsdrake.control.priority`). One system computes
them all (one Python evaluation per control tick) into one packed port; the controller
splits it with Drake's (C++) ``Demultiplexer`` for its diagnostic ports (``d_min``,
``manipulability``, …).
"""

from __future__ import annotations

import numpy as np

from nsdrake.control.layout import CRITERIA
from nsdrake.control.plan import ControllerPlan
from nsdrake.control.priority import Criterion
from nsdrake.control.stages import CRITERIA as STAGE
from nsdrake.control.systems._values import StageSystem

CRITERION_LAYOUT = ("gradient", "value", "switching", "activation")  # [Φ (n); p; s; a]


def criterion_parts(n: int) -> dict[str, int]:
    """The parts of one criterion's row for n joints and their sizes, in order."""
    return dict(zip(CRITERION_LAYOUT, (n, 1, 1, 1), strict=True))


def criteria_parts(n: int) -> dict[str, int]:
    """The parts of the ``criteria`` port, ``<criterion>_<part>``, in order (Criterion's)."""
    return {f"{c.value}_{part}": size for c in Criterion for part, size in criterion_parts(n).items()}


def unpack_criterion(packed: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """(Φ, p, s, a) from one criterion's row."""
    return packed[:-3], float(packed[-3]), float(packed[-2]), float(packed[-1])


class CriteriaSystem(StageSystem):
    """The criteria of Section 3.5 and joint limits at the measured state (stage 2 of
    :mod:`nsdrake.control.stages`): obstacle avoidance (Eq. 31) from the controller model's
    own geometry (the arm's links and the obstacles it knows about), joint torque due to
    the desired force (Eqs. 32–33), manipulability w = √det(J Jᵀ), and joint-limit
    avoidance (:mod:`nsdrake.control.criteria`).

    .. pydrake_system::

        name: CriteriaSystem
        input_ports:
        - robot_terms
        output_ports:
        - criteria

    ``criteria`` is four rows [Φ (n); p; s; a], one per criterion in the order obstacle,
    joint_torque, manipulability, joint_limits (:func:`criteria_parts`):

    - obstacle: Φ [m³/rad], p [m³], s = d_min the smallest link–obstacle distance [m]
      (compared with d_lim; ∞ without geometry), a ∈ [0, 1] (:func:`nsdrake.control.smoothing.activation`);
    - joint_torque: p = ‖Jᵀ F_d‖² [N² m²] with F_d = ``nominal_force`` n, s = p, a = 1;
    - manipulability: w, s = w (compared with w_lim), a = 1;
    - joint_limits: p [rad³], s = the smallest distance of a joint to a limit [rad]
      (compared with q_lim; ∞ without limits), a ∈ [0, 1].
    """

    def __init__(self, *, plan: ControllerPlan):
        super().__init__(plan)
        self._shape = (CRITERIA, plan.n + 3)
        self.DeclareVectorOutputPort(
            "criteria",
            CRITERIA * (plan.n + 3),
            self._calc,
            prerequisites_of_calc={self.input_port_ticket(self._terms.get_index())},
        )

    def output_parts(self) -> dict[str, int]:
        return criteria_parts(self._plan.n)

    def _calc(self, context, output):
        b = self.buffers(context)
        self.run(context, STAGE, b)
        output.SetFromVector(b.criteria.ravel())

"""Fig. 1's decision tree exactly at its limits (nsdrake.control.priority.select_mode and the
PrioritySelector system): which mode at d_min = d_lim, w = w_lim, joint-limit margin = q_lim
and at the ends of their hysteresis bands, entering from below and leaving from inside.

The tree enters a mode strictly below its limit (d_min < d_lim: obstacle avoidance; margin <
q_lim: joint limits; w < w_lim: manipulability) and leaves it only at or beyond limit + band;
at the limit itself, a mode not already active is not entered, and an active one is kept.
Each case is also checked one floating-point step below the boundary, where the answer
flips, so that a < written as <= (or the reverse) fails.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import paper_arm
from pydrake.common.value import AbstractValue

from nsdrake.control.config import ControllerConfig
from nsdrake.control.model import ControllerModel
from nsdrake.control.plan import ControllerPlan
from nsdrake.control.priority import Criterion, Mode, SelectorLimits, select_mode
from nsdrake.control.stages import pack_criterion
from nsdrake.control.systems import PrioritySelector
from nsdrake.control.systems._values import TermsValue

LIMITS = SelectorLimits(d_lim=0.05, w_lim=0.1, d_band=0.01, w_band=0.02, q_lim=0.2, q_band=0.05)
CLEAR = {"d_min": 1.0, "w": 1.0, "margin": 1.0}  # far from every limit: joint torque (mode 2)
T, O, M, L = Mode.joint_torque, Mode.obstacle_avoidance, Mode.manipulability, Mode.joint_limits


def below(x: float) -> float:
    return float(np.nextafter(x, -np.inf))


# (criterion, value at which it is judged, previous mode, expected mode); ``below`` the same
# value one step down. Boundaries are written as the tree computes them (limit + band).
CASES = [
    # obstacle avoidance: entered strictly below d_lim, kept strictly below d_lim + d_band
    ("d_min", LIMITS.d_lim, T, T),
    ("d_min", below(LIMITS.d_lim), T, O),
    ("d_min", LIMITS.d_lim, O, O),
    ("d_min", LIMITS.d_lim + LIMITS.d_band, O, T),
    ("d_min", below(LIMITS.d_lim + LIMITS.d_band), O, O),
    ("d_min", below(LIMITS.d_lim + LIMITS.d_band), T, T),  # inside the band, not entered
    # joint-limit avoidance: the same with the margin, q_lim and q_band
    ("margin", LIMITS.q_lim, T, T),
    ("margin", below(LIMITS.q_lim), T, L),
    ("margin", LIMITS.q_lim, L, L),
    ("margin", LIMITS.q_lim + LIMITS.q_band, L, T),
    ("margin", below(LIMITS.q_lim + LIMITS.q_band), L, L),
    ("margin", below(LIMITS.q_lim + LIMITS.q_band), T, T),
    # manipulability: on level 2 strictly below w_lim, kept strictly below w_lim + w_band
    ("w", LIMITS.w_lim, T, T),
    ("w", below(LIMITS.w_lim), T, M),
    ("w", LIMITS.w_lim, M, M),
    ("w", LIMITS.w_lim + LIMITS.w_band, M, T),
    ("w", below(LIMITS.w_lim + LIMITS.w_band), M, M),
    ("w", below(LIMITS.w_lim + LIMITS.w_band), T, T),
]
IDS = [f"{c}={v!r} from {p.name}" for c, v, p, _ in CASES]


@pytest.mark.parametrize(("criterion", "value", "previous", "expected"), CASES, ids=IDS)
def test_the_tree_at_its_limits(criterion, value, previous, expected):
    judged = {**CLEAR, criterion: value}
    assert select_mode(judged["d_min"], judged["w"], previous, LIMITS, judged["margin"]) == expected


def test_at_both_limits_at_once_the_obstacle_comes_first():
    """d_min and the margin both a step below their limits: obstacle avoidance; the margin
    alone: joint limits, whatever w."""
    assert select_mode(below(LIMITS.d_lim), below(LIMITS.w_lim), T, LIMITS, below(LIMITS.q_lim)) == O
    assert select_mode(LIMITS.d_lim, below(LIMITS.w_lim), T, LIMITS, below(LIMITS.q_lim)) == L


@pytest.fixture(scope="module")
def selector():
    """A PrioritySelector on the paper's arm with every criterion's gain non-zero and
    :data:`LIMITS` as its selector settings, and a context whose criterion input and stored
    mode a case sets."""
    arm = paper_arm()
    config = ControllerConfig()
    d = config.desired_null_space
    d.criteria.obstacle.gain = 1.0
    d.criteria.joint_torque.gain = -1.0
    d.criteria.manipulability.gain = 1.0
    d.criteria.joint_limits.gain = 1.0
    for name in ("d_lim", "w_lim", "d_band", "w_band", "q_lim", "q_band"):
        setattr(d.selector, name, getattr(LIMITS, name))
    d.selector.blend_time = 0.2
    model = ControllerModel.from_plant(arm.plant, tool_frame="tool", task_axes=("x", "y"))
    plan = ControllerPlan(model=model, config=config, normal=np.array([0.0, 1.0]), wrench_point=None)
    terms = plan.allocate_terms()
    plan.terms(plan.create_scratch(), np.array([0.4, 0.9, 1.0, 0.6]), np.zeros(4), terms)
    system = PrioritySelector(plan=plan)
    context = system.CreateDefaultContext()
    system.GetInputPort("robot_terms").FixValue(context, AbstractValue.Make(TermsValue(terms)))
    return system, context


@pytest.mark.parametrize(("criterion", "value", "previous", "expected"), CASES, ids=IDS)
def test_the_selector_system_reads_each_criterion_against_its_own_limit(
    selector, criterion, value, previous, expected
):
    """The same table through the system, its criteria on their packed ports [Φ; p; s; a]:
    catches a switching quantity read from the wrong criterion's port, or the stored mode
    not used for the hysteresis."""
    system, context = selector
    judged = {**CLEAR, criterion: value}
    switching = {
        Criterion.obstacle: judged["d_min"],
        Criterion.manipulability: judged["w"],
        Criterion.joint_limits: judged["margin"],
        Criterion.joint_torque: 0.0,
    }
    criteria = np.zeros((len(Criterion), 4 + 3))
    for c, s in switching.items():
        pack_criterion(criteria[list(Criterion).index(c)], np.ones(4), 0.0, s, 1.0)
    system.GetInputPort("criteria").FixValue(context, criteria.ravel())
    context.SetTime(1.0)
    context.get_mutable_discrete_state(0).SetFromVector([float(previous), float(previous), -np.inf])
    assert system.GetOutputPort("selection").Eval(context)[4] == float(expected)

"""Joint-limit avoidance (nsdrake/criteria/joint_limits.py) and its place in Fig. 1's tree.

Tolerances: the criterion is a sum of cubes, its gradient exact to rounding; central
differences with h = 1e-6 have truncation O(h²)·|p'''| ≈ 1e-12 and rounding O(ε/h)
≈ 1e-10 relative to |p| ≤ ρ³, so 1e-7 relative to the largest gradient entry.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import PANDA_Q0, panda_arm, panda_configurations

from nsdrake import ControllerConfig, ControllerModel, NullSpaceImpedanceController
from nsdrake.control.criteria.joint_limits import joint_limits_criterion
from nsdrake.control.priority import ORDERINGS, Criterion, Mode, SelectorLimits, select_mode
from nsdrake.control.smoothing import activation
from nsdrake.station.models import models_dir

FD = 1e-7
RHO = 0.3


@pytest.fixture(scope="module")
def limits():
    plant = panda_arm().plant
    return plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()


def near_limit_configurations(limits, count, seed):
    """q with one to three joints inside the influence zone of a limit (either side)."""
    lower, upper = limits
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        q = rng.uniform(lower + RHO, upper - RHO)
        for i in rng.choice(7, rng.integers(1, 4), replace=False):
            depth = rng.uniform(0.0, RHO)
            q[i] = lower[i] + depth if rng.random() < 0.5 else upper[i] - depth
        out.append(q)
    return out


def test_gradient_matches_central_differences_on_the_panda(limits):
    """Φ against central differences on 100 random Panda poses, 60 with joints inside the
    influence zone and 10 near a singular pose (1e-7 relative). Catches a gradient with the
    wrong sign on the upper limit, a square where the cube belongs, or a joint's two
    limits mixed up."""
    lower, upper = limits
    h = 1e-6
    states = panda_configurations(100, seed=11, near_singular=10) + near_limit_configurations(limits, 60, 12)
    active = 0
    for q in states:
        p, Phi, _ = joint_limits_criterion(q, lower, upper, RHO)
        fd = np.array(
            [
                (
                    joint_limits_criterion(q + h * e, lower, upper, RHO)[0]
                    - joint_limits_criterion(q - h * e, lower, upper, RHO)[0]
                )
                / (2 * h)
                for e in np.eye(7)
            ]
        )
        scale = max(float(np.max(np.abs(Phi))), 1e-12)
        assert np.max(np.abs(Phi - fd)) <= FD * max(scale, RHO**2)
        active += p < 0
    assert active >= 60  # the near-limit states do exercise the criterion


def test_zero_far_from_the_limits_and_pushes_back_inside(limits):
    """p = 0 and Φ = 0 while every joint is more than ρ inside its range (the table-wiping
    start is); inside the zone p < 0 and a step along +Φ raises the joint's margin. A joint
    without limits (±inf) never counts. Catches a criterion that acts everywhere (it would
    fight the other criteria far from any limit) or pushes toward the limit."""
    lower, upper = limits
    p, Phi, margin = joint_limits_criterion(PANDA_Q0, lower, upper, RHO)
    assert p == 0.0 and not Phi.any() and margin > RHO
    for i, (q_i, sign) in enumerate([(lower[0] + 0.1, +1), (upper[3] - 0.05, -1)]):
        j = (0, 3)[i]
        q = PANDA_Q0.copy()
        q[j] = q_i
        p, Phi, margin = joint_limits_criterion(q, lower, upper, RHO)
        assert p < 0 and np.sign(Phi[j]) == sign and np.count_nonzero(Phi) == 1
        assert margin == pytest.approx(min(q[j] - lower[j], upper[j] - q[j]))
    p, Phi, margin = joint_limits_criterion(np.array([100.0]), np.array([-np.inf]), np.array([np.inf]), RHO)
    assert p == 0.0 and not Phi.any() and margin == np.inf


def test_smooth_where_a_joint_enters_the_zone(limits):
    """Φ and its slope are continuous at margin = ρ (C¹ gradient: the cube), so q̈_dⁿ's
    feed-forward sees no step. Catches a square potential (Φ would kink there)."""
    lower, upper = limits
    q = PANDA_Q0.copy()
    for eps in (1e-4, 1e-6):
        values = []
        for margin in (RHO + eps, RHO, RHO - eps):
            q[0] = lower[0] + margin
            values.append(joint_limits_criterion(q, lower, upper, RHO)[1][0])
        assert max(abs(v) for v in values) <= 2 * eps**2  # Φ ≈ (ρ − δ)², its slope 2(ρ − δ) → 0


def test_activation_fades_in_inside_the_zone():
    """The level's weight: 0 beyond ρ, 1 within ρ/2, the smoothstep between. Catches a level
    that takes its direction from the levels below at once as a joint enters the zone
    (a step in q̇_dⁿ), or one that never takes it."""
    assert activation(RHO, RHO) == 0.0 and activation(2 * RHO, RHO) == 0.0
    assert activation(0.75 * RHO, RHO) == pytest.approx(0.5)
    assert activation(0.5 * RHO, RHO) == 1.0 and activation(0.0, RHO) == 1.0


def test_fig1_tree_puts_joint_limits_after_the_obstacle_with_hysteresis():
    """Mode 4 when a joint is within q_lim and no link is within d_lim; the obstacle wins
    over it; it stays until the margin exceeds q_lim + q_band; with q_lim = 0 the paper's
    three branches are unchanged. In every ordering the joint-limit level comes right
    after the obstacle level. Catches the branch placed after the optimisation criteria,
    missing hysteresis, or a q_lim = 0 default that changes fig3's tree."""
    limits = SelectorLimits(d_lim=0.05, w_lim=0.01, d_band=0.01, w_band=0.005, q_lim=0.2, q_band=0.05)
    assert select_mode(0.1, 0.1, Mode.joint_torque, limits, margin=0.1) == Mode.joint_limits
    assert select_mode(0.04, 0.1, Mode.joint_torque, limits, margin=0.1) == Mode.obstacle_avoidance
    assert select_mode(0.1, 0.1, Mode.joint_limits, limits, margin=0.22) == Mode.joint_limits
    assert select_mode(0.1, 0.1, Mode.joint_limits, limits, margin=0.26) == Mode.joint_torque
    assert select_mode(0.1, 0.001, Mode.joint_torque, limits, margin=0.1) == Mode.joint_limits
    paper = SelectorLimits(d_lim=0.05, w_lim=0.01, d_band=0.01, w_band=0.005)
    for d, w, previous in (
        (0.1, 0.1, Mode.joint_torque),
        (0.1, 0.001, Mode.joint_torque),
        (0.01, 0.1, Mode.none),
    ):
        assert select_mode(d, w, previous, paper, margin=0.01) == select_mode(d, w, previous, paper)
    for mode, order in ORDERINGS.items():
        if mode in (Mode.none,):
            continue
        assert set(order) == set(Criterion)
        safety = [c for c in order if c in (Criterion.obstacle, Criterion.joint_limits)]
        if mode in (Mode.obstacle_avoidance, Mode.joint_limits):
            assert order[:2] == tuple(safety)
        else:
            assert order.index(Criterion.joint_limits) == order.index(Criterion.obstacle) + 1


def test_controller_reads_the_limits_from_its_model():
    """The controller's joint-limit criterion uses the URDF's limits (Drake's
    PositionLower/UpperLimits) and its margin output is the smallest distance to them; the
    joint-speed limits default to the model's velocity limits (2.175 / 2.61 rad/s).
    Catches limits typed into the code, or taken from the wrong joints."""
    from nsdrake.control.controller import speed_limits

    config = ControllerConfig()
    config.desired_null_space.criteria.joint_limits.gain = 1.0
    model = ControllerModel.from_urdf(
        models_dir() / "panda.urdf", tool_frame="tool", task_axes=("x", "y", "z")
    )
    controller = NullSpaceImpedanceController(controller_model=model, normal=[0, 0, -1.0], config=config)
    context = controller.CreateDefaultContext()
    q = PANDA_Q0.copy()
    q[3] = -3.0  # 0.0718 rad above joint 4's lower limit −3.0718
    controller.GetInputPort("estimated_state").FixValue(context, np.concatenate([q, np.zeros(7)]))
    assert controller.GetOutputPort("joint_limit_margin").Eval(context)[0] == pytest.approx(0.0718, abs=1e-12)
    assert controller.GetOutputPort("joint_limits_criterion").Eval(context)[0] < 0
    assert speed_limits(config, model) == pytest.approx([2.175] * 4 + [2.61] * 3)

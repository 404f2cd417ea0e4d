"""Fig. 1's decision tree, the multi-level null-space velocity and its continuity,
and the priority_demo run in closed loop."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import terms_at
from models import random_states

from nsdrake.control.priority import (
    Level,
    Mode,
    SelectorLimits,
    SwitchState,
    blend_weight,
    prioritized_velocity,
    select_mode,
    update_switch_state,
)
from nsdrake.control.pseudo_inverse import GeneralizedInverse

LIMITS = SelectorLimits(d_lim=0.05, w_lim=0.1, d_band=0.01, w_band=0.02)
DC = GeneralizedInverse()


@pytest.mark.parametrize(
    ("d_min", "w", "previous", "expected"),
    [
        (0.04, 0.5, Mode.joint_torque, Mode.obstacle_avoidance),  # a link too close: obstacle first
        (0.04, 0.01, Mode.manipulability, Mode.obstacle_avoidance),  # … even near a singular pose
        (0.2, 0.5, Mode.none, Mode.joint_torque),  # clear and well-conditioned: joint torque
        (0.2, 0.05, Mode.joint_torque, Mode.manipulability),  # clear but nearly singular
        (0.055, 0.5, Mode.obstacle_avoidance, Mode.obstacle_avoidance),  # hysteresis: stays …
        (0.061, 0.5, Mode.obstacle_avoidance, Mode.joint_torque),  # … until d_lim + d_band
        (0.055, 0.5, Mode.joint_torque, Mode.joint_torque),  # entering needs d < d_lim
        (0.2, 0.11, Mode.manipulability, Mode.manipulability),  # hysteresis on w
        (0.2, 0.121, Mode.manipulability, Mode.joint_torque),
        (0.2, 0.11, Mode.joint_torque, Mode.joint_torque),
    ],
)
def test_decision_tree(d_min, w, previous, expected):
    assert select_mode(d_min, w, previous, LIMITS) == expected


def test_selection_is_idempotent():
    """Re-selecting with the same inputs and the mode just chosen gives that mode again,
    so evaluating the selector twice at one instant cannot make it flicker."""
    rng = np.random.default_rng(3)
    for _ in range(500):
        d, w, prev = rng.uniform(0, 0.1), rng.uniform(0, 0.2), Mode(int(rng.integers(0, 4)))
        m = select_mode(d, w, prev, LIMITS)
        assert select_mode(d, w, m, LIMITS) == m


def test_blend_is_continuous_and_ends():
    state = update_switch_state(
        SwitchState(Mode.joint_torque, Mode.joint_torque, -np.inf), 1.0, Mode.obstacle_avoidance
    )
    assert state == SwitchState(Mode.obstacle_avoidance, Mode.joint_torque, 1.0)
    ts = np.linspace(1.0, 1.3, 301)
    sigma = np.array([blend_weight(state, t, 0.2) for t in ts])
    assert sigma[0] == 0.0 and sigma[-1] == 1.0 and np.all(np.diff(sigma) >= 0)
    assert np.max(np.abs(np.diff(sigma))) < 1.6 * (ts[1] - ts[0]) / 0.2  # smoothstep slope ≤ 1.5 / T


def levels_at(T, rng, gains=(1.0, -1.0, 0.5)):
    return [Level(rng.standard_normal(T.n), k) for k in gains]


def test_each_level_leaves_the_task_and_the_levels_above_alone(arm):
    """Exact hierarchy (no damping): J q̇ = 0, and level k's contribution has no first-order
    effect on any criterion above it; each level still improves its own criterion."""
    if arm.n - arm.m < 2:
        pytest.skip("needs two redundant degrees of freedom")
    rng = np.random.default_rng(61)
    for q, v in random_states(arm.n, 30, seed=61):
        T = terms_at(arm, q, v, coriolis=False)
        inv = DC.at(T)
        levels = levels_at(T, rng)[: arm.n - arm.m]
        qdot = prioritized_velocity(inv.N, T.H, T.H_inv, levels, rank_damping=0.0)
        assert np.max(np.abs(T.J @ qdot)) < 1e-9 * max(1.0, np.max(np.abs(qdot)))
        for k in range(1, len(levels)):
            above = prioritized_velocity(inv.N, T.H, T.H_inv, levels[:k], rank_damping=0.0)
            lower = qdot - above
            for j in range(k):
                assert abs(levels[j].gradient @ lower) < 1e-9 * max(1.0, np.linalg.norm(lower))
            own = prioritized_velocity(inv.N, T.H, T.H_inv, levels[: k + 1], rank_damping=0.0) - above
            assert levels[k].gain * (levels[k].gradient @ own) >= -1e-12


def test_damping_keeps_q_dot_continuous_through_an_algorithmic_singularity(arm4):
    """Level 3's gradient swept through the one direction left free by levels 1 and 2:
    without damping, level 4 gains that direction at once and q̇ jumps; with it, q̇
    changes at the rate the inputs do."""
    rng = np.random.default_rng(62)
    q, v = next(random_states(4, 1, seed=62))
    T = terms_at(arm4, q, v, coriolis=False)
    inv = DC.at(T)
    top = rng.standard_normal(4)
    # The direction still free after J and top: u with J u = 0, topᵀ u = 0 (in the H metric).
    N2 = inv.N - np.outer(inv.N @ T.H_inv @ top, (inv.N @ T.H_inv @ top) @ T.H) / (
        top @ inv.N @ T.H_inv @ top
    )
    free = np.linalg.svd(N2)[0][:, 0]
    base = rng.standard_normal(4)
    base -= (base @ free) * free / (free @ free)  # a gradient orthogonal to the free direction
    last = rng.standard_normal(4)

    def sweep(damping):
        out = []
        for a in np.linspace(-1e-3, 1e-3, 201):
            levels = [Level(top, 1.0), Level(base + a * T.H @ free, 1.0), Level(last, 1.0)]
            out.append(prioritized_velocity(inv.N, T.H, T.H_inv, levels, rank_damping=damping))
        return np.array(out)

    step = lambda x: np.max(np.linalg.norm(np.diff(x, axis=0), axis=1))  # noqa: E731
    assert step(sweep(0.0)) > 100 * step(sweep(1e-2))


def test_an_inactive_level_fades_out_of_the_projection(arm4):
    """With activation → 0 the obstacle level stops taking a direction from the levels
    below: the result tends to the stack without that level (its own step is
    switched off here, gain 0, to isolate the projection)."""
    rng = np.random.default_rng(63)
    q, v = next(random_states(4, 1, seed=63))
    T = terms_at(arm4, q, v, coriolis=False)
    inv = DC.at(T)
    torque, obstacle, manip = (rng.standard_normal(4) for _ in range(3))
    without = prioritized_velocity(inv.N, T.H, T.H_inv, [Level(torque, -1.0), Level(manip, 1.0)])
    gaps = []
    for a in (1.0, 0.5, 0.1, 1e-3, 0.0):
        levels = [Level(torque, -1.0), Level(1e-9 * obstacle, 0.0, activation=a), Level(manip, 1.0)]
        gaps.append(np.linalg.norm(prioritized_velocity(inv.N, T.H, T.H_inv, levels) - without))
    assert gaps[0] > 1e-3 and gaps[-1] < 1e-8 and all(np.diff(gaps) <= 1e-12)


@pytest.mark.slow
def test_priority_demo_closed_loop(tmp_path):
    """The shipped priority_demo: modes 1, 2 and 3 visited, each mode's criterion improving
    while it is active, no torque step at a switch beyond 2 × the 99th percentile
    elsewhere, no joint over its speed limit (all from metrics.json's figures)."""
    from nsdrake.experiment.scenario import load_scenario
    from nsdrake.reporting.run_folder import run_to_folder

    result = run_to_folder(load_scenario("priority_demo"), tmp_path)
    by_name = {m.name: m for m in result.metrics}
    for name in (
        "modes_visited",
        "mode1_d_min_change_min",
        "mode2_p_tau_change_min",
        "mode3_w_change_min",
        "torque_step_at_switch_max",
        "joint_speed_ratio_max",
    ):
        assert by_name[name].passed, f"{name} = {by_name[name].value} (bound {by_name[name].bound})"
    assert (tmp_path / "priority.png").is_file()

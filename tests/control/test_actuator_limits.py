"""Actuator limits with the primary task first (nsdrake/actuator_limits.py)."""

from __future__ import annotations

import numpy as np
import pytest

from nsdrake.control.actuator_limits import limit_torque, torque_window

INF = np.full(3, np.inf)


def test_nothing_binds_the_sum_is_exact():
    """With room to spare, τ = τ_task + τ₀ bit for bit and s = 1."""
    a, b = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.1, -0.2])
    tau, s, clipped = limit_torque(a, b, -INF, INF)
    assert s == 1.0 and clipped == 0
    assert np.array_equal(tau, a + b)


def test_null_space_torque_gives_way_first():
    """A limit that only τ₀ would break scales τ₀ down (the whole vector, keeping its
    direction, so J H⁻¹ τ₀ = 0 still holds) and leaves τ_task untouched; the binding
    joint ends exactly at its limit. Clipping the sum instead fails."""
    a, b = np.array([1.0, -2.0, 0.5]), np.array([2.0, 0.4, -0.2])
    limit = np.array([2.0, 3.0, 3.0])
    tau, s, clipped = limit_torque(a, b, -limit, limit)
    assert clipped == 0
    assert s == pytest.approx(0.5, abs=1e-15)
    assert np.allclose(tau - a, s * b, rtol=0, atol=1e-15)
    assert tau[0] == pytest.approx(2.0, abs=1e-15)


def test_task_torque_outside_its_window_is_clipped_and_counted():
    """Only when τ_task alone leaves a joint's window: s = 0 and that joint is clipped."""
    a, b = np.array([5.0, -1.0, 0.5]), np.array([0.1, 0.1, 0.1])
    limit = np.array([2.0, 3.0, 3.0])
    tau, s, clipped = limit_torque(a, b, -limit, limit)
    assert s == 0.0 and clipped == 1
    assert np.array_equal(tau, [2.0, -1.0, 0.5])


def test_rate_window_narrows_around_the_previous_torque():
    """The window is ±τ_max ∩ τ_prev ± ρ T, and no rate limit before a previous torque."""
    lower, upper = torque_window(np.array([10.0]), np.array([100.0]), 0.002, np.array([9.9]), True)
    assert lower[0] == pytest.approx(9.7) and upper[0] == 10.0
    lower, upper = torque_window(np.array([10.0]), np.array([100.0]), 0.002, np.array([9.9]), False)
    assert lower[0] == -10.0 and upper[0] == 10.0


def test_closed_loop_limits_hold_and_saturation_is_traced(tmp_path):
    """fig3 with torque and torque-rate limits below what it would use (unlimited: 4.7 N m
    and 860 N m/s at contact): every logged τ within ±τ_max, every change within
    ρ_max T (to rounding), the saturation columns show the limits acting, and the
    tool still presses 10 N on the plate."""
    from conftest import fig3_with

    from nsdrake.experiment.simulate import run

    scenario = fig3_with(
        tmp_path,
        "actuator_limits:\n"
        "  torque: {joint1: 4.0, joint2: 4.0, joint3: 4.0, joint4: 4.0}\n"
        "  torque_rate: {joint1: 300.0, joint2: 300.0, joint3: 300.0, joint4: 300.0}\n",
        duration=2.0,
    )
    traces, _ = run(scenario)
    tau = traces.block("tau")
    assert np.max(np.abs(tau)) <= 4.0 + 1e-12
    assert np.max(np.abs(np.diff(tau, axis=0))) <= 300.0 * scenario.control_period * (1 + 1e-9)
    assert np.min(traces["tau0_scale"]) < 1.0  # the limits did bind
    assert traces["f_n"][-1] == pytest.approx(10.0, rel=0.02)  # and the tool still presses

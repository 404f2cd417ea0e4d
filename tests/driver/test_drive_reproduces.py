"""panda_wipe through the controller side and the simulated driver, in one process over
memq://, against the direct simulation (issue 17: "Driving it must reproduce the direct
simulation"), and the gravity setting in both directions."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from drake import lcmt_panda_status
from fake_bus import FakeBus

from nsdrake.driver.controller_side import build_controller_side
from nsdrake.driver.loop import ControllerLoop
from nsdrake.driver.run import drive_traces, prepare, run_simulated
from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.simulate import run
from nsdrake.reporting.run_folder import compute_metrics

COMPARED = ("force_error_rms", "position_error_rms", "orientation_error_rms", "d_post_min")


def with_driver(scenario, **fields):
    return dataclasses.replace(scenario, driver=dataclasses.replace(scenario.driver, **fields))


def assert_same_traces(direct, driven, rtol: float):
    """Every column of the direct run's traces, in the driven run's, to ``rtol`` of the
    largest magnitude of its vector (the columns name1…nameN of one vector share it: a
    vector's round-off is relative to the whole vector, and a component that stays near 0,
    as e^n on joint 4 at 3e-8 rad/s through the gentle first contact, keeps the whole one's;
    a column alone: its own). Driven traces have more columns: f_*_measured, cmd*."""
    assert len(direct) == len(driven)
    for name in direct.names:
        a, b = direct[name], driven[name]
        prefix = re.fullmatch(r"(.*?\D)\d+", name)
        vector = [n for n in direct.names if prefix and re.fullmatch(re.escape(prefix[1]) + r"\d+", n)]
        scale = max([float(np.max(np.abs(direct[n]))) for n in vector or [name]] + [1e-12])
        assert np.max(np.abs(a - b)) <= rtol * scale, (name, float(np.max(np.abs(a - b))), scale)


def test_a_short_drive_reproduces_the_direct_simulation():
    """Through the approach, first contact (1.44 s) and the force ramp, every column (τ,
    the reference, the diagnostics) to 1e-9. Catches the reference's contact update run
    at the wrong instant (at t_k instead of the previous tick's t_j, as Drake's periodic
    update runs it: contact declared a period early or late), a time base off by a period,
    g removed and added with different models, a wrench about the wrong point, a command
    answering an older status."""
    scenario = load_scenario("panda_wipe", duration=1.75)
    direct, _ = run(scenario)
    driven = run_simulated(scenario, realtime_rate=0.0)
    assert driven.failure is None
    traces = drive_traces(driven)
    assert_same_traces(direct, traces, rtol=1e-9)
    assert float(np.max(traces["f_n"])) > 5.0  # the comparison covers contact
    assert np.array_equal(traces["f_n_measured"], traces["f_n"])  # the sensor's message is its reading


@pytest.mark.slow
def test_panda_wipe_through_the_driver_meets_its_bounds_like_the_direct_run(panda_wipe_direct):
    """The whole 28 s: force error RMS, pose error RMS and the elbow's distance to the post
    within 10% of the direct simulation's, every bound met. (The direct run is conftest's
    panda_wipe_direct: run(load_scenario("panda_wipe")), simulated once per worker.)"""
    scenario = load_scenario("panda_wipe")
    direct, built = panda_wipe_direct
    driven = run_simulated(scenario, realtime_rate=0.0)
    assert driven.failure is None
    traces = drive_traces(driven)
    expected = {m.name: m for m in compute_metrics(scenario, built.station, direct, None)}
    got = {m.name: m for m in compute_metrics(driven.scenario, driven.loop.drive.station, traces, None)}
    failed = [m.name for m in got.values() if m.passed is False]
    assert not failed, failed
    for name in COMPARED:
        assert got[name].value == pytest.approx(expected[name].value, rel=0.10), name
    assert driven.timing["ticks"] == len(direct) == driven.loop.commands


def gravity_run(controller_excludes_g: bool, robot_adds_g: bool, duration: float):
    scenario = load_scenario("panda_wipe", duration=duration)
    scenario = with_driver(scenario, robot_adds_gravity=controller_excludes_g)
    return run_simulated(scenario, realtime_rate=0.0, robot_adds_gravity=robot_adds_g)


@pytest.mark.parametrize(
    ("controller_excludes_g", "robot_adds_g"),
    [(True, True), (False, False), (False, True), (True, False)],
    ids=["panda", "driver removes g", "g twice", "g never"],
)
def test_the_robot_receives_the_law_s_torque_only_with_the_setting_right(controller_excludes_g, robot_adds_g):
    """The torque the simulated plant receives against the law's τ, over 50 ms: equal when
    the setting matches the robot, off by exactly +g(q) (g sent twice) or −g(q) (never
    applied) when it does not. g(q) from the station plant's own gravity forces at the
    logged q, not from the systems under test; the command sent is τ − g(q) exactly when
    the controller excludes g."""
    driven = gravity_run(controller_excludes_g, robot_adds_g, duration=0.05)
    traces = drive_traces(driven)
    plant = driven.driver.built.station.plant
    context = plant.CreateDefaultContext()
    tau = traces.block("tau")
    q = traces.block("q")
    cmd = traces.block("cmd")
    g = np.empty_like(tau)
    for k in range(len(traces)):
        plant.SetPositions(context, q[k])
        g[k] = -plant.CalcGravityGeneralizedForces(context)
    applied = traces.block("tau_applied")[:-1]  # over [t_k, t_k+1); the last is not yet applied
    tau, g = tau[:-1], g[:-1]
    cmd = cmd[:-1]
    np.testing.assert_allclose(
        cmd, tau - (g if controller_excludes_g else 0.0), atol=1e-9 * np.max(np.abs(g))
    )
    expected_error = {(True, True): 0.0, (False, False): 0.0, (False, True): 1.0, (True, False): -1.0}
    sign = expected_error[(controller_excludes_g, robot_adds_g)]
    np.testing.assert_allclose(applied - tau, sign * g, atol=1e-9 * np.max(np.abs(g)))
    assert np.max(np.abs(g)) > 10.0  # the Panda's shoulder holds tens of N m: the test can tell


def test_the_simulated_status_reports_the_command_and_the_torque_it_makes():
    """The status of t_k carries the last command (joint_torque_desired, τ_cmd of t_{k−1})
    and the torque the robot makes with it at q_k (joint_torque, τ_cmd + g(q_k)): catches a
    driver that adds g to the plant but not to the status, or reports the wrong command."""
    drive = prepare(load_scenario("panda_wipe", duration=0.01), realtime_rate=0.0)
    statuses = []
    drive.loop.bus.subscribe("PANDA_STATUS", lambda data: statuses.append(lcmt_panda_status.decode(data)))
    result = drive.run()
    assert result.failure is None
    traces = drive_traces(result)
    plant = drive.driver.built.station.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, traces.block("q")[-1])
    g = -plant.CalcGravityGeneralizedForces(context)
    last = statuses[-1]
    np.testing.assert_array_equal(last.joint_torque_desired, traces.block("cmd")[-2])
    np.testing.assert_allclose(last.joint_torque, traces.block("cmd")[-2] + g, rtol=0, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("controller_excludes_g", "robot_adds_g"), [(False, True), (True, False)], ids=["g twice", "g never"]
)
def test_gravity_wrong_either_way_fails_the_bounds(controller_excludes_g, robot_adds_g):
    """Through first contact and 0.5 s of pressing: with g sent twice the arm rises, with g
    never applied it sags, and panda_wipe's bounds fail."""
    driven = gravity_run(controller_excludes_g, robot_adds_g, duration=2.5)
    traces = drive_traces(driven)
    metrics = compute_metrics(driven.scenario, driven.loop.drive.station, traces, None)
    assert [m.name for m in metrics if m.passed is False]


@pytest.mark.slow
def test_gravity_right_the_other_way_meets_the_bounds():
    """A driver that removes its own g (--remove_gravity_compensation) with a command that
    includes g: the robot gets the law's torque, and the bounds of a 2.5 s run hold."""
    driven = gravity_run(False, False, duration=2.5)
    traces = drive_traces(driven)
    metrics = compute_metrics(driven.scenario, driven.loop.drive.station, traces, None)
    assert not [m.name for m in metrics if m.passed is False]


def test_a_recorded_status_sequence_gives_the_same_commands():
    """The statuses (and force-torque messages) the simulated driver published in a
    lockstep drive, replayed at 1 kHz to a fresh controller side on a fake bus: every
    command's torques equal to 1e-9 of the largest (they are the same calls on the same
    numbers: equal to the bit). Catches a loop whose output depends on anything but the
    status stream (the driver's in-process state, the wall clock, a previous run)."""
    scenario = load_scenario("panda_wipe", duration=1.4)
    drive = prepare(scenario, realtime_rate=0.0)
    recorded = []
    for channel in ("PANDA_STATUS", "PANDA_FORCE_TORQUE"):
        drive.loop.bus.subscribe(channel, lambda data, channel=channel: recorded.append((channel, data)))
    result = drive.run()
    assert result.failure is None
    sent = drive_traces(result).block("cmd")
    bus = FakeBus()
    loop = ControllerLoop(build_controller_side(scenario), bus, clock=bus.clock)
    k = -1
    for channel, data in recorded:
        k += channel == "PANDA_STATUS"
        bus.at((k + 1) * 1e-3, channel, data)
    loop.run(scenario.duration)
    replayed = np.array([command.joint_torque for _, command in bus.sent])
    assert replayed.shape == sent.shape == (1401, 7)
    np.testing.assert_allclose(replayed, sent, rtol=0, atol=1e-9 * np.max(np.abs(sent)))

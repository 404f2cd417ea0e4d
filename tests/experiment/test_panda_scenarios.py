"""The Panda's scenarios (panda_wipe, panda_self_motion): their reference, desired
orientation, traces and metrics, and (slow) their acceptance figures from full runs.

The closed-loop tests simulate the shipped scenarios (28 s and 7.2 s at 1 kHz) and check
the issue's bounds on the traces the runner writes; they are marked slow.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from models import PANDA_CIRCLE
from pydrake.systems.framework import DiagramBuilder

from nsdrake.control.orientation import orientation_error
from nsdrake.experiment.diagram import build_diagram
from nsdrake.experiment.reference import CircleOnSurface, there_and_back
from nsdrake.experiment.scenario import ScenarioError, load_scenario
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.experiment.simulate import run
from nsdrake.experiment.traces import Traces
from nsdrake.reporting.metrics import pose_metrics, self_motion_metrics
from nsdrake.reporting.run_folder import compute_metrics
from nsdrake.station.plant import desired_tool_orientation, tool_orientation


def circle(**overrides):
    return CircleOnSurface(**(PANDA_CIRCLE | overrides))


# ---------------------------------------------------------------- the circle reference


@pytest.mark.parametrize("speed", [0.05, -0.05], ids=["counter-clockwise", "clockwise"])
def test_circle_velocity_and_acceleration_are_derivatives(speed):
    """ẋ_d = dx_d/dt and ẍ_d = dẋ_d/dt (central differences) through the approach, the press,
    the speed blends at both ends of the circle and the cruise, either way round. Catches
    a missing centripetal term (−ṡ²/r u), a blend whose acceleration is dropped, or a
    clockwise circle whose velocity keeps the counter-clockwise sign."""
    ref = circle(speed=speed)
    t_c = 1.0
    start = t_c + ref.delay
    h = 1e-6
    for t in (0.2, 0.9, t_c + 0.1, start + 0.1, start + 0.3, start + 5.0, start + ref.duration - 0.2):
        before, here, after = ref.at(t - h, t_c), ref.at(t, t_c), ref.at(t + h, t_c)
        assert np.allclose((after[0] - before[0]) / (2 * h), here[1], rtol=0, atol=1e-8)
        assert np.allclose((after[1] - before[1]) / (2 * h), here[2], rtol=0, atol=1e-6)
    assert abs(np.linalg.norm(ref.at(start + 5.0, t_c)[1]) - abs(speed)) < 1e-12  # cruising speed
    centripetal = ref.at(start + 5.0, t_c)[2]
    assert abs(np.linalg.norm(centripetal) - speed**2 / ref.radius) < 1e-12


def test_circle_geometry_press_and_return():
    """The circle starts at the contact point, keeps the normal coordinate frozen there,
    stays at radius r from a centre r along t₂ (start angle −π/2), lies in the surface,
    comes back to its start after the laps and rests there; f_d ramps to its value.
    Catches a centre on the wrong side, a circle that drifts off the surface, or a path
    that stops short of (or past) the last lap."""
    ref = circle()
    t_c = 1.0
    contact = ref.at(t_c, t_c)[0]
    centre = contact + ref.radius * np.array([0.0, 1.0, 0.0])
    for t in np.linspace(t_c, t_c + ref.delay + ref.duration + 1.0, 200):
        x = ref.at(t, t_c)[0]
        assert abs(np.linalg.norm(x - centre) - ref.radius) < 1e-12
        assert x[2] == contact[2]
    end = ref.at(t_c + ref.delay + ref.duration + 0.5, t_c)
    assert np.allclose(end[0], contact, atol=1e-12) and not end[1].any() and not end[2].any()
    assert ref.at(t_c + ref.force_ramp_time, t_c)[3] == 10.0 and ref.at(t_c, t_c)[3] == 0.0
    s, sd, sdd = there_and_back((1.0 / 0.05 + 0.5) / 2, 1.0, 0.05, 0.5)  # half-way through a 1 m move
    assert s == pytest.approx(0.5) and sd == pytest.approx(0.05) and sdd == 0.0


def test_circle_keeps_its_clock_through_a_contact_loss():
    """Contact lost during the circle: f_d ramps to 0 and the normal reference moves on at
    most max_overtravel (as SlideAndPress), while the path along the surface keeps the
    first contact's clock: a contact regained later (a new t_contact) does not send x_d
    back to the start of the circle. Catches a circle timed from the latest contact."""
    from nsdrake.experiment.reference import ContactState

    ref = circle()
    t_first, t = 1.0, 8.0
    lost = ContactState(t_contact=t_first, r_contact=0.02, t_lost=7.0)
    x_lost, _, _, f_lost = ref.at(t, state=lost, t_first=t_first)
    assert f_lost == 0.0
    assert (x_lost - ref.x0) @ ref.normal <= 0.02 + ref.max_overtravel + 1e-12
    regained = ContactState(t_contact=7.9, r_contact=0.03)
    along = np.eye(3) - np.outer(ref.normal, ref.normal)
    x_first = ref.at(t, state=ContactState(t_contact=t_first, r_contact=0.02), t_first=t_first)[0]
    x_again = ref.at(t, state=regained, t_first=t_first)[0]
    assert np.allclose(along @ x_again, along @ x_first, atol=1e-15)
    assert np.linalg.norm(along @ (ref.at(t, state=regained)[0] - x_first)) > 0.05  # the mistake


# ---------------------------------------------------------------- scenarios and station


@pytest.fixture(scope="module")
def wipe():
    return load_scenario("panda_wipe")


def test_panda_scenarios_build_with_the_pose_ports(wipe):
    """Both Panda scenarios build: the controller has the rotational ports, fed by the
    orientation reference; the task is the full pose (m = 6) on the 7-joint arm with
    gravity on, the table's push direction is world −z. Catches a plate roll that lays
    the table upside down, or a pose task left without its orientation input."""
    for scenario in (wipe, load_scenario("panda_self_motion")):
        built = build_diagram(scenario)
        controller, station = built.controller, built.station
        assert controller.model.m == 6 and controller.model.n == 7
        assert np.allclose(station.normal, [0.0, 0.0, -1.0], atol=1e-12)
        assert np.allclose(station.gravity, [0.0, 0.0, -9.81])
        assert built.system("orientation_reference") is not None
        assert controller.HasInputPort("desired_orientation")


def test_desired_orientation_is_perpendicular_to_the_table(wipe):
    """reference.orientation: perpendicular points the tool frame's z axis exactly along
    the push direction (world −z), turning the start orientation by the smallest rotation:
    at the shipped q0 (q6 = q2 − q4, already pointing down) not at all, from a q0 tilted
    by 0.05 rad about joint 6 by exactly that tilt and no spin about the tool axis.
    Catches a desired orientation that keeps the start's tilt, or one that also spins
    the tool about its axis."""
    station = add_scenario_station(DiagramBuilder(), wipe)
    R0 = tool_orientation(station, station.q0)
    assert np.linalg.norm(orientation_error(desired_tool_orientation(station, "perpendicular"), R0)) < 1e-12
    tilted = dataclasses.replace(station, q0=station.q0 + [0, 0, 0, 0, 0, 0.05, 0])
    R0 = tool_orientation(tilted, tilted.q0)
    R_d = desired_tool_orientation(tilted, "perpendicular")
    assert np.allclose(R_d[:, 2], [0.0, 0.0, -1.0], atol=1e-15)
    tilt = orientation_error(R_d, R0)
    assert np.linalg.norm(tilt) == pytest.approx(0.05, abs=1e-12)
    assert abs(tilt @ R0[:, 2]) < 1e-12  # no spin about the tool axis
    assert np.array_equal(desired_tool_orientation(tilted, "start"), R0)


def test_circle_needs_three_translational_axes(tmp_path):
    """A circle on a planar task, and a task the arm cannot span, are refused with one line
    naming the field. Catches a planar circle that would silently drop the second tangent."""
    path = tmp_path / "planar.yaml"
    path.write_text("reference: {path: circle}\n")
    with pytest.raises(
        ScenarioError, match="reference.path: a circle on the surface needs the task axes x, y, z"
    ):
        load_scenario("fig3", config=path)
    path.write_text("task: {axes: [x, y, z]}\nplate: {roll: -1.5707963267948966}\n")
    with pytest.raises(ScenarioError, match="cannot span") as error:
        build_diagram(load_scenario("fig3", config=path))
    assert "\n" not in str(error.value)


def test_pose_traces_have_the_new_columns(wipe):
    """A short panda_wipe run's traces hold x, y, z and their references, rot_err, q1…q7,
    v1…v7, tau1…tau7, the criteria values, d_min, each obstacle's distance and the
    per-joint margins to the position, speed and torque limits; the margins agree with the
    joint columns and the model's limits. Catches a margin taken against the wrong limit
    (e.g. the scenario's speed headroom instead of the arm's velocity limit)."""
    traces, built = run(dataclasses.replace(wipe, duration=0.05))
    names = set(traces.names)
    expected = {"x", "y", "z", "x_d", "y_d", "z_d", "rot_err", "d_min", "d_post", "d_plate", "swivel"}
    expected |= {"w", "p_tau", "p_obstacle", "p_joint_limits", "q_margin"}
    expected |= {
        f"{k}{i}" for k in ("q", "v", "tau", "q_margin", "v_margin", "tau_margin") for i in range(1, 8)
    }
    assert expected <= names
    plant = built.station.plant
    q, v, tau = traces.block("q"), traces.block("v"), traces.block("tau")
    lo, hi = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    assert np.allclose(traces.block("q_margin"), np.minimum(q - lo, hi - q))
    assert np.allclose(traces.block("v_margin"), plant.GetVelocityUpperLimits() - np.abs(v))
    assert np.allclose(traces.block("tau_margin"), [87.0] * 4 + [12.0] * 3 - np.abs(tau))
    assert traces["rot_err"][0] < 1e-12 and abs(traces["swivel"][0]) < 1e-12
    assert 0.05 < traces["d_post"][0] < 0.1  # the post starts within the influence distance


def test_pose_metrics_fail_what_they_should():
    """The pose metrics fail an orientation error of 0.6° RMS, a link 4 cm from the post
    (d_lim 5 cm), a 1.5 mm in-plane error and a 3% force error, and pass the same traces
    without them; the normal (force-controlled) coordinate does not count as position
    error. Catches a bound compared in radians instead of degrees, or a normal error
    counted as a tracking error."""
    t = np.arange(0.0, 3.0, 0.001)
    k = len(t)
    good = {
        "t": t,
        "f_n": np.where(t > 1.0, 10.0, 0.0),
        "f_d": np.where(t > 1.0, 10.0, 0.0),
        "x": np.zeros(k),
        "y": np.zeros(k),
        "z": np.where(t > 1.0, -5e-3, 0.0),  # pressed 5 mm into the table: normal, not an error
        "x_d": np.zeros(k),
        "y_d": np.zeros(k),
        "z_d": np.zeros(k),
        "rot_err": np.full(k, np.radians(0.1)),
        "d_post": np.full(k, 0.06),
        "d_plate": np.full(k, 0.1),
        "forbidden_contacts": np.zeros(k),
        "saturated_joints": np.zeros(k),
    }
    for kind in ("q", "v", "tau"):
        good[f"{kind}_margin1"] = np.ones(k)
    kwargs = {
        "normal": np.array([0.0, 0.0, -1.0]),
        "task_axes": ("x", "y", "z"),
        "contact_threshold": 0.5,
        "d_lim": 0.05,
        "obstacles": ("post",),
    }
    assert all(m.passed is not False for m in pose_metrics(Traces(good), **kwargs))
    for column, value, metric in (
        ("rot_err", np.radians(0.6), "orientation_error_rms"),
        ("d_post", 0.04, "d_post_min"),
        ("x", 1.5e-3, "position_error_rms"),
        ("f_n", 10.3, "force_error_rms"),
    ):
        bad = dict(good, **{column: np.full(k, value) if column != "f_n" else np.where(t > 1.0, value, 0.0)})
        failed = {m.name for m in pose_metrics(Traces(bad), **kwargs) if m.passed is False}
        assert metric in failed, (column, failed)


# ---------------------------------------------------------------- closed loop (slow)


def passed(metrics):
    return {m.name: m.passed for m in metrics}, {m.name: m.value for m in metrics}


@pytest.mark.slow
def test_panda_wipe_meets_the_acceptance_figures(wipe, tmp_path, panda_wipe_direct):
    """The shipped panda_wipe (28 s), from its traces.csv, from 0.5 s after first contact:
    normal force positive, RMS(f_n − f_d) ≤ 2% and max ≤ 10% of f_d, in-plane position
    error RMS ≤ 1 mm, orientation error RMS ≤ 0.5° and max ≤ 2°; over the whole run the
    links stay farther than d_lim from the post, nothing but the tool touches the table or
    the post, and no joint reaches its position, speed or torque limit. Catches any
    regression of the pose law, the force loop, the obstacle criterion on a 3-D arm, or
    the limits."""
    traces, built = panda_wipe_direct  # run(wipe), simulated once for this and the drive's comparison
    traces.write_csv(tmp_path / "traces.csv")
    traces = Traces.read_csv(tmp_path / "traces.csv")
    metrics = compute_metrics(wipe, built.station, traces, None)
    verdicts, values = passed(metrics)
    failed = sorted(name for name, ok in verdicts.items() if ok is False)
    assert not failed, {name: values[name] for name in failed}
    for name in (
        "force_error_rms",
        "force_error_max",
        "position_error_rms",
        "orientation_error_rms",
        "orientation_error_max",
        "d_post_min",
        "forbidden_contacts_max",
        "q_margin4_min",
        "tau_margin6_min",
    ):
        assert verdicts[name] is True, name


@pytest.mark.slow
def test_without_the_null_space_task_the_elbow_reaches_the_post(wipe):
    """The same wipe with q̇_dⁿ = 0 (the null-space controller only damps self-motion) for
    its first 10 s: the arm's self-motion drifts the elbow to within d_lim of the post.
    Catches a post placed where it does not matter: the acceptance figure d_post > d_lim
    would then say nothing about obstacle avoidance."""
    traces, _ = run(dataclasses.replace(wipe, duration=10.0), null_space_task=False)
    assert traces["d_post"].min() < wipe.desired_null_space.selector.d_lim


@pytest.mark.slow
def test_panda_self_motion_sweeps_the_elbow_while_the_tool_holds(tmp_path_factory):
    """The shipped panda_self_motion: the elbow swivels through ≥ 0.5 rad of the
    self-motion and back while the tool's in-plane position error stays ≤ 1 mm and the
    force error ≤ 2% RMS (Eq. 11 on a 7-joint arm with gravity). Catches a null-space law
    whose τ₀ leaks into the task (J H⁻¹ τ₀ ≠ 0) at the Panda's speeds. (The run is
    conftest's shipped_run, which test_first_contact.py's torque-rate test reads too.)"""
    from conftest import shipped_run

    traces, built = shipped_run(tmp_path_factory, "panda_self_motion")
    metrics = self_motion_metrics(
        traces, normal=built.station.normal, task_axes=("x", "y", "z"), contact_threshold=0.5
    )
    verdicts, values = passed(metrics)
    assert all(ok is not False for ok in verdicts.values()), values
    assert values["swivel_range"] >= 0.5
    swivel = traces["swivel"]
    assert abs(swivel[-1] - swivel[0]) < 0.1 * values["swivel_range"]  # and back


def test_unstable_rotational_gains_are_refused(tmp_path):
    """A pose task's rotational gains are checked for the sampled loop's stability like the
    translational ones (k_p,r = 4e6 /s² at 1 ms is unstable), with one line naming them.
    Catches a check that only looks at the translational rows."""
    from nsdrake.reporting.run_folder import check_scenario

    path = tmp_path / "stiff.yaml"
    path.write_text("impedance: {K_p_rotation: 4000000.0}\n")
    with pytest.raises(ScenarioError, match="impedance.K_p_rotation, K_v_rotation") as error:
        check_scenario(load_scenario("panda_wipe", config=path))
    assert "\n" not in str(error.value)

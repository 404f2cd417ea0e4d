"""NullSpaceImpedanceController as a component: its τ at fixed inputs against an
independent rebuild from plain plant calls, each switch, the selector's blend, the
reference, the contact monitor, and a user's own arm (diagrams/own_arm.py).

The rebuild uses only Drake's plant calls on the *simulated* plant (H, C q̇, g, J,
J̇ q̇), AutoDiff for J̄̇ and for the Christoffel C, and numpy: none of nsdrake's math.
The controller computes its terms with Pinocchio on its own model, so agreement to
1e-10 relative is agreement of two independent computations to near machine precision.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from drake_reference import AutoDiffArm, christoffel_C, plant_terms
from pydrake.systems.framework import DiagramBuilder
from reference_math import (
    dynamically_consistent_inverse,
    null_space_projector,
    task_space_inertia,
    task_velocity_compensation,
)

from nsdrake.control.priority import ORDERINGS, Criterion, Level, Mode, prioritized_velocity
from nsdrake.control.systems.criteria import unpack_criterion
from nsdrake.experiment.diagram import build_controller
from nsdrake.experiment.reference import SlideAndPress
from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.experiment.simulate import moving_link_geometries
from nsdrake.station.force_sensor import ForceSensor

TOL = 1e-10
ROOT = Path(__file__).resolve().parents[2]


def fig3_controller(scenario):
    station = add_scenario_station(DiagramBuilder(), scenario)
    sensor = ForceSensor(plant=station.plant, sensor_joint=station.sensor_joint)
    return build_controller(scenario, station, sensor.p_WSo), station, sensor.p_WSo


def with_null_space(scenario, **switches):
    return dataclasses.replace(scenario, null_space=dataclasses.replace(scenario.null_space, **switches))


def fixed_inputs(controller, context, q, v, rng):
    inputs = {
        "estimated_state": np.concatenate([q, v]),
        "measured_wrench": rng.standard_normal(6) * [0.1, 0.1, 0.1, 3.0, 10.0, 0.5],
        "desired_position": [0.3, 0.5] + 0.01 * rng.standard_normal(2),
        "desired_velocity": 0.05 * rng.standard_normal(2),
        "desired_acceleration": 0.2 * rng.standard_normal(2),
        "desired_force": [7.0],
    }
    for name, value in inputs.items():
        controller.GetInputPort(name).FixValue(context, value)
    return inputs


def expected_torque(scenario, station, p_WSo, inputs, qdot_ns_d, previous_qdot_ns_d):
    """τ of Eqs. 6–8 and 21 from plain plant calls and AutoDiff (module docstring)."""
    arm = station.arm_model
    n = arm.n
    q, v = inputs["estimated_state"][:n], inputs["estimated_state"][n:]
    ref = plant_terms(arm, q, v)
    H, J = ref["H"], ref["J"]
    H_inv = np.linalg.inv(H)
    Lam = task_space_inertia(J, H_inv)
    Jbar, Jbar_dot = AutoDiffArm(arm).Jbar_and_dot(q, v)
    assert np.allclose(Jbar, dynamically_consistent_inverse(J, H_inv), rtol=1e-12, atol=1e-12)
    N = null_space_projector(J, Jbar)
    # Impedance (Eqs. 6–8): the plate's normal is +y, its tangent +x.
    imp = scenario.impedance
    W = inputs["measured_wrench"]
    f = W[3:]
    M_T = W[:3] + np.cross(p_WSo - ref["p_WT"], f)
    nrm, tan = np.array([0.0, 1.0]), np.array([1.0, 0.0])
    x, xdot = ref["x"], J @ v
    x_d, xd_d, xdd_d = inputs["desired_position"], inputs["desired_velocity"], inputs["desired_acceleration"]
    xddot_c = (
        xdd_d
        + tan * (imp.K_v_tangent * tan @ (xd_d - xdot) + imp.K_p_tangent * tan @ (x_d - x))
        + nrm
        * (
            imp.K_v_normal * nrm @ (xd_d - xdot)
            + imp.K_p_normal * nrm @ (x_d - x)
            + imp.K_f * (inputs["desired_force"][0] - nrm @ f[:2])
        )
    )
    tau = J.T @ Lam @ (xddot_c - ref["Jdot_v"]) + ref["J_spatial"][:3].T @ M_T + ref["J_spatial"][3:].T @ f
    tau += ref["Cv"] + ref["g"]
    # Null space (Eq. 21).
    ns = scenario.null_space
    e = qdot_ns_d - N @ v
    a = ns.K_n * e
    if ns.acceleration_feedforward:
        a = a + (qdot_ns_d - previous_qdot_ns_d) / scenario.control_period
    if ns.task_velocity_compensation:
        Jdot = AutoDiffArm(arm).Jdot(q, v)
        a = a + task_velocity_compensation(J, Jdot, Jbar, Jbar_dot, v)
    if ns.coriolis_compensation:
        a = a + H_inv @ christoffel_C(arm, q, v) @ e
    return tau + H @ N @ a


@pytest.mark.parametrize(
    "switches",
    [
        {},
        {"acceleration_feedforward": False},
        {"task_velocity_compensation": False},
        {"coriolis_compensation": False},
    ],
    ids=["full", "no_feedforward", "no_task_velocity_compensation", "no_coriolis_compensation"],
)
def test_generalized_force_matches_an_independent_rebuild(switches):
    """τ of the whole controller at fixed inputs and a stored previous q̇_dⁿ, against
    Eqs. 6–8 and 21 rebuilt from plain plant calls. Dropping any term (the q̈_dⁿ
    feed-forward, the task-velocity or Coriolis compensation, J̇ q̇, the wrench
    transport, g) or flipping a sign makes the two differ by far more than 1e-10; so
    does a switch that fails to remove its term (the parametrised cases)."""
    scenario = with_null_space(load_scenario("fig3"), **switches)
    controller, station, p_WSo = fig3_controller(scenario)
    rng = np.random.default_rng(8)
    n = station.arm_model.n
    for _ in range(5):
        context = controller.CreateDefaultContext()
        q = station.q0 + 0.1 * rng.standard_normal(n)
        v = 0.1 * rng.standard_normal(n)  # within fig3's joint-speed limits
        inputs = fixed_inputs(controller, context, q, v, rng)
        previous = 0.1 * rng.standard_normal(n)
        context.SetTime(1.0)  # the selector settled in mode 2 (no blend from rest)
        selector = controller.GetSubsystemByName("priority_selector")
        selector.GetMyMutableContextFromRoot(context).get_mutable_discrete_state(0).SetFromVector(
            [2.0, 2.0, -np.inf]
        )
        ns = controller.GetSubsystemByName("null_space_controller")
        ns.GetMyMutableContextFromRoot(context).get_mutable_discrete_state(0).SetFromVector(
            np.append(previous, 1.0)
        )
        qdot_ns_d = controller.GetOutputPort("desired_null_space_velocity").Eval(context)
        assert np.linalg.norm(qdot_ns_d) > 1e-3  # the selector commands something
        got = controller.GetOutputPort("generalized_force").Eval(context)
        want = expected_torque(scenario, station, p_WSo, inputs, qdot_ns_d, previous)
        assert np.max(np.abs(got - want)) <= TOL * np.max(np.abs(want))


def test_null_space_outputs_match_eqs_14_and_23():
    """eⁿ = q̇_dⁿ − N q̇ (Eq. 14) and ν = ½ eⁿᵀ H eⁿ (Eq. 23) at the controller's ports."""
    scenario = load_scenario("fig3")
    controller, station, _ = fig3_controller(scenario)
    arm, n = station.arm_model, station.arm_model.n
    rng = np.random.default_rng(3)
    context = controller.CreateDefaultContext()
    q, v = station.q0 + 0.1 * rng.standard_normal(n), rng.standard_normal(n)
    fixed_inputs(controller, context, q, v, rng)
    ref = plant_terms(arm, q, v)
    H, J = ref["H"], ref["J"]
    N = null_space_projector(J, dynamically_consistent_inverse(J, np.linalg.inv(H)))
    e = controller.GetOutputPort("desired_null_space_velocity").Eval(context) - N @ v
    assert np.allclose(
        controller.GetOutputPort("null_space_velocity_error").Eval(context), e, rtol=0, atol=1e-12
    )
    nu = controller.GetOutputPort("lyapunov").Eval(context)[0]
    assert abs(nu - 0.5 * e @ H @ e) <= 1e-12 * max(nu, 1e-12)


def test_selector_blends_from_the_old_ordering_after_a_switch():
    """Half-way through the blend after a switch from mode 3 to mode 2, q̇_dⁿ is the
    smoothstep mix ½(new) + ½(old) of the two orderings' velocities (Fig. 1 switching,
    nsdrake.control.priority). Skipping the blend, or blending the wrong way, fails. (Joint-speed
    limits off, so that no scaling enters.)"""
    scenario = load_scenario("fig3")
    d = dataclasses.replace(scenario.desired_null_space, joint_speed_limits={})
    scenario = dataclasses.replace(scenario, desired_null_space=d)
    controller, station, _ = fig3_controller(scenario)
    blend = scenario.desired_null_space.selector.blend_time
    t = 1.0
    context = controller.CreateDefaultContext()
    context.SetTime(t)
    q, v = station.q0, np.zeros(station.arm_model.n)
    fixed_inputs(controller, context, q, v, np.random.default_rng(0))
    selector = controller.GetSubsystemByName("priority_selector")
    sel_context = selector.GetMyMutableContextFromRoot(context)
    sel_context.get_mutable_discrete_state(0).SetFromVector([2.0, 3.0, t - blend / 2])
    assert controller.GetOutputPort("mode").Eval(context)[0] == 2
    assert controller.GetOutputPort("speed_scale").Eval(context)[0] == pytest.approx(1.0, abs=1e-12)
    got = controller.GetOutputPort("desired_null_space_velocity").Eval(context)

    ref = plant_terms(station.arm_model, q, v)
    H, J = ref["H"], ref["J"]
    H_inv = np.linalg.inv(H)
    N = null_space_projector(J, dynamically_consistent_inverse(J, H_inv))
    crit = scenario.desired_null_space.criteria
    gains = {
        Criterion.obstacle: crit.obstacle.gain,
        Criterion.joint_torque: crit.joint_torque.gain,
        Criterion.manipulability: crit.manipulability.gain,
        Criterion.joint_limits: crit.joint_limits.gain,
    }
    levels = {}
    rows = selector.GetInputPort("criteria").Eval(sel_context).reshape(len(Criterion), -1)
    for k, c in enumerate(Criterion):  # the criteria system's rows, in Criterion's order
        gradient, _, _, a = unpack_criterion(rows[k])
        levels[c] = Level(gradient, gains[c], a if gains[c] else 0.0)

    def ordering(mode):
        return prioritized_velocity(N, H, H_inv, [levels[c] for c in ORDERINGS[mode]])

    new, old = ordering(Mode.joint_torque), ordering(Mode.manipulability)
    assert np.linalg.norm(new - old) > 1e-3 * np.linalg.norm(new)  # the orderings differ
    want = 0.5 * new + 0.5 * old
    assert np.max(np.abs(got - want)) <= 1e-9 * np.max(np.abs(want))


def test_obstacle_activation_fades_in_between_the_influence_distance_and_its_half():
    """The obstacle level's weight (nsdrake.control.smoothing.activation): 0 beyond the
    influence distance d_∞, 1 inside d_∞/2, the smoothstep in between. Replacing the
    fade by a constant, or by a hard switch at d_∞, fails."""
    from nsdrake.control.smoothing import activation

    d_inf = 0.1
    assert activation(0.2, d_inf) == 0.0
    assert activation(d_inf, d_inf) == 0.0
    assert activation(0.75 * d_inf, d_inf) == pytest.approx(0.5, abs=1e-15)
    assert activation(0.5 * d_inf, d_inf) == 1.0
    assert activation(0.01, d_inf) == 1.0
    d = np.linspace(0.04, 0.11, 701)
    a = np.array([activation(x, d_inf) for x in d])
    assert np.max(np.abs(np.diff(a))) < 0.005  # no step: continuous
    assert np.all(np.diff(a) <= 0)  # monotone: nearer, more weight


def test_controller_reports_the_obstacle_activation_it_uses():
    """The obstacle criterion's activation is the fade of its own d_min, and the controller's
    d_min port is that same distance."""
    from nsdrake.control.smoothing import activation

    scenario = load_scenario("fig3")
    controller, station, _ = fig3_controller(scenario)
    context = controller.CreateDefaultContext()
    criteria = controller.GetSubsystemByName("criteria")
    sub = criteria.GetMyContextFromRoot(context)
    influence = scenario.desired_null_space.criteria.obstacle.influence_distance
    for q in (station.q0, station.q0 + [0.0, 0.3, 0.3, 0.3]):
        controller.GetInputPort("estimated_state").FixValue(context, np.concatenate([q, np.zeros(4)]))
        obstacle_row = criteria.GetOutputPort("criteria").Eval(sub).reshape(len(Criterion), -1)[0]
        _, _, d_min, got = unpack_criterion(obstacle_row)
        assert got == activation(d_min, influence)
        assert controller.GetOutputPort("d_min").Eval(context)[0] == d_min


def test_reference_velocity_and_acceleration_are_derivatives_and_force_ramps():
    """ẋ_d = dx_d/dt and ẍ_d = dẋ_d/dt (central differences, 1e-6) through the speed
    blend, the approach frozen at contact, and f_d rising from 0 at contact to f over
    the ramp (½ f half-way). Dropping the ramp's acceleration, or the force ramp, fails."""
    ref = SlideAndPress(
        x0=np.array([0.3, 0.4]),
        tangent=np.array([1.0, 0.0]),
        normal=np.array([0.0, 1.0]),
        tangent_speed=0.05,
        approach_speed=0.03,
        blend_time=0.2,
        force=10.0,
        force_ramp_time=0.2,
    )
    h = 1e-6
    t_c = 1.0
    for t in (0.01, 0.05, 0.1, 0.15, 0.19, 0.5, 1.05, 1.5):
        before, here, after = ref.at(t - h, t_c), ref.at(t, t_c), ref.at(t + h, t_c)
        assert np.allclose((after[0] - before[0]) / (2 * h), here[1], rtol=0, atol=1e-8)
        assert np.allclose((after[1] - before[1]) / (2 * h), here[2], rtol=0, atol=1e-6)
    assert np.max(np.abs(ref.at(0.1, t_c)[2])) > 0.1  # the blend accelerates
    assert ref.at(t_c, t_c)[3] == 0.0
    assert ref.at(t_c + 0.1, t_c)[3] == pytest.approx(5.0, abs=1e-12)
    assert ref.at(t_c + 0.2, t_c)[3] == 10.0
    assert ref.at(t_c + 0.05, t_c)[3] < 5.0  # a ramp, not a step
    assert ref.at(t_c + 1.0, t_c)[1][1] == 0.0  # the normal reference is frozen at contact


def test_contact_monitor_counts_a_link_touching_the_plate(tmp_path):
    """With the plate moved onto link 2, the monitor counts forbidden contacts from the
    first step; at fig3's start (nothing touches) it counts none. A monitor that never
    counts, or counts the tool, fails."""
    from conftest import fig3_with, simulate_to

    touching = fig3_with(tmp_path, "plate: {position: [0.3, 0.23, 0.0]}\n")
    built, context = simulate_to(touching, 0.01)
    monitor = built.system("contact_monitor")
    assert monitor.get_output_port().Eval(monitor.GetMyContextFromRoot(context))[0] >= 1
    built, context = simulate_to(load_scenario("fig3"), 0.01)
    monitor = built.system("contact_monitor")
    assert monitor.get_output_port().Eval(monitor.GetMyContextFromRoot(context))[0] == 0


def test_controller_on_an_arm_nsdrake_did_not_build():
    """diagrams/own_arm.py: the controller dropped onto a 5-joint arm built from a URDF
    string, pressing on a wall of its own; the normal force reaches 5 N within 2%."""
    out = subprocess.run(
        [sys.executable, str(ROOT / "diagrams" / "own_arm.py"), "3"],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    ).stdout
    force = float(out.split("normal force")[1].split("N")[0])
    assert force == pytest.approx(5.0, rel=0.02)


def test_diagnostic_ports_are_the_criteria_they_name():
    """The criteria system's packed rows [Φ; p; s; a] are split by a Demultiplexer into the
    controller's named ports: manipulability is w = √det(J Jᵀ), joint_torque_criterion is
    ‖Jᵀ F_d‖², d_min is the smallest link–plate distance, all at the measured state and
    against plain plant calls. A split out of order (value and switching quantity
    swapped), or a criterion packed in the wrong layout, fails."""
    scenario = load_scenario("fig3")
    controller, station, _ = fig3_controller(scenario)
    arm, n = station.arm_model, station.arm_model.n
    rng = np.random.default_rng(5)
    context = controller.CreateDefaultContext()
    q = station.q0 + 0.1 * rng.standard_normal(n)
    fixed_inputs(controller, context, q, np.zeros(n), rng)
    J = plant_terms(arm, q, np.zeros(n))["J"]
    F_d = scenario.reference.force * station.normal
    port = lambda name: controller.GetOutputPort(name).Eval(context)[0]  # noqa: E731
    assert port("manipulability") == pytest.approx(np.sqrt(np.linalg.det(J @ J.T)), rel=1e-12)
    assert port("joint_torque_criterion") == pytest.approx(np.sum((J.T @ F_d) ** 2), rel=1e-12)
    # d_min from Drake's own signed-distance queries on the simulated station's geometry
    # (its GJK distance for a capsule and a box is good to about 1e-5 m).
    builder = DiagramBuilder()
    sim_station = add_scenario_station(builder, scenario)
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    sim_station.plant.SetPositions(sim_station.plant.GetMyMutableContextFromRoot(root), q)
    sg = sim_station.scene_graph
    query = sg.get_query_output_port().Eval(sg.GetMyContextFromRoot(root))
    want = min(
        query.ComputeSignedDistancePairClosestPoints(link, obstacle).distance
        for link in moving_link_geometries(sim_station)
        for obstacle in sim_station.obstacle_geometries
    )
    assert abs(port("d_min") - want) < 1e-4
    criteria = controller.GetSubsystemByName("criteria")
    packed = criteria.GetOutputPort("criteria").Eval(criteria.GetMyContextFromRoot(context))
    _, p, s, _ = unpack_criterion(packed.reshape(len(Criterion), -1)[0])
    assert (s, p) == (port("d_min"), port("obstacle_potential"))

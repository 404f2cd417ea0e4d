"""The realism ladder (nsdrake/realism.py): each rung changes what it should, and
nothing when it is off.

Unit tests build the piece alone (the sensor chain, the hold, the friction law, the
elastic arm); closed-loop tests run fig3 for short durations. The family's own
directions (each rung against the clean run) are in the slow test at the end.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from conftest import fig3_with
from pydrake.common import RandomGenerator
from pydrake.multibody.tree import MultibodyForces
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from nsdrake.experiment.diagram import build_diagram
from nsdrake.experiment.scenario import Scenario, ScenarioError, load_scenario, shipped_scenarios
from nsdrake.experiment.simulate import run
from nsdrake.realism.config import RUNGS, ForceSensorConfig, RealismConfig
from nsdrake.realism.model_error import scale_urdf_masses
from nsdrake.realism.wiring import ForceSensorModel
from nsdrake.station.elastic import elastic_urdf
from nsdrake.station.friction import friction_slope, friction_torque
from nsdrake.station.models import models_dir
from nsdrake.studies.measures import drift_rate, force_oscillation, wrong_way_share

ARM4 = (models_dir() / "arm4.urdf").read_text()


# --- off by default -----------------------------------------------------------------


def test_every_rung_is_off_by_default_and_in_every_shipped_scenario():
    """Catches a rung switched on by default, which would change every shipped
    scenario's traces (the README promises they are the clean simulation)."""
    assert not RealismConfig().any
    assert not Scenario().realism.any
    for name in shipped_scenarios():
        assert not load_scenario(name).realism.any, name


def test_with_every_rung_off_the_diagram_has_none_of_their_systems(tmp_path):
    """Catches realism wiring leaking into the default diagram: no hold, sensor model,
    friction or encoders, the plant steps at the control period and the plant's state
    is the arm's."""
    built = build_diagram(fig3_with(tmp_path))
    for name in ("control_hold", "force_sensor_model", "joint_friction", "motor_encoders", "link_state"):
        assert not built.diagram.HasSubsystemNamed(name), name
    assert built.station.plant.time_step() == built.scenario.control_period
    assert built.station.elastic is None
    assert built.station.plant.num_positions() == built.station.arm_model.n


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ("realism: {physics: {substeps: 3}}", "realism.physics.substeps: must be a power of two"),
        (
            "realism: {force_sensor: {enabled: true, sample_period: 0.0003}}",
            "realism.force_sensor.sample_period: 0.0003 s must be the control period",
        ),
        ("realism: {force_sensor: {noise_force: -1.0}}", "realism.force_sensor.noise_force: must be"),
        ("realism: {force_sensor: {bias_force: [1.0]}}", "realism.force_sensor.bias_force: must be three"),
        ("realism: {friction: {smoothing_speed: 0.0}}", "realism.friction.smoothing_speed: must be > 0"),
        ("realism: {belt: {stiffness: -5.0}}", "realism.belt.stiffness: must be > 0"),
        ("realism: {delay: {periods: -1}}", "realism.delay.periods: must be an integer >= 0"),
        ("realism: {model_error: {mass_error: -1.0}}", "realism.model_error.mass_error: must be a finite"),
        ("realism: {wind: {enabled: true}}", "realism.wind: unknown field"),
    ],
)
def test_invalid_realism_settings_are_refused_in_one_line(tmp_path, overrides, message):
    """Catches a setting that would simulate something else than asked (a plant step
    that misses the controller's instants, a negative stiffness, masses ≤ 0) instead of
    being refused before the run, with the field named."""
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, overrides + "\n")
    assert message in str(info.value) and "\n" not in str(info.value)


# --- physics finer than control, computation delay: the hold --------------------------


def _applied_and_commanded(scenario, t_end):
    """(times, torque the plant receives, controller's τ) at every plant step up to t_end."""
    built = build_diagram(scenario)
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant, station = built.station.plant, built.station
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), station.plant_q0)
    simulator.Initialize()
    actuation = built.diagram.GetSubsystemByName("actuation_map")
    controller = built.controller
    h = plant.time_step()
    times, applied, commanded = [], [], []
    for k in range(round(t_end / h) + 1):
        simulator.AdvanceTo(k * h)
        times.append(context.get_time())
        applied.append(actuation.get_output_port().Eval(actuation.GetMyContextFromRoot(context)).copy())
        tau = controller.GetOutputPort("generalized_force").Eval(controller.GetMyContextFromRoot(context))
        commanded.append(tau.copy())
    return np.array(times), np.array(applied), np.array(commanded), built


@pytest.mark.parametrize("delay", [0, 1])
def test_finer_physics_holds_the_torque_sampled_at_each_control_instant(tmp_path, delay):
    """With the plant at 0.5 ms and the controller at 2 ms, the torque the plant receives
    over [t_k, t_k+1) is the controller's τ at t_k exactly (or at t_k−1 with one period
    of delay). Catches a hold that samples after the plant's step (Drake's ZeroOrderHold
    would), that re-evaluates the controller between instants, or a delay of one plant
    step instead of one control period."""
    realism = "realism: {physics: {enabled: true, substeps: 4}"
    realism += ", delay: {enabled: true, periods: 1}}\n" if delay else "}\n"
    scenario = fig3_with(tmp_path, realism, duration=0.2)
    t, applied, commanded, built = _applied_and_commanded(scenario, 0.08)
    T = scenario.control_period
    assert built.station.plant.time_step() == pytest.approx(T / 4)
    instants = np.flatnonzero(np.isclose(np.mod(t + 1e-9, T), 1e-9, atol=1e-7))
    assert len(instants) >= 40 and np.abs(commanded).max() > 0.01  # not vacuous: the arm is driven
    for a, b in zip(instants[:-1], instants[1:], strict=True):
        source = a - 4 * delay
        expected = commanded[source] if source >= 0 else np.zeros_like(commanded[a])
        for j in range(a, b):  # (to rounding: the test's sample times are k h, Drake's its own)
            np.testing.assert_allclose(applied[j], expected, rtol=1e-9, atol=1e-12)


def test_the_hold_at_one_plant_step_per_period_changes_nothing(tmp_path):
    """Physics rung on with 1 substep: the hold is in the loop, yet every trace column
    equals the direct connection's to the last bit, through contact. Catches a hold
    that samples a different state than the plant's step and the controller's own
    stores (the null-space q̇_dⁿ memory) use."""
    clean, _ = run(fig3_with(tmp_path, duration=1.5))
    held, built = run(fig3_with(tmp_path, "realism: {physics: {enabled: true, substeps: 1}}\n", duration=1.5))
    assert built.diagram.HasSubsystemNamed("control_hold")
    assert clean["f_n"].max() > 5.0  # the window includes contact
    for name in clean.names:
        np.testing.assert_array_equal(held[name], clean[name], err_msg=name)


# --- the force sensor -------------------------------------------------------------------


def _sensor_samples(config: ForceSensorConfig, seed: int, duration: float = 1.0, R_WS=None):
    builder = DiagramBuilder()
    truth = builder.AddSystem(ConstantVectorSource(np.array([0.0, 0.0, 0.0, 1.0, 10.0, 0.0])))
    model = builder.AddSystem(ForceSensorModel(config=config, R_WS=np.eye(3) if R_WS is None else R_WS))
    builder.Connect(truth.get_output_port(), model.GetInputPort("true_wrench"))
    log = LogVectorOutput(model.GetOutputPort("wrench"), builder, publish_period=config.sample_period)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    diagram.SetRandomContext(context, RandomGenerator(seed))
    simulator.AdvanceTo(duration)
    data = log.FindLog(context).data()
    return data[:, 10:] - np.array([0.0, 0.0, 0.0, 1.0, 10.0, 0.0])[:, None]  # the reading's error


def test_sensor_noise_has_the_configured_sigma_per_axis_and_no_mean():
    """Without the filter and the bias, the reading minus the true wrench is white noise
    of the configured σ (force and moment axes), zero mean. Catches noise not scaled by
    σ, the moment σ applied to the force axes, or a drift in the noise."""
    config = ForceSensorConfig(noise_force=0.3, noise_moment=0.01, bias_force=[0.0] * 3, filter_cutoff=0.0)
    error = _sensor_samples(config, seed=1)
    assert error.shape[1] >= 7000
    np.testing.assert_allclose(error[3:].std(axis=1), 0.3, rtol=0.05)
    np.testing.assert_allclose(error[:3].std(axis=1), 0.01, rtol=0.05)
    assert np.all(np.abs(error[3:].mean(axis=1)) < 4 * 0.3 / math.sqrt(error.shape[1]))
    lag1 = np.corrcoef(error[4, :-1], error[4, 1:])[0, 1]
    assert abs(lag1) < 0.05  # white at the sensor's rate


def test_sensor_low_pass_leaves_the_first_order_filters_share_of_the_noise():
    """Through the 125 Hz first-order filter, white noise sampled every T_s keeps
    σ √((1 − a)/(1 + a)), a = exp(−T_s/τ), τ = 1/(2π f_c): ≈ 0.22 σ at the defaults.
    Catches a missing or mis-scaled filter (a cutoff taken as a time constant)."""
    config = ForceSensorConfig(bias_force=[0.0] * 3)
    error = _sensor_samples(config, seed=3, duration=2.0)
    a = math.exp(-config.sample_period * 2.0 * math.pi * config.filter_cutoff)
    expected = config.noise_force * math.sqrt((1.0 - a) / (1.0 + a))
    assert expected == pytest.approx(0.066, abs=0.002)
    np.testing.assert_allclose(error[3:, 100:].std(axis=1), expected, rtol=0.1)


def test_sensor_bias_is_given_in_the_sensor_frame():
    """The bias is a vector of the sensor's (the plate's) frame: with the plate yawed by
    90°, the bias along the sensor's +y reads along the world's −x. Catches a bias added
    in the world frame."""
    config = ForceSensorConfig(
        noise_force=0.0, noise_moment=0.0, bias_force=[0.0, 0.2, 0.0], filter_cutoff=0.0
    )
    R_WS = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # yaw 90°
    error = _sensor_samples(config, seed=1, duration=0.01, R_WS=R_WS)
    np.testing.assert_allclose(error[3:, -1], [-0.2, 0.0, 0.0], atol=1e-12)


def test_sensor_noise_is_seeded_same_seed_same_traces_other_seed_other():
    """Catches unseeded noise (runs that cannot be reproduced) or a seed that is ignored."""
    config = ForceSensorConfig()
    a, b, c = (_sensor_samples(config, seed=s, duration=0.05) for s in (7, 7, 8))
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 0.01


def test_a_closed_loop_run_with_the_sensor_is_reproducible_from_its_seed(tmp_path):
    """simulate.run seeds the diagram from realism.force_sensor.seed: two runs with seed 4
    give identical traces, seed 5 another. Catches the seed not reaching the run."""
    runs = {}
    for key, seed in (("a", 4), ("b", 4), ("c", 5)):
        overrides = f"realism: {{force_sensor: {{enabled: true, seed: {seed}}}}}\n"
        runs[key], _ = run(fig3_with(tmp_path, overrides, duration=0.3))
    np.testing.assert_array_equal(runs["a"]["f_n"], runs["b"]["f_n"])
    np.testing.assert_array_equal(runs["a"]["tau1"], runs["b"]["tau1"])
    assert np.abs(runs["a"]["f_n"] - runs["c"]["f_n"]).max() > 1e-3
    assert np.abs(runs["a"]["f_n_true"]).max() < 1e-9  # before contact the noise is all the sensor reads


# --- gear friction ----------------------------------------------------------------------


def test_friction_opposes_the_motion_is_odd_and_tends_to_coulomb_plus_viscous():
    """τ_f = −(τ_c tanh(v/v_s) + b v): v τ_f ≤ 0 everywhere, τ_f(−v) = −τ_f(v), τ_f(0) = 0,
    −(τ_c + b v) well above v_s, slope −(τ_c/v_s + b) at 0. Catches a sign that feeds
    energy in, a Coulomb part that does not saturate, or a non-smooth law."""
    v = np.linspace(-3.0, 3.0, 601)
    tau = friction_torque(v, 0.1, 0.02, 0.05)
    assert np.all(v * tau <= 0.0)
    np.testing.assert_allclose(friction_torque(-v, 0.1, 0.02, 0.05), -tau, atol=1e-15)
    assert friction_torque(np.array([0.0]), 0.1, 0.02, 0.05)[0] == 0.0
    np.testing.assert_allclose(friction_torque(np.array([2.0]), 0.1, 0.02, 0.05), [-(0.1 + 0.04)], rtol=1e-12)
    eps = 1e-7
    slope = friction_torque(np.array([eps]), 0.1, 0.02, 0.05) - friction_torque(
        np.array([-eps]), 0.1, 0.02, 0.05
    )
    assert slope[0] / (2 * eps) == pytest.approx(-friction_slope(0.1, 0.02, 0.05), rel=1e-6)


def test_friction_acts_on_the_joints_in_the_rigid_arm_and_on_the_motors_with_the_belt(tmp_path):
    """The friction system's generalized force equals the law on the arm's joints
    (rigid arm) or on the motor coordinates (belt: the gears sit before the belt), and
    is zero on the belt coordinates. Catches friction applied to the wrong coordinates."""
    for overrides, dofs_of in (
        (
            "realism: {friction: {enabled: true}}\n",
            lambda st: [j.velocity_start() for j in st.arm_model.joints],
        ),
        (
            "realism: {friction: {enabled: true}, belt: {enabled: true}}\n",
            lambda st: list(st.elastic.motor_v),
        ),
    ):
        built = build_diagram(fig3_with(tmp_path, overrides))
        plant, station = built.station.plant, built.station
        context = built.diagram.CreateDefaultContext()
        v = np.linspace(-0.3, 0.4, plant.num_velocities())
        plant.SetVelocities(plant.GetMyMutableContextFromRoot(context), v)
        friction = built.diagram.GetSubsystemByName("joint_friction")
        tau = friction.get_output_port().Eval(friction.GetMyContextFromRoot(context))
        f = built.scenario.realism.friction
        dofs = dofs_of(station)
        expected = np.zeros_like(v)
        expected[dofs] = friction_torque(v[dofs], f.coulomb, f.viscous, f.smoothing_speed)
        np.testing.assert_allclose(tau, expected, rtol=1e-14, atol=1e-15)
        assert np.count_nonzero(tau) == len(dofs) == station.arm_model.n


def test_friction_steps_the_plant_finely_enough_and_the_check_refuses_a_coarse_step(tmp_path):
    """Friction alone steps the plant at 0.5 ms (min_substeps 4), where its explicit slope
    × step × max λ(H⁻¹) stays below 1 for fig3's arm; at 2 ms the check before a run
    refuses it in one line. Catches friction integrated at a step where it chatters."""
    from nsdrake.reporting.run_folder import check_scenario

    scenario = fig3_with(tmp_path, "realism: {friction: {enabled: true}}\n")
    check_scenario(scenario)
    assert build_diagram(scenario).station.plant.time_step() == pytest.approx(5e-4)
    with pytest.raises(ScenarioError) as info:
        check_scenario(fig3_with(tmp_path, "realism: {friction: {enabled: true, min_substeps: 1}}\n"))
    assert "realism.friction: slope" in str(info.value) and "chatter" in str(info.value)


@pytest.mark.slow
def test_friction_at_its_plant_step_agrees_with_a_finer_one(tmp_path):
    """fig3 with friction at its 0.5 ms plant step and at 0.25 ms agree to 1% in the
    joint speeds (free approach and pressing) and the pressing force; at 2 ms the joints
    chatter as they break away from rest (measured while choosing min_substeps).
    Catches a plant step at which explicit friction makes numerical stick-slip that
    would pass for noise."""
    coarse, _ = run(fig3_with(tmp_path, "realism: {friction: {enabled: true}}\n", duration=2.6))
    fine, _ = run(
        fig3_with(
            tmp_path,
            "realism: {friction: {enabled: true}, physics: {enabled: true, substeps: 8}}\n",
            duration=2.6,
        )
    )
    assert coarse["f_n"].max() > 5.0
    # The impact and the force ramp are resolved differently by the two steps (contact, not
    # friction): compare the free approach and the steady pressing after it.
    t = coarse["t"]
    t_contact = t[np.argmax(coarse["f_n"] > 0.5)]
    free, pressing = t < t_contact - 0.05, t > t_contact + 0.3
    v_scale = np.abs(coarse.block("v")).max()
    np.testing.assert_allclose(coarse.block("v")[free], fine.block("v")[free], atol=0.01 * v_scale)
    np.testing.assert_allclose(coarse["f_n"][pressing], fine["f_n"][pressing], rtol=0.01)
    np.testing.assert_allclose(coarse.block("v")[pressing], fine.block("v")[pressing], atol=0.01 * v_scale)


# --- belt elasticity --------------------------------------------------------------------


def test_elastic_urdf_splits_each_driven_joint_and_keeps_everything_else():
    """joint → joint_motor (with the transmission) + joint_rotor + joint (the belt), the
    tool's drake: contact properties intact. Catches a split that renames the drake:
    tags (an XML round trip without the namespace loses the tool's stiffness and
    friction) or leaves the actuator on the link side."""
    text, split = elastic_urdf(ARM4)
    assert split == ["joint1", "joint2", "joint3", "joint4"]
    assert 'name="joint1_motor"' in text and 'name="joint1_rotor"' in text
    assert "<drake:point_contact_stiffness" in text and "<drake:mu_dynamic" in text
    assert text.count("<transmission") == 4 and '<joint name="joint4_motor"' in text


def _belt_station(tmp_path, plane="horizontal"):
    built = build_diagram(fig3_with(tmp_path, f"plane: {plane}\nrealism: {{belt: {{enabled: true}}}}\n"))
    return built, built.station, built.scenario.realism.belt


def test_the_belt_spring_torque_is_k_times_motor_minus_link_angle(tmp_path):
    """At a state with motor angles θ_m (q_m/N) and link angles q, the force elements
    give each belt coordinate k (θ_m − q) − d (q̇ − θ̇_m) and each motor coordinate
    nothing (the belt's reaction reaches the motor through the rotor body). Catches a
    spring on the wrong joint, a sign error, or a missing damper."""
    built, station, belt = _belt_station(tmp_path)
    plant, elastic = station.plant, station.elastic
    context = plant.CreateDefaultContext()
    q, theta_m = np.array([0.3, 0.9, 1.1, 0.5]), np.array([0.31, 0.88, 1.13, 0.49])
    v, vm = np.array([0.1, -0.2, 0.3, 0.0]), np.array([0.12, -0.25, 0.3, 0.05])
    plant.SetPositions(context, elastic.plant_positions(q, q - theta_m))
    x = np.zeros(plant.num_velocities())
    x[elastic.motor_v], x[elastic.belt_v] = vm, v - vm
    plant.SetVelocities(context, x)
    forces = MultibodyForces(plant)
    plant.CalcForceElementsContribution(context, forces)
    generalized = forces.generalized_forces()
    expected = belt.stiffness * (theta_m - q) - belt.damping * (v - vm)
    np.testing.assert_allclose(generalized[elastic.belt_v], expected, rtol=1e-12)
    np.testing.assert_allclose(generalized[elastic.motor_v], 0.0, atol=1e-12)


def test_the_motors_carry_the_reflected_rotor_inertia(tmp_path):
    """The mass matrix of the elastic plant has N² I_m more on each motor coordinate than
    the same plant without rotor inertia would. Catches a rotor inertia that never
    reaches the actuators (Drake's GetJointActuatorIndices is empty before Finalize)."""
    built, station, belt = _belt_station(tmp_path)
    plant, elastic = station.plant, station.elastic
    for index in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(index)
        assert actuator.default_rotor_inertia() == belt.rotor_inertia
        assert actuator.default_gear_ratio() == belt.gear_ratio
        assert actuator.joint().name().endswith("_motor")
    q = station.q0
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, elastic.plant_positions(q))
    H = plant.CalcMassMatrix(context)
    rigid = station.arm_model.plant
    rigid_context = rigid.CreateDefaultContext()
    rigid.SetPositions(rigid_context, q)
    H_arm = rigid.CalcMassMatrix(rigid_context)
    # θ_m moves the links and the 1 g placeholder rotors beyond it (< 1% here) besides its own
    # reflected inertia.
    reflected = belt.gear_ratio**2 * belt.rotor_inertia
    np.testing.assert_allclose(np.diag(H)[elastic.motor_v] - np.diag(H_arm), reflected, rtol=0.01)


def test_the_controller_reads_the_motor_encoders_and_the_traces_the_links(tmp_path):
    """Belt on: the controller's estimated_state is [θ_m; θ̇_m] (what a real controller
    measures), the logged state [θ_m + δ; θ̇_m + δ̇] (the link). Catches a controller fed
    the link state it could not measure, or traces of the motor side labelled q."""
    built, station, _ = _belt_station(tmp_path)
    plant, elastic = station.plant, station.elastic
    context = built.diagram.CreateDefaultContext()
    theta_m, delta = np.array([0.4, 0.9, 1.0, 0.6]), np.array([0.01, -0.02, 0.03, -0.04])
    plant.SetPositions(
        plant.GetMyMutableContextFromRoot(context), elastic.plant_positions(theta_m + delta, delta)
    )
    controller = built.controller
    estimated = controller.GetInputPort("estimated_state").Eval(controller.GetMyContextFromRoot(context))
    np.testing.assert_allclose(estimated[:4], theta_m, atol=1e-15)
    links = built.diagram.GetSubsystemByName("link_state")
    np.testing.assert_allclose(
        links.get_output_port().Eval(links.GetMyContextFromRoot(context))[:4], theta_m + delta, atol=1e-15
    )


def test_in_the_vertical_plane_the_belts_start_preloaded_by_gravity(tmp_path):
    """The start deflection δ = τ_g/k makes spring and gravity cancel on every link, so
    the arm starts at rest; the link angles are the scenario's q0. Catches a start with
    slack belts (the arm would drop at t = 0) or motors at q0 and links elsewhere."""
    built, station, belt = _belt_station(tmp_path, plane="vertical")
    plant, elastic = station.plant, station.elastic
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, station.plant_q0)
    forces = MultibodyForces(plant)
    plant.CalcForceElementsContribution(context, forces)
    gravity = plant.CalcGravityGeneralizedForces(context)
    link_q = elastic.link_state_matrix()[:4, : elastic.nq] @ station.plant_q0
    np.testing.assert_allclose(link_q, station.q0, atol=1e-15)
    total = forces.generalized_forces() + gravity
    assert np.abs(gravity[elastic.belt_v]).max() > 0.1  # not vacuous
    np.testing.assert_allclose(total[elastic.belt_v], 0.0, atol=1e-9)


# --- model error ------------------------------------------------------------------------


def test_scaled_urdf_changes_masses_and_inertias_only():
    """Every <mass> and inertia entry × factor, nothing else. Catches scaling the
    positions of the centres of mass, or a rewrite that drops the drake: tags."""
    scaled = scale_urdf_masses(ARM4, 0.8)
    assert scaled.count('<mass value="0.32000000000000006"/>') == 4
    assert '<mass value="0.04000000000000001"/>' in scaled
    assert 'izz="0.0016719999999999999"' in scaled
    strip = re.compile(r"<inertial\b.*?</inertial>", re.DOTALL)
    assert strip.sub("", scaled) == strip.sub("", ARM4)


def test_model_error_scales_the_controllers_model_not_the_arm(tmp_path):
    """mass_error −0.2: every link and the tool weigh 0.8 of the simulated arm's in the
    controller's model, with the simulated arm untouched. Catches scaling the simulated
    arm (no model error at all) or only some bodies."""
    built = build_diagram(fig3_with(tmp_path, "realism: {model_error: {enabled: true, mass_error: -0.2}}\n"))
    model, plant = built.controller.model.plant, built.station.plant
    for name in ("link1", "link2", "link3", "link4", "tool"):
        m_model = model.GetBodyByName(name).default_mass()
        m_arm = plant.GetBodyByName(name).default_mass()
        assert m_model == pytest.approx(0.8 * m_arm, rel=1e-12), name
    clean = build_diagram(fig3_with(tmp_path))
    assert clean.controller.model.plant.GetBodyByName("link1").default_mass() == 0.4
    assert plant.GetBodyByName("link1").default_mass() == 0.4


# --- measures -----------------------------------------------------------------------------


def test_force_oscillation_finds_the_frequency_and_amplitude_and_ignores_drift():
    """A 23 Hz, 0.3 N oscillation on a drift of 0.5 N/s and a 0.5 Hz swell: 23 Hz, RMS
    0.3/√2, peak-to-peak 0.6. Catches drift counted as oscillation."""
    t = np.arange(0.0, 3.0, 0.002)
    e = 0.3 * np.sin(2 * np.pi * 23 * t) + 0.5 * t + np.sin(2 * np.pi * 0.5 * t)
    frequency, rms, p2p = force_oscillation(t, e)
    assert frequency == pytest.approx(23.0, abs=0.4)
    assert rms == pytest.approx(0.3 / math.sqrt(2), rel=0.03)
    assert p2p == pytest.approx(0.6, rel=0.15)
    assert force_oscillation(t, 0.5 * t)[1] < 1e-3  # a pure ramp: only the filter's edge effects


def test_an_oscillation_below_the_noise_floor_has_no_frequency():
    """The same 0.3 N oscillation (RMS 0.21 N) has its frequency above a floor of 0.2 N and
    none above 0.22 N, its RMS and peak-to-peak either way; a drift with a 1e-6 N ripple
    (the clean run's kind) has none at fig3's floor. Catches the first bin above the cutoff
    printed as the frequency of nothing (the table's 5.57 Hz)."""
    t = np.arange(0.0, 3.0, 0.002)
    e = 0.3 * np.sin(2 * np.pi * 23 * t) + 0.5 * t
    assert force_oscillation(t, e, floor=0.2)[0] == pytest.approx(23.0, abs=0.4)
    frequency, rms, p2p = force_oscillation(t, e, floor=0.22)
    assert math.isnan(frequency) and rms == pytest.approx(0.3 / math.sqrt(2), rel=0.03) and p2p > 0.5
    ripple = 0.5 * t + 1e-6 * np.sin(2 * np.pi * 40 * t)
    assert math.isnan(force_oscillation(t, ripple, floor=0.01)[0])


def test_drift_rate_is_the_least_squares_slope():
    """A ramp of 0.8 N/s under a 0.3 N oscillation: 0.8 N/s; a constant offset: 0."""
    t = np.arange(2.5, 5.0, 0.002)
    assert drift_rate(t, 3.0 + 0.8 * (t - 2.5) + 0.3 * np.sin(2 * np.pi * 23 * t)) == pytest.approx(
        0.8, rel=0.01
    )
    assert drift_rate(t, np.full_like(t, 2.7)) == pytest.approx(0.0, abs=1e-12)


def test_wrong_way_share_counts_only_active_periods_against_the_gain():
    """Catches a share counted over inactive periods or with the gain's sign ignored."""
    values = np.array([5.0, 4.0, 4.5, 3.0, 3.5, 3.6])
    active = np.array([True, True, False, True, True, True])
    # changes from rows 0–4: −1, +0.5, −1.5 (inactive), +0.5, +0.1; row 5 starts no period
    share, periods = wrong_way_share(values, -1.0, active)
    assert periods == 4 and share == pytest.approx(3 / 4)
    share, _ = wrong_way_share(values, +1.0, active)
    assert share == pytest.approx(1 / 4)


def test_every_rung_has_a_switch_and_every_value_a_unit():
    """Each rung's dataclass has ``enabled`` (off) and a docstring; each of its other
    fields is preceded in the source by a comment that ends with its unit in brackets.
    Catches an undocumented rung or value."""
    import inspect

    for name in RUNGS:
        cls = type(getattr(RealismConfig(), name))
        assert getattr(RealismConfig(), name).enabled is False and cls.__doc__
        lines = inspect.getsource(cls).splitlines()
        for field in cls.__dataclass_fields__:
            if field == "enabled":
                continue
            k = next(i for i, ln in enumerate(lines) if ln.strip().startswith(f"{field}:"))
            comment = lines[k - 1].strip()
            assert comment.startswith("#") and re.search(r"\[[^\]]*\]\.?$", comment), (name, field)


# --- the ladder in closed loop ------------------------------------------------------------


@pytest.mark.slow
def test_each_rung_moves_fig3s_figures_the_way_physics_predicts(tmp_path):
    """``nsdrake compare realism`` for 3.5 s (contact at 1.27 s, at 2.5 s with every rung):
    each rung against the clean run, in the direction its physics predicts. Catches a
    rung that is wired but does nothing, or that does something else."""
    from nsdrake.studies.compare import load_family, run_family

    result = run_family(load_family("realism"), tmp_path, duration=3.5, jobs=2)
    rows = [dict(row) for row in result.rows]
    clean, physics, sensor, friction, belt, delay, model, everything, real_rotor = rows
    # Finer physics: a torque held over a continuous plant lags by half a period, the
    # null-space loop (K_n T = 0.2) tracks a little worse; force and position hardly move.
    assert physics["en_rms"] > 1.3 * clean["en_rms"]
    assert abs(physics["force_error_rms"] - clean["force_error_rms"]) < 0.01
    # Sensor: white noise of σ 0.3 N through the 125 Hz filter leaves ≈ 0.066 N; the
    # controller regulates the reading, so the true force is off by the 0.1 N bias.
    assert sensor["force_oscillation_rms"] == pytest.approx(0.066, rel=0.3)
    assert sensor["force_error_mean"] - sensor["true_force_error_mean"] == pytest.approx(0.1, abs=0.01)
    assert sensor["true_force_error_rms"] < sensor["force_error_rms"]
    # Friction opposes every motion and the impedance law has no integral action: a
    # slower approach, a steady force offset, worse tracking along the plate and in the
    # null space — but no oscillation.
    assert friction["first_contact_time"] > clean["first_contact_time"] + 0.3
    assert friction["force_error_mean"] > 1.0
    assert friction["tangential_position_error_rms"] > 10 * clean["tangential_position_error_rms"]
    assert friction["en_rms"] > 100 * clean["en_rms"]
    assert friction["force_oscillation_rms"] < 0.01 and friction["force_oscillation_frequency"] == ""
    # … and the offset is two parts: the spring of the normal reference, frozen 23 mm
    # beyond the tool when contact came late, and the joints' friction seen along the normal.
    assert friction["reference_offset_force"] == pytest.approx(2.3, abs=0.3)
    assert clean["force_oscillation_frequency"] == "" and abs(clean["reference_offset_force"]) < 0.05
    residual = friction_force_balance(tmp_path / "variants" / "03-gear-friction" / "traces.csv")
    assert np.sqrt(np.mean(residual**2)) < 0.05
    # Belt: the controller's model lacks the rotors (slower approach), the motor
    # encoders miss the belts' deflection (a force offset), and the belt modes ring
    # after contact (tens of Hz, newtons peak to peak).
    assert belt["first_contact_time"] > clean["first_contact_time"] + 0.2
    assert belt["force_error_mean"] > 0.3
    assert 15.0 < belt["force_oscillation_frequency"] < 45.0 and belt["force_oscillation_p2p"] > 1.0
    # Delay and a lighter model both lower the loops' effective gains or margins.
    assert delay["en_rms"] > 2 * clean["en_rms"]
    assert delay["tangential_position_error_rms"] > 1.5 * clean["tangential_position_error_rms"]
    assert model["en_rms"] > 2 * clean["en_rms"]
    # Everything: visibly noisy, oscillating, offset.
    assert everything["force_oscillation_rms"] > 0.1 > 1000 * clean["force_oscillation_rms"]
    assert everything["force_error_rms"] > 1.0
    # A real servo's rotor behind the belt: fig3's gains diverge.
    assert "diverged_at" in real_rotor and float(real_rotor["diverged_at"].split(" s")[0]) < 0.1
    assert (tmp_path / "force.png").is_file() and (tmp_path / "table.md").is_file()


def friction_force_balance(path) -> np.ndarray:
    """f_n − f_d − [K_p,n nᵀ(x_d − x) + nᵀ J H⁻¹ τ_f] / K_f per row of the fig3 window of the
    friction variant's traces: the impedance law in the normal direction at rest
    (ẍ_c = 0 along n), with the joints' friction torques τ_f(q̇) (the rung's law, from the
    logged q̇) as the one disturbance the controller does not compensate; J and H from
    plain plant calls. Near zero if that is all the force error is."""
    from drake_reference import plant_terms

    from nsdrake.experiment.traces import Traces

    scenario = load_scenario("fig3")
    friction, imp = scenario.realism.friction, scenario.impedance
    station = build_diagram(scenario).station
    traces = Traces.read_csv(path)
    t, n = traces["t"], station.normal
    window = t >= t[np.flatnonzero(traces["f_n"] >= scenario.reference.contact_threshold)[0]] + 0.5
    q, v = traces.block("q"), traces.block("v")
    residual = []
    for k in np.flatnonzero(window):
        ref = plant_terms(station.arm_model, q[k], v[k])
        tau_f = friction_torque(v[k], friction.coulomb, friction.viscous, friction.smoothing_speed)
        offset = np.array([traces[f"{a}_d"][k] - traces[a][k] for a in ("x", "y")])
        pushed = imp.K_p_normal * n @ offset + n @ ref["J"] @ np.linalg.solve(ref["H"], tau_f)
        residual.append(traces["f_n"][k] - traces["f_d"][k] - pushed / imp.K_f)
    return np.array(residual)

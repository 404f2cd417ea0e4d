"""The controller's tick run three ways gives one τ (issue 20, item 2).

The named systems (``NullSpaceImpedanceController``), the fused system
(``NullSpaceImpedanceController(fused=True)``) and the plain ``ControllerStep`` run the
same stages (nsdrake.control.stages). Each closed-loop run here simulates the scenario with
the named systems and with the fused system, logging the controller's inputs and τ at every
control tick; the plain step is then called once per logged tick with the logged inputs, as
a robot's loop would. All three must agree at every tick to 1e-12 relative (they run the
same compiled code on the same numbers, so they agree to the last bit).

What the comparison catches: a stage dropped or run out of order in the fused system or in
the plain step (the selector's commit after the selection, the stores before the limits,
the pending discrete update skipped, …) changes τ from the first tick or the first mode
switch on; so does a discrete update at the wrong instant (Drake's event order: the
stores in the unrestricted update with the plant's step, the selector's commit in the
discrete update that follows, at the same time but from the post-step state).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import fig3_with
from drake_reference import plant_terms
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput
from reference_math import task_space_inertia

from nsdrake import ControllerModel, ControllerStep, NullSpaceImpedanceController
from nsdrake.control.orientation import rotation_to_quaternion
from nsdrake.experiment import diagram as assembly
from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.station.models import models_dir
from nsdrake.station.plant import desired_tool_orientation

EXACT = 1e-12  # relative, per tick
LOGGED = ("generalized_force", "desired_null_space_velocity", "mode", "saturation", "d_min", "lyapunov")


def scenario_controller(scenario):
    def make(station, structure):
        return assembly.build_controller(scenario, station, station.sensor.p_WSo, structure=structure)

    return make


def closed_loop(scenario, structure: str, make_controller=None) -> dict:
    """The scenario's diagram (as nsdrake.experiment.diagram builds it, without the realism
    rungs) with the controller in ``structure`` ("systems" or "fused"), simulated; returns
    the logged controller inputs and outputs, one column per control tick."""
    builder = DiagramBuilder()
    station = add_scenario_station(builder, scenario)
    reference = assembly.add_reference(builder, scenario, station)
    controller = (make_controller or scenario_controller(scenario))(station, structure)
    builder.AddSystem(controller)
    assembly.connect_controller(builder, station, controller, reference)
    R_d = None
    if station.arm_model.m_r:
        R_d = desired_tool_orientation(station, scenario.reference.orientation)
        assembly.add_orientation_reference(builder, controller, R_d)
    ports = {"state": station.ports.state, "wrench": station.ports.wrench}
    ports |= {name: reference.GetOutputPort(name) for name in ("x_d", "xdot_d", "xddot_d", "f_d")}
    ports |= {name: controller.GetOutputPort(name) for name in LOGGED}
    loggers = {
        name: LogVectorOutput(port, builder, publish_period=scenario.control_period)
        for name, port in ports.items()
    }
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    plant_context = station.plant.GetMyMutableContextFromRoot(context)
    station.plant.SetPositions(plant_context, station.q0)
    station.plant.SetVelocities(plant_context, station.v0)
    simulator.Initialize()
    simulator.AdvanceTo(scenario.duration)
    logs = {name: logger.FindLog(context).data() for name, logger in loggers.items()}
    logs["t"] = loggers["state"].FindLog(context).sample_times()
    logs["controller"], logs["R_d"] = controller, R_d
    return logs


def plain_steps(logs: dict) -> np.ndarray:
    """τ of a ControllerStep built from the same model, task and config, called once per
    logged tick with the logged state, wrench and reference. (n, ticks)."""
    controller = logs["controller"]
    step = ControllerStep(
        controller_model=controller.model,
        normal=controller.normal,
        config=controller.config,
        wrench_point=controller.wrench_point,
    )
    n = controller.model.n
    rotation = () if logs["R_d"] is None else (rotation_to_quaternion(logs["R_d"]), np.zeros(3), np.zeros(3))
    out = np.empty((n, len(logs["t"])))
    for k, t in enumerate(logs["t"]):
        x = logs["state"][:, k]
        desired = (logs[name][:, k] for name in ("x_d", "xdot_d", "xddot_d"))
        result = step.step(t, x[:n], x[n:], logs["wrench"][:, k], *desired, logs["f_d"][0, k], *rotation)
        out[:, k] = result.tau
    return out


def worst_relative(a: np.ndarray, b: np.ndarray) -> float:
    """max over ticks of max|a_k − b_k| / max|b_k| (columns are ticks); equal entries, ∞ (no
    obstacle: d_min) and nan (ν of a posture law) included, differ by 0."""
    same = (a == b) | (np.isnan(a) & np.isnan(b))  # nan: ν and eⁿ where a law has none
    with np.errstate(invalid="ignore"):  # ∞ − ∞ where both are ∞: equal, counted 0
        difference = np.where(same, 0.0, np.abs(a - b))
    scale = np.maximum(np.max(np.abs(np.where(np.isfinite(b), b, 0.0)), axis=0), 1e-300)
    return float(np.max(np.max(difference, axis=0) / scale))


def assert_three_ways_agree(scenario, make_controller=None) -> dict:
    named = closed_loop(scenario, "systems", make_controller)
    fused = closed_loop(scenario, "fused", make_controller)
    for name in LOGGED:
        assert worst_relative(fused[name], named[name]) <= EXACT, name
    assert worst_relative(plain_steps(named), named["generalized_force"]) <= EXACT
    return named


def test_fig3_approach_three_ways():
    """fig3's first 0.4 s: the approach, mode 0 → 2 at the first tick, obstacle and
    criteria gradients active, the q̈_dⁿ feed-forward from the second tick on."""
    named = assert_three_ways_agree(load_scenario("fig3", duration=0.4))
    assert set(np.unique(named["mode"])) == {2.0}
    assert np.max(np.abs(named["desired_null_space_velocity"])) > 0.1  # the null space is commanded


def test_panda_pose_task_with_obstacles_three_ways():
    """panda_wipe's first 0.3 s: the full pose task, the obstacle criterion inside its
    influence distance (the table), the joint-limit criterion, gravity."""
    named = assert_three_ways_agree(load_scenario("panda_wipe", duration=0.3))
    assert np.max(named["d_min"]) < 0.1  # the obstacle level acts


def test_actuator_limits_three_ways(tmp_path):
    """fig3 with torque and torque-rate limits that bind from the start (its first 0.3 s
    use up to 0.44 N m and 21 N m/s on joint 1 unlimited): τ₀ scaled (0 < s < 1) and the
    task torque clipped, the rate window around the stored previous τ. (Before issue 29
    looser limits seemed to bind here: the old limiter's chatter dropped τ₀ whenever
    |τ₀_j| exceeded one period's rate step.)"""
    limits = "actuator_limits: {torque: {joint1: 0.3, joint2: 4.0, joint3: 0.15, joint4: 1.5}, torque_rate: {joint1: 10.0, joint2: 200.0, joint3: 8.0, joint4: 50.0}}\n"  # noqa: E501
    named = assert_three_ways_agree(fig3_with(tmp_path, limits, duration=0.3))
    s, clipped = named["saturation"]
    assert np.any((s > 0.0) & (s < 1.0)) and np.max(clipped) >= 1  # both limits bind


def test_a_blended_mode_switch_three_ways(tmp_path):
    """priority_demo's first 0.15 s with the manipulability band moved onto its start
    (w_lim 0.0765, w_band 0.0005; w is 0.0762 at the start and rises): mode 3, then the
    switch to mode 2 at 0.05 s, blended over 0.05 s (blend_time), the three ways agreeing
    at every tick through the switch and the blend. The fast twin of
    test_priority_demo_every_branch_three_ways (6 s, slow). Catches the selector's switch
    committed at the tick's own time instead of the previous tick's (equivalent in the
    Drake systems, whose discrete update runs at t_previous, but the blend one period late
    in ControllerStep: issue 46, mistake 9), and any stage of the blend run differently."""
    path = tmp_path / "early_switch.yaml"
    path.write_text("desired_null_space:\n  selector: {w_lim: 0.0765, w_band: 0.0005, blend_time: 0.05}\n")
    named = assert_three_ways_agree(load_scenario("priority_demo", config=path, duration=0.15))
    mode, t = named["mode"][0], named["t"]
    switches = [(t[k + 1], mode[k], mode[k + 1]) for k in np.flatnonzero(np.diff(mode))]
    assert mode[0] == 3.0 and [(m0, m1) for _, m0, m1 in switches] == [(3.0, 2.0)]
    assert 0.02 < switches[0][0] < 0.15 - 0.05  # the whole blend inside the run


@pytest.mark.slow
def test_fig3_whole_run_three_ways():
    """fig3 through contact, pressing and sliding (5 s)."""
    assert_three_ways_agree(load_scenario("fig3"))


@pytest.mark.slow
def test_priority_demo_every_branch_three_ways():
    """priority_demo: manipulability (mode 3), joint torque (mode 2), obstacle avoidance
    (mode 1), each switch blended, hysteresis on both limits."""
    named = assert_three_ways_agree(load_scenario("priority_demo"))
    assert {1.0, 2.0, 3.0} <= set(np.unique(named["mode"]))


@pytest.mark.slow
def test_panda_wipe_through_contact_three_ways(tmp_path):
    """panda_wipe to 1.5 s with the unguarded first contact of before issue 35 (the approach
    at 1.5 cm/s stopped at once when contact is detected, ≈ 1.27 s), where the torque-rate
    limit binds (the shipped guarded contact never binds it)."""
    unguarded = tmp_path / "unguarded.yaml"
    unguarded.write_text(
        "reference: {approach_speed: 0.015, touch_speed: 0.0, slow_down_distance: 0.0, stop_time: 0.0}\n"
    )
    named = assert_three_ways_agree(load_scenario("panda_wipe", config=unguarded, duration=1.5))
    assert np.min(named["saturation"][0]) < 1.0


def test_drake_terms_three_ways():
    """A controller whose model terms come from Drake's plant calls (ControllerModel.from_plant,
    no Pinocchio, no obstacles) runs the same stages: fig3's first 0.3 s three ways."""
    scenario = load_scenario("fig3", duration=0.3)
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(str(models_dir() / "arm4.urdf"))
    plant.Finalize()
    model = ControllerModel.from_plant(plant, tool_frame="tool", task_axes=("x", "y"))
    config = assembly.controller_config(scenario)
    config.desired_null_space.criteria.obstacle.gain = 0.0  # a plant alone knows no obstacles

    def controller(station, structure):
        return NullSpaceImpedanceController(
            controller_model=model, normal=station.normal, config=config,
            wrench_point=station.sensor.p_WSo, fused=structure == "fused",
        )  # fmt: skip

    named = assert_three_ways_agree(scenario, controller)
    assert named["controller"].model.dynamics == "drake"


FIG3_POSTURE = "{q_d: {joint1: 0.401, joint2: 0.972, joint3: 1.012, joint4: 0.614}, offset: {joint1: 0.3}, offset_time: 0.1, offset_ramp_time: 0.1"  # noqa: E501


@pytest.mark.parametrize(
    "law",
    [
        f"desired_null_space: {{source: posture, posture: {FIG3_POSTURE}, gain: -0.1224}}}}",
        "null_space: {law: kinematic_posture_pd, posture_stiffness: 0.3, posture_damping: 0.03, "
        "projector_damping: 0.2}\n"
        f"desired_null_space: {{posture: {FIG3_POSTURE}}}}}",
        "null_space: {law: dynamically_consistent_posture_pd, posture_stiffness: 2500.0, "
        "posture_damping: 100.0}\n"
        f"desired_null_space: {{posture: {FIG3_POSTURE}}}}}",
        "null_space: {law: dynamically_consistent_torque_pd, posture_stiffness: 12.2, "
        "posture_damping: 0.49}\n"
        f"desired_null_space: {{posture: {FIG3_POSTURE}}}}}",
    ],
    ids=[
        "paper with the posture criterion",
        "kinematic posture PD, damped inverse",
        "dynamically consistent posture PD",
        "dynamically consistent torque PD",
    ],
)
def test_null_space_laws_three_ways(tmp_path, law):
    """fig3's first 0.3 s with each null-space law of issue 19 and a posture q_d(t) that
    moves from 0.1 s (nsdrake.control.null_space_laws): the posture laws' stage and the
    posture criterion's q̇_dⁿ run the same in all three ways (ν and eⁿ nan for the PD laws)."""
    named = assert_three_ways_agree(fig3_with(tmp_path, law, duration=0.3))
    assert np.max(np.abs(named["generalized_force"])) > 0.0


def test_a_force_step_changes_tau_in_all_three_ways():
    """A step of the desired force f_d at a fixed state, as a user's own diagram sees it when
    its force source changes: the named systems, the fused system and ControllerStep give
    the same τ before and after the step (1e-12 relative), and the task torque moves by
    Jᵀ Λ n K_f Δf_d from plain plant calls (1e-9 relative; Eq. 7 with Eq. 8's force term).
    Catches f_d missing from a stage's prerequisites of calculation (the named
    ImpedanceController's cached task torque then outlives the step: the closed-loop runs
    above cannot see it, since the state changes at every tick and recomputes it anyway)."""
    model = ControllerModel.from_urdf(
        str(models_dir() / "arm4.urdf"), tool_frame="tool", task_axes=("x", "y")
    )
    config = assembly.controller_config(load_scenario("fig3"))
    config.impedance.max_task_inertia = np.inf  # Λ uncapped: the plain plant calls' Λ
    config.desired_null_space.criteria.obstacle.gain = 0.0  # the URDF alone knows no obstacles
    normal = np.array([0.0, 1.0])
    q, v = np.array([0.4, 0.9, 1.0, 0.6]), np.array([0.1, -0.2, 0.3, -0.1])
    T = plant_terms(model.arm, q, v)
    inputs = {
        "estimated_state": np.concatenate([q, v]),
        "measured_wrench": np.array([0.0, 0.0, 0.0, 0.0, 2.0, 0.0]),
        "desired_position": T["x"] + [0.01, 0.0],
        "desired_velocity": np.zeros(2),
        "desired_acceleration": np.zeros(2),
    }
    forces = (5.0, 15.0)

    def diagram_taus(fused: bool) -> list[tuple[np.ndarray, np.ndarray]]:
        controller = NullSpaceImpedanceController(
            controller_model=model, normal=normal, config=config, fused=fused
        )
        context = controller.CreateDefaultContext()
        for name, value in inputs.items():
            controller.GetInputPort(name).FixValue(context, value)
        out = []
        for f_d in forces:  # the same context: only the force input changes
            controller.GetInputPort("desired_force").FixValue(context, [f_d])
            out.append(
                tuple(
                    controller.GetOutputPort(p).Eval(context).copy()
                    for p in ("generalized_force", "task_torque")
                )
            )
        return out

    step = ControllerStep(controller_model=model, normal=normal, config=config)
    plain = []
    for f_d in forces:
        step.reset()
        w = inputs["measured_wrench"]
        result = step.step(0.0, q, v, w, inputs["desired_position"], np.zeros(2), np.zeros(2), f_d)
        plain.append((result.tau.copy(), result.task_torque.copy()))
    J = T["J"]
    Lambda = task_space_inertia(J, np.linalg.inv(T["H"]))
    expected = J.T @ Lambda @ normal * config.impedance.K_f * (forces[1] - forces[0])
    assert np.allclose(plain[1][1] - plain[0][1], expected, rtol=0, atol=1e-9 * np.linalg.norm(expected))
    for fused in (False, True):
        for (tau, task), (tau_plain, task_plain) in zip(diagram_taus(fused), plain, strict=True):
            assert np.max(np.abs(tau - tau_plain)) <= EXACT * np.max(np.abs(tau_plain)), fused
            assert np.max(np.abs(task - task_plain)) <= EXACT * np.max(np.abs(task_plain)), fused


def test_a_change_of_any_input_changes_tau_in_all_three_ways():
    """Each input of the controller changed at a fixed state, after τ was evaluated: the
    named systems and the fused system give ControllerStep's τ for the new inputs (1e-12
    relative), and τ did change. Catches any input missing from a stage's prerequisites of
    calculation (the f_d of issue 28's mistake 1 is one; the state, the references, the
    measured wrench and the given q̇_dⁿ are the others), which only a change at a fixed
    state shows."""
    model = ControllerModel.from_urdf(
        str(models_dir() / "arm4.urdf"), tool_frame="tool", task_axes=("x", "y")
    )
    config = assembly.controller_config(load_scenario("fig3"))
    config.desired_null_space.criteria.obstacle.gain = 0.0  # the URDF alone knows no obstacles
    normal = np.array([0.0, 1.0])
    q, v = np.array([0.4, 0.9, 1.0, 0.6]), np.array([0.1, -0.2, 0.3, -0.1])
    base = {
        "estimated_state": np.concatenate([q, v]),
        "measured_wrench": np.array([0.0, 0.0, 0.0, 0.0, 2.0, 0.0]),
        "desired_position": plant_terms(model.arm, q, v)["x"] + [0.01, 0.0],
        "desired_velocity": np.zeros(2),
        "desired_acceleration": np.zeros(2),
        "desired_force": np.array([5.0]),
        "desired_null_space_velocity": np.array([0.1, -0.1, 0.05, 0.0]),
    }
    changes = {
        "estimated_state": np.concatenate([q + 0.01, v]),
        "measured_wrench": np.array([0.1, 0.0, 0.3, 1.0, 4.0, 0.0]),
        "desired_position": base["desired_position"] + [0.0, 0.005],
        "desired_velocity": np.array([0.02, -0.01]),
        "desired_acceleration": np.array([0.3, 0.1]),
        "desired_force": np.array([15.0]),
        "desired_null_space_velocity": np.array([-0.1, 0.2, 0.0, 0.1]),
    }
    step = ControllerStep(controller_model=model, normal=normal, config=config)

    def plain(inputs: dict) -> np.ndarray:
        step.reset()
        x = inputs["estimated_state"]
        refs = (inputs[n] for n in ("desired_position", "desired_velocity", "desired_acceleration"))
        qns = inputs["desired_null_space_velocity"]
        out = step.step(0.0, x[:4], x[4:], inputs["measured_wrench"], *refs, inputs["desired_force"][0],
                        desired_null_space_velocity=qns)  # fmt: skip
        return out.tau.copy()

    before = plain(base)
    for fused in (False, True):
        controller = NullSpaceImpedanceController(
            controller_model=model, normal=normal, config=config, fused=fused
        )
        for name, value in changes.items():
            context = controller.CreateDefaultContext()
            for port, fixed in base.items():
                controller.GetInputPort(port).FixValue(context, fixed)
            tau = controller.GetOutputPort("generalized_force").Eval(context)
            assert np.max(np.abs(tau - before)) <= EXACT * np.max(np.abs(before))
            controller.GetInputPort(name).FixValue(context, value)
            tau = controller.GetOutputPort("generalized_force").Eval(context)
            after = plain(base | {name: value})
            assert np.max(np.abs(after - before)) > 1e-6 * np.max(np.abs(before)), name  # the change acts
            assert np.max(np.abs(tau - after)) <= EXACT * np.max(np.abs(after)), (name, fused)

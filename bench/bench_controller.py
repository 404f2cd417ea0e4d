"""Benchmark: CPU time per control tick inside real simulations, and the controller's
cost per step on a 4-joint and a 7-joint arm.

    python bench/bench_controller.py [--repeats N] [--steps N] [--panda-repeats N]

- ``fig3_tick_us``: process CPU time of ``Simulator.AdvanceTo`` over the fig3 run
  (5 s, 2500 control ticks; building the diagram excluded), divided by the ticks.
- ``baseline_tick_us``: the same plant, contact and force sensor, the joints driven
  by Drake's C++ JointStiffnessController along fig3's own joint trajectory (so
  the tool presses and slides on the plate as in fig3), state and force logged.
  Runs are interleaved with fig3's, so both see the same machine load; ``ratio``
  is fig3 over baseline.
- ``panda_wipe_tick_us``: the same for the shipped panda_wipe (28 s at 1 kHz, 28000
  ticks: the Panda with gravity, the table on its sensor, the post, the full pose task,
  obstacle and joint-limit criteria), median of ``--panda-repeats`` runs (at least 3).
- ``controller_step_us_4dof`` / ``_7dof``: the controller diagram's
  ``generalized_force`` evaluated hot at fresh states (a new ``estimated_state``
  each call, as a real-robot loop would), on fig3's arm and controller, and on
  the Panda (urdf/panda.urdf) with a 3-D position task, joint-torque and
  manipulability criteria.
- ``plain_step_us_4dof`` / ``_7dof``: ``nsdrake.ControllerStep.step`` (the fused tick as
  a plain call, no Drake system around it) at fresh states, ``--plain-calls`` calls
  (at least 20 000), each timed on its own: ``{"median": …, "p99_9": …, "p99_9_cpu": …}``
  [µs], the wall-clock median and 99.9th percentile, and the 99.9th percentile of the
  thread's CPU time per call (on a shared machine the wall-clock tail is the scheduler's:
  a call preempted by another process waits a time slice, milliseconds). 4dof:
  fig3's controller; 7dof: panda_wipe's (the Panda, the full pose task, the obstacle
  and joint-limit criteria, the actuator limits).
- ``fused_ratio``: fig3 with the fused controller (one LeafSystem) over the baseline,
  interleaved with the other runs as ``ratio`` is.
- ``systems_step_over_floor``: ``controller_step_us_4dof`` over the floor that
  bench_dispatch_floor.py measures (the same diagram with its math replaced by stored
  values), measured here after everything else.

Every figure is a median over ``--repeats`` runs. The last line is one JSON object.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import time

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import JointStiffnessController
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from nsdrake import ControllerConfig, ControllerModel, ControllerStep, NullSpaceImpedanceController
from nsdrake.experiment.diagram import build_controller, build_diagram
from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.experiment.simulate import collect_traces
from nsdrake.station.models import models_dir


def simulate_cpu(diagram, plant, q0, v0, duration: float) -> tuple[float, object]:
    """CPU seconds of Initialize + AdvanceTo(duration); the diagram is built already."""
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, q0)
    plant.SetVelocities(plant_context, v0)
    t0 = time.process_time()
    simulator.Initialize()
    simulator.AdvanceTo(duration)
    return time.process_time() - t0, context


def fig3_run(scenario, structure: str = "systems"):
    built = build_diagram(dataclasses.replace(scenario, controller_structure=structure))
    st = built.station
    cpu, context = simulate_cpu(built.diagram, st.plant, st.q0, st.v0, scenario.duration)
    return cpu, collect_traces(built, context)


def tick_us(scenario) -> float:
    """CPU µs per control tick of Initialize + AdvanceTo over the scenario (diagram built already)."""
    built = build_diagram(scenario)
    st = built.station
    cpu, _ = simulate_cpu(built.diagram, st.plant, st.q0, st.v0, scenario.duration)
    return cpu / round(scenario.duration / scenario.control_period) * 1e6


def baseline_run(scenario, traces) -> float:
    builder = DiagramBuilder()
    station = add_scenario_station(builder, scenario)
    plant, n = station.plant, station.arm_model.n
    trajectory = PiecewisePolynomial.FirstOrderHold(
        traces["t"], np.vstack([traces.block("q").T, traces.block("v").T])
    )
    desired = builder.AddSystem(TrajectorySource(trajectory))
    controller = builder.AddSystem(JointStiffnessController(plant, np.full(n, 20.0), np.full(n, 0.5)))
    builder.Connect(plant.get_state_output_port(), controller.get_input_port_estimated_state())
    builder.Connect(desired.get_output_port(), controller.get_input_port_desired_state())
    builder.Connect(controller.get_output_port_actuation(), station.ports.actuation)
    LogVectorOutput(plant.get_state_output_port(), builder, publish_period=scenario.control_period)
    LogVectorOutput(station.ports.wrench, builder, publish_period=scenario.control_period)
    cpu, _ = simulate_cpu(builder.Build(), plant, station.q0, station.v0, scenario.duration)
    return cpu


def step_cost(controller: NullSpaceImpedanceController, q0: np.ndarray, steps: int, seed: int = 0) -> float:
    """µs per ``generalized_force`` evaluation at a fresh state (median-free: one run)."""
    context = controller.CreateDefaultContext()
    n, m = controller.model.n, controller.model.m
    x0 = controller.GetOutputPort("task_position")
    controller.GetInputPort("estimated_state").FixValue(context, np.concatenate([q0, np.zeros(n)]))
    x_d = x0.Eval(context).copy()
    for name, value in (
        ("measured_wrench", np.zeros(6)),
        ("desired_position", x_d),
        ("desired_velocity", np.zeros(m)),
        ("desired_acceleration", np.zeros(m)),
        ("desired_force", [5.0]),
    ):
        controller.GetInputPort(name).FixValue(context, value)
    rng = np.random.default_rng(seed)
    states = np.hstack([q0 + 0.05 * rng.standard_normal((256, n)), 0.2 * rng.standard_normal((256, n))])
    state_port = controller.GetInputPort("estimated_state")
    tau = controller.GetOutputPort("generalized_force")
    for i in range(64):  # warm up
        state_port.FixValue(context, states[i % 256])
        tau.Eval(context)
    t0 = time.process_time()
    for i in range(steps):
        state_port.FixValue(context, states[i % 256])
        tau.Eval(context)
    return (time.process_time() - t0) / steps * 1e6


def fig3_controller():
    scenario = load_scenario("fig3")
    station = add_scenario_station(DiagramBuilder(), scenario)
    return build_controller(scenario, station, station.sensor.p_WSo), station.q0


PANDA_Q0 = np.array([0.0, 0.3, 0.0, -2.0, 0.0, 2.3, 0.8])  # elbow up, tool in front of the base


def panda_controller():
    model = ControllerModel.from_urdf(
        models_dir() / "panda.urdf", tool_frame="tool", task_axes=("x", "y", "z")
    )
    config = ControllerConfig()
    config.desired_null_space.criteria.joint_torque.gain = -0.01
    config.desired_null_space.criteria.manipulability.gain = 0.5
    return NullSpaceImpedanceController(
        controller_model=model, normal=[0.0, 0.0, -1.0], config=config
    ), PANDA_Q0


def scenario_step(name: str) -> tuple[ControllerStep, np.ndarray, float]:
    """The shipped scenario's controller as a plain ControllerStep, its q0 and period."""
    scenario = load_scenario(name)
    station = add_scenario_station(DiagramBuilder(), scenario)
    c = build_controller(scenario, station, station.sensor.p_WSo)
    step = ControllerStep(
        controller_model=c.model, normal=c.normal, config=c.config, wrench_point=c.wrench_point
    )
    return step, station.q0, scenario.control_period


def plain_step_us(name: str, calls: int, seed: int = 0) -> dict[str, float]:
    """Median and p99.9 [µs] of ``ControllerStep.step`` at fresh states, one call a period
    (so the discrete updates run as in a robot's loop), each call timed on its own."""
    step, q0, period = scenario_step(name)
    n, m_t, rotational = step.model.n, step.plan.m_t, step.plan.m_r > 0
    rng = np.random.default_rng(seed)
    states = np.hstack([q0 + 0.05 * rng.standard_normal((512, n)), 0.2 * rng.standard_normal((512, n))])
    x_d = np.zeros(m_t)
    extra = (np.array([0.0, 1.0, 0.0, 0.0]), np.zeros(3), np.zeros(3)) if rotational else ()
    wrench = np.zeros(6)
    times, cpu = np.empty(calls), np.empty(calls)
    for k in range(calls + 200):  # the first 200 calls warm up
        s = states[k % 512]
        t0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        step.step(k * period, s[:n], s[n:], wrench, x_d, x_d, x_d, 5.0, *extra)
        if k >= 200:
            times[k - 200] = (time.perf_counter_ns() - t0) / 1e3
            cpu[k - 200] = (time.thread_time_ns() - c0) / 1e3
    return {
        "median": round(float(np.median(times)), 1),
        "p99_9": round(float(np.percentile(times, 99.9)), 1),
        "p99_9_cpu": round(float(np.percentile(cpu, 99.9)), 1),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs per figure (median), at least 5")
    parser.add_argument("--steps", type=int, default=3000, help="controller evaluations per step-cost run")
    parser.add_argument("--panda-repeats", type=int, default=3, help="panda_wipe runs (median), at least 3")
    parser.add_argument("--plain-calls", type=int, default=20000, help="ControllerStep calls per arm")
    args = parser.parse_args()

    scenario = load_scenario("fig3")
    ticks = round(scenario.duration / scenario.control_period)
    ours, fused, base = [], [], []
    for k in range(args.repeats):  # interleaved, so all see the same machine load
        cpu, traces = fig3_run(scenario)
        ours.append(cpu / ticks * 1e6)
        fused.append(fig3_run(scenario, "fused")[0] / ticks * 1e6)
        base.append(baseline_run(scenario, traces) / ticks * 1e6)
        print(
            f"  run {k + 1}: fig3 {ours[-1]:6.1f} µs/tick (fused {fused[-1]:6.1f}), "
            f"baseline {base[-1]:6.1f} µs/tick",
            flush=True,
        )
    fig3_us, fused_us, base_us = statistics.median(ours), statistics.median(fused), statistics.median(base)
    print(f"fig3, {scenario.duration:g} s simulated ({ticks} ticks), CPU per tick, median of {args.repeats}:")
    print(f"  nsdrake (plant, sensor, reference, controller, loggers)  {fig3_us:7.1f} µs   ")
    print(f"  JointStiffnessController (C++), same plant and sensor   {base_us:7.1f} µs")
    print(f"  ratio {'':49} {fig3_us / base_us:7.2f}      (target ≤ 4)")
    print(
        f"  the same with the fused controller {'':20} {fused_us:7.1f} µs, "
        f"ratio {fused_us / base_us:.2f} (target ≤ 2.5)"
    )

    panda = load_scenario("panda_wipe")
    wipe = []
    for k in range(args.panda_repeats):
        wipe.append(tick_us(panda))
        print(f"  run {k + 1}: panda_wipe {wipe[-1]:6.1f} µs/tick", flush=True)
    wipe_us = statistics.median(wipe)
    ticks = round(panda.duration / panda.control_period)
    print(f"panda_wipe, {panda.duration:g} s simulated ({ticks} ticks), CPU per tick, ", end="")
    print(f"median of {args.panda_repeats}:")
    print(f"  nsdrake (Panda, table, post, pose task, criteria, loggers)  {wipe_us:7.1f} µs   (aim ≤ 350)")

    steps = {}
    for label, make in (("4dof", fig3_controller), ("7dof", panda_controller)):
        controller, q0 = make()
        steps[label] = statistics.median(
            step_cost(controller, q0, args.steps, seed=k) for k in range(args.repeats)
        )
        print(
            f"controller step, {label} ({controller.model.dynamics} terms), fresh state → generalized_force: "
            f"{steps[label]:6.1f} µs   (target ≤ {60 if label == '4dof' else 100})"
        )
    plain = {
        label: plain_step_us(name, args.plain_calls)
        for label, name in (("4dof", "fig3"), ("7dof", "panda_wipe"))
    }
    for label, figures in plain.items():
        print(
            f"ControllerStep.step, {label}: median {figures['median']} µs, p99.9 {figures['p99_9']} µs "
            f"(CPU time: {figures['p99_9_cpu']} µs)"
        )
    from bench_dispatch_floor import replace_math_by_stored_values  # it imports this module

    replace_math_by_stored_values()  # after everything else: it patches the systems' classes
    controller, q0 = fig3_controller()
    floor = statistics.median(step_cost(controller, q0, args.steps, seed=k) for k in range(args.repeats))
    print(
        f"the 4dof systems' step over their dispatch floor: {steps['4dof']:.1f} / {floor:.1f} µs (target ≤ 2)"
    )
    print(
        json.dumps(
            {
                "fig3_tick_us": round(fig3_us, 1),
                "baseline_tick_us": round(base_us, 1),
                "ratio": round(fig3_us / base_us, 2),
                "panda_wipe_tick_us": round(wipe_us, 1),
                "controller_step_us_4dof": round(steps["4dof"], 1),
                "controller_step_us_7dof": round(steps["7dof"], 1),
                "plain_step_us_4dof": plain["4dof"],
                "plain_step_us_7dof": plain["7dof"],
                "fused_ratio": round(fused_us / base_us, 2),
                "systems_step_over_floor": round(steps["4dof"] / floor, 2),
            }
        )
    )


if __name__ == "__main__":
    main()

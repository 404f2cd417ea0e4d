"""Benchmark: cost of one control tick per LeafSystem and for the whole stack, and the
fig3 run's wall time against Drake's C++ JointStiffnessController on the same plant,
contact and sensor.

    python bench/bench_controller.py [--repeats N] [--ticks N]

Prints medians of several runs. The machines are noisy, so the run-time figure is a
ratio to a baseline measured in the same process, interleaved with ours.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import JointStiffnessController
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from nsdrake.diagram import build_diagram
from nsdrake.plant import add_station
from nsdrake.scenario import load_scenario
from nsdrake.simulate import run
from nsdrake.systems import ForceSensor

# The controller stack in evaluation order: (system, output port).
STACK = [
    ("robot_terms", "robot_terms"),
    ("force_sensor", "wrench"),
    ("reference", "x_d"),
    ("impedance_controller", "generalized_force"),
    ("joint_torque_criterion", "gradient"),
    ("manipulability_criterion", "gradient"),
    ("obstacle_criterion", "gradient"),
    ("priority_selector", "desired_null_space_velocity"),
    ("null_space_controller", "generalized_force"),
    ("torque_sum", "sum"),
    ("actuation_map", "y0"),
]


def tick_costs(ticks: int, repeats: int) -> tuple[dict[str, float], float]:
    """Median µs per tick for each system (its own cost, upstream already evaluated)
    and for the whole stack (a fresh state, then the actuation)."""
    scenario = load_scenario("fig3")
    built = build_diagram(scenario)
    context = built.diagram.CreateDefaultContext()
    plant = built.station.plant
    plant_context = plant.GetMyMutableContextFromRoot(context)
    context.SetTime(2.0)  # in contact phase of the reference (the state is what varies)
    rng = np.random.default_rng(0)
    states = np.hstack(
        [built.station.q0 + 0.05 * rng.standard_normal((256, 4)), 0.2 * rng.standard_normal((256, 4))]
    )
    ports = []
    for name, port in STACK:
        system = built.system(name)
        ports.append((name, system.GetOutputPort(port), system.GetMyContextFromRoot(context)))
    per_system: dict[str, list[float]] = {name: [] for name, _, _ in ports}
    clock = time.perf_counter
    for i in range(ticks):
        plant.SetPositionsAndVelocities(plant_context, states[i % 256])
        for name, port, sub in ports:
            t0 = clock()
            port.Eval(sub)
            per_system[name].append(clock() - t0)
    actuation, actuation_context = ports[-1][1], ports[-1][2]
    whole = []
    for _ in range(repeats):
        t0 = clock()
        for i in range(ticks):
            plant.SetPositionsAndVelocities(plant_context, states[i % 256])
            actuation.Eval(actuation_context)
        elapsed = clock() - t0
        t0 = clock()
        for i in range(ticks):
            plant.SetPositionsAndVelocities(plant_context, states[i % 256])
        whole.append((elapsed - (clock() - t0)) / ticks)
    skip = ticks // 10  # warm-up
    medians = {name: statistics.median(v[skip:]) * 1e6 for name, v in per_system.items()}
    return medians, statistics.median(whole) * 1e6


def fig3_wall_time(scenario) -> tuple[float, object]:
    t0 = time.perf_counter()
    traces, _ = run(scenario)
    return time.perf_counter() - t0, traces


def baseline_wall_time(scenario, traces) -> float:
    """The same plant, contact and force sensor, the joints driven by Drake's C++
    JointStiffnessController along the fig3 run's joint trajectory (so the tool
    presses and slides on the plate as in fig3), with the state and force logged."""
    t0 = time.perf_counter()
    builder = DiagramBuilder()
    station = add_station(builder, scenario)
    plant: MultibodyPlant = station.plant
    n = station.arm_model.n
    sensor = builder.AddNamedSystem(
        "force_sensor", ForceSensor(plant=plant, sensor_joint=station.sensor_joint)
    )
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.get_input_port())
    q = traces.block("q").T
    v = traces.block("v").T
    trajectory = PiecewisePolynomial.FirstOrderHold(traces["t"], np.vstack([q, v]))
    desired = builder.AddSystem(TrajectorySource(trajectory))
    controller = builder.AddSystem(JointStiffnessController(plant, np.full(n, 20.0), np.full(n, 0.5)))
    builder.Connect(plant.get_state_output_port(), controller.get_input_port_estimated_state())
    builder.Connect(desired.get_output_port(), controller.get_input_port_desired_state())
    builder.Connect(controller.get_output_port_actuation(), plant.get_actuation_input_port())
    LogVectorOutput(plant.get_state_output_port(), builder, publish_period=scenario.control_period)
    LogVectorOutput(sensor.GetOutputPort("force"), builder, publish_period=scenario.control_period)
    simulator = Simulator(builder.Build())
    plant.SetPositions(plant.GetMyMutableContextFromRoot(simulator.get_mutable_context()), station.q0)
    simulator.Initialize()
    simulator.AdvanceTo(scenario.duration)
    return time.perf_counter() - t0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs per figure (median)")
    parser.add_argument("--ticks", type=int, default=2000, help="control ticks per tick-cost run")
    args = parser.parse_args()

    medians, whole = tick_costs(args.ticks, args.repeats)
    print("cost of one control tick, median [µs] (each system alone, upstream cached):")
    for name, us in medians.items():
        print(f"  {name:30s} {us:8.1f}")
    print(f"  {'sum of the above':30s} {sum(medians.values()):8.1f}")
    print(f"whole controller stack per tick (fresh state → actuation), median [µs]: {whole:.1f}")
    print("  (target ≤ 150)")

    scenario = load_scenario("fig3")
    ours, base = [], []
    traces = None
    for _ in range(args.repeats):  # interleaved, so both see the same machine load
        t, traces = fig3_wall_time(scenario)
        ours.append(t)
        base.append(baseline_wall_time(scenario, traces))
    o, b = statistics.median(ours), statistics.median(base)
    steps = round(scenario.duration / scenario.control_period)
    print(f"fig3 run, {scenario.duration:g} s simulated ({steps} steps), median of {args.repeats} [s]:")
    print(f"  nsdrake stack                          {o:7.3f}  ({o / steps * 1e6:6.0f} µs/step)")
    print(f"  JointStiffnessController (C++)         {b:7.3f}  ({b / steps * 1e6:6.0f} µs/step)")
    print(f"  ratio                                  {o / b:7.2f}   (target ≤ 4)")


if __name__ == "__main__":
    main()

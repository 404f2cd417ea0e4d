"""The controller behind plants of other time steps: diagrams/own_arm.py's set-up (a 5-joint
planar arm pressing 5 N on a wall on a sensor joint, joint torques minimised in the null
space, T = 2 ms) with the plant stepping at T, at T/4 and continuously, connected directly,
through nsdrake.ControlHold or through Drake's ZeroOrderHold.

    python bench/bench_plant_timing.py [--duration SECONDS] [--out DIR]

Prints, per set-up, whether the diagram builds, the normal force at the end, RMS ‖eⁿ‖ from
1.5 s on (after contact), and the process CPU time of the simulation; the last row repeats
the continuous plant behind ControlHold with the q̈_dⁿ feed-forward switched off, to compare
with the ZeroOrderHold row. With ``--out`` it also writes them as DIR/table.md, the table
docs/own_diagram.md ("The contract") cites (scripts/regenerate_results.py --family
plant_timing). The CPU times are this machine's, under its load at the time.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from pydrake.all import (
    AddMultibodyPlant,
    Box,
    DiagramBuilder,
    LogVectorOutput,
    MultibodyPlantConfig,
    Parser,
    ProximityProperties,
    RigidTransform,
    Simulator,
    SpatialInertia,
    WeldJoint,
    ZeroOrderHold,
)

from nsdrake import ControlHold, ControllerConfig, NullSpaceImpedanceController
from nsdrake.experiment.reference import SlideAndPress
from nsdrake.experiment.reference_system import SurfaceReference
from nsdrake.station.force_sensor import ForceSensor

T = 0.002
LINK = (
    '<link name="l{i}"><inertial><origin xyz="0.1 0 0"/><mass value="0.3"/><inertia ixx="1e-5" ixy="0" '
    'ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial></link><joint name="j{i}" type="revolute">'
    '<parent link="{parent}"/><child link="l{i}"/><origin xyz="{x} 0 0"/><axis xyz="0 0 1"/>'
    '<limit lower="-3" upper="3" effort="50" velocity="5"/></joint><transmission>'
    '<type>transmission_interface/SimpleTransmission</type><joint name="j{i}"/><actuator name="m{i}"/>'
    "</transmission>"
)
TOOL = (
    '<link name="tool"><inertial><mass value="0.05"/><inertia ixx="2e-6" ixy="0" ixz="0" iyy="2e-6" '
    'iyz="0" izz="2e-6"/></inertial><collision><geometry><sphere radius="0.015"/></geometry>'
    '<drake:proximity_properties><drake:point_contact_stiffness value="1e5"/>'
    '<drake:hunt_crossley_dissipation value="5"/></drake:proximity_properties></collision></link>'
    '<joint name="tw" type="fixed"><parent link="l5"/><child link="tool"/><origin xyz="0.2 0 0"/></joint>'
)
LINKS = LINK.format(i=1, parent="world", x=0) + "".join(
    LINK.format(i=i, parent=f"l{i - 1}", x=0.2) for i in range(2, 6)
)
URDF = f'<robot name="arm5" xmlns:drake="http://drake.mit.edu">{LINKS}{TOOL}</robot>'


def build(time_step: float, connection: str, feedforward: bool = True):
    builder = DiagramBuilder()
    plant_config = MultibodyPlantConfig(time_step=time_step)
    if time_step > 0:
        plant_config.discrete_contact_approximation = "lagged"
    plant, _ = AddMultibodyPlant(plant_config, builder)
    Parser(plant).AddModelsFromString(URDF, "urdf")
    wall = plant.AddRigidBody(
        "wall", plant.AddModelInstance("wall"), SpatialInertia.SolidBoxWithMass(1.0, 1.0, 0.02, 0.1)
    )
    props = ProximityProperties()
    props.AddProperty("material", "point_contact_stiffness", 1e5)
    props.AddProperty("material", "hunt_crossley_dissipation", 5.0)
    plant.RegisterCollisionGeometry(wall, RigidTransform([0, 0.01, 0]), Box(1.0, 0.02, 0.1), "wall", props)
    mount = plant.AddJoint(
        WeldJoint("wall_mount", plant.world_frame(), wall.body_frame(), RigidTransform([0.8, 0.35, 0]))
    )
    plant.Finalize()
    plant.SetDefaultPositions([1.2, -0.6, -0.5, -0.3, 0.3])
    sensor = builder.AddSystem(ForceSensor(plant=plant, sensor_joint=mount))
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.get_input_port())
    config = ControllerConfig(period=T, nominal_force=5.0)
    config.desired_null_space.criteria.joint_torque.gain = -0.005
    config.null_space.acceleration_feedforward = feedforward
    controller = builder.AddSystem(
        NullSpaceImpedanceController(
            controller_model=URDF, normal=[0.0, 1.0], config=config, wrench_point=sensor.p_WSo
        )
    )
    builder.Connect(plant.get_state_output_port(), controller.GetInputPort("estimated_state"))
    builder.Connect(sensor.GetOutputPort("wrench"), controller.GetInputPort("measured_wrench"))
    x0 = plant.GetFrameByName("tool").CalcPoseInWorld(plant.CreateDefaultContext()).translation()[:2]
    path = SlideAndPress(x0, np.array([1.0, 0.0]), np.array([0.0, 1.0]), 0.0, 0.05, 0.2, 5.0, 0.2)
    reference = builder.AddSystem(
        SurfaceReference(reference=path, task_rows=[0, 1], contact_threshold=0.5, period=T)
    )
    builder.Connect(sensor.GetOutputPort("wrench"), reference.GetInputPort("measured_wrench"))
    for port, signal in (
        ("desired_position", "x_d"),
        ("desired_velocity", "xdot_d"),
        ("desired_acceleration", "xddot_d"),
        ("desired_force", "f_d"),
    ):
        builder.Connect(reference.GetOutputPort(signal), controller.GetInputPort(port))
    tau = controller.GetOutputPort("generalized_force")
    hold = {
        "direct": None,
        "ControlHold": lambda: ControlHold(size=5, period=T),
        "ControlHold(direct_feedthrough=False)": lambda: ControlHold(
            size=5, period=T, direct_feedthrough=False
        ),
        "ZeroOrderHold": lambda: ZeroOrderHold(T, 5),
    }[connection]
    if hold is not None:
        system = builder.AddSystem(hold())
        builder.Connect(tau, system.get_input_port())
        tau = system.get_output_port()
    builder.Connect(tau, plant.get_actuation_input_port())
    en = LogVectorOutput(controller.GetOutputPort("null_space_velocity_error"), builder, T)
    force = LogVectorOutput(sensor.GetOutputPort("force"), builder, T)
    return builder.Build(), en, force


def run(time_step: float, connection: str, duration: float, feedforward: bool = True) -> dict:
    """The set-up's figures: f_n at the end [N], RMS ‖eⁿ‖ from 1.5 s [rad/s], CPU [s]; or
    ``builds``, why the diagram does not build."""
    try:
        diagram, en_log, force_log = build(time_step, connection, feedforward)
    except RuntimeError as e:
        if "algebraic loop" not in str(e):
            raise
        return {"builds": "no: an algebraic loop (Drake's DiagramBuilder refuses it)"}
    simulator = Simulator(diagram)
    start = time.process_time()
    simulator.AdvanceTo(duration)
    cpu = time.process_time() - start
    context = simulator.get_context()
    t = en_log.FindLog(context).sample_times()
    en = np.linalg.norm(en_log.FindLog(context).data(), axis=0)[t >= 1.5]
    f_n = force_log.FindLog(context).data()[1, -1]
    return {"builds": "yes", "f_n_end": f_n, "en_rms": float(np.sqrt(np.mean(en**2))), "cpu": cpu}


def text(row: dict) -> str:
    if row["builds"] != "yes":
        return f"does not build ({row['builds'][4:]})"
    return f"f_n {row['f_n_end']:.3f} N, RMS ||e^n|| {row['en_rms']:.2e} rad/s, CPU {row['cpu']:.2f} s"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=3.0)
    parser.add_argument("--out", type=Path, help="also write the figures as DIR/table.md")
    args = parser.parse_args()
    lines = []
    for time_step, connection, feedforward in (
        (T, "direct", True),
        (T / 4, "direct", True),
        (T / 4, "ControlHold", True),
        (0.0, "direct", True),
        (0.0, "ControlHold", True),
        (0.0, "ZeroOrderHold", True),
        (0.0, "ControlHold(direct_feedthrough=False)", True),
        (0.0, "ControlHold(direct_feedthrough=False)", False),
    ):
        plant = f"plant step {time_step * 1e3:g} ms" if time_step else "continuous plant"
        label = f"{plant}, {connection}" + ("" if feedforward else ", no q̈_dⁿ feed-forward")
        row = run(time_step, connection, args.duration, feedforward)
        print(f"{label:70s} {text(row)}", flush=True)
        cells = [f"{row[k]:.4g}" if k in row else "" for k in ("f_n_end", "en_rms", "cpu")]
        lines.append(f"| {label} | {row['builds']} | " + " | ".join(cells) + " |")
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "table.md").write_text(
            "# plant_timing\n\n"
            "The controller behind plants of other time steps: diagrams/own_arm.py's set-up (a 5-joint "
            "planar arm pressing 5 N on a wall, T = 2 ms) with the plant stepping at T, at T/4 and "
            f"continuously, connected directly or through a hold, {args.duration:g} s each; f_n_end the "
            "normal force at the end, "
            "en_rms RMS ‖eⁿ‖ from 1.5 s on, cpu the process CPU time of the simulation (this machine's, "
            "under its load at the time).\n\n"
            "| set-up | builds | f_n_end [N] | en_rms [rad/s] | cpu [s] |\n|---|---|---|---|---|\n"
            + "\n".join(lines)
            + "\n"
        )
        print(f"wrote {args.out / 'table.md'}")


if __name__ == "__main__":
    main()

"""nsdrake's controller on an arm nsdrake did not build: python diagrams/own_arm.py [DURATION].

A 5-joint planar arm written here as a URDF string presses 5 N on a wall that is
welded to the world through a joint named ``wall_mount`` (the force sensor), while
its three redundant joints minimise the joint torques (Eqs. 32-33). Prints the
final normal force.
"""

import sys

import numpy as np
from pydrake.all import (
    AddMultibodyPlant,
    Box,
    DiagramBuilder,
    MultibodyPlantConfig,
    Parser,
    ProximityProperties,
    RigidTransform,
    Simulator,
    SpatialInertia,
    WeldJoint,
)

from nsdrake import ControllerConfig, NullSpaceImpedanceController
from nsdrake.experiment.reference import SlideAndPress
from nsdrake.experiment.reference_system import SurfaceReference
from nsdrake.station.force_sensor import ForceSensor

LINK = '<link name="l{i}"><inertial><origin xyz="0.1 0 0"/><mass value="0.3"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial></link><joint name="j{i}" type="revolute"><parent link="{parent}"/><child link="l{i}"/><origin xyz="{x} 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="50" velocity="5"/></joint><transmission><type>transmission_interface/SimpleTransmission</type><joint name="j{i}"/><actuator name="m{i}"/></transmission>'  # noqa: E501
TOOL = '<link name="tool"><inertial><mass value="0.05"/><inertia ixx="2e-6" ixy="0" ixz="0" iyy="2e-6" iyz="0" izz="2e-6"/></inertial><collision><geometry><sphere radius="0.015"/></geometry><drake:proximity_properties><drake:point_contact_stiffness value="1e5"/><drake:hunt_crossley_dissipation value="5"/></drake:proximity_properties></collision></link><joint name="tw" type="fixed"><parent link="l5"/><child link="tool"/><origin xyz="0.2 0 0"/></joint>'  # noqa: E501
links = "".join(
    LINK.format(i=i, parent=f"l{i - 1}" if i > 1 else "world", x=0.2 if i > 1 else 0) for i in range(1, 6)
)
URDF = f'<robot name="arm5" xmlns:drake="http://drake.mit.edu">{links}{TOOL}</robot>'

builder = DiagramBuilder()
plant, _ = AddMultibodyPlant(
    MultibodyPlantConfig(time_step=0.002, discrete_contact_approximation="lagged"), builder
)
Parser(plant).AddModelsFromString(URDF, "urdf")
wall = plant.AddRigidBody(
    "wall", plant.AddModelInstance("wall"), SpatialInertia.SolidBoxWithMass(1.0, 1.0, 0.02, 0.1)
)
props = ProximityProperties()
props.AddProperty("material", "point_contact_stiffness", 1e5)
plant.RegisterCollisionGeometry(wall, RigidTransform([0, 0.01, 0]), Box(1.0, 0.02, 0.1), "wall", props)
mount = plant.AddJoint(
    WeldJoint("wall_mount", plant.world_frame(), wall.body_frame(), RigidTransform([0.8, 0.35, 0]))
)
plant.Finalize()
q0 = np.array([1.2, -0.6, -0.5, -0.3, 0.3])
plant.SetDefaultPositions(q0)

sensor = builder.AddSystem(ForceSensor(plant=plant, sensor_joint=mount))  # wrench the tool exerts on the wall
config = ControllerConfig(nominal_force=5.0)
config.desired_null_space.criteria.joint_torque.gain = -0.005  # minimise ‖Jᵀ F_d‖² in the null space
controller = builder.AddSystem(
    NullSpaceImpedanceController(
        controller_model=URDF,  # the controller's own model of the arm, not the simulated plant
        normal=[0.0, 1.0],  # it pushes along +y
        config=config,
        tool_frame="tool",
        task_axes=("x", "y"),
        wrench_point=sensor.p_WSo,  # the sensor's moment is about its own origin
    )
)
context = plant.CreateDefaultContext()
x0 = plant.GetFrameByName("tool").CalcPoseInWorld(context).translation()[:2]
ref = SlideAndPress(x0, np.array([1.0, 0.0]), np.array([0.0, 1.0]), 0.0, 0.05, 0.2, 5.0, 0.2)
reference = builder.AddSystem(
    SurfaceReference(reference=ref, task_rows=[0, 1], contact_threshold=0.5, period=0.002)
)
builder.Connect(plant.get_reaction_forces_output_port(), sensor.get_input_port())
builder.Connect(sensor.GetOutputPort("wrench"), reference.GetInputPort("measured_wrench"))
builder.Connect(sensor.GetOutputPort("wrench"), controller.GetInputPort("measured_wrench"))
builder.Connect(plant.get_state_output_port(), controller.GetInputPort("estimated_state"))
for port, ref_port in [
    ("desired_position", "x_d"),
    ("desired_velocity", "xdot_d"),
    ("desired_acceleration", "xddot_d"),
    ("desired_force", "f_d"),
]:  # noqa: E501
    builder.Connect(reference.GetOutputPort(ref_port), controller.GetInputPort(port))
builder.Connect(controller.GetOutputPort("generalized_force"), plant.get_actuation_input_port())
diagram = builder.Build()

simulator = Simulator(diagram)
simulator.AdvanceTo(float(sys.argv[1]) if len(sys.argv) > 1 else 3.0)
force = sensor.GetOutputPort("force").Eval(sensor.GetMyContextFromRoot(simulator.get_context()))
print(f"normal force {force[1]:.3f} N (desired 5 N)")

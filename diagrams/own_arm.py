"""nsdrake's controller on an arm nsdrake did not build: python diagrams/own_arm.py [DURATION]

A 5-joint planar arm, written here as URDF text, presses 5 N on a wall welded to the
world through a joint named wall_mount (the force sensor) while its three redundant
joints lower the joint torques (Eqs. 32-33). Prints the final normal force.
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

from nsdrake import (
    ControllerConfig,
    ForceSensor,
    NullSpaceImpedanceController,
    SlideAndPress,
    SurfaceReference,
)

T = 0.002  # control period = plant time step [s]
LINK = """
<link name="l{i}"><inertial><origin xyz="0.1 0 0"/><mass value="0.3"/>
  <inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial></link>
<joint name="j{i}" type="revolute"><parent link="{parent}"/><child link="l{i}"/><origin xyz="{x} 0 0"/>
  <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="50" velocity="5"/></joint>
<transmission><type>transmission_interface/SimpleTransmission</type>
  <joint name="j{i}"/><actuator name="m{i}"/></transmission>"""
TOOL = """
<link name="tool"><inertial><mass value="0.05"/>
  <inertia ixx="2e-6" ixy="0" ixz="0" iyy="2e-6" iyz="0" izz="2e-6"/></inertial>
  <collision><geometry><sphere radius="0.015"/></geometry><drake:proximity_properties>
    <drake:point_contact_stiffness value="1e5"/><drake:hunt_crossley_dissipation value="5"/>
  </drake:proximity_properties></collision></link>
<joint name="tw" type="fixed"><parent link="l5"/><child link="tool"/><origin xyz="0.2 0 0"/></joint>"""
links = "".join(LINK.format(i=i, parent=f"l{i - 1}", x=0.2) for i in range(2, 6))
links = LINK.format(i=1, parent="world", x=0) + links
URDF = f'<robot name="arm5" xmlns:drake="http://drake.mit.edu">{links}{TOOL}</robot>'

# The simulated world: the arm, and a wall on a sensor joint.
builder = DiagramBuilder()
plant_config = MultibodyPlantConfig(time_step=T, discrete_contact_approximation="lagged")
plant, _ = AddMultibodyPlant(plant_config, builder)
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
plant.SetDefaultPositions([1.2, -0.6, -0.5, -0.3, 0.3])
sensor = builder.AddSystem(ForceSensor(plant=plant, sensor_joint=mount))  # the wrench the tool exerts
builder.Connect(plant.get_reaction_forces_output_port(), sensor.get_input_port())

# The controller, on its own model of the arm (the URDF), not on the simulated plant.
config = ControllerConfig(period=T, nominal_force=5.0)  # gains, inverse, switches, criteria
config.desired_null_space.criteria.joint_torque.gain = -0.005  # minimise ‖Jᵀ F_d‖² (Eq. 32)
controller = builder.AddSystem(
    NullSpaceImpedanceController(
        controller_model=URDF,  # a path, the URDF's text, a ControllerModel, or a plant it owns
        tool_frame="tool",  # the task point
        task_axes=("x", "y"),  # world axes of x (Eq. 1); ("x", "y", "z", "rx", "ry", "rz"): full pose
        normal=[0.0, 1.0],  # the task direction in which the tool pushes
        config=config,
        wrench_point=sensor.p_WSo,  # the point the sensor's moment is about (None: the tool)
    )
)
builder.Connect(plant.get_state_output_port(), controller.GetInputPort("estimated_state"))
builder.Connect(sensor.GetOutputPort("wrench"), controller.GetInputPort("measured_wrench"))
builder.Connect(controller.GetOutputPort("generalized_force"), plant.get_actuation_input_port())

# The task: approach the wall along +y, press 5 N, slide along +x at 5 cm/s.
x0 = plant.GetFrameByName("tool").CalcPoseInWorld(plant.CreateDefaultContext()).translation()[:2]
path = SlideAndPress(x0, np.array([1.0, 0.0]), np.array([0.0, 1.0]), 0.0, 0.05, 0.2, 5.0, 0.2)
reference = builder.AddSystem(
    SurfaceReference(reference=path, task_rows=[0, 1], contact_threshold=0.5, period=T)
)
builder.Connect(sensor.GetOutputPort("wrench"), reference.GetInputPort("measured_wrench"))
for port, signal in [
    ("desired_position", "x_d"),
    ("desired_velocity", "xdot_d"),
    ("desired_acceleration", "xddot_d"),
    ("desired_force", "f_d"),
]:
    builder.Connect(reference.GetOutputPort(signal), controller.GetInputPort(port))

simulator = Simulator(builder.Build())
simulator.AdvanceTo(float(sys.argv[1]) if len(sys.argv) > 1 else 3.0)
force = sensor.GetOutputPort("force").Eval(sensor.GetMyContextFromRoot(simulator.get_context()))
print(f"normal force {force[1]:.3f} N (desired 5 N)")

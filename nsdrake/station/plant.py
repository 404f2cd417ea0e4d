"""The simulated station: the arm, the plate on its force sensor, compliant contact.

A discrete ``MultibodyPlant`` whose time step is the control period, point
contact with Coulomb friction between the tool and the plate (the contact
properties live in the URDFs; urdf/README.md says where each comes from), and
the plate welded to the world by a fixed joint named ``force_sensor``, whose
reaction force the force sensor reads.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.geometry import Box, Cylinder, ProximityProperties, Sphere
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import ModelInstanceIndex, SpatialInertia, WeldJoint
from pydrake.systems.framework import DiagramBuilder

from nsdrake.control.criteria.obstacle import proximity_geometries
from nsdrake.control.dynamics import ArmModel
from nsdrake.control.model import Obstacle
from nsdrake.experiment.checks import check_model_file
from nsdrake.experiment.scenario import Scenario, ScenarioError, check_against_plant
from nsdrake.realism.config import substeps
from nsdrake.station.elastic import ElasticMap, add_elastic_arm, rigid_arm_plant
from nsdrake.station.models import resolve_model

SENSOR_JOINT = "force_sensor"
GRAVITY = 9.81  # [m/s²]


@dataclass
class Station:
    """Handles to what :func:`add_station` built."""

    plant: MultibodyPlant
    scene_graph: object
    arm: ModelInstanceIndex
    plate: ModelInstanceIndex
    arm_model: ArmModel
    sensor_joint: WeldJoint
    # Task-space direction (m,) in which the tool pushes on the plate (unit).
    normal: np.ndarray
    # Task-space direction (m,) along the plate, perpendicular to ``normal`` (unit), when m ≥ 2.
    tangent: np.ndarray
    q0: np.ndarray  # (n,) initial joint positions [rad]
    v0: np.ndarray  # (n,) initial joint velocities [rad/s]
    arm_file: Path  # the arm's URDF
    gravity: np.ndarray  # (3,) world gravity [m/s²]
    # Bodies of the extra obstacles (welded to the world).
    obstacle_bodies: list = field(default_factory=list)
    # Proximity geometries of the arm's links (the tool's excepted) and of the obstacles (plate included).
    link_geometries: list = field(default_factory=list)
    obstacle_geometries: list = field(default_factory=list)
    # Pose of the plate frame in the world (its +y is the push direction).
    X_WP: RigidTransform | None = None
    # With the belt rung (nsdrake/elastic.py): the plant has motor and belt coordinates,
    # arm_model is the rigid arm on a plant of its own (link coordinates), and this maps
    # between them. None: the plant's state is the arm's [q; q̇].
    elastic: ElasticMap | None = None
    # The plant's initial positions and velocities (q0, v0 unless elastic).
    plant_q0: np.ndarray | None = None
    plant_v0: np.ndarray | None = None

    @property
    def tool_body(self):
        """The tool's body in the simulated plant."""
        return self.plant.GetFrameByName(self.arm_model.tool_frame.name(), self.arm).body()


def gravity_vector(scenario: Scenario) -> np.ndarray:
    """World gravity: the scenario's ``gravity`` if given, else along −z for a
    horizontal arm's plane and −y for a vertical one. (3,) [m/s²]."""
    if scenario.gravity:
        return np.asarray(scenario.gravity, dtype=float)
    return (
        np.array([0.0, 0.0, -GRAVITY]) if scenario.plane == "horizontal" else np.array([0.0, -GRAVITY, 0.0])
    )


def surface_directions(R_WP: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(normal, tangent) on the task axes ``rows`` for a plate of orientation R_WP:
    the plate frame's +y axis points into the plate (the push), its +x along it. The
    tangent is projected onto the task axes, made perpendicular to the normal and
    re-normalised. Raises ValueError when the normal leaves the task axes."""
    normal = R_WP[:, 1][rows]
    if np.linalg.norm(normal) < 0.99:
        raise ValueError("the plate's normal leaves the task axes")
    normal = normal / np.linalg.norm(normal)
    tangent = R_WP[:, 0][rows]
    tangent = tangent - (tangent @ normal) * normal
    size = np.linalg.norm(tangent)
    return normal, (tangent / size if size > 1e-9 else np.zeros_like(tangent))


def _model_file(scenario: Scenario, where: str, name: str) -> Path:
    try:
        return resolve_model(name, Path(scenario.base_dir) if scenario.base_dir else None)
    except FileNotFoundError as e:
        raise ScenarioError(f"{scenario.source or 'scenario'}: {where}: {e}") from None


def add_station(builder: DiagramBuilder, scenario: Scenario) -> Station:
    """Adds the plant and scene graph for ``scenario`` to ``builder``; finalizes the plant."""
    src = scenario.source or "scenario"
    config = MultibodyPlantConfig(
        time_step=scenario.control_period / substeps(scenario.realism),
        contact_model=scenario.contact.model,
        discrete_contact_approximation=scenario.contact.approximation,
    )
    plant, scene_graph = AddMultibodyPlant(config, builder)
    plant.set_name("plant")
    scene_graph.set_name("scene_graph")
    parser = Parser(plant)
    arm_file = _model_file(scenario, "arm.urdf", scenario.arm.urdf)
    plate_file = _model_file(scenario, "plate.urdf", scenario.plate.urdf)
    for path in (arm_file, plate_file):
        try:
            check_model_file(path)
        except ScenarioError as e:
            raise ScenarioError(f"{src}: {e}") from None
    belt = scenario.realism.belt
    try:
        (arm,) = (
            add_elastic_arm(plant, parser, arm_file, belt)
            if belt.enabled
            else parser.AddModels(str(arm_file))
        )
        (plate,) = parser.AddModels(str(plate_file))
    except Exception as e:
        raise ScenarioError(f"{src}: cannot parse a model: {' '.join(str(e).split())}") from None
    plate_bodies = plant.GetBodyIndices(plate)
    if len(plate_bodies) != 1:
        raise ScenarioError(f"{src}: plate.urdf: the plate model must have exactly one body")
    plate_body = plant.get_body(plate_bodies[0])
    pl = scenario.plate
    X_WP = RigidTransform(RollPitchYaw(pl.roll, pl.pitch, pl.yaw), np.asarray(pl.position))
    sensor_joint = plant.AddJoint(WeldJoint(SENSOR_JOINT, plant.world_frame(), plate_body.body_frame(), X_WP))
    obstacle_bodies = _add_obstacles(plant, scene_graph, scenario, plate_body)
    gravity = gravity_vector(scenario)
    plant.mutable_gravity_field().set_gravity_vector(gravity)
    plant.Finalize()

    if not plant.HasFrameNamed(scenario.arm.tool_frame, arm):
        raise ScenarioError(f"{src}: arm.tool_frame: no frame '{scenario.arm.tool_frame}' in {arm_file.name}")
    tool = plant.GetFrameByName(scenario.arm.tool_frame, arm)
    if belt.enabled:  # the link coordinates' kinematics and dynamics: the rigid arm alone
        rigid = rigid_arm_plant(arm_file, gravity)
        tool = rigid.GetFrameByName(scenario.arm.tool_frame)
    try:
        arm_model = ArmModel(tool.GetParentPlant(), tool, scenario.task.axes)
    except ValueError as e:
        raise ScenarioError(f"{src}: arm.urdf: {e}") from None
    check_against_plant(scenario, arm_model.joint_names)
    for name in scenario.report.swivel_frames:
        if not plant.HasFrameNamed(name, arm):
            raise ScenarioError(f"{src}: report.swivel_frames: no frame '{name}' in {arm_file.name}")
    if plant.num_actuators() != arm_model.n:
        raise ScenarioError(
            f"{src}: arm.urdf: the arm needs one actuator per joint ({arm_model.n}), "
            f"it has {plant.num_actuators()}"
        )
    names = arm_model.joint_names
    q0 = np.array([scenario.arm.initial_positions[j] for j in names])
    v0 = np.array([scenario.arm.initial_velocities.get(j, 0.0) for j in names])
    elastic, plant_q0, plant_v0 = None, q0, v0
    if belt.enabled:
        elastic = ElasticMap.build(plant, arm, names, belt.stiffness)
        # Belts preloaded by gravity, so that the arm starts at rest: the gravity torque on
        # each belt coordinate (links and rotors beyond it) does not depend on δ at fixed q.
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, elastic.plant_positions(q0))
        tau_g = plant.CalcGravityGeneralizedForces(context)[elastic.belt_v]
        plant_q0 = elastic.plant_positions(q0, elastic.static_deflection(tau_g))
        plant_v0 = elastic.plant_velocities(v0)
    plant.SetDefaultPositions(plant_q0)  # survives context resets (DRAKE_NOTES)

    try:
        normal, tangent = surface_directions(X_WP.rotation().matrix(), arm_model.rows)
    except ValueError as e:
        raise ScenarioError(f"{src}: plate: {e} {scenario.task.axes}") from None
    if scenario.reference.path == "circle" and np.linalg.norm(tangent) < 0.99:
        raise ScenarioError(f"{src}: plate: the plate's x axis leaves the task axes {scenario.task.axes}")
    inspector = scene_graph.model_inspector()
    tool = plant.GetFrameByName(scenario.arm.tool_frame, arm).body().index()
    arm_bodies = [b for b in plant.GetBodyIndices(arm) if b != tool]
    obstacle_indices = [plate_body.index(), *(b.index() for b in obstacle_bodies)]
    return Station(
        plant=plant,
        scene_graph=scene_graph,
        arm=arm,
        plate=plate,
        arm_model=arm_model,
        sensor_joint=sensor_joint,
        normal=normal,
        tangent=tangent,
        q0=q0,
        v0=v0,
        arm_file=arm_file,
        gravity=gravity,
        obstacle_bodies=obstacle_bodies,
        link_geometries=proximity_geometries(inspector, plant, arm_bodies),
        obstacle_geometries=proximity_geometries(inspector, plant, obstacle_indices),
        X_WP=X_WP,
        elastic=elastic,
        plant_q0=plant_q0,
        plant_v0=plant_v0,
    )


def _add_obstacles(plant: MultibodyPlant, scene_graph, scenario: Scenario, plate_body) -> list:
    """Welds each scenario obstacle to the world (joint obstacle_<name>), with the
    plate's contact properties, so that a link that hits one is stopped physically."""
    if not scenario.obstacles:
        return []
    instance = plant.AddModelInstance("obstacles")
    inspector = scene_graph.model_inspector()
    (plate_geometry,) = plant.GetCollisionGeometriesForBody(plate_body)
    properties = inspector.GetProximityProperties(plate_geometry)
    bodies = []
    for ob in scenario.obstacles:
        shape = {
            "box": lambda s: Box(*s),
            "sphere": lambda s: Sphere(s[0]),
            "cylinder": lambda s: Cylinder(s[0], s[1]),
        }[ob.shape](ob.size)
        body = plant.AddRigidBody(ob.name, instance, SpatialInertia.SolidSphereWithMass(1.0, 0.05))
        plant.RegisterCollisionGeometry(
            body, RigidTransform(), shape, ob.name, ProximityProperties(properties)
        )
        plant.RegisterVisualGeometry(body, RigidTransform(), shape, ob.name, np.array([0.85, 0.55, 0.2, 0.9]))
        X_WO = RigidTransform(RollPitchYaw(0.0, 0.0, ob.yaw), np.asarray(ob.position, dtype=float))
        plant.AddJoint(WeldJoint(f"obstacle_{ob.name}", plant.world_frame(), body.body_frame(), X_WO))
        bodies.append(body)
    return bodies


def station_obstacles(station: Station) -> list[Obstacle]:
    """The plate and the obstacles as the controller should know them: each proximity
    shape with its pose in the world."""
    plant, inspector = station.plant, station.scene_graph.model_inspector()
    context = plant.CreateDefaultContext()
    out = []
    for g in station.obstacle_geometries:
        body = plant.GetBodyFromFrameId(inspector.GetFrameId(g))
        X_WG = plant.EvalBodyPoseInWorld(context, body) @ inspector.GetPoseInFrame(g)
        out.append(Obstacle(inspector.GetName(g), inspector.GetShape(g).Clone(), X_WG))
    return out


def tool_orientation(station: Station, q: np.ndarray) -> np.ndarray:
    """R_WT, the tool frame's orientation in the world at joint positions q. (3, 3)."""
    context = station.plant.CreateDefaultContext()
    station.plant.SetPositions(context, q)
    return station.arm_model.tool_frame.CalcPoseInWorld(context).rotation().matrix()


def desired_tool_orientation(station: Station, how: str) -> np.ndarray:
    """R_d for a pose task (scenario ``reference.orientation``): the tool's orientation at
    q0 ("start"), or that one turned by the smallest rotation that points the tool frame's
    z axis along the plate's push direction ("perpendicular"). (3, 3)."""
    R0 = tool_orientation(station, station.q0)
    if how == "start":
        return R0
    z = station.X_WP.rotation().matrix()[:, 1]  # the push direction, world
    axis = np.cross(R0[:, 2], z)
    s, c = np.linalg.norm(axis), float(R0[:, 2] @ z)
    if s < 1e-15:
        return R0 if c > 0 else RollPitchYaw(np.pi, 0.0, 0.0).ToRotationMatrix().matrix() @ R0
    return AngleAxis(np.arctan2(s, c), axis / s).rotation() @ R0

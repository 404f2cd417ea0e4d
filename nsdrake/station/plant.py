"""The simulated station: the arm, the plate on its force sensor, compliant contact.

A discrete ``MultibodyPlant`` whose time step is the control period (or a power-of-two
fraction of it), point contact with Coulomb friction between the tool and the plate
(the contact properties live in the URDFs; urdf/README.md says where each comes from),
and the plate welded to the world by a fixed joint named ``force_sensor``, whose
reaction force the force sensor reads::

    ┌──────────────────────────── station ─────────────────────────────┐
    │ plant ─state─[motor_encoders (belts)]──────────► ports.state       │
    │   │   └─reaction_forces─► force_sensor ─wrench─► ports.wrench      │
    │   │   └─contact_results─► contact_monitor                          │
    │   └── actuation ◄─ actuation_map (Bᵀ) ◄────────── ports.actuation  │
    └───────────────────────────────────────────────────────────────────┘

A controller reads ``ports.state`` ([q; q̇] of the arm, in its joint order) and
``ports.wrench``, and writes τ (arm joint order) into ``ports.actuation``. The rungs of
the realism ladder (:mod:`nsdrake.realism.wiring`) plug into these ports: a sensor
chain after the wrench, a hold and delay before the actuation, friction on the plant.

Everything here reads the station's own settings (:mod:`nsdrake.station.config`), not
a scenario; every problem is a one-line :class:`StationError` naming ``source``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.geometry import Box, Cylinder, ProximityProperties, Sphere
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import ModelInstanceIndex, SpatialInertia, WeldJoint
from pydrake.systems.framework import DiagramBuilder, InputPort, OutputPort
from pydrake.systems.primitives import MatrixGain

from nsdrake.control.criteria.obstacle import proximity_geometries
from nsdrake.control.dynamics import ArmModel
from nsdrake.control.model import Obstacle
from nsdrake.control.model_files import (
    Payload,
    add_payload,
    choose_joints,
    model_file_problem,
    packages_problem,
    parse_model_file,
    payload_problem,
    sdf_file_problem,
)
from nsdrake.control.validation import ControllerConfigError, arm_problem
from nsdrake.station.config import ArmConfig, ContactConfig, ObstacleConfig, PlateConfig, StationError
from nsdrake.station.contact_monitor import ContactMonitor
from nsdrake.station.elastic import ElasticMap, add_elastic_arm, rigid_arm_plant
from nsdrake.station.force_sensor import ForceSensor
from nsdrake.station.model_checks import check_model_file
from nsdrake.station.models import installed_package, package_of, resolve_model

SENSOR_JOINT = "force_sensor"


@dataclass
class StationPorts:
    """Where a controller meets the station (and where the realism rungs plug in)."""

    state: OutputPort  # [q; q̇] the controller reads (motor encoders behind belts) [rad, rad/s]
    link_state: OutputPort  # [q; q̇] of the links themselves, for the traces [rad, rad/s]
    wrench: OutputPort  # [M_So; f] the controller and the reference read, world [N m, N]
    true_wrench: OutputPort  # the ideal sensor's wrench (the contact itself) [N m, N]
    actuation: InputPort  # τ in the arm's joint order [N m]


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
    arm_file: Path  # the arm's model file (URDF, SDF or model directives)
    gravity: np.ndarray  # (3,) world gravity [m/s²]
    # package:// folders for the arm's model file, {name: folder} (besides its package.xml).
    packages: dict = field(default_factory=dict)
    # The payload welded to the tool, and whether the controller is told about it.
    payload: Payload | None = None
    payload_declared: bool = True
    # Drake's parser warnings on the arm's model files, {file name: [full text]}: the run's
    # model_warnings.txt (said one line per file as they are parsed).
    model_warnings: dict = field(default_factory=dict)
    # Bodies of the extra obstacles (welded to the world).
    obstacle_bodies: list = field(default_factory=list)
    # Proximity geometries of the arm's links (the tool's excepted) and of the obstacles (plate included).
    link_geometries: list = field(default_factory=list)
    obstacle_geometries: list = field(default_factory=list)
    # Pose of the plate frame in the world (its +y is the push direction).
    X_WP: RigidTransform | None = None
    # With belts (nsdrake/station/elastic.py): the plant has motor and belt coordinates,
    # arm_model is the rigid arm on a plant of its own (link coordinates), and this maps
    # between them. None: the plant's state is the arm's [q; q̇].
    elastic: ElasticMap | None = None
    # The plant's initial positions and velocities (q0, v0 unless elastic).
    plant_q0: np.ndarray | None = None
    plant_v0: np.ndarray | None = None
    sensor: ForceSensor | None = None  # the ideal six-axis sensor under the plate
    monitor: ContactMonitor | None = None  # contacts of the plate and obstacles with anything but the tool
    ports: StationPorts | None = None

    @property
    def tool_body(self):
        """The tool's body in the simulated plant."""
        return self.plant.GetFrameByName(self.arm_model.tool_frame.name(), self.arm).body()


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


def _model_file(src: str, where: str, name: str, base_dir: Path | None, packages=None) -> Path:
    try:
        path = resolve_model(name, base_dir, packages)
    except FileNotFoundError as e:
        raise StationError(f"{src}: {where}: {e}") from None
    problem = model_file_problem(path)
    if problem:
        raise StationError(f"{src}: {where}: {problem}")
    if path.suffix.lower() == ".urdf":
        try:
            check_model_file(path)
        except StationError as e:
            raise StationError(f"{src}: {e}") from None
    problem = sdf_file_problem(path)
    if problem:
        raise StationError(f"{src}: {path.name}: {problem[0]}: {problem[1]}")
    return path


def add_station(
    builder: DiagramBuilder,
    *,
    arm: ArmConfig,
    plate: PlateConfig,
    contact: ContactConfig,
    task_axes: Sequence[str],
    gravity: Sequence[float],
    time_step: float,
    obstacles: Sequence[ObstacleConfig] = (),
    belt=None,
    base_dir: Path | None = None,
    source: str = "station",
    sensing: bool = True,
) -> Station:
    """Adds the plant and scene graph, the force sensor, the contact monitor and the
    actuation map to ``builder``; finalizes the plant.

    ``belt``: with an object holding ``stiffness``, ``damping``, ``rotor_inertia`` and
    ``gear_ratio`` (:class:`nsdrake.realism.config.BeltConfig`), every joint is driven
    through a belt (:mod:`nsdrake.station.elastic`). Model paths are resolved against
    ``base_dir``; every problem is a one-line StationError naming ``source``. Without
    ``sensing``, only the plant and its scene graph (no ports): a diagram Drake can
    convert to AutoDiffXd, for geometry queries."""
    world = _add_world(
        builder,
        arm=arm,
        plate=plate,
        contact=contact,
        gravity=gravity,
        time_step=time_step,
        obstacles=obstacles,
        belt=belt,
        base_dir=base_dir,
        source=source,
    )
    station = _station_on(world, arm, task_axes, belt, source)
    _add_geometries(station, world.plate_body)
    if sensing:
        _add_sensing_and_actuation(builder, station)
    return station


class _World(NamedTuple):
    """The finalized plant and what :func:`_add_world` put in it."""

    plant: MultibodyPlant
    scene_graph: object
    arm: ModelInstanceIndex
    plate: ModelInstanceIndex
    plate_body: object
    sensor_joint: WeldJoint
    obstacle_bodies: list
    X_WP: RigidTransform
    arm_file: Path
    gravity: np.ndarray
    packages: dict
    payload: Payload | None
    model_warnings: dict  # Drake's parser warnings on the arm's files: {file name: [full text]}


def _add_world(
    builder, *, arm, plate, contact, gravity, time_step, obstacles, belt, base_dir, source
) -> _World:
    """The plant and its scene graph with the arm (behind belts, with ``belt``) and its
    payload, the plate welded to the world through the sensor joint, the obstacles and
    gravity; finalized."""
    config = MultibodyPlantConfig(
        time_step=time_step,
        contact_model=contact.model,
        discrete_contact_approximation=contact.approximation,
    )
    plant, scene_graph = AddMultibodyPlant(config, builder)
    plant.set_name("plant")
    scene_graph.set_name("scene_graph")
    packages = package_folders(arm, base_dir, source)
    arm_file = _model_file(source, "arm.urdf", arm.urdf, base_dir, packages)
    plate_file = _model_file(source, "plate.urdf", plate.urdf, base_dir)
    arm_instance, plate_instance, model_warnings = _parse(
        plant, arm_file, plate_file, belt, packages, arm, source
    )
    payload = station_payload(arm, source)
    if payload is not None:
        add_payload(plant, plant.GetFrameByName(arm.tool_frame, arm_instance), payload)
    plate_body = _the_one_body(plant, plate_instance, source)
    if arm.tip_radius > 0:
        tool = plant.GetFrameByName(arm.tool_frame, arm_instance)
        _add_tip(plant, scene_graph, tool, arm.tip_radius, plate_body)
    X_WP = RigidTransform(RollPitchYaw(plate.roll, plate.pitch, plate.yaw), np.asarray(plate.position))
    sensor_joint = plant.AddJoint(WeldJoint(SENSOR_JOINT, plant.world_frame(), plate_body.body_frame(), X_WP))
    obstacle_bodies = _add_obstacles(plant, scene_graph, obstacles, plate_body)
    gravity = np.asarray(gravity, dtype=float)
    plant.mutable_gravity_field().set_gravity_vector(gravity)
    _finalize(plant, source)
    return _World(
        plant,
        scene_graph,
        arm_instance,
        plate_instance,
        plate_body,
        sensor_joint,
        obstacle_bodies,
        X_WP,
        arm_file,
        gravity,
        packages,
        payload,
        model_warnings,
    )


def package_folders(arm: ArmConfig, base_dir: Path | None, source: str) -> dict[str, Path]:
    """``arm.packages`` with each folder resolved against ``base_dir`` (the scenario's folder),
    and the package of an ``arm.urdf`` given as ``package://NAME/...`` that pip installed
    (:func:`nsdrake.station.models.installed_package`) unless ``arm.packages`` names it."""
    folders = {
        name: (base_dir or Path.cwd()) / Path(folder).expanduser() for name, folder in arm.packages.items()
    }
    package = package_of(arm.urdf)
    if package is not None and package not in folders and installed_package(package) is not None:
        folders[package] = installed_package(package)
    problem = packages_problem(folders)
    if problem:
        raise StationError(f"{source}: arm.packages: {problem}")
    return folders


def station_payload(arm: ArmConfig, source: str) -> Payload | None:
    """``arm.payload`` as a :class:`nsdrake.control.model_files.Payload`, or None (mass 0)."""
    p = arm.payload
    if p.mass == 0:
        return None
    payload = Payload(mass=p.mass, com=tuple(p.com), inertia=tuple(p.inertia) if p.inertia else None)
    problem = payload_problem(payload)
    if problem:
        raise StationError(f"{source}: arm.payload: {problem}")
    return payload


def _station_on(world: _World, arm: ArmConfig, task_axes, belt, source: str) -> Station:
    """The arm's model on the task axes, its initial state and the plate's directions on
    the task axes, on the finalized ``world``."""
    plant = world.plant
    arm_model = _arm_model(plant, world, arm, task_axes, belt, source)
    q0, v0 = _initial_state(arm, arm_model.joint_names, source)
    elastic, plant_q0, plant_v0 = _plant_initial_state(plant, world.arm, arm_model, belt, q0, v0)
    try:
        normal, tangent = surface_directions(world.X_WP.rotation().matrix(), arm_model.rows)
    except ValueError as e:
        raise StationError(f"{source}: plate: {e} {list(task_axes)}") from None
    return Station(
        plant=plant,
        scene_graph=world.scene_graph,
        arm=world.arm,
        plate=world.plate,
        arm_model=arm_model,
        sensor_joint=world.sensor_joint,
        normal=normal,
        tangent=tangent,
        q0=q0,
        v0=v0,
        arm_file=world.arm_file,
        gravity=world.gravity,
        packages=world.packages,
        payload=world.payload,
        payload_declared=arm.payload.declared,
        model_warnings=world.model_warnings,
        obstacle_bodies=world.obstacle_bodies,
        X_WP=world.X_WP,
        elastic=elastic,
        plant_q0=plant_q0,
        plant_v0=plant_v0,
    )


def _parse(plant: MultibodyPlant, arm_file: Path, plate_file: Path, belt, packages, arm: ArmConfig, src: str):
    """(the arm's model instance, the plate's, Drake's parser warnings on the arm's files by
    file name): the arm's is the one that holds the tool frame
    (a model directives file may add several). The arm's files are read as the controller's
    model reads them (:func:`nsdrake.control.model_files.parse_model_file`: every included
    file checked, meshes Drake takes no hull of given as hulls, a floating root welded, an
    actuator per ``<limit effort>``), and the joints not in ``arm.joints`` locked."""
    if belt is not None and arm_file.suffix.lower() != ".urdf":
        raise StationError(
            f"{src}: realism.belt: belts split the joints of a URDF; {arm_file.name} is not one"
        )
    add = None if belt is None else (lambda parser, file: add_elastic_arm(plant, parser, file, belt))
    try:
        parsed = parse_model_file(plant, arm_file, packages, "arm.urdf", add=add)
        choose_joints(plant, arm.joints or None, arm.locked, parsed.sources.mimics, "arm.joints")
    except ControllerConfigError as e:
        raise StationError(f"{src}: {e}") from None
    try:
        (plate,) = Parser(plant).AddModels(str(plate_file))
    except Exception as e:
        raise StationError(f"{src}: cannot parse a model: {' '.join(str(e).split())}") from None
    holding = [i for i in parsed.instances if plant.HasFrameNamed(arm.tool_frame, i)]
    if len(holding) != 1:
        raise StationError(f"{src}: arm.tool_frame: no frame '{arm.tool_frame}' in {arm_file.name}")
    return holding[0], plate, parsed.warnings


def _the_one_body(plant: MultibodyPlant, plate: ModelInstanceIndex, src: str):
    plate_bodies = plant.GetBodyIndices(plate)
    if len(plate_bodies) != 1:
        raise StationError(f"{src}: plate.urdf: the plate model must have exactly one body")
    return plant.get_body(plate_bodies[0])


def _arm_model(plant, world: _World, arm: ArmConfig, task_axes, belt, src) -> ArmModel:
    """The arm's kinematics and dynamics on the task axes: on the station's plant, or on a
    rigid arm of its own beside belts (link coordinates)."""
    arm_instance, arm_file = world.arm, world.arm_file
    if not plant.HasFrameNamed(arm.tool_frame, arm_instance):
        raise StationError(f"{src}: arm.tool_frame: no frame '{arm.tool_frame}' in {arm_file.name}")
    tool = plant.GetFrameByName(arm.tool_frame, arm_instance)
    if belt is not None:
        tool = rigid_arm_plant(arm_file, world.gravity, world.packages).GetFrameByName(arm.tool_frame)
    try:
        arm_model = ArmModel(tool.GetParentPlant(), tool, tuple(task_axes))
    except ValueError as e:
        raise StationError(f"{src}: arm.urdf: {e}") from None
    problem = arm_problem(arm_model.n, arm_model.m, task_axes)  # before any terms are computed
    if problem:
        where = "task.axes" if problem[0] == "task_axes" else f"arm.urdf: {arm_file.name}"
        raise StationError(f"{src}: {where}: {problem[1]}")
    if plant.num_actuators() != arm_model.n:
        raise StationError(
            f"{src}: arm.urdf: the arm needs one actuator per joint ({arm_model.n}), "
            f"it has {plant.num_actuators()}"
        )
    return arm_model


def _finalize(plant: MultibodyPlant, source: str) -> None:
    """Finalizes the plant; what the model checks did not foresee is one line."""
    try:
        plant.Finalize()
    except RuntimeError as e:
        text = " ".join(str(e).split())
        text = text if len(text) <= 240 else text[:239] + "…"
        raise StationError(f"{source}: arm.urdf: Drake cannot build the plant: {text}") from None


def _short(name) -> str:
    text = " ".join(str(name).split())
    return text if len(text) <= 80 else text[:79] + "…"


def _initial_state(arm: ArmConfig, names: tuple[str, ...], src: str) -> tuple[np.ndarray, np.ndarray]:
    """(q0, v0) in the arm's joint order from the settings keyed by joint name."""
    for where, table in (
        ("arm.initial_positions", arm.initial_positions),
        ("arm.initial_velocities", arm.initial_velocities),
    ):
        for name in table:
            if name not in names:
                raise StationError(
                    f"{src}: {where}.{_short(name)}: unknown joint; the arm's joints are {', '.join(names)}"
                )
    missing = [j for j in names if j not in arm.initial_positions]
    if missing:
        raise StationError(f"{src}: arm.initial_positions: no position for joint(s) {', '.join(missing)}")
    q0 = np.array([arm.initial_positions[j] for j in names])
    v0 = np.array([arm.initial_velocities.get(j, 0.0) for j in names])
    return q0, v0


def _plant_initial_state(plant, arm_instance, arm_model: ArmModel, belt, q0, v0):
    """(elastic map or None, the plant's q0, its v0): the arm's own without belts; behind
    belts, the belts preloaded by gravity so that the arm starts at rest (the gravity
    torque on each belt coordinate, links and rotors beyond it, does not depend on δ at
    fixed q). Sets the plant's default positions, which survive context resets."""
    if belt is None:
        plant.SetDefaultPositions(q0)
        return None, q0, v0
    elastic = ElasticMap.build(plant, arm_instance, arm_model.joint_names, belt.stiffness)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, elastic.plant_positions(q0))
    tau_g = plant.CalcGravityGeneralizedForces(context)[elastic.belt_v]
    plant_q0 = elastic.plant_positions(q0, elastic.static_deflection(tau_g))
    plant.SetDefaultPositions(plant_q0)  # DRAKE_NOTES
    return elastic, plant_q0, elastic.plant_velocities(v0)


def _add_geometries(station: Station, plate_body) -> None:
    plant = station.plant
    inspector = station.scene_graph.model_inspector()
    tool = station.tool_body.index()
    arm_bodies = [b for b in plant.GetBodyIndices(station.arm) if b != tool]
    obstacle_indices = [plate_body.index(), *(b.index() for b in station.obstacle_bodies)]
    station.link_geometries = proximity_geometries(inspector, plant, arm_bodies)
    station.obstacle_geometries = proximity_geometries(inspector, plant, obstacle_indices)


def _add_sensing_and_actuation(builder: DiagramBuilder, station: Station) -> None:
    """The force sensor under the plate, the monitor of contacts other than the tool's,
    the motor encoders behind belts, and τ = B u's map u = Bᵀ τ (a permutation, or the
    motors behind the belts); sets ``station.ports``."""
    plant = station.plant
    sensor = builder.AddNamedSystem(
        "force_sensor", ForceSensor(plant=plant, sensor_joint=station.sensor_joint)
    )
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.get_input_port())
    monitor = builder.AddNamedSystem(
        "contact_monitor",
        ContactMonitor(
            plant=plant,
            watched={*plant.GetBodyIndices(station.plate), *(b.index() for b in station.obstacle_bodies)},
            allowed={station.tool_body.index()},
        ),
    )
    builder.Connect(plant.get_contact_results_output_port(), monitor.get_input_port())
    state = link_state = plant.get_state_output_port()
    if station.elastic is not None:
        encoders = builder.AddNamedSystem("motor_encoders", MatrixGain(station.elastic.motor_state_matrix()))
        builder.Connect(plant.get_state_output_port(), encoders.get_input_port())
        links = builder.AddNamedSystem("link_state", MatrixGain(station.elastic.link_state_matrix()))
        builder.Connect(plant.get_state_output_port(), links.get_input_port())
        state, link_state = encoders.get_output_port(), links.get_output_port()
    B_T = station.elastic.actuation if station.elastic is not None else plant.MakeActuationMatrix().T
    actuation = builder.AddNamedSystem("actuation_map", MatrixGain(B_T))
    builder.Connect(actuation.get_output_port(), plant.get_actuation_input_port())
    station.sensor, station.monitor = sensor, monitor
    station.ports = StationPorts(
        state=state,
        link_state=link_state,
        wrench=sensor.GetOutputPort("wrench"),
        true_wrench=sensor.GetOutputPort("wrench"),
        actuation=actuation.get_input_port(),
    )


def _add_tip(plant: MultibodyPlant, scene_graph, tool_frame, radius: float, plate_body) -> None:
    """arm.tip_radius: a sphere centred on the tool frame's origin, on the tool frame's body
    (no mass of its own), to touch with, with the plate's contact properties (the shipped
    tools' and plates' are the same: stiffness 1e5 N/m, dissipation 5 s/m, mu 0.3)."""
    (plate_geometry,) = plant.GetCollisionGeometriesForBody(plate_body)
    properties = scene_graph.model_inspector().GetProximityProperties(plate_geometry)
    body, X_BT = tool_frame.body(), tool_frame.GetFixedPoseInBodyFrame()
    plant.RegisterCollisionGeometry(body, X_BT, Sphere(radius), "tip", ProximityProperties(properties))
    plant.RegisterVisualGeometry(body, X_BT, Sphere(radius), "tip", np.array([0.85, 0.2, 0.15, 1.0]))


def _add_obstacles(
    plant: MultibodyPlant, scene_graph, obstacles: Sequence[ObstacleConfig], plate_body
) -> list:
    """Welds each obstacle to the world (joint obstacle_<name>), with the plate's contact
    properties, so that a link that hits one is stopped physically."""
    if not obstacles:
        return []
    instance = plant.AddModelInstance("obstacles")
    inspector = scene_graph.model_inspector()
    (plate_geometry,) = plant.GetCollisionGeometriesForBody(plate_body)
    properties = inspector.GetProximityProperties(plate_geometry)
    bodies = []
    for ob in obstacles:
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


def initial_task_position(station: Station) -> np.ndarray:
    """x = p(q0), the tool's task position at the initial pose. (m,) [m]."""
    plant = station.arm_model.plant  # the station's plant, or the rigid arm's beside an elastic one
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, station.q0)
    return station.arm_model.task_position(context)


def has_joint_limits(station: Station) -> bool:
    """Whether the arm has any finite joint position limit (the Panda; not the paper's arm)."""
    plant = station.plant
    return bool(
        np.isfinite(plant.GetPositionLowerLimits()).any() or np.isfinite(plant.GetPositionUpperLimits()).any()
    )


def tool_orientation(station: Station, q: np.ndarray) -> np.ndarray:
    """R_WT, the tool frame's orientation in the world at joint positions q. (3, 3)."""
    context = station.plant.CreateDefaultContext()
    station.plant.SetPositions(context, q)
    return station.arm_model.tool_frame.CalcPoseInWorld(context).rotation().matrix()


def desired_tool_orientation(station: Station, how: str) -> np.ndarray:
    """R_d for a pose task: the tool's orientation at q0 ("start"), or that one turned by
    the smallest rotation that points the tool frame's z axis along the plate's push
    direction ("perpendicular"). (3, 3)."""
    R0 = tool_orientation(station, station.q0)
    if how == "start":
        return R0
    z = station.X_WP.rotation().matrix()[:, 1]  # the push direction, world
    axis = np.cross(R0[:, 2], z)
    s, c = np.linalg.norm(axis), float(R0[:, 2] @ z)
    if s < 1e-15:
        return R0 if c > 0 else RollPitchYaw(np.pi, 0.0, 0.0).ToRotationMatrix().matrix() @ R0
    return AngleAxis(np.arctan2(s, c), axis / s).rotation() @ R0

"""The station's settings: the arm's and the plate's model files and poses, Drake's
contact model, and the extra obstacles. A scenario (:mod:`nsdrake.experiment.scenario`)
is built from these; :func:`nsdrake.station.plant.add_station` reads them.
Every field names its unit."""

from dataclasses import dataclass, field

CONTACT_APPROXIMATIONS = ("lagged", "sap", "similar")
CONTACT_MODELS = ("point", "hydroelastic_with_fallback")


class StationError(ValueError):
    """A station that cannot be built; the message is one line naming file and field."""


@dataclass
class PayloadConfig:
    """What the tool carries (a gripper, a part), welded to the tool frame in the simulated
    plant and, when ``declared``, in the controller's model too."""

    # Its mass; 0: no payload [kg].
    mass: float = 0.0
    # Its centre of mass in the tool frame [m].
    com: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    # Its rotational inertia about the centre of mass, in the tool frame's axes, as
    # [ixx, iyy, izz, ixy, ixz, iyz]; empty: a point mass [kg m²].
    inertia: list[float] = field(default_factory=list)
    # Whether the controller is told (false: the arm carries a payload its controller does
    # not know about, and the tool sags by what the impedance lets it) [-].
    declared: bool = True


@dataclass
class ArmConfig:
    # Model file: a shipped model name (urdf/), a path relative to the scenario file, or
    # package://NAME/path (NAME's folder from packages, else the package pip installed, as
    # example-robot-data's robots); a URDF, an SDF or Drake model directives (.dmd.yaml),
    # parsed from the file (its meshes' relative URIs resolve from its folder) [-].
    urdf: str = "arm4.urdf"
    # package:// URIs: {package name: folder}, folders relative to the scenario file; the
    # nearest package.xml above the model file and ROS_PACKAGE_PATH are searched too [-].
    packages: dict[str, str] = field(default_factory=dict)
    # A payload on the tool frame; none by default.
    payload: PayloadConfig = field(default_factory=PayloadConfig)
    # Frame of the arm whose origin is the task point (the tool tip) [-].
    tool_frame: str = "tool"
    # A sphere of this radius centred on the tool frame's origin, massless, with the plate's
    # contact properties: a tip that touches, for a model whose file has no tool of its own
    # (a vendor's flange or hand); 0: none [m].
    tip_radius: float = 0.0
    # The arm's joints, by name; empty: every joint of the model file. The others (gripper
    # fingers, a mobile base) are locked at their position in ``locked`` [-].
    joints: list[str] = field(default_factory=list)
    # Positions of the joints not in ``joints``, keyed by joint name; 0 where not given [rad or m].
    locked: dict[str, float] = field(default_factory=dict)
    # Joint positions at t = 0, keyed by joint name; every joint must be given [rad].
    initial_positions: dict[str, float] = field(default_factory=dict)
    # Joint velocities at t = 0, keyed by joint name; missing joints start at rest [rad/s].
    initial_velocities: dict[str, float] = field(default_factory=dict)


@dataclass
class PlateConfig:
    # Model file of the plate (the force-sensor mount welds its root body to the world) [-].
    urdf: str = "plate.urdf"
    # Position of the plate frame (centre of its contact face) in the world [m].
    position: list[float] = field(default_factory=lambda: [0.0, 0.6, 0.0])
    # Rotation of the plate about the world z axis; at 0 the tool pushes along +y [rad].
    yaw: float = 0.0
    # Rotations about the world x and y axes (roll, pitch, then yaw), for a tilted plate;
    # the push direction (plate +y) must stay within the task axes [rad].
    roll: float = 0.0
    pitch: float = 0.0


@dataclass
class ContactConfig:
    # Drake's discrete contact approximation: lagged, sap or similar [-].
    approximation: str = "lagged"
    # Drake's contact model: point, or hydroelastic_with_fallback [-].
    model: str = "point"


OBSTACLE_SHAPES = {"box": 3, "sphere": 1, "cylinder": 2}  # number of size entries


@dataclass
class ObstacleConfig:
    """An extra obstacle welded to the world (the plate is always one)."""

    # Unique name; its weld joint is called obstacle_<name> [-].
    name: str = ""
    # box, sphere or cylinder (axis along z) [-].
    shape: str = ""
    # box: [lx, ly, lz]; sphere: [radius]; cylinder: [radius, length] [m].
    size: list[float] = field(default_factory=list)
    # Position of its centre in the world [m].
    position: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    # Rotation about the world z axis [rad].
    yaw: float = 0.0

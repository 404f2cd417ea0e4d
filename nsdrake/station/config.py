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
class ArmConfig:
    # Model file: a shipped model name (urdf/) or a path relative to the scenario file [-].
    urdf: str = "arm4.urdf"
    # Frame of the arm whose origin is the task point (the tool tip) [-].
    tool_frame: str = "tool"
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

"""Scenarios: typed dataclasses loaded from YAML with Drake's ``yaml_load_typed``.

(No ``from __future__ import annotations`` here: ``yaml_load_typed`` reads the
dataclass field types at run time.)

A scenario file sets any subset of the fields below; the rest keep their
defaults. Every field names its unit. :func:`load_scenario` reads a shipped
scenario by name, optionally overlays a user's YAML file on it, and validates
the result; every problem is a :class:`ScenarioError` whose one-line message
names the file and the field.
"""

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from pydrake.common.yaml import yaml_load_typed

from .config import (
    NULL_SPACE_SOURCES,
    ActuatorLimitsConfig,
    DesiredNullSpaceConfig,
    ImpedanceConfig,
    NullSpaceConfig,
)
from .pseudo_inverse import GeneralizedInverse, PseudoInverseKind
from .realism import RealismConfig, realism_problems

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"

PLANES = ("horizontal", "vertical")
CONTACT_APPROXIMATIONS = ("lagged", "sap", "similar")
CONTACT_MODELS = ("point", "hydroelastic_with_fallback")


class ScenarioError(ValueError):
    """A scenario that cannot be run; the message is one line naming file and field."""


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


@dataclass
class TaskConfig:
    # World axes of the primary task, the tool point's coordinates x (Eq. 1) [-].
    axes: list[str] = field(default_factory=lambda: ["x", "y"])


@dataclass
class ReferenceConfig:
    """The Fig. 3 task: slide along the plate, approach it until contact, then press."""

    # Speed of the constant-velocity ramp along the plate [m/s].
    tangent_speed: float = 0.05
    # Speed of the approach toward the plate, held until contact is detected; 0 holds the
    # distance (a run without contact) [m/s].
    approach_speed: float = 0.03
    # Time over which both speeds rise from rest (constant acceleration) [s].
    blend_time: float = 0.2
    # Desired normal force once in contact, f_d [N].
    force: float = 10.0
    # Time over which f_d rises from 0 to its value after contact (smoothstep) [s].
    force_ramp_time: float = 0.2
    # Measured normal force above which the tool counts as touching [N].
    contact_threshold: float = 0.5
    # A step of the desired force, this long after contact; 0 (or less) means no step [s].
    step_time: float = 0.0
    # The desired normal force after that step [N].
    step_force: float = 0.0
    # Contact counts as lost once the normal force has stayed below contact_threshold this long [s].
    loss_time: float = 0.05
    # After a loss, the normal reference approaches at most this far beyond the lost surface [m].
    max_overtravel: float = 0.02
    # The slide stops where the reference would come closer than this share of the arm's
    # reach to the edge of its workspace [-].
    reach_margin: float = 0.05


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


REPORT_CHECKS = ("fig3", "priority")


@dataclass
class DivergenceConfig:
    """When a run counts as diverged and is stopped (nsdrake/simulate.py)."""

    # Any joint faster than this [rad/s].
    max_joint_speed: float = 100.0
    # Any commanded joint torque larger than this [N m].
    max_torque: float = 1.0e4


@dataclass
class ReportConfig:
    # Also run the scenario with q̇_dⁿ = 0 and report its final joint-torque criterion [-].
    compare_without_null_space_task: bool = True
    # Acceptance figures to compute: fig3 (contact, force and position tracking, the
    # null space follows its command) and/or priority (modes, criteria, torque steps) [-].
    checks: list[str] = field(default_factory=lambda: ["fig3"])
    # With the priority check: the modes the run must visit (1 obstacle avoidance,
    # 2 joint torque, 3 manipulability) [-].
    required_modes: list[int] = field(default_factory=list)


@dataclass
class Scenario:
    # One line saying what the scenario shows [-].
    description: str = ""
    # Simulated time [s].
    duration: float = 5.0
    # Control period; the discrete plant steps at this period too [s].
    control_period: float = 0.002
    # horizontal: gravity along −z, normal to the arm's plane; vertical: gravity along −y [-].
    plane: str = "horizontal"
    # World gravity [gx, gy, gz], in any direction; empty: set by ``plane`` [m/s²].
    gravity: list[float] = field(default_factory=list)
    arm: ArmConfig = field(default_factory=ArmConfig)
    plate: PlateConfig = field(default_factory=PlateConfig)
    contact: ContactConfig = field(default_factory=ContactConfig)
    task: TaskConfig = field(default_factory=TaskConfig)
    reference: ReferenceConfig = field(default_factory=ReferenceConfig)
    impedance: ImpedanceConfig = field(default_factory=ImpedanceConfig)
    null_space: NullSpaceConfig = field(default_factory=NullSpaceConfig)
    desired_null_space: DesiredNullSpaceConfig = field(default_factory=DesiredNullSpaceConfig)
    actuator_limits: ActuatorLimitsConfig = field(default_factory=ActuatorLimitsConfig)
    # Obstacles besides the plate.
    obstacles: list[ObstacleConfig] = field(default_factory=list)
    report: ReportConfig = field(default_factory=ReportConfig)
    divergence: DivergenceConfig = field(default_factory=DivergenceConfig)
    # Effects of the real robot, each off by default (nsdrake/realism.py: the realism ladder).
    realism: RealismConfig = field(default_factory=RealismConfig)
    # Where the scenario was read from (set by the loader; not a YAML field).
    source: str = field(default="", metadata={"yaml": False})
    # Folder that relative model paths are resolved against (set by the loader; not a YAML field).
    base_dir: str = field(default="", metadata={"yaml": False})

    def generalized_inverse(self) -> GeneralizedInverse:
        return GeneralizedInverse(PseudoInverseKind(self.null_space.pseudo_inverse), self.null_space.damping)


def shipped_scenarios() -> list[str]:
    """Names of the scenarios that ship with nsdrake."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


class _StrictLoader(yaml.SafeLoader):
    """A YAML loader that refuses duplicate keys instead of keeping the last one."""


def _no_duplicates(loader, node, deep=False):
    seen = set()
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            line = key_node.start_mark.line + 1
            raise yaml.constructor.ConstructorError(None, None, f"line {line}: duplicate key '{key}'")
        seen.add(key)
    return loader.construct_mapping(node, deep=deep)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _no_duplicates)


def _kind(t) -> str:
    origin = typing.get_origin(t)
    if dataclasses.is_dataclass(t):
        return "a mapping of fields"
    if origin is dict:
        return "a mapping"
    if origin is list:
        return "a list"
    return {float: "a number", int: "an integer", bool: "true or false", str: "a string"}.get(t, str(t))


def check_shape(data, schema, where: str) -> str | None:
    """The first place where ``data`` (parsed YAML) does not fit ``schema``, as "path: problem"."""
    if dataclasses.is_dataclass(schema):
        if not isinstance(data, dict):
            return f"{where or 'the file'}: must be {_kind(schema)}, got {data!r}"
        hints = typing.get_type_hints(schema)
        fields = {f.name: f for f in dataclasses.fields(schema) if f.metadata.get("yaml", True)}
        for key, value in data.items():
            path = f"{where}.{key}" if where else str(key)
            if key not in fields:
                return f"{path}: unknown field; valid fields here are {', '.join(fields)}"
            problem = check_shape(value, hints[key], path)
            if problem:
                return problem
        return None
    origin, args = typing.get_origin(schema), typing.get_args(schema)
    if origin is dict:
        if not isinstance(data, dict):
            return f"{where}: must be {_kind(schema)}, got {data!r}"
        for key, value in data.items():
            problem = check_shape(value, args[1], f"{where}.{key}")
            if problem:
                return problem
        return None
    if origin is list:
        if not isinstance(data, list):
            return f"{where}: must be {_kind(schema)}, got {data!r}"
        for i, value in enumerate(data):
            problem = check_shape(value, args[0], f"{where}[{i}]")
            if problem:
                return problem
        return None
    ok = {
        float: lambda x: isinstance(x, (int, float)) and not isinstance(x, bool),
        int: lambda x: isinstance(x, int) and not isinstance(x, bool),
        bool: lambda x: isinstance(x, bool),
        str: lambda x: isinstance(x, str),
    }[schema]
    if not ok(data):
        return f"{where}: must be {_kind(schema)}, got {data!r}"
    return None


def read_yaml(path: Path, kind: str = "scenario") -> tuple[str, object]:
    """(text, parsed data) of a YAML file, with duplicate keys refused; every problem
    (missing, unreadable, malformed, empty) is a one-line ScenarioError naming the file."""
    if not path.is_file():
        raise ScenarioError(f"{path}: no such {kind} file")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(f"{path}: cannot read: {_one_line(e)}") from None
    try:
        data = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as e:
        raise ScenarioError(f"{path}: malformed YAML: {_one_line(e)}") from None
    if data is None:
        raise ScenarioError(f"{path}: the file is empty")
    return text, data


def _read(path: Path, defaults: Scenario | None) -> Scenario:
    text, data = read_yaml(path)
    problem = check_shape(data, Scenario, "")
    if problem:
        raise ScenarioError(f"{path}: {problem}")
    try:
        return yaml_load_typed(schema=Scenario, data=text, defaults=defaults or Scenario())
    except Exception as e:  # anything the shape check missed
        raise ScenarioError(f"{path}: {_one_line(e)}") from None


def load_scenario(name: str, config: str | Path | None = None, duration: float | None = None) -> Scenario:
    """The shipped scenario ``name``, with the YAML file ``config`` overlaid, validated.

    ``duration`` (command line) overrides the files. Raises ScenarioError.
    """
    known = shipped_scenarios()
    if name not in known:
        raise ScenarioError(f"unknown scenario '{name}'; the shipped scenarios are {', '.join(known)}")
    path = SCENARIO_DIR / f"{name}.yaml"
    scenario = _read(path, None)
    scenario.source, scenario.base_dir = str(path), str(path.parent)
    if config is not None:
        config = Path(config)
        scenario = _read(config, scenario)
        scenario.source, scenario.base_dir = f"{path.name} + {config}", str(config.resolve().parent)
    if duration is not None:
        scenario = dataclasses.replace(scenario, duration=duration)
        check_positive(scenario.source, "--duration", duration)
    validate(scenario)
    return scenario


def load_scenario_file(path: str | Path) -> Scenario:
    """A scenario from a standalone YAML file (defaults for everything it leaves out), validated."""
    path = Path(path)
    scenario = _read(path, None)
    scenario.source, scenario.base_dir = str(path), str(path.resolve().parent)
    validate(scenario)
    return scenario


def _fail(source: str, where: str, problem: str):
    raise ScenarioError(f"{source}: {where}: {problem}")


def check_finite(source: str, where: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        _fail(source, where, f"must be a finite number, got {value!r}")


def check_positive(source: str, where: str, value) -> None:
    check_finite(source, where, value)
    if value <= 0:
        _fail(source, where, f"must be > 0, got {value!r}")


def check_non_negative(source: str, where: str, value) -> None:
    check_finite(source, where, value)
    if value < 0:
        _fail(source, where, f"must be >= 0, got {value!r}")


def check_choice(source: str, where: str, value, choices) -> None:
    if value not in choices:
        _fail(source, where, f"must be one of {', '.join(choices)}, got {value!r}")


def validate(s: Scenario) -> None:
    """Checks every field that does not need the plant; raises ScenarioError."""
    src = s.source or "scenario"
    check_positive(src, "duration", s.duration)
    check_positive(src, "control_period", s.control_period)
    if s.control_period > s.duration:
        _fail(src, "control_period", f"{s.control_period} s is longer than the duration {s.duration} s")
    check_choice(src, "plane", s.plane, PLANES)
    for name, value in s.arm.initial_positions.items():
        check_finite(src, f"arm.initial_positions.{name}", value)
    for name, value in s.arm.initial_velocities.items():
        check_finite(src, f"arm.initial_velocities.{name}", value)
    if not s.arm.initial_positions:
        _fail(src, "arm.initial_positions", "must give a position for every joint")
    if len(s.plate.position) != 3:
        _fail(src, "plate.position", f"must be [x, y, z], got {s.plate.position!r}")
    for i, value in enumerate(s.plate.position):
        check_finite(src, f"plate.position[{i}]", value)
    for name in ("yaw", "roll", "pitch"):
        check_finite(src, f"plate.{name}", getattr(s.plate, name))
    if s.gravity and len(s.gravity) != 3:
        _fail(src, "gravity", f"must be [gx, gy, gz] or empty, got {s.gravity!r}")
    for i, value in enumerate(s.gravity):
        check_finite(src, f"gravity[{i}]", value)
    for i, check in enumerate(s.report.checks):
        check_choice(src, f"report.checks[{i}]", check, REPORT_CHECKS)
    for i, m in enumerate(s.report.required_modes):
        if m not in (0, 1, 2, 3):
            _fail(src, f"report.required_modes[{i}]", f"must be a mode 0-3, got {m!r}")
    check_choice(src, "contact.approximation", s.contact.approximation, CONTACT_APPROXIMATIONS)
    check_choice(src, "contact.model", s.contact.model, CONTACT_MODELS)
    axes = s.task.axes
    for i, a in enumerate(axes):
        check_choice(src, f"task.axes[{i}]", a, ("x", "y", "z"))
    if not axes or len(set(axes)) != len(axes):
        _fail(src, "task.axes", f"must be distinct axes, got {axes!r}")
    r = s.reference
    for name in ("tangent_speed", "approach_speed"):
        check_finite(src, f"reference.{name}", getattr(r, name))
    check_non_negative(src, "reference.approach_speed", r.approach_speed)
    for name in ("blend_time", "force_ramp_time"):
        check_non_negative(src, f"reference.{name}", getattr(r, name))
    check_positive(src, "reference.force", r.force)
    check_positive(src, "reference.contact_threshold", r.contact_threshold)
    check_positive(src, "reference.loss_time", r.loss_time)
    check_non_negative(src, "reference.max_overtravel", r.max_overtravel)
    check_non_negative(src, "reference.reach_margin", r.reach_margin)
    if r.reach_margin >= 1.0:
        _fail(src, "reference.reach_margin", f"must be below 1, got {r.reach_margin}")
    check_finite(src, "reference.step_time", r.step_time)
    if r.step_time > 0:
        check_positive(src, "reference.step_force", r.step_force)
    if r.contact_threshold >= r.force:
        _fail(
            src,
            "reference.contact_threshold",
            f"{r.contact_threshold} N must be below reference.force {r.force} N",
        )
    imp = s.impedance
    for name in ("K_p_tangent", "K_v_tangent", "K_v_normal", "K_f"):
        check_positive(src, f"impedance.{name}", getattr(imp, name))
    check_non_negative(src, "impedance.K_p_normal", imp.K_p_normal)
    ns = s.null_space
    check_positive(src, "null_space.K_n", ns.K_n)
    check_choice(src, "null_space.pseudo_inverse", ns.pseudo_inverse, [k.value for k in PseudoInverseKind])
    check_non_negative(src, "null_space.damping", ns.damping)
    try:
        s.generalized_inverse()
    except ValueError as e:
        _fail(src, "null_space.damping", _one_line(e))
    d = s.desired_null_space
    check_choice(src, "desired_null_space.source", d.source, NULL_SPACE_SOURCES)
    for name, value in d.sweep.direction.items():
        check_finite(src, f"desired_null_space.sweep.direction.{name}", value)
    check_non_negative(src, "desired_null_space.sweep.amplitude", d.sweep.amplitude)
    check_non_negative(src, "desired_null_space.sweep.frequency", d.sweep.frequency)
    check_non_negative(src, "desired_null_space.sweep.start_time", d.sweep.start_time)
    check_non_negative(src, "desired_null_space.sweep.ramp_time", d.sweep.ramp_time)
    if d.source == "sweep" and not any(d.sweep.direction.values()):
        _fail(src, "desired_null_space.sweep.direction", "a sweep needs a non-zero direction")
    crit = "desired_null_space.criteria"
    check_non_negative(src, f"{crit}.obstacle.gain", d.criteria.obstacle.gain)
    check_positive(src, f"{crit}.obstacle.influence_distance", d.criteria.obstacle.influence_distance)
    check_finite(src, f"{crit}.joint_torque.gain", d.criteria.joint_torque.gain)
    if d.criteria.joint_torque.gain > 0:
        _fail(
            src,
            f"{crit}.joint_torque.gain",
            f"must be <= 0 (a negative gain minimises the torque), got {d.criteria.joint_torque.gain}",
        )
    check_non_negative(src, f"{crit}.manipulability.gain", d.criteria.manipulability.gain)
    sel = d.selector
    for name in ("d_lim", "w_lim", "d_band", "w_band", "blend_time"):
        check_non_negative(src, f"desired_null_space.selector.{name}", getattr(sel, name))
    if d.criteria.obstacle.influence_distance < sel.d_lim + sel.d_band:
        _fail(
            src,
            f"{crit}.obstacle.influence_distance",
            f"{d.criteria.obstacle.influence_distance} m must be >= selector.d_lim + d_band = "
            f"{sel.d_lim + sel.d_band} m, or obstacle avoidance would have no gradient when it takes level 2",
        )
    for name, value in d.joint_speed_limits.items():
        check_positive(src, f"desired_null_space.joint_speed_limits.{name}", value)
    check_non_negative(src, "desired_null_space.speed_headroom", d.speed_headroom)
    if d.speed_headroom >= 1.0:
        _fail(src, "desired_null_space.speed_headroom", f"must be below 1, got {d.speed_headroom}")
    for kind in ("torque", "torque_rate"):
        for name, value in getattr(s.actuator_limits, kind).items():
            check_positive(src, f"actuator_limits.{kind}.{name}", value)
    check_positive(src, "divergence.max_joint_speed", s.divergence.max_joint_speed)
    check_positive(src, "divergence.max_torque", s.divergence.max_torque)
    for where, problem in realism_problems(s.realism, s.control_period):
        _fail(src, f"realism.{where}", problem)
    names = set()
    for i, ob in enumerate(s.obstacles):
        where = f"obstacles[{i}]"
        if not ob.name:
            _fail(src, f"{where}.name", "every obstacle needs a name")
        if ob.name in names:
            _fail(src, f"{where}.name", f"duplicate obstacle name '{ob.name}'")
        names.add(ob.name)
        if not ob.shape:
            _fail(
                src,
                where,
                f"obstacle '{ob.name}' has no geometry: give shape ({', '.join(OBSTACLE_SHAPES)}) and size",
            )
        check_choice(src, f"{where}.shape", ob.shape, tuple(OBSTACLE_SHAPES))
        if len(ob.size) != OBSTACLE_SHAPES[ob.shape]:
            _fail(
                src,
                f"{where}.size",
                f"a {ob.shape} needs {OBSTACLE_SHAPES[ob.shape]} size entries, got {ob.size!r}",
            )
        for k, value in enumerate(ob.size):
            check_positive(src, f"{where}.size[{k}]", value)
        if len(ob.position) != 3:
            _fail(src, f"{where}.position", f"must be [x, y, z], got {ob.position!r}")
        for k, value in enumerate(ob.position):
            check_finite(src, f"{where}.position[{k}]", value)
        check_finite(src, f"{where}.yaw", ob.yaw)


def check_against_plant(s: Scenario, joint_names: tuple[str, ...]) -> None:
    """Checks the fields keyed by joint name against the arm's joints."""
    src = s.source or "scenario"
    valid = ", ".join(joint_names)
    tables = {
        "arm.initial_positions": s.arm.initial_positions,
        "arm.initial_velocities": s.arm.initial_velocities,
        "desired_null_space.joint_speed_limits": s.desired_null_space.joint_speed_limits,
        "desired_null_space.sweep.direction": s.desired_null_space.sweep.direction,
        "actuator_limits.torque": s.actuator_limits.torque,
        "actuator_limits.torque_rate": s.actuator_limits.torque_rate,
    }
    for where, table in tables.items():
        for name in table:
            if name not in joint_names:
                _fail(src, f"{where}.{name}", f"unknown joint; the arm's joints are {valid}")
    missing = [j for j in joint_names if j not in s.arm.initial_positions]
    if missing:
        _fail(src, "arm.initial_positions", f"no position for joint(s) {', '.join(missing)}")

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
import re
import typing
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from pydrake.common.yaml import yaml_load_typed

from .pseudo_inverse import GeneralizedInverse, PseudoInverseKind

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


@dataclass
class ImpedanceConfig:
    """Gains of the primary task law, Eqs. 6–8 (acceleration units: the law multiplies by Λ)."""

    # Position gain along the plate [1/s²].
    K_p_tangent: float = 400.0
    # Velocity gain along the plate [1/s].
    K_v_tangent: float = 40.0
    # Position gain normal to the plate [1/s²].
    K_p_normal: float = 100.0
    # Velocity gain normal to the plate [1/s].
    K_v_normal: float = 200.0
    # Force gain normal to the plate [m/(s² N)].
    K_f: float = 1.0
    # Add the gravity torques g of Eq. 7 (needed in the vertical plane) [-].
    gravity_compensation: bool = True


@dataclass
class NullSpaceConfig:
    """The null-space velocity controller, Eq. 21."""

    # Null-space velocity gain K_n (a scalar: Eq. 24 needs K_n H positive definite) [1/s].
    K_n: float = 40.0
    # Generalised inverse: dynamically_consistent (Eq. 13), moore_penrose, damped_least_squares [-].
    pseudo_inverse: str = "dynamically_consistent"
    # Damping λ of the damped least-squares inverse [m]; 0 for the others.
    damping: float = 0.0
    # Task-velocity compensation (J̄̇ J + J̄ J̇) q̇ of Eq. 21 [-].
    task_velocity_compensation: bool = True
    # Coriolis compensation H⁻¹ C eⁿ of Eq. 21 [-].
    coriolis_compensation: bool = True
    # Feed forward q̈_dⁿ, the backward difference of q̇_dⁿ over one control period [-].
    acceleration_feedforward: bool = True


@dataclass
class ObstacleCriterionConfig:
    """Obstacle avoidance, Eq. 31 (nsdrake/criteria/obstacle.py): p = −⅓ Σ max(0, d_∞ − d)³."""

    # Step gain K of Eq. 30; >= 0, a positive gain pushes the links away [rad/s per m³/(kg m²)].
    gain: float = 0.0
    # Influence distance d_∞: links farther than this from every obstacle feel nothing [m].
    influence_distance: float = 0.1


@dataclass
class JointTorqueCriterionConfig:
    """Joint torque due to the desired end-effector force, Eqs. 32–33: p = ‖Jᵀ F_d‖²."""

    # Step gain K of Eq. 30; <= 0, a negative gain minimises p [rad/s per N² m²/(kg m²)].
    gain: float = 0.0


@dataclass
class ManipulabilityCriterionConfig:
    """Manipulability (Yoshikawa): w = √det(J Jᵀ)."""

    # Step gain K of Eq. 30; >= 0, a positive gain maximises w [rad/s per m²/(kg m²)].
    gain: float = 0.0


@dataclass
class CriteriaConfig:
    """The criteria of Section 3.5. A zero gain keeps a criterion in the hierarchy with no effect."""

    obstacle: ObstacleCriterionConfig = field(default_factory=ObstacleCriterionConfig)
    joint_torque: JointTorqueCriterionConfig = field(default_factory=JointTorqueCriterionConfig)
    manipulability: ManipulabilityCriterionConfig = field(default_factory=ManipulabilityCriterionConfig)


@dataclass
class SelectorConfig:
    """Fig. 1's decision tree (nsdrake/priority.py)."""

    # A link closer than this to an obstacle puts obstacle avoidance on level 2 [m].
    d_lim: float = 0.05
    # Hysteresis: obstacle avoidance leaves level 2 only beyond d_lim + d_band [m].
    d_band: float = 0.01
    # Manipulability below this puts its maximisation on level 2 (above: joint torque) [m²].
    w_lim: float = 0.01
    # Hysteresis: manipulability leaves level 2 only above w_lim + w_band [m²].
    w_band: float = 0.005
    # After a switch, q̇_dⁿ blends from the old ordering to the new over this time [s].
    blend_time: float = 0.2


@dataclass
class SweepConfig:
    """A prescribed self-motion: q̇_dⁿ = a(t) N d / ‖N d‖, d a fixed joint-space direction."""

    # Direction d, keyed by joint name (missing joints 0) [-].
    direction: dict[str, float] = field(default_factory=dict)
    # Amplitude of the commanded null-space speed ‖q̇_dⁿ‖ [rad/s].
    amplitude: float = 0.5
    # Frequency of a(t) = amplitude sin(2π f (t − start)); 0 holds a constant speed [Hz].
    frequency: float = 1.0
    # Time the sweep starts [s].
    start_time: float = 0.0
    # a(t) rises from 0 with a smoothstep over this time [s].
    ramp_time: float = 0.2


NULL_SPACE_SOURCES = ("criteria", "sweep")


@dataclass
class DesiredNullSpaceConfig:
    """The desired null-space velocity q̇_dⁿ by gradient projection (Eqs. 28–30), prioritised."""

    # Where q̇_dⁿ comes from: criteria (Fig. 1's priority selector) or sweep (a prescribed
    # self-motion, for the experiments of nsdrake compare) [-].
    source: str = "criteria"
    sweep: SweepConfig = field(default_factory=SweepConfig)
    # Rotate each gradient by H⁻¹ before projecting (Eq. 30); false gives Eq. 28's form [-].
    rotate_gradient: bool = True
    criteria: CriteriaConfig = field(default_factory=CriteriaConfig)
    selector: SelectorConfig = field(default_factory=SelectorConfig)
    # Largest joint speed, keyed by joint name: q̇_dⁿ is scaled, keeping its direction, so
    # that no joint's commanded speed (task part plus q̇_dⁿ) exceeds it. Missing joints are
    # unlimited [rad/s].
    joint_speed_limits: dict[str, float] = field(default_factory=dict)
    # Fraction of each speed limit kept free for the null-space tracking error: commands
    # stay within (1 − headroom) × limit, so the measured speeds stay within the limit [-].
    speed_headroom: float = 0.05


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
    arm: ArmConfig = field(default_factory=ArmConfig)
    plate: PlateConfig = field(default_factory=PlateConfig)
    contact: ContactConfig = field(default_factory=ContactConfig)
    task: TaskConfig = field(default_factory=TaskConfig)
    reference: ReferenceConfig = field(default_factory=ReferenceConfig)
    impedance: ImpedanceConfig = field(default_factory=ImpedanceConfig)
    null_space: NullSpaceConfig = field(default_factory=NullSpaceConfig)
    desired_null_space: DesiredNullSpaceConfig = field(default_factory=DesiredNullSpaceConfig)
    # Obstacles besides the plate.
    obstacles: list[ObstacleConfig] = field(default_factory=list)
    report: ReportConfig = field(default_factory=ReportConfig)
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


SHOW_LENGTH = 80  # [characters] longest echo of a user's value in an error message


def _show(value) -> str:
    """``repr(value)`` on one line, cut to SHOW_LENGTH characters with "…"."""
    text = _one_line(repr(value))
    return text if len(text) <= SHOW_LENGTH else text[: SHOW_LENGTH - 1] + "…"


def _cut(text, length: int = 4 * SHOW_LENGTH) -> str:
    """A message from elsewhere (Drake, the OS) on one line, cut to ``length`` characters."""
    text = _one_line(text)
    return text if len(text) <= length else text[: length - 1] + "…"


def _name(key) -> str:
    """A mapping key (a field or joint name) for a path in an error message, cut like _show."""
    text = _one_line(key)
    return text if len(text) <= SHOW_LENGTH else text[: SHOW_LENGTH - 1] + "…"


# Limits of the YAML reader. A scenario or family file holds a few hundred values at
# most, nested 8 deep; these refuse anything far beyond, before it costs time or memory.
MAX_DEPTH = 32  # nesting of lists and mappings, aliases expanded
MAX_VALUES = 10_000  # values (scalars, lists, mappings) in one file, each alias counted expanded
MAX_BYTES = 1_000_000  # size of one file

_MERGE_TAG = "tag:yaml.org,2002:merge"


class _Refused(yaml.YAMLError):
    """Something the strict reader refuses (not a syntax error): one problem at one line."""

    def __init__(self, mark, problem: str):
        super().__init__(problem)
        self.line = mark.line + 1
        self.problem = problem

    def __str__(self) -> str:
        return f"line {self.line}: {self.problem}"


class _StrictLoader(yaml.SafeLoader):
    """A safe YAML loader for scenario and family files that refuses, with the line:

    - duplicate keys (PyYAML keeps the last one);
    - keys that are not names (a list, a mapping, a number, true/false, null);
    - merge keys (``<<: *base``);
    - nesting deeper than MAX_DEPTH, and more than MAX_VALUES values with every alias
      expanded (a "billion laughs" file is a few lines that expand to 10⁹ values);
    - an alias inside the node it names (a recursive structure).

    It reads YAML 1.2 floats such as ``1e3`` and ``-2E-3`` as numbers (YAML 1.1, and so
    PyYAML, needs a dot and a signed exponent: ``1.0e+3``).
    """

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0
        self._extent: dict[int, tuple[int, int]] = {}  # id(node) -> (values, height), expanded

    def compose_node(self, parent, index):
        event = self.peek_event()
        if self._depth >= MAX_DEPTH:
            raise _Refused(event.start_mark, f"nested deeper than {MAX_DEPTH} levels")
        self._depth += 1
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        if isinstance(event, yaml.AliasEvent):
            if id(node) not in self._extent:
                raise _Refused(event.start_mark, f"alias *{event.anchor} is inside the value it names")
            return node
        if isinstance(node, yaml.ScalarNode):
            children = []
        elif isinstance(node, yaml.SequenceNode):
            children = node.value
        else:
            children = [n for pair in node.value for n in pair]
        values, height = 1, 1
        for child in children:
            v, h = self._extent[id(child)]
            values, height = values + v, max(height, h + 1)
        if height > MAX_DEPTH:
            raise _Refused(event.start_mark, f"nested deeper than {MAX_DEPTH} levels with aliases expanded")
        if values > MAX_VALUES:
            raise _Refused(
                event.start_mark,
                f"more than {MAX_VALUES} values once aliases are expanded; nsdrake refuses files this large",
            )
        self._extent[id(node)] = (values, height)
        return node


def _strict_mapping(loader, node):
    seen = set()
    for key_node, _ in node.value:
        mark = key_node.start_mark
        if key_node.tag == _MERGE_TAG:
            raise _Refused(mark, "merge keys (<<) are not supported; write the fields out")
        if not isinstance(key_node, yaml.ScalarNode):
            kind = "a list" if isinstance(key_node, yaml.SequenceNode) else "a mapping"
            raise _Refused(mark, f"a key must be a name, got {kind}")
        key = loader.construct_object(key_node)
        if not isinstance(key, str):
            raise _Refused(mark, f"a key must be a name, got {_show(key)}; quote it if it is one")
        if key in seen:
            raise _Refused(mark, f"duplicate key '{_name(key)}'")
        seen.add(key)
    return loader.construct_mapping(node)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _strict_mapping)
# YAML 1.2 floats that YAML 1.1 reads as strings: an exponent without a dot or without a sign.
_StrictLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


def normalised_yaml(data) -> str:
    """``data`` (as read by read_yaml) as plain YAML for Drake's ``yaml_load_typed``:
    aliases expanded, floats in a form every YAML reader takes."""

    class _Plain(yaml.SafeDumper):
        def ignore_aliases(self, data):
            return True

    return yaml.dump(data, Dumper=_Plain, sort_keys=False, allow_unicode=True, width=float("inf"))


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
            return f"{where or 'the file'}: must be {_kind(schema)}, got {_show(data)}"
        hints = typing.get_type_hints(schema)
        fields = {f.name: f for f in dataclasses.fields(schema) if f.metadata.get("yaml", True)}
        for key, value in data.items():
            path = f"{where}.{_name(key)}" if where else _name(key)
            if key not in fields:
                return f"{path}: unknown field; valid fields here are {', '.join(fields)}"
            problem = check_shape(value, hints[key], path)
            if problem:
                return problem
        return None
    origin, args = typing.get_origin(schema), typing.get_args(schema)
    if origin is dict:
        if not isinstance(data, dict):
            return f"{where}: must be {_kind(schema)}, got {_show(data)}"
        for key, value in data.items():
            problem = check_shape(value, args[1], f"{where}.{_name(key)}")
            if problem:
                return problem
        return None
    if origin is list:
        if not isinstance(data, list):
            return f"{where}: must be {_kind(schema)}, got {_show(data)}"
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
        return f"{where}: must be {_kind(schema)}, got {_show(data)}"
    return None


def read_yaml(path: Path, kind: str = "scenario") -> tuple[str, object]:
    """(the data as plain YAML text, the parsed data) of a YAML file read by _StrictLoader.

    Every problem (missing, unreadable, too large, malformed, refused, empty) is a
    one-line ScenarioError naming the file (and the line, where there is one). Pass the
    returned text, not the file's, to ``yaml_load_typed``: it has the aliases expanded
    and the floats the strict reader took (``1e3``) written so that Drake takes them too.
    """
    if not path.is_file():
        raise ScenarioError(f"{path}: no such {kind} file")
    try:
        size = path.stat().st_size
        if size > MAX_BYTES:
            raise ScenarioError(f"{path}: {size} bytes; nsdrake refuses {kind} files over {MAX_BYTES} bytes")
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        raise ScenarioError(f"{path}: cannot read: {_cut(e)}") from None
    try:
        data = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 (a SafeLoader subclass)
    except _Refused as e:
        raise ScenarioError(f"{path}: {e}") from None
    except yaml.YAMLError as e:
        raise ScenarioError(f"{path}: malformed YAML: {_cut(e)}") from None
    if data is None:
        raise ScenarioError(f"{path}: the file is empty")
    return normalised_yaml(data), data


def _read(path: Path, defaults: Scenario | None) -> Scenario:
    text, data = read_yaml(path)
    problem = check_shape(data, Scenario, "")
    if problem:
        raise ScenarioError(f"{path}: {problem}")
    try:
        return yaml_load_typed(schema=Scenario, data=text, defaults=defaults or Scenario())
    except Exception as e:  # anything the shape check missed
        raise ScenarioError(f"{path}: {_cut(e)}") from None


def load_scenario(name: str, config: str | Path | None = None, duration: float | None = None) -> Scenario:
    """The shipped scenario ``name``, with the YAML file ``config`` overlaid, validated.

    ``duration`` (command line) overrides the files. Raises ScenarioError.
    """
    known = shipped_scenarios()
    if name not in known:
        raise ScenarioError(f"unknown scenario '{_name(name)}'; the shipped scenarios are {', '.join(known)}")
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
        _fail(source, where, f"must be a finite number, got {_show(value)}")


def check_positive(source: str, where: str, value) -> None:
    check_finite(source, where, value)
    if value <= 0:
        _fail(source, where, f"must be > 0, got {_show(value)}")


def check_non_negative(source: str, where: str, value) -> None:
    check_finite(source, where, value)
    if value < 0:
        _fail(source, where, f"must be >= 0, got {_show(value)}")


def check_choice(source: str, where: str, value, choices) -> None:
    if value not in choices:
        _fail(source, where, f"must be one of {', '.join(choices)}, got {_show(value)}")


def validate(s: Scenario) -> None:
    """Checks every field that does not need the plant; raises ScenarioError."""
    src = s.source or "scenario"
    check_positive(src, "duration", s.duration)
    check_positive(src, "control_period", s.control_period)
    if s.control_period > s.duration:
        _fail(src, "control_period", f"{s.control_period} s is longer than the duration {s.duration} s")
    check_choice(src, "plane", s.plane, PLANES)
    for name, value in s.arm.initial_positions.items():
        check_finite(src, f"arm.initial_positions.{_name(name)}", value)
    for name, value in s.arm.initial_velocities.items():
        check_finite(src, f"arm.initial_velocities.{_name(name)}", value)
    if not s.arm.initial_positions:
        _fail(src, "arm.initial_positions", "must give a position for every joint")
    if len(s.plate.position) != 3:
        _fail(src, "plate.position", f"must be [x, y, z], got {_show(s.plate.position)}")
    for i, value in enumerate(s.plate.position):
        check_finite(src, f"plate.position[{i}]", value)
    check_finite(src, "plate.yaw", s.plate.yaw)
    for i, check in enumerate(s.report.checks):
        check_choice(src, f"report.checks[{i}]", check, REPORT_CHECKS)
    for i, m in enumerate(s.report.required_modes):
        if m not in (0, 1, 2, 3):
            _fail(src, f"report.required_modes[{i}]", f"must be a mode 0-3, got {_show(m)}")
    check_choice(src, "contact.approximation", s.contact.approximation, CONTACT_APPROXIMATIONS)
    check_choice(src, "contact.model", s.contact.model, CONTACT_MODELS)
    axes = s.task.axes
    for i, a in enumerate(axes):
        check_choice(src, f"task.axes[{i}]", a, ("x", "y", "z"))
    if not axes or len(set(axes)) != len(axes):
        _fail(src, "task.axes", f"must be distinct axes, got {_show(axes)}")
    r = s.reference
    for name in ("tangent_speed", "approach_speed"):
        check_finite(src, f"reference.{name}", getattr(r, name))
    check_non_negative(src, "reference.approach_speed", r.approach_speed)
    for name in ("blend_time", "force_ramp_time"):
        check_non_negative(src, f"reference.{name}", getattr(r, name))
    check_positive(src, "reference.force", r.force)
    check_positive(src, "reference.contact_threshold", r.contact_threshold)
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
        check_finite(src, f"desired_null_space.sweep.direction.{_name(name)}", value)
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
        check_positive(src, f"desired_null_space.joint_speed_limits.{_name(name)}", value)
    check_non_negative(src, "desired_null_space.speed_headroom", d.speed_headroom)
    if d.speed_headroom >= 1.0:
        _fail(src, "desired_null_space.speed_headroom", f"must be below 1, got {d.speed_headroom}")
    names = set()
    for i, ob in enumerate(s.obstacles):
        where = f"obstacles[{i}]"
        if not ob.name:
            _fail(src, f"{where}.name", "every obstacle needs a name")
        if ob.name in names:
            _fail(src, f"{where}.name", f"duplicate obstacle name '{_name(ob.name)}'")
        names.add(ob.name)
        if not ob.shape:
            _fail(
                src,
                where,
                f"obstacle '{_name(ob.name)}' has no geometry: "
                f"give shape ({', '.join(OBSTACLE_SHAPES)}) and size",
            )
        check_choice(src, f"{where}.shape", ob.shape, tuple(OBSTACLE_SHAPES))
        if len(ob.size) != OBSTACLE_SHAPES[ob.shape]:
            _fail(
                src,
                f"{where}.size",
                f"a {ob.shape} needs {OBSTACLE_SHAPES[ob.shape]} size entries, got {_show(ob.size)}",
            )
        for k, value in enumerate(ob.size):
            check_positive(src, f"{where}.size[{k}]", value)
        if len(ob.position) != 3:
            _fail(src, f"{where}.position", f"must be [x, y, z], got {_show(ob.position)}")
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
    }
    for where, table in tables.items():
        for name in table:
            if name not in joint_names:
                _fail(src, f"{where}.{_name(name)}", f"unknown joint; the arm's joints are {valid}")
    missing = [j for j in joint_names if j not in s.arm.initial_positions]
    if missing:
        _fail(src, "arm.initial_positions", f"no position for joint(s) {', '.join(missing)}")

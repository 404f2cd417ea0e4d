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

from nsdrake.control.config import (
    NULL_SPACE_SOURCES,
    ActuatorLimitsConfig,
    DesiredNullSpaceConfig,
    ImpedanceConfig,
    NullSpaceConfig,
)
from nsdrake.control.dynamics import AXIS_NAMES, ROTATION_AXIS_NAMES, parse_task_axes
from nsdrake.control.pseudo_inverse import GeneralizedInverse, PseudoInverseKind
from nsdrake.experiment.driver_config import DriverConfig, driver_problems
from nsdrake.realism.config import RealismConfig, realism_problems
from nsdrake.station.config import (
    CONTACT_APPROXIMATIONS,
    CONTACT_MODELS,
    OBSTACLE_SHAPES,
    ArmConfig,
    ContactConfig,
    ObstacleConfig,
    PlateConfig,
)

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"

PLANES = ("horizontal", "vertical")


class ScenarioError(ValueError):
    """A scenario that cannot be run; the message is one line naming file and field."""


@dataclass
class TaskConfig:
    # World axes of the primary task: x, y, z for the tool point's coordinates x (Eq. 1), then
    # rx, ry, rz for its orientation (a pose task; [x, y, z, rx, ry, rz] is the full pose) [-].
    axes: list[str] = field(default_factory=lambda: ["x", "y"])


REFERENCE_PATHS = ("slide", "circle")
ORIENTATIONS = ("start", "perpendicular")


@dataclass
class ReferenceConfig:
    """The task: approach the plate until contact, then press; along the plate, the Fig. 3
    ramp (path: slide) or, after the press, a circle on the surface (path: circle)."""

    # slide: a constant-velocity ramp along the plate from the start (Fig. 3); circle: once in
    # contact, a circle on the surface, laps times round (needs the task axes x, y, z) [-].
    path: str = "slide"
    # Speed along the plate: of the ramp (slide) or along the circle, negative for clockwise
    # (circle) [m/s].
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
    # Circle: its radius [m].
    radius: float = 0.1
    # Circle: how many times round [-].
    laps: float = 2.0
    # Circle: where on it the tool starts, the angle from the plate's x axis toward its z
    # axis (-pi/2: the circle lies toward the plate's +z from the contact point) [rad].
    start_angle: float = -1.5707963267948966
    # Circle: time from first contact to the start of the motion along it [s].
    delay: float = 0.3
    # Pose tasks: the desired tool orientation, held throughout. start: the tool's at the
    # initial pose; perpendicular: that one turned by the smallest rotation that points the
    # tool frame's z axis along the plate's push direction [-].
    orientation: str = "start"
    # Contact counts as lost once the normal force has stayed below contact_threshold this long [s].
    loss_time: float = 0.05
    # After a loss, the normal reference approaches at most this far beyond the lost surface [m].
    max_overtravel: float = 0.02
    # The slide stops where the reference would come closer than this share of the arm's
    # reach to the edge of its workspace [-].
    reach_margin: float = 0.05


REPORT_CHECKS = ("fig3", "priority", "pose", "self_motion")


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
    # null space follows its command), priority (modes, criteria, torque steps), pose
    # (force, position and orientation tracking of a pose task, distances to the obstacles,
    # joint position, speed and torque margins) and/or self_motion (the elbow's swivel
    # while the tool holds its pose and force) [-].
    checks: list[str] = field(default_factory=lambda: ["fig3"])
    # Frames of the shoulder, elbow and wrist (e.g. panda_link2, panda_link4, panda_link7):
    # the traces get the elbow's swivel angle about the shoulder-wrist line, a coordinate
    # of the self-motion while the tool holds its pose; empty: none [-].
    swivel_frames: list[str] = field(default_factory=list)
    # Replay camera position and target in the world; empty: nsdrake's default view [m].
    camera_position: list[float] = field(default_factory=list)
    camera_target: list[float] = field(default_factory=list)
    # With the priority check: the modes the run must visit (1 obstacle avoidance,
    # 2 joint torque, 3 manipulability, 4 joint limits) [-].
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
    # How nsdrake drive meets a Franka Panda's LCM driver (nsdrake/experiment/driver_config.py).
    driver: DriverConfig = field(default_factory=DriverConfig)
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
    for name in ("yaw", "roll", "pitch"):
        check_finite(src, f"plate.{name}", getattr(s.plate, name))
    if s.gravity and len(s.gravity) != 3:
        _fail(src, "gravity", f"must be [gx, gy, gz] or empty, got {s.gravity!r}")
    for i, value in enumerate(s.gravity):
        check_finite(src, f"gravity[{i}]", value)
    for i, check in enumerate(s.report.checks):
        check_choice(src, f"report.checks[{i}]", check, REPORT_CHECKS)
    for i, m in enumerate(s.report.required_modes):
        if m not in (0, 1, 2, 3, 4):
            _fail(src, f"report.required_modes[{i}]", f"must be a mode 0-4, got {_show(m)}")
    check_choice(src, "contact.approximation", s.contact.approximation, CONTACT_APPROXIMATIONS)
    check_choice(src, "contact.model", s.contact.model, CONTACT_MODELS)
    axes = s.task.axes
    for i, a in enumerate(axes):
        check_choice(src, f"task.axes[{i}]", a, AXIS_NAMES + ROTATION_AXIS_NAMES)
    if not axes or len(set(axes)) != len(axes):
        _fail(src, "task.axes", f"must be distinct axes, got {_show(axes)}")
    try:
        rows, _ = parse_task_axes(axes)
    except ValueError as e:
        _fail(src, "task.axes", _one_line(e))
    if s.report.swivel_frames and len(s.report.swivel_frames) != 3:
        _fail(
            src,
            "report.swivel_frames",
            f"must name three frames or none, got {_show(s.report.swivel_frames)}",
        )
    for name in ("camera_position", "camera_target"):
        value = getattr(s.report, name)
        if value and (len(value) != 3 or not all(math.isfinite(v) for v in value)):
            _fail(src, f"report.{name}", f"must be [x, y, z] or empty, got {_show(value)}")
    r = s.reference
    check_choice(src, "reference.path", r.path, REFERENCE_PATHS)
    check_choice(src, "reference.orientation", r.orientation, ORIENTATIONS)
    if r.path == "circle":
        if len(rows) != 3:
            _fail(src, "reference.path", f"a circle on the surface needs the task axes x, y, z, got {axes!r}")
        check_positive(src, "reference.radius", r.radius)
        check_positive(src, "reference.laps", r.laps)
        check_finite(src, "reference.start_angle", r.start_angle)
        check_non_negative(src, "reference.delay", r.delay)
        if r.tangent_speed == 0:
            _fail(src, "reference.tangent_speed", "a circle needs a non-zero speed")
        length = 2 * math.pi * r.radius * r.laps
        if length < abs(r.tangent_speed) * r.blend_time:
            _fail(
                src,
                "reference.laps",
                f"the circle ({length:.4g} m) is shorter than the speed blends need "
                f"(|tangent_speed| x blend_time = {abs(r.tangent_speed) * r.blend_time:.4g} m)",
            )
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
    for name in ("K_p_tangent", "K_v_tangent", "K_v_normal", "K_f", "K_p_rotation", "K_v_rotation"):
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
    check_non_negative(src, f"{crit}.joint_limits.gain", d.criteria.joint_limits.gain)
    check_positive(src, f"{crit}.joint_limits.influence", d.criteria.joint_limits.influence)
    sel = d.selector
    for name in ("d_lim", "w_lim", "d_band", "w_band", "q_lim", "q_band", "blend_time"):
        check_non_negative(src, f"desired_null_space.selector.{name}", getattr(sel, name))
    if sel.q_lim > 0 and d.criteria.joint_limits.influence < sel.q_lim + sel.q_band:
        _fail(
            src,
            f"{crit}.joint_limits.influence",
            f"{d.criteria.joint_limits.influence} rad must be >= selector.q_lim + q_band = "
            f"{sel.q_lim + sel.q_band} rad, or joint-limit avoidance would have no gradient "
            "when it takes level 2",
        )
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
    for kind in ("torque", "torque_rate"):
        for name, value in getattr(s.actuator_limits, kind).items():
            check_positive(src, f"actuator_limits.{kind}.{name}", value)
    check_positive(src, "divergence.max_joint_speed", s.divergence.max_joint_speed)
    check_positive(src, "divergence.max_torque", s.divergence.max_torque)
    for where, problem in realism_problems(s.realism, s.control_period):
        _fail(src, f"realism.{where}", problem)
    for where, problem in driver_problems(s.driver):
        _fail(src, f"driver.{where}", problem)
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
        "actuator_limits.torque": s.actuator_limits.torque,
        "actuator_limits.torque_rate": s.actuator_limits.torque_rate,
    }
    for where, table in tables.items():
        for name in table:
            if name not in joint_names:
                _fail(src, f"{where}.{_name(name)}", f"unknown joint; the arm's joints are {valid}")
    missing = [j for j in joint_names if j not in s.arm.initial_positions]
    if missing:
        _fail(src, "arm.initial_positions", f"no position for joint(s) {', '.join(missing)}")

"""Scenarios: typed dataclasses loaded from YAML with Drake's ``yaml_load_typed``.

(No ``from __future__ import annotations`` here: ``yaml_load_typed`` reads the
dataclass field types at run time.)

A scenario file sets any subset of the fields below; the rest keep their
defaults. Every field names its unit. :func:`load_scenario` reads a shipped
scenario by name, optionally overlays a user's YAML file on it, and validates
the result; every problem is a :class:`ScenarioError` whose one-line message
names the file and the field.
"""

import copy
import dataclasses
import math
import os
import re
import typing
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import yaml
from pydrake.common.yaml import yaml_load_typed

from nsdrake.control.config import (
    ActuatorLimitsConfig,
    DesiredNullSpaceConfig,
    ImpedanceConfig,
    NullSpaceConfig,
)
from nsdrake.control.dynamics import AXIS_NAMES
from nsdrake.control.pseudo_inverse import GeneralizedInverse, PseudoInverseKind
from nsdrake.control.validation import (
    choice_problem,
    config_problems,
    finite_problem,
    fraction_problem,
    gravity_problem,
    length_problem,
    non_negative_problem,
    positive_problem,
    task_axes_problem,
)
from nsdrake.experiment.driver_config import REMOVED_FIELDS, DriverConfig, driver_problems
from nsdrake.experiment.push import PushConfig, push_problems
from nsdrake.experiment.reference import touch_problems
from nsdrake.realism.config import SHORTEST_STEP, RealismConfig, realism_problems, substeps
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
    # A guarded approach: the speed it slows to before the surface (over blend_time, as it
    # rose), and touches it at; 0: no slow-down, it touches at approach_speed [m/s].
    touch_speed: float = 0.0
    # Guarded approach: how far the approach has travelled when it has slowed to touch_speed;
    # set it to the surface's distance less its uncertainty [m].
    slow_down_distance: float = 0.0
    # At contact the normal reference comes to rest over this time from the speed it had
    # (1 - smoothstep), touch_speed x stop_time / 2 beyond where contact was detected; 0: it
    # stops there at once (the paper's Fig. 3 task) [s].
    stop_time: float = 0.0
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
CONTROLLER_STRUCTURES = ("auto", "systems", "fused")


@dataclass
class DivergenceConfig:
    """When a run counts as diverged and is stopped (nsdrake/experiment/simulate.py)."""

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
    # Log the null-space torque s τ₀ the controller applies (after the actuator limits) as
    # trace columns tau0_1 … tau0_n [-].
    null_space_torque: bool = False
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
    # An external force pulse on a link (nsdrake/experiment/push.py); off by default.
    push: PushConfig = field(default_factory=PushConfig)
    # Effects of the real robot, each off by default (nsdrake/realism/: the realism ladder).
    realism: RealismConfig = field(default_factory=RealismConfig)
    # How the controller's stages run (NullSpaceImpedanceController's ``fused``): systems,
    # the paper's named systems (diagram.svg shows them); fused, the same stages in one
    # LeafSystem, the same traces for about a third of the controller's cost; auto, systems
    # for nsdrake run and fused for nsdrake compare and sweep [-].
    controller_structure: str = "auto"
    # How nsdrake drive meets a Franka Panda's LCM driver (nsdrake/experiment/driver_config.py).
    driver: DriverConfig = field(default_factory=DriverConfig)
    # Where the scenario was read from (set by the loader; not a YAML field).
    source: str = field(default="", metadata={"yaml": False})
    # Folder that relative model paths are resolved against (set by the loader; not a YAML field).
    base_dir: str = field(default="", metadata={"yaml": False})
    # What the loader did that the user should hear of, one line each: the tables of another
    # arm's joints an overlay dropped (set by the loader; not a YAML field).
    notes: list[str] = field(default_factory=list, metadata={"yaml": False})

    def generalized_inverse(self) -> GeneralizedInverse:
        return GeneralizedInverse(PseudoInverseKind(self.null_space.pseudo_inverse), self.null_space.damping)


def shipped_scenarios() -> list[str]:
    """Names of the scenarios that ship with nsdrake."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


# The fields keyed by joint name, written as a mapping so that a reader sees which joint
# each number is for. On the same arm an overlay that gives one changes the joints it
# names and keeps the others (a torque limit, a start position, a posture weight: one value
# per joint, as the README's "only the fields you give change"; replacing would silently
# drop the other joints' limits), except VECTOR_TABLES, which an overlay replaces whole as
# it replaces a list (a direction: {joint1: 1} on a base's {joint2: 1, joint3: -1} merged
# is a direction nobody wrote, not e1). On another arm the base's tables are dropped.
JOINT_TABLES = (
    "arm.locked",  # keyed by the joints that are not the arm's (arm.joints)
    "arm.initial_positions",
    "arm.initial_velocities",
    "desired_null_space.joint_speed_limits",
    "desired_null_space.sweep.direction",
    "desired_null_space.posture.q_d",
    "desired_null_space.posture.weight",
    "desired_null_space.posture.offset",
    "actuator_limits.torque",
    "actuator_limits.torque_rate",
)
VECTOR_TABLES = ("desired_null_space.sweep.direction",)

# The fields that choose the arm. An overlay that changes one and gives arm.initial_positions
# for another set of joints (every joint must have one) chooses another arm: the base's
# joint tables it does not give name the other arm's joints and are dropped, each said
# (Scenario.notes). Another file of the same joints (a model edited) keeps them.
ARM_FIELDS = ("arm.urdf", "arm.joints")


def value_at(tree, path: str):
    """The value at the dotted ``path`` of ``tree`` (nested mappings or dataclasses), or
    _ABSENT."""
    node = tree
    for part in path.split("."):
        if isinstance(node, dict):
            if part not in node:
                return _ABSENT
            node = node[part]
        elif dataclasses.is_dataclass(node):
            node = getattr(node, part)
        else:
            return _ABSENT
    return node


_ABSENT = object()


def _set(scenario: "Scenario", path: str, value) -> None:
    *parents, leaf = path.split(".")
    node = scenario
    for part in parents:
        node = getattr(node, part)
    setattr(node, leaf, value)


def overlay(base: "Scenario", data, origin: str) -> "Scenario":
    """``base`` with the fields of ``data`` (parsed YAML: a file, a compare variant's
    overrides, a sweep run's values) set. A section the data gives merges field by field;
    a list and a vector keyed by joint name (VECTOR_TABLES) the data gives replace the
    base's whole; another table keyed by joint name (JOINT_TABLES) changes the joints
    given. Data that chooses another arm (ARM_FIELDS) with positions for other joints
    drops the base's joint tables it does not give, each named in the
    result's ``notes`` (from ``origin``, the overlay's name). ``base`` is not changed.
    Raises what ``yaml_load_typed`` raises (the caller names the file)."""
    base = copy.deepcopy(base)
    changed = [
        p for p in ARM_FIELDS if value_at(data, p) is not _ABSENT and value_at(data, p) != value_at(base, p)
    ]
    joints = value_at(data, "arm.initial_positions")
    other_arm = bool(changed) and isinstance(joints, dict) and set(joints) != set(base.arm.initial_positions)
    dropped = []
    for path in JOINT_TABLES:
        given = value_at(data, path) is not _ABSENT
        if (given and path in VECTOR_TABLES) or other_arm:
            if not given and value_at(base, path):
                dropped.append(path)
            _set(base, path, {})
    scenario = yaml_load_typed(schema=Scenario, data=normalised_yaml(data), defaults=base)
    if dropped:
        was = ", ".join(f"{p} {_show(value_at(base, p))} -> {_show(value_at(data, p))}" for p in changed)
        was += f", positions for its {len(joints)} joints"
        scenario.notes = scenario.notes + [
            f"{origin} chooses another arm ({was}): the base's tables keyed by the other arm's joints "
            f"are dropped: {', '.join(dropped)}"
        ]
    return scenario


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
            if key not in fields and schema is DriverConfig and key in REMOVED_FIELDS:
                return f"{path}: {REMOVED_FIELDS[key]}"
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


def _read(path: Path, base: Scenario | None) -> Scenario:
    """The scenario file ``path``: on its own (defaults for what it leaves out), or
    overlaid on ``base`` (:func:`overlay`)."""
    text, data = read_yaml(path)
    problem = check_shape(data, Scenario, "")
    if problem:
        raise ScenarioError(f"{path}: {problem}")
    try:
        if base is None:
            return yaml_load_typed(schema=Scenario, data=text, defaults=Scenario())
        return overlay(base, data, str(path))
    except Exception as e:  # anything the shape check missed
        raise ScenarioError(f"{path}: {_cut(e)}") from None


def find_scenario(name_or_path: str | Path) -> Path:
    """The file of the scenario ``name_or_path``: the name of a shipped scenario (nsdrake
    list), else the path of a scenario file. A shipped scenario's bare name means the
    shipped one even beside a file of that name (``./fig3`` names the file). Raises
    ScenarioError saying what was tried."""
    text = str(name_or_path)
    known = shipped_scenarios()
    if text in known:
        return SCENARIO_DIR / f"{text}.yaml"
    path = Path(text).expanduser()
    shipped = f"the shipped scenarios are {', '.join(known)}"
    if path.is_file():
        return path
    if path.is_dir():
        raise ScenarioError(
            f"{_name(text)}: a folder, not a scenario file (nor a shipped scenario: {shipped})"
        )
    if os.sep in text or "/" in text or path.suffix in (".yaml", ".yml"):
        raise ScenarioError(f"{_name(text)}: no such scenario file (nor a shipped one: {shipped})")
    raise ScenarioError(
        f"unknown scenario '{_name(text)}'; {shipped}; and there is no file '{_name(text)}' "
        "(a scenario file of yours is given by its path, e.g. my_arm.yaml)"
    )


def scenario_label(name_or_path: str | Path) -> str:
    """A scenario's short name for folders and progress lines: a shipped one's name, a
    file's stem."""
    text = str(name_or_path)
    return text if text in shipped_scenarios() else Path(text).stem


def load_scenario(
    name: str | Path,
    config: str | Path | None = None,
    duration: float | None = None,
    *,
    validated: bool = True,
) -> Scenario:
    """The scenario ``name`` (a shipped scenario's name or a scenario file's path:
    :func:`find_scenario`), with the YAML file ``config`` overlaid (:func:`overlay`),
    validated (unless ``validated`` is False: a base that more overrides follow, validated
    after them, as a compare variant's).

    ``duration`` (command line) overrides the files. Raises ScenarioError.
    """
    path = find_scenario(name)
    scenario = _read(path, None)
    scenario.source, scenario.base_dir = str(path), str(path.resolve().parent)
    if str(name) in shipped_scenarios() and Path(str(name)).is_file():
        scenario.notes.append(
            f"'{name}' is the shipped scenario; the file '{name}' in this folder is run as ./{name}"
        )
    if config is not None:
        config = Path(config)
        scenario = _read(config, anchored(scenario))
        head = path.name if path.parent == SCENARIO_DIR else str(path)
        scenario.source, scenario.base_dir = f"{head} + {config}", str(config.resolve().parent)
    if duration is not None:
        scenario = dataclasses.replace(scenario, duration=duration)
        check_positive(scenario.source, "--duration", duration)
    if validated:
        try:
            validate(scenario)
        except ScenarioError as e:  # a table the overlay dropped may be why: say so on the same line
            if not scenario.notes:
                raise
            raise ScenarioError(f"{e} (note: {'; '.join(scenario.notes)})") from None
    return scenario


def anchored(scenario: Scenario) -> Scenario:
    """``scenario`` with its model paths that are relative to its own folder (base_dir)
    made absolute, so that an overlay read from another folder, which becomes the base
    folder, leaves them pointing at the same files (shipped model names stay names)."""
    if not scenario.base_dir:
        return scenario
    folder = Path(scenario.base_dir)
    s = copy.deepcopy(scenario)
    for model in (s.arm, s.plate):
        if not Path(model.urdf).expanduser().is_absolute() and (folder / model.urdf).is_file():
            model.urdf = str((folder / model.urdf).resolve())
    s.arm.packages = {
        name: str((folder / Path(where).expanduser()).resolve()) for name, where in s.arm.packages.items()
    }
    return s


def load_scenario_file(path: str | Path) -> Scenario:
    """A scenario from a standalone YAML file (defaults for everything it leaves out), validated."""
    path = Path(path)
    scenario = _read(path, None)
    scenario.source, scenario.base_dir = str(path), str(path.resolve().parent)
    validate(scenario)
    return scenario


def _fail(source: str, where: str, problem: str):
    raise ScenarioError(f"{source}: {where}: {problem}")


def _fail_if(source: str, where: str, problem: str | None) -> None:
    if problem:
        _fail(source, where, problem)


def check_finite(source: str, where: str, value) -> None:
    _fail_if(source, where, finite_problem(value))


def check_positive(source: str, where: str, value) -> None:
    _fail_if(source, where, positive_problem(value))


def check_non_negative(source: str, where: str, value) -> None:
    _fail_if(source, where, non_negative_problem(value))


def check_choice(source: str, where: str, value, choices) -> None:
    _fail_if(source, where, choice_problem(value, choices))


def validate(s: Scenario, *, push_within_run: bool = True) -> None:
    """Checks every field that does not need the plant; raises ScenarioError for the first
    problem. The controller's sections are checked by the controller's own rules
    (:mod:`nsdrake.control.validation`), named after the scenario's fields.
    ``push_within_run`` False lets a push start after the run's end (``nsdrake compare
    --duration`` shortening a family whose push is within its own runs: that row says so)."""
    src = s.source or "scenario"
    for where, problem in scenario_problems(s, push_within_run=push_within_run):
        _fail(src, where, problem)


def scenario_problems(s: Scenario, *, push_within_run: bool = True) -> Iterator[tuple[str, str]]:
    """(field, problem) for every field that does not need the plant, in the order a
    reader meets them; a later check may assume the earlier ones found nothing (the
    caller stops at the first problem)."""
    yield from _checked("duration", positive_problem(s.duration))
    yield from _controller_problems(s)
    if s.control_period > s.duration:
        yield "control_period", f"{s.control_period} s is longer than the duration {s.duration} s"
    yield from _checked("plane", choice_problem(s.plane, PLANES))
    yield from _checked("controller_structure", choice_problem(s.controller_structure, CONTROLLER_STRUCTURES))
    if s.gravity:
        yield from _checked("gravity", gravity_problem(s.gravity))
    yield from _arm_and_plate_problems(s)
    yield from _task_and_report_problems(s)
    yield from _reference_problems(s)
    yield from _checked("divergence.max_joint_speed", positive_problem(s.divergence.max_joint_speed))
    yield from _checked("divergence.max_torque", positive_problem(s.divergence.max_torque))
    for where, problem in realism_problems(s.realism, s.control_period):
        yield f"realism.{where}", problem
    for where, problem in driver_problems(s.driver, s.control_period):
        yield f"driver.{where}", problem
    yield from _step_problems(s)
    yield from _obstacle_problems(s)
    yield from push_problems(s.push, s.duration if push_within_run else None)


def _checked(where: str, problem: str | None) -> Iterator[tuple[str, str]]:
    if problem:
        yield where, problem


# The controller's fields as a scenario names them (the others keep their names).
CONTROLLER_FIELDS = {"period": "control_period", "nominal_force": "reference.force"}


def controller_fields(s: Scenario) -> dict:
    """The scenario's part of a ControllerConfig, as keyword arguments."""
    return {
        "period": s.control_period,
        "impedance": s.impedance,
        "null_space": s.null_space,
        "desired_null_space": s.desired_null_space,
        "actuator_limits": s.actuator_limits,
        "nominal_force": s.reference.force,
    }


def _controller_problems(s: Scenario) -> Iterator[tuple[str, str]]:
    """The controller's sections, by the controller's rules (the same the Python API obeys)."""
    for where, problem in config_problems(SimpleNamespace(**controller_fields(s))):
        head, _, rest = where.partition(".")
        yield CONTROLLER_FIELDS.get(head, head) + (f".{rest}" if rest else ""), problem


def _step_problems(s: Scenario) -> Iterator[tuple[str, str]]:
    """The plant's step, the control period over the substeps of the realism rungs that
    are on, is no shorter than SHORTEST_STEP (no rung on: the control period itself)."""
    k = substeps(s.realism)
    step = s.control_period / k
    if step >= SHORTEST_STEP:
        return
    if k == 1:
        where = "control_period"
    elif s.realism.physics.enabled and k == s.realism.physics.substeps:
        where = "realism.physics.substeps"
    else:
        where = "realism.friction.min_substeps"
    yield (
        where,
        f"a plant step of {step:.3g} s ({s.control_period:g} s / {k}) is shorter than {SHORTEST_STEP:g} s: "
        f"more than {1 / SHORTEST_STEP:,.0f} plant steps per simulated second",
    )


def _arm_and_plate_problems(s: Scenario) -> Iterator[tuple[str, str]]:
    for table in ("initial_positions", "initial_velocities"):
        for name, value in getattr(s.arm, table).items():
            yield from _checked(f"arm.{table}.{_name(name)}", finite_problem(value))
    if not s.arm.initial_positions:
        yield "arm.initial_positions", "must give a position for every joint"
    yield from _payload_problems(s.arm.payload)
    tip = s.arm.tip_radius
    yield from _checked("arm.tip_radius", finite_problem(tip) or non_negative_problem(tip))
    yield from _checked("arm.tip_radius", length_problem([tip], "the tip's radius"))
    if len(s.plate.position) != 3:
        yield "plate.position", f"must be [x, y, z], got {_show(s.plate.position)}"
    for i, value in enumerate(s.plate.position):
        yield from _checked(f"plate.position[{i}]", finite_problem(value))
    yield from _checked("plate.position", length_problem(s.plate.position, "its distance from the origin"))
    for name in ("yaw", "roll", "pitch"):
        yield from _checked(f"plate.{name}", finite_problem(getattr(s.plate, name)))
    yield from _checked(
        "contact.approximation", choice_problem(s.contact.approximation, CONTACT_APPROXIMATIONS)
    )
    yield from _checked("contact.model", choice_problem(s.contact.model, CONTACT_MODELS))


def _payload_problems(p) -> Iterator[tuple[str, str]]:
    """The payload's fields one by one (its physical validity: the station's Payload check)."""
    yield from _checked("arm.payload.mass", finite_problem(p.mass) or non_negative_problem(p.mass))
    if len(p.com) != 3:
        yield "arm.payload.com", f"must be [x, y, z] in the tool frame, got {_show(p.com)}"
    if len(p.inertia) not in (0, 6):
        yield (
            "arm.payload.inertia",
            f"must be [ixx, iyy, izz, ixy, ixz, iyz] or empty, got {_show(p.inertia)}",
        )
    for name in ("com", "inertia"):
        for i, value in enumerate(getattr(p, name)):
            yield from _checked(f"arm.payload.{name}[{i}]", finite_problem(value))


def _task_and_report_problems(s: Scenario) -> Iterator[tuple[str, str]]:
    problem = task_axes_problem(s.task.axes)
    if problem:
        yield f"task.axes{problem[0]}", problem[1]
    for i, check in enumerate(s.report.checks):
        yield from _checked(f"report.checks[{i}]", choice_problem(check, REPORT_CHECKS))
    for i, m in enumerate(s.report.required_modes):
        if m not in (0, 1, 2, 3, 4):
            yield f"report.required_modes[{i}]", f"must be a mode 0-4, got {_show(m)}"
    if s.report.swivel_frames and len(s.report.swivel_frames) != 3:
        yield "report.swivel_frames", f"must name three frames or none, got {_show(s.report.swivel_frames)}"
    yield from check_needs(s)


def check_needs(s: Scenario) -> Iterator[tuple[str, str]]:
    """What a check of report.checks needs from the scenario's other fields, refused before
    the run rather than after it (the check's figures read trace columns that only these
    settings write); what needs the arm (joint limits) is checked with the station
    (:func:`nsdrake.experiment.scenario_station.check_needs_model`)."""
    checks = s.report.checks
    if "self_motion" in checks and not s.report.swivel_frames:
        yield (
            f"report.checks[{checks.index('self_motion')}]",
            "self_motion measures the elbow's swivel: give report.swivel_frames, the shoulder's, "
            "elbow's and wrist's frames (the Panda's: panda_link2, panda_link4, panda_link7)",
        )
    if s.report.required_modes and "priority" not in checks:
        yield (
            "report.required_modes",
            f"only the priority check reads them, and report.checks is {_show(checks)}: add priority",
        )
    if 4 in s.report.required_modes and s.desired_null_space.selector.q_lim <= 0:
        yield (
            f"report.required_modes[{s.report.required_modes.index(4)}]",
            "mode 4 (joint-limit avoidance) never comes with desired_null_space.selector.q_lim 0 "
            "(the branch is off); give q_lim > 0",
        )
    for name in ("camera_position", "camera_target"):
        value = getattr(s.report, name)
        if value and (len(value) != 3 or not all(math.isfinite(v) for v in value)):
            yield f"report.{name}", f"must be [x, y, z] or empty, got {_show(value)}"


def _reference_problems(s: Scenario) -> Iterator[tuple[str, str]]:
    r = s.reference
    yield from _checked("reference.path", choice_problem(r.path, REFERENCE_PATHS))
    yield from _checked("reference.orientation", choice_problem(r.orientation, ORIENTATIONS))
    if r.path == "circle":
        yield from _circle_problems(r, s.task.axes)
    for name in ("tangent_speed", "approach_speed"):
        yield from _checked(f"reference.{name}", finite_problem(getattr(r, name)))
    checks = [
        ("approach_speed", non_negative_problem(r.approach_speed)),
        ("blend_time", non_negative_problem(r.blend_time)),
        ("force_ramp_time", non_negative_problem(r.force_ramp_time)),
        ("contact_threshold", positive_problem(r.contact_threshold)),
        ("loss_time", positive_problem(r.loss_time)),
        ("max_overtravel", non_negative_problem(r.max_overtravel)),
        ("reach_margin", fraction_problem(r.reach_margin)),
        ("step_time", finite_problem(r.step_time)),
    ]
    for name, problem in checks + touch_problems(r):
        yield from _checked(f"reference.{name}", problem)
    if r.step_time > 0:
        yield from _checked("reference.step_force", positive_problem(r.step_force))
    if r.contact_threshold >= r.force:
        yield (
            "reference.contact_threshold",
            f"{r.contact_threshold} N must be below reference.force {r.force} N",
        )


def _circle_problems(r: ReferenceConfig, axes) -> Iterator[tuple[str, str]]:
    if len([a for a in axes if a in AXIS_NAMES]) != 3:
        yield "reference.path", f"a circle on the surface needs the task axes x, y, z, got {axes!r}"
    yield from _checked("reference.radius", positive_problem(r.radius))
    yield from _checked("reference.laps", positive_problem(r.laps))
    yield from _checked("reference.start_angle", finite_problem(r.start_angle))
    yield from _checked("reference.delay", non_negative_problem(r.delay))
    if r.tangent_speed == 0:
        yield "reference.tangent_speed", "a circle needs a non-zero speed"
    length = 2 * math.pi * r.radius * r.laps
    if length < abs(r.tangent_speed) * r.blend_time:
        yield (
            "reference.laps",
            f"the circle ({length:.4g} m) is shorter than the speed blends need "
            f"(|tangent_speed| x blend_time = {abs(r.tangent_speed) * r.blend_time:.4g} m)",
        )


def _obstacle_problems(s: Scenario) -> Iterator[tuple[str, str]]:
    names = set()
    for i, ob in enumerate(s.obstacles):
        where = f"obstacles[{i}]"
        if not ob.name:
            yield f"{where}.name", "every obstacle needs a name"
        if ob.name in names:
            yield f"{where}.name", f"duplicate obstacle name '{_name(ob.name)}'"
        names.add(ob.name)
        if not ob.shape:
            shapes = ", ".join(OBSTACLE_SHAPES)
            yield where, f"obstacle '{_name(ob.name)}' has no geometry: give shape ({shapes}) and size"
        yield from _checked(f"{where}.shape", choice_problem(ob.shape, tuple(OBSTACLE_SHAPES)))
        if len(ob.size) != OBSTACLE_SHAPES[ob.shape]:
            entries = OBSTACLE_SHAPES[ob.shape]
            yield f"{where}.size", f"a {ob.shape} needs {entries} size entries, got {_show(ob.size)}"
        for k, value in enumerate(ob.size):
            yield from _checked(f"{where}.size[{k}]", positive_problem(value))
        yield from _checked(f"{where}.size", length_problem(ob.size, "its size"))
        if len(ob.position) != 3:
            yield f"{where}.position", f"must be [x, y, z], got {_show(ob.position)}"
        for k, value in enumerate(ob.position):
            yield from _checked(f"{where}.position[{k}]", finite_problem(value))
        yield from _checked(f"{where}.position", length_problem(ob.position, "its distance from the origin"))
        yield from _checked(f"{where}.yaw", finite_problem(ob.yaw))


def check_against_plant(s: Scenario, joint_names: tuple[str, ...]) -> None:
    """Checks the fields keyed by joint name against the arm's joints."""
    src = s.source or "scenario"
    valid = ", ".join(joint_names)
    for where in JOINT_TABLES:
        if where == "arm.locked":  # the joints that are not the arm's (checked where they are locked)
            continue
        for name in value_at(s, where):
            if name not in joint_names:
                _fail(src, f"{where}.{_name(name)}", f"unknown joint; the arm's joints are {valid}")
    missing = [j for j in joint_names if j not in s.arm.initial_positions]
    if missing:
        _fail(src, "arm.initial_positions", f"no position for joint(s) {', '.join(missing)}")

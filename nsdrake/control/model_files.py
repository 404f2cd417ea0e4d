"""Model files as vendors ship them, parsed by Drake from the file, and a tool payload.

A model file is a URDF, an SDF or Drake model directives (``.dmd.yaml``); Drake parses it
from its path, so a relative mesh URI (``meshes/link1.obj``) resolves from the file's
folder. A ``package://NAME/…`` URI resolves, first found wins, from

1. ``packages``, an explicit ``{name: folder}`` map (the API's argument, a scenario's
   ``arm.packages``);
2. the nearest ``package.xml`` above the file (the package the file belongs to);
3. the folders of ``ROS_PACKAGE_PATH`` (every ``package.xml`` below them; Drake warns when
   one names a package already found elsewhere, and keeps the first).

Drake uses an ``.obj`` collision mesh's convex hull for distance queries and point
contact; the controller's obstacle criterion sees it as Drake does.

A :class:`Payload` is what the tool carries (a gripper, a part): a mass, its centre of mass
and optionally its rotational inertia, on the tool frame. :func:`add_payload` welds a body
of that inertia to the tool frame, in the controller's model (the controller is told) and
in a simulated station (the arm carries it).
"""

from __future__ import annotations

import logging
import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RotationalInertia, SpatialInertia, WeldJoint

from nsdrake.control.model_sources import HulledModel, ModelSources, read_sources
from nsdrake.control.urdf_checks import sdf_problems
from nsdrake.control.validation import (
    ControllerConfigError,
    one_line,
    positive_problem,
    real_problem,
    show,
    vector_problem,
)

MODEL_SUFFIXES = (".urdf", ".sdf", ".dmd.yaml")


@dataclass(frozen=True)
class Payload:
    """A payload on the tool frame T: ``mass`` [kg], its centre of mass ``com`` in T [m],
    and ``inertia``, its rotational inertia about the centre of mass in T's axes, a (3, 3)
    matrix or the six numbers (ixx, iyy, izz, ixy, ixz, iyz) [kg m²]; None: a point mass."""

    mass: float  # [kg]
    com: Sequence[float] = (0.0, 0.0, 0.0)  # its centre of mass in the tool frame [m]
    inertia: Sequence | None = None  # about the centre of mass, tool frame axes [kg m²]; None: a point mass

    def spatial_inertia(self) -> SpatialInertia:
        """M_TTo: the payload's spatial inertia about T's origin, expressed in T."""
        I = np.zeros((3, 3)) if self.inertia is None else inertia_matrix(self.inertia)
        I_Tcm = RotationalInertia(I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
        return SpatialInertia.MakeFromCentralInertia(
            float(self.mass), np.asarray(self.com, dtype=float), I_Tcm
        )


def inertia_matrix(inertia) -> np.ndarray:
    """(3, 3) from a (3, 3) matrix or the six numbers (ixx, iyy, izz, ixy, ixz, iyz)."""
    values = np.asarray(inertia, dtype=float)
    if values.shape == (6,):
        xx, yy, zz, xy, xz, yz = values
        return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    return values


def payload_problem(payload) -> str | None:
    """Why ``payload`` is no physical payload, or None. Its numbers follow the package's one
    number rule (:func:`nsdrake.control.validation.real_problem`): booleans (True is not
    1 kg), text and complex values are refused, naming the field."""
    if not isinstance(payload, Payload):
        return f"must be a Payload(mass, com, inertia), got {show(payload)}"
    mass = payload.mass
    problem = real_problem(mass, "a finite number > 0 [kg]")
    if problem is None and positive_problem(mass):
        problem = f"must be a finite number > 0 [kg], got {show(mass)}"
    if problem:
        return f"mass {problem}"
    what = "three finite numbers within 10 m of the tool frame [m]"
    problem = vector_problem(payload.com, 3, what)
    if problem is None and np.max(np.abs(np.asarray(payload.com, dtype=float))) > 10.0:
        problem = f"must be {what}, got {show(payload.com)}"
    if problem:
        return f"com {problem}"
    if payload.inertia is None:
        return None
    what = "a symmetric (3, 3) matrix or (ixx, iyy, izz, ixy, ixz, iyz) [kg m²]"
    problem = real_problem(payload.inertia, what)
    if problem:
        return f"inertia {problem}"
    I = inertia_matrix(payload.inertia) if _numeric(payload.inertia) else None
    if I is None or I.shape != (3, 3) or not np.all(np.isfinite(I)) or not np.allclose(I, I.T):
        return f"inertia must be {what}, got {show(payload.inertia)}"
    moments = np.linalg.eigvalsh(I)
    if moments[0] < 0 or moments[0] + moments[1] < moments[2] * (1 - 1e-9):
        return f"inertia is not physical: principal moments {np.round(moments, 9).tolist()}"
    return None


def _numeric(value) -> bool:
    try:
        np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return False
    return True


def add_payload(plant: MultibodyPlant, tool_frame, payload: Payload, name: str = "payload"):
    """Welds a body of the payload's inertia to ``tool_frame`` (its body frame is the tool
    frame) in the not yet finalized ``plant``; returns the body."""
    instance = tool_frame.model_instance()
    body = plant.AddRigidBody(name, instance, payload.spatial_inertia())
    plant.WeldFrames(tool_frame, body.body_frame(), RigidTransform())
    return body


def model_file_problem(path) -> str | None:
    """Why ``path`` is no model file Drake can read, or None."""
    if not isinstance(path, str | os.PathLike):
        return f"must be a path to a model file, got {show(path)}"
    name = Path(path).name.lower()
    if not name.endswith(MODEL_SUFFIXES):
        return f"{show(str(path))} must be a {', '.join(MODEL_SUFFIXES)} file"
    if not Path(path).is_file():
        return f"{show(str(path))} is not a file"
    return None


def sdf_file_problem(path: Path) -> tuple[str, str] | None:
    """(where, problem) for the first link of an SDF file that is physically invalid
    (:func:`nsdrake.control.urdf_checks.sdf_problems`), or None (other kinds: None)."""
    if not str(path).lower().endswith(".sdf"):
        return None
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as e:
        return "", f"not XML: {one_line(e)}"
    return next(iter(sdf_problems(root)), None)


def packages_problem(packages) -> str | None:
    """Why ``packages`` is no {name: folder} map of existing folders, or None."""
    if not isinstance(packages, Mapping):
        return f"must be a {{name: folder}} mapping, got {show(packages)}"
    for name, folder in packages.items():
        if not isinstance(name, str) or not name or "/" in name:
            return f"package names must be non-empty strings without '/', got {show(name)}"
        if not isinstance(folder, str | os.PathLike) or not Path(folder).is_dir():
            return f"{name}: {show(str(folder))} is not a folder"
    return None


def nearest_package_xml(path: Path) -> Path | None:
    """The first ``package.xml`` in the file's folder or a folder above it, or None."""
    for folder in Path(path).resolve().parents:
        candidate = folder / "package.xml"
        if candidate.is_file():
            return candidate
    return None


def _package_name(xml: Path) -> str:
    """The <name> a package.xml declares ("" if none)."""
    try:
        name = ET.parse(xml).getroot().find("name")
    except ET.ParseError:
        return ""  # Drake's AddPackageXml says what is wrong with it
    return "" if name is None or name.text is None else name.text.strip()


def model_parser(plant: MultibodyPlant, path: Path, packages: Mapping[str, str | Path]) -> Parser:
    """A Parser of ``plant`` whose package map resolves ``package://`` as the module says."""
    parser = Parser(plant)
    package_map = parser.package_map()
    for name, folder in packages.items():
        package_map.Add(name, str(Path(folder).resolve()))
    xml = nearest_package_xml(path)
    if xml is not None and not package_map.Contains(_package_name(xml)):
        package_map.AddPackageXml(str(xml))
    if os.environ.get("ROS_PACKAGE_PATH"):
        package_map.PopulateFromRosPackagePath()
    return parser


@dataclass
class ParsedModel:
    """What :func:`parse_model_file` put in the plant."""

    instances: list  # the model instances the file added
    sources: ModelSources  # every file of the model and what they declare
    welded: list[str]  # root bodies that floated, welded to the world here
    warnings: dict[str, list[str]]  # Drake's parser warnings, by file name (full text)
    locked: dict[str, float] = field(default_factory=dict)  # joints locked (choose_joints) -> position


class _DrakeWarnings(logging.Handler):
    """Collects Drake's log records (pydrake sends spdlog's to Python's "drake" logger)
    while a file is parsed, instead of printing each."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.records: list[str] = []

    def emit(self, record):
        self.records.append(record.getMessage())

    def __enter__(self):
        logger = logging.getLogger("drake")
        self._propagate, logger.propagate = logger.propagate, False
        logger.addHandler(self)
        return self

    def __exit__(self, *_):
        logger = logging.getLogger("drake")
        logger.removeHandler(self)
        logger.propagate = self._propagate


def parse_model_file(
    plant: MultibodyPlant,
    path,
    packages=None,
    where: str = "model_file",
    *,
    base_pose=None,
    add=None,
    visuals: bool = True,
) -> ParsedModel:
    """Drake parses the model file ``path`` into ``plant`` (module docstring), after every file
    it includes passed the checks of :mod:`nsdrake.control.model_sources`. With a SceneGraph,
    collision meshes Drake takes no hull of are given as their hulls. A root body that floats
    (no joint to the world: a ROS URDF without a ``world`` link) is welded to the world at
    ``base_pose`` (a RigidTransform; the world's origin if None), said in one line; a joint
    with a ``<limit effort>`` but no actuator (no ``<transmission>``) gets an actuator of that
    effort limit. Drake's parser warnings are said in one line per file. ``add(parser, path)``
    replaces ``parser.AddModels(path)`` (the station's belts); without ``visuals``, a copy
    made for hulls leaves the visual elements out. Every problem is a one-line
    ControllerConfigError naming ``where``."""
    _check_arguments(path, packages, base_pose, where)
    path = Path(path)
    parser = model_parser(plant, path, packages or {})
    sources = read_sources(path, parser.package_map(), where)
    add = add or (lambda parser, file: parser.AddModels(str(file)))
    hulled = plant.geometry_source_is_registered() and sources.meshes_to_hull
    with (
        _DrakeWarnings() as drake,
        HulledModel(sources, parser.package_map(), where, visuals) if hulled else _Same(path) as copy,
    ):
        try:
            instances = add(parser, copy.top)
        except (RuntimeError, ValueError) as e:
            text = copy.original_text(one_line(e))
            hint = (
                " (give the package as packages={name: folder}, in a package.xml above the file, "
                "or in ROS_PACKAGE_PATH)"
                if "unknown package" in text
                else ""
            )
            # 240 characters of Drake's words, the file's own folder not counted (it repeats
            # the path: where the file is installed must not change what the line keeps).
            folder = str(path.parent) + "/"
            budget = 240 + text.count(folder) * len(folder)
            text = text if len(text) <= budget else text[: budget - 1] + "…"
            raise ControllerConfigError(
                f"{where}: {path.name}", f"Drake cannot parse it: {text}{hint}"
            ) from None
        warnings = _by_file([copy.original_text(r) for r in drake.records], sources)
    _say_warnings(warnings, where, path)
    welded = weld_floating_roots(plant, instances, base_pose or RigidTransform())
    if welded:
        bodies, at = ", ".join(f"'{b}'" for b in welded), "its origin" if base_pose is None else "base_pose"
        say_once(
            f"{where}: {path.name}: its root body {bodies} floats (no joint to the world): welded to the "
            f"world at {at} (base_pose= places it)",
            path.resolve(),
        )
    add_effort_actuators(plant, instances, sources.efforts)
    return ParsedModel(instances, sources, welded, warnings)


LOG = logging.getLogger("nsdrake")


def _check_arguments(path, packages, base_pose, where: str) -> None:
    problem = model_file_problem(path)
    if problem:
        raise ControllerConfigError(where, problem)
    problem = packages_problem({} if packages is None else packages)
    if problem:
        raise ControllerConfigError("packages", problem)
    if base_pose is not None and not isinstance(base_pose, RigidTransform):
        raise ControllerConfigError("base_pose", f"must be a RigidTransform, got {show(base_pose)}")


def _say_warnings(warnings: dict[str, list[str]], where: str, path: Path) -> None:
    """One line per file: how many warnings Drake's parser gave, and the first."""
    for name, texts in warnings.items():
        first = " ".join(texts[0].split("warning: ", 1)[-1].split())
        first = first if len(first) <= 160 else first[:159] + "…"
        line = f"{where}: {name}: Drake's parser warned {len(texts)} time(s) (first: {first})"
        say_once(line, path.resolve())


MODEL_WARNINGS = "model_warnings.txt"  # a run folder's file of Drake's parser warnings, in full


def warnings_text(warnings: dict[str, list[str]]) -> str:
    """Every parser warning in full (:attr:`ParsedModel.warnings`), a file's after its name:
    the text of a run's :data:`MODEL_WARNINGS`, of which the log says one line per file."""
    sections = [
        f"# {name}: {len(texts)} warning(s) of Drake's parser\n" + "".join(f"{t.rstrip()}\n" for t in texts)
        for name, texts in warnings.items()
    ]
    return "\n".join(sections)


_SAID: set = set()


def say_once(line: str, about=None) -> None:
    """``line`` on nsdrake's logger, once per process for the same ``about`` (a file's path;
    None: the line itself): a run parses the same file for the simulated station and for
    the controller's model."""
    key = (about, line)
    if key not in _SAID:
        _SAID.add(key)
        LOG.warning("%s", line)


class _Same:
    """The model file itself (no copy needed)."""

    def __init__(self, path: Path):
        self.top = path

    def __enter__(self):
        return self

    def __exit__(self, *_):
        return None

    def original_text(self, text: str) -> str:
        return text


def _by_file(records: list[str], sources: ModelSources) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for record in records:
        name = next((f.path.name for f in sources.files if str(f.path) in record), sources.files[0].path.name)
        out.setdefault(name, []).append(record)
    return out


def weld_floating_roots(plant: MultibodyPlant, instances, X_WB: RigidTransform) -> list[str]:
    """Welds to the world, at X_WB, every body of ``instances`` that is no joint's child (it
    would float); returns their names."""
    children = {plant.get_joint(j).child_body().index() for j in plant.GetJointIndices()}
    world = plant.world_body().index()
    welded = []
    for instance in instances:
        for index in plant.GetBodyIndices(instance):
            if index != world and index not in children:
                body = plant.get_body(index)
                plant.WeldFrames(plant.world_frame(), body.body_frame(), X_WB)
                welded.append(body.name())
    return welded


def add_effort_actuators(plant: MultibodyPlant, instances, efforts: Mapping[str, float]) -> list[str]:
    """An actuator for each revolute or prismatic joint of ``instances`` that has none, with the
    effort limit its file declares (``<limit effort>``; Drake makes actuators only from a
    ``<transmission>``); a joint without one gets none. Returns the joints given one."""
    actuated = {plant.get_joint_actuator(a).joint().index() for a in plant.GetJointActuatorIndices()}
    added = []
    for instance in instances:
        for index in plant.GetJointIndices(instance):
            joint = plant.get_joint(index)
            if index in actuated or joint.num_velocities() != 1 or joint.name() not in efforts:
                continue
            plant.AddJointActuator(joint.name(), joint, efforts[joint.name()])
            added.append(joint.name())
    return added


def choose_joints(plant: MultibodyPlant, joints, locked, mimics: Mapping, where: str = "joints") -> dict:
    """Keeps ``joints`` (names; None: every joint) as the arm's joints and welds every other
    revolute or prismatic joint at its position in ``locked`` ({name: position} [rad or m];
    0 if not given, said in one line naming them; a mimic joint at its leader's image), so that
    its child's mass joins its parent's; in the not yet finalized ``plant``. A ``<mimic>``
    joint (``mimics``: the follower's name → :class:`nsdrake.control.model_sources.Mimic`)
    among the arm's joints, or following one of them, is refused: the controller's joints are
    independent. Returns the locked positions. Every problem is a one-line ControllerConfigError."""
    movable = [plant.get_joint(j) for j in plant.GetJointIndices() if plant.get_joint(j).num_velocities()]
    names = [j.name() for j in movable]
    locked = {} if locked is None else locked
    chosen = _chosen(names, joints, locked, where)
    for mimic in mimics.values():
        if mimic.joint in names and (mimic.joint in chosen or mimic.leader in chosen):
            raise ControllerConfigError(
                f"{where}: {mimic.joint}",
                f"mimics '{mimic.leader}' (<mimic>): the arm's joints must be independent; leave both out "
                "of joints=[...] (they are locked)",
            )
    positions, unstated = {}, []
    locked_indices = {j.index() for j in movable if j.name() not in chosen}
    present = [m for m in mimics.values() if m.joint in names]
    if locked_indices and present and plant.num_constraints() == len(present):
        for constraint in plant.GetConstraintIds():  # the <mimic>s' couplers, all between locked joints
            plant.RemoveConstraint(constraint)
    for joint in movable:
        if joint.name() in chosen:
            continue
        q = locked.get(joint.name())
        mimic = mimics.get(joint.name())
        if q is None and mimic is not None:
            leader = locked.get(mimic.leader, 0.0)
            q = mimic.multiplier * leader + mimic.offset
        if q is None:
            unstated.append(joint.name())
        q = 0.0 if q is None else float(q)
        lower, upper = joint.position_lower_limits()[0], joint.position_upper_limits()[0]
        if not lower - 1e-12 <= q <= upper + 1e-12:
            raise ControllerConfigError(
                f"locked: {joint.name()}",
                f"{q:g} is outside the joint's limits [{lower:g}, {upper:g}]; state it",
            )
        positions[joint.name()] = q
        _weld(plant, joint, q, where)  # the joint object is gone after this
    if unstated:
        say_once(
            f"locked: {', '.join(unstated)} held at 0 [rad or m], the default: no position stated "
            "for them in locked (arm.locked in a scenario)"
        )
    return positions


def _chosen(names: list[str], joints, locked, where: str) -> list[str]:
    """The arm's joints: ``joints`` (None: ``names``, every joint) checked against ``names``,
    and ``locked`` checked to name only other joints, with numbers."""
    if joints is not None and (isinstance(joints, str) or not isinstance(joints, Sequence)):
        raise ControllerConfigError(where, f"must be a list of joint names, got {show(joints)}")
    chosen = list(names if joints is None else joints)
    for name in chosen:
        if name not in names or chosen.count(name) > 1:
            why = "named twice" if name in names else "unknown joint"
            raise ControllerConfigError(
                f"{where}: {show(name)}", f"{why}; the file's joints are {', '.join(names)}"
            )
    if not isinstance(locked, Mapping):
        raise ControllerConfigError("locked", f"must be a {{joint: position}} mapping, got {show(locked)}")
    for name, value in locked.items():
        if name not in names or name in chosen:
            why = "is one of the arm's joints" if name in chosen else "unknown joint"
            raise ControllerConfigError(
                f"locked: {show(name)}", f"{why}; locked joints are those not in joints"
            )
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            raise ControllerConfigError(
                f"locked: {name}", f"must be a finite number [rad or m], got {show(value)}"
            )
    return chosen


def _weld(plant: MultibodyPlant, joint, q: float, where: str) -> None:
    """Replaces the revolute or prismatic ``joint`` by a weld at position ``q``."""
    kind = joint.type_name()
    if kind == "revolute":
        X_FM = RigidTransform(RotationMatrix(AngleAxis(q, np.asarray(joint.revolute_axis()))), np.zeros(3))
    elif kind == "prismatic":
        X_FM = RigidTransform(q * np.asarray(joint.translation_axis()))
    else:
        raise ControllerConfigError(
            f"{where}: {joint.name()}", f"a {kind} joint cannot be locked here (revolute and prismatic can)"
        )
    F, M, name = joint.frame_on_parent(), joint.frame_on_child(), joint.name()
    for a in list(plant.GetJointActuatorIndices()):
        if plant.get_joint_actuator(a).joint().index() == joint.index():
            plant.RemoveJointActuator(plant.get_joint_actuator(a))
    try:
        plant.RemoveJoint(joint)
    except RuntimeError as e:
        raise ControllerConfigError(f"{where}: {name}", f"Drake cannot lock it: {one_line(e)}") from None
    plant.AddJoint(WeldJoint(name, F, M, X_FM))

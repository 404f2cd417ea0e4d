"""The arm as the controller knows it: its own model, never the simulated plant.

A :class:`ControllerModel` owns a Drake ``MultibodyPlant`` of the arm (and, for
obstacle avoidance, a ``SceneGraph`` holding the arm's collision geometry and the
obstacles it should keep away from), the tool frame and the task axes. It is what
a controller on a real robot has: a model of the arm and of its surroundings,
read from its model file (URDF, SDF or Drake model directives, with meshes and
packages: :mod:`nsdrake.control.model_files`), and nothing from the simulator.

Model terms (H, C q̇, g, C, J) come from one of two libraries:

- ``"drake"``: the plant's own calls (:class:`nsdrake.control.dynamics.ArmModel`), C by
  polarisation of the bias term;
- ``"pinocchio"``: Pinocchio (``pip install pin``) built from the same plant
  (:mod:`nsdrake.control.pinocchio_tree`), C from
  ``computeCoriolisMatrix`` (the Christoffel matrix, Ḣ = C + Cᵀ), about ten times
  faster. At construction H, g, C q̇ and the tool Jacobian of both libraries are
  compared at a few seeded random states; a mismatch is refused with a one-line
  error naming the term (:class:`ModelMismatchError`).

``"auto"`` takes Pinocchio when it is installed and the model came from a model file
or URDF text (:meth:`ControllerModel.from_file`, :meth:`ControllerModel.from_urdf`).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit
from pydrake.geometry import ProximityProperties, SceneGraph, Shape
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.systems.framework import DiagramBuilder

from nsdrake.control.criteria.obstacle import proximity_geometries
from nsdrake.control.dynamics import ArmModel, RobotTerms
from nsdrake.control.model_files import (
    Payload,
    add_payload,
    choose_joints,
    model_file_problem,
    parse_model_file,
    payload_problem,
    say_once,
)
from nsdrake.control.pinocchio_tree import pinocchio_model
from nsdrake.control.urdf_checks import parse_urdf, urdf_problems
from nsdrake.control.validation import (
    ControllerConfigError,
    arm_problem,
    damping_time_problem,
    gravity_problem,
    length_problem,
    one_line,
    show,
    task_axes_problem,
)

DYNAMICS = ("auto", "drake", "pinocchio")


class ModelMismatchError(ControllerConfigError):
    """Two model libraries disagree about the same arm."""


@dataclass(frozen=True)
class Obstacle:
    """A fixed obstacle the controller knows about: a shape at a pose in the world."""

    name: str  # its name
    shape: Shape  # pydrake.geometry.Box, Sphere, Cylinder, …
    X_WO: RigidTransform  # pose of the shape's frame in the world


class ControllerModel:
    """The controller's model of the arm and its surroundings (module docstring).

    Build it with :meth:`from_file` or :meth:`from_urdf` (obstacle avoidance, Pinocchio and
    a payload possible) or
    :meth:`from_plant` (a finalized plant of your own, Drake terms, no obstacles).

    Attributes:
        plant: the controller's MultibodyPlant (finalized).
        arm: the :class:`nsdrake.control.dynamics.ArmModel` (joint order, tool frame, task axes).
        n, m: joints, task axes.
        joint_names: in velocity order.
        dynamics: "drake" or "pinocchio", the library the model terms come from.

    ``damping_time`` (every constructor): T_D [s], the time over which the model takes the
    joints' declared damping D to act on a held command, added to its inertia as H + T_D D
    (:class:`nsdrake.control.dynamics.ArmModel` says why). State it: the plant's step ``h``
    for Drake's discrete plant stepping once per control period T (exact), (T + h)/2 with
    several steps per period, T/2 for a real arm (continuous damping, the command held over
    the period); None: 0 (D q̇ compensated at the tick's state only), said in one line when
    the model has damping.
    """

    def __init__(
        self,
        *,
        plant: MultibodyPlant,
        tool_frame: str,
        task_axes: Sequence[str],
        scene_graph: SceneGraph | None = None,
        diagram=None,
        fast_terms: bool = False,
        dynamics: str = "auto",
        damping_time: float | None = None,
    ):
        _check_arguments(plant, tool_frame, task_axes, dynamics)
        problem = damping_time_problem(damping_time)
        if problem:
            raise ControllerConfigError("damping_time", problem)
        self.plant = plant
        self.scene_graph = scene_graph
        self.diagram = diagram
        self.tool_frame_name = tool_frame
        try:
            self.arm = ArmModel(plant, plant.GetFrameByName(tool_frame), task_axes, damping_time or 0.0)
        except ValueError as e:  # joints nsdrake cannot model (floating, ball, …)
            raise ControllerConfigError("controller_model", one_line(e)) from None
        problem = arm_problem(self.arm.n, self.arm.m, task_axes)
        if problem:  # before any model term is computed (Pinocchio and numba need joints)
            raise ControllerConfigError(*problem)
        self.n, self.m = self.arm.n, self.arm.m
        self.joint_names = self.arm.joint_names
        self.link_geometries: list = []
        self.obstacle_geometries: list = []
        if scene_graph is not None:
            inspector = scene_graph.model_inspector()
            tool = self.arm.tool_frame.body().index()
            world = plant.world_body().index()
            arm_bodies = [plant.get_body(b).index() for b in _moving_bodies(plant) if b != tool]
            self.link_geometries = proximity_geometries(inspector, plant, arm_bodies)
            self.obstacle_geometries = proximity_geometries(inspector, plant, [world])
        self._pinocchio = _pinocchio_dynamics(fast_terms, self.arm, dynamics)
        self.dynamics = "pinocchio" if self._pinocchio else "drake"
        if damping_time is None and np.any(self.arm.damping):
            say_once(damping_note(self.arm))
        # What the model file's parse found (nsdrake.control.model_files.ParsedModel), or None.
        self.parsed = None

    @classmethod
    def from_file(
        cls,
        path: str | Path,
        *,
        tool_frame: str,
        task_axes: Sequence[str],
        packages: Mapping[str, str | Path] | None = None,
        gravity: Sequence[float] = (0.0, 0.0, -9.81),
        obstacles: Sequence[Obstacle] = (),
        payload: Payload | None = None,
        dynamics: str = "auto",
        joints: Sequence[str] | None = None,
        locked: Mapping[str, float] | None = None,
        base_pose: RigidTransform | None = None,
        damping_time: float | None = None,
    ) -> ControllerModel:
        """The arm of a model file as its vendor ships it: a URDF, an SDF or Drake model
        directives (``.dmd.yaml``), parsed by Drake from the file, so relative mesh URIs
        resolve from its folder and ``package://`` from ``packages`` ({name: folder}), the
        nearest ``package.xml`` above the file and ``ROS_PACKAGE_PATH``
        (:mod:`nsdrake.control.model_files`). The file welds the arm to the world. A
        ``payload`` (:class:`nsdrake.control.model_files.Payload`) is welded to the tool
        frame. Otherwise as :meth:`from_urdf`: the same fast terms (Pinocchio, built from the
        plant Drake parsed: :mod:`nsdrake.control.pinocchio_tree`) and obstacle avoidance
        against the model's collision geometry (a mesh as its convex hull, whatever its
        format). Without obstacles no geometry is read at all.

        Every file the model includes is checked first (:mod:`nsdrake.control.model_sources`).
        A root body that floats (a ROS URDF without a ``world`` link) is welded to the world
        at ``base_pose`` (the origin if None), said in one line. ``joints``: the arm's joints
        (None: every joint of the file); every other one is locked at its position in
        ``locked`` ({name: position}, 0 if not given) and its links' mass joins its parent
        (gripper fingers, a mobile base). A ``<mimic>`` joint must be locked. A joint's
        ``<limit effort>`` gives its torque limit when the file has no ``<transmission>``;
        its ``<dynamics damping>`` D is compensated, as D q̇ and as the inertia ``damping_time``
        · D it adds over a held command (the class docstring)."""
        problem = model_file_problem(path)
        if problem:
            raise ControllerConfigError("model_file", problem)
        where = f"model_file: {Path(path).name}"

        def add(plant):
            parsed = parse_model_file(plant, path, packages, "model_file", base_pose=base_pose, visuals=False)
            parsed.locked = choose_joints(plant, joints, locked, parsed.sources.mimics)
            return parsed

        return cls._parsed(
            add,
            where,
            tool_frame=tool_frame,
            task_axes=task_axes,
            gravity=gravity,
            obstacles=obstacles,
            payload=payload,
            dynamics=dynamics,
            damping_time=damping_time,
        )

    @classmethod
    def from_urdf(
        cls,
        urdf: str | Path,
        *,
        tool_frame: str,
        task_axes: Sequence[str],
        gravity: Sequence[float] = (0.0, 0.0, -9.81),
        obstacles: Sequence[Obstacle] = (),
        payload: Payload | None = None,
        dynamics: str = "auto",
        damping_time: float | None = None,
    ) -> ControllerModel:
        """The arm of a URDF, welded to the world by the file itself, with ``obstacles``
        fixed in the world and ``gravity`` [m/s²]. ``urdf``: a ``Path``, or a ``str`` that
        is the URDF's text (it holds a "<" or a line break) or else a path (a ``.urdf`` path
        goes to :meth:`from_file`: meshes and packages resolve from the file; another name is
        read and parsed as text). The URDF is
        checked before Drake or Pinocchio reads it (:mod:`nsdrake.control.urdf_checks`);
        every problem is a one-line :class:`ControllerConfigError` naming the argument."""
        text, where = _urdf_text(urdf)
        if where != "controller_model" and str(urdf).lower().endswith(".urdf"):  # Drake parses the file
            return cls.from_file(
                urdf,
                tool_frame=tool_frame,
                task_axes=task_axes,
                gravity=gravity,
                obstacles=obstacles,
                payload=payload,
                dynamics=dynamics,
                damping_time=damping_time,
            )

        def add(plant):
            try:
                Parser(plant).AddModelsFromString(text, "urdf")
            except RuntimeError as e:
                raise ControllerConfigError(where, f"Drake cannot parse it: {_cut(e)}") from None

        return cls._parsed(
            add,
            where,
            tool_frame=tool_frame,
            task_axes=task_axes,
            gravity=gravity,
            obstacles=obstacles,
            payload=payload,
            dynamics=dynamics,
            damping_time=damping_time,
        )

    @classmethod
    def _parsed(
        cls, add_models, where, *, tool_frame, task_axes, gravity, obstacles, payload, dynamics, damping_time
    ):
        """The model of what ``add_models(plant)`` parses, with obstacles, payload and gravity."""
        problem = gravity_problem(gravity)
        if problem:
            raise ControllerConfigError("gravity", problem)
        check_obstacles(obstacles)
        problem = None if payload is None else payload_problem(payload)
        if problem:
            raise ControllerConfigError("payload", problem)
        builder = DiagramBuilder()
        if obstacles:
            plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        else:  # no geometry is needed, none is read
            plant, scene_graph = builder.AddSystem(MultibodyPlant(0.0)), None
        plant.set_name("controller_model")
        parsed = add_models(plant)
        for ob in obstacles:
            plant.RegisterCollisionGeometry(
                plant.world_body(), ob.X_WO, ob.shape, ob.name, ProximityProperties()
            )
        if payload is not None:
            if not isinstance(tool_frame, str) or not plant.HasFrameNamed(tool_frame):
                raise ControllerConfigError(
                    "tool_frame", f"the controller model has no frame named {show(tool_frame)}"
                )
            add_payload(plant, plant.GetFrameByName(tool_frame), payload)
        plant.mutable_gravity_field().set_gravity_vector(np.asarray(gravity, dtype=float))
        try:
            plant.Finalize()
        except RuntimeError as e:
            raise ControllerConfigError(where, f"Drake cannot build the plant: {_cut(e)}") from None
        diagram = builder.Build()
        model = cls(
            plant=plant,
            tool_frame=tool_frame,
            task_axes=task_axes,
            scene_graph=scene_graph,
            diagram=diagram,
            fast_terms=True,
            dynamics=dynamics,
            damping_time=damping_time,
        )
        model.parsed = parsed
        limits = [plant.get_joint_actuator(a).effort_limit() for a in plant.GetJointActuatorIndices()]
        if not any(np.isfinite(limits)):
            say_once(
                f"{where}: no joint has a torque limit (no <transmission> effort, no <limit effort>): "
                "nothing bounds the commands but actuator_limits.torque",
                parsed.sources.files[0].path if parsed is not None else None,
            )
        return model

    @classmethod
    def from_plant(
        cls,
        plant: MultibodyPlant,
        *,
        tool_frame: str,
        task_axes: Sequence[str],
        damping_time: float | None = None,
    ) -> ControllerModel:
        """A finalized plant of the arm alone (not the simulated one): Drake terms, no obstacles."""
        return cls(
            plant=plant,
            tool_frame=tool_frame,
            task_axes=task_axes,
            dynamics="drake",
            damping_time=damping_time,
        )

    @property
    def has_geometry(self) -> bool:
        return bool(self.link_geometries) and bool(self.obstacle_geometries)

    @property
    def pinocchio(self) -> PinocchioDynamics | None:
        """The Pinocchio model when the terms come from Pinocchio, else None."""
        return self._pinocchio

    def create_scratch(self) -> ModelScratch:
        """Per-context scratch memory for :meth:`terms`, the controller's stages and the
        geometry queries: a context of the model's diagram (or of the plant alone) and,
        with Pinocchio, a Pinocchio ``Data`` with its arrays viewed in place."""
        context = (self.diagram or self.plant).CreateDefaultContext()
        return ModelScratch(context, self._pinocchio.create_data() if self._pinocchio else None)

    def plant_context(self, scratch: ModelScratch):
        return self.plant.GetMyMutableContextFromRoot(scratch.context) if self.diagram else scratch.context

    def query_object(self, scratch: ModelScratch):
        """The scene graph's QueryObject at the positions set in :meth:`plant_context`."""
        scene_graph = self.scene_graph
        return scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(scratch.context))

    def terms(
        self, scratch, q: np.ndarray, v: np.ndarray, coriolis: bool, max_task_inertia: float = math.inf
    ) -> RobotTerms:
        """:class:`nsdrake.control.dynamics.RobotTerms` at (q, q̇), from the chosen library."""
        if self._pinocchio is not None:
            return self._pinocchio.terms(q, v, coriolis, max_task_inertia)
        return self.arm.terms(self.plant_context(scratch), q, v, coriolis, max_task_inertia)


class ModelScratch:
    """What :meth:`ControllerModel.create_scratch` returns: ``context``, a context of the
    model's diagram (or plant), and ``pinocchio``, a :class:`PinocchioScratch` or None."""

    def __init__(self, context, pinocchio: PinocchioScratch | None):
        self.context = context
        self.pinocchio = pinocchio


def _moving_bodies(plant: MultibodyPlant) -> list:
    """Bodies that some joint moves (the arm's links and tool)."""
    joints = [plant.get_joint(j) for j in plant.GetJointIndices() if plant.get_joint(j).num_velocities()]
    return list(plant.GetBodiesKinematicallyAffectedBy([j.index() for j in joints])) if joints else []


def _cut(e, length: int = 240) -> str:
    text = one_line(e)
    return text if len(text) <= length else text[: length - 1] + "…"


def _check_arguments(plant, tool_frame, task_axes, dynamics: str) -> None:
    if dynamics not in DYNAMICS:
        raise ControllerConfigError("dynamics", f"must be one of {', '.join(DYNAMICS)}, got {show(dynamics)}")
    if not isinstance(plant, MultibodyPlant) or not plant.is_finalized():
        raise ControllerConfigError(
            "controller_model", "the controller model's plant must be a finalized MultibodyPlant"
        )
    if not isinstance(tool_frame, str) or not plant.HasFrameNamed(tool_frame):
        raise ControllerConfigError(
            "tool_frame", f"the controller model has no frame named {show(tool_frame)}"
        )
    problem = task_axes_problem(task_axes)
    if problem:
        raise ControllerConfigError(f"task_axes{problem[0]}", problem[1])


def _urdf_text(urdf) -> tuple[str, str]:
    """(the URDF's text, the name its errors go by), the text checked by the URDF rules."""
    where = "controller_model"
    if isinstance(urdf, str) and ("<" in urdf or "\n" in urdf):
        text = urdf
    else:
        path = Path(urdf)
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError, ValueError) as e:
            why = getattr(e, "strerror", None) or one_line(e)
            raise ControllerConfigError(
                where, f"{show(str(urdf))} is neither a readable URDF file ({why}) nor URDF text (no '<')"
            ) from None
        where = f"controller_model: {path.name}"
    try:
        root = parse_urdf(text)
    except ValueError as e:
        raise ControllerConfigError(
            where, f"the URDF is {e}" if str(e).startswith("not XML") else str(e)
        ) from None
    for link, problem in urdf_problems(root):
        raise ControllerConfigError(f"{where}: {link}", problem)
    return text, where


def damping_note(arm: ArmModel) -> str:
    """The line that says an unstated ``damping_time`` is taken as 0 on a damped model."""
    damped = [f"{name} {d:g}" for name, d in zip(arm.joint_names, arm.damping, strict=True) if d]
    return (
        f"controller model: the joints' damping D [N m s/rad] ({', '.join(damped)}) is compensated as "
        "D q̇ only: damping_time not stated, its inertia damping_time · D over a held command taken as 0 "
        "(state it: the plant's step h for Drake's discrete plant stepping once per period T, (T + h)/2 "
        "with several steps, T/2 on a real arm)"
    )


def check_obstacles(obstacles: Sequence[Obstacle]) -> None:
    """Each obstacle: a named Drake shape at a finite pose, its size and distance within
    LARGEST_LENGTH (farther or larger is no robot cell, and overflows the criterion)."""
    names = set()
    for i, ob in enumerate(obstacles):
        where = f"obstacles[{i}]"
        if not isinstance(ob, Obstacle) or not isinstance(ob.shape, Shape):
            raise ControllerConfigError(where, f"must be an Obstacle(name, shape, X_WO), got {show(ob)}")
        if not isinstance(ob.name, str) or not ob.name or ob.name in names:
            raise ControllerConfigError(
                f"{where}.name", f"must be a distinct non-empty name, got {show(ob.name)}"
            )
        names.add(ob.name)
        if not isinstance(ob.X_WO, RigidTransform):
            raise ControllerConfigError(f"{where}.X_WO", f"must be a RigidTransform, got {show(ob.X_WO)}")
        problem = length_problem(ob.X_WO.translation(), "its position")
        sizes = [getattr(ob.shape, f)() for f in _SHAPE_SIZES.get(type(ob.shape).__name__, ())]
        problem = problem or length_problem(np.asarray(sizes), "its size")
        if problem:
            raise ControllerConfigError(where, problem)


_SHAPE_SIZES = {
    "Box": ("width", "depth", "height"),
    "Sphere": ("radius",),
    "Cylinder": ("radius", "length"),
    "Capsule": ("radius", "length"),
    "Ellipsoid": ("a", "b", "c"),
}


def _pinocchio_dynamics(fast_terms: bool, arm: ArmModel, dynamics: str):
    """Pinocchio's terms, built from the model's plant (:mod:`nsdrake.control.pinocchio_tree`)
    and checked against Drake's, when asked for (or, for "auto", when the model came from a
    file or URDF text and Pinocchio is installed and can represent the arm); else None."""
    if dynamics == "pinocchio" and not fast_terms:
        raise ControllerConfigError(
            "dynamics",
            "Pinocchio dynamics need the model's file: build it with ControllerModel.from_file or from_urdf",
        )
    if dynamics == "drake" or not fast_terms or (dynamics == "auto" and not _has_pinocchio()):
        return None
    try:
        model = pinocchio_model(arm.plant, frames=[arm.tool_frame])
        pinocchio = PinocchioDynamics(model, arm, arm.plant.gravity_field().gravity_vector())
    except ControllerConfigError:
        raise
    except ValueError as e:  # a joint Pinocchio's model here does not take
        if dynamics == "auto":
            return None  # the same terms from Drake
        raise ControllerConfigError(
            "controller_model", f"Pinocchio cannot model the arm: {_cut(e)}"
        ) from None
    check_agreement(pinocchio, arm)
    return pinocchio


def _has_pinocchio() -> bool:
    try:
        import pinocchio  # noqa: F401
    except ImportError:
        return False
    return True


def pinocchio_urdf(text: str) -> str:
    """The URDF as Pinocchio's parser reads it: geometry and Drake extensions dropped
    (Pinocchio needs only kinematics and inertia, and rejects Drake's capsules), the
    ``world`` link declared, and continuous joints as revolute ones (Pinocchio would
    give them two position coordinates, cos and sin)."""
    root = ET.fromstring(text)
    for parent in root.iter():
        for child in list(parent):
            if child.tag in ("collision", "visual", "transmission") or str(child.tag).startswith("{"):
                parent.remove(child)
    for joint in root.findall("joint"):
        if joint.get("type") == "continuous":
            joint.set("type", "revolute")
            limit = joint.find("limit")
            if limit is None:
                limit = ET.SubElement(joint, "limit", effort="0", velocity="0")
            limit.set("lower", "-1e300")
            limit.set("upper", "1e300")
    links = {link.get("name") for link in root.findall("link")}
    for joint in root.findall("joint"):
        parent = joint.find("parent").get("link")
        if parent not in links:
            ET.SubElement(root, "link", name=parent)
            links.add(parent)
    return ET.tostring(root, encoding="unicode")


class PinocchioScratch:
    """A Pinocchio ``Data`` and its arrays, viewed in place once (they keep their memory
    for the Data's life): after :meth:`PinocchioDynamics.update`, ``M`` (upper triangle
    at least), ``nle``, ``g``, ``C`` (if asked for), ``J`` the world joint Jacobians
    [v_O; ω] (6, nv), ``X`` the joint poses (nj, 3, 4) [R | p], and the tool's pose
    ``R_tool``, ``p_tool`` hold the state's values, in Pinocchio's joint order."""

    def __init__(self, model, data, tool: int):
        self.data = data
        self.M, self.nle, self.g, self.C, self.J = data.M, data.nle, data.g, data.C, data.J
        self.R_tool, self.p_tool = data.oMf[tool].rotation, data.oMf[tool].translation
        self.X = _stacked_placements(data.oMi)


SE3_STRIDES = (96, 8, 24)  # [R (3 × 3, column-major) | p (3)] per SE3: element (i, j) at 8 (i + 3 j)


def _stacked_placements(placements):
    """The placements of a Pinocchio ``StdVec_SE3`` as one (k, 3, 4) array [R | p]: a view
    of the vector's own memory where its elements lie as Pinocchio lays out SE3 (checked
    here element by element), else None (:meth:`PinocchioDynamics.joint_poses` copies)."""
    first = placements[0].rotation
    base = first.__array_interface__["data"][0]
    for i in range(len(placements)):
        R, p = placements[i].rotation, placements[i].translation
        if (
            R.__array_interface__["data"][0] != base + i * SE3_STRIDES[0]
            or p.__array_interface__["data"][0] != base + i * SE3_STRIDES[0] + 9 * 8
            or R.strides != (8, 24)
        ):
            return None
    return np.lib.stride_tricks.as_strided(
        first, shape=(len(placements), 3, 4), strides=SE3_STRIDES, writeable=False
    )


class PinocchioDynamics:
    """Model terms from Pinocchio, in the joint order of the Drake ``arm``."""

    def __init__(self, source, arm: ArmModel, gravity: np.ndarray):
        """``source``: a ``pinocchio.Model`` of the arm, or the arm's URDF text."""
        import pinocchio as pin

        self._pin = pin
        self._model = pin.buildModelFromXML(pinocchio_urdf(source)) if isinstance(source, str) else source
        self._model.gravity.linear = np.asarray(gravity, dtype=float)
        self._data = self._model.createData()
        name = arm.tool_frame.name()
        # The tool's frame: a body's frame, else an added one (a joint may share its name).
        kinds = [k for k in (pin.BODY, pin.OP_FRAME) if self._model.existFrame(name, k)]
        if not kinds:
            raise ModelMismatchError(
                "controller_model", f"Pinocchio's model of the arm has no frame '{name}'"
            )
        self._tool = self._model.getFrameId(name, kinds[0])
        if self._model.nq != arm.n or self._model.nv != arm.n:
            raise ModelMismatchError(
                "controller_model",
                f"Pinocchio's model has nq={self._model.nq}, nv={self._model.nv}; Drake's has {arm.n} joints",
            )
        # Drake's velocity order → Pinocchio's.
        order = [self._model.joints[self._model.getJointId(j)].idx_v for j in arm.joint_names]
        self._order = None if order == list(range(arm.n)) else np.array(order)
        self._rows = arm.rows
        self._spatial_rows = arm.spatial_rows
        self._rotation = arm.m_r > 0
        self._drake_rows = np.array([3, 4, 5, 0, 1, 2])
        self._partials = arm._partials
        # The joints' damping D in Pinocchio's order, added to nle (ArmModel's C q̇ has it too),
        # and the inertia T_D D it adds over a held command as Pinocchio's armature, which its
        # mass matrix (computeAllTerms) carries on the diagonal as ArmModel's H does.
        self._damping = self._to_pin(arm.damping) if np.any(arm.damping) else None
        self._model.armature = self._model.armature + self._to_pin(arm.damping_inertia)

    @property
    def order(self) -> np.ndarray:
        """order[j]: Pinocchio's velocity index of the model's joint j."""
        return np.arange(self._model.nv) if self._order is None else self._order

    @property
    def num_joint_poses(self) -> int:
        return self._model.njoints

    def tool_support(self) -> np.ndarray:
        """(n,) 1 where the model's joint j moves the tool frame, else 0."""
        return self._support(self._model.frames[self._tool].parentJoint)

    def _support(self, joint: int) -> np.ndarray:
        moving = {self._model.joints[j].idx_v for j in self._model.supports[joint] if j > 0}
        return np.array([1 if k in moving else 0 for k in self.order], dtype=np.int64)

    def body_in_joint(self, body: str) -> tuple[int, np.ndarray, np.ndarray]:
        """(joint, X_JB, support) of the URDF link ``body``: the Pinocchio joint that carries
        it, its pose in that joint's frame as [R | p] (3, 4), and :meth:`tool_support`'s mask
        for it."""
        frame = self._model.frames[self._model.getFrameId(body, self._pin.BODY)]
        X, joint = frame.placement, frame.parentJoint
        return joint, np.hstack([X.rotation, X.translation[:, None]]), self._support(joint)

    def create_data(self) -> PinocchioScratch:
        return PinocchioScratch(self._model, self._model.createData(), self._tool)

    def update(self, scratch: PinocchioScratch, q: np.ndarray, v: np.ndarray, coriolis: bool) -> None:
        """Pinocchio's passes at (q, q̇) (the model's joint order) into ``scratch``'s arrays."""
        pin, model, data = self._pin, self._model, scratch.data
        if self._order is not None:
            q, v = self._to_pin(q), self._to_pin(v)
        pin.computeAllTerms(model, data, q, v)  # M, nle, g, joint Jacobians, joint poses
        if self._damping is not None:
            scratch.nle += self._damping * v  # in place: the stages read nle there
        if coriolis:
            pin.computeCoriolisMatrix(model, data, q, v)
        pin.updateFramePlacement(model, data, self._tool)

    def joint_poses(self, scratch: PinocchioScratch) -> np.ndarray:
        """The joint poses (nj, 3, 4) after :meth:`update`: the in-place view, or a copy."""
        if scratch.X is not None:
            return scratch.X
        oMi = scratch.data.oMi
        return np.array([np.hstack([X.rotation, X.translation[:, None]]) for X in oMi])

    def _to_pin(self, x: np.ndarray) -> np.ndarray:
        if self._order is None:
            return x
        out = np.empty_like(x)
        out[self._order] = x
        return out

    def terms(
        self, q: np.ndarray, v: np.ndarray, coriolis: bool, max_task_inertia: float = math.inf
    ) -> RobotTerms:
        pin, model, data = self._pin, self._model, self._data
        qp, vp = self._to_pin(q), self._to_pin(v)
        pin.computeAllTerms(model, data, qp, vp)  # M (upper triangle), nle, g, joint Jacobians
        J6 = pin.getFrameJacobian(model, data, self._tool, pin.LOCAL_WORLD_ALIGNED)
        X_WT = pin.updateFramePlacement(model, data, self._tool)
        p_WT = X_WT.translation.copy()
        R_WT = X_WT.rotation.copy() if self._rotation else None
        H, H_inv = symmetric_and_inverse(data.M)
        nle, g = data.nle.copy(), data.g.copy()
        if self._damping is not None:
            nle += self._damping * vp
        C = pin.computeCoriolisMatrix(model, data, qp, vp).copy() if coriolis else None
        J_spatial = J6[self._drake_rows]  # Drake's order: [angular; translational]
        if self._order is not None:
            o = self._order
            H, H_inv, nle, g, J_spatial = H[np.ix_(o, o)], H_inv[np.ix_(o, o)], nle[o], g[o], J_spatial[:, o]
            C = C[np.ix_(o, o)] if C is not None else None
        J_w, J_v = J_spatial[:3], J_spatial[3:]
        return RobotTerms(
            q=q.copy(),
            v=v.copy(),
            H=H,
            H_inv=H_inv,
            Cv=nle - g,
            g=g,
            x=p_WT[self._rows],
            p_WT=p_WT,
            J=J_spatial[self._spatial_rows],
            J_spatial=J_spatial,
            dJ_dq=self._partials(J_w, J_v),
            C=C,
            R_WT=R_WT,
            max_task_inertia=max_task_inertia,
        )


@njit(cache=True)
def symmetric_and_inverse(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, H⁻¹) from Pinocchio's mass matrix, which fills only its upper triangle."""
    H = M.copy()
    for i in range(H.shape[0]):
        for j in range(i):
            H[i, j] = H[j, i]
    return H, np.linalg.inv(H)


AGREEMENT_TOLERANCE = 1e-9  # relative, per term


def check_agreement(pinocchio: PinocchioDynamics, arm: ArmModel, states: int = 3, seed: int = 0) -> None:
    """Raises ModelMismatchError unless Pinocchio's and Drake's H, g, C q̇, C and J agree
    at ``states`` seeded random states, to AGREEMENT_TOLERANCE relative to the term's size.
    (C q̇ is the difference of two terms that hold g, so its rounding grows with |g| too.)"""
    rng = np.random.default_rng(seed)
    context = arm.plant.CreateDefaultContext()
    for _ in range(states):
        q, v = rng.uniform(-np.pi, np.pi, arm.n), rng.uniform(-1.0, 1.0, arm.n)
        a, b = pinocchio.terms(q, v, True), arm.terms(context, q, v, True)
        gravity = float(np.max(np.abs(b.g)))
        for name in ("H", "g", "Cv", "C", "J_spatial"):
            x, y = getattr(a, name), getattr(b, name)
            scale = max(float(np.max(np.abs(y))), gravity if name == "Cv" else 0.0, 1.0)
            error = float(np.max(np.abs(x - y)))
            if not error <= AGREEMENT_TOLERANCE * scale:
                raise ModelMismatchError(
                    "controller_model",
                    f"the controller model's {name} from Pinocchio differs from Drake's by {error:.3g} "
                    f"at q = {np.round(q, 3).tolist()}: the two libraries model the arm differently",
                )

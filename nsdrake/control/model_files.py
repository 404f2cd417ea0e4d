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

import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RotationalInertia, SpatialInertia

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


def parse_model_file(plant: MultibodyPlant, path, packages=None, where: str = "model_file") -> list:
    """Drake parses the model file ``path`` into ``plant`` (module docstring); returns its
    model instances. Every problem is a one-line ControllerConfigError naming ``where``."""
    problem = model_file_problem(path)
    if problem:
        raise ControllerConfigError(where, problem)
    problem = packages_problem({} if packages is None else packages)
    if problem:
        raise ControllerConfigError("packages", problem)
    path = Path(path)
    problem = sdf_file_problem(path)
    if problem:
        raise ControllerConfigError(f"{where}: {path.name}: {problem[0]}".rstrip(": "), problem[1])
    try:
        parser = model_parser(plant, path, packages or {})
        return parser.AddModels(str(path))
    except (RuntimeError, ValueError) as e:
        text = one_line(e)
        hint = (
            " (give the package as packages={name: folder}, in a package.xml above the file, "
            "or in ROS_PACKAGE_PATH)"
            if "unknown package" in text
            else ""
        )
        text = text if len(text) <= 240 else text[:239] + "…"
        raise ControllerConfigError(f"{where}: {path.name}", f"Drake cannot parse it: {text}{hint}") from None

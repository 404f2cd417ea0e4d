"""Physical validity of a model file, before Drake reads it.

A URDF that Drake would accept but that is physically invalid is refused with the
file and the element named: a non-positive mass, an inertia that is not positive
definite or breaks the triangle inequality, a geometry with a non-positive size, a
kinematic loop. (Drake warns and "repairs" an impossible inertia, or fails with a raw
parser line.) The rules themselves are :mod:`nsdrake.control.urdf_checks`, which the
controller's own model obeys too.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from nsdrake.control.urdf_checks import urdf_problems
from nsdrake.station.config import StationError


def check_model_file(path: Path) -> None:
    """Physical validity of every link of a URDF file, and a tree of joints (module docstring)."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as e:
        raise StationError(f"{path}: not a readable URDF: {' '.join(str(e).split())}") from None
    for where, problem in urdf_problems(root):
        raise StationError(f"{path.name}: {where}: {problem}")

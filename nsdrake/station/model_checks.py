"""Physical validity of a model file, before Drake reads it.

A URDF that Drake would accept but that is physically invalid is refused with the
file and the element named: a non-positive mass, an inertia that is not positive
definite or breaks the triangle inequality, a geometry with a non-positive size.
(Drake warns and "repairs" an impossible inertia, or fails with a raw parser line.)
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from nsdrake.station.config import StationError

GEOMETRY_SIZES = {
    "box": ("size",),
    "sphere": ("radius",),
    "cylinder": ("radius", "length"),
    "capsule": ("radius", "length"),
}


def _fail(where: str, problem: str):
    raise StationError(f"{where}: {problem}")


def check_model_file(path: Path) -> None:
    """Physical validity of every link of a URDF file (module docstring)."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as e:
        _fail(str(path), f"not a readable URDF: {' '.join(str(e).split())}")
    for link in root.iter("link"):
        where = f"{path.name}: link '{link.get('name')}'"
        inertial = link.find("inertial")
        if inertial is not None:
            _check_inertial(inertial, where)
        for element in (*link.findall("collision"), *link.findall("visual")):
            geometry = element.find("geometry")
            for shape in () if geometry is None else list(geometry):
                for attribute in GEOMETRY_SIZES.get(shape.tag, ()):
                    for value in _numbers(shape.get(attribute, "1"), where):
                        if not value > 0:
                            _fail(where, f"{element.tag} {shape.tag} {attribute} {value:g} must be > 0")


def _numbers(text: str, where: str) -> list[float]:
    try:
        return [float(x) for x in text.split()]
    except ValueError:
        _fail(where, f"'{text[:40]}' is not a number")


def _check_inertial(inertial, where: str) -> None:
    mass = inertial.find("mass")
    if mass is not None:
        (m,) = _numbers(mass.get("value", "0"), where)
        if not m > 0 or not math.isfinite(m):
            _fail(where, f"mass {m:g} kg must be > 0")
    inertia = inertial.find("inertia")
    if inertia is None:
        return
    get = {k: _numbers(inertia.get(k, "0"), where)[0] for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")}
    I = np.array(
        [
            [get["ixx"], get["ixy"], get["ixz"]],
            [get["ixy"], get["iyy"], get["iyz"]],
            [get["ixz"], get["iyz"], get["izz"]],
        ]
    )
    moments = np.linalg.eigvalsh(I)
    if not np.all(np.isfinite(I)) or moments[0] <= 0:
        _fail(
            where,
            f"inertia must be positive definite, its principal moments are {np.round(moments, 9).tolist()}",
        )
    if moments[0] + moments[1] < moments[2] * (1 - 1e-9):
        _fail(
            where,
            f"inertia breaks the triangle inequality: principal moments {np.round(moments, 9).tolist()}",
        )

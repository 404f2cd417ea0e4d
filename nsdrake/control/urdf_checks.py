"""What a URDF (or an SDF's links) must be before Drake or Pinocchio reads it: the one home of these rules,
for the controller's model (:meth:`nsdrake.ControllerModel.from_urdf`) and the simulated
station's model files (:mod:`nsdrake.station.model_checks`).

Physically valid links: a mass > 0, an inertia that is positive definite and meets the
triangle inequality, geometry sizes > 0. A link that cannot move on its own -- the root
(welded to the world, by the file or by nsdrake), or a frame link on a fixed joint (ROS's
``tool0``, ``panda_link8``) -- merges into its parent or the world, so it may have no mass
and a degenerate inertia (mass ≥ 0, principal moments ≥ −MERGED_INERTIA_ROUNDING, no
triangle inequality); a negative mass, or a clearly negative moment, is refused wherever
it is. (Drake would simulate a negative mass, warn and
"repair" an impossible inertia, fail on a bad size with a raw parser line; Pinocchio and
Drake disagree on a massless link, which a model check would then blame on the
libraries). A tree of joints: every joint names a parent and a child link, no link is
the child of two joints and no chain of joints returns to where it started (a kinematic
loop, which Drake refuses when the plant is finalized with a long line and Pinocchio
cannot represent).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterator

import numpy as np

GEOMETRY_SIZES = {
    "box": ("size",),
    "sphere": ("radius",),
    "cylinder": ("radius", "length"),
    "capsule": ("radius", "length"),
}


class _NotANumberError(ValueError):
    pass


def _numbers(text: str) -> list[float]:
    try:
        return [float(x) for x in text.split()]
    except ValueError:
        raise _NotANumberError(f"'{text[:40]}' is not a number") from None


def parse_urdf(text: str) -> ET.Element:
    """The URDF text's root element; ValueError (one line) if it is not XML or not a <robot>."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise ValueError(f"not XML: {e}") from None
    if root.tag != "robot":
        raise ValueError(f"not a URDF: the root element is <{str(root.tag)[:40]}>, not <robot>")
    return root


def urdf_problems(root: ET.Element) -> Iterator[tuple[str, str]]:
    """(where, problem) for every link that is physically invalid and every joint that
    breaks the tree (module docstring); ``where`` names the link or joint."""
    fixed = _links_that_cannot_move(
        root.findall("joint"), [link.get("name") for link in root.iter("link")], "urdf"
    )
    for link in root.iter("link"):
        where = f"link '{link.get('name')}'"
        try:
            problem = _link_problem(link, link.get("name") in fixed)
        except _NotANumberError as e:
            problem = str(e)
        if problem:
            yield where, problem
    yield from _tree_problems(root)


def _links_that_cannot_move(joints, links, kind: str) -> set:
    """Links that are the child of a fixed joint, or of no joint (the roots)."""
    children, fixed = set(), set()
    for joint in joints:
        child = joint.find("child")
        name = (child.get("link") if kind == "urdf" else child.text) if child is not None else None
        name = (name or "").strip()
        children.add(name)
        if joint.get("type") == "fixed":
            fixed.add(name)
    return fixed | {link for link in links if link not in children}


def _link_problem(link, cannot_move: bool = False) -> str | None:
    inertial = link.find("inertial")
    if inertial is not None:
        problem = _inertial_problem(inertial, cannot_move)
        if problem:
            return problem
    for element in (*link.findall("collision"), *link.findall("visual")):
        geometry = element.find("geometry")
        for shape in () if geometry is None else list(geometry):
            for attribute in GEOMETRY_SIZES.get(shape.tag, ()):
                for value in _numbers(shape.get(attribute, "1")):
                    if not value > 0 or not math.isfinite(value):
                        return f"{element.tag} {shape.tag} {attribute} {value:g} must be > 0"
    return None


def _inertial_problem(inertial, cannot_move: bool = False) -> str | None:
    mass = inertial.find("mass")
    inertia = inertial.find("inertia")
    get = None
    if inertia is not None:
        get = {k: _numbers(inertia.get(k, "0") or "0")[0] for k in INERTIA_ENTRIES}
    return _mass_and_inertia_problem(None if mass is None else mass.get("value", "0"), get, cannot_move)


# A link that cannot move adds its inertia into its parent's (or the world's): a principal
# moment down to −1e-6 kg m² (a 10 g body a centimetre across) is a vendor's rounding
# (TIAGo's antennas: −3.5e-8), not a body; a triangle inequality broken there breaks nothing.
MERGED_INERTIA_ROUNDING = 1e-6  # [kg m²]

INERTIA_ENTRIES = ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")


_SDF_DEFAULTS = {"ixx": "1", "iyy": "1", "izz": "1", "ixy": "0", "ixz": "0", "iyz": "0"}  # SDFormat's


def sdf_problems(root: ET.Element) -> Iterator[tuple[str, str]]:
    """(where, problem) for every SDF <link> whose <inertial> has a mass ≤ 0 or an impossible
    inertia (Drake's SDF parser only warns, and simulates a "repaired" 1 kg body instead)."""
    links = list(root.iter("link"))
    fixed = _links_that_cannot_move(list(root.iter("joint")), [link.get("name") for link in links], "sdf")
    for link in links:
        inertial = link.find("inertial")
        if inertial is None:
            continue
        mass, inertia = inertial.find("mass"), inertial.find("inertia")
        get = None
        try:
            if inertia is not None:
                get = {k: _numbers(_text(inertia.find(k)) or _SDF_DEFAULTS[k])[0] for k in INERTIA_ENTRIES}
            problem = _mass_and_inertia_problem(
                None if mass is None else _text(mass), get, link.get("name") in fixed
            )
        except _NotANumberError as e:
            problem = str(e)
        if problem:
            yield f"link '{link.get('name')}'", problem


def _text(element) -> str:
    return "" if element is None or element.text is None else element.text.strip()


def _mass_and_inertia_problem(
    mass_text: str | None, get: dict | None, cannot_move: bool = False
) -> str | None:
    """A mass (its text; None: not given) that is not one number > 0, or an inertia
    ({ixx: …}; None: not given) that is not positive definite or breaks the triangle
    inequality; for a link that ``cannot_move`` (module docstring), mass 0 and a positive
    semi-definite inertia are allowed."""
    if mass_text is not None:
        values = _numbers(mass_text or "0")
        if len(values) != 1:
            return f"mass '{mass_text}' must be one number"
        if not math.isfinite(values[0]) or values[0] < 0 or (values[0] == 0 and not cannot_move):
            return f"mass {values[0]:g} kg must be > 0"
    if get is None:
        return None
    I = np.array(
        [
            [get["ixx"], get["ixy"], get["ixz"]],
            [get["ixy"], get["iyy"], get["iyz"]],
            [get["ixz"], get["iyz"], get["izz"]],
        ]
    )
    if not np.all(np.isfinite(I)):
        return f"inertia must be finite, got {I[np.triu_indices(3)].tolist()}"
    moments = np.linalg.eigvalsh(I)
    if cannot_move:  # it merges into its parent: only a clearly negative moment is impossible
        if moments[0] < -MERGED_INERTIA_ROUNDING:
            return f"inertia has a negative principal moment: {np.round(moments, 9).tolist()}"
        return None
    if moments[0] <= 0:
        return f"inertia must be positive definite, its principal moments are {np.round(moments, 9).tolist()}"
    if moments[0] + moments[1] < moments[2] * (1 - 1e-9):
        return f"inertia breaks the triangle inequality: principal moments {np.round(moments, 9).tolist()}"
    return None


def _tree_problems(root: ET.Element) -> Iterator[tuple[str, str]]:
    parent_of: dict[str, tuple[str, str]] = {}  # child link -> (joint, parent link)
    for joint in root.findall("joint"):
        name = joint.get("name")
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None or not parent.get("link") or not child.get("link"):
            yield f"joint '{name}'", "needs a <parent link=…/> and a <child link=…/>"
            return
        child_link = child.get("link")
        if child_link in parent_of:
            other = parent_of[child_link][0]
            yield (
                f"link '{child_link}'",
                f"child of two joints ('{other}' and '{name}'): a kinematic loop; nsdrake's arms are "
                "trees of joints",
            )
            return
        parent_of[child_link] = (name, parent.get("link"))
    for start in parent_of:
        seen, link = [start], parent_of[start][1]
        while link in parent_of:
            if link in seen:
                yield f"link '{link}'", "its own ancestor: the joints form a kinematic loop"
                return
            seen.append(link)
            link = parent_of[link][1]

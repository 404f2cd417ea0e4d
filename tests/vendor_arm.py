"""A 7-joint arm as a vendor would ship it, written by the tests themselves.

``write_vendor_arm(root)`` writes a ROS-style package ``myarm`` under ``root``::

    myarm/package.xml
    myarm/meshes/upper.obj       a box (link 3's collision and visual mesh)
    myarm/meshes/fin.obj         a U (non-convex: Drake uses its convex hull) on link 5
    myarm/urdf/arm7.urdf         meshes as package://myarm/meshes/upper.obj and ../meshes/fin.obj
    myarm/urdf/arm7_free.urdf    the same, not welded to the world (for the directives)
    myarm/sdf/arm7.sdf           the same arm in SDFormat 1.9, the same mesh URIs
    myarm/arm7.dmd.yaml          Drake model directives: arm7_free.urdf welded to the world

and ``mesh_free_urdf()`` is the same arm's URDF text without any geometry: the reference the
model files must reproduce. Axes: aligned ones (z, y), one reversed (−z) and one oblique,
so that every kind of Pinocchio joint the model builder makes is exercised.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# (name, parent-joint origin xyz, rpy, axis, mass, com, (ixx, iyy, izz)) per joint/link
JOINTS = [
    ("j1", (0.0, 0.0, 0.20), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 3.0, (0.0, 0.01, 0.08), (0.020, 0.020, 0.010)),
    (
        "j2",
        (0.0, 0.0, 0.15),
        (0.0, 0.0, 0.0),
        (0.0, 1.0, 0.0),
        2.5,
        (0.0, -0.01, 0.15),
        (0.030, 0.030, 0.008),
    ),
    ("j3", (0.0, 0.0, 0.30), (0.0, 0.0, 0.3), (0.0, 0.0, 1.0), 2.0, (0.01, 0.0, 0.12), (0.020, 0.020, 0.006)),
    (
        "j4",
        (0.04, 0.0, 0.25),
        (0.0, 0.0, 0.0),
        (0.0, 0.6, 0.8),
        1.8,
        (0.0, 0.02, 0.10),
        (0.015, 0.015, 0.005),
    ),
    ("j5", (0.0, 0.0, 0.22), (0.2, 0.0, 0.0), (0.0, 0.0, -1.0), 1.2, (0.0, 0.0, 0.08), (0.008, 0.008, 0.003)),
    ("j6", (0.0, 0.0, 0.18), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 1.0, (0.01, 0.0, 0.05), (0.004, 0.004, 0.002)),
    ("j7", (0.0, 0.0, 0.10), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.6, (0.0, 0.0, 0.03), (0.001, 0.001, 0.0008)),
]
TOOL = ("tool", np.array([0.0, 0.0, 0.08]), 0.2, (0.0, 0.0, 0.02), (2e-4, 2e-4, 1e-4))
LINKS = [f"link{i}" for i in range(1, 8)]
Q0 = np.array([0.1, 0.6, -0.2, 1.1, 0.3, 0.9, 0.2])  # a configuration away from singularities
UPPER_HALF = (0.04, 0.04, 0.15)  # link 3's box mesh, centred at (0, 0, 0.15) of link 3
# The U on link 5: three boxes (x from, x to, y from, y to, z from, z to) [m]; its mouth faces +x.
FIN_BOXES = [
    (0.05, 0.07, -0.06, 0.06, 0.02, 0.14),  # the bottom of the U
    (0.07, 0.20, 0.04, 0.06, 0.02, 0.14),  # its arms
    (0.07, 0.20, -0.06, -0.04, 0.02, 0.14),
]


@dataclass
class VendorArm:
    package: Path  # the package's folder (myarm/)
    urdf: Path
    urdf_free: Path
    sdf: Path
    directives: Path


def _box_obj(boxes) -> str:
    """OBJ text of axis-aligned boxes (each closed, outward faces)."""
    lines, offset = [], 0
    for x0, x1, y0, y1, z0, z1 in boxes:
        for x in (x0, x1):
            for y in (y0, y1):
                for z in (z0, z1):
                    lines.append(f"v {x} {y} {z}")
        faces = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
        lines += [f"f {' '.join(str(offset + i) for i in face)}" for face in faces]
        offset += 8
    return "\n".join(lines) + "\n"


def fin_vertices() -> np.ndarray:
    """The U's vertices in link 5's frame (k, 3) [m]."""
    return np.array(
        [
            (x, y, z)
            for x0, x1, y0, y1, z0, z1 in FIN_BOXES
            for x in (x0, x1)
            for y in (y0, y1)
            for z in (z0, z1)
        ]
    )


def _inertial(mass, com, moments, indent="    ") -> str:
    ixx, iyy, izz = moments
    return (
        f'{indent}<inertial><origin xyz="{_v(com)}"/><mass value="{mass}"/>'
        f'<inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial>\n'
    )


def _v(xs) -> str:
    return " ".join(repr(float(x)) for x in xs)


def _urdf(geometry: bool, welded: bool) -> str:
    out = ['<?xml version="1.0"?>\n<robot name="arm7">\n']
    out.append('  <link name="base">\n' + _inertial(4.0, (0, 0, 0.05), (0.02, 0.02, 0.02)) + "  </link>\n")
    if welded:
        out.append('  <link name="world"/>\n')
        out.append(
            '  <joint name="base_weld" type="fixed"><parent link="world"/><child link="base"/></joint>\n'
        )
    parent = "base"
    for k, (name, xyz, rpy, axis, mass, com, moments) in enumerate(JOINTS):
        link = LINKS[k]
        body = _inertial(mass, com, moments)
        if geometry and link == "link3":
            mesh = '<geometry><mesh filename="package://myarm/meshes/upper.obj"/></geometry>'
            body += f'    <visual>{mesh}</visual>\n    <collision name="upper">{mesh}</collision>\n'
        if geometry and link == "link5":
            mesh = '<geometry><mesh filename="../meshes/fin.obj"/></geometry>'
            body += f'    <visual>{mesh}</visual>\n    <collision name="fin">{mesh}</collision>\n'
        if geometry and link == "link6":
            body += (
                '    <collision name="wrist"><origin xyz="0 0 0.05"/>'
                '<geometry><capsule radius="0.03" length="0.06"/></geometry></collision>\n'
            )
        out.append(f'  <link name="{link}">\n{body}  </link>\n')
        out.append(
            f'  <joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{link}"/>'
            f'<origin xyz="{_v(xyz)}" rpy="{_v(rpy)}"/><axis xyz="{_v(axis)}"/>'
            '<limit lower="-3" upper="3" effort="200" velocity="3"/></joint>\n'
        )
        out.append(
            f'  <transmission name="{name}_tr"><type>transmission_interface/SimpleTransmission</type>'
            f'<joint name="{name}"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>'
            f'<actuator name="{name}_motor"><mechanicalReduction>1</mechanicalReduction></actuator>'
            "</transmission>\n"
        )
        parent = link
    name, xyz, mass, com, moments = TOOL
    out.append(f'  <link name="{name}">\n{_inertial(mass, com, moments)}  </link>\n')
    out.append(
        f'  <joint name="tool_joint" type="fixed"><parent link="link7"/><child link="tool"/>'
        f'<origin xyz="{_v(xyz)}"/></joint>\n'
    )
    return "".join(out) + "</robot>\n"


def mesh_free_urdf() -> str:
    """The arm's URDF text with no geometry at all (the reference)."""
    return _urdf(geometry=False, welded=True)


def _sdf_inertial(mass, com, moments) -> str:
    ixx, iyy, izz = moments
    return (
        f"<inertial><pose>{_v(com)} 0 0 0</pose><mass>{mass}</mass><inertia><ixx>{ixx}</ixx><ixy>0</ixy>"
        f"<ixz>0</ixz><iyy>{iyy}</iyy><iyz>0</iyz><izz>{izz}</izz></inertia></inertial>"
    )


def _sdf() -> str:
    """The same arm in SDFormat 1.9: each link placed at its joint (URDF's convention),
    written with relative_to; the joint axes expressed in the joint frames."""
    out = ['<?xml version="1.0"?>\n<sdf version="1.9">\n<model name="arm7">\n']
    out.append(f'<link name="base">{_sdf_inertial(4.0, (0, 0, 0.05), (0.02, 0.02, 0.02))}</link>\n')
    out.append('<joint name="base_weld" type="fixed"><parent>world</parent><child>base</child></joint>\n')
    parent = "base"
    for k, (name, xyz, rpy, axis, mass, com, moments) in enumerate(JOINTS):
        link = LINKS[k]
        geometry = ""
        if link == "link3":
            mesh = "<geometry><mesh><uri>package://myarm/meshes/upper.obj</uri></mesh></geometry>"
            geometry = f'<visual name="upper_v">{mesh}</visual><collision name="upper">{mesh}</collision>'
        if link == "link5":
            mesh = "<geometry><mesh><uri>../meshes/fin.obj</uri></mesh></geometry>"
            geometry = f'<visual name="fin_v">{mesh}</visual><collision name="fin">{mesh}</collision>'
        if link == "link6":
            geometry = (
                '<collision name="wrist"><pose>0 0 0.05 0 0 0</pose>'
                "<geometry><capsule><radius>0.03</radius><length>0.06</length></capsule></geometry></collision>"
            )
        out.append(
            f'<frame name="{name}_origin" attached_to="{parent}"><pose relative_to="{parent}">'
            f"{_v(xyz)} {_v(rpy)}</pose></frame>\n"
        )
        # Link 7's frame sits 1 cm up its joint's axis, the joint's frame 1 cm below the link
        # (SDF's joint pose, in the child): the same arm, with Drake's X_CM not the identity.
        shift = 0.01 if link == "link7" else 0.0
        com = (com[0], com[1], com[2] - shift)
        out.append(
            f'<link name="{link}"><pose relative_to="{name}_origin">0 0 {shift} 0 0 0</pose>'
            f"{_sdf_inertial(mass, com, moments)}{geometry}</link>\n"
        )
        out.append(
            f'<joint name="{name}" type="revolute"><pose>0 0 {-shift} 0 0 0</pose>'
            f"<parent>{parent}</parent><child>{link}</child>"
            f"<axis><xyz>{_v(axis)}</xyz><limit><lower>-3</lower><upper>3</upper><effort>200</effort>"
            "<velocity>3</velocity></limit></axis></joint>\n"
        )
        parent = link
    name, xyz, mass, com, moments = TOOL
    pose = f'<pose relative_to="link7">{_v(xyz - np.array([0, 0, 0.01]))} 0 0 0</pose>'
    out.append(f'<link name="tool">{pose}{_sdf_inertial(mass, com, moments)}</link>\n')
    out.append('<joint name="tool_joint" type="fixed"><parent>link7</parent><child>tool</child></joint>\n')
    return "".join(out) + "</model>\n</sdf>\n"


DIRECTIVES = """directives:
- add_model:
    name: arm7
    file: package://myarm/urdf/arm7_free.urdf
- add_weld:
    parent: world
    child: arm7::base
"""

PACKAGE_XML = """<?xml version="1.0"?>
<package format="2">
  <name>myarm</name>
  <version>0.1.0</version>
  <description>A 7-joint arm written by nsdrake's tests</description>
  <maintainer email="tests@example.com">tests</maintainer>
  <license>BSD-3-Clause</license>
</package>
"""


def write_vendor_arm(root: Path) -> VendorArm:
    """Writes the package (module docstring) under ``root``; returns its paths."""
    package = Path(root) / "myarm"
    for folder in ("meshes", "urdf", "sdf"):
        (package / folder).mkdir(parents=True, exist_ok=True)
    (package / "package.xml").write_text(PACKAGE_XML)
    hx, hy, hz = UPPER_HALF
    (package / "meshes" / "upper.obj").write_text(_box_obj([(-hx, hx, -hy, hy, 0.15 - hz, 0.15 + hz)]))
    (package / "meshes" / "fin.obj").write_text(_box_obj(FIN_BOXES))
    arm = VendorArm(
        package=package,
        urdf=package / "urdf" / "arm7.urdf",
        urdf_free=package / "urdf" / "arm7_free.urdf",
        sdf=package / "sdf" / "arm7.sdf",
        directives=package / "arm7.dmd.yaml",
    )
    arm.urdf.write_text(_urdf(geometry=True, welded=True))
    arm.urdf_free.write_text(_urdf(geometry=True, welded=False))
    arm.sdf.write_text(_sdf())
    arm.directives.write_text(DIRECTIVES)
    return arm


assert math.isclose(float(np.linalg.norm(JOINTS[3][3])), 1.0)  # the oblique axis is a unit vector

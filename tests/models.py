"""URDF text for test arms that are not the paper's: other sizes, spatial axes,
prismatic joints, actuators declared out of order; and the arguments of a circle on the
Panda's table that the reference tests share."""

from __future__ import annotations

import math

import numpy as np

# CircleOnSurface's arguments: a 0.1 m circle twice round on the table below the Panda's
# tool, 10 N pressed (the shape of panda_wipe's reference)
PANDA_CIRCLE = {
    "x0": np.array([0.5, 0.0, 0.15]),
    "tangent": np.array([1.0, 0.0, 0.0]),
    "normal": np.array([0.0, 0.0, -1.0]),
    "radius": 0.1,
    "laps": 2.0,
    "speed": 0.05,
    "start_angle": -math.pi / 2,
    "delay": 0.3,
    "approach_speed": 0.03,
    "blend_time": 0.5,
    "force": 10.0,
    "force_ramp_time": 0.3,
}


def serial_arm_urdf(
    axes: list[str],
    lengths: list[float],
    masses: list[float],
    *,
    kinds: list[str] | None = None,
    actuator_order: list[int] | None = None,
    name: str = "test_arm",
) -> str:
    """A serial arm: joint i ("joint{i+1}") turns (or slides) about ``axes[i]`` ("x", "y" or "z"),
    link i is a box of length ``lengths[i]`` along its local x with mass ``masses[i]``; a
    frame "tool" sits at the tip. Actuators are declared in ``actuator_order``."""
    n = len(axes)
    kinds = kinds or ["revolute"] * n
    actuator_order = actuator_order if actuator_order is not None else list(range(n))
    unit = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}
    parts = [
        f'<robot name="{name}">',
        '<link name="base"/>',
        '<joint name="base_weld" type="fixed"><parent link="world"/><child link="base"/></joint>',
    ]
    parent = "base"
    offset = 0.0
    for i in range(n):
        L, m = lengths[i], masses[i]
        ixx, iyy, izz = 0.1 * m * L * L / 12 + 1e-4, m * L * L / 12 + 2e-4, m * L * L / 12 + 3e-4
        parts.append(
            f'<link name="link{i + 1}"><inertial><origin xyz="{L / 2} 0.01 0"/><mass value="{m}"/>'
            f'<inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial></link>'
        )
        kind = "continuous" if kinds[i] == "revolute" else "prismatic"
        limit = '<limit lower="-1" upper="1" effort="0" velocity="0"/>' if kind == "prismatic" else ""
        parts.append(
            f'<joint name="joint{i + 1}" type="{kind}"><parent link="{parent}"/><child link="link{i + 1}"/>'
            f'<origin xyz="{offset} 0 0"/><axis xyz="{unit[axes[i]]}"/>{limit}</joint>'
        )
        parent, offset = f"link{i + 1}", L
    parts.append('<link name="tool"/>')
    parts.append(
        f'<joint name="tool_weld" type="fixed"><parent link="{parent}"/><child link="tool"/>'
        f'<origin xyz="{offset} 0 0"/></joint>'
    )
    for i in actuator_order:
        parts.append(
            f'<transmission type="SimpleTransmission" name="t{i + 1}"><actuator name="motor{i + 1}"/>'
            f'<joint name="joint{i + 1}"/><mechanicalReduction>1</mechanicalReduction></transmission>'
        )
    parts.append("</robot>")
    return "\n".join(parts)


# Arms used across the tests: (URDF text, task axes).
TEST_ARMS = {
    "planar3": (serial_arm_urdf(["z"] * 3, [0.3, 0.25, 0.2], [1.0, 0.7, 0.4]), ("x", "y")),
    "planar5": (serial_arm_urdf(["z"] * 5, [0.2] * 5, [0.5, 0.45, 0.4, 0.35, 0.3]), ("x", "y")),
    "spatial6": (
        serial_arm_urdf(
            ["z", "y", "y", "x", "y", "z"], [0.1, 0.3, 0.25, 0.1, 0.1, 0.05], [2.0, 1.5, 1.0, 0.5, 0.4, 0.2]
        ),
        ("x", "y", "z"),
    ),
    "with_prismatic": (
        serial_arm_urdf(
            ["z", "x", "z", "z"],
            [0.3, 0.2, 0.25, 0.2],
            [1.0, 0.8, 0.6, 0.4],
            kinds=["revolute", "prismatic", "revolute", "revolute"],
        ),
        ("x", "y"),
    ),
}


def random_states(n: int, count: int, seed: int, *, speed: float = 1.0):
    """``count`` seeded (q, v) pairs: q uniform in [−π, π), v normal with std ``speed``."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield rng.uniform(-np.pi, np.pi, n), speed * rng.standard_normal(n)

"""Belt elasticity: each joint driven by a motor through a gear and an elastic belt
(the realism ladder's ``belt`` rung).

Spong's flexible-joint model, built from the arm's own URDF: every actuated joint
``J`` between links P and C becomes

    P ──J_motor (actuated, revolute)──► J_rotor ──J (RevoluteSpring, damping)──► C

with the same origin and axis. θ_m = q(J_motor) is the motor angle seen through the
gear (q_m/N, what the motor encoder reads once divided by the gear ratio N), δ = q(J)
the belt's deflection, and the link angle is q = θ_m + δ. The belt is a torsional
spring–damper at the joint: it applies −k δ − d δ̇ to the link and the reaction to the
rotor. The motor's rotor inertia I_m enters as Drake's reflected inertia N² I_m on
θ_m (``JointActuator`` rotor inertia and gear ratio; the actuation is the torque at
the gear output, as the controller's τ). The rotor body itself is a 1 g point on
the joint axis, a placeholder that carries the spring.

Simplifications, said here once: the rotor sits on the previous link (Spong), while
the paper's motors sit in the base and their belts cross the proximal joints (which
couples the motor angles of a real belt-driven arm); the rotor's gyroscopic terms
are left out (as Drake's reflected inertia does).

:class:`ElasticMap` relates the plant's state [θ_m, δ; θ̇_m, δ̇] (in the plant's
order) to the arm's link state [q; q̇] and to the motor state [θ_m; θ̇_m], both in the
rigid arm's joint order.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JointActuatorIndex, RevoluteSpring

from nsdrake.control.model_files import model_parser

DRAKE_NS = "http://drake.mit.edu"
ROTOR_MASS = 1e-3  # [kg] the placeholder rotor body (its inertia is the reflected one, on θ_m)
ROTOR_INERTIA = 1e-8  # [kg m²] each principal moment of the placeholder


def motor_joint_name(joint: str) -> str:
    return f"{joint}_motor"


def rotor_link_name(joint: str) -> str:
    return f"{joint}_rotor"


def elastic_urdf(urdf_text: str) -> tuple[str, list[str]]:
    """The URDF with every transmission-driven revolute (or continuous) joint split
    into motor joint, rotor link and belt joint (module docstring); returns the text
    and the names of the split joints. The belt joint keeps the joint's name and
    has no limits; the motor joint takes the limits and the transmission."""
    ET.register_namespace("drake", DRAKE_NS)
    root = ET.fromstring(urdf_text)
    driven = {
        j.get("name") for t in root.iter("transmission") for j in t.iter("joint") if j.get("name") is not None
    }
    split = []
    for joint in list(root.findall("joint")):
        name = joint.get("name")
        if name not in driven or joint.get("type") not in ("revolute", "continuous"):
            continue
        split.append(name)
        child = joint.find("child")
        axis = joint.find("axis")
        rotor = rotor_link_name(name)
        joint.set("name", motor_joint_name(name))
        original_child = child.get("link")
        child.set("link", rotor)
        link = ET.SubElement(root, "link", {"name": rotor})
        inertial = ET.SubElement(link, "inertial")
        ET.SubElement(inertial, "mass", {"value": repr(ROTOR_MASS)})
        ET.SubElement(
            inertial,
            "inertia",
            {k: repr(ROTOR_INERTIA if k in ("ixx", "iyy", "izz") else 0.0) for k in _INERTIA_KEYS},
        )
        belt = ET.SubElement(root, "joint", {"name": name, "type": "continuous"})
        ET.SubElement(belt, "parent", {"link": rotor})
        ET.SubElement(belt, "child", {"link": original_child})
        ET.SubElement(belt, "origin", {"xyz": "0 0 0", "rpy": "0 0 0"})
        ET.SubElement(belt, "axis", {"xyz": axis.get("xyz") if axis is not None else "1 0 0"})
    for transmission in root.iter("transmission"):
        for j in transmission.iter("joint"):
            if j.get("name") in split:
                j.set("name", motor_joint_name(j.get("name")))
    return ET.tostring(root, encoding="unicode"), split


_INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")


def add_elastic_arm(plant: MultibodyPlant, parser: Parser, arm_file, belt) -> tuple:
    """Parses the arm of ``arm_file`` with its joints split (:func:`elastic_urdf`), adds
    each belt's spring and damping and each motor's reflected rotor inertia; returns
    the model instances (one). Before ``Finalize``."""
    text, split = elastic_urdf(open(arm_file).read())
    instances = parser.AddModelsFromString(text, "urdf")
    (arm,) = instances
    for name in split:
        joint = plant.GetJointByName(name, arm)
        plant.AddForceElement(RevoluteSpring(joint, 0.0, belt.stiffness))
        joint.set_default_damping(belt.damping)
        motor = plant.GetJointByName(motor_joint_name(name), arm)
        for k in range(plant.num_actuators()):  # (GetJointActuatorIndices is empty before Finalize)
            actuator = plant.get_joint_actuator(JointActuatorIndex(k))
            if actuator.joint().index() == motor.index():
                actuator.set_default_rotor_inertia(belt.rotor_inertia)
                actuator.set_default_gear_ratio(belt.gear_ratio)
    return instances


def rigid_arm_plant(arm_file, gravity, packages=None) -> MultibodyPlant:
    """The arm of ``arm_file`` alone, rigid, finalized: the kinematics and dynamics of the
    link coordinates (traces, metrics), never simulated. ``packages``: as the station's."""
    plant = MultibodyPlant(0.0)
    model_parser(plant, Path(arm_file), packages or {}).AddModels(str(arm_file))
    plant.mutable_gravity_field().set_gravity_vector(np.asarray(gravity, dtype=float))
    plant.Finalize()
    return plant


@dataclass
class ElasticMap:
    """Indices of each arm joint's motor and belt coordinates in the elastic plant,
    in the rigid arm's joint order, and the maps between the plant's state and the
    link and motor states."""

    nq: int  # the plant's positions
    nv: int  # the plant's velocities
    motor_q: np.ndarray  # (n,) position index of θ_m per arm joint
    motor_v: np.ndarray  # (n,) velocity index of θ̇_m
    belt_q: np.ndarray  # (n,) position index of δ
    belt_v: np.ndarray  # (n,) velocity index of δ̇
    actuation: np.ndarray  # (actuators, n): u = P τ, τ in the arm's joint order
    stiffness: float  # [N m/rad]

    @classmethod
    def build(cls, plant: MultibodyPlant, arm, joint_names, stiffness: float) -> ElasticMap:
        idx = {k: [] for k in ("mq", "mv", "bq", "bv")}
        for name in joint_names:
            motor = plant.GetJointByName(motor_joint_name(name), arm)
            belt = plant.GetJointByName(name, arm)
            idx["mq"].append(motor.position_start())
            idx["mv"].append(motor.velocity_start())
            idx["bq"].append(belt.position_start())
            idx["bv"].append(belt.velocity_start())
        actuation = np.zeros((plant.num_actuators(), len(joint_names)))
        for index in plant.GetJointActuatorIndices():
            actuator = plant.get_joint_actuator(index)
            joint = actuator.joint().name()
            for k, name in enumerate(joint_names):
                if joint == motor_joint_name(name):
                    actuation[actuator.input_start(), k] = 1.0
        return cls(
            nq=plant.num_positions(),
            nv=plant.num_velocities(),
            motor_q=np.array(idx["mq"]),
            motor_v=np.array(idx["mv"]),
            belt_q=np.array(idx["bq"]),
            belt_v=np.array(idx["bv"]),
            actuation=actuation,
            stiffness=stiffness,
        )

    @property
    def n(self) -> int:
        return len(self.motor_q)

    def link_state_matrix(self) -> np.ndarray:
        """(2n, nq + nv): [q; q̇] = [θ_m + δ; θ̇_m + δ̇] from the plant's state."""
        n, S = self.n, np.zeros((2 * self.n, self.nq + self.nv))
        S[np.arange(n), self.motor_q] = 1.0
        S[np.arange(n), self.belt_q] = 1.0
        S[n + np.arange(n), self.nq + self.motor_v] = 1.0
        S[n + np.arange(n), self.nq + self.belt_v] = 1.0
        return S

    def motor_state_matrix(self) -> np.ndarray:
        """(2n, nq + nv): [θ_m; θ̇_m], what the motor encoders give (divided by N)."""
        n, S = self.n, np.zeros((2 * self.n, self.nq + self.nv))
        S[np.arange(n), self.motor_q] = 1.0
        S[n + np.arange(n), self.nq + self.motor_v] = 1.0
        return S

    def plant_positions(self, q: np.ndarray, deflection: np.ndarray | None = None) -> np.ndarray:
        """The plant's positions for link angles q and belt deflections δ (default 0):
        θ_m = q − δ."""
        delta = np.zeros(self.n) if deflection is None else np.asarray(deflection, dtype=float)
        x = np.zeros(self.nq)
        x[self.motor_q] = np.asarray(q, dtype=float) - delta
        x[self.belt_q] = delta
        return x

    def plant_velocities(self, v: np.ndarray) -> np.ndarray:
        """The plant's velocities for link speeds v with the belts at rest: θ̇_m = v."""
        x = np.zeros(self.nv)
        x[self.motor_v] = np.asarray(v, dtype=float)
        return x

    def static_deflection(self, tau_g: np.ndarray) -> np.ndarray:
        """δ at which each belt holds the gravity force τ_g on its coordinate (arm joint
        order): the spring's −k δ balances τ_g, δ = τ_g / k [rad]."""
        return np.asarray(tau_g, dtype=float) / self.stiffness

"""ForceSensor: the six-axis force-torque sensor under the plate (Section 4: a JR3)."""

from __future__ import annotations

import numpy as np
from numba import njit
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Joint

from nsdrake.control.leaf_system import LeafSystem
from nsdrake.station.config import StationError


def sensor_tare(plant: MultibodyPlant, sensor_joint: Joint) -> tuple[np.ndarray, np.ndarray]:
    """(p_WSo, W_tare): the sensor origin So in the world [m] and the wrench
    [moment about So; force] (6) [N m, N], world, that the weld applies to the
    plate when nothing touches it: it holds the plate's weight."""
    context = plant.CreateDefaultContext()
    instance = sensor_joint.child_body().model_instance()
    p_WSo = sensor_joint.frame_on_child().CalcPoseInWorld(context).translation()
    mass = plant.CalcTotalMass(context, [instance])
    p_Wcm = plant.CalcCenterOfMassPositionInWorld(context, [instance])
    weight = mass * plant.gravity_field().gravity_vector()
    return p_WSo, -np.concatenate([np.cross(p_Wcm - p_WSo, weight), weight])


@njit(cache=True)
def contact_wrench(R_WJc: np.ndarray, F_J: np.ndarray, tare: np.ndarray) -> np.ndarray:
    """W_c = −(W_J − W_tare) (:class:`ForceSensor`) from the weld's reaction F_J = [moment;
    force] in the joint's child frame, rotated to world by R_WJc; zero (no sample) for an
    all-zero reading. (6,) [N m, N]."""
    W_J = np.empty(6)
    W_J[:3] = R_WJc @ F_J[:3]
    W_J[3:] = R_WJc @ F_J[3:]
    if not W_J.any():
        return W_J
    return -(W_J - tare)


def sensor_problem(plant, sensor_joint) -> str | None:
    """Why ``sensor_joint`` of ``plant`` cannot be a force sensor (:class:`ForceSensor`), or None."""
    if not isinstance(plant, MultibodyPlant):
        return f"plant must be a MultibodyPlant, got {type(plant).__name__}"
    if not plant.is_finalized():
        return "plant must be finalized (plant.Finalize()) before the sensor reads its joints"
    if not isinstance(sensor_joint, Joint):
        return f"sensor_joint must be a weld joint of the plant, got {type(sensor_joint).__name__}"
    if sensor_joint.GetParentPlant() is not plant:
        return f"sensor_joint '{sensor_joint.name()}' is a joint of another plant"
    if sensor_joint.type_name() != "weld":
        return (
            f"sensor_joint '{sensor_joint.name()}' is a {sensor_joint.type_name()} joint: it must be a weld "
            "(only a weld's reaction is the whole wrench on the body it holds)"
        )
    return None


class ForceSensor(LeafSystem):
    """The wrench the tool exerts on the plate, in world coordinates, from the
    reaction of the weld that mounts the plate (the sensor).

    .. pydrake_system::

        name: ForceSensor
        input_ports:
        - reaction_forces
        output_ports:
        - wrench
        - force

    ``reaction_forces`` is the plant's port of the same name. ``wrench`` (6) is
    [M_So; f] [N m, N]: the moment about the sensor origin So and the force, in
    world coordinates, of everything but the world and gravity acting on the
    plate; ``force`` (3) is f alone.

    For a welded, hence static, plate the weld's reaction W_J, gravity W_g and
    the contact W_c balance: W_J + W_g + W_c = 0. A real sensor is zeroed with
    nothing touching the plate, when it reads W_J = −W_g: this tare is computed
    from the model at construction (:func:`sensor_tare`), and the output is
    W_c = −(W_J − W_tare).

    A discrete plant's sampled reaction port reads exactly zero until its first
    step, which no loaded weld does: the sensor reports no sample (zero) for an
    all-zero reading.

    ``plant`` must be finalized and ``sensor_joint`` one of its weld joints (the reaction
    of any other joint is not the wrench on the plate: a revolute joint's carries no
    moment about its axis); anything else raises :class:`nsdrake.station.config.StationError`
    (a ValueError) in one line.
    """

    def __init__(self, *, plant: MultibodyPlant, sensor_joint: Joint):
        problem = sensor_problem(plant, sensor_joint)
        if problem is not None:
            raise StationError(f"ForceSensor: {problem}")
        super().__init__()
        # The plant's reaction forces are listed by the joints' order among the joints it
        # has (their ordinals), not by JointIndex: a joint removed before (a vendor's finger,
        # locked by a weld: nsdrake/control/model_files.py, choose_joints) leaves a gap in
        # the indices and none in the list.
        self._index = list(plant.GetJointIndices()).index(sensor_joint.index())
        context = plant.CreateDefaultContext()
        self._R_WJc = sensor_joint.frame_on_child().CalcPoseInWorld(context).rotation().matrix()
        self.p_WSo, self._tare = sensor_tare(plant, sensor_joint)
        self._reactions = self.DeclareAbstractInputPort(
            "reaction_forces", AbstractValue.Make([SpatialForce()])
        )
        deps = {self.input_port_ticket(self._reactions.get_index())}
        self._wrench = self.DeclareVectorOutputPort(
            "wrench", 6, self._calc_wrench, prerequisites_of_calc=deps
        )
        self.DeclareVectorOutputPort(
            "force", 3, lambda c, o: o.SetFromVector(self._wrench.Eval(c)[3:]), prerequisites_of_calc=deps
        )

    @property
    def tare(self) -> np.ndarray:
        """The reading [moment about So; force] (6) with nothing on the plate, world [N m, N]."""
        return self._tare.copy()

    def _calc_wrench(self, context, output):
        F_J = self._reactions.Eval(context)[self._index]
        output.SetFromVector(contact_wrench(self._R_WJc, F_J.get_coeffs(), self._tare))

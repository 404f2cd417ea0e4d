"""Stage 2 when the obstacle row needs Drake's queries (an obstacle shape without a closed
form, here a cylinder): the other criteria rows must still be computed. They were not:
the stage returned to have the obstacle row queried before it packed the joint-torque,
manipulability and joint-limit rows, and the rest of the tick ran without them."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.geometry import Cylinder
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable

import nsdrake
from nsdrake.station.models import models_dir

ARM = models_dir() / "arm4.urdf"
NORMAL = np.array([0.0, 1.0])


def jacobian(q):
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(str(ARM))
    plant.Finalize()
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    J = plant.CalcJacobianTranslationalVelocity(
        context, JacobianWrtVariable.kV, plant.GetFrameByName("tool"), np.zeros(3),
        plant.world_frame(), plant.world_frame(),
    )  # fmt: skip
    return J[:2]


@pytest.mark.parametrize("fused", [False, True], ids=["named systems", "fused"])
def test_queried_obstacles_leave_the_other_criteria_computed(fused):
    """A cylinder far from the arm (queried, d_min finite): joint_torque_criterion is
    ‖Jᵀ F_d‖² (F_d = nominal_force n) and manipulability √det(J Jᵀ), against a plain
    plant's J, to 1e-10. Catches the early return that left those rows unpacked."""
    model = nsdrake.ControllerModel.from_urdf(
        ARM, tool_frame="tool", task_axes=("x", "y"),
        obstacles=[nsdrake.Obstacle("post", Cylinder(0.05, 0.5), RigidTransform([2.0, 2.0, 0.0]))],
    )  # fmt: skip
    config = nsdrake.ControllerConfig(period=0.002, nominal_force=10.0)
    config.desired_null_space.criteria.joint_torque.gain = -0.005
    config.desired_null_space.criteria.obstacle.gain = 1e-3
    controller = nsdrake.NullSpaceImpedanceController(
        controller_model=model, config=config, normal=NORMAL, fused=fused
    )
    context = controller.CreateDefaultContext()
    q = np.array([0.4, 0.9, 1.0, 0.6])
    controller.GetInputPort("estimated_state").FixValue(context, np.concatenate([q, np.zeros(4)]))
    controller.GetInputPort("measured_wrench").FixValue(context, np.zeros(6))
    for name in ("desired_position", "desired_velocity", "desired_acceleration"):
        controller.GetInputPort(name).FixValue(context, np.zeros(2))
    controller.GetInputPort("desired_force").FixValue(context, [10.0])
    J = jacobian(q)
    p = controller.GetOutputPort("joint_torque_criterion").Eval(context)[0]
    w = controller.GetOutputPort("manipulability").Eval(context)[0]
    assert np.isfinite(controller.GetOutputPort("d_min").Eval(context)[0])
    assert p == pytest.approx(np.sum((J.T @ (10.0 * NORMAL)) ** 2), rel=1e-10)
    assert w == pytest.approx(np.sqrt(np.linalg.det(J @ J.T)), rel=1e-10)

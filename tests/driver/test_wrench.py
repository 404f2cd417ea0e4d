"""The measured wrench on the wire: the external-torque estimate W_T = (J Jᵀ)⁻¹ J τ_ext and
the lcmt_force_torque messages."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from drake import lcmt_force_torque
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import MultibodyForces
from pydrake.systems.lcm import _Serializer_

from nsdrake.driver.controller_side import build_controller_side
from nsdrake.driver.run import drive_traces, run_simulated
from nsdrake.driver.wire import ForceTorqueBuffer
from nsdrake.driver.wrench import (
    ForceTorqueSender,
    force_torque_message,
    wrench_from_external_torques,
    wrench_of,
)
from nsdrake.experiment.scenario import load_scenario
from nsdrake.station.models import models_dir

PANDA = models_dir() / "panda.urdf"
Q0 = np.array([0.0, 0.182, 0.0, -2.4, 0.0, 2.582, 0.785])


def test_the_estimate_inverts_the_jacobian_transpose():
    """τ = Jᵀ W for a random 6 × 7 J and wrench W: the estimate gives W back (the
    least-squares solution is exact when τ lies in the range of Jᵀ); a torque in Jᵀ's
    null complement (which no tool wrench makes) changes nothing."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        J, W = rng.normal(size=(6, 7)), rng.normal(size=6)
        np.testing.assert_allclose(wrench_from_external_torques(J, J.T @ W), W, atol=1e-10)
        null = np.linalg.svd(J)[2][-1]  # J null = 0: no tool wrench makes this torque
        np.testing.assert_allclose(wrench_from_external_torques(J, J.T @ W + 3.0 * null), W, atol=1e-10)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_estimator_recovers_a_wrench_applied_at_the_tool(seed):
    """Independent of the estimator's Jacobian: a spatial force F_env that the work piece
    applies to the tool at its point T goes into Drake's MultibodyForces
    (RigidBody.AddInForce), the plant turns it into generalized forces τ_F = Jᵀ F_env
    (CalcGeneralizedForces); the arm holds it with τ_ext = −τ_F, and the estimator must
    return the wrench the tool exerts, W_T = −F_env = [−M; −f]."""
    rng = np.random.default_rng(seed)
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModels(str(PANDA))
    plant.Finalize()
    context = plant.CreateDefaultContext()
    q = Q0 + rng.uniform(-0.3, 0.3, 7)
    plant.SetPositions(context, q)
    tool = plant.GetFrameByName("tool")
    F_env = SpatialForce(rng.normal(size=3), rng.normal(size=3) * 10.0)
    forces = MultibodyForces(plant)
    tool.body().AddInForce(
        context, tool.GetFixedPoseInBodyFrame().translation(), F_env, plant.world_frame(), forces
    )
    tau_ext = -plant.CalcGeneralizedForces(context, forces)
    scenario = load_scenario("panda_wipe")
    scenario = dataclasses.replace(
        scenario, driver=dataclasses.replace(scenario.driver, force_source="external_torque")
    )
    W = build_controller_side(scenario).estimated_wrench(q, tau_ext)  # the drive's, on its own model
    np.testing.assert_allclose(W, -np.concatenate([F_env.rotational(), F_env.translational()]), atol=1e-9)


def test_force_torque_messages_round_trip():
    W = np.array([0.1, -0.2, 0.3, 4.0, -5.0, 6.0])
    message = force_torque_message(W, 1.234)
    assert message.timestamp == 1234  # milliseconds, as lcmt_force_torque defines it
    np.testing.assert_array_equal(wrench_of(lcmt_force_torque.decode(message.encode())), W)
    sender = ForceTorqueSender()
    sc = sender.CreateDefaultContext()
    serializer = _Serializer_[lcmt_force_torque]()  # Drake's C++ message, as the LCM systems hold it
    sender.GetInputPort("wrench").FixValue(sc, W)
    sc.SetTime(1.234)
    sent = serializer.Serialize(sender.get_output_port().EvalAbstract(sc))
    assert lcmt_force_torque.decode(sent).timestamp == 1234  # the context's time [ms]
    received = ForceTorqueBuffer()  # the controller side's in-place decoding
    assert received.problem(sent) is None
    received.load(sent)
    np.testing.assert_array_equal(received.wrench, W)
    assert "not an lcmt_force_torque" in received.problem(sent[:-1])


def test_the_estimate_tracks_the_table_sensor_through_contact():
    """panda_wipe through contact with the wrench estimated from the status's external
    joint torques: the estimated normal force against the simulated table sensor's, and
    the run's force bounds. The simulated driver's τ_ext is exact, so what differs is the
    mapping alone (README: what the estimate costs)."""
    scenario = load_scenario("panda_wipe", duration=2.0)
    scenario = dataclasses.replace(
        scenario, driver=dataclasses.replace(scenario.driver, force_source="external_torque")
    )
    driven = run_simulated(scenario, realtime_rate=0.0)
    traces = drive_traces(driven)
    touching = traces["f_n"] > 0.5
    assert touching.sum() > 500
    error = traces["f_n_measured"][touching] - traces["f_n"][touching]
    assert float(np.sqrt(np.mean(error**2))) < 0.01  # [N], of 10 N
    assert float(np.max(np.abs(traces["f_n"][traces["t"] > 1.8] - 10.0))) < 0.2

"""The payload's gravity split between the robot and the controller (issue 43, item 1;
docs/real_arm.md, "Gravity"): Franka's robot adds g(q) of its own model, the arm and the
load its settings declare (a point mass m_load at F_x_Cload); the controller sends τ − g(q)
of its model. A payload declared in the scenario stands for one set in Franka's load
settings too; an undeclared one is known to neither. So the torque the robot applies,
command + its g(q), is the controller's τ exactly, declared or not.

The simulated robot's g(q) is checked against Franka's load model computed here from plain
Drake calls: the arm's own gravity plus the point mass's, −J_v(q)ᵀ m g at the load's centre
of mass (no payload body welded anywhere)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable

from nsdrake.driver.run import drive_traces, run_simulated
from nsdrake.experiment.scenario import load_scenario
from nsdrake.station.config import PayloadConfig
from nsdrake.station.models import models_dir

MASS, COM = 2.0, [0.02, -0.01, 0.05]  # [kg], [m] in the tool frame: within the Panda's rating


class FrankaGravity:
    """g(q) [N m] as Franka's robot adds it: urdf/panda.urdf's arm plus a point load ``mass``
    at ``com`` in the tool frame, −(Drake's gravity forces of the arm + J_v(com)ᵀ m g)."""

    def __init__(self, mass: float, com):
        self.plant = MultibodyPlant(0.0)
        Parser(self.plant).AddModels(str(models_dir() / "panda.urdf"))
        self.plant.Finalize()
        self.context = self.plant.CreateDefaultContext()
        self.mass, self.com = mass, np.asarray(com, dtype=float)
        self.tool = self.plant.GetFrameByName("tool")

    def __call__(self, q) -> np.ndarray:
        plant, context = self.plant, self.context
        plant.SetPositions(context, q)
        J_v = plant.CalcJacobianTranslationalVelocity(
            context, JacobianWrtVariable.kV, self.tool, self.com, plant.world_frame(), plant.world_frame()
        )
        load = J_v.T @ (self.mass * plant.gravity_field().gravity_vector())
        return -(plant.CalcGravityGeneralizedForces(context) + load)


@pytest.mark.parametrize("declared", [True, False], ids=["declared", "undeclared"])
def test_the_controller_subtracts_exactly_what_the_robot_adds(declared):
    """panda_wipe driven in lockstep against the simulated driver for 30 ms with a 2 kg
    payload: at every row the torque the robot applied (command + its g) is the controller's
    τ to 1e-9 N m, and what the robot added is Franka's load model at that row's q (the
    payload's mass when declared, none when not) to 1e-9 N m. Catches a controller that
    subtracts the arm's gravity alone while the robot adds the load's (the payload's
    g(q), 5-20 N m on joints 2 and 4, sent twice or never), and a simulated robot that adds
    the physics' payload, which Franka's settings do not know when it is undeclared (today's
    main: the undeclared case)."""
    s = load_scenario("panda_wipe", duration=0.03)
    payload = PayloadConfig(mass=MASS, com=COM, declared=declared)
    s = dataclasses.replace(s, arm=dataclasses.replace(s.arm, payload=payload))
    run = run_simulated(s, realtime_rate=0.0)
    assert run.failure is None, run.failure
    traces = drive_traces(run)
    rows = len(traces) - 1  # the last row's applied torque is NaN (applied after the run)
    assert rows >= 29
    tau = np.array([traces[f"tau{i}"][:rows] for i in range(1, 8)])
    applied = np.array([traces[f"tau_applied{i}"][:rows] for i in range(1, 8)])
    command = np.array([traces[f"cmd{i}"][:rows] for i in range(1, 8)])
    q = np.array([traces[f"q{i}"][:rows] for i in range(1, 8)])
    np.testing.assert_allclose(applied, tau, rtol=0, atol=1e-9)
    franka = FrankaGravity(MASS if declared else 0.0, COM)
    added = applied - command
    for k in range(rows):
        np.testing.assert_allclose(added[:, k], franka(q[:, k]), rtol=0, atol=1e-9)
    # the payload's share is no rounding: it is what a wrong split would send twice or never
    share = FrankaGravity(MASS, COM)(q[:, 0]) - FrankaGravity(0.0, COM)(q[:, 0])
    assert np.max(np.abs(share)) > 5.0

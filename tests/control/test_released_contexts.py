"""A refused input keeps no borrowed Drake context alive (nsdrake.control.leaf_system).

Drake lends a system's callback its context as a Python wrapper of a C++ object Drake owns.
An exception leaving the callback holds the callback's frames in its traceback, and so the
wrapper; once the caller's context is freed, that wrapper is stale, and pybind11 hands it
back for the next context allocated at the same address, whose owning pointer it drops:
the new context is freed at once and its first use is a segmentation fault. (Seen in the
suite: the controller's ControllerInputError tests, then ControllerModel's check of
Pinocchio against Drake crashing in plant.SetPositionsAndVelocities on a fresh context.)

The independent check of the crash is a separate process doing what the suite did
(an error kept, the controller's context dropped, new plant contexts used), judged by its
exit status; the in-process check walks the error's traceback for Drake contexts.
"""

from __future__ import annotations

import os
import subprocess
import sys
import traceback
from pathlib import Path

import numpy as np
import pytest
from models import serial_arm_urdf
from pydrake.all import (
    AddMultibodyPlant,
    ConstantVectorSource,
    DiagramBuilder,
    MultibodyPlantConfig,
    Parser,
    Simulator,
)
from pydrake.systems.framework import ContextBase

import nsdrake
from nsdrake import ControllerConfig, ControllerInputError, NullSpaceImpedanceController

T = 0.002
ARM = serial_arm_urdf(["z"] * 4, [0.25] * 4, [1.0, 0.8, 0.6, 0.4], name="arm")
N = 4
NAN_STATE = np.r_[np.nan, np.zeros(2 * N - 1)]
REFERENCES = {"desired_position": [0.5, 0.4], "desired_velocity": [0, 0], "desired_acceleration": [0, 0]}

# The suite's sequence, made deterministic: each round frees a controller context whose
# refused evaluation is kept, then uses fresh plant contexts (which reuse its memory).
SCRIPT = """
import numpy as np
from models import serial_arm_urdf
from pydrake.all import MultibodyPlant, Parser
from nsdrake import ControllerConfig, ControllerInputError, NullSpaceImpedanceController

ARM = serial_arm_urdf(["z"] * 4, [0.25] * 4, [1.0, 0.8, 0.6, 0.4], name="arm")
controller = NullSpaceImpedanceController(controller_model=ARM, config=ControllerConfig(period=0.002))
plant = MultibodyPlant(0.0)
Parser(plant).AddModelsFromString(ARM, "urdf")
plant.Finalize()
kept, contexts = [], []
for _ in range(30):
    context = controller.CreateDefaultContext()
    controller.GetInputPort("estimated_state").FixValue(context, np.r_[np.nan, np.zeros(7)])
    for name in ("desired_position", "desired_velocity", "desired_acceleration"):
        controller.GetInputPort(name).FixValue(context, np.zeros(2))
    try:
        controller.GetOutputPort("generalized_force").Eval(context)
    except ControllerInputError as e:
        kept.append(e)  # as pytest.raises or a log keeps it
    del context  # Drake frees the controller's context (and its subsystems')
    for _ in range(20):
        c = plant.CreateDefaultContext()
        plant.SetPositionsAndVelocities(c, np.zeros(8))
        contexts.append(c)
print("done")
"""


def test_a_kept_refusal_does_not_crash_later_contexts():
    """In a fresh process: 30 refused evaluations kept, their contexts freed, 600 plant
    contexts created and used. Fails (exit −11, SIGSEGV, from the first round) if a
    callback's frame keeps the freed controller context's wrapper, as it did."""
    env = dict(os.environ)
    paths = [str(Path(nsdrake.__file__).parents[1]), str(Path(__file__).parents[1])]
    env["PYTHONPATH"] = os.pathsep.join(paths + [env.get("PYTHONPATH", "")])
    result = subprocess.run(
        [sys.executable, "-X", "faulthandler", "-c", SCRIPT],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    outcome = (result.returncode, result.stderr[-2000:])
    assert result.returncode == 0 and result.stdout.strip() == "done", outcome


def contexts_in(error: BaseException) -> list[str]:
    """The Drake contexts that the frames of ``error``'s traceback hold, as 'function: name'."""
    held = []
    for frame, _ in traceback.walk_tb(error.__traceback__):
        for name, value in list(frame.f_locals.items()):
            if isinstance(value, ContextBase):
                held.append(f"{frame.f_code.co_name}: {name}")
    return held


@pytest.mark.parametrize("fused", [False, True], ids=["named", "fused"])
def test_a_refusal_from_an_output_port_holds_no_context(fused):
    """Eval of generalized_force with a NaN state: the ControllerInputError's traceback
    still runs through nsdrake's callback (its lines are kept) but no frame holds a
    context. Fails if a callback is declared without nsdrake.control.leaf_system's release."""
    controller = NullSpaceImpedanceController(
        controller_model=ARM, config=ControllerConfig(period=T), fused=fused
    )
    context = controller.CreateDefaultContext()
    controller.GetInputPort("estimated_state").FixValue(context, NAN_STATE)
    for name, value in REFERENCES.items():
        controller.GetInputPort(name).FixValue(context, np.asarray(value, dtype=float))
    with pytest.raises(ControllerInputError) as caught:
        controller.GetOutputPort("generalized_force").Eval(context)
    error = caught.value
    functions = [frame.f_code.co_name for frame, _ in traceback.walk_tb(error.__traceback__)]
    assert "check_inputs" in functions, functions  # the traceback still says where
    # this test's own frame holds `context`, its own: only the frames below it count
    assert [c for c in contexts_in(error) if not c.startswith("test_")] == [], contexts_in(error)


def test_a_refusal_during_a_simulation_holds_no_context():
    """A user's diagram whose plant state turns NaN: the error out of AdvanceTo (through
    the controller's discrete updates and output ports) holds no context in the frames
    below the test's. Fails if any update or calc callback keeps its context."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=T), builder)
    Parser(plant).AddModelsFromString(ARM, "urdf")
    plant.Finalize()
    controller = builder.AddSystem(
        NullSpaceImpedanceController(controller_model=ARM, config=ControllerConfig(period=T))
    )
    builder.Connect(plant.get_state_output_port(), controller.GetInputPort("estimated_state"))
    builder.Connect(controller.GetOutputPort("generalized_force"), plant.get_actuation_input_port())
    for name, value in REFERENCES.items():
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, dtype=float)))
        builder.Connect(source.get_output_port(), controller.GetInputPort(name))
    simulator = Simulator(builder.Build())
    plant_context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    plant.SetPositions(plant_context, [0.4, 0.9, 1.0, 0.6])
    simulator.AdvanceTo(0.01)
    plant_context.get_mutable_discrete_state_vector().SetAtIndex(2 * N - 1, np.nan)
    with pytest.raises(ControllerInputError) as caught:
        simulator.AdvanceTo(0.02)
    held = [c for c in contexts_in(caught.value) if not c.startswith("test_")]
    assert held == [], held

"""The simulated driver costs the PC little (issue 44, item 2) and is the same robot as
before: the lean driver (nsdrake/driver/simulated_driver.py: the command an input port
fixed each period, the messages encoded in place from the diagram's ports, logs only where
read) against the Drake diagram of LCM systems it replaced (tests/driver/lcm_simulated_driver.py:
Drake's subscriber, PandaCommandReceiver, PandaStatusSender, publishers, loggers), both
given the same commands: a recorded panda_wipe drive through its approach and first contact,
and random torques. Every period's plant state, status bytes, sensor bytes and logged rows
are the same to the bit."""

from __future__ import annotations

import numpy as np
import pytest
from lcm_simulated_driver import LcmSimulatedDriver
from pydrake.lcm import DrakeLcm

from nsdrake.driver.run import run_simulated
from nsdrake.driver.simulated_driver import LOGS, SimulatedDriver
from nsdrake.experiment.scenario import load_scenario

CONTACT_AT = 1.44  # [s] panda_wipe's first contact (tests/driver/test_drive_reproduces.py)


class Reference:
    """The old driver on a bus of its own, its statuses and sensor messages taken off it."""

    def __init__(self, scenario, adds_gravity: bool):
        self.lcm = DrakeLcm("memq://")
        self.messages: dict[str, list[bytes]] = {"status": [], "force_torque": []}
        d = scenario.driver
        self.lcm.Subscribe(d.status_channel, self.messages["status"].append)
        self.lcm.Subscribe(d.force_torque_channel, self.messages["force_torque"].append)
        self.driver = LcmSimulatedDriver(scenario, self.lcm, adds_gravity=adds_gravity)

    def start(self):
        self.driver.start()
        return self._taken()

    def step(self, torque):
        self.driver.apply_torque(torque)
        self.driver.advance()
        return self._taken()

    def _taken(self):
        self.lcm.HandleSubscriptions(0)
        status, force_torque = self.messages["status"], self.messages["force_torque"]
        assert len(status) == len(force_torque) == 1
        return status.pop(), force_torque.pop()


def compare(scenario, commands: np.ndarray, adds_gravity: bool) -> dict:
    """Both drivers through ``commands`` (periods, 7): states, messages, logs bit for bit;
    the lean driver's logs."""
    old = Reference(scenario, adds_gravity)
    new = SimulatedDriver(scenario, None, adds_gravity=adds_gravity)
    old_context, new_context = old.driver.context, new.context
    new.start()
    assert old.start() == new.messages()
    for k, torque in enumerate(commands):
        ours = new.apply_torque(torque), new.advance(), new.messages()
        assert old.step(torque) == ours[2], k
        assert new.time == old.driver.time
        old_state = old_context.get_discrete_state_vector().CopyToVector()
        new_state = new_context.get_discrete_state_vector().CopyToVector()
        assert old_state.tobytes() == new_state.tobytes(), k
    old_logs, new_logs = old.driver.logs(), new.logs()
    for name in LOGS:
        assert old_logs[name].sample_times().tobytes() == new_logs[name].sample_times().tobytes(), name
        assert old_logs[name].data().tobytes() == new_logs[name].data().tobytes(), name
    return new_logs


@pytest.fixture(scope="module")
def recorded():
    """The commands a lockstep panda_wipe drive sent through its approach and first contact."""
    scenario = load_scenario("panda_wipe", duration=CONTACT_AT + 0.15)
    run = run_simulated(scenario, realtime_rate=0.0)
    assert run.failure is None
    return scenario, run.loop.recorder.logs()["command"].data().T.copy()


def test_the_lean_driver_is_the_same_robot_through_a_drive_s_contact(recorded):
    """panda_wipe's recorded commands, the robot adding g (the shipped setting): every
    state, status, sensor message and logged row equal to the bit, through the first contact
    (the sensor reads over 4 N by the end: the contact model is compared too).
    Catches the contact forces' sign (τ_ext), a message field left out or in the wrong
    place, the command applied a period early or late, a plant or step that differs."""
    scenario, commands = recorded
    logs = compare(scenario, commands, adds_gravity=True)
    assert np.max(np.abs(logs["wrench"].data()[3:])) > 4.0  # in contact, pressing


def test_the_lean_driver_is_the_same_robot_without_gravity_and_on_random_torques():
    """Random torques (±5 N m about the recorded drive's first command) for 200 periods,
    the robot applying the command alone (driver.robot_adds_gravity false's stand-in):
    the same to the bit. Catches g added where the robot adds none."""
    scenario = load_scenario("panda_wipe", duration=0.2)
    rng = np.random.default_rng(44)
    compare(scenario, rng.uniform(-5.0, 5.0, (200, 7)), adds_gravity=False)

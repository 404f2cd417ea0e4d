"""The last gate before the wire (issue 43, item 1): no command beyond the Panda's published
torque limits (87 N m on joints 1-4, 12 N m on joints 5-7) or torque rate (1000 N m/s, a new
command acting within the robot's 1 ms cycle) ever leaves `nsdrake drive`, whatever shaped it
(the law's τ, the gravity the robot adds, a payload inside it, the limiter's state); a payload
the Panda is not rated for (3 kg) is refused before anything is built.

The published numbers are typed here from Franka's FCI documentation ("Limits for Panda"),
not read from nsdrake/driver/panda.py, so that a wrong constant there fails these tests."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from fake_bus import FakeBus, force_torque_bytes, status_bytes
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import SpatialInertia, UnitInertia

from nsdrake.cli import main
from nsdrake.control.actuator_limits import limited_torque
from nsdrake.driver.controller_side import build_controller_side
from nsdrake.driver.loop import ControllerLoop, DriveFaultError
from nsdrake.driver.panda import command_problem
from nsdrake.experiment.scenario import load_scenario
from nsdrake.station.config import PayloadConfig
from nsdrake.station.models import models_dir

PUBLISHED_TORQUE = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])  # [N m] Franka's FCI documentation
PUBLISHED_RATE = 1000.0  # [N m/s]
CYCLE = 1e-3  # [s] the Panda's control cycle
ROUNDING = 1e-9  # [N m] what the gate may forgive (the rounding of τ − g)
NAMES = tuple(f"panda_joint{k}" for k in range(1, 8))
UTIME0 = 1_700_000_000_000_000


def beyond(command, previous) -> bool:
    """The command breaks the published limits (independently of nsdrake's gate)."""
    command = np.asarray(command)
    if not np.all(np.abs(command) <= PUBLISHED_TORQUE + ROUNDING):
        return True
    return previous is not None and not np.all(
        np.abs(command - previous) <= PUBLISHED_RATE * CYCLE + ROUNDING
    )


# --- the gate alone, at its boundaries ------------------------------------------------------


@pytest.mark.parametrize("joint", range(7))
def test_the_gate_takes_each_joint_at_its_published_limit_and_refuses_just_beyond(joint):
    """Each joint's own limit: exactly at it (and at the full rate) is sent; 1e-6 N m
    beyond it, or 1e-6 N m beyond one cycle's rate, is refused naming that joint. Catches
    87 N m used for the wrist joints (5-7), one limit for all, a rate taken over the
    scenario's period times a gap, the sign of a command ignored."""
    for sign in (1.0, -1.0):
        command = np.zeros(7)
        command[joint] = sign * PUBLISHED_TORQUE[joint]
        assert command_problem(command, None, NAMES) is None
        command[joint] += sign * 1e-6
        problem = command_problem(command, None, NAMES)
        assert problem is not None and problem.startswith(f"panda_joint{joint + 1} would be sent "), problem
        assert f"beyond the Panda's published {PUBLISHED_TORQUE[joint]:g} N m" in problem
        previous = np.zeros(7)
        step = np.zeros(7)
        step[joint] = sign * PUBLISHED_RATE * CYCLE
        assert command_problem(previous + step, previous, NAMES) is None
        step[joint] += sign * 1e-6
        problem = command_problem(previous + step, previous, NAMES)
        assert problem is not None and problem.startswith(f"panda_joint{joint + 1}'s command would change by")


def test_the_first_command_has_no_rate_to_keep_and_a_nan_is_refused():
    """The first command of a drive is checked for its size only (no command was sent
    before it: the limiter has no previous torque either); a NaN or an inf never passes."""
    command = np.full(7, 10.0)
    assert command_problem(command, None, NAMES) is None
    assert "would change by" in command_problem(command, np.zeros(7), NAMES)
    for bad in (np.nan, np.inf):
        command[3] = bad
        assert command_problem(command, None, NAMES) == f"panda_joint4's command is {bad!r}"


# --- the whole final stage, on the loop, with random payloads, gravity and limiter states ---


@pytest.fixture(scope="module")
def side():
    s = load_scenario("panda_wipe", duration=0.05)
    s = dataclasses.replace(s, driver=dataclasses.replace(s.driver, first_status_timeout=0.3))
    return build_controller_side(s)


class InjectedStep:
    """The side's ControllerStep, with τ and g(q) replaced by planned values once a plan is
    set (the warm-up runs the real step)."""

    def __init__(self, real):
        self.real, self.plan, self.gravity = real, [], real.gravity

    def reset(self):
        self.real.reset()

    def shift_rate_reference(self, delta):
        self.real.shift_rate_reference(delta)

    def step(self, *args):
        result = self.real.step(*args)
        if self.plan:
            tau, self.gravity = self.plan.pop(0)
            result.tau[:] = tau
        else:
            self.gravity = self.real.gravity
        return result


def payload_gravity(q, mass, com, gravity) -> np.ndarray:
    """g(q) [N m] of urdf/panda.urdf with a point mass ``mass`` at ``com`` in the tool frame,
    under ``gravity`` [m/s²]: plain Drake calls (the holding torque, −Drake's gravity forces)."""
    plant = MultibodyPlant(0.0)
    (arm,) = Parser(plant).AddModels(str(models_dir() / "panda.urdf"))
    if mass > 0:
        body = plant.AddRigidBody("load", arm, SpatialInertia(mass, np.zeros(3), UnitInertia(0.0, 0.0, 0.0)))
        plant.WeldFrames(plant.GetFrameByName("tool"), body.body_frame(), RigidTransform(com))
    plant.mutable_gravity_field().set_gravity_vector(gravity)
    plant.Finalize()
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    return -plant.CalcGravityGeneralizedForces(context)


def test_no_command_beyond_the_published_limits_ever_leaves(side):
    """Hypothesis draws what shapes the command: a payload (0-100 kg, its centre of mass
    within 0.5 m of the tool), gravity (any direction, up to 3 g) and a pose, for the g(q)
    the robot adds; the limiter's state (its previous torque, or none) and the law's torques
    for τ (the limiter's output at the scenario's limits, as the step computes it); the robot
    adding g or not. Each drive on a fake bus answers up to five statuses with those. Every
    command that reached the bus is within the published limits and one cycle's rate of the
    one before, and is τ − g (τ without the robot's g); a drive stopped by the gate stopped
    on a command that was beyond them, with nothing more sent. Both outcomes occur. Catches
    the gate removed or checking τ instead of what is sent (the 431 N m of issue 43), the
    rate left unchecked, and a command within the limits refused."""
    real = side.step
    seen = {"sent": 0, "refused": 0}
    q_lo = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
    q_hi = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
    unit = st.floats(0.0, 1.0)

    @settings(max_examples=100, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
    @given(
        mass=st.one_of(st.just(0.0), st.floats(0.0, 100.0)),
        com=st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3),
        g_size=st.floats(0.0, 3 * 9.81),
        g_dir=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).filter(
            lambda d: np.linalg.norm(d) > 0.1
        ),
        pose=st.lists(unit, min_size=7, max_size=7),
        adds_gravity=st.booleans(),
        ticks=st.lists(
            st.tuples(
                st.lists(st.floats(-300.0, 300.0), min_size=7, max_size=7),  # τ_task
                st.lists(st.floats(-50.0, 50.0), min_size=7, max_size=7),  # τ₀
                st.lists(st.floats(-1.0, 1.0), min_size=7, max_size=7),  # the previous τ, of τ_max
                st.booleans(),  # the limiter has a previous τ
            ),
            min_size=1,
            max_size=5,
        ),
    )
    def drive(mass, com, g_size, g_dir, pose, adds_gravity, ticks):
        gravity = g_size * np.asarray(g_dir) / np.linalg.norm(g_dir)
        g = payload_gravity(q_lo + np.asarray(pose) * (q_hi - q_lo), mass, np.asarray(com), gravity)
        plan = []
        for tau_task, tau0, previous, has_previous in ticks:
            out = limited_torque(
                np.asarray(tau_task), np.asarray(tau0), PUBLISHED_TORQUE, np.full(7, PUBLISHED_RATE),
                CYCLE, np.asarray(previous) * PUBLISHED_TORQUE, has_previous,
            )  # fmt: skip
            plan.append((out[:7].copy(), g))
        bus = FakeBus()
        side.step = step = InjectedStep(real)
        side.adds_gravity = adds_gravity
        try:
            side.reset()
            loop = ControllerLoop(side, bus, clock=bus.clock, capacity=16)
            loop.ready()
            utime = UTIME0
            for k in range(len(plan)):
                utime += 1000
                bus.at(
                    (k + 1) * 1e-3,
                    "PANDA_STATUS",
                    status_bytes(side.station.q0, utime=utime, robot_utime=utime),
                )
                bus.at((k + 1) * 1e-3, "PANDA_FORCE_TORQUE", force_torque_bytes())
            expected = [tau - (gk if adds_gravity else 0.0) for tau, gk in plan]
            step.plan = list(plan)
            refused = None
            try:
                loop.start()
                for _ in range(len(plan) - 1):
                    loop.tick()
            except DriveFaultError as e:
                refused = e
        finally:
            side.step, side.adds_gravity = real, side.scenario.driver.robot_adds_gravity
        sent = [np.asarray(message.joint_torque) for _, message in bus.sent]
        previous = None
        for k, command in enumerate(sent):
            assert not beyond(command, previous), (k, command, previous)
            np.testing.assert_allclose(command, expected[k], rtol=0, atol=1e-12)
            previous = command
        assert len(sent) == loop.commands
        if refused is not None:
            assert "command refused, not sent: " in refused.problem, refused
            assert beyond(expected[len(sent)], previous)  # the gate refused only what was beyond
            seen["refused"] += 1
        else:
            assert len(sent) == len(plan)
        seen["sent"] += len(sent)

    drive()
    assert seen["sent"] > 0 and seen["refused"] > 0, seen


def test_the_command_keeps_the_rate_limit_while_gravity_moves(side):
    """Joint 2 steps to 1.2 rad/s (its position the trapezoid of its reported velocities:
    every status consistent) for 20 periods: the damping's torque jumps, the limiter holds
    the rate at 1000 N m/s, and g(q) moves under the arm. Every command is answered (no
    stop) and changes by at most 1 N m a cycle, the limit reached. Catches a rate limit on
    τ alone: the command τ − g then changes by 1 N m plus g's change, and the gate stops
    the drive (1.001 N m, before this was fixed)."""
    bus = FakeBus()
    side.reset()
    loop = ControllerLoop(side, bus, clock=bus.clock, capacity=32)
    loop.ready()
    q, v = np.array(side.station.q0, dtype=float), np.zeros(7)
    utime = UTIME0
    for k in range(21):
        if k:
            q[1] += 0.5 * 1e-3 * (v[1] + 1.2)
            v[1] = 1.2
        utime += 1000
        bus.at((k + 1) * 1e-3, "PANDA_STATUS", status_bytes(q, v=v, utime=utime, robot_utime=utime))
        bus.at((k + 1) * 1e-3, "PANDA_FORCE_TORQUE", force_torque_bytes())
    loop.start()
    for _ in range(20):
        loop.tick()
    sent = np.array([message.joint_torque for _, message in bus.sent])
    assert len(sent) == 21
    change = np.abs(np.diff(sent, axis=0))
    assert change.max() <= PUBLISHED_RATE * CYCLE + ROUNDING
    assert change.max() > 0.999 * PUBLISHED_RATE * CYCLE  # the limiter was at its rate limit


# --- a payload beyond the rating, a model beyond the limits -----------------------------------


@pytest.mark.parametrize("command", ["drive", "sim-driver"])
def test_a_payload_the_panda_is_not_rated_for_is_refused_before_anything_is_sent(tmp_path, capsys, command):
    """Issue 43's 100 kg payload (and 3.01 kg, just over Franka's published 3 kg; declared or
    not: the arm carries it either way): one line naming arm.payload.mass, exit 2, no run
    folder, nothing built that listens or sends. Catches a drive that sends 431 N m."""
    for payload in ("{mass: 100.0, com: [0, 0, 0.05]}", "{mass: 3.01, declared: false}"):
        config = tmp_path / "c.yaml"
        config.write_text(f"arm: {{payload: {payload}}}\n")
        out = tmp_path / "out"
        bus = ["--simulated-driver", "--out", str(out)] if command == "drive" else ["--lcm", "bogus://x"]
        assert main([command, "panda_wipe", "--config", str(config), *bus]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "arm.payload.mass: " in err, err
        assert "above the Panda's published payload of 3 kg" in err
        assert not out.exists()


def test_the_rated_payload_itself_is_taken():
    """3 kg exactly is within the rating (catches a refusal one step early)."""
    from nsdrake.driver.controller_side import check_drive_scenario

    s = load_scenario("panda_wipe", duration=0.01)
    check_drive_scenario(
        dataclasses.replace(s, arm=dataclasses.replace(s.arm, payload=PayloadConfig(mass=3.0)))
    )


# A rated 3 kg payload whose centre of mass lies 6 m off the tool: its gravity at panda_wipe's
# start is beyond what joint 6 may be sent (the limiter clips τ, the command τ − g is not).
HOSTILE = "arm: {payload: {mass: 3.0, com: [6.0, 0.0, 0.0]}}\n"


def test_a_command_beyond_the_limits_stops_the_drive_before_it_is_sent(side):
    """The hostile payload on a fake bus: the drive stops at its first status with one line
    naming the joint and its command, and the bus carries no command. Catches the gate
    missing (the command is sent: today's main sent all 32 of issue 43's)."""
    s = load_scenario("panda_wipe", duration=0.05)
    s = dataclasses.replace(
        s,
        arm=dataclasses.replace(s.arm, payload=PayloadConfig(mass=3.0, com=[6.0, 0.0, 0.0])),
        driver=dataclasses.replace(s.driver, first_status_timeout=0.3),
    )
    hostile = build_controller_side(s)
    bus = FakeBus()
    loop = ControllerLoop(hostile, bus, clock=bus.clock, capacity=8)
    loop.ready()
    bus.at(1e-3, "PANDA_STATUS", status_bytes(hostile.station.q0, utime=UTIME0, robot_utime=UTIME0))
    bus.at(1e-3, "PANDA_FORCE_TORQUE", force_torque_bytes())
    with pytest.raises(DriveFaultError) as info:
        loop.start()
    assert bus.sent == [] and loop.commands == 0
    line = str(info.value)
    assert "\n" not in line and line.startswith(
        "before the first command: command refused, not sent: panda_joint"
    )
    assert line.endswith("stopped commanding after 0 command(s)")
    assert beyond(hostile.command, None)

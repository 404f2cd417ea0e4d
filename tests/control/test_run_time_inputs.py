"""What the controller refuses at run time (issue 24, item 6): ControllerStep.step's
arguments and the values on NullSpaceImpedanceController's input ports.

Each refusal is a ControllerInputError (a ValueError), one line naming the argument or port
(and the joint, axis or entry), raised before anything is computed. The independent
computation each test compares against is a second ControllerStep (or controller context)
that never saw the bad call: a refusal that wrote half of its inputs, the discrete state or
the kept R_d would show in the τ of the next good call, to the last bit.

The arm is the tests' own planar 4-joint arm (tests/models.py): a force task on (x, y) with
the normal −y for the force axis, a free-space task (normal None) for the optional ports,
and a spatial 7-joint arm with the full pose task for the rotational inputs.
"""

from __future__ import annotations

import re
import threading

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

from nsdrake import (
    ControllerConfig,
    ControllerInputError,
    ControllerModel,
    ControllerStep,
    NullSpaceImpedanceController,
)

T = 0.002  # control period [s]
ARM = serial_arm_urdf(["z"] * 4, [0.25] * 4, [1.0, 0.8, 0.6, 0.4], name="arm")
Q0 = np.array([0.4, 0.9, 1.0, 0.6])
N = 4
POSE = ("x", "y", "z", "rx", "ry", "rz")
SPATIAL = serial_arm_urdf(
    ["z", "y", "y", "x", "y", "z", "y"],
    [0.1, 0.3, 0.25, 0.1, 0.1, 0.05, 0.05],
    [2.0, 1.5, 1.0, 0.5, 0.4, 0.2, 0.1],
)
SPATIAL_Q0 = np.array([0.3, 0.5, -0.8, 0.2, 0.6, 0.1, -0.4])


def config() -> ControllerConfig:
    c = ControllerConfig(period=T)
    c.desired_null_space.criteria.joint_torque.gain = -0.005  # q̇_dⁿ changes: the state matters
    return c


def planar(normal=(0.0, -1.0)) -> ControllerStep:
    return ControllerStep(controller_model=ARM, config=config(), normal=normal)


def good_call(k: int):
    """The arguments of the k-th good call of a force task (t, q, v, wrench, x_d, ẋ_d, ẍ_d, f_d)."""
    rng = np.random.default_rng(k)
    q, v = Q0 + 0.05 * rng.standard_normal(N), 0.3 * rng.standard_normal(N)
    wrench = np.r_[0.0, 0.0, 0.1 * rng.standard_normal(), 0.0, -3.0, 0.0]
    x_d = np.array([0.5, 0.4]) + 0.01 * rng.standard_normal(2)
    return k * T, q, v, wrench, x_d, np.zeros(2), np.zeros(2), 4.0


def bad(k: int, **change):
    """good_call(k) with some arguments replaced (by name)."""
    names = ("t", "q", "v", "wrench", "x_d", "xdot_d", "xddot_d", "f_d")
    args = dict(zip(names, good_call(k), strict=True))
    args.update(change)
    return [args[name] for name in names]


NAN_Q = np.array([0.4, np.nan, 1.0, 0.6])
# (arguments of the third call, what the one-line message must say)
REFUSED = {
    "q short": (bad(2, q=Q0[:3]), r"q must be 4 joint positions .*joint1.*got"),
    "q long": (bad(2, q=np.r_[Q0, 0.0]), r"q must be 4 joint positions"),
    "q as a column": (bad(2, q=Q0[:, None]), r"q must be 4 joint positions"),
    "q scalar": (bad(2, q=0.3), r"q must be 4 joint positions"),
    "q None": (bad(2, q=None), r"q must be 4 joint positions .*got None"),
    "q text": (bad(2, q="abcd"), r"q must be 4 joint positions .*got 'abcd'"),
    "q nan": (bad(2, q=NAN_Q), r"q\[joint2\] is nan: must be finite"),
    "v inf": (bad(2, v=np.array([0.0, 0.0, -np.inf, 0.0])), r"v\[joint3\] is -inf: must be finite"),
    "v short": (bad(2, v=np.zeros(2)), r"v must be 4 joint speeds"),
    "x_d scalar (was broadcast to every axis)": (
        bad(2, x_d=0.5),
        r"x_d must be 2 numbers, the task axes \['x', 'y'\]",
    ),
    "x_d one entry (was broadcast)": (bad(2, x_d=np.array([0.5])), r"x_d must be 2 numbers"),
    "x_d 3-D": (bad(2, x_d=np.zeros(3)), r"x_d must be 2 numbers"),
    "x_d nan": (bad(2, x_d=np.array([0.5, np.nan])), r"x_d\[y\] is nan: must be finite"),
    "xdot_d as a matrix": (bad(2, xdot_d=np.zeros((2, 2))), r"xdot_d must be 2 numbers"),
    "xddot_d inf": (bad(2, xddot_d=np.array([np.inf, 0.0])), r"xddot_d\[x\] is inf"),
    "wrench of 3": (bad(2, wrench=np.zeros(3)), r"wrench must be \[M; f\] \(6\)"),
    "wrench nan": (bad(2, wrench=np.r_[np.zeros(4), np.nan, 0.0]), r"wrench\[4\] is nan"),
    "wrench None with a force axis": (bad(2, wrench=None), r"wrench is None, but the task has a force axis"),
    "f_d nan": (bad(2, f_d=np.nan), r"f_d is nan: must be finite"),
    "f_d a list": (bad(2, f_d=[4.0]), r"f_d must be a number \[N\]"),
    "f_d None with a force axis": (bad(2, f_d=None), r"f_d is None, but the task has a force axis"),
    "t nan": (bad(2, t=np.nan), r"t must be a finite number"),
    "t inf": (bad(2, t=np.inf), r"t must be a finite number, got inf"),
    "t before the previous call": (
        bad(2, t=0.0),
        r"t = 0 s is before the previous call's 0\.002 s: reset\(\)",
    ),
    "t text": (bad(2, t="later"), r"t must be a finite number"),
    "t text of a number (numpy would read it)": (bad(0, t="0.1"), r"t must be a finite number, got '0\.1'"),
    "f_d text of a number": (bad(2, f_d="4"), r"f_d must be a number \[N\], got '4'"),
}


def message_of(error: Exception) -> str:
    text = str(error)
    assert "\n" not in text and text.startswith("ControllerStep.step: "), text
    return text


@pytest.mark.parametrize("case", list(REFUSED))
def test_a_refused_call_names_its_argument_and_changes_nothing(case):
    """Each bad argument is refused in one line naming it (and its joint or axis); the step
    then gives, call after call, exactly the τ of a step that never saw the bad call. Fails
    if an argument is accepted (numpy broadcasting a scalar x_d, a NaN reaching τ), if the
    error is Pinocchio's, numpy's or LinAlgError, or if the refused call wrote the discrete
    state or the previous time."""
    args, expected = REFUSED[case]
    step, reference = planar(), planar()
    for k in range(2):
        step.step(*good_call(k))
        reference.step(*good_call(k))
    with pytest.raises(ControllerInputError) as caught:
        step.step(*args)
    assert isinstance(caught.value, ValueError)
    assert re.search(expected, message_of(caught.value)), str(caught.value)
    for k in range(2, 5):
        tau = step.step(*good_call(k)).tau.copy()
        np.testing.assert_array_equal(tau, reference.step(*good_call(k)).tau)
        assert np.all(np.isfinite(tau))


def test_a_prescribed_null_space_velocity_is_checked_like_the_rest():
    """q̇_dⁿ of the wrong length or with a NaN is refused naming desired_null_space_velocity
    (and the joint); a good one after it gives the τ of a step that never saw the bad one.
    Fails if a NaN q̇_dⁿ silently gives a NaN τ (as it did) or a short one a numpy error."""
    step, reference = planar(), planar()
    step.step(*good_call(0))
    reference.step(*good_call(0))
    qdot = np.array([0.1, -0.2, 0.3, 0.0])
    for value, expected in (
        (np.array([0.1, np.nan, 0.0, 0.0]), r"desired_null_space_velocity\[joint2\] is nan: must be finite"),
        (np.zeros(3), r"desired_null_space_velocity must be 4 joint speeds"),
        (0.1, r"desired_null_space_velocity must be 4 joint speeds"),
    ):
        with pytest.raises(ControllerInputError, match=expected):
            step.step(*good_call(1), desired_null_space_velocity=value)
    tau = step.step(*good_call(1), desired_null_space_velocity=qdot).tau
    np.testing.assert_array_equal(tau, reference.step(*good_call(1), desired_null_space_velocity=qdot).tau)


def test_without_a_force_axis_a_desired_force_is_refused_and_none_is_zero():
    """normal None: f_d is refused (it would change nothing) unless None, the wrench may be
    None (zero) or given, and R_d is refused on a task with no rotational axes. Fails if a
    desired force is silently dropped."""
    step = planar(normal=None)
    t, q, v, wrench, x_d, xdot_d, xddot_d, _ = good_call(0)
    with pytest.raises(
        ControllerInputError, match=r"f_d is 4\.0, but the task has no force axis .*pass None"
    ):
        step.step(t, q, v, wrench, x_d, xdot_d, xddot_d, 4.0)
    with pytest.raises(ControllerInputError, match=r"R_d is given, but the task has no rotational axes"):
        step.step(t, q, v, wrench, x_d, xdot_d, xddot_d, None, np.array([1.0, 0.0, 0.0, 0.0]))
    zero = step.step(t, q, v, None, x_d, xdot_d, xddot_d, None).tau.copy()
    other = planar(normal=None)
    np.testing.assert_array_equal(zero, other.step(t, q, v, np.zeros(6), x_d, xdot_d, xddot_d, None).tau)


def pose_step() -> ControllerStep:
    model = ControllerModel.from_urdf(SPATIAL, tool_frame="tool", task_axes=POSE)
    return ControllerStep(controller_model=model, config=ControllerConfig(period=T))


def pose_call(k: int, **rotation):
    rng = np.random.default_rng(k)
    q, v = SPATIAL_Q0 + 0.05 * rng.standard_normal(7), 0.2 * rng.standard_normal(7)
    x_d = np.array([0.3, 0.1, 0.4]) + 0.01 * rng.standard_normal(3)
    return (k * T, q, v, None, x_d, np.zeros(3), np.zeros(3), None), rotation


UNIT = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])


@pytest.mark.parametrize(
    "rotation, expected",
    [
        ({"R_d": np.zeros(4)}, r"R_d is the zero quaternion: it must be a rotation \[w, x, y, z\]"),
        ({"R_d": np.array([np.nan, 0.0, 0.0, 1.0])}, r"R_d\[w\] is nan: must be finite"),
        ({"R_d": np.array([1.0, 0.0, 0.0])}, r"R_d must be a quaternion \[w, x, y, z\]"),
        ({"R_d": UNIT, "omega_d": np.array([0.0, np.inf, 0.0])}, r"omega_d\[1\] is inf"),
        ({"omegadot_d": np.zeros(4)}, r"omegadot_d must be 3 numbers"),
    ],
)
def test_a_refused_rotation_keeps_the_last_good_one(rotation, expected):
    """A zero, NaN or mis-sized R_d (or ω_d, ω̇_d) is refused by name, and the next call
    that passes None keeps the last *good* R_d, ω_d, ω̇_d: the τ of a step that never saw
    the bad call. Fails if a zero quaternion silently means the identity (as it did) or if
    the refused values are kept for the calls that pass None."""
    step, reference = pose_step(), pose_step()
    args, _ = pose_call(0)
    step.step(*args, UNIT, np.array([0.1, 0.0, 0.0]), np.zeros(3))
    reference.step(*args, UNIT, np.array([0.1, 0.0, 0.0]), np.zeros(3))
    args, _ = pose_call(1)
    with pytest.raises(ControllerInputError, match=expected):
        step.step(*args, **rotation)
    for k in (1, 2):
        args, _ = pose_call(k)
        np.testing.assert_array_equal(step.step(*args).tau, reference.step(*args).tau)


def test_a_second_thread_is_refused_until_reset():
    """A ControllerStep belongs to the thread of its first call: another thread's call is
    refused in one line (it used to return the other thread's τ now and then), and after
    reset() the other thread may take it. Fails if a second thread's call goes through."""
    step = planar()
    step.step(*good_call(0))
    outcome = {}

    def other(key):
        try:
            outcome[key] = step.step(*good_call(1)).tau.copy()
        except ControllerInputError as e:
            outcome[key] = e

    thread = threading.Thread(target=other, args=("before reset",))
    thread.start()
    thread.join()
    error = outcome["before reset"]
    assert isinstance(error, ControllerInputError), error
    assert re.fullmatch(
        r"ControllerStep\.step: called from a second thread: .*make one per thread", str(error)
    )
    step.step(*good_call(1))  # the owner still may
    step.reset()
    thread = threading.Thread(target=other, args=("after reset",))
    thread.start()
    thread.join()
    np.testing.assert_array_equal(outcome["after reset"], planar().step(*good_call(1)).tau)
    with pytest.raises(ControllerInputError, match="second thread"):
        step.step(*good_call(2))  # now the main thread is the other one


# ------------------------------------------------------------------ the controller's ports


def fixed_context(controller, state, **inputs):
    context = controller.CreateDefaultContext()
    controller.GetInputPort("estimated_state").FixValue(context, state)
    for name, value in inputs.items():
        controller.GetInputPort(name).FixValue(context, value)
    return context


FORCE_INPUTS = {
    "measured_wrench": np.zeros(6),
    "desired_position": np.array([0.5, 0.4]),
    "desired_velocity": np.zeros(2),
    "desired_acceleration": np.zeros(2),
    "desired_force": np.array([4.0]),
}
STATE = np.r_[Q0, 0.1, -0.2, 0.0, 0.3]


@pytest.mark.parametrize("fused", [False, True], ids=["named", "fused"])
@pytest.mark.parametrize(
    "port, value, expected",
    [
        ("estimated_state", np.r_[Q0, 0.1, np.nan, 0.0, 0.3], r"estimated_state\[v joint2\] is nan"),
        ("estimated_state", np.r_[np.inf, Q0[1:], np.zeros(4)], r"estimated_state\[q joint1\] is inf"),
        ("desired_position", np.array([np.nan, 0.4]), r"desired_position\[x\] is nan"),
        ("desired_acceleration", np.array([0.0, -np.inf]), r"desired_acceleration\[y\] is -inf"),
        ("desired_force", np.array([np.nan]), r"desired_force is nan"),
        ("measured_wrench", np.r_[np.zeros(5), np.nan], r"measured_wrench\[5\] is nan"),
        (
            "desired_null_space_velocity",
            np.array([0.0, 0.0, np.nan, 0.0]),
            r"desired_null_space_velocity\[joint3\]",
        ),
    ],
)
def test_a_port_value_that_is_not_finite_is_named(fused, port, value, expected):
    """A NaN or inf on any input port raises ControllerInputError naming the controller, the
    time, the port and its entry, in both structures; the same context with the value
    repaired gives the τ of a context that never saw it. Fails if a NaN gives a silent NaN τ
    (f_d, q̇_dⁿ) or numba's LinAlgError (the state), as each did."""
    controller = NullSpaceImpedanceController(
        controller_model=ARM, config=config(), normal=[0.0, -1.0], fused=fused
    )
    good = {"estimated_state": STATE, **FORCE_INPUTS}
    inputs = {name: v for name, v in good.items() if name != "estimated_state"}
    context = fixed_context(controller, STATE, **inputs)
    controller.GetInputPort(port).FixValue(context, value)
    tau = controller.GetOutputPort("generalized_force")
    with pytest.raises(ControllerInputError) as caught:
        tau.Eval(context)
    text = str(caught.value)
    assert "\n" not in text and text.startswith("::controller at t = 0 s: "), text
    assert re.search(expected + r".*: must be finite", text), text
    if port != "desired_null_space_velocity":
        controller.GetInputPort(port).FixValue(context, good[port])
        np.testing.assert_array_equal(tau.Eval(context), tau.Eval(fixed_context(controller, STATE, **inputs)))


@pytest.mark.parametrize("fused", [False, True], ids=["named", "fused"])
def test_a_zero_desired_orientation_is_refused(fused):
    """desired_orientation [0, 0, 0, 0] is no rotation (the law read it as the identity):
    refused naming the port."""
    controller = NullSpaceImpedanceController(
        controller_model=SPATIAL, config=ControllerConfig(period=T), task_axes=POSE, fused=fused
    )
    context = fixed_context(
        controller,
        np.r_[SPATIAL_Q0, np.zeros(7)],
        desired_position=np.array([0.3, 0.1, 0.4]),
        desired_velocity=np.zeros(3),
        desired_acceleration=np.zeros(3),
        desired_orientation=np.zeros(4),
        desired_angular_velocity=np.zeros(3),
        desired_angular_acceleration=np.zeros(3),
    )
    with pytest.raises(ControllerInputError, match=r"desired_orientation is the zero quaternion"):
        controller.GetOutputPort("generalized_force").Eval(context)


@pytest.mark.parametrize("fused", [False, True], ids=["named", "fused"])
def test_a_desired_force_connected_without_a_force_axis_is_refused(fused):
    """normal None: a connected desired_force would change nothing, so evaluating the
    controller refuses it in one line; unconnected it reads zero, and a connected measured
    wrench (it enters Eq. 6's Jᵀ F) is still taken and changes τ."""
    controller = NullSpaceImpedanceController(controller_model=ARM, config=config(), fused=fused)
    positions = {k: v for k, v in FORCE_INPUTS.items() if k.startswith("desired_") and k != "desired_force"}
    tau = controller.GetOutputPort("generalized_force")
    with pytest.raises(ControllerInputError) as caught:
        tau.Eval(fixed_context(controller, STATE, desired_force=np.array([0.0]), **positions))
    text = str(caught.value)
    expected = (
        r"::controller input desired_force: connected, but the controller has no force axis \(normal=None\)"
    )
    assert re.match(expected, text) and "\n" not in text, text
    free = tau.Eval(fixed_context(controller, STATE, **positions))
    pushed = tau.Eval(
        fixed_context(controller, STATE, measured_wrench=np.r_[0, 0, 0, 1.0, 0, 0], **positions)
    )
    assert np.all(np.isfinite(free)) and np.abs(pushed - free).max() > 1e-3


def test_a_state_gone_nan_mid_run_in_a_users_diagram_is_named():
    """A user's diagram (plant, controller, constant references): the plant's velocity made
    NaN mid-run, as a diverging model would, stops AdvanceTo with the controller's one line
    naming estimated_state and the joint, not numba's LinAlgError."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=T), builder)
    Parser(plant).AddModelsFromString(ARM, "urdf")
    plant.Finalize()
    controller = builder.AddSystem(NullSpaceImpedanceController(controller_model=ARM, config=config()))
    builder.Connect(plant.get_state_output_port(), controller.GetInputPort("estimated_state"))
    builder.Connect(controller.GetOutputPort("generalized_force"), plant.get_actuation_input_port())
    for name, value in (
        ("desired_position", [0.5, 0.4]),
        ("desired_velocity", [0, 0]),
        ("desired_acceleration", [0, 0]),
    ):
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, dtype=float)))
        builder.Connect(source.get_output_port(), controller.GetInputPort(name))
    diagram = builder.Build()
    diagram.set_name("user")
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, Q0)
    simulator.AdvanceTo(0.02)
    plant_context.get_mutable_discrete_state_vector().SetAtIndex(
        2 * N - 1, np.nan
    )  # SetVelocities refuses NaN
    with pytest.raises(ControllerInputError) as caught:
        simulator.AdvanceTo(0.04)
    assert re.fullmatch(
        r"::user::controller at t = 0\.02 s: estimated_state\[v joint4\] is nan: must be finite",
        str(caught.value),
    ), str(caught.value)


def test_the_first_call_refuses_a_time_given_as_text():
    """numpy reads the text "0.1" as 0.1 when it is copied into an array: the first call
    (with no previous time to compare against) still refuses it, by name."""
    with pytest.raises(
        ControllerInputError, match=r"^ControllerStep\.step: t must be a finite number, got '0\.1'"
    ):
        planar().step("0.1", *good_call(0)[1:])


# ------------------------------------------------- nothing silently assumed (issue 36, item 3)


@pytest.mark.parametrize("missing", ["R_d", "omega_d", "omegadot_d"])
def test_a_rotation_never_given_is_refused_by_the_step_and_after_a_reset(missing):
    """A pose task's first call without R_d (or ω_d, ω̇_d) is refused naming it: R_d = None
    used to command the identity orientation (joints at their effort limits on issue 36's
    arm). After a good call None holds the last one; after reset() it must be given again.
    The τ of the call that holds equals the τ of a call that gives the same values again."""
    step, reference = pose_step(), pose_step()
    given = {"R_d": UNIT, "omega_d": np.array([0.1, 0.0, 0.0]), "omegadot_d": np.zeros(3)}
    first = {name: value for name, value in given.items() if name != missing}
    args, _ = pose_call(0)
    with pytest.raises(ControllerInputError) as caught:
        step.step(*args, **first)
    assert re.fullmatch(
        rf"ControllerStep\.step: {missing} is None on the first call \(since the step was made or "
        r"reset\(\)\), but the task has rotational axes \['rx', 'ry', 'rz'\]: give .*; "
        r"later calls may pass None to hold it",
        str(caught.value),
    ), str(caught.value)
    step.step(*args, **given)
    reference.step(*args, **given)
    args, _ = pose_call(1)
    np.testing.assert_array_equal(step.step(*args, **first).tau, reference.step(*args, **given).tau)
    step.reset()
    with pytest.raises(ControllerInputError, match=rf"{missing} is None on the first call"):
        step.step(*pose_call(0)[0], **first)


@pytest.mark.parametrize("fused", [False, True], ids=["named", "fused"])
@pytest.mark.parametrize(
    "missing", ["desired_orientation", "desired_angular_velocity", "desired_angular_acceleration"]
)
def test_a_rotation_port_never_connected_is_named_by_the_controllers_port(fused, missing):
    """The Diagram, named or fused, refuses an unconnected rotation input naming the
    controller's own port in one line (Drake named "InputPort[6] (R_d) of …
    impedance_controller", or the Multiplexer's u5 in the fused system)."""
    controller = NullSpaceImpedanceController(
        controller_model=SPATIAL, config=ControllerConfig(period=T), task_axes=POSE, fused=fused
    )
    inputs = {
        "desired_position": np.array([0.3, 0.1, 0.4]),
        "desired_velocity": np.zeros(3),
        "desired_acceleration": np.zeros(3),
        "desired_orientation": UNIT,
        "desired_angular_velocity": np.zeros(3),
        "desired_angular_acceleration": np.zeros(3),
    }
    del inputs[missing]
    context = fixed_context(controller, np.r_[SPATIAL_Q0, np.zeros(7)], **inputs)
    with pytest.raises(ControllerInputError) as caught:
        controller.GetOutputPort("generalized_force").Eval(context)
    assert str(caught.value) == (
        f"::controller input {missing}: not connected: the controller needs it at every tick "
        "(connect it, or fix its value)"
    )


def test_time_must_advance_by_whole_periods_and_skipped_periods_are_taken():
    """t repeated, between periods, or backwards: refused, the step as it was. Skipped
    periods (t two or more periods on) are taken however many calls in a row: nsdrake's
    drive on a loaded machine answers late for many statuses in a row, each time the
    newest (nsdrake/driver/loop.py), and its UDP silence test stopped on the step's refusal
    when ten skips in a row were refused. Fails if a stuck t is taken (it was: a second
    tick at the same time), if a skip is refused, or if a refused call changed the step."""
    step, reference = planar(), planar()
    args = list(good_call(0))
    step.step(*args)
    reference.step(*args)
    for t, expected in (
        (0.0, r"t = 0 s is the previous call's time again"),
        (
            0.5 * T,
            r"t = 0\.001 s is 0\.5 periods after the previous call's 0 s: t must advance by whole periods",
        ),
        (1.002 * T, r"t = 0\.002004 s is 1\.002 periods after"),
        (-T, r"t = -0\.002 s is before the previous call's 0 s"),
    ):
        with pytest.raises(ControllerInputError, match=expected):
            step.step(t, *args[1:])
    t = 0.0
    for k in range(30):  # thirty calls, each two or three periods on: taken
        t += (2 + k % 2) * T
        tau = step.step(t, *args[1:]).tau.copy()
        np.testing.assert_array_equal(tau, reference.step(t, *args[1:]).tau)  # the refusals changed nothing
        assert np.all(np.isfinite(tau))
    step.step(t + T * (1 + 1e-9), *args[1:])  # rounding of t is not a time between periods


def limited_step(robot_adds_gravity: bool = False) -> ControllerStep:
    """The planar force task with |τ| ≤ 30 N m and |dτ/dt| ≤ 500 N m/s (1 N m per period)."""
    c = config()
    c.actuator_limits.torque = {f"joint{k}": 30.0 for k in range(1, 5)}
    c.actuator_limits.torque_rate = {f"joint{k}": 500.0 for k in range(1, 5)}
    return ControllerStep(
        controller_model=ARM, config=c, normal=(0.0, -1.0), robot_adds_gravity=robot_adds_gravity
    )


@pytest.mark.parametrize("robot_adds_gravity", [False, True])
def test_a_held_torque_bounds_the_first_call_s_rate_and_a_bad_one_is_refused(robot_adds_gravity):
    """hold_torque gives the first call the torque applied before it (τ, or τ − g(q) when the
    robot adds g): the first τ (τ − g) is within ρ_max T = 1 N m of it on every joint, at
    exactly 1 N m where the free first call (no held torque) asks for more, towards that;
    holding the free call's own torque changes nothing, to the bit. A held torque that is
    not 4 finite numbers within the torque limits, or one given after the first call, is
    refused in one line naming it, the step as before (its next call's τ that of a step
    that never saw it). Catches the held torque ignored, taken with g when the robot adds g
    (or without it when it does not), and a refused one written half-way."""
    free = limited_step(robot_adds_gravity)
    tau_free = free.step(*good_call(0)).tau.copy()
    g = free.gravity.copy() if robot_adds_gravity else np.zeros(N)
    wanted = tau_free - g
    held = wanted - 5.0 * np.where(wanted > 0.0, 1.0, -1.0)  # 5 N m off, towards zero: within the limits
    step = limited_step(robot_adds_gravity)
    step.hold_torque(held)
    asked = step.step(*good_call(0)).tau - g
    np.testing.assert_allclose(np.abs(asked - held), 1.0, rtol=0, atol=1e-12)
    assert np.all(np.sign(asked - held) == np.sign(wanted - held))
    same = limited_step(robot_adds_gravity)
    same.hold_torque(wanted)
    np.testing.assert_array_equal(same.step(*good_call(0)).tau, tau_free)
    for torque, expected in (
        (np.zeros(3), r"torque must be 4 joint torques"),
        (np.array([0.0, np.nan, 0.0, 0.0]), r"torque\[joint2\] is nan: must be finite"),
        (np.array([0.0, 0.0, -31.0, 0.0]), r"torque\[joint3\] -31 N m is beyond the joint's torque limit 30"),
    ):
        refused, reference = limited_step(robot_adds_gravity), limited_step(robot_adds_gravity)
        with pytest.raises(ControllerInputError, match=expected) as caught:
            refused.hold_torque(torque)
        assert str(caught.value).startswith("ControllerStep.hold_torque: ") and "\n" not in str(caught.value)
        for k in range(3):
            np.testing.assert_array_equal(refused.step(*good_call(k)).tau, reference.step(*good_call(k)).tau)
    with pytest.raises(ControllerInputError, match="called after the first step"):
        step.hold_torque(held)
    step.reset()
    step.hold_torque(held)  # a reset forgets the first call: a torque may be held again

"""One rule for every public numeric argument (issue 34, item 3), fed the same hostile values.

Every public entry point that takes numbers (ControllerStep and its step, the controller's
constructor and input ports, the references and the contact pieces) takes real numbers
and real arrays of the right shape, and nothing else: text (numpy would read "0.40" as
0.4), booleans (True as 1), complex values (their imaginary part dropped), object arrays,
None where a value is needed, the wrong shape, NaN and inf are each refused in ONE line
naming the argument (nsdrake.control.validation.is_real_array, the one home of the rule).
Integers are taken: the same result as the same floats, and no new numba compile (an
integer t used to compile the kernels anew for int, 35 s).

The independent computation: for the refusals, the argument's name, which the test knows
and the message must carry; for the integers, the same call with floats, and numba's own
count of compiled signatures.
"""

from __future__ import annotations

import math
import re
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from models import PANDA_CIRCLE, serial_arm_urdf

from nsdrake import (
    CircleOnSurface,
    ControlHold,
    ControllerConfig,
    ControllerConfigError,
    ControllerInputError,
    ControllerModel,
    ControllerStep,
    NullSpaceImpedanceController,
    SlideAndPress,
    SurfaceReference,
    TaskReferenceError,
)
from nsdrake.experiment.reference import PlainSurfaceReference
from nsdrake.station.config import StationError

T = 0.002
ARM = serial_arm_urdf(["z"] * 4, [0.25] * 4, [1.0, 0.8, 0.6, 0.4], name="arm")
Q0 = np.array([0.4, 0.9, 1.0, 0.6])
SPATIAL = serial_arm_urdf(
    ["z", "y", "y", "x", "y", "z", "y"],
    [0.1, 0.3, 0.25, 0.1, 0.1, 0.05, 0.05],
    [2.0, 1.5, 1.0, 0.5, 0.4, 0.2, 0.1],
)
POSE = ("x", "y", "z", "rx", "ry", "rz")
SPATIAL_Q0 = np.array([0.3, 0.5, -0.8, 0.2, 0.6, 0.1, -0.4])
QUIET = settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)


def hostile(size: int | None, none_allowed: bool = False, sized: bool = True) -> st.SearchStrategy:
    """Values no numeric argument of ``size`` entries (None: a number) takes: text and
    numeric text, booleans, complex values, object arrays, None (where a value is needed),
    the wrong shape (unless not ``sized``: an argument that sets the size of the others),
    NaN and inf among good numbers."""
    good = 0.25 if size is None else [0.25] * size
    wrong_sizes = [k for k in range(0, 8) if k != size]
    values = [
        st.text(max_size=5),
        st.floats(allow_nan=False, allow_infinity=False).map(str),  # "0.4": numpy would read it
        st.booleans(),
        st.just(np.bool_(True)),
        st.complex_numbers(allow_nan=False, allow_infinity=False, min_magnitude=1e-3),
        st.just(np.array(good, dtype=object)),
        st.just(np.array(good, dtype=complex)),
        st.sampled_from([math.nan, math.inf, -math.inf]).map(
            lambda bad: bad if size is None else [*good[:-1], bad]
        ),
    ]
    if size is not None:
        values += [
            st.just([True] * size),
            st.just(np.ones(size, dtype=bool)),
            st.just([*good[:-1], True]),  # a bool among numbers: numpy makes it 1.0
            st.just([str(v) for v in good]),
            st.just(np.full((size, 1), 0.25)),
            st.just(0.25),
        ]
        if sized:
            values.append(st.sampled_from(wrong_sizes).map(lambda k: np.full(k, 0.25)))
    else:
        values += [st.just([0.25]), st.just(np.array([0.25, 0.5]))]
    if not none_allowed:
        values.append(st.none())
    return st.one_of(values)


def refused_naming(error_type, name: str, call) -> str:
    """The one-line message of ``call()``'s refusal, which must name ``name``."""
    with pytest.raises(error_type) as caught:
        call()
    text = str(caught.value)
    assert "\n" not in text, text
    assert name in text, f"{name!r} not named in: {text}"
    return text


# ------------------------------------------------------------------------ ControllerStep.step


def planar_step() -> ControllerStep:
    return ControllerStep(controller_model=ARM, config=ControllerConfig(period=T), normal=[0.0, -1.0])


PLANAR_STEP, REFERENCE_STEP = planar_step(), planar_step()
PLANAR_ARGS = {
    "t": (None, False),
    "q": (4, False),
    "v": (4, False),
    "wrench": (6, False),
    "x_d": (2, False),
    "xdot_d": (2, False),
    "xddot_d": (2, False),
    "f_d": (None, False),
}


def planar_call(**change) -> list:
    args = {
        "t": T,
        "q": Q0,
        "v": np.zeros(4),
        "wrench": np.r_[0.0, 0.0, 0.0, 0.0, -3.0, 0.0],
        "x_d": np.array([0.5, 0.4]),
        "xdot_d": np.zeros(2),
        "xddot_d": np.zeros(2),
        "f_d": 4.0,
    }
    args.update(change)
    return [args[name] for name in PLANAR_ARGS]


@pytest.mark.parametrize("name", list(PLANAR_ARGS))
@QUIET
@given(data=st.data())
def test_every_step_argument_refuses_what_is_not_real_numbers(name, data):
    """Each of step's arguments, given a hostile value on the call after a good one, is
    refused in one line that starts with the argument's name; the step then gives the τ of
    a step that never saw the bad call. Fails if numpy's reading of "0.40", True or 1+2j
    reaches τ (as each did), or if the message names another argument."""
    size, none_allowed = PLANAR_ARGS[name]
    value = data.draw(hostile(size, none_allowed))
    step = PLANAR_STEP
    step.reset()
    step.step(*planar_call(t=0.0))
    text = refused_naming(ControllerInputError, name, lambda: step.step(*planar_call(**{name: value})))
    assert text.split(": ", 1)[1].startswith((f"{name} ", f"{name}[", f"{name}=")), text
    tau = step.step(*planar_call()).tau.copy()
    fresh = REFERENCE_STEP
    fresh.reset()
    fresh.step(*planar_call(t=0.0))
    np.testing.assert_array_equal(tau, fresh.step(*planar_call()).tau)


POSE_STEP = ControllerStep(controller_model=SPATIAL, config=ControllerConfig(period=T), task_axes=POSE)
UNIT = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])


def pose_call(t: float, **rotation):
    args = (t, SPATIAL_Q0, np.zeros(7), None, np.array([0.3, 0.1, 0.4]), np.zeros(3), np.zeros(3), None)
    kept = {"R_d": UNIT, "omega_d": np.zeros(3), "omegadot_d": np.zeros(3)} | rotation
    return args, kept


@pytest.mark.parametrize(
    "name, size", [("R_d", 4), ("omega_d", 3), ("omegadot_d", 3), ("desired_null_space_velocity", 7)]
)
@QUIET
@given(data=st.data())
def test_the_rotation_and_the_prescribed_velocity_refuse_the_same_values(name, size, data):
    """R_d, ω_d, ω̇_d and q̇_dⁿ (keyword arguments; None means held, or the configured
    source, so None is not hostile here) refuse the same hostile values, naming themselves."""
    value = data.draw(hostile(size, none_allowed=True))
    step = POSE_STEP
    step.reset()
    args, rotation = pose_call(0.0)
    step.step(*args, **rotation)
    args, rotation = pose_call(T, **{name: value} if name != "desired_null_space_velocity" else {})
    extra = {name: value} if name == "desired_null_space_velocity" else {}
    refused_naming(ControllerInputError, name, lambda: step.step(*args, **rotation, **extra))


# --------------------------------------------------------------- constructors and references


PLANAR_MODEL = ControllerModel.from_urdf(ARM, tool_frame="tool", task_axes=("x", "y"))


def build_step(**change):
    return ControllerStep(controller_model=PLANAR_MODEL, config=ControllerConfig(period=T), **change)


def build_controller(**change):
    return NullSpaceImpedanceController(
        controller_model=PLANAR_MODEL, config=ControllerConfig(period=T), **change
    )


SLIDE = {
    "x0": np.array([0.3, 0.4]),
    "tangent": np.array([1.0, 0.0]),
    "normal": np.array([0.0, 1.0]),
    "tangent_speed": 0.05,
    "approach_speed": 0.03,
    "blend_time": 0.2,
    "force": 10.0,
    "force_ramp_time": 0.2,
}
SURFACE = {"contact_threshold": 0.5, "period": T, "loss_time": 0.05}

# (entry point, argument, (size, None allowed), error type)
CONSTRUCTORS = [
    (build_step, "normal", (2, True), ControllerConfigError),
    (build_step, "wrench_point", (3, True), ControllerConfigError),
    (build_controller, "normal", (2, True), ControllerConfigError),
    (build_controller, "wrench_point", (3, True), ControllerConfigError),
    *[
        (lambda **c: SlideAndPress(**(SLIDE | c)), name, (2, False), TaskReferenceError)
        for name in ("x0", "tangent", "normal")
    ],  # fmt: skip
    *[
        (lambda **c: SlideAndPress(**(SLIDE | c)), name, (None, False), TaskReferenceError)
        for name in (
            "tangent_speed",
            "approach_speed",
            "blend_time",
            "force",
            "force_ramp_time",
            "step_force",
            "max_overtravel",
        )
    ],  # fmt: skip
    (lambda **c: SlideAndPress(**(SLIDE | c)), "centre", (2, True), TaskReferenceError),
    *[
        (lambda **c: CircleOnSurface(**(PANDA_CIRCLE | c)), name, (3, False), TaskReferenceError)
        for name in ("x0", "tangent", "normal")
    ],  # fmt: skip
    *[
        (lambda **c: CircleOnSurface(**(PANDA_CIRCLE | c)), name, (None, False), TaskReferenceError)
        for name in ("radius", "laps", "speed", "start_angle", "delay", "approach_speed", "force")
    ],  # fmt: skip
    *[
        (
            lambda kind=kind, **c: kind(reference=SlideAndPress(**SLIDE), task_rows=[0, 1], **(SURFACE | c)),
            name,
            (None, False),
            TaskReferenceError,
        )
        for kind in (SurfaceReference, PlainSurfaceReference)
        for name in ("contact_threshold", "period", "loss_time")
    ],  # fmt: skip
    *[
        (lambda **c: ControlHold(**({"size": 2, "period": T} | c)), name, (None, False), StationError)
        for name in ("size", "period", "delay_periods")
    ],  # fmt: skip
]


@pytest.mark.parametrize(
    "make, name, spec, error", CONSTRUCTORS, ids=[f"{k}-{c[1]}" for k, c in enumerate(CONSTRUCTORS)]
)
@QUIET
@given(data=st.data())
def test_every_constructor_argument_refuses_what_is_not_real_numbers(make, name, spec, error, data):
    """The same hostile values given to each numeric argument of the constructors:
    refused in one line naming the argument (the piece's own error, a ValueError)."""
    value = data.draw(hostile(*spec))
    refused_naming(error, name, lambda: make(**{name: value}))


@pytest.mark.parametrize("kind", [SurfaceReference, PlainSurfaceReference])
@pytest.mark.parametrize(
    "rows",
    [[True, False], np.array([True, False]), [0.0, 1.0], np.array([0.0, 1.0]), ["0", "1"], [0, 1.0], None, 1],
    ids=["bool list", "bool array", "float list", "float array", "text", "mixed", "None", "scalar"],
)
def test_task_rows_are_indices_in_both_references(kind, rows):
    """task_rows [True, False] (numpy's rows [1, 0]: x and y swapped, a press along the
    normal never seen as contact) and [0.0, 1.0] (PlainSurfaceReference took it, then
    raised IndexError at its first tick) are refused by both references, the same line."""
    text = refused_naming(
        TaskReferenceError,
        "task_rows",
        lambda: kind(reference=SlideAndPress(**SLIDE), task_rows=rows, **SURFACE),
    )
    assert "as indices" in text, text


def test_task_rows_as_integers_of_any_kind_are_taken_and_read_the_right_force():
    """Python ints, numpy int64 scalars and arrays of every integer dtype (int8 … int64,
    uint8 … uint64) are taken; the plain reference then sees contact from a force along
    its normal (y: row 1), and not from the same force on x; arrays of every float dtype
    are refused (an index is counted, not measured). Fails if the rows were swapped or
    converted wrongly, or an integer family refused (issue 46: every dtype family at the
    index rule, as at the number rule)."""
    integer_dtypes = [d for d in REAL_DTYPES if np.dtype(d).kind in "iu"]  # every width, signed and not
    for rows in ([0, 1], (np.int64(0), np.int64(1)), *(np.array([0, 1], dtype=d) for d in integer_dtypes)):
        plain = PlainSurfaceReference(reference=SlideAndPress(**SLIDE), task_rows=rows, **SURFACE)
        plain.tick(0.0, np.zeros(6))
        plain.tick(T, np.r_[0.0, 0.0, 0.0, 5.0, 0.0, 0.0])  # 5 N along x: not the normal
        assert not plain.in_contact
        plain.tick(2 * T, np.r_[0.0, 0.0, 0.0, 0.0, 5.0, 0.0])  # 5 N along y, the normal
        plain.tick(3 * T, np.r_[0.0, 0.0, 0.0, 0.0, 5.0, 0.0])
        assert plain.in_contact
    for dtype in (d for d in REAL_DTYPES if np.dtype(d).kind == "f"):
        rows = np.array([0, 1], dtype=dtype)

        def make(rows=rows):
            return PlainSurfaceReference(reference=SlideAndPress(**SLIDE), task_rows=rows, **SURFACE)

        assert "as indices" in refused_naming(TaskReferenceError, "task_rows", make)


@pytest.mark.parametrize("name, size", [("t", None), ("wrench", 6)])
@QUIET
@given(data=st.data())
def test_the_plain_reference_tick_refuses_the_same_values(name, size, data):
    """PlainSurfaceReference.tick (the drive's reference): t and the wrench refused by name."""
    value = data.draw(hostile(size))
    plain = PlainSurfaceReference(reference=SlideAndPress(**SLIDE), task_rows=[0, 1], **SURFACE)
    args = {"t": 0.0, "wrench": np.zeros(6)} | {name: value}
    refused_naming(TaskReferenceError, f"tick.{name}", lambda: plain.tick(**args))


# ----------------------------------------------------------------- integers, and no compile


def compiled_signatures() -> int:
    """Every signature numba has compiled (or loaded from its cache) for nsdrake's kernels
    in this process, summed over every dispatcher of every nsdrake module."""
    from numba.core.dispatcher import Dispatcher

    total, seen = 0, set()
    for module_name, module in list(sys.modules.items()):
        if not module_name.startswith("nsdrake") or module is None:
            continue
        for value in vars(module).values():
            if isinstance(value, Dispatcher) and id(value) not in seen:
                seen.add(id(value))
                total += len(value.signatures)
    return total


@settings(max_examples=15, deadline=None, derandomize=True)
@given(
    q=st.lists(st.integers(-1, 2), min_size=4, max_size=4),
    v=st.lists(st.integers(-2, 2), min_size=4, max_size=4),
    f_d=st.integers(0, 10),
    t=st.integers(0, 3),
)
def test_integers_give_the_floats_result_without_a_new_compile(q, v, f_d, t):
    """An integer t, integer arrays (numpy's and lists) and an integer f_d give, to the last
    bit, the τ of the same numbers as floats, and numba compiles nothing new: the count of
    compiled signatures is the same before and after the integer call. Fails if an int
    reaches a kernel (a new signature: the 35 s compile of issue 34) or is read wrongly."""
    step = PLANAR_STEP
    args = dict(wrench=[0, 0, 0, 0, -3, 0], x_d=[1, 0], xdot_d=[0, 0], xddot_d=[0, 0])
    step.reset()
    expected = step.step(float(t), np.array(q, float), np.array(v, float), *(
        np.array(a, float) for a in args.values()), float(f_d)).tau.copy()  # fmt: skip
    before = compiled_signatures()
    assert before > 0  # the kernels are found
    for as_ints in (np.array, list):
        step.reset()
        tau = step.step(t, as_ints(q), as_ints(v), *(as_ints(a) for a in args.values()), f_d).tau
        np.testing.assert_array_equal(tau, expected)
    assert compiled_signatures() == before


# every numpy dtype of real numbers, by family: signed and unsigned integers of each width,
# floats of each width (issue 46, mistake 6: one dtype family was untested)
REAL_DTYPES = [
    np.int8, np.int16, np.int32, np.int64, np.uint8, np.uint16, np.uint32, np.uint64,
    np.float16, np.float32, np.float64, np.longdouble,
]  # fmt: skip
NOT_REAL_DTYPES = [
    np.bool_, np.complex64, np.complex128, object, "U4", "S4", "datetime64[s]", "timedelta64[s]",
]  # fmt: skip


@pytest.mark.parametrize("dtype", REAL_DTYPES, ids=lambda d: np.dtype(d).name)
def test_every_real_dtype_is_taken_and_gives_the_float64_result(dtype):
    """q, q̇ and every reference and wrench as arrays of ``dtype``, t and f_d as its scalars,
    of numbers each dtype holds exactly (non-negative whole numbers below 256, so uint8 and
    float16 too): τ is the float64 call's to the last bit, and numba compiles nothing new.
    Catches a dtype family refused by the number rule (unsigned integers: their kind "u"
    left out), or one that reaches a kernel (a new signature)."""
    q, v = [0, 1, 1, 0], [0, 1, 0, 2]
    args = dict(wrench=[0, 0, 0, 0, 3, 0], x_d=[1, 0], xdot_d=[0, 0], xddot_d=[0, 0])
    step = PLANAR_STEP
    step.reset()
    expected = step.step(
        1.0, np.array(q, float), np.array(v, float), *(np.array(a, float) for a in args.values()), 4.0
    ).tau.copy()
    before = compiled_signatures()
    step.reset()
    typed = (np.array(a, dtype=dtype) for a in args.values())
    tau = step.step(np.dtype(dtype).type(1), np.array(q, dtype=dtype), np.array(v, dtype=dtype), *typed,
                    np.dtype(dtype).type(4)).tau  # fmt: skip
    np.testing.assert_array_equal(tau, expected)
    assert compiled_signatures() == before


@pytest.mark.parametrize("dtype", NOT_REAL_DTYPES, ids=lambda d: np.dtype(d).name)
def test_every_dtype_that_is_not_real_numbers_is_refused(dtype):
    """The other dtype families (booleans, complex, objects, text, bytes, dates, time spans)
    as q: refused in one line naming q, whatever the values. Catches a number rule that
    takes any numpy array whose values convert (a timedelta64 array converts to float)."""
    value = np.zeros(4, dtype=np.int64).astype(dtype)
    step = PLANAR_STEP
    step.reset()
    refused_naming(ControllerInputError, "q", lambda: step.step(*planar_call(q=value)))


def test_an_integer_time_on_the_pose_task_compiles_nothing_new():
    """The pose task's step with t = 0 (an int), an integer quaternion and integer ω_d:
    the τ of the floats, no new signature."""
    step = POSE_STEP
    step.reset()
    args, rotation = pose_call(0.0, R_d=np.array([1.0, 0.0, 0.0, 0.0]))
    expected = step.step(*args, **rotation).tau.copy()
    before = compiled_signatures()
    step.reset()
    args, rotation = pose_call(0, R_d=[1, 0, 0, 0], omega_d=[0, 0, 0], omegadot_d=np.zeros(3, dtype=int))
    np.testing.assert_array_equal(step.step(*args, **rotation).tau, expected)
    assert compiled_signatures() == before


# ---------------------------------------------------------------- the controller's input ports

PORTS = {
    "estimated_state": np.r_[Q0, 0.1, -0.2, 0.0, 0.3],
    "measured_wrench": np.zeros(6),
    "desired_position": np.array([0.5, 0.4]),
    "desired_velocity": np.zeros(2),
    "desired_acceleration": np.zeros(2),
    "desired_force": np.array([4.0]),
}
FORCE_CONTROLLERS = {
    fused: NullSpaceImpedanceController(
        controller_model=ARM, config=ControllerConfig(period=T), normal=[0.0, -1.0], fused=fused
    )
    for fused in (False, True)
}


@pytest.mark.parametrize("fused", [False, True], ids=["named", "fused"])
@pytest.mark.parametrize("port", list(PORTS))
@settings(max_examples=8, deadline=None, derandomize=True)
@given(bad=st.sampled_from([math.nan, math.inf, -math.inf, None]), entry=st.integers(0, 7))
def test_every_input_port_refuses_a_value_it_cannot_use_naming_the_port(fused, port, bad, entry):
    """A port's value reaches the controller as Drake's doubles (FixValue or a connected
    system converts it; a str is Drake's own TypeError), so what the controller can refuse
    there is NaN, inf and no value at all (None here: the port left unconnected). Each is
    one line naming the controller's port, not an inner system's."""
    controller = FORCE_CONTROLLERS[fused]
    context = controller.CreateDefaultContext()
    for name, value in PORTS.items():
        if name != port or bad is not None:
            controller.GetInputPort(name).FixValue(context, value)
    if bad is not None:
        value = PORTS[port].copy()
        value[entry % value.size] = bad
        controller.GetInputPort(port).FixValue(context, value)
    text = refused_naming(
        ControllerInputError, port, lambda: controller.GetOutputPort("generalized_force").Eval(context)
    )
    assert "impedance_controller" not in text and "Multiplexer" not in text and "InputPort[" not in text, text


@pytest.mark.parametrize(
    "bad, expected",
    [
        (np.r_[0.0, 0.0, 0.0, 0.0, np.nan, 0.0], r"measured_wrench\[4\] is nan: must be finite"),
        (None, r"measured_wrench is not connected"),
    ],
)
def test_the_surface_reference_refuses_a_wrench_it_cannot_read(bad, expected):
    """SurfaceReference's measured_wrench NaN (its force never reaches the threshold: contact
    silently never detected) or unconnected: one line naming the port at the first update."""
    from pydrake.systems.analysis import Simulator

    reference = SurfaceReference(reference=SlideAndPress(**SLIDE), task_rows=[0, 1], **SURFACE)
    simulator = Simulator(reference)
    if bad is not None:
        reference.GetInputPort("measured_wrench").FixValue(simulator.get_mutable_context(), bad)
    with pytest.raises(TaskReferenceError) as caught:
        simulator.AdvanceTo(2 * T)
    assert "\n" not in str(caught.value) and re.search(expected, str(caught.value)), str(caught.value)


def test_the_models_gravity_takes_the_same_rule():
    """ControllerModel.from_urdf's gravity: text and booleans refused naming it."""
    for gravity in ([0, 0, "-9.81"], [False, 0.0, -9.81], np.array([0, 0, -9.81], dtype=complex)):
        refused_naming(
            ControllerConfigError,
            "gravity",
            lambda g=gravity: ControllerModel.from_urdf(
                ARM, tool_frame="tool", task_axes=("x", "y"), gravity=g
            ),
        )

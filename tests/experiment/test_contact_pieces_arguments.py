"""The public contact pieces refuse, when they are made, arguments they cannot work with
(issue 24, item 7): ForceSensor, SlideAndPress, CircleOnSurface and SurfaceReference.

Each refusal is one line (a ValueError subclass: StationError for the sensor,
TaskReferenceError for the references) naming the piece and the argument. Each test also
checks that the good arguments next to the bad one are taken and behave (the independent
computation: the piece's own output for a case whose answer is known by hand), so a check
that refuses everything fails too.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from models import PANDA_CIRCLE
from pydrake.all import (
    MultibodyPlant,
    RevoluteJoint,
    RigidTransform,
    Simulator,
    SpatialInertia,
    WeldJoint,
)

from nsdrake import CircleOnSurface, ForceSensor, SlideAndPress, SurfaceReference, TaskReferenceError
from nsdrake.experiment.reference import PlainSurfaceReference
from nsdrake.station.config import StationError


def plate_plant(finalize: bool = True):
    """A 2 kg plate on a weld to the world (the sensor) and a second body on a revolute joint."""
    plant = MultibodyPlant(0.0)
    plate = plant.AddRigidBody(
        "plate", plant.AddModelInstance("plate"), SpatialInertia.SolidBoxWithMass(2.0, 0.3, 0.02, 0.3)
    )
    weld = plant.AddJoint(
        WeldJoint("mount", plant.world_frame(), plate.body_frame(), RigidTransform([0.0, 0.0, 0.1]))
    )
    link = plant.AddRigidBody(
        "link", plant.AddModelInstance("link"), SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.1)
    )
    hinge = plant.AddJoint(RevoluteJoint("hinge", plant.world_frame(), link.body_frame(), [0.0, 0.0, 1.0]))
    if finalize:
        plant.Finalize()
    return plant, weld, hinge


def test_the_force_sensor_takes_only_a_weld_of_its_finalized_plant():
    """A revolute joint (its reaction lacks the moment about its axis), None, a joint of
    another plant, a plant not finalized: each refused in one line naming the argument.
    The weld is taken and its tare holds the plate's weight, m g = 2 × 9.81 N upward."""
    plant, weld, hinge = plate_plant()
    other, other_weld, _ = plate_plant()
    unfinished, unfinished_weld, _ = plate_plant(finalize=False)
    cases = [
        (plant, hinge, r"ForceSensor: sensor_joint 'hinge' is a revolute joint: it must be a weld"),
        (plant, None, r"ForceSensor: sensor_joint must be a weld joint of the plant, got NoneType"),
        (plant, "mount", r"ForceSensor: sensor_joint must be a weld joint of the plant, got str"),
        (plant, other_weld, r"ForceSensor: sensor_joint 'mount' is a joint of another plant"),
        (unfinished, unfinished_weld, r"ForceSensor: plant must be finalized"),
        (None, weld, r"ForceSensor: plant must be a MultibodyPlant, got NoneType"),
    ]
    for p, joint, expected in cases:
        with pytest.raises(StationError) as caught:
            ForceSensor(plant=p, sensor_joint=joint)
        assert isinstance(caught.value, ValueError)
        assert re.match(expected, str(caught.value)) and "\n" not in str(caught.value), str(caught.value)
    sensor = ForceSensor(plant=plant, sensor_joint=weld)
    np.testing.assert_allclose(sensor.tare[3:], [0.0, 0.0, 2.0 * 9.81], rtol=1e-12)


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


@pytest.mark.parametrize(
    "change, expected",
    [
        ({"x0": np.array([np.nan, 0.4])}, r"SlideAndPress\.x0: must be the tool position"),
        ({"x0": None}, r"SlideAndPress\.x0: must be the tool position"),
        ({"x0": np.zeros((2, 2))}, r"SlideAndPress\.x0: must be the tool position"),
        ({"normal": np.zeros(2)}, r"SlideAndPress\.normal: must be a unit direction \(norm 1\), got norm 0"),
        (
            {"normal": np.array([0.0, 2.0])},
            r"SlideAndPress\.normal: must be a unit direction \(norm 1\), got norm 2",
        ),
        (
            {"normal": np.array([0.0, 1.0, 0.0])},
            r"SlideAndPress\.normal: must be a unit direction of 2 numbers",
        ),
        ({"normal": np.array([np.nan, 1.0])}, r"SlideAndPress\.normal: must be finite"),
        (
            {"tangent": np.zeros(2)},
            r"SlideAndPress\.tangent: must be a unit direction \(norm 1\), got norm 0",
        ),
        ({"tangent": np.array([0.6, 0.8])}, r"SlideAndPress\.tangent: must be perpendicular to normal"),
        ({"tangent_speed": math.nan}, r"SlideAndPress\.tangent_speed: must be a finite number"),
        ({"approach_speed": -0.01}, r"SlideAndPress\.approach_speed: must be >= 0"),
        ({"blend_time": math.inf}, r"SlideAndPress\.blend_time: must be a finite number"),
        ({"force": -1.0}, r"SlideAndPress\.force: must be >= 0"),
        ({"force_ramp_time": "fast"}, r"SlideAndPress\.force_ramp_time: must be a finite number, got 'fast'"),
        ({"step_time": 0.0}, r"SlideAndPress\.step_time: must be > 0, got 0.0 \(math.inf: no step\)"),
        ({"step_time": math.nan}, r"SlideAndPress\.step_time: must be a finite number"),
        ({"max_overtravel": -0.01}, r"SlideAndPress\.max_overtravel: must be >= 0"),
        ({"centre": np.zeros(3)}, r"SlideAndPress\.centre: must be 2 numbers"),
        ({"reach": 0.0}, r"SlideAndPress\.reach: must be > 0"),
    ],
)
def test_slide_and_press_refuses_what_it_cannot_follow(change, expected):
    """A NaN start, a zero or non-unit normal, a tangent along the normal, a negative
    speed, time or force, step_time 0: each refused naming the field (they used to give NaN
    or silently wrong references). Fails if the check is missing or names another field."""
    with pytest.raises(TaskReferenceError) as caught:
        SlideAndPress(**(SLIDE | change))
    assert re.match(expected, str(caught.value)) and "\n" not in str(caught.value), str(caught.value)


def test_slide_and_press_takes_lists_and_a_zero_tangent_without_a_slide():
    """Lists are taken as arrays; without a slide (tangent_speed 0, as CircleOnSurface's
    press) a zero tangent is no direction needed. The reference at t = 1 s before contact
    is x0 + s(1) n with s the approach ramp: 0.03 (1 − 0.1) = 0.027 m, by hand."""
    path = SlideAndPress(**(SLIDE | {"x0": [0.3, 0.4], "tangent": [0.0, 0.0], "tangent_speed": 0.0}))
    x_d, xdot_d, _, f_d = path.at(1.0)
    np.testing.assert_allclose(x_d, [0.3, 0.4 + 0.03 * (1.0 - 0.1)], rtol=0, atol=1e-15)
    np.testing.assert_allclose(xdot_d, [0.0, 0.03], rtol=0, atol=1e-15)
    assert f_d == 0.0


@pytest.mark.parametrize(
    "change, expected",
    [
        ({"radius": 0.0}, r"CircleOnSurface\.radius: must be > 0, got 0.0"),
        ({"radius": -0.1}, r"CircleOnSurface\.radius: must be > 0"),
        ({"speed": 0.0}, r"CircleOnSurface\.speed: must not be zero"),
        ({"speed": math.inf}, r"CircleOnSurface\.speed: must be a finite number"),
        ({"laps": 0.0}, r"CircleOnSurface\.laps: must be > 0"),
        (
            {"laps": 0.001},
            r"CircleOnSurface\.laps: the circle \(0.0006283 m\) is shorter than its speed blends",
        ),
        ({"start_angle": math.nan}, r"CircleOnSurface\.start_angle: must be a finite number"),
        ({"delay": -1.0}, r"CircleOnSurface\.delay: must be >= 0"),
        ({"x0": np.array([0.5, 0.0])}, r"CircleOnSurface\.x0: must be \[x, y, z\]"),
        ({"x0": np.array([0.5, np.nan, 0.1])}, r"CircleOnSurface\.x0: must be finite"),
        (
            {"normal": np.zeros(3)},
            r"CircleOnSurface\.normal: must be a unit direction \(norm 1\), got norm 0",
        ),
        (
            {"tangent": np.array([0.0, 0.0, 1.0])},
            r"CircleOnSurface\.tangent: must be perpendicular to normal",
        ),
        ({"tangent": np.zeros(3)}, r"CircleOnSurface\.tangent: must be a unit direction"),
    ],
)
def test_circle_on_surface_refuses_what_it_cannot_draw(change, expected):
    """Radius 0 (a circle of no length, s/r = 0/0), speed 0 (its duration divides by it),
    a circle shorter than its speed blends, a NaN angle, a zero normal or tangent: refused
    naming the field."""
    with pytest.raises(TaskReferenceError) as caught:
        CircleOnSurface(**(PANDA_CIRCLE | change))
    assert re.match(expected, str(caught.value)) and "\n" not in str(caught.value), str(caught.value)


def test_a_good_circle_is_taken_and_drawn():
    """The good arguments are taken: a quarter of the way round after its blend, the tool
    is on the circle of radius 0.1 m about the centre c = p_c − r u(φ₀), by hand."""
    path = CircleOnSurface(**(PANDA_CIRCLE | {"laps": 1.0}))
    t_c = 0.5
    start = path.at(t_c, t_c)[0]
    centre = start - 0.1 * np.array([0.0, -1.0, 0.0])  # u(−π/2) = −t₂, t₂ = t₁ × n = (0, 1, 0)
    for t in (2.0, 5.0, 9.0):
        assert abs(np.linalg.norm(path.at(t, t_c)[0] - centre) - 0.1) < 1e-12


@pytest.mark.parametrize(
    "change, expected",
    [
        (
            {"task_rows": [0, 5]},
            r"SurfaceReference\.task_rows: must be 2 distinct rows of the measured force",
        ),
        ({"task_rows": [0]}, r"SurfaceReference\.task_rows: must be 2 distinct rows"),
        ({"task_rows": [1, 1]}, r"SurfaceReference\.task_rows: must be 2 distinct rows"),
        ({"task_rows": [0, -1]}, r"SurfaceReference\.task_rows: must be 2 distinct rows"),
        ({"task_rows": [0.5, 1]}, r"SurfaceReference\.task_rows: must be 2 distinct rows"),
        ({"task_rows": "xy"}, r"SurfaceReference\.task_rows: must be 2 distinct rows"),
        ({"period": 0.0}, r"SurfaceReference\.period: must be > 0, got 0.0"),
        ({"period": math.nan}, r"SurfaceReference\.period: must be a finite number"),
        ({"contact_threshold": -1.0}, r"SurfaceReference\.contact_threshold: must be > 0, got -1.0"),
        ({"contact_threshold": 0.0}, r"SurfaceReference\.contact_threshold: must be > 0"),
        ({"loss_time": 0.0}, r"SurfaceReference\.loss_time: must be > 0"),
        ({"reference": None}, r"SurfaceReference\.reference: must be a SlideAndPress or a CircleOnSurface"),
    ],
)
@pytest.mark.parametrize("made", [SurfaceReference, PlainSurfaceReference], ids=lambda c: c.__name__)
def test_the_surface_reference_refuses_what_would_fail_mid_run(change, expected, made):
    """An out-of-range task row (IndexError mid-simulation, as it was), period 0 (Drake's
    error later), a contact threshold ≤ 0 (contact declared with no force): refused when
    the reference is made, naming the argument; the same by the drive's plain reference
    (which took them all before, and failed in the loop)."""
    arguments = {
        "reference": SlideAndPress(**SLIDE),
        "task_rows": [0, 1],
        "contact_threshold": 0.5,
        "period": 0.002,
    }
    with pytest.raises(TaskReferenceError) as caught:
        made(**(arguments | change))
    message = str(caught.value)
    assert re.match(expected.replace("SurfaceReference", made.__name__), message), message
    assert "\n" not in message


def test_the_surface_reference_declares_contact_only_with_force():
    """With good arguments (rows [2, 0]: the force's z and x), the reference declares
    contact once the measured normal force reaches the threshold and not with no force,
    f_n = n · f[rows] read on the rows given, and f_d then ramps from the contact."""
    reference = SurfaceReference(
        reference=SlideAndPress(**SLIDE), task_rows=np.array([2, 0]), contact_threshold=0.5, period=0.002
    )
    for force, expected in ((np.zeros(3), 0.0), (np.array([0.6, 0.0, 0.0]), 1.0)):  # n = (0, 1): f_x on row 0
        simulator = Simulator(reference)
        context = simulator.get_mutable_context()
        reference.get_input_port().FixValue(context, np.r_[np.zeros(3), force])
        simulator.AdvanceTo(0.01)
        assert reference.GetOutputPort("in_contact").Eval(context)[0] == expected
        u = 0.01 / 0.2  # f_d ramps from contact at t = 0: force (3u² − 2u³), by hand
        f_d = reference.GetOutputPort("f_d").Eval(context)[0]
        assert f_d == (0.0 if expected == 0.0 else pytest.approx(10.0 * (3 * u**2 - 2 * u**3), rel=1e-12))

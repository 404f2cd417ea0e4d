"""A model file's joint damping D in the controller's model (issue 42): D q̇ in C q̇ and the
inertia T_D D it adds over a held command on H's diagonal (nsdrake.control.dynamics.ArmModel),
against Drake's own discrete plant of the same URDF text (no nsdrake code steps it).

The arm is tests/vendor_arm.py's 7-joint arm with the xArm7's declared damping
(xarm7.urdf: 10, 10, 5, 5, 5, 2, 2 N m s/rad), so that h D / H_jj reaches ≈ 2 on the wrist
at a 1 ms step: the damping's inertia is no rounding there."""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from nsdrake.control import ControllerConfigError, ControllerModel, model_files
from nsdrake.control.model import symmetric_and_inverse
from nsdrake.experiment.diagram import controller_model
from nsdrake.experiment.scenario import load_scenario_file
from nsdrake.experiment.scenario_station import add_scenario_station
from tests.vendor_arm import Q0, mesh_free_urdf

POSE = ("x", "y", "z", "rx", "ry", "rz")
DAMPING = (10.0, 10.0, 5.0, 5.0, 5.0, 2.0, 2.0)  # the xArm7's <dynamics damping> [N m s/rad]
STEP = 1e-3  # Drake's plant step h, one per control period [s]


def damped_urdf() -> str:
    """The arm's mesh-free URDF with ``<dynamics damping>`` on its seven joints."""
    root = ET.fromstring(mesh_free_urdf())
    joints = [j for j in root.findall("joint") if j.get("type") == "revolute"]
    for joint, d in zip(joints, DAMPING, strict=True):
        ET.SubElement(joint, "dynamics", damping=str(d))
    return ET.tostring(root, encoding="unicode")


def drakes_next_velocity(
    text: str, q: np.ndarray, v: np.ndarray, tau: np.ndarray, period: float = STEP, steps: int = 1
) -> np.ndarray:
    """v after ``period`` of Drake's discrete plant of ``text``, stepping ``steps`` times
    (h = period / steps), from (q, v) under the generalized force ``tau`` held."""
    plant = MultibodyPlant(period / steps)
    Parser(plant).AddModelsFromString(text, "urdf")
    plant.Finalize()
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, np.concatenate([q, v]))
    plant.get_applied_generalized_force_input_port().FixValue(context, tau)
    plant.get_actuation_input_port().FixValue(context, np.zeros(plant.num_actuated_dofs()))
    simulator = Simulator(plant, context)
    simulator.AdvanceTo(period)  # steps at t = 0, h, …, period − h
    return plant.GetVelocities(context)


def predicted_velocity(model: ControllerModel, q, v, tau, period: float = STEP) -> np.ndarray:
    """v + T H⁻¹ (τ − C q̇ − g): the model's Eq. 5 over a period T, its terms as the law reads them."""
    terms = model.terms(model.create_scratch(), q, v, False)
    return v + period * np.linalg.solve(terms.H, tau - terms.Cv - terms.g)


def states(count: int = 3, seed: int = 7):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield Q0 + 0.3 * rng.standard_normal(7), rng.uniform(-1.0, 1.0, 7), rng.uniform(-20.0, 20.0, 7)


@pytest.mark.parametrize("dynamics", ["drake", "pinocchio"])
def test_one_step_of_drakes_discrete_plant_is_the_models_prediction_with_h_d_added_to_h(dynamics):
    """With ``damping_time`` = h the model predicts Drake's discrete step exactly: the plant
    integrates the damping implicitly, M (v⁺ − v) = h (τ − b − g − D v⁺), which is
    (M + h D)(v⁺ − v) = h (τ − b − g − D v), the model's H and C q̇. Tolerance 1e-9 of the
    velocity change |v⁺ − v| (rounding only: the two are the same linear equation). The term
    dropped (T_D = 0, the law before issue 42) or doubled (2 h) misses by more than 10% of the
    change, as does D q̇ dropped from C q̇; the test checks that it would."""
    text = damped_urdf()
    model = ControllerModel.from_urdf(
        text, tool_frame="tool", task_axes=POSE, dynamics=dynamics, damping_time=STEP
    )
    dropped, doubled = (
        ControllerModel.from_urdf(text, tool_frame="tool", task_axes=POSE, dynamics=dynamics, damping_time=t)
        for t in (0.0, 2 * STEP)
    )
    assert model.dynamics == dynamics
    np.testing.assert_array_equal(model.arm.damping, DAMPING)
    for q, v, tau in states():
        v_next = drakes_next_velocity(text, q, v, tau)
        change = float(np.linalg.norm(v_next - v))
        error = float(np.linalg.norm(predicted_velocity(model, q, v, tau) - v_next))
        assert error <= 1e-9 * change, (error, change)
        for wrong in (dropped, doubled):
            assert np.linalg.norm(predicted_velocity(wrong, q, v, tau) - v_next) > 0.1 * change


def test_with_several_plant_steps_per_period_half_the_period_plus_half_a_step_is_nearest():
    """The plant stepping k = 4 times per period T = 0.2 ms (T D / H_jj ≈ 0.4 on the wrist,
    within the first-order regime): the model with T_D = (T + h)/2 (ArmModel; what a scenario
    derives: nsdrake.experiment.diagram.simulated_damping_time) predicts the velocity after T
    within 2% of its change and at most half the error of T_D = h, T, T/2 or 0 (measured:
    1.3–1.6% against 6–19% and 30–35% for 0). Taking one plant step's h as T_D whatever k,
    or T, fails this."""
    text, period, steps = damped_urdf(), 2e-4, 4
    h = period / steps
    model, *others = (
        ControllerModel.from_urdf(text, tool_frame="tool", task_axes=POSE, dynamics="drake", damping_time=t)
        for t in ((period + h) / 2, h, period, period / 2, 0.0)
    )
    for q, v, tau in states(2):
        v_next = drakes_next_velocity(text, q, v, tau, period, steps)
        change = float(np.linalg.norm(v_next - v))
        error = float(np.linalg.norm(predicted_velocity(model, q, v, tau, period) - v_next))
        assert error <= 0.02 * change
        for other in others:
            assert error <= 0.5 * np.linalg.norm(predicted_velocity(other, q, v, tau, period) - v_next)


def test_the_in_place_mass_matrix_of_the_compiled_stages_carries_h_d_too():
    """The controller's compiled stages read Pinocchio's mass matrix in place (``update``),
    not through ``terms``: it carries T_D D as the terms' H does (Pinocchio's armature), to
    1e-12 relative. A T_D D added in ``terms`` only (the compiled law without it) fails this."""
    model = ControllerModel.from_urdf(
        damped_urdf(), tool_frame="tool", task_axes=POSE, dynamics="pinocchio", damping_time=STEP
    )
    pin, scratch = model.pinocchio, model.create_scratch()
    order = pin.order
    for q, v, _ in states(2, seed=11):
        pin.update(scratch.pinocchio, q, v, False)
        H = symmetric_and_inverse(scratch.pinocchio.M)[0][np.ix_(order, order)]
        expected = model.terms(scratch, q, v, False).H
        np.testing.assert_allclose(H, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))
        bare = ControllerModel.from_urdf(damped_urdf(), tool_frame="tool", task_axes=POSE, damping_time=0.0)
        H0 = bare.terms(bare.create_scratch(), q, v, False).H
        np.testing.assert_allclose(np.diag(H - H0), STEP * np.array(DAMPING), rtol=1e-9)


@pytest.mark.parametrize(
    "value, says",
    [
        (-1e-3, "damping_time: must be a finite time >= 0 [s]"),
        (float("nan"), "damping_time: must be a finite time >= 0 [s]"),
        ("1 ms", "damping_time: must be a time [s] or None, got '1 ms'"),
    ],
)
def test_a_damping_time_that_is_no_time_is_refused_in_one_line(value, says):
    with pytest.raises(ControllerConfigError) as e:
        ControllerModel.from_urdf(damped_urdf(), tool_frame="tool", task_axes=POSE, damping_time=value)
    assert "\n" not in str(e.value) and str(e.value).startswith(says)


def test_an_unstated_damping_time_on_a_damped_model_is_said_in_one_line(caplog, monkeypatch):
    """None on a model with damping: the damping's inertia taken as 0, said once in one line
    naming the joints' damping and what to state; a model without damping says nothing."""
    monkeypatch.setattr(model_files, "_SAID", set())  # what this process said before
    with caplog.at_level(logging.WARNING, logger="nsdrake"):
        model = ControllerModel.from_urdf(damped_urdf(), tool_frame="tool", task_axes=POSE)
        ControllerModel.from_urdf(damped_urdf(), tool_frame="tool", task_axes=POSE)
        ControllerModel.from_urdf(mesh_free_urdf(), tool_frame="tool", task_axes=POSE)
    lines = [r.getMessage() for r in caplog.records if "damping_time" in r.getMessage()]
    assert model.arm.damping_time == 0.0 and not np.any(model.arm.damping_inertia)
    assert len(lines) == 1 and "\n" not in lines[0]
    assert lines[0].startswith("controller model: the joints' damping D [N m s/rad] (j1 10, j2 10,")
    assert "taken as 0" in lines[0]


@pytest.mark.parametrize(
    "realism, steps", [("", 1), ("realism: {physics: {enabled: true, substeps: 4}}\n", 4)]
)
def test_a_scenarios_controller_takes_its_damping_time_from_the_simulated_plants_step(
    tmp_path, realism, steps
):
    """A scenario whose arm file declares damping: the controller's model has T_D = (T + h)/2
    from the station plant's step h and the control period T: T itself at one step per
    period (the exact case above), 0.625 T with the physics rung's four (the nearest above).
    Not stating it (0), taking a real arm's T/2, or h, in the simulation fails this."""
    (tmp_path / "arm7.urdf").write_text(damped_urdf())
    joints = ", ".join(f"j{k + 1}: {q}" for k, q in enumerate(Q0))
    path = tmp_path / "scenario.yaml"
    path.write_text(
        f"arm:\n  urdf: arm7.urdf\n  initial_positions: {{{joints}}}\nplate:\n  position: [1.5, 1.5, -1.0]\n"
        "task:\n  axes: [x, y, z, rx, ry, rz]\nreference:\n  approach_speed: 0.0\n"
        "report:\n  compare_without_null_space_task: false\n  checks: []\n" + realism
    )
    scenario = load_scenario_file(path)
    station = add_scenario_station(DiagramBuilder(), scenario)
    model = controller_model(scenario, station)
    T = scenario.control_period
    assert station.plant.time_step() == pytest.approx(T / steps, rel=1e-12)
    assert model.arm.damping_time == pytest.approx((T + T / steps) / 2, rel=1e-12)
    np.testing.assert_allclose(
        model.arm.damping_inertia, model.arm.damping_time * np.array(DAMPING), rtol=1e-12
    )

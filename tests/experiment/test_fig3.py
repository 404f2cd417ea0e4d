"""The fig3 acceptance figures in closed loop, on a run short enough for CI, and the
properties of the whole diagram: determinism, actuator order, other arm sizes."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from conftest import fig3_with, once_per_test_run
from models import serial_arm_urdf

from nsdrake.experiment.simulate import run
from nsdrake.experiment.traces import Traces
from nsdrake.reporting.run_folder import run_to_folder
from nsdrake.station.models import models_dir

# Contact comes at ≈ 1.27 s, so the acceptance window [contact + 0.5 s, end] is 0.8 s long.
CI_DURATION = 2.6


@pytest.fixture(scope="module")
def fig3_run(tmp_path_factory):
    """(out folder, RunResult) of fig3 for CI_DURATION, simulated once in the whole test run
    (conftest's once_per_test_run: the two tests below may run in different workers)."""
    from nsdrake.experiment.scenario import load_scenario

    def compute(folder):
        out = folder / "fig3"
        out.mkdir()  # run_to_folder writes into a folder that is ready
        return out, run_to_folder(load_scenario("fig3", duration=CI_DURATION), out)

    return once_per_test_run(tmp_path_factory, "fig3_ci", compute)


@pytest.mark.slow
def test_fig3_acceptance_figures(fig3_run):
    out, result = fig3_run
    by_name = {m.name: m for m in result.metrics}
    expected = {
        "normal_force_min",
        "force_error_rms",
        "force_error_max",
        "tangential_position_error_rms",
        "null_space_error_rms",
        "forbidden_contacts_max",
        "p_tau_end",
    }
    assert expected <= set(by_name)
    failed = [f"{m.name}={m.value:.4g} (bound {m.bound})" for m in result.metrics if m.passed is False]
    assert failed == []
    assert by_name["window_rows"].value > 300
    assert 0.5 < by_name["first_contact_time"].value < 2.0


@pytest.mark.slow
def test_metrics_recompute_from_the_written_traces(fig3_run):
    """metrics.json's figures come from the CSV files alone: recomputing them from the
    written files and the scenario (no simulation) gives the same numbers."""
    out, result = fig3_run
    from nsdrake.experiment.diagram import build_diagram
    from nsdrake.experiment.scenario import load_scenario_file
    from nsdrake.reporting.run_folder import compute_metrics

    scenario = load_scenario_file(out / "scenario.yaml")
    traces = Traces.read_csv(out / "traces.csv")
    baseline = Traces.read_csv(out / "traces_without_null_space_task.csv")
    again = compute_metrics(scenario, build_diagram(scenario).station, traces, baseline)
    assert [(m.name, m.value) for m in again] == [(m.name, m.value) for m in result.metrics]
    stored = json.loads((out / "metrics.json").read_text())["metrics"]
    assert {name: m["value"] for name, m in stored.items()} == {m.name: m.value for m in again}


def test_two_runs_give_identical_traces(tmp_path):
    scenario = fig3_with(tmp_path, duration=1.5)
    first, _ = run(scenario)
    second, _ = run(scenario)
    first.write_csv(tmp_path / "a.csv")
    second.write_csv(tmp_path / "b.csv")
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


def test_actuators_declared_out_of_order_change_nothing(tmp_path):
    """The same arm with its transmissions listed 3, 1, 4, 2: the actuation map must
    route each joint's torque to its own motor, so the traces are identical."""
    text = (models_dir() / "arm4.urdf").read_text()
    blocks = re.findall(r"  <transmission.*?</transmission>\n", text, flags=re.S)
    assert len(blocks) == 4
    shuffled = text
    for block in blocks:
        shuffled = shuffled.replace(block, "")
    marker = "  <!-- The links pass over"
    shuffled = shuffled.replace(marker, "".join(blocks[i] for i in (2, 0, 3, 1)) + marker)
    path = tmp_path / "arm4_shuffled.urdf"
    path.write_text(shuffled)
    reference, _ = run(fig3_with(tmp_path, duration=1.4))
    other, built = run(fig3_with(tmp_path, f"arm: {{urdf: {path}}}", duration=1.4))
    B = built.station.plant.MakeActuationMatrix()
    assert not np.array_equal(B, np.eye(4))  # the model really is shuffled
    assert np.array_equal(reference.data, other.data)


def test_a_five_joint_arm_runs_through_the_same_diagram(tmp_path):
    """No hidden 4: a 5-DOF planar arm, its traces have q1…q5 and its null space is 3-D."""
    urdf = tmp_path / "arm5.urdf"
    urdf.write_text(serial_arm_urdf(["z"] * 5, [0.2] * 5, [0.5, 0.45, 0.4, 0.35, 0.3]))
    positions = ", ".join(f"joint{i + 1}: {q}" for i, q in enumerate([0.3, 0.5, 0.4, 0.3, 0.2]))
    text = (
        f"arm: {{urdf: {urdf}, initial_positions: {{{positions}}}}}\n"
        "desired_null_space: {criteria: {obstacle: {gain: 0.0}}}\n"  # the test arm has no collision geometry
    )
    traces, built = run(fig3_with(tmp_path, text, duration=0.3))
    assert built.station.arm_model.n == 5
    for prefix in ("q", "v", "tau", "qns", "en"):
        assert traces.block(prefix).shape == (len(traces), 5)
    others = [k for k, name in enumerate(traces.names) if name != "d_min"]
    assert np.all(np.isfinite(traces.data[:, others]))
    assert np.all(np.isinf(traces["d_min"]))  # no link geometry, so no obstacle distance
    # The tool follows its reference in free motion (approach phase), to a fraction of a millimetre.
    assert np.max(np.abs(traces["x"] - traces["x_d"])) < 1e-3

"""A run that diverges ends cleanly: it stops at once, keeps what it computed up to
that moment (traces, plots, report, marked failed), and says so in one line."""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from nsdrake.experiment.scenario import load_scenario
from nsdrake.reporting.run_folder import run_to_folder


def unstable_fig3():
    """fig3 whose controller believes the arm 11 times heavier than it is (the realism
    ladder's model error at +1000%): every model-based gain acts 11 times stronger, so the
    normal velocity loop has T K_v = 0.002 × 200 × 11 = 4.4, beyond the sampled loop's
    bound of 2. No check can refuse it (the checks see the controller's own model); the
    run diverges within a few periods."""
    s = load_scenario("fig3", duration=1.0)
    error = dataclasses.replace(s.realism.model_error, enabled=True, mass_error=10.0)
    return dataclasses.replace(s, realism=dataclasses.replace(s.realism, model_error=error))


def test_a_diverging_run_keeps_its_traces_and_is_marked_failed(tmp_path):
    """The monitor stops the run at the first out-of-bound step (joint speed beyond
    100 rad/s, well before anything is NaN); traces.csv holds every period up to
    then, metrics.json and report.html say failed and why. Without the monitor the
    run would raise out of Drake (or run on with NaN) and write nothing."""
    result = run_to_folder(unstable_fig3(), tmp_path, replay=False)
    assert result.failure is not None and result.failure.startswith("diverged at t = ")
    assert not result.passed
    traces = np.loadtxt(tmp_path / "traces.csv", delimiter=",", skiprows=1)
    assert 5 < len(traces) < 500  # stopped early, not at 1 s
    assert np.all(np.isfinite(traces))
    body = json.loads((tmp_path / "metrics.json").read_text())
    assert body["status"] == "failed" and body["failure"] == result.failure
    assert "run FAILED" in (tmp_path / "report.html").read_text()
    assert (tmp_path / "fig3.png").exists()


def test_the_command_line_prints_one_line_and_exits_non_zero(tmp_path, capsys):
    """nsdrake run with a bound the run must cross: exit status 1, one error line naming
    the scenario, the time and the reason, and the run's folder written."""
    from nsdrake.cli import main

    config = tmp_path / "tight.yaml"
    config.write_text("divergence: {max_joint_speed: 0.05}\n")
    out = tmp_path / "out"
    status = main(
        ["run", "fig3", "--config", str(config), "--out", str(out), "--duration", "1", "--no-replay"]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1
    assert len(err) == 1
    assert err[0].startswith("nsdrake: error: ") and "diverged at t = " in err[0] and "joint speed" in err[0]
    assert (out / "traces.csv").exists() and (out / "report.html").exists()

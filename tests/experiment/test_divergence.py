"""A run that diverges ends cleanly: it stops at once, keeps what it computed up to
that moment (traces, plots, report, marked failed), and says so in one line."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.traces import Traces
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


class _PoisonedSimulator(Simulator):
    """A Simulator whose plant state holds a NaN joint speed when the run starts (Drake's
    SetVelocities refuses one, a diverging plant or a faulty estimator does not)."""

    def Initialize(self):
        plant = self.get_system().GetSubsystemByName("plant")
        context = plant.GetMyMutableContextFromRoot(self.get_mutable_context())
        x = context.get_discrete_state_vector().CopyToVector()
        x[plant.num_positions()] = np.nan
        context.get_mutable_discrete_state_vector().SetFromVector(x)
        return super().Initialize()


def test_a_non_finite_state_ends_the_run_with_the_monitors_line(monkeypatch):
    """Issue 15, item 3: a non-finite estimated_state made a system raise inside the step
    (Drake's "Detected NaN in the actuation input port", or a linear solve), whose text
    became the reason. The run now ends as the monitor would have ended it, and keeps its
    traces."""
    import nsdrake.experiment.simulate as simulate

    monkeypatch.setattr(simulate, "Simulator", _PoisonedSimulator)
    with pytest.raises(simulate.DivergenceError) as info:
        simulate.run(load_scenario("fig3", duration=0.1))
    assert str(info.value) == "diverged at t = 0.0000 s: the joint state is not finite"
    assert isinstance(info.value.traces, Traces)


def test_an_overflow_inside_a_system_is_a_failed_run_not_a_traceback(monkeypatch):
    """An OverflowError (an ArithmeticError, not one of the errors the run caught) raised
    by a system in the middle of the run ends it as a divergence, in one line, with the
    traces so far."""
    import nsdrake.experiment.simulate as simulate
    from nsdrake.control.plan import ControllerPlan

    real = ControllerPlan.run
    calls = []

    def overflowing(*args, **kwargs):
        calls.append(1)
        if len(calls) > 100:  # several stage calls a period: about a dozen periods
            raise OverflowError(34, "Numerical result out of range")
        return real(*args, **kwargs)

    monkeypatch.setattr(ControllerPlan, "run", overflowing)
    with pytest.raises(simulate.DivergenceError) as info:
        simulate.run(load_scenario("fig3", duration=0.2))
    assert str(info.value).endswith("s: (34, 'Numerical result out of range')")
    assert 5 <= len(info.value.traces) <= 21


def test_ctrl_c_inside_a_step_keeps_every_complete_row(monkeypatch):
    """Ctrl-C lands inside a step, between two loggers' publishes (here in the contact
    monitor, which only its logger evaluates): some loggers have the new row, others not,
    and the traces failed with "trace columns differ in length". The run ends as
    RunInterrupted (a KeyboardInterrupt) with the rows every logger has."""
    import nsdrake.experiment.simulate as simulate
    from nsdrake.station.contact_monitor import ContactMonitor

    real = ContactMonitor._calc
    calls = []

    def interrupted(self, context, output):
        calls.append(1)
        if len(calls) == 20:
            raise KeyboardInterrupt
        return real(self, context, output)

    monkeypatch.setattr(ContactMonitor, "_calc", interrupted)
    with pytest.raises(KeyboardInterrupt) as info:
        simulate.run(load_scenario("fig3", duration=0.5))
    stopped = info.value
    assert isinstance(stopped, simulate.RunInterrupted)
    assert stopped.reason == f"interrupted at t = {stopped.t:.4f} s (Ctrl-C)"
    assert len(stopped.traces) == 19 and stopped.traces["t"][-1] == pytest.approx(0.036)


def test_ctrl_c_held_until_the_runs_end_keeps_every_row():
    """A Ctrl-C held back while the traces' kernels compiled (nsdrake/ctrl_c.py keeps it for
    the next progress report) is raised by the end's second report, after the traces are
    collected: the run ends as RunInterrupted at its end with every row. Catches the
    report made outside the conversion to RunInterrupted (the whole run's traces lost),
    and a run that never reports its end again (the Ctrl-C never answered)."""
    import nsdrake.experiment.simulate as simulate

    ends = []

    def progress(done):
        if done == 1.0:
            ends.append(done)
            if len(ends) == 2:
                raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt) as info:  # (a plain one escaping would end pytest)
        simulate.run(load_scenario("fig3", duration=0.05), progress=progress)
    assert isinstance(info.value, simulate.RunInterrupted)
    assert info.value.t == pytest.approx(0.05)
    assert len(info.value.traces) == len(simulate.run(load_scenario("fig3", duration=0.05))[0])

"""Running ``nsdrake drive`` and ``nsdrake sim-driver``, and writing a drive's run folder.

- :func:`prepare` and :meth:`Drive.run`: the controller side alone on a bus (a real
  Panda's driver, or ``nsdrake sim-driver`` in a second process), or with the simulated
  driver in one process over ``memq://`` (:func:`run_simulated`), in lockstep: the
  simulated driver publishes a status, the controller answers it, the driver steps.
- ``nsdrake sim-driver``: the simulated driver alone on a bus, free-running
  (:mod:`nsdrake.driver.serve`).
- :func:`write_drive_folder`: the run folder as ``nsdrake run`` writes it (traces, metrics
  with their bounds, plots, report) plus ``timing.json``.
"""

from __future__ import annotations

import contextlib
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from pydrake.lcm import DrakeLcm

from nsdrake.control.model_files import MODEL_WARNINGS
from nsdrake.control.validation import ControllerInputError
from nsdrake.driver.bus import Bus, DrakeBus
from nsdrake.driver.controller_side import build_controller_side
from nsdrake.driver.loop import ControllerLoop, DriveFaultError, DriveInterruptedError
from nsdrake.driver.realtime import RealtimeSettings, realtime_mode, realtime_settings
from nsdrake.driver.rows import Log
from nsdrake.driver.simulated_driver import SimulatedDriver
from nsdrake.driver.stop import ctrl_c_requests
from nsdrake.driver.timing import (
    GcPauses,
    collector_paused,
    gap_summary,
    timing_line,
    timing_summary,
    write_timing,
)
from nsdrake.experiment.output import declare, record_written
from nsdrake.experiment.scenario import Scenario, ScenarioError
from nsdrake.experiment.simulate import collect_traces
from nsdrake.experiment.traces import Traces
from nsdrake.reporting.loops import controller_box, loops_json
from nsdrake.reporting.metrics import contact_events, write_metrics
from nsdrake.reporting.report import write_report
from nsdrake.reporting.run_folder import (
    RunResult,
    compute_metrics,
    contact_note,
    controller_loops,
    scenario_name,
    scenario_yaml,
    write_model_warnings,
    write_plots,
)


@dataclass
class DriveRun:
    """A drive that ran (or stopped on a fault): both sides' handles and what it measured."""

    loop: ControllerLoop
    driver: SimulatedDriver | None
    timing: dict
    failure: str | None = None  # the DriveFaultError's line
    notes: list[str] = field(default_factory=list)
    interrupted: bool = False  # Ctrl-C stopped it (failure says when)

    @property
    def scenario(self) -> Scenario:
        return self.loop.drive.scenario


class Drive:
    """A drive ready to run: the controller side on a bus, and the simulated driver when
    both sides share this process (:func:`prepare`). Every problem with the scenario was
    raised while building it, before anything listens or sends."""

    def __init__(self, loop: ControllerLoop, driver: SimulatedDriver | None, realtime_rate: float = 0.0):
        self.loop, self.driver, self.realtime_rate = loop, driver, realtime_rate

    def run(
        self, *, pause_gc: bool = True, progress=None, stop=None, realtime: RealtimeSettings | None = None
    ) -> DriveRun:
        """Runs to the scenario's duration, the first fault or Ctrl-C (which stops it at the
        next status, :mod:`nsdrake.driver.stop`). ``pause_gc``: the garbage collector off
        during the loop (:func:`nsdrake.driver.timing.collector_paused`). ``stop``: a
        :class:`nsdrake.driver.stop.StopRequest` the caller set up already (a Ctrl-C that
        came before the loop began then stops it before its first command); without one,
        Ctrl-C is read from here on. ``realtime``: the loop thread's real-time mode
        (:mod:`nsdrake.driver.realtime`; the collector off with it); None: the scenario's
        ``driver.realtime`` (off unless enabled)."""
        loop, driver = self.loop, self.driver
        duration = loop.drive.scenario.duration
        failure, interrupted, pauses = None, False, GcPauses()
        requests = contextlib.nullcontext(stop) if stop is not None else ctrl_c_requests()
        realtime = realtime or realtime_settings(loop.config.realtime)
        pause_gc = pause_gc or realtime is not None
        with (
            requests as stop,
            collector_paused(pause_gc),
            realtime_mode(realtime, collector=False) as applied,
            pauses.watching(),
        ):
            loop.stop = stop
            try:
                if driver is None:
                    loop.run(duration, progress=progress)
                else:
                    _lockstep(loop, driver, duration, progress, Pacer(self.realtime_rate, stop))
            except DriveFaultError as e:
                failure, interrupted = str(e), isinstance(e, DriveInterruptedError)
            except Exception as e:  # noqa: BLE001 (anything else the loop met: one line, the folder kept)
                t = loop.time if loop.started else None
                failure = str(DriveFaultError(t, _unexpected(e), loop.commands))
        timing = _timing(loop, pauses, pause_gc) | {"realtime": applied.as_dict()}
        return DriveRun(loop=loop, driver=driver, timing=timing, failure=failure, interrupted=interrupted)


def _unexpected(error: Exception) -> str:
    """The line for an error the loop's own checks did not turn into a fault: the
    controller refusing its input, the bus failing (an OSError of LCM's socket), or a bug
    (its type named). The run still keeps what it computed."""
    if isinstance(error, ControllerInputError):
        problem = f"the controller refused its input: {error}"
    elif isinstance(error, OSError):
        problem = f"the LCM bus failed: {error}"
    else:
        problem = f"unexpected {type(error).__name__}: {error}"
    return " ".join(problem.split())


MAX_PACING_SLEEP = 1.0  # [s] the longest a paced step may wait for the wall clock
PACING_SLICE = 0.02  # [s] the pacing sleeps in slices this long, reading Ctrl-C's flag between them


def pacing_problem(realtime_rate: float, period: float) -> str | None:
    """Why ``realtime_rate`` cannot pace a drive of control period ``period`` [s] (None:
    it can): each step would wait more than MAX_PACING_SLEEP for the wall clock."""
    if realtime_rate > 0 and period / realtime_rate > MAX_PACING_SLEEP:
        return (
            f"{realtime_rate:g} would wait {period / realtime_rate:.3g} s of wall clock for each "
            f"{period * 1e3:g} ms control period; give at least {period / MAX_PACING_SLEEP:g} "
            "(1: real time; 0: as fast as possible)"
        )
    return None


class Pacer:
    """The simulated driver's pace against the wall clock: ``wait(t)`` sleeps until the
    wall clock is t / ``rate`` [s] after the first call (never when behind; rate 0: never),
    in slices of PACING_SLICE, returning early once ``stop`` (Ctrl-C's flag) is set. Why
    not Drake's Simulator pacing: it sleeps in C++, where a Python signal handler cannot
    run, so a slow rate left Ctrl-C unanswered."""

    def __init__(self, rate: float, stop):
        self.rate, self.stop, self._start = rate, stop, None

    def wait(self, t: float) -> None:
        if self.rate <= 0:
            return
        now = time.perf_counter()
        if self._start is None:
            self._start = now - t / self.rate
        target = self._start + t / self.rate
        while now < target and not self.stop.requested:
            time.sleep(min(PACING_SLICE, target - now))
            now = time.perf_counter()


def _lockstep(loop: ControllerLoop, driver: SimulatedDriver, duration: float, progress, pacer: Pacer) -> None:
    """Status, command, step: the driver publishes, the controller answers, the driver
    steps, paced by ``pacer``."""
    loop.ready()
    driver.start()
    loop.start()
    while loop.time < duration - 0.5 * loop.period:
        driver.step()
        pacer.wait(driver.time)
        loop.tick()
        if progress is not None and loop.periods % 1000 == 0:
            progress(loop.time / duration)


def prepare(
    scenario: Scenario,
    bus: Bus | None = None,
    *,
    realtime_rate: float = 1.0,
    robot_adds_gravity: bool = True,
) -> Drive:
    """The controller side on ``bus``; without one, the controller side and the simulated
    driver in this process over ``memq://``, the driver paced at ``realtime_rate`` (1: the
    robot's real time; 0: as fast as possible; one refused that waits over a second a
    period, :func:`pacing_problem`) and adding g to the command when
    ``robot_adds_gravity`` (the controller side follows ``scenario.driver.robot_adds_gravity``)."""
    problem = None if bus is not None else pacing_problem(realtime_rate, scenario.control_period)
    if problem:
        raise ScenarioError(f"--realtime-rate: {problem}")
    side = build_controller_side(scenario)  # the scenario's problems first
    if bus is not None:
        return Drive(ControllerLoop(side, bus), None)
    lcm = DrakeLcm("memq://")
    driver = SimulatedDriver(scenario, lcm, adds_gravity=robot_adds_gravity)  # paced by the Drive (Pacer)
    loop = ControllerLoop(side, DrakeBus(lcm), clock=lambda: driver.time)  # lockstep: the robot's time
    return Drive(loop, driver, realtime_rate)


def run_simulated(scenario: Scenario, *, pause_gc: bool = True, progress=None, **options) -> DriveRun:
    """:func:`prepare` without a bus (both sides here, over ``memq://``), then run."""
    return prepare(scenario, **options).run(pause_gc=pause_gc, progress=progress)


def _timing(loop: ControllerLoop, pauses: GcPauses, paused: bool) -> dict:
    return timing_summary(
        loop.times.seconds,
        loop.period,
        loop.times.cpu_seconds,
        commands=loop.commands,
        statuses_skipped=loop.skipped,
        longest_silence_us=loop.longest_silence * 1e6,
        periods=loop.periods,
        clock=loop.clock_name,
        control_command_success_rate_min=None
        if loop.success_rate_min != loop.success_rate_min
        else loop.success_rate_min,
        gc_disabled=paused,
        gc_collections=pauses.count,
        gc_longest_pause_us=pauses.longest * 1e6,
        silence_bound_periods=loop.bound_periods,
        **gap_summary(loop.gap_counts, loop.longest_gap),
    )


def drive_traces(run: DriveRun) -> Traces:
    """The drive's traces, with the columns of ``nsdrake run``'s (docs/command_line.md) from the
    controller side's records, and:

    - with the simulated driver, ``f_x…``, ``f_n`` and ``forbidden_contacts`` from the
      simulated station (its sensor and contact monitor, the truth), and
      ``f_x_measured…``, ``f_n_measured`` the wrench the controller used (the sensor's
      message, or the estimate from the external joint torques);
    - without it (a real arm), ``f_…`` the wrench the controller used, and
      ``forbidden_contacts`` NaN (nothing observes them);
    - ``cmd1…`` the torques sent [N m] (τ − g(q) when the robot adds g), and with the
      simulated driver ``tau_applied1…`` the torque its plant applied from that row's time
      to the next row's [N m] (as the realism rungs' column; NaN on the last row).
    """
    side = run.loop.side
    logs = run.loop.recorder.logs()
    times = logs["state"].sample_times()
    measured = logs["wrench"].data()
    if run.driver is not None:
        truth = run.driver.logs()
        rows = np.searchsorted(truth["wrench"].sample_times(), times)
        for name in ("wrench", "forbidden_contacts", "applied"):
            logs[name] = Log(times, truth[name].data()[:, rows])
    else:
        logs["forbidden_contacts"] = Log(times, np.full((1, times.size), np.nan))
    traces = collect_traces(side, side.station_diagram.CreateDefaultContext(), logs=logs)
    columns = {name: traces[name] for name in traces.names}
    arm = side.station.arm_model
    if run.driver is not None:
        force = measured[3:][arm.rows]
        for axis, row in zip(arm.task_axes[: arm.m_t], force, strict=True):
            columns[f"f_{axis}_measured"] = row
        columns["f_n_measured"] = side.station.normal @ force
    for i, row in enumerate(logs["command"].data()):
        columns[f"cmd{i + 1}"] = row
    if run.driver is not None:  # applied over [t, t + T): the plant reports it at t + T
        applied = np.column_stack([logs["applied"].data()[:, 1:], np.full((arm.n, 1), np.nan)])
        for i, row in enumerate(applied):
            columns[f"tau_applied{i + 1}"] = row
    return Traces(columns)


# Every file a drive may write into its folder, declared in the manifest before any is written.
DRIVE_FILES = (
    "scenario.yaml",
    "traces.csv",
    "metrics.json",
    "pose.png",
    "fig3.png",
    "priority.png",
    "report.html",
    "timing.json",
    MODEL_WARNINGS,
)


def write_drive_folder(run: DriveRun, out: Path) -> RunResult:
    """The run folder (module docstring) in ``out``, which must be ready (claimed). A run
    stopped by a fault writes what it computed up to the fault, marked failed; one that
    never commanded writes scenario.yaml and timing.json only."""
    out = Path(out)
    try:
        return _write_drive_folder(run, out)
    finally:
        record_written(out)


def _drive_extra(run: DriveRun, status: str, events) -> dict:
    """metrics.json's description of the drive beside its metrics."""
    extra = {
        "scenario": run.scenario.source,
        "duration": run.scenario.duration,
        "status": status,
        "contact_events": [{"event": e, "t": t} for e, t in events],
        "driver": "simulated (memq://, lockstep)" if run.driver is not None else "on the bus",
        "statuses_skipped": run.loop.skipped,
    }
    if run.failure:
        extra["failure"] = run.failure
    return extra


def _write_drive_folder(run: DriveRun, out: Path) -> RunResult:
    scenario = run.scenario
    declare(out, DRIVE_FILES)
    (out / "scenario.yaml").write_text(scenario_yaml(scenario))
    write_model_warnings(out, run.loop.drive.station)
    status = "interrupted" if run.interrupted else "failed" if run.failure else "ok"
    write_timing(
        out / "timing.json", run.timing | ({"failure": run.failure, "status": status} if run.failure else {})
    )
    if run.loop.commands == 0:
        return RunResult(
            out=out,
            metrics=[],
            notes=[timing_line(run.timing)],
            failure=run.failure,
            interrupted=run.interrupted,
        )
    traces = drive_traces(run)
    traces.write_csv(out / "traces.csv")
    traces = Traces.read_csv(out / "traces.csv")
    metrics = [] if run.failure else compute_metrics(scenario, run.loop.drive.station, traces, None)
    notes = [timing_line(run.timing)]
    if run.driver is None:
        metrics = [m for m in metrics if m.name != "forbidden_contacts_max"]
        notes.append(
            "no ground truth on a real arm: forbidden contacts are not observed, and f_* is the "
            "wrench the controller used"
        )
    events = contact_events(traces)
    extra = _drive_extra(run, status, events)
    station = run.loop.drive.station
    box, loops = controller_box(scenario, station), controller_loops(scenario, station)
    extra["loops"] = loops_json(loops)
    write_metrics(out / "metrics.json", metrics, extra)
    with warnings.catch_warnings():  # a drive stopped early: the tool has not moved on the surface yet
        warnings.filterwarnings("ignore", message="Attempting to set identical low and high [xy]lims")
        plots = write_plots(scenario, run.loop.drive, traces, None, out)
    notes += [contact_note(events)] if any(e == "lost" for e, _ in events) else []
    write_report(
        out,
        title=f"nsdrake drive {out.resolve().name}",
        description=f"{scenario.description} (scenario: {scenario_name(scenario)}; "
        f"through the Panda's LCM messages, {extra['driver']})",
        parameters=yaml.safe_load(scenario_yaml(scenario)),
        metrics=metrics,
        plots=plots,
        diagram=None,
        replay=None,
        notes=notes,
        failure=run.failure,
        controller=box,
        loops=loops,
        delay_periods=1,  # the drive answers status k with the command the robot applies at k + 1
    )
    return RunResult(out=out, metrics=metrics, notes=notes, failure=run.failure, interrupted=run.interrupted)

"""One run of a scenario into an output folder: traces, metrics, plots, the
diagram's picture, the 3D replay and the HTML report.

(The output folder rules are in nsdrake/experiment/output.py; their names are re-exported here.)
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from pydrake.geometry import Meshcat
from pydrake.systems.framework import DiagramBuilder

from nsdrake.control.model_files import MODEL_WARNINGS, warnings_text
from nsdrake.experiment.checks import check_with_model
from nsdrake.experiment.diagram import build_diagram, speed_limit_vector
from nsdrake.experiment.output import (  # noqa: F401 (re-exported: diagrams/fig3.py, the CLI)
    OutputFolderError,
    declare,
    default_output_folder,
    prepare_output_folder,
    record_written,
)
from nsdrake.experiment.scenario import Scenario
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.experiment.simulate import DivergenceError, RunInterrupted, run
from nsdrake.experiment.traces import Traces
from nsdrake.reporting.loops import controller_box, loops_json, null_space_loop_of, task_loops
from nsdrake.reporting.metrics import (
    Metric,
    contact_events,
    fig3_metrics,
    first_contact_index,
    joint_speed_metric,
    pose_metrics,
    priority_metrics,
    self_motion_metrics,
    write_metrics,
)
from nsdrake.reporting.replay import write_diagram_picture, write_replay
from nsdrake.reporting.report import write_report
from nsdrake.station.visualization import start_meshcat


def check_scenario(scenario: Scenario) -> None:
    """Builds the station, then the diagram, once, so that every field checked against the
    model (files, joint and frame names, the task's rank at the initial pose, the sampled
    loops' stability, then what the controller refuses) fails now, before an output
    folder is made."""
    check_with_model(scenario, add_scenario_station(DiagramBuilder(), scenario))
    build_diagram(scenario)


def scenario_yaml(scenario: Scenario) -> str:
    """The effective scenario as YAML that load_scenario_file reads back."""
    data = dataclasses.asdict(scenario)
    for f in dataclasses.fields(scenario):
        if not f.metadata.get("yaml", True):
            data.pop(f.name)
    return yaml.safe_dump(data, sort_keys=False)


@dataclass
class RunResult:
    out: Path
    metrics: list[Metric]
    notes: list[str] = field(default_factory=list)  # one line each, for the user (e.g. no Graphviz)
    failure: str | None = None  # why the run stopped early ("diverged at t = … s: …")
    interrupted: bool = False  # Ctrl-C stopped it (failure says when)

    @property
    def passed(self) -> bool:
        return self.failure is None and all(m.passed for m in self.metrics if m.passed is not None)


def run_to_folder(
    scenario: Scenario,
    out: Path,
    *,
    progress=None,
    replay: bool = True,
    meshcat: Meshcat | None = None,
) -> RunResult:
    """Simulates ``scenario`` and writes into ``out`` (which must be ready):

    - traces.csv: one row per control period (docs/command_line.md, "traces.csv", for the columns);
    - traces_without_null_space_task.csv: the same run with q̇_dⁿ = 0, if the
      scenario asks for the comparison;
    - metrics.json: the acceptance figures, computed from the CSV files;
    - fig3.png: the Fig. 3-style plots (with the fig3 check);
    - priority.png: mode timeline and criteria (with the priority check);
    - pose.png: force, path on the surface, position and orientation errors, obstacle
      distances, joint-limit margins, the elbow's swivel (with the pose or self_motion check);
    - scenario.yaml: the scenario as run;
    - model_warnings.txt: every warning Drake's parser gave on the arm's model files, in
      full (the log says one line per file), if there were any;
    - diagram.dot and diagram.svg (if Graphviz's dot is found): the Drake diagram;
    - replay.html: the main run in Meshcat, self-contained (unless not ``replay``);
    - report.html: all of the above on one page.

    With a ``meshcat`` (a live viewer), the main run is shown in it as it runs,
    at real time; the comparison run is never shown nor recorded. A run that
    diverges (:class:`nsdrake.experiment.simulate.DivergenceError`) or is interrupted
    (Ctrl-C: :class:`nsdrake.experiment.simulate.RunInterrupted`) writes the same files up
    to that moment, marked failed or interrupted (metrics.json's ``status``), and returns
    with ``failure`` set (and ``interrupted``). In a folder
    claimed by prepare_output_folder or default_output_folder, the manifest then
    lists these files.
    """
    out = Path(out)
    try:
        return _run_to_folder(scenario, out, progress=progress, replay=replay, meshcat=meshcat)
    finally:  # done or failed: the manifest lists what the run wrote, for a later --overwrite
        record_written(out)


# Every file a run may write into its folder, declared in the manifest before any is written.
def write_model_warnings(out: Path, station) -> None:
    """The folder's model_warnings.txt: every warning Drake's parser gave on the arm's model
    files, in full (the log said one line per file); none written without warnings."""
    if station.model_warnings:
        (out / MODEL_WARNINGS).write_text(warnings_text(station.model_warnings))


RUN_FILES = (
    "scenario.yaml",
    "traces.csv",
    "traces_without_null_space_task.csv",
    "replay.html",
    "diagram.dot",
    "diagram.svg",
    "metrics.json",
    "fig3.png",
    "priority.png",
    "pose.png",
    "report.html",
    MODEL_WARNINGS,
)


def _run_to_folder(scenario: Scenario, out: Path, *, progress, replay: bool, meshcat) -> RunResult:
    declare(out, RUN_FILES)
    live = meshcat is not None
    if meshcat is None and replay:
        meshcat = start_meshcat(live=False)
    sim = _simulate(scenario, out, progress, meshcat, live)
    # after the simulation: until its first step (where the kernels compile), the folder
    # stays empty, so that a Ctrl-C there undoes the claim (nsdrake/ctrl_c.py)
    (out / "scenario.yaml").write_text(scenario_yaml(scenario))
    write_model_warnings(out, sim.built.station)
    replay_path = write_replay(meshcat, out / "replay.html") if replay else None
    picture = write_diagram_picture(sim.built.diagram, out)
    traces = Traces.read_csv(out / "traces.csv")
    failure = sim.failure
    metrics = compute_metrics(scenario, sim.built.station, traces, sim.baseline) if failure is None else []
    events = contact_events(traces)
    extra = {
        "scenario": scenario.source,
        "duration": scenario.duration,
        "status": "interrupted" if sim.interrupted else "failed" if failure else "ok",
        "contact_events": [{"event": e, "t": t} for e, t in events],
    }
    if failure:
        extra["failure"] = failure
    box, loops = controller_box(scenario, sim.built.station), controller_loops(scenario, sim.built.station)
    extra["loops"] = loops_json(loops)
    write_metrics(out / "metrics.json", metrics, extra)
    title = run_title(scenario, traces, events, failure)
    plots = write_plots(scenario, sim.built, traces, sim.baseline, out, title=title)
    notes = [contact_note(events)] if any(e == "lost" for e, _ in events) else []
    notes += [picture.note] if picture.note else []
    write_report(
        out,
        title=title,
        description=f"The scenario ({scenario_name(scenario)}, folder {out.resolve().name}): "
        f"{scenario.description}",
        parameters=yaml.safe_load(scenario_yaml(scenario)),
        defaults=yaml.safe_load(scenario_yaml(Scenario())),
        modes=modes_in_order(traces),
        metrics=metrics,
        plots=plots,
        diagram=dataclasses.replace(picture, note=report_note(picture.note, out)),
        replay=replay_path.name if replay_path else None,
        notes=[report_note(note, out) for note in notes],
        failure=failure,
        controller=box,
        loops=loops,
        delay_periods=scenario.realism.delay.periods if scenario.realism.delay.enabled else 0,
    )
    return RunResult(out=out, metrics=metrics, notes=notes, failure=failure, interrupted=sim.interrupted)


def controller_loops(scenario: Scenario, station) -> list:
    """The task's loops and the null-space loop (nsdrake/reporting/loops.py)."""
    return [*task_loops(scenario, station), null_space_loop_of(scenario, station)]


def scenario_name(scenario: Scenario) -> str:
    """The scenario as a report names it: its file's name, never a machine's path."""
    return Path(scenario.source).name if scenario.source else "built in code"


def report_note(note: str, out: Path) -> str:
    """A note for the report, which lives in ``out``: the run's files by their names (the
    terminal's note names them by path)."""
    return note.replace(f"{out}{os.sep}", "").replace(f"{out.resolve()}{os.sep}", "")


@dataclass
class _Simulated:
    built: object  # ControlledStation of the main run
    baseline: Traces | None  # the comparison run's traces (q̇_dⁿ = 0), if it ran to the end
    failure: str | None  # why the run stopped early
    interrupted: bool  # Ctrl-C stopped it


def _simulate(scenario: Scenario, out: Path, progress, meshcat, live: bool) -> _Simulated:
    """Runs the scenario (and its comparison run) and writes traces.csv (and
    traces_without_null_space_task.csv); a run that diverges or is interrupted writes
    its traces up to that moment."""
    stages = 2 if scenario.report.compare_without_null_space_task else 1
    report = (lambda k: lambda f: progress((k + f) / stages)) if progress else (lambda k: None)
    try:
        traces, built = run(scenario, progress=report(0), meshcat=meshcat, live=live)
    except (DivergenceError, RunInterrupted) as e:
        e.traces.write_csv(out / "traces.csv")
        if e.built.visualizers is not None:
            e.built.visualizers.publish_recording()
        stopped = str(e) if isinstance(e, DivergenceError) else e.reason
        return _Simulated(e.built, None, stopped, isinstance(e, RunInterrupted))
    traces.write_csv(out / "traces.csv")
    if stages == 1:
        return _Simulated(built, None, None, False)
    baseline_csv = out / "traces_without_null_space_task.csv"
    try:
        baseline_traces, _ = run(scenario, null_space_task=False, progress=report(1))
    except (DivergenceError, RunInterrupted) as e:
        e.traces.write_csv(baseline_csv)
        if isinstance(e, RunInterrupted):
            return _Simulated(built, None, f"the comparison run (q̇_dⁿ = 0) was {e.reason}", True)
        return _Simulated(built, None, f"the comparison run (q̇_dⁿ = 0) {e}", False)
    baseline_traces.write_csv(baseline_csv)
    return _Simulated(built, Traces.read_csv(baseline_csv), None, False)


def modes_in_order(traces: Traces) -> list[int]:
    """The modes of Fig. 1 the run went through, in order, a mode repeated when the run
    returned to it; [] for traces without a mode column."""
    if "mode" not in traces or len(traces) == 0:
        return []
    mode = traces["mode"].astype(int)
    return [int(m) for k, m in enumerate(mode) if k == 0 or m != mode[k - 1]]


def run_title(
    scenario: Scenario, traces: Traces, events: list[tuple[str, float]], failure: str | None
) -> str:
    """The report's title, from what the run did (not what the scenario meant it to do):
    how long it ran, whether and when the tool touched, which criteria the null space
    served (Fig. 1's modes), and a failure."""
    from nsdrake.reporting.report import MODE_WORDS

    source = scenario.source or "a scenario built in code"
    name = Path(source).stem if source.endswith((".yaml", ".yml")) else source
    t_end = float(traces["t"][-1]) if len(traces) else 0.0
    parts = [f"{name}, {t_end:.3g} s"]
    touched = [t for e, t in events if e == "contact"]
    if scenario.reference.force > 0 or touched:
        parts.append(f"contact from t = {touched[0]:.3g} s" if touched else "the tool never touched")
    modes = modes_in_order(traces)
    if len(modes) == 1:
        parts.append(f"level 2: {MODE_WORDS.get(modes[0], '?')} throughout (mode {modes[0]})")
    elif modes:
        parts.append("level 2: " + " → ".join(f"{MODE_WORDS.get(m, '?')} ({m})" for m in modes[:6]))
        parts[-1] += " …" if len(modes) > 6 else ""
    if failure:
        parts.append("FAILED")
    return "; ".join(parts)


def contact_note(events: list[tuple[str, float]]) -> str:
    """One line: when contact was made, lost and regained."""
    words = {"contact": "made", "lost": "lost"}
    parts, seen = [], False
    for event, t in events:
        word = "regained" if event == "contact" and seen else words[event]
        seen = seen or event == "contact"
        parts.append(f"{word} at t = {t:.3f} s")
    return "contact " + ", ".join(parts) + " (the force command falls to 0 while contact is lost)"


def write_plots(
    scenario: Scenario, built, traces: Traces, baseline: Traces | None, out: Path, title: str | None = None
) -> list[Path]:
    """fig3.png, priority.png and pose.png, as the scenario's checks ask (none for an empty trace),
    titled ``title`` (what the run did: :func:`run_title`; default the scenario's description)."""
    # matplotlib only here: a sweep's workers import this module for its metrics and plot nothing
    from nsdrake.reporting.plots import plot_fig3, plot_pose, plot_priority

    title = scenario.description if title is None else title
    if len(traces) < 2:
        return []
    k0 = first_contact_index(traces, scenario.reference.contact_threshold)
    contact_time = float(traces["t"][k0]) if k0 is not None else None
    plots = []
    if "fig3" in scenario.report.checks:
        plots.append(out / "fig3.png")
        plot_fig3(
            traces,
            out / "fig3.png",
            task_axes=built.station.arm_model.task_axes[: built.station.arm_model.m_t],
            title=title,
            baseline=baseline,
            contact_time=contact_time,
            selector=scenario.desired_null_space.selector,
        )
    if "priority" in scenario.report.checks:
        plots.append(out / "priority.png")
        plot_priority(
            traces,
            out / "priority.png",
            title=title,
            selector=scenario.desired_null_space.selector,
        )
    if {"pose", "self_motion"} & set(scenario.report.checks):
        arm = built.station.arm_model
        plots.append(out / "pose.png")
        plot_pose(
            traces,
            out / "pose.png",
            normal=built.station.normal,
            task_axes=arm.task_axes[: arm.m_t],
            title=title,
            baseline=baseline,
            contact_time=contact_time,
            d_lim=scenario.desired_null_space.selector.d_lim,
        )
    return plots


def compute_metrics(scenario: Scenario, station, traces: Traces, baseline: Traces | None) -> list[Metric]:
    """The figures the scenario's ``report.checks`` ask for, from the traces (and the
    station's plate directions and arm model)."""
    selector = scenario.desired_null_space.selector
    threshold = scenario.reference.contact_threshold
    arm = station.arm_model
    translational = arm.task_axes[: arm.m_t]  # the traces' position columns; tangent is on these rows
    metrics: list[Metric] = []
    if "fig3" in scenario.report.checks:
        metrics += fig3_metrics(
            traces,
            tangent=station.tangent,
            task_axes=translational,
            contact_threshold=threshold,
            p_tau_without_null_space_task=float(baseline["p_tau"][-1]) if baseline is not None else None,
            d_lim=selector.d_lim,
            null_space_law=scenario.null_space.law,
        )
    if "priority" in scenario.report.checks:
        metrics += priority_metrics(
            traces,
            blend_time=selector.blend_time,
            contact_threshold=threshold,
            required_modes=tuple(scenario.report.required_modes),
        )
    if "pose" in scenario.report.checks:
        metrics += pose_metrics(
            traces,
            normal=station.normal,
            task_axes=translational,
            contact_threshold=threshold,
            d_lim=selector.d_lim,
            obstacles=tuple(ob.name for ob in scenario.obstacles),
        )
    if "self_motion" in scenario.report.checks:
        metrics += self_motion_metrics(
            traces, normal=station.normal, task_axes=translational, contact_threshold=threshold
        )
    metrics.append(joint_speed_metric(traces, speed_limit_vector(scenario, station.arm_model)))
    return metrics

"""Families of runs that put the paper's claims side by side (``nsdrake compare``).

A family (``nsdrake/families/NAME.yaml``) names a shipped base scenario, a measure
and a list of variants, each a set of scenario overrides::

    description: "…"
    scenario: force_step          # the base scenario
    measure: contact_force_into_null_space
    variants:
      - name: dynamically consistent
        overrides: {null_space: {pseudo_inverse: dynamically_consistent}}

Each variant's scenario is the base, then the user's ``--config`` file, then the
variant's overrides (the variant's defining switch always wins). Every variant
is simulated, its traces written to ``variants/NN-slug/traces.csv``, and the
measure computes one table row from those traces alone. The table is written as
``table.md`` and ``table.csv``, and ``compare.png`` overlays the variants.
"""

from __future__ import annotations

import csv
import dataclasses
import logging
import math
import multiprocessing
import multiprocessing.connection
import os
import re
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nsdrake.control.dynamics import ArmModel
from nsdrake.control.kernels import compiling
from nsdrake.experiment.output import declare, record_written
from nsdrake.experiment.scenario import (
    Scenario,
    ScenarioError,
    _cut,
    _name,
    _show,
    check_shape,
    load_scenario,
    overlay,
    read_yaml,
)
from nsdrake.experiment.traces import Traces
from nsdrake.reporting.metrics import (
    FIRST_CONTACT_METRICS,
    SETTLE_TIME,
    first_contact_index,
    measuring_window_gap,
    torque_steps,
)
from nsdrake.studies.measures import (
    MODE_CRITERION,
    MODE_NAME,
    OSCILLATION_FLOOR_SHARE,
    commanded_step_rates,
    drift_rate,
    force_oscillation,
    wrong_way_share,
)

FAMILY_DIR = Path(__file__).resolve().parent / "families"
MIN_WINDOW_ROWS = 8  # [control periods] the fewest the realism measure's window needs (its spectrum)


@dataclass(frozen=True)
class Variant:
    name: str
    overrides: dict
    scenario: str = ""  # its own base scenario; "": the family's


@dataclass(frozen=True)
class Family:
    name: str
    description: str
    scenario: str
    measure: str
    variants: tuple[Variant, ...]
    source: str


def shipped_families() -> list[str]:
    return sorted(p.stem for p in FAMILY_DIR.glob("*.yaml"))


def load_family(name: str) -> Family:
    """A shipped family, checked: base scenario, measure, variant names and overrides."""
    known = shipped_families()
    if name not in known:
        raise ScenarioError(f"unknown family '{name}'; the shipped families are {', '.join(known)}")
    path = FAMILY_DIR / f"{name}.yaml"
    _, data = read_yaml(path, "family")
    if not isinstance(data, dict):
        raise ScenarioError(f"{path}: must be a mapping with description, scenario, measure, variants")
    unknown = set(data) - {"description", "scenario", "measure", "variants"}
    if unknown:
        raise ScenarioError(f"{path}: {_name(sorted(unknown, key=str)[0])}: unknown field")
    if data.get("measure") not in MEASURES:
        raise ScenarioError(
            f"{path}: measure: must be one of {', '.join(MEASURES)}, got {_show(data.get('measure'))}"
        )
    variants = []
    for i, v in enumerate(data.get("variants") or []):
        variants.append(_variant(path, i, v))
    if not variants:
        raise ScenarioError(f"{path}: variants: a family needs at least one variant")
    names = [v.name for v in variants]
    if len(set(names)) != len(names):
        raise ScenarioError(f"{path}: variants: names must be distinct")
    return Family(
        name=name,
        description=str(data.get("description", "")),
        scenario=str(data.get("scenario", "")),
        measure=data["measure"],
        variants=tuple(variants),
        source=str(path),
    )


def _variant(path: Path, i: int, v) -> Variant:
    """variants[i] of the family file at ``path``: a name, a mapping of overrides and
    optionally its own base scenario (a shipped one), checked."""
    from nsdrake.experiment.scenario import shipped_scenarios

    if (
        not isinstance(v, dict)
        or not isinstance(v.get("name"), str)
        or not isinstance(v.get("overrides", {}), dict)
    ):
        raise ScenarioError(f"{path}: variants[{i}]: needs a name and a mapping of overrides")
    unknown = set(v) - {"name", "overrides", "scenario"}
    if unknown:
        raise ScenarioError(f"{path}: variants[{i}].{_name(sorted(unknown, key=str)[0])}: unknown field")
    scenario = v.get("scenario", "")
    if scenario and scenario not in shipped_scenarios():
        raise ScenarioError(
            f"{path}: variants[{i}].scenario: unknown scenario {_show(scenario)}; "
            f"the shipped scenarios are {', '.join(shipped_scenarios())}"
        )
    problem = check_shape(v.get("overrides", {}), Scenario, "")
    if problem:
        raise ScenarioError(f"{path}: variants[{i}].overrides.{problem}")
    return Variant(v["name"], v.get("overrides", {}), str(scenario))


def variant_scenario(family: Family, index: int, config: Path | None, duration: float | None) -> Scenario:
    """The base scenario (the variant's own, else the family's), then ``config``, then the
    variant's overrides; validated."""
    from nsdrake.experiment.scenario import validate

    variant = family.variants[index]
    # validated once the variant's overrides are on it: the user's file may set what only
    # the variant makes valid (a posture gain where the variant's source is the posture)
    base = load_scenario(
        variant.scenario or family.scenario, config=config, duration=duration, validated=False
    )
    try:
        scenario = overlay(base, variant.overrides, f"{family.source} [{variant.name}]")
    except Exception as e:
        raise ScenarioError(f"{family.source}: variants[{index}].overrides: {_cut(e)}") from None
    scenario.source = f"{family.source} [{variant.name}]"
    scenario.base_dir = base.base_dir
    if duration is not None:  # the variant as written (its push within its own run), then shortened
        validate(scenario)
        scenario = dataclasses.replace(scenario, duration=duration)
    validate(scenario, push_within_run=duration is None)  # a push after --duration's end: the row's note
    return scenario


def check_variants(family: Family, config: Path | None, duration: float | None) -> None:
    """Every variant's scenario (with ``config`` overlaid), and its station and joint names
    (:func:`nsdrake.experiment.scenario_station.add_scenario_station`: fields keyed by
    joint name against that variant's arm), before any variant runs. A problem that only
    ``config`` brings (the same variant without it is fine) names the user's file, not the
    family's (the family's own variants are the shipped ones, tested), and the variant: a
    setting only some variants accept (keyed by one arm's joints) is refused for the
    first variant that does not."""
    from pydrake.systems.framework import DiagramBuilder

    from nsdrake.experiment.scenario_station import add_scenario_station

    def check(index: int, overlay: Path | None) -> None:
        scenario = variant_scenario(family, index, overlay, duration)
        add_scenario_station(DiagramBuilder(), scenario, sensing=False)

    for i, variant in enumerate(family.variants):
        try:
            check(i, config)
        except ScenarioError as e:
            if config is None:
                raise
            try:
                check(i, None)
            except ScenarioError:
                raise e from None
            where, text = f"{family.source} [{variant.name}]: ", str(e)
            if text.startswith(where):  # named after the family's file: the user's file it is
                text = f"{config}: {text[len(where) :]}"
            raise ScenarioError(f"{text} (in the variant '{variant.name}' of {family.name})") from None


def slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


# --- measures: one table row from one variant's traces --------------------------------


@dataclass(frozen=True)
class RunFacts:
    """What a measure may know besides the traces: the scenario and the station."""

    scenario: Scenario
    station: object  # nsdrake.station.plant.Station

    @property
    def arm(self) -> ArmModel:
        return self.station.arm_model

    @property
    def tangent(self) -> np.ndarray:
        return self.station.tangent

    @property
    def normal(self) -> np.ndarray:
        return self.station.normal


def _rms(x) -> float:
    x = np.asarray(x)
    return float(np.sqrt(np.mean(x * x))) if x.size else math.nan


def _norms(traces: Traces, prefix: str) -> np.ndarray:
    return np.linalg.norm(traces.block(prefix), axis=1)


def dc_null_space_speed(traces: Traces, arm: ArmModel) -> np.ndarray:
    """‖(I − J̄ J) q̇‖ per row, with the dynamically consistent projector, recomputed
    from the logged q and q̇ (the same measure whichever inverse the run used)."""
    from nsdrake.control.pseudo_inverse import GeneralizedInverse

    context = arm.plant.CreateDefaultContext()
    dc = GeneralizedInverse()
    q, v = traces.block("q"), traces.block("v")
    out = np.empty(len(traces))
    for k in range(len(traces)):
        terms = arm.terms(context, q[k], v[k], coriolis=False)
        out[k] = np.linalg.norm(dc.at(terms).N @ v[k])
    return out


def measure_contact_force_into_null_space(traces: Traces, ctx: RunFacts) -> dict:
    """Eq. 26. Null-space velocity after the desired-force step (1 s window) and before it
    (0.5 s of steady pressing: the floor of the contact model's own transient)."""
    s = ctx.scenario
    t = traces["t"]
    k0 = first_contact_index(traces, s.reference.contact_threshold)
    if k0 is None:
        return {"contact": False}
    t_step = t[k0] + s.reference.step_time
    after = (t >= t_step) & (t < t_step + 1.0)
    before = (t >= t_step - 0.5) & (t < t_step)
    en = _norms(traces, "en")
    dc = dc_null_space_speed(traces, ctx.arm)
    f_err = traces["f_n"] - traces["f_d"]
    return {
        "pseudo_inverse": s.null_space.pseudo_inverse,
        "control_period": s.control_period,
        "en_peak_after_step": float(en[after].max()),
        "en_rms_after_step": _rms(en[after]),
        "en_peak_before_step": float(en[before].max()),
        "dc_null_space_speed_peak_after_step": float(dc[after].max()),
        "dc_null_space_speed_peak_before_step": float(dc[before].max()),
        "force_error_rms_after_step": _rms(f_err[after]),
    }


def measure_null_space_motion_into_task(traces: Traces, ctx: RunFacts) -> dict:
    """Eq. 11. Disturbance of force and position while the self-motion sweep runs
    (from the end of its ramp to the end of the run), against the 0.5 s before it."""
    s = ctx.scenario
    t = traces["t"]
    sw = s.desired_null_space.sweep
    during = t >= sw.start_time + sw.ramp_time
    before = (t >= sw.start_time - 0.5) & (t < sw.start_time)
    f_err = traces["f_n"] - traces["f_d"]
    axes = ctx.arm.task_axes
    pos_err = np.column_stack([traces[a] - traces[f"{a}_d"] for a in axes])
    tangential = pos_err @ ctx.tangent
    normal = pos_err @ ctx.normal
    return {
        "null_space_speed_rms": _rms(_norms(traces, "qns")[during]),
        "en_rms": _rms(_norms(traces, "en")[during]),
        "force_error_peak": float(np.abs(f_err[during]).max()),
        "force_error_rms": _rms(f_err[during]),
        "force_error_rms_before": _rms(f_err[before]),
        "tangential_error_peak": float(np.abs(tangential[during]).max()),
        "tangential_error_rms": _rms(tangential[during]),
        "normal_deviation_peak": float(np.abs(normal[during] - normal[before].mean()).max())
        if before.any()
        else math.nan,
    }


def measure_lyapunov(traces: Traces, ctx: RunFacts) -> dict:
    """Eqs. 23–24. The largest increase of ν between consecutive control periods."""
    nu = traces["nu"]
    dnu = np.diff(nu)
    return {
        "nu_initial": float(nu[1]) if len(nu) > 1 else math.nan,
        "nu_final": float(nu[-1]),
        "nu_increase_max": float(dnu.max()),
        "nu_increase_max_relative": float(dnu.max() / max(nu.max(), 1e-300)),
        "periods_with_nu_increase": int(np.sum(dnu > 1e-12 * max(nu.max(), 1e-300))),
        "en_final": float(_norms(traces, "en")[-1]),
    }


def measure_fig3(traces: Traces, ctx: RunFacts) -> dict:
    """The fig3 acceptance figures (primary task and null space), and the largest torque step."""
    from nsdrake.reporting.run_folder import compute_metrics

    s = dataclasses.replace(ctx.scenario, report=dataclasses.replace(ctx.scenario.report, checks=["fig3"]))
    metrics = compute_metrics(s, ctx.station, traces, None)
    # the first contact's figures (a run's report has them since issue 45) are not this
    # measure's columns: its tables compare the window
    left_out = ("window_start", "window_rows", "p_tau_end_without_null_space_task", *FIRST_CONTACT_METRICS)
    metrics = [m for m in metrics if m.name not in left_out]
    row = {m.name: m.value for m in metrics}
    row["all_bounds_met"] = all(m.passed for m in metrics if m.passed is not None)
    row["torque_step_max"] = float(torque_steps(traces).max())
    gap = measuring_window_gap(traces, s.reference.contact_threshold)
    return {**row, "note": gap} if gap else row


def measure_realism(traces: Traces, ctx: RunFacts) -> dict:
    """The realism ladder (nsdrake/realism/), in the fig3 window (from 0.5 s after first
    contact to the end): the measured normal force's error (what the controller and the
    paper's Fig. 3 see), its drift (least-squares slope) and the share of it that the
    impedance law's normal spring adds, K_p,n nᵀ(x_d − x) / K_f (mean; the normal
    reference is frozen where contact was detected, so a tool that lagged its approach
    reference is pressed harder for the rest of the run), the true contact force's
    error, how the force oscillates around f_d (:func:`nsdrake.studies.measures.force_oscillation`;
    no frequency below the noise floor, :data:`~nsdrake.studies.measures.OSCILLATION_FLOOR_SHARE`
    of f_d), the tangential position error, ‖eⁿ‖ and ν."""
    s = ctx.scenario
    t = traces["t"]
    k0 = first_contact_index(traces, s.reference.contact_threshold)
    gap = measuring_window_gap(traces, s.reference.contact_threshold, min_rows=MIN_WINDOW_ROWS)
    if k0 is None:
        return {"first_contact_time": math.inf, "note": gap}
    window = t >= t[k0] + SETTLE_TIME
    row: dict = {"first_contact_time": float(t[k0])}
    if gap:  # the row's force figures stay blank, and the note says why
        return {**row, "note": gap}
    row |= _force_error_figures(traces, ctx, window)
    frequency, rms, p2p = force_oscillation(
        t[window],
        (traces["f_n"] - traces["f_d"])[window],
        floor=OSCILLATION_FLOOR_SHARE * float(traces["f_d"][window].max()),
    )
    row["force_oscillation_frequency"] = frequency if math.isfinite(frequency) else ""  # "": none
    row["force_oscillation_rms"] = rms
    row["force_oscillation_p2p"] = p2p
    pos_err = np.column_stack([traces[a] - traces[f"{a}_d"] for a in ctx.arm.task_axes])[window]
    row["tangential_position_error_rms"] = _rms(pos_err @ ctx.tangent)
    row["en_rms"] = _rms(_norms(traces, "en")[window])
    row["nu_rms"] = _rms(traces["nu"][window])
    return row


def _force_error_figures(traces: Traces, ctx: RunFacts, window: np.ndarray) -> dict:
    """The measured and the true force's error in ``window``, the error's drift, and the
    normal spring's share of it (:func:`measure_realism`)."""
    imp = ctx.scenario.impedance
    t = traces["t"][window]
    error = (traces["f_n"] - traces["f_d"])[window]
    true = traces["f_n_true"] if "f_n_true" in traces else traces["f_n"]
    true_error = (true - traces["f_d"])[window]
    axes = ctx.arm.task_axes[: len(ctx.normal)]
    offset = np.column_stack([traces[f"{a}_d"] - traces[a] for a in axes])[window] @ ctx.normal
    return {
        "force_error_rms": _rms(error),
        "force_error_peak": float(np.abs(error).max()),
        "force_error_mean": float(error.mean()),
        "force_error_drift": drift_rate(t, error),
        "reference_offset_force": float(imp.K_p_normal * offset.mean() / imp.K_f),
        "true_force_error_rms": _rms(true_error),
        "true_force_error_mean": float(true_error.mean()),
    }


def measure_gradient_projection(traces: Traces, ctx: RunFacts) -> dict:
    """Section 3.4 in closed loop. For each criterion while it is the active level-2
    criterion (Fig. 1's mode) and q̇_dⁿ ≠ 0: the share of control periods in which its
    logged value moved against the sign of its gain (task motion included), the share
    in which the commanded step alone, Φᵀ q̇_dⁿ, points the wrong way (the paper's
    claim; joint torque and manipulability, Φ recomputed from q), and its value at
    the start and the end; and, over the whole run, the smallest link–obstacle distance
    and the most contacts of links with obstacles.

    A run in which a link touches the plate or an obstacle has failed: nothing guards
    the links in this family, so a criterion can improve by driving a link into the
    plate, and from then on the arm is jammed against it and the task is lost. Its row
    says when and how hard (``failed_at``), and its criterion figures cover only the
    control periods before that moment (the end is the last one), so that they describe
    the gradient step and not the jammed arm."""
    forbidden = np.flatnonzero(traces["forbidden_contacts"] > 0)
    clean = int(forbidden[0]) if forbidden.size else len(traces)
    row: dict = _gradient_step_figures(_first_rows(traces, clean), ctx)
    row["d_min_min"] = float(traces["d_min"].min())
    row["forbidden_contacts_max"] = int(traces["forbidden_contacts"].max())
    if forbidden.size:
        k = int(forbidden[0])
        row["failed_at"] = (
            f"{traces['t'][k]:.4g} s: a link touched the plate or an obstacle "
            f"(normal force up to {traces['f_n'][k:].max():.3g} N after)"
        )
    return row


def _first_rows(traces: Traces, rows: int) -> Traces:
    return Traces({name: traces[name][:rows] for name in traces.names})


def _gradient_step_figures(traces: Traces, ctx: RunFacts) -> dict:
    """:func:`measure_gradient_projection`'s criterion figures, over ``traces``."""
    s = ctx.scenario
    d = s.desired_null_space
    gains = {1: d.criteria.obstacle.gain, 2: d.criteria.joint_torque.gain, 3: d.criteria.manipulability.gain}
    mode = traces["mode"]
    commanded = _norms(traces, "qns") > 0.0
    row: dict = {"pseudo_inverse": s.null_space.pseudo_inverse, "rotate_gradient": d.rotate_gradient}
    for m, column in MODE_CRITERION.items():
        active = (mode == m) & commanded
        if not active[:-1].any() or gains[m] == 0.0:
            continue
        name = MODE_NAME[m]
        values = traces[column]
        share, periods = wrong_way_share(values, gains[m], active)
        row[f"{name}_active_periods"] = periods
        row[f"{name}_wrong_way_share"] = share
        if m in (2, 3):
            rates = commanded_step_rates(traces, ctx.arm, m, s.reference.force * ctx.normal)
            wrong = (np.sign(rates) == -np.sign(gains[m])) & active
            row[f"{name}_commanded_step_wrong_share"] = float(wrong[:-1].sum()) / periods
        row[f"{name}_start"] = float(values[0])
        row[f"{name}_end"] = float(values[-1])
    return row


def measure_null_space_laws(traces: Traces, ctx: RunFacts) -> dict:
    """Issue 19: one null-space law on one task (:mod:`nsdrake.studies.null_space_laws`)."""
    from nsdrake.studies.null_space_laws import law_figures

    return law_figures(traces, ctx)


def measure_null_space_bandwidth(traces: Traces, ctx: RunFacts) -> dict:
    """Issue 25: one law at one null-space bandwidth (:mod:`nsdrake.studies.null_space_laws`),
    the law's row with the bandwidth it was tuned for (its slowest pole)."""
    from nsdrake.studies.null_space_laws import law_figures

    return law_figures(traces, ctx)


MEASURES: dict[str, Callable[[Traces, RunFacts], dict]] = {
    "contact_force_into_null_space": measure_contact_force_into_null_space,
    "null_space_motion_into_task": measure_null_space_motion_into_task,
    "lyapunov": measure_lyapunov,
    "fig3": measure_fig3,
    "realism": measure_realism,
    "gradient_projection": measure_gradient_projection,
    "null_space_laws": measure_null_space_laws,
    "null_space_bandwidth": measure_null_space_bandwidth,
}


# --- running ------------------------------------------------------------------------

VARIANT_TIMEOUT = 900.0  # [s] of wall time after which a variant still running is stopped (--variant-timeout)
STOP_GRACE = 10.0  # [s] a stopped or interrupted variant has to write its traces before it is killed


@dataclass(frozen=True)
class _Task:
    family: Family
    index: int
    config: Path | None
    duration: float | None
    folder: Path


FAULT_VARIABLE = "NSDRAKE_TEST_FAULT"
SIMULATING_VARIABLE = "NSDRAKE_TEST_SIMULATING"


def _injected_fault(index: int) -> None:
    """Test hook: with NSDRAKE_TEST_FAULT=INDEX:KIND in the environment, variant INDEX dies
    as a segfault would, leaving no result (exit), raises (raise), hangs until interrupted
    (hang), or hangs deaf to Ctrl-C (hang_hard: only a kill ends it); several variants
    take a comma-separated list (0:hang,1:raise). A hanging variant says so in the folder
    of NSDRAKE_TEST_SIMULATING (file INDEX.hanging), when that is set. The tests use it to
    check that ``nsdrake compare`` survives such a variant; unset, it does nothing."""
    faults = dict(entry.partition(":")[::2] for entry in os.environ.get(FAULT_VARIABLE, "").split(","))
    kind = faults.get(str(index))
    if kind is None:
        return
    if kind == "exit":
        os._exit(70)
    if kind in ("hang", "hang_hard"):
        if kind == "hang_hard":
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        if os.environ.get(SIMULATING_VARIABLE):
            (Path(os.environ[SIMULATING_VARIABLE]) / f"{index}.hanging").touch()
        while True:
            time.sleep(1.0)
    raise RuntimeError(f"{FAULT_VARIABLE} asked variant {index} to fail")


def _simulated_time_file(task: _Task, duration: float) -> Callable[[float], None]:
    """Test hook: with NSDRAKE_TEST_SIMULATING=DIR in the environment, variant INDEX keeps
    the time it has simulated [s] in DIR/INDEX, rewritten a hundred times per run, so that
    a test can wait until a variant is simulating (not for an amount of time or CPU, which
    depends on the machine and on whether the kernels were compiled). Unset: does nothing."""
    folder = os.environ.get(SIMULATING_VARIABLE)
    path = Path(folder) / str(task.index) if folder else None

    def simulated(fraction: float) -> None:
        if path is not None:
            partial = path.with_suffix(".partial")
            partial.write_text(f"{fraction * duration!r}\n")
            partial.replace(path)  # whole, never half-written

    return simulated


def _run_variant(task: _Task, progress: Callable[[float], None] | None = None) -> tuple[str, object]:
    """Simulates one variant, writes its traces and measures them (from the file):
    ("ok", row), or ("interrupted", t) when Ctrl-C stopped it (its traces so far are
    written). ``progress`` is called with the fraction simulated, a hundred times per run."""
    from nsdrake.experiment.simulate import DivergenceError, RunInterrupted, run

    _injected_fault(task.index)
    scenario = variant_scenario(task.family, task.index, task.config, task.duration)
    test_hook = _simulated_time_file(task, scenario.duration)

    def simulated(fraction: float) -> None:
        if progress is not None:
            progress(fraction)
        test_hook(fraction)

    diverged = None
    try:  # the same traces as the named systems', cheaper
        traces, built = run(scenario, auto_structure="fused", progress=simulated)
    except DivergenceError as e:  # a row that says so, with what it measured up to then
        traces, built, diverged = e.traces, e.built, f"{e.t:.4g} s: {e.reason}"
    except RunInterrupted as e:
        task.folder.mkdir(parents=True, exist_ok=True)
        e.traces.write_csv(task.folder / "traces.csv")
        return "interrupted", e.t
    task.folder.mkdir(parents=True, exist_ok=True)
    if task.family.measure in (
        "null_space_laws",
        "null_space_bandwidth",
    ):  # per-row figures, kept with the traces
        from nsdrake.studies.null_space_laws import law_columns

        traces = law_columns(traces, scenario, built.station.arm_model)
    traces.write_csv(task.folder / "traces.csv")
    traces = Traces.read_csv(task.folder / "traces.csv")
    row = MEASURES[task.family.measure](traces, RunFacts(scenario=scenario, station=built.station))
    if diverged:  # diverged_at says why its figures are blank
        row.pop("note", None)
        return "ok", {"diverged_at": diverged, **row}
    return "ok", row


def _failure(e: BaseException) -> str:
    return f"failed: {type(e).__name__}: {_cut(e, 200)}"


class _WorkerState:
    """What a worker's SIGINT handler needs to know: whether the run has simulated (its first
    hundredth), and whether it was interrupted."""

    simulating = False
    interrupted = False


def _interrupt_once(signum, frame) -> None:
    """A worker's SIGINT handler. Before the run has simulated anything there is nothing
    to keep: the handler does nothing, and the command, which stops a worker that has not
    reported simulating by killing it (:meth:`_Pool.stop`), ends it at once, wherever it is
    (importing, building, compiling the kernels: an exception raised there can take
    minutes to surface, or none, if a finalizer swallows it). Once it simulates, the first
    SIGINT interrupts the run (which keeps its traces), any later one is ignored, so that
    the traces and the report reach the parent; inside a compile the interruption waits
    for the run's next hundredth."""
    if not _WorkerState.simulating:
        return
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _WorkerState.interrupted = True
    if not compiling():
        raise KeyboardInterrupt


def _variant_process(task: _Task, conn) -> None:
    """Worker process: one variant; sends ("simulating", None) once its run has simulated
    a hundredth, then ("ok", row), ("interrupted", t) or ("failed", reason), and exits.
    It starts with SIGINT ignored (:func:`start_quietly`), so that a Ctrl-C during its
    start-up is not a traceback, and installs its handler first thing. The model's notes
    (nsdrake's logger: a file's parser warnings, no torque limit) stay in the worker: every
    variant would say its family's notes again, once per process; ``nsdrake run`` of the
    scenario says them."""
    signal.signal(signal.SIGINT, _interrupt_once)
    logging.getLogger("nsdrake").setLevel(logging.ERROR)

    def simulated(fraction: float) -> None:
        if not _WorkerState.simulating:
            conn.send(("simulating", None))  # before the flag: a SIGINT meanwhile is a no-op
            _WorkerState.simulating = True
        if _WorkerState.interrupted:  # the handler's exception waited for a compile to end
            raise KeyboardInterrupt

    try:
        if hasattr(signal, "pthread_sigmask"):  # a later worker inherits the start's blocked mask
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        message = _run_variant(task, simulated)
    except BaseException as e:  # every failure, an interruption outside the run included, is the row's
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        message = ("interrupted", None) if isinstance(e, KeyboardInterrupt) else ("failed", _failure(e))
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the report is sent whole
    conn.send(message)
    conn.close()


def _crash(exitcode: int | None) -> str:
    """Why a worker that sent nothing ended."""
    if exitcode is not None and exitcode < 0:
        try:
            return f"crashed: killed by signal {signal.Signals(-exitcode).name}"
        except ValueError:
            return f"crashed: killed by signal {-exitcode}"
    return f"crashed: the process exited with status {exitcode} without a result"


def _interrupted_row(t: float | None) -> dict:
    kept = f" at t = {t:.4g} s; its traces so far are kept" if t is not None else " before it simulated"
    return {"error": f"interrupted{kept}"}


def _timed_out_row(timeout: float, t: float | None) -> dict:
    kept = f"; its traces up to t = {t:.4g} s are kept" if t is not None else ""
    return {"error": f"failed: timed out after {timeout:g} s (--variant-timeout){kept}"}


def start_quietly(process) -> None:
    """Starts ``process`` with SIGINT ignored: an ignored signal stays ignored across exec,
    and Python keeps it so, so a Ctrl-C that lands while the worker imports is not a
    traceback (blocking it is not enough: measured in /proc, the first worker began with
    an empty signal mask, the second with the block inherited, which the worker lifts).
    This process holds SIGINT blocked meanwhile and gets a Ctrl-C that landed as soon as
    the start returns (Linux keeps a blocked signal pending though it is ignored)."""
    if not hasattr(signal, "pthread_sigmask"):
        process.start()
        return
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        process.start()
    finally:
        signal.signal(signal.SIGINT, handler)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


@dataclass
class _Worker:
    index: int
    process: object  # multiprocessing.Process
    deadline: float  # [s, monotonic] when it is stopped (SIGINT), or killed once stopped
    stopped: str | None = None  # why it was stopped: "timeout" or "interrupt"
    simulating: bool = False  # it reported that its run simulates: it has traces to keep


class _Pool:
    """Variants in processes of their own, ``jobs`` at a time. A worker reports through a
    pipe; one that dies without reporting (segfault, os._exit, killed) closes its pipe, so
    the wait always ends and the variant is reported as crashed. A worker still running
    after ``timeout`` is stopped (:meth:`stop`)."""

    def __init__(self, jobs: int, timeout: float, done: Callable[[int, dict], None]):
        self.ctx = multiprocessing.get_context("spawn")
        self.jobs, self.timeout, self.done = jobs, timeout, done
        self.running: dict = {}  # receiving end of the pipe -> _Worker

    def start(self, task: _Task) -> None:
        receive, send = self.ctx.Pipe(duplex=False)
        process = self.ctx.Process(target=_variant_process, args=(task, send), daemon=True)
        start_quietly(process)
        send.close()  # the worker holds the only writing end: its death means EOF here
        self.running[receive] = _Worker(task.index, process, time.monotonic() + self.timeout)

    def wait(self) -> None:
        """Waits for the next report or deadline; reports what finished, stops what is late."""
        now = time.monotonic()
        soonest = min(w.deadline for w in self.running.values())
        ready = multiprocessing.connection.wait(list(self.running), timeout=max(0.0, soonest - now))
        for receive in ready:
            self._read(receive)
        now = time.monotonic()
        for receive, w in list(self.running.items()):
            if w.deadline > now:
                continue
            if w.stopped is None:
                self.stop(w, "timeout")
            else:  # deaf to SIGINT: killed, and reported without traces
                w.process.kill()
                self._finish(receive)

    def stop(self, w: _Worker, why: str) -> None:
        """A worker whose run simulates is sent SIGINT: it writes its traces so far and
        reports, or is killed STOP_GRACE later. One that has not reported simulating has
        nothing to keep (it is starting up, building or compiling) and is killed at once."""
        w.stopped, w.deadline = why, time.monotonic() + STOP_GRACE
        if not w.process.is_alive():
            return
        if w.simulating:
            os.kill(w.process.pid, signal.SIGINT)
        else:
            w.process.kill()

    def _read(self, receive) -> None:
        """The worker's next message: a report finishes it; "simulating" is noted."""
        try:
            message = receive.recv()
        except (EOFError, OSError):
            message = ("crashed", None)
        if message[0] == "simulating":
            self.running[receive].simulating = True
        else:
            self._finish(receive, message)

    def _finish(self, receive, message: tuple[str, object] | None = None) -> None:
        w = self.running.pop(receive)
        while message is None or message[0] == "simulating":  # what a killed worker sent before
            try:
                message = receive.recv() if receive.poll() else ("crashed", None)
            except (EOFError, OSError):
                message = ("crashed", None)
        status, value = message
        receive.close()
        w.process.join()
        if w.stopped == "timeout" and status != "ok":
            row = _timed_out_row(self.timeout, value if status == "interrupted" else None)
        elif w.stopped == "interrupt" and status != "ok":
            row = _interrupted_row(value if status == "interrupted" else None)
        elif status == "ok":
            row = value
        elif status == "interrupted":
            row = _interrupted_row(value)
        else:
            row = {"error": value if status == "failed" else _crash(w.process.exitcode)}
        self.done(w.index, row)

    def interrupt(self) -> None:
        """Ctrl-C: every running variant is stopped (the terminal may have sent it SIGINT
        already) and has STOP_GRACE to report its traces so far."""
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C must not lose the table
        for receive in list(self.running):  # "simulating" sent but not read yet: traces to keep
            while receive in self.running and receive.poll():
                self._read(receive)
        for w in self.running.values():
            self.stop(w, "interrupt")
        while self.running:
            self.wait()

    def close(self) -> None:
        for w in self.running.values():  # after an error here: no worker outlives the command
            w.process.kill()
        for w in self.running.values():
            w.process.join()


def _run_in_processes(tasks: list[_Task], jobs: int, timeout: float, done) -> bool:
    """Runs every task in a :class:`_Pool`; True if Ctrl-C stopped it (the tasks not yet
    started are then not run)."""
    pool = _Pool(jobs, timeout, done)
    pending = list(tasks)
    previous = signal.getsignal(signal.SIGINT)
    try:
        while pending or pool.running:
            while pending and len(pool.running) < jobs:
                pool.start(pending.pop(0))
            pool.wait()
    except KeyboardInterrupt:
        pool.interrupt()
        return True
    finally:
        pool.close()
        signal.signal(signal.SIGINT, previous)
    return False


def _run_here(tasks: list[_Task], done) -> bool:
    """Runs every task in this process, one after the other; True if Ctrl-C stopped it."""
    for task in tasks:
        try:
            status, value = _run_variant(task)
        except KeyboardInterrupt:
            done(task.index, _interrupted_row(None))
            return True
        except Exception as e:  # the variant's row says why; the others still run
            done(task.index, {"error": _failure(e)})
            continue
        if status == "interrupted":
            done(task.index, _interrupted_row(value))
            return True
        done(task.index, value)
    return False


@dataclass
class FamilyResult:
    family: Family
    rows: list[dict]  # one per variant, in the family's order, with "variant" first
    out: Path
    interrupted: bool = False  # Ctrl-C stopped the comparison (the table has every row so far)

    @property
    def failures(self) -> dict[str, str]:
        """Variant name -> why it has no figures (its row's "error")."""
        return {row["variant"]: row["error"] for row in self.rows if "error" in row}

    @property
    def notes(self) -> dict[str, str]:
        """Variant name -> why some of its figures are blank (its row's "note")."""
        return {row["variant"]: row["note"] for row in self.rows if row.get("note")}


def run_family(
    family: Family,
    out: Path,
    *,
    config: Path | None = None,
    duration: float | None = None,
    jobs: int = 1,
    isolate: bool | None = None,
    progress: Callable[[float], None] | None = None,
    variant_timeout: float = VARIANT_TIMEOUT,
    checked: bool = False,
) -> FamilyResult:
    """Runs every variant, writes the table and the overlay plot; first checks every
    variant (:func:`check_variants`) unless the caller has (``checked``).

    With ``isolate`` (the default when ``jobs`` > 1) each variant runs in a process of its
    own, ``jobs`` at a time, and is stopped after ``variant_timeout`` seconds of wall time;
    otherwise one after the other in this process (no time limit). A variant that raises,
    whose process dies, or that runs out of time becomes a row with its reason under
    "error"; the others run on, and the table is written with every row. Ctrl-C stops
    every variant (each keeps its traces so far), writes the table with the rows so far
    and returns with ``interrupted``.
    """
    if not checked:
        check_variants(family, config, duration)  # every input error before any simulation
    folders = [out / "variants" / f"{i:02d}-{slug(v.name)}" for i, v in enumerate(family.variants)]
    declare(out, [*COMPARE_FILES, *(f"{f.relative_to(out).as_posix()}/traces.csv" for f in folders)])
    try:
        return _run_family(family, out, folders, config, duration, jobs, isolate, progress, variant_timeout)
    finally:  # done or failed: the manifest lists what the run wrote, for a later --overwrite
        record_written(out)


# The files a comparison writes beside its variants' traces (declared before any is written).
COMPARE_FILES = (
    "table.md",
    "table.csv",
    "compare.png",
    "force.png",
    "laws.png",
    "bandwidth.png",
    *(f"{name}/table.md" for name in ("task", "posture", "push")),  # null_space_laws' further tables
)


def _run_family(family, out, folders, config, duration, jobs, isolate, progress, timeout) -> FamilyResult:
    tasks = [_Task(family, i, config, duration, folders[i]) for i in range(len(family.variants))]
    rows: dict[int, dict] = {}

    def done(index: int, row: dict) -> None:
        rows[index] = row
        if progress:
            progress(len(rows) / len(tasks))

    if isolate or (isolate is None and jobs > 1):
        interrupted = _run_in_processes(tasks, max(1, jobs), timeout, done)
    else:
        interrupted = _run_here(tasks, done)
    for i in range(len(tasks)):
        rows.setdefault(i, {"error": "not run: the comparison was interrupted"})
    table = [{"variant": family.variants[i].name, **rows[i]} for i in range(len(tasks))]
    _add_ratios(family, table)
    write_table(out, family, table)
    if interrupted:  # no plots: the table and each variant's traces so far
        return FamilyResult(family=family, rows=table, out=out, interrupted=True)
    ran = [(v, f) for v, f, row in zip(family.variants, folders, table, strict=True) if "error" not in row]
    if ran:
        plot_family(
            out / "compare.png",
            family,
            [v for v, _ in ran],
            [Traces.read_csv(f / "traces.csv") for _, f in ran],
        )
        if family.measure == "realism" and len(ran) == len(folders):
            plot_force_panels(out / "force.png", family, [Traces.read_csv(f / "traces.csv") for f in folders])
        if family.measure == "null_space_laws":
            from nsdrake.studies.null_space_laws import plot_laws

            ran_rows = [row for row in table if "error" not in row]
            plot_laws(out / "laws.png", family, ran_rows, [Traces.read_csv(f / "traces.csv") for _, f in ran])
        if family.measure == "null_space_bandwidth":
            from nsdrake.studies.null_space_laws import plot_bandwidth

            plot_bandwidth(out / "bandwidth.png", family, [row for row in table if "error" not in row])
    return FamilyResult(family=family, rows=table, out=out)


def _add_ratios(family: Family, table: list[dict]) -> None:
    """For the Eq. 26 family: each row's null-space peak over that of the dynamically
    consistent row with the same control period, the ratio the paper's claim is about."""
    if family.measure != "contact_force_into_null_space":
        return
    reference = {
        row["control_period"]: row
        for row in table
        if row.get("pseudo_inverse") == "dynamically_consistent" and "en_peak_after_step" in row
    }
    for row in table:
        ref = reference.get(row.get("control_period"))
        if ref is None or "en_peak_after_step" not in row:
            continue
        for key in ("en_peak_after_step", "dc_null_space_speed_peak_after_step"):
            row[f"{key}_vs_dc"] = row[key] / ref[key] if ref[key] > 0 else math.inf


def _format(value) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(value)
    if isinstance(value, float):
        return f"{value:.4g}"
    return " ".join(str(value).split()).replace("|", "\\|")  # one table cell


def write_table(out: Path, family: Family, table: list[dict]) -> None:
    """table.csv (full precision) and table.md (4 significant digits); for null_space_laws,
    table.md holds the loops and the further tables task/, posture/ and push/ the rest
    (:func:`nsdrake.studies.null_space_laws.table_parts`)."""
    columns = list(dict.fromkeys(key for row in table for key in row))
    for key in ("note", "error"):  # why a variant has no (or blank) figures, next to its name
        if key in columns:
            columns.remove(key)
            columns.insert(1, key)
    with (out / "table.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, columns)
        writer.writeheader()
        for row in table:
            writer.writerow({k: row.get(k, "") for k in columns})
    if family.measure != "null_space_laws":
        _write_markdown(out / "table.md", f"# {family.name}", family.description, columns, table)
        return
    from nsdrake.studies.null_space_laws import table_parts

    for folder, header, rows in table_parts(table):  # the loops in table.md, the rest beside it
        if folder:
            (out / folder).mkdir(exist_ok=True)
        title = f"# {family.name}" + (f"/{folder}" if folder else "")
        _write_markdown(out / folder / "table.md", title, family.description, header, rows)


def _write_markdown(path: Path, title: str, description: str, columns: list[str], rows: list[dict]) -> None:
    lines = [title, "", description, ""]
    lines.append("| " + " | ".join(columns) + " |")
    lines.append("|" + "---|" * len(columns))
    for row in rows:
        lines.append("| " + " | ".join(_format(row.get(k, "")) for k in columns) + " |")
    path.write_text("\n".join(lines) + "\n")


def plot_family(path: Path, family: Family, variants: list[Variant], traces: list[Traces]) -> None:
    """Overlays ``variants`` (those of ``family`` that ran): normal force, position error,
    ‖eⁿ‖ and ν over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(4, 1, figsize=(9, 10), sharex=True, constrained_layout=True)
    for variant, tr in zip(variants, traces, strict=True):
        t = tr["t"]
        axes[0].plot(t, tr["f_n"], label=variant.name, lw=1)
        error = np.sqrt(sum((tr[a] - tr[f"{a}_d"]) ** 2 for a in tr.task_axes))
        axes[1].semilogy(t, np.maximum(error, 1e-9), lw=1)
        axes[2].semilogy(t, np.maximum(_norms(tr, "en"), 1e-9), lw=1)
        axes[3].semilogy(t, np.maximum(tr["nu"], 1e-15), lw=1)
    axes[0].plot(traces[0]["t"], traces[0]["f_d"], "k--", lw=0.8, label="desired $f_d$")
    axes[0].set_ylabel("normal force [N]")
    axes[0].legend(fontsize=7, loc="best")
    axes[1].set_ylabel(r"$\|x - x_d\|$ [m]")
    axes[2].set_ylabel(r"$\|e^n\|$ [rad/s]")
    axes[3].set_ylabel(r"$\nu$ [J]")
    axes[3].set_xlabel("time [s]")
    fig.suptitle(f"{family.name}: {family.description}", fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_force_panels(path: Path, family: Family, traces: list[Traces]) -> None:
    """Fig. 3's force plot once per variant, stacked on a shared time axis and force
    scale: the measured normal force and f_d (and the true contact force, where the
    sensor model makes them differ)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    k = len(traces)
    fig, axes = plt.subplots(
        k, 1, figsize=(9, 1.6 * k + 0.8), sharex=True, squeeze=False, constrained_layout=True
    )
    top = max(float(np.nanmax(tr["f_d"])) for tr in traces) * 1.6
    t_end = max(float(tr["t"][-1]) for tr in traces)
    for ax, variant, tr in zip(axes[:, 0], family.variants, traces, strict=True):
        t = tr["t"]
        if t[-1] < 0.99 * t_end:  # the run stopped early (diverged)
            ax.text(0.5, 0.5, f"diverged at t = {t[-1]:.3g} s", transform=ax.transAxes, ha="center")
        if "f_n_true" in tr and np.any(tr["f_n_true"] != tr["f_n"]):
            ax.plot(t, tr["f_n_true"], color="0.6", lw=0.6, label="true contact force")
        ax.plot(t, tr["f_n"], lw=0.7, label="measured $f_n$")
        ax.plot(t, tr["f_d"], "k--", lw=0.7, label="$f_d$")
        ax.set_ylim(-0.1 * top, top)
        ax.set_ylabel("[N]")
        ax.set_title(variant.name, fontsize=8, loc="left")
    axes[0, 0].legend(fontsize=7, loc="upper left", ncol=3)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(f"{family.name}: normal force in the style of Fig. 3", fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)

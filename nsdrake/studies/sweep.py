"""Parameter sweeps (``nsdrake sweep SPEC``): one scenario, many values of its fields.

A sweep spec (``nsdrake/sweeps/NAME.yaml``, or a file of yours) names a shipped base
scenario, optionally a YAML overlay, and the fields to vary::

    description: "…"                 # optional
    base: fig3                       # a shipped scenario
    config: my_settings.yaml         # optional overlay, relative to the spec file
    duration: 2.0                    # optional, overrides the scenario's [s]
    seed: 0                          # random samples and per-run seeds
    axes:                            # any dotted scenario field path
      null_space.K_n: [20.0, 100.0, 500.0]                 # a grid axis: listed values
      impedance.K_p_normal: {random: {low: 50.0, high: 400.0, count: 4}}   # random samples
    metrics: [force_error_rms, null_space_error_rms]

The runs are the product of the grid axes (the first axis varies slowest) and, inside
it, ``count`` points drawn uniformly and jointly in the box of the random axes (all
random axes share one count; the samples come from ``seed``). Each run's scenario is
the base, the overlay, the duration, then the run's values, and must pass
:func:`nsdrake.experiment.scenario.validate` and the model checks before anything runs.

Outputs (``OUT``): ``results.csv`` (one row per run, in run order, byte-identical
whatever the engine and the number of jobs), ``runs/NNNN/traces.csv`` and
``runs/NNNN/result.json`` (written when the run finishes; the table is rebuilt from
them), ``sweep.png``, ``sweep.yaml`` (the spec as given) and ``sweep.json`` (what
identifies the sweep, for resuming). The engines live in :mod:`nsdrake.studies.sweep_engines`.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import itertools
import json
import math
import os
import random
import sys
import time
import typing
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from nsdrake.experiment.output import (
    OutputFolderError,
    declare,
    entries,
    prepare_output_folder,
    read_manifest,
    record_written,
    refuse_foreign,
    remove_listed,
    take_over,
)
from nsdrake.experiment.scenario import (
    Scenario,
    ScenarioError,
    _kind,
    _one_line,
    check_shape,
    load_scenario,
    read_yaml,
    shipped_scenarios,
    validate,
)
from nsdrake.reporting.metrics import D_MIN_AFTER
from nsdrake.reporting.run_folder import scenario_yaml

SWEEP_DIR = Path(__file__).resolve().parent / "sweeps"
SWEEP_CHECKS = ("fig3", "priority")  # what a sweep's run of a planar scenario computes
SPEC_FIELDS = ("description", "base", "config", "duration", "seed", "axes", "metrics")

# The figures `nsdrake run` computes (nsdrake.reporting.run_folder.compute_metrics), with the check of
# report.checks each belongs to. A sweep's run computes every check (so that a spec whose
# metrics change re-tabulates without simulating again).
FIG3_METRICS = (
    "first_contact_time",
    "window_start",
    "window_rows",
    "normal_force_min",
    "force_error_rms",
    "force_error_max",
    "tangential_position_error_rms",
    "null_space_command_rms",
    "null_space_error_rms",
    f"d_min_after_{D_MIN_AFTER:g}s",
    "forbidden_contacts_max",
    "p_tau_end",
    "p_tau_end_without_null_space_task",  # needs the comparison run with q̇_dⁿ = 0 (twice the time)
)
PRIORITY_METRICS = (
    "modes_visited",
    "mode1_time",
    "mode2_time",
    "mode3_time",
    "mode1_d_min_change_min",
    "mode2_p_tau_change_min",
    "mode3_w_change_min",
    "mode_switches",
    "torque_step_p99_elsewhere",
    "torque_step_at_switch_max",
)
METRICS: dict[str, str | None] = {
    **{name: "fig3" for name in FIG3_METRICS},
    **{name: "priority" for name in PRIORITY_METRICS},
    "joint_speed_ratio_max": None,
    "all_bounds_met": None,  # every computed figure meets its bound (true/false)
}
BASELINE_METRIC = "p_tau_end_without_null_space_task"

# Test hook: a worker *process* given this run index exits at once (a crashed worker).
CRASH_ENV = "NSDRAKE_SWEEP_TEST_CRASH"


class SweepError(ScenarioError):
    """A sweep spec that cannot be run; the message is one line naming file and field."""


@dataclass(frozen=True)
class Axis:
    path: str  # dotted scenario field path
    values: tuple | None  # a grid axis
    random: tuple[float, float, int] | None  # (low, high, count): random samples


@dataclass(frozen=True)
class SweepSpec:
    name: str
    source: str  # the spec file
    description: str
    base: str
    config: Path | None
    duration: float | None
    seed: int
    axes: tuple[Axis, ...]
    metrics: tuple[str, ...]
    text: str  # the file as given


@dataclass(frozen=True)
class Run:
    index: int
    values: dict  # axis path -> value
    seed: int
    scenario: Scenario
    yaml: str  # the run's scenario, as the worker receives it
    hash: str  # of yaml and seed: what identifies a finished run

    def task(self, spec: SweepSpec) -> dict:
        """The plain parameters a worker needs (picklable, no Drake objects)."""
        return {
            "index": self.index,
            "scenario_yaml": self.yaml,
            "source": self.scenario.source,
            "base_dir": self.scenario.base_dir,
            "seed": self.seed,
            "hash": self.hash,
            "baseline": BASELINE_METRIC in spec.metrics,
        }


def shipped_sweeps() -> list[str]:
    return sorted(p.stem for p in SWEEP_DIR.glob("*.yaml"))


def spec_path(spec: str) -> Path:
    """A shipped sweep's file, or the path given (anything with a / or a .yaml suffix)."""
    if "/" in spec or os.sep in spec or spec.endswith((".yaml", ".yml")):
        return Path(spec)
    known = shipped_sweeps()
    if spec not in known:
        raise SweepError(
            f"unknown sweep '{spec}'; the shipped sweeps are {', '.join(known)} "
            "(or give a path to a spec file)"
        )
    return SWEEP_DIR / f"{spec}.yaml"


# --- the spec ---------------------------------------------------------------------------


def field_type(path: str):
    """The type of the scenario field at a dotted ``path``; raises ValueError with the reason."""
    schema: typing.Any = Scenario
    parts = path.split(".")
    if not path or any(not p for p in parts):
        raise ValueError("not a dotted field path")
    for i, part in enumerate(parts):
        where = ".".join(parts[:i])
        if dataclasses.is_dataclass(schema):
            fields = [f.name for f in dataclasses.fields(schema) if f.metadata.get("yaml", True)]
            if part not in fields:
                here = f" of {where}" if where else ""
                raise ValueError(f"unknown field '{part}'; valid fields{here} are {', '.join(fields)}")
            schema = typing.get_type_hints(schema)[part]
        elif typing.get_origin(schema) is dict:
            schema = typing.get_args(schema)[1]  # a key, e.g. a joint name (checked by the model checks)
        else:
            raise ValueError(f"{where} is {_kind(schema)}, it has no field '{part}'")
    return schema


def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _axis(src: str, path, spec) -> Axis:
    where = f"axes.{path}"
    if not isinstance(path, str):
        raise SweepError(f"{src}: axes: {path!r}: a field path must be a string")
    try:
        schema = field_type(path)
    except ValueError as e:
        raise SweepError(f"{src}: {where}: {e}") from None
    if isinstance(spec, list):
        if not spec:
            raise SweepError(f"{src}: {where}: empty axis; give at least one value")
        for i, value in enumerate(spec):
            problem = check_shape(value, schema, f"{where}[{i}]")
            if problem:
                raise SweepError(f"{src}: {problem}")
        return Axis(path, tuple(spec), None)
    if isinstance(spec, dict) and set(spec) == {"random"}:
        r = spec["random"]
        where = f"{where}.random"
        if schema is not float:
            raise SweepError(f"{src}: {where}: random samples need a number field; {path} is {_kind(schema)}")
        if not isinstance(r, dict) or set(r) != {"low", "high", "count"}:
            raise SweepError(f"{src}: {where}: must be a mapping with low, high and count, got {r!r}")
        if not _number(r["low"]):
            raise SweepError(f"{src}: {where}.low: must be a finite number, got {r['low']!r}")
        if not _number(r["high"]) or r["high"] <= r["low"]:
            raise SweepError(
                f"{src}: {where}.high: must be a number above low = {r['low']}, got {r['high']!r}"
            )
        if not isinstance(r["count"], int) or isinstance(r["count"], bool) or r["count"] < 1:
            raise SweepError(f"{src}: {where}.count: must be a whole number >= 1, got {r['count']!r}")
        return Axis(path, None, (float(r["low"]), float(r["high"]), r["count"]))
    raise SweepError(
        f"{src}: {where}: must be a list of values or {{random: {{low, high, count}}}}, got {spec!r}"
    )


def load_sweep(spec: str) -> SweepSpec:
    """A sweep spec (shipped name or path), every field checked; raises SweepError."""
    path = spec_path(spec)
    try:
        text, data = read_yaml(path, "sweep spec")
    except ScenarioError as e:
        raise SweepError(str(e)) from None
    src = str(path)
    if not isinstance(data, dict):
        raise SweepError(f"{src}: the file: must be a mapping with {', '.join(SPEC_FIELDS)}")
    for key in data:
        if key not in SPEC_FIELDS:
            raise SweepError(f"{src}: {key}: unknown field; valid fields are {', '.join(SPEC_FIELDS)}")
    if "base" not in data:
        raise SweepError(f"{src}: base: missing; name a shipped scenario ({', '.join(shipped_scenarios())})")
    if data["base"] not in shipped_scenarios():
        raise SweepError(
            f"{src}: base: unknown scenario {data['base']!r}; the shipped scenarios are "
            f"{', '.join(shipped_scenarios())}"
        )
    description = data.get("description", "")
    if not isinstance(description, str):
        raise SweepError(f"{src}: description: must be a string, got {description!r}")
    config = data.get("config")
    if config is not None:
        if not isinstance(config, str) or not config:
            raise SweepError(f"{src}: config: must be a path to a YAML file, got {config!r}")
        config = (path.parent / config) if not Path(config).is_absolute() else Path(config)
        if not config.is_file():
            raise SweepError(f"{src}: config: no such file {config}")
    duration = data.get("duration")
    if duration is not None and (not _number(duration) or duration <= 0):
        raise SweepError(f"{src}: duration: must be a number of seconds > 0, got {duration!r}")
    seed = data.get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise SweepError(f"{src}: seed: must be a whole number >= 0, got {seed!r}")
    axes_data = data.get("axes")
    if not isinstance(axes_data, dict) or not axes_data:
        raise SweepError(f"{src}: axes: must map at least one field path to its values, got {axes_data!r}")
    axes = tuple(_axis(src, p, v) for p, v in axes_data.items())
    for a, b in itertools.combinations(axes, 2):
        if a.path.startswith(b.path + ".") or b.path.startswith(a.path + "."):
            raise SweepError(f"{src}: axes.{a.path}: overlaps axes.{b.path}; sweep one or the other")
    counts = sorted({a.random[2] for a in axes if a.random})
    if len(counts) > 1:
        raise SweepError(
            f"{src}: axes: the random axes are sampled together and must share one count, got "
            f"{', '.join(map(str, counts))}"
        )
    metrics = data.get("metrics")
    if not isinstance(metrics, list) or not metrics:
        raise SweepError(
            f"{src}: metrics: must be a list of metric names; valid names are {', '.join(METRICS)}"
        )
    for i, m in enumerate(metrics):
        if m not in METRICS:
            raise SweepError(
                f"{src}: metrics[{i}]: unknown metric {m!r}; valid names are {', '.join(METRICS)}"
            )
    if len(set(metrics)) != len(metrics):
        raise SweepError(f"{src}: metrics: names must be distinct")
    return SweepSpec(
        name=path.stem,
        source=src,
        description=description,
        base=data["base"],
        config=config,
        duration=float(duration) if duration is not None else None,
        seed=seed,
        axes=axes,
        metrics=tuple(metrics),
        text=text,
    )


# --- the runs ---------------------------------------------------------------------------


def run_seed(seed: int, index: int) -> int:
    """The seed of run ``index``: independent streams per run, fixed by the spec's seed."""
    return int(np.random.SeedSequence(entropy=seed, spawn_key=(index,)).generate_state(1)[0])


def expand(spec: SweepSpec) -> list[dict]:
    """The values of every run, in run order: the grid's product (first axis slowest),
    and inside it the random points (uniform in the random axes' box, from ``seed``)."""
    grid = [a for a in spec.axes if a.values is not None]
    rand = [a for a in spec.axes if a.random is not None]
    points = [{}]
    if rand:
        count = rand[0].random[2]
        rng = np.random.default_rng(spec.seed)
        u = rng.random((count, len(rand)))
        points = [
            {a.path: float(a.random[0] + u[k, j] * (a.random[1] - a.random[0])) for j, a in enumerate(rand)}
            for k in range(count)
        ]
    out = []
    for combo in itertools.product(*(a.values for a in grid)):
        for point in points:
            values = dict(zip((a.path for a in grid), combo, strict=True)) | point
            out.append({a.path: values[a.path] for a in spec.axes})  # spec order
    return out


def _nested(values: dict) -> dict:
    tree: dict = {}
    for path, value in values.items():
        node = tree
        *parents, leaf = path.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return tree


def _label(values: dict) -> str:
    return ", ".join(f"{p}={_cell(v)}" for p, v in values.items())


def plan_runs(spec: SweepSpec, *, check_models: bool = True) -> list[Run]:
    """Every run's scenario, validated (and checked against the model: the diagram is
    built once per run, about 0.05 s); the first problem is a one-line ScenarioError."""
    from pydrake.common.yaml import yaml_load_typed

    from nsdrake.reporting.run_folder import check_scenario

    base = load_scenario(spec.base, config=spec.config, duration=spec.duration)
    runs = []
    for index, values in enumerate(expand(spec)):
        source = f"{spec.source} (run {index}: {_label(values)})"
        try:
            scenario = yaml_load_typed(schema=Scenario, data=yaml.safe_dump(_nested(values)), defaults=base)
        except Exception as e:
            raise SweepError(f"{source}: {_one_line(e)}") from None
        scenario.source, scenario.base_dir = source, base.base_dir
        validate(scenario)
        if check_models:
            check_scenario(scenario)
        text = scenario_yaml(scenario)
        seed = run_seed(spec.seed, index)
        digest = hashlib.sha256(f"{text}\nseed: {seed}\n".encode()).hexdigest()
        runs.append(Run(index, values, seed, scenario, text, digest))
    return runs


# --- the worker -------------------------------------------------------------------------


def simulate_run(task: dict) -> dict:
    """Worker: builds the run's diagram from plain parameters, simulates, measures.
    Returns plain results: status, reason, metrics (name -> number) and the traces
    as CSV text. Never raises for a failing run: the failure is the result."""
    from pydrake.common.yaml import yaml_load_typed

    from nsdrake.experiment.simulate import DivergenceError, run
    from nsdrake.reporting.run_folder import compute_metrics

    start = time.perf_counter()
    result = {"index": task["index"], "status": "ok", "reason": "", "metrics": {}, "traces_csv": None}
    random.seed(task["seed"])
    np.random.seed(task["seed"] % 2**32)
    try:
        scenario = yaml_load_typed(schema=Scenario, data=task["scenario_yaml"], defaults=Scenario())
        scenario.source, scenario.base_dir = task["source"], task["base_dir"]
        # fig3's and the priority checks for the planar scenarios (every figure a spec may
        # name); a scenario with checks of its own (the Panda's) keeps its own.
        own = scenario.report.checks
        checks = own if set(own) - set(SWEEP_CHECKS) else list(SWEEP_CHECKS)
        measured = dataclasses.replace(scenario, report=dataclasses.replace(scenario.report, checks=checks))
        try:
            traces, built = run(scenario)
        except DivergenceError as e:
            result.update(status="failed", reason=str(e), traces_csv=_csv_text(e.traces))
        else:
            result["traces_csv"] = _csv_text(traces)
            baseline = run(scenario, null_space_task=False)[0] if task["baseline"] else None
            metrics = compute_metrics(measured, built.station, traces, baseline)
            values = {m.name: _plain(m.value) for m in metrics}
            values["all_bounds_met"] = all(m.passed for m in metrics if m.passed is not None)
            result["metrics"] = values
    except Exception as e:  # a failing run is a row, not the end of the sweep
        reason = _one_line(e) or type(e).__name__
        result.update(status="failed", reason=f"{type(e).__name__}: {reason}")
    result["wall_time_s"] = time.perf_counter() - start
    return result


def _csv_text(traces) -> str:
    buffer = io.StringIO()
    traces.write_csv(buffer)  # the same bytes as nsdrake run's traces.csv
    return buffer.getvalue()


def _plain(value):
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    return float(value)


def crash_if_asked(task: dict) -> None:
    """The test hook: called in worker processes only (never in the caller's)."""
    if os.environ.get(CRASH_ENV) == str(task["index"]):
        os._exit(70)


# --- the output folder ------------------------------------------------------------------


def sweep_identity(spec: SweepSpec, runs: list[Run]) -> str:
    """What a resumed sweep must share with the folder's: its runs (each run's scenario
    and seed). The metrics are not part of it: the table is rebuilt from the runs."""
    return hashlib.sha256("\n".join(r.hash for r in runs).encode()).hexdigest()


SWEEP_FILES = ("sweep.yaml", "sweep.json", "results.csv", "sweep.png")


def _with_tmp(names) -> list[str]:
    """The names and the temporary files :func:`_write_atomic` writes them through."""
    return [x for name in names for x in (name, f"{name}.tmp")]


def run_entries(index: int) -> list[str]:
    """What a sweep writes for run ``index`` (paths relative to the sweep's folder)."""
    return _with_tmp([f"runs/{index:04d}/traces.csv", f"runs/{index:04d}/result.json"])


def _previous_sweep(out: Path) -> dict | None:
    try:
        previous = json.loads((out / "sweep.json").read_text())
    except (OSError, ValueError):
        return None
    return previous if isinstance(previous, dict) else None


def prepare_sweep_folder(out: Path, spec: SweepSpec, runs: list[Run], *, overwrite: bool) -> bool:
    """Claims ``out`` for the sweep (True: resuming this same sweep there), under the rules
    of every nsdrake output folder (:mod:`nsdrake.experiment.output`): a new or empty folder is
    claimed; a folder holding this sweep (its manifest and ``sweep.json``) is taken over
    to resume; a folder holding another sweep is refused unless ``overwrite``, and then
    keeps the runs still part of this sweep and removes only the listed files of the
    others; any other folder is treated as ``nsdrake run`` treats it (with ``overwrite``
    only what an nsdrake command listed is removed). A folder holding anything nsdrake
    did not write is refused, removing nothing."""
    out = Path(out)
    identity = sweep_identity(spec, runs)
    if out.exists() and not out.is_dir():
        raise OutputFolderError(f"{out}: exists and is not a folder")
    resuming = False
    if not out.is_dir() or not entries(out):
        if out.is_dir() and read_manifest(out) is not None:
            take_over(out)  # claimed empty (the default folder), or a killed command's
        else:
            prepare_output_folder(out, overwrite=False)
    else:
        manifest = read_manifest(out)
        previous = _previous_sweep(out) if manifest is not None else None
        if previous is None:
            if not overwrite:
                raise OutputFolderError(
                    f"{out}: folder is not empty; choose another --out or pass --overwrite"
                )
            prepare_output_folder(out, overwrite=True)  # an nsdrake run's: its listed files only
        elif previous.get("identity") == identity:
            take_over(out)
            resuming = True
        else:
            if not overwrite:
                raise OutputFolderError(
                    f"{out}: holds a sweep of {previous.get('spec', 'another spec')} whose runs differ "
                    f"from {spec.source}'s (the spec or its scenario changed); pass --overwrite to replace "
                    "them, or choose another --out"
                )
            manifest = take_over(out)
            refuse_foreign(out, manifest)
            keep = {f"runs/{r.index:04d}/" for r in runs}
            remove_listed(
                out, [e for e in manifest.listed if e.startswith("runs/") and not e.startswith(tuple(keep))]
            )
    declare(out, _with_tmp(SWEEP_FILES))
    _write_atomic(out / "sweep.yaml", spec.text)
    body = {"spec": spec.source, "identity": identity, "runs": len(runs)}
    _write_atomic(out / "sweep.json", json.dumps(body, indent=2) + "\n")
    return resuming


def _write_atomic(path: Path, text: str) -> None:
    """Written in full or not at all (a killed sweep leaves no half file behind)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def run_folder(out: Path, index: int) -> Path:
    return Path(out) / "runs" / f"{index:04d}"


def finished(out: Path, run: Run, spec: SweepSpec) -> dict | None:
    """The stored result of ``run`` if it finished with these parameters (a worker that
    died is tried again, and so is a run without the comparison run a metric now needs),
    else None."""
    try:
        record = json.loads((run_folder(out, run.index) / "result.json").read_text())
    except (OSError, ValueError):
        return None
    if record.get("hash") != run.hash or record.get("crashed"):
        return None
    if BASELINE_METRIC in spec.metrics and not record.get("baseline"):
        return None
    return record


def store(out: Path, run: Run, result: dict, baseline: bool) -> dict:
    """Writes the run's traces, then its result.json (so a result always has its traces);
    returns the record as it reads back from the file."""
    folder = run_folder(out, run.index)
    declare(out, run_entries(run.index))
    folder.mkdir(parents=True, exist_ok=True)
    if result.get("traces_csv") is not None:
        _write_atomic(folder / "traces.csv", result["traces_csv"])
    record = {
        "index": run.index,
        "hash": run.hash,
        "seed": run.seed,
        "values": run.values,
        "status": result["status"],
        "reason": result["reason"],
        "crashed": bool(result.get("crashed", False)),
        "baseline": baseline,  # the comparison run (q̇_dⁿ = 0) was simulated
        "metrics": result["metrics"],
        "wall_time_s": result.get("wall_time_s"),
    }
    text = json.dumps(record, indent=2) + "\n"
    _write_atomic(folder / "result.json", text)
    return json.loads(text)


# --- the table --------------------------------------------------------------------------


def _cell(value) -> str:
    """Deterministic text: repr for floats (shortest exact), JSON for lists and mappings."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return value
    return json.dumps(value, sort_keys=True)


def write_results(out: Path, spec: SweepSpec, records: dict[int, dict]) -> None:
    """results.csv from the finished runs, sorted by index (whatever order they finished in)."""
    paths = [a.path for a in spec.axes]
    columns = ["index", *paths, "seed", "status", "reason", *spec.metrics]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for index in sorted(records):
        r = records[index]
        writer.writerow(
            [
                str(index),
                *(_cell(r["values"][p]) for p in paths),
                str(r["seed"]),
                r["status"],
                r["reason"],
                *(_cell(r["metrics"].get(m)) for m in spec.metrics),
            ]
        )
    _write_atomic(Path(out) / "results.csv", buffer.getvalue())


# --- the plot ---------------------------------------------------------------------------


def _numeric(values: list) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)


def plot_sweep(path: Path, spec: SweepSpec, records: dict[int, dict]) -> None:
    """Each metric against each swept parameter; a heat map per metric when exactly two
    axes are swept on a full grid. Failed runs are left out (their count is in the title)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [records[i] for i in sorted(records) if records[i]["status"] == "ok"]
    failed = sum(1 for r in records.values() if r["status"] != "ok")
    paths = [a.path for a in spec.axes]

    def metric(r, m):
        v = r["metrics"].get(m)
        return math.nan if v is None else float(v)

    grid = len(paths) == 2 and all(a.values is not None and _numeric(list(a.values)) for a in spec.axes)
    rows, cols = len(spec.metrics), (1 if grid else len(paths))
    fig, axes = plt.subplots(
        rows, cols, figsize=(4.2 * cols + 1, 3.2 * rows + 0.6), squeeze=False, constrained_layout=True
    )
    for i, m in enumerate(spec.metrics):
        if grid:
            ax = axes[i][0]
            xs, ys = list(dict.fromkeys(spec.axes[0].values)), list(dict.fromkeys(spec.axes[1].values))
            z = np.full((len(ys), len(xs)), np.nan)
            for r in ok:
                z[ys.index(r["values"][paths[1]]), xs.index(r["values"][paths[0]])] = metric(r, m)
            image = ax.imshow(z, origin="lower", aspect="auto", cmap="viridis")
            ax.set_xticks(range(len(xs)), [_cell(x) for x in xs])
            ax.set_yticks(range(len(ys)), [_cell(y) for y in ys])
            for (yi, xi), value in np.ndenumerate(z):
                bright = not np.isnan(value) and image.norm(value) > 0.6  # dark text on light cells
                text = "failed" if np.isnan(value) else f"{value:.3g}"
                ax.text(xi, yi, text, ha="center", va="center", fontsize=7, color="k" if bright else "w")
            ax.set_xlabel(paths[0])
            ax.set_ylabel(paths[1])
            ax.set_title(m, fontsize=9)
            fig.colorbar(image, ax=ax)
            continue
        for j, p in enumerate(paths):
            ax = axes[i][j]
            xs = [r["values"][p] for r in ok]
            ys = [metric(r, m) for r in ok]
            if _numeric(xs):
                ax.plot(xs, ys, "o", ms=4)
            else:
                labels = list(dict.fromkeys(_cell(x) for x in xs))
                ax.plot([labels.index(_cell(x)) for x in xs], ys, "o", ms=4)
                ax.set_xticks(range(len(labels)), labels, rotation=30, fontsize=7)
            ax.set_xlabel(p)
            ax.set_ylabel(m, fontsize=8)
    title = f"sweep {spec.name}: {len(ok)} runs" + (f", {failed} failed (not shown)" if failed else "")
    fig.suptitle(title, fontsize=10)
    fig.savefig(path, dpi=100)
    plt.close(fig)


# --- running ----------------------------------------------------------------------------


class SweepProgress:
    """``\\r[#####.....] 12/40`` on a terminal; silent when the stream is not one (CI logs)."""

    def __init__(self, total: int, stream=None, width: int = 30):
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = self.stream.isatty()
        self.total, self.width = total, width

    def __call__(self, done: int, failed: int = 0):
        if not self.enabled:
            return
        k = int(self.width * done / max(self.total, 1))
        tail = f" ({failed} failed)" if failed else ""
        self.stream.write(f"\r[{'#' * k}{'.' * (self.width - k)}] {done}/{self.total}{tail}")
        if done >= self.total:
            self.stream.write("\n")
        self.stream.flush()


@dataclass
class SweepOutcome:
    out: Path
    records: dict[int, dict]
    simulated: list[int]  # the indices run this time (the others were already finished)

    @property
    def failed(self) -> list[int]:
        return [i for i in sorted(self.records) if self.records[i]["status"] != "ok"]


def run_sweep(
    spec: SweepSpec,
    runs: list[Run],
    out: Path,
    *,
    engine: str = "process",
    jobs: int = 2,
    scheduler: str | None = None,
    overwrite: bool = False,
    progress=None,
    prepared: bool = False,
) -> SweepOutcome:
    """Runs every run not already finished in ``out`` (claimed here, unless ``prepared``
    by :func:`prepare_sweep_folder`); writes each result as it comes. Done, failed or
    interrupted, the folder's manifest then lists what the sweep wrote."""
    out = Path(out)
    if not prepared:
        prepare_sweep_folder(out, spec, runs, overwrite=overwrite)
    try:
        return _run_sweep(spec, runs, out, engine=engine, jobs=jobs, scheduler=scheduler, progress=progress)
    finally:
        record_written(out)


def _run_sweep(spec, runs, out, *, engine, jobs, scheduler, progress) -> SweepOutcome:
    from nsdrake.studies.sweep_engines import results

    records = {r.index: rec for r in runs if (rec := finished(out, r, spec)) is not None}
    write_results(out, spec, records)
    todo = [r for r in runs if r.index not in records]
    by_index = {r.index: r for r in runs}
    simulated = []
    if progress:
        progress(len(records), sum(1 for r in records.values() if r["status"] != "ok"))
    for result in results([r.task(spec) for r in todo], engine=engine, jobs=jobs, scheduler=scheduler):
        run = by_index[result["index"]]
        records[run.index] = store(out, run, result, BASELINE_METRIC in spec.metrics)
        simulated.append(run.index)
        write_results(out, spec, records)
        if progress:
            progress(len(records), sum(1 for r in records.values() if r["status"] != "ok"))
    plot_sweep(out / "sweep.png", spec, records)
    return SweepOutcome(out=out, records=records, simulated=simulated)


def sweep_command(args) -> int:
    """``nsdrake sweep``: every input checked (spec, engine, each run's scenario, the
    folder) before the first run; exit status 1 if any run failed."""
    from nsdrake.reporting.run_folder import default_output_folder
    from nsdrake.studies.sweep_engines import check_engine

    spec = load_sweep(args.spec)
    check_engine(args.engine, args.scheduler)
    runs = plan_runs(spec)
    out = Path(args.out) if args.out is not None else default_output_folder(f"sweep-{spec.name}")
    where = f"a Dask cluster at {args.scheduler}" if args.scheduler else (
        f"a local Dask cluster of {args.jobs} workers" if args.engine == "dask" else
        f"{args.jobs} processes" if args.jobs > 1 else "this process"
    )  # fmt: skip
    resume = f"nsdrake sweep {args.spec} --out {out}"
    prepare_sweep_folder(out, spec, runs, overwrite=args.overwrite)  # refused before a word is printed
    print(f"nsdrake: sweeping {spec.name}: {len(runs)} runs on {where} into {out}/")
    try:
        outcome = run_sweep(
            spec,
            runs,
            out,
            engine=args.engine,
            jobs=args.jobs,
            scheduler=args.scheduler,
            progress=SweepProgress(len(runs)),
            prepared=True,
        )
    except KeyboardInterrupt:
        kept = sum(1 for r in runs if finished(out, r, spec) is not None)
        print(f"\nnsdrake: interrupted; {kept} of {len(runs)} runs are kept in {out}/; resume with: {resume}",
              file=sys.stderr)  # fmt: skip
        return 130
    skipped = len(runs) - len(outcome.simulated)
    print(
        f"nsdrake: {len(outcome.simulated)} runs simulated"
        + (f", {skipped} already finished (resumed)" if skipped else "")
        + f"; wrote {out}/: results.csv, sweep.png, runs/NNNN/traces.csv"
    )
    for i in outcome.failed:
        print(f"nsdrake: error: run {i} ({_label(outcome.records[i]['values'])}) failed: "
              f"{outcome.records[i]['reason']}", file=sys.stderr)  # fmt: skip
    return 1 if outcome.failed else 0

"""A sweep's spec (``nsdrake sweep SPEC``) and its runs: every field checked, the runs
expanded from the grid and the random samples, each run's scenario validated.

A sweep spec (``nsdrake/studies/sweeps/NAME.yaml``, or a file of yours) names a shipped
base scenario, optionally a YAML overlay, and the fields to vary (docs/command_line.md: Sweeps)::

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
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import os
import typing
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nsdrake.experiment.scenario import (
    JOINT_TABLES,
    Scenario,
    ScenarioError,
    _kind,
    _name,
    _one_line,
    _show,
    check_shape,
    load_scenario,
    overlay,
    read_yaml,
    shipped_scenarios,
    validate,
    value_at,
)
from nsdrake.reporting.metrics import D_MIN_AFTER, FIRST_CONTACT_METRICS
from nsdrake.reporting.run_folder import scenario_yaml

SWEEP_DIR = Path(__file__).resolve().parent / "sweeps"
SPEC_FIELDS = ("description", "base", "config", "duration", "seed", "axes", "metrics")

# The figures `nsdrake run` computes (nsdrake.reporting.run_folder.compute_metrics), with the check of
# report.checks each belongs to. A sweep's run computes every check (so that a spec whose
# metrics change re-tabulates without simulating again).
FIG3_METRICS = (
    "first_contact_time",
    "window_start",
    "window_rows",
    *FIRST_CONTACT_METRICS,  # the first contact's transient (issue 45)
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
    """A shipped sweep's file, or the path given (anything with a /, a suffix such as .yaml
    or .json, or the name of a file that exists)."""
    if "/" in spec or os.sep in spec or Path(spec).suffix or Path(spec).is_file():
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
        raise SweepError(f"{src}: axes: {_show(path)}: a field path must be a string")
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
            raise SweepError(f"{src}: {where}: must be a mapping with low, high and count, got {_show(r)}")
        if not _number(r["low"]):
            raise SweepError(f"{src}: {where}.low: must be a finite number, got {_show(r['low'])}")
        if not _number(r["high"]) or r["high"] <= r["low"]:
            raise SweepError(
                f"{src}: {where}.high: must be a number above low = {r['low']}, got {_show(r['high'])}"
            )
        if not isinstance(r["count"], int) or isinstance(r["count"], bool) or r["count"] < 1:
            raise SweepError(f"{src}: {where}.count: must be a whole number >= 1, got {_show(r['count'])}")
        return Axis(path, None, (float(r["low"]), float(r["high"]), r["count"]))
    raise SweepError(
        f"{src}: {where}: must be a list of values or {{random: {{low, high, count}}}}, got {_show(spec)}"
    )


def load_sweep(spec: str) -> SweepSpec:
    """A sweep spec (shipped name or path), every field checked; raises SweepError."""
    path = spec_path(spec)
    try:
        text, data = read_yaml(path, "sweep spec")
    except ScenarioError as e:
        raise SweepError(str(e)) from None
    src = str(path)
    _check_fields(src, data)
    duration = data.get("duration")
    if duration is not None and (not _number(duration) or duration <= 0):
        raise SweepError(f"{src}: duration: must be a number of seconds > 0, got {_show(duration)}")
    seed = data.get("seed", 0)
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise SweepError(f"{src}: seed: must be a whole number >= 0, got {_show(seed)}")
    return SweepSpec(
        name=path.stem,
        source=src,
        description=data.get("description", ""),
        base=data["base"],
        config=_config(src, data.get("config"), path),
        duration=float(duration) if duration is not None else None,
        seed=seed,
        axes=_axes(src, data.get("axes")),
        metrics=_metrics(src, data.get("metrics")),
        text=text,
    )


def _check_fields(src: str, data) -> None:
    """The file is a mapping of known fields, with a shipped base and a text description."""
    if not isinstance(data, dict):
        raise SweepError(f"{src}: the file: must be a mapping with {', '.join(SPEC_FIELDS)}")
    for key in data:
        if key not in SPEC_FIELDS:
            raise SweepError(f"{src}: {_name(key)}: unknown field; valid fields are {', '.join(SPEC_FIELDS)}")
    if "base" not in data:
        raise SweepError(f"{src}: base: missing; name a shipped scenario ({', '.join(shipped_scenarios())})")
    if not isinstance(data["base"], str) or data["base"] not in shipped_scenarios():
        raise SweepError(
            f"{src}: base: unknown scenario {_show(data['base'])}; the shipped scenarios are "
            f"{', '.join(shipped_scenarios())}"
        )
    description = data.get("description", "")
    if not isinstance(description, str):
        raise SweepError(f"{src}: description: must be a string, got {_show(description)}")


def _config(src: str, config, path: Path) -> Path | None:
    if config is None:
        return None
    if not isinstance(config, str) or not config:
        raise SweepError(f"{src}: config: must be a path to a YAML file, got {_show(config)}")
    config = (path.parent / config) if not Path(config).is_absolute() else Path(config)
    if not config.is_file():
        raise SweepError(f"{src}: config: no such file {config}")
    return config


def _axes(src: str, axes_data) -> tuple[Axis, ...]:
    if not isinstance(axes_data, dict) or not axes_data:
        raise SweepError(
            f"{src}: axes: must map at least one field path to its values, got {_show(axes_data)}"
        )
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
    return axes


def _metrics(src: str, metrics) -> tuple[str, ...]:
    if not isinstance(metrics, list) or not metrics:
        raise SweepError(
            f"{src}: metrics: must be a list of metric names; valid names are {', '.join(METRICS)}"
        )
    for i, m in enumerate(metrics):
        if not isinstance(m, str) or m not in METRICS:
            raise SweepError(
                f"{src}: metrics[{i}]: unknown metric {_show(m)}; valid names are {', '.join(METRICS)}"
            )
    if len(set(metrics)) != len(metrics):
        raise SweepError(f"{src}: metrics: names must be distinct")
    return tuple(metrics)


# A sweep of more runs than this is refused unless --max-runs raises it: 1000 runs of the
# shipped robustness sweep's kind (3.5 s of fig3 each) take about 75 minutes on two cores,
# and checking their scenarios alone about a minute.
MAX_RUNS = 1000


def run_count(spec: SweepSpec) -> int:
    """How many runs the spec makes: the product of the grid axes' lengths, times the
    random axes' shared count (computed without listing the runs)."""
    count = math.prod(len(a.values) for a in spec.axes if a.values is not None)
    counts = [a.random[2] for a in spec.axes if a.random is not None]
    return count * (counts[0] if counts else 1)


def sweep_size(spec: SweepSpec) -> str:
    """The size in words: "18 runs (3 x 3 x 2)"."""
    factors = [str(len(a.values)) for a in spec.axes if a.values is not None]
    counts = [a.random[2] for a in spec.axes if a.random is not None]
    if counts:
        factors.append(f"{counts[0]} random samples")
    total = run_count(spec)
    shape = f" ({' x '.join(factors)})" if len(factors) > 1 else ""
    return f"{total} run{'s' if total != 1 else ''}{shape}"


def check_size(spec: SweepSpec, max_runs: int = MAX_RUNS) -> int:
    """The number of runs; a sweep of more than ``max_runs`` is refused (SweepError) before
    any run is listed."""
    total = run_count(spec)
    if total > max_runs:
        raise SweepError(
            f"{spec.source}: axes: {sweep_size(spec)} is more than --max-runs {max_runs} allows; "
            f"pass --max-runs {total} to run them all, or sweep fewer values"
        )
    return total


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


def _nested(values: dict, base: Scenario) -> dict:
    """The runs' values as nested mappings for :func:`overlay`. An axis into a table keyed
    by joint name (arm.initial_positions.joint2) sets that one entry: the table is given
    whole, the base's with the entry set (an overlay replaces a joint table it gives); an
    axis that is a whole table (sweep.direction: [{joint1: 1}, …]) replaces it."""
    tree: dict = {}
    for table in JOINT_TABLES:
        if any(path.startswith(table + ".") for path in values):
            node = tree
            *parents, leaf = table.split(".")
            for p in parents:
                node = node.setdefault(p, {})
            node[leaf] = dict(value_at(base, table))
    for path, value in values.items():
        node = tree
        *parents, leaf = path.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    return tree


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


def _label(values: dict) -> str:
    return ", ".join(f"{p}={_cell(v)}" for p, v in values.items())


def plan_runs(spec: SweepSpec, *, check_models: bool = True) -> list[Run]:
    """Every run's scenario, validated (and checked against the model: the diagram is
    built once per run, about 0.05 s); the first problem is a one-line ScenarioError."""
    from nsdrake.reporting.run_folder import check_scenario

    base = load_scenario(spec.base, config=spec.config, duration=spec.duration)
    runs = []
    for index, values in enumerate(expand(spec)):
        source = f"{spec.source} (run {index}: {_label(values)})"
        try:
            scenario = overlay(base, _nested(values, base), source)
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

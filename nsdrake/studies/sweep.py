"""Parameter sweeps (``nsdrake sweep SPEC``): one scenario, many values of its fields.

The spec and its runs are :mod:`nsdrake.studies.sweep_spec`; a run is simulated by
:mod:`nsdrake.studies.sweep_worker` on an engine of :mod:`nsdrake.studies.sweep_engines`.
This module claims the output folder, stores each result as it comes, and writes the
table and the plot.

Outputs (``OUT``): ``results.csv`` (one row per run, in run order, byte-identical
whatever the engine and the number of jobs), ``runs/NNNN/traces.csv`` and
``runs/NNNN/result.json`` (written when the run finishes; the table is rebuilt from
them), ``sweep.png``, ``sweep.yaml`` (the spec as given) and ``sweep.json`` (what
identifies the sweep, for resuming).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nsdrake.experiment.output import (
    OutputFolderError,
    declare,
    entries,
    prepare_output_folder,
    read_manifest,
    record_written,
    refuse_foreign,
    release_unused,
    remove_listed,
    take_over,
)
from nsdrake.reporting.progress import Progress
from nsdrake.studies.sweep_spec import (
    BASELINE_METRIC,
    MAX_RUNS,
    Run,
    SweepSpec,
    _cell,
    _label,
    check_size,
    load_sweep,
    plan_runs,
    sweep_size,
)

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


# What a stored result.json holds (store writes it): field -> the types it may have.
RECORD_FIELDS = {
    "index": (int,),
    "hash": (str,),
    "seed": (int,),
    "values": (dict,),
    "status": (str,),
    "reason": (str,),
    "crashed": (bool,),
    "baseline": (bool,),
    "metrics": (dict,),
}


def _typed(value, types: tuple) -> bool:
    """``value`` is of one of ``types`` (a bool counts as a bool only, not as an int)."""
    return isinstance(value, types) and (bool in types or not isinstance(value, bool))


def finished(out: Path, run: Run, spec: SweepSpec) -> dict | None:
    """The stored result of ``run`` if it finished with these parameters (a worker that
    died is tried again, and so is a run without the comparison run a metric now needs),
    else None. A result that is not complete (a field missing or of another type, the
    traces of a run that finished missing: a file cut short, edited or half restored) is
    run again too."""
    folder = run_folder(out, run.index)
    try:
        record = json.loads((folder / "result.json").read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(record, dict) or not all(_typed(record.get(k), t) for k, t in RECORD_FIELDS.items()):
        return None
    if record["hash"] != run.hash or record["index"] != run.index or record["crashed"]:
        return None
    if record["status"] not in ("ok", "failed") or set(record["values"]) != set(run.values):
        return None
    if record["status"] == "ok" and not (folder / "traces.csv").is_file():
        return None
    if BASELINE_METRIC in spec.metrics and not record["baseline"]:
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
    """``nsdrake sweep``: every input checked (spec, size, engine, each run's scenario, the
    folder) before the first run; exit status 1 if any run failed, 130 after Ctrl-C."""
    from nsdrake.reporting.run_folder import default_output_folder
    from nsdrake.studies.sweep_engines import check_engine

    spec = load_sweep(args.spec)
    check_size(spec, getattr(args, "max_runs", MAX_RUNS))
    check_engine(args.engine, args.scheduler)
    print(f"nsdrake: sweep {spec.name}: {sweep_size(spec)}; checking every run's scenario", flush=True)
    runs = plan_runs(spec)
    created: list[Path] = []
    out = (
        Path(args.out)
        if args.out is not None
        else default_output_folder(f"sweep-{spec.name}", created=created)
    )
    try:
        prepare_sweep_folder(out, spec, runs, overwrite=args.overwrite)  # refused before "sweeping … into"
    except BaseException:
        release_unused(out, created)
        raise
    print(f"nsdrake: sweeping {spec.name}: {len(runs)} runs on {_engine_words(args)} into {out}/")
    progress = Progress(spec.name, len(runs), unit="runs")
    try:
        with progress:  # the heartbeat: a run reports only when it ends
            outcome = run_sweep(
                spec,
                runs,
                out,
                engine=args.engine,
                jobs=args.jobs,
                scheduler=args.scheduler,
                progress=progress,
                prepared=True,
            )
    except KeyboardInterrupt:
        kept = sum(1 for r in runs if finished(out, r, spec) is not None)
        progress.end_line()
        print(f"nsdrake: interrupted; {kept} of {len(runs)} runs are kept in {out}/; resume with: "
              f"nsdrake sweep {args.spec} --out {out}", file=sys.stderr)  # fmt: skip
        return 130
    _summary(outcome, runs, out)
    return 1 if outcome.failed else 0


def _engine_words(args) -> str:
    if args.scheduler:
        return f"a Dask cluster at {args.scheduler}"
    if args.engine == "dask":
        return f"a local Dask cluster of {args.jobs} workers"
    return f"{args.jobs} processes" if args.jobs > 1 else "this process"


def _summary(outcome: SweepOutcome, runs: list[Run], out: Path) -> None:
    """What was simulated, which runs have no force figures and why, which failed."""
    skipped = len(runs) - len(outcome.simulated)
    print(
        f"nsdrake: {len(outcome.simulated)} runs simulated"
        + (f", {skipped} already finished (resumed)" if skipped else "")
        + f"; wrote {out}/: results.csv, sweep.png, runs/NNNN/traces.csv"
    )
    empty = [
        i
        for i in sorted(outcome.records)
        if outcome.records[i]["status"] == "ok" and outcome.records[i]["reason"]
    ]
    if empty:
        first = outcome.records[empty[0]]
        print(
            f"nsdrake: {len(empty)} of {len(runs)} runs have empty force figures (all_bounds_met false); "
            f"run {empty[0]}: {first['reason']} (results.csv's reason says why for each)"
        )
    for i in outcome.failed:
        print(f"nsdrake: error: run {i} ({_label(outcome.records[i]['values'])}) failed: "
              f"{outcome.records[i]['reason']}", file=sys.stderr)  # fmt: skip

"""Benchmark: sweep throughput with one and two processes, and the Dask engine's overhead.

    python bench/bench_sweep.py [--repeats N] [--duration SECONDS] [--spec SPEC]

Runs the shipped ``robustness`` sweep (18 runs of 3.5 s of fig3; ``--duration``
shortens them) into a fresh folder each time, interleaved so that every engine sees the same
machine load: ``--jobs 1`` (in this process), ``--jobs 2`` (two spawned processes),
and ``--engine dask --jobs 2`` (a LocalCluster of two single-threaded workers, started
and stopped within the timing, as ``nsdrake sweep`` does). Every timing is a whole
sweep: process or cluster start, the runs, writing the files and the plot. The model
checks before the runs (``plan_runs``) are done once, outside the timings.

Prints every time, the medians, and a JSON line: ``sweep_speedup_jobs2`` (median
``--jobs 1`` time over median ``--jobs 2`` time) and ``dask_overhead_s_per_run``
((median Dask time − median ``--jobs 2`` time) / runs). Skips Dask, with a line, when
it is not installed (``pip install 'nsdrake[cluster]'``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import tempfile
import time
from pathlib import Path

from nsdrake.studies.sweep import run_sweep
from nsdrake.studies.sweep_spec import load_sweep, plan_runs


def timed(spec, runs, out: Path, **engine) -> float:
    t0 = time.perf_counter()
    outcome = run_sweep(spec, runs, out, **engine)
    elapsed = time.perf_counter() - t0
    assert not outcome.failed and len(outcome.simulated) == len(runs), outcome.failed
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="sweeps per engine (median)")
    parser.add_argument(
        "--duration", type=float, help="simulated time of every run [s] (default: the spec's)"
    )
    parser.add_argument("--spec", default="robustness", help="a shipped sweep or a spec file")
    args = parser.parse_args()

    spec = load_sweep(args.spec)
    if args.duration is not None:
        spec = dataclasses.replace(spec, duration=args.duration)
    runs = plan_runs(spec)
    try:
        import dask.distributed  # noqa: F401

        have_dask = True
    except ImportError:
        have_dask = False
        print(
            "bench_sweep: Dask is not installed (pip install 'nsdrake[cluster]'); timing the processes only"
        )
    engines = {
        "jobs 1": {"engine": "process", "jobs": 1},
        "jobs 2": {"engine": "process", "jobs": 2},
    }
    if have_dask:
        engines["dask, 2 workers"] = {"engine": "dask", "jobs": 2}
    print(f"sweep {spec.name}: {len(runs)} runs of {runs[0].scenario.duration:g} s simulated")
    times: dict[str, list[float]] = {name: [] for name in engines}
    with tempfile.TemporaryDirectory() as tmp:
        timed(spec, runs, Path(tmp) / "warm-up", engine="process", jobs=1)  # numba cache, imports
        for k in range(args.repeats):
            for name, engine in engines.items():
                times[name].append(
                    timed(spec, runs, Path(tmp) / f"{k}-{engine['engine']}-{engine['jobs']}", **engine)
                )
    medians = {name: statistics.median(t) for name, t in times.items()}
    for name, t in times.items():
        per_run = medians[name] / len(runs)
        print(
            f"  {name:16s} {' '.join(f'{x:6.2f}' for x in t)} s   median {medians[name]:6.2f} s"
            f"   {per_run:5.2f} s per run"
        )
    speedup = medians["jobs 1"] / medians["jobs 2"]
    print(f"  --jobs 2 speed-up over --jobs 1: {speedup:.2f}")
    result = {
        "spec": spec.name,
        "runs": len(runs),
        "run_duration_s": runs[0].scenario.duration,
        "repeats": args.repeats,
        "median_s": {name: round(m, 3) for name, m in medians.items()},
        "sweep_speedup_jobs2": round(speedup, 3),
        "dask_overhead_s_per_run": None,
    }
    if have_dask:
        overhead = (medians["dask, 2 workers"] - medians["jobs 2"]) / len(runs)
        print(f"  Dask overhead over the process pool: {overhead:+.3f} s per run")
        result["dask_overhead_s_per_run"] = round(overhead, 3)
    print(json.dumps(result))


if __name__ == "__main__":
    main()

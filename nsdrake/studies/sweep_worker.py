"""A sweep's worker: one run simulated and measured from plain parameters (picklable,
no Drake objects), in whatever process or cluster worker the engine gives it."""

from __future__ import annotations

import dataclasses
import io
import os
import random
import time

import numpy as np

from nsdrake.experiment.scenario import (
    Scenario,
    _one_line,
)

SWEEP_CHECKS = ("fig3", "priority")  # what a sweep's run of a planar scenario computes

# Test hook: a worker *process* given this run index exits at once (a crashed worker).
CRASH_ENV = "NSDRAKE_SWEEP_TEST_CRASH"


def simulate_run(task: dict) -> dict:
    """Worker: builds the run's diagram from plain parameters, simulates, measures.
    Returns plain results: status, reason, metrics (name -> number) and the traces
    as CSV text. Never raises for a failing run: the failure is the result."""
    from pydrake.common.yaml import yaml_load_typed

    from nsdrake.experiment.simulate import DivergenceError, run
    from nsdrake.reporting.metrics import measuring_window_gap
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
            traces, built = run(scenario, auto_structure="fused")  # the same traces, cheaper
        except DivergenceError as e:
            result.update(status="failed", reason=str(e), traces_csv=_csv_text(e.traces))
        else:
            result["traces_csv"] = _csv_text(traces)
            baseline = (
                run(scenario, null_space_task=False, auto_structure="fused")[0] if task["baseline"] else None
            )
            metrics = compute_metrics(measured, built.station, traces, baseline)
            values = {m.name: _plain(m.value) for m in metrics}
            values["all_bounds_met"] = all(m.passed for m in metrics if m.passed is not None)
            result["metrics"] = values
            # A run without force figures is not a failure, but its row says why they are empty.
            result["reason"] = measuring_window_gap(traces, scenario.reference.contact_threshold) or ""
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

"""Accuracy: the contact force estimated from the status's external joint torques against
the wrist (table) sensor, measured in simulation.

    python bench/bench_force_estimate.py [--duration 28] [--after 3]

Drives panda_wipe through the controller side and the simulated driver (one process,
memq://, unpaced) twice: with ``driver.force_source: external_torque`` (the controller
uses W = (J Jᵀ)⁻¹ J τ_ext from the status) and with ``sensor`` (the table sensor's
``lcmt_force_torque``). For the first it compares, over the rows after ``--after`` seconds
in which the tool touches the plate (sensor normal force > 0.5 N), the estimate the
controller used (traces ``f_*_measured``) with the simulated sensor's reading (``f_*``):
RMS and largest difference along the plate's normal and along each task axis [N]. For both
runs it reports the run's force error RMS (the scenario's own metric). One JSON line.

The simulated driver's τ_ext is exact (minus the generalized contact forces on the arm), so
the difference is the estimate's mapping alone: this is the method's floor. A real Panda's
τ_ext also carries Franka's model and friction error, which this cannot measure.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys

import numpy as np

from nsdrake.driver.run import drive_traces, run_simulated
from nsdrake.experiment.scenario import load_scenario
from nsdrake.reporting.run_folder import compute_metrics


def drive(force_source: str, duration: float):
    scenario = load_scenario("panda_wipe", duration=duration)
    scenario = dataclasses.replace(
        scenario, driver=dataclasses.replace(scenario.driver, force_source=force_source)
    )
    run = run_simulated(scenario, realtime_rate=0.0)
    if run.failure:
        raise SystemExit(f"bench_force_estimate: the {force_source} drive stopped: {run.failure}")
    traces = drive_traces(run)
    metrics = {m.name: m.value for m in compute_metrics(run.scenario, run.loop.drive.station, traces, None)}
    return run, traces, metrics


def differences(traces, axes, after: float) -> dict:
    """Estimate minus sensor over the touching rows after ``after`` [s]: RMS and max [N]."""
    rows = (traces["t"] > after) & (traces["f_n"] > 0.5)
    out = {"rows": int(rows.sum())}
    for axis in ("n", *axes):
        error = traces[f"f_{axis}_measured"][rows] - traces[f"f_{axis}"][rows]
        out[f"f_{axis}_rms_N"] = float(np.sqrt(np.mean(error**2)))
        out[f"f_{axis}_max_N"] = float(np.max(np.abs(error)))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=28.0, help="drive length [s] (panda_wipe: 28)")
    parser.add_argument("--after", type=float, default=3.0, help="compare the rows after this time [s]")
    args = parser.parse_args()
    estimated, traces, metrics = drive("external_torque", args.duration)
    arm = estimated.loop.drive.station.arm_model
    result = differences(traces, arm.task_axes[: arm.m_t], args.after)
    result["f_d_N"] = float(estimated.scenario.reference.force)
    result["force_error_rms_N_estimate"] = metrics.get("force_error_rms")
    _, _, sensor_metrics = drive("sensor", args.duration)
    result["force_error_rms_N_sensor"] = sensor_metrics.get("force_error_rms")
    result.update(duration_s=args.duration, after_s=args.after)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())

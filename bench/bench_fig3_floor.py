"""Benchmark: the floor of a fig3 tick under the controller's math — what the rest of the
simulation costs.

    python bench/bench_fig3_floor.py [--repeats N]

Runs fig3 (named systems, then fused) once recording every write of the controller's
stage calls (``ControllerPlan.terms``: Pinocchio's model terms, ``run_arrays``: the
compiled stages), then again with each call replaced by the replay of its recorded writes,
in order. The replayed run follows the same trajectory bit for bit (checked: the τ
traces are compared), with the same Drake events, ports, caches, plant steps, reference,
force sensor, monitor and loggers, but no controller arithmetic. Its CPU per tick is
the floor that the diagram around the controller puts under any implementation of the
math; ``*_over_baseline`` divides it by bench_controller.py's baseline (the same plant
and sensor under Drake's C++ JointStiffnessController), interleaved. Medians of
``--repeats`` runs; the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import statistics

import numpy as np
from bench_controller import baseline_run, fig3_run

from nsdrake.control.plan import ControllerPlan
from nsdrake.experiment.scenario import load_scenario

_TERMS, _RUN = ControllerPlan.terms, ControllerPlan.run_arrays


class Replay:
    """Patches ControllerPlan's stage calls to record their writes, or to replay them."""

    def __init__(self):
        self.log, self.k, self.replaying = [], 0, False

    def install(self) -> None:
        replay = self

        def terms(plan, scratch, q, v, out):
            replay._call(lambda: _TERMS(plan, scratch, q, v, out), (out,))

        def run_arrays(plan, *args):
            # args: stages, t, t_previous, terms, criteria, switch, previous_qdot, previous_tau,
            # commands, tick, scratch; written: criteria, the discrete state's parts, tick
            replay._call(lambda: _RUN(plan, *args), (*args[4:8], args[9]))

        ControllerPlan.terms, ControllerPlan.run_arrays = terms, run_arrays

    def _call(self, compute, written) -> None:
        if self.replaying:
            for array, value in zip(written, self.log[self.k], strict=True):
                array[:] = value
            self.k += 1
        else:
            compute()
            self.log.append([a.copy() for a in written])

    def start_replay(self) -> None:
        self.k, self.replaying = 0, True


def floor_run(scenario, structure: str) -> tuple[float, float]:
    """(CPU of the replayed run, max |Δτ| against the recorded run)."""
    replay = Replay()
    replay.install()
    try:
        _, recorded = fig3_run(scenario, structure)
        replay.start_replay()
        cpu, replayed = fig3_run(scenario, structure)
    finally:
        ControllerPlan.terms, ControllerPlan.run_arrays = _TERMS, _RUN
    if replay.k != len(replay.log):
        raise RuntimeError(f"replayed {replay.k} of {len(replay.log)} stage calls: the runs differ")
    return cpu, float(np.max(np.abs(recorded.block("tau") - replayed.block("tau"))))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs per figure (median)")
    args = parser.parse_args()
    scenario = load_scenario("fig3")
    ticks = round(scenario.duration / scenario.control_period)
    fig3_run(scenario, "fused")  # compiled kernels loaded, caches warm
    floors = {"systems": [], "fused": []}
    base = []
    for k in range(args.repeats):  # interleaved, so all see the same machine load
        for structure, runs in floors.items():
            cpu, dtau = floor_run(scenario, structure)
            if dtau != 0.0:
                raise RuntimeError(f"the replayed {structure} run left the recorded one: |Δτ| {dtau:g}")
            runs.append(cpu / ticks * 1e6)
        _, traces = fig3_run(scenario, "fused")
        base.append(baseline_run(scenario, traces) / ticks * 1e6)
        print(
            f"  run {k + 1}: floor, named systems {floors['systems'][-1]:6.1f} µs/tick, "
            f"fused {floors['fused'][-1]:6.1f}; baseline {base[-1]:6.1f}",
            flush=True,
        )
    figures = {s: statistics.median(r) for s, r in floors.items()}
    base_us = statistics.median(base)
    print(f"fig3 with the controller's math replayed, CPU per tick, median of {args.repeats}:")
    for structure, us in figures.items():
        print(f"  {structure:8s} {us:7.1f} µs, {us / base_us:5.2f}x the baseline ({base_us:.1f} µs)")
    print(
        json.dumps(
            {"baseline_tick_us": round(base_us, 1)}
            | {f"{s}_floor_tick_us": round(us, 1) for s, us in figures.items()}
            | {f"{s}_floor_over_baseline": round(us / base_us, 2) for s, us in figures.items()}
        )
    )


if __name__ == "__main__":
    main()

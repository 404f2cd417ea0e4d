"""Benchmark: what ControllerStep.step's argument checks cost, against an earlier step.py.

    python bench/bench_step_checks.py [--against COMMIT] [--blocks N] [--calls N]

Loads ``nsdrake/control/step.py`` as it was at ``--against`` (``git show``; it must run
on this checkout's other modules: its imports must still exist) beside this checkout's,
builds both steps from the same model and configuration (fig3's controller: 4 joints, a
force task; panda_wipe's: 7 joints, the full pose task), and calls them in alternating
blocks of ``--calls`` calls at fresh states, one period apart, as bench_controller.py's
``plain_step_us`` does. Each call's thread CPU time is taken; a block's figure is its
median. Prints per arm the median over blocks (the first pair left out: warm-up) of the
old and the new step [µs] and of their ratio new/old, block by block: both see the same
machine load, so the ratio holds on a shared machine where the microseconds do not.
The last line is one JSON object.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from pydrake.systems.framework import DiagramBuilder

from nsdrake import ControllerStep
from nsdrake.experiment.diagram import build_controller
from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.scenario_station import add_scenario_station

ROOT = Path(__file__).resolve().parents[1]


def old_step_class(commit: str):
    """ControllerStep of nsdrake/control/step.py at ``commit``, as a module of its own."""
    text = subprocess.run(
        ["git", "show", f"{commit}:nsdrake/control/step.py"],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    path = Path(tempfile.mkdtemp()) / "old_step.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("old_step", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.ControllerStep


def block(step, q0, period, calls: int, rng, start: int) -> float:
    """Median thread CPU time [µs] of ``calls`` calls at fresh states, from tick ``start``."""
    n, m_t, rotational = step.model.n, step.plan.m_t, step.plan.m_r > 0
    states = np.hstack([q0 + 0.05 * rng.standard_normal((256, n)), 0.2 * rng.standard_normal((256, n))])
    x_d, wrench = np.zeros(m_t), np.zeros(6)
    extra = (np.array([0.0, 1.0, 0.0, 0.0]), np.zeros(3), np.zeros(3)) if rotational else ()
    cpu = np.empty(calls)
    for k in range(calls):
        s = states[k % 256]
        c0 = time.thread_time_ns()
        step.step((start + k) * period, s[:n], s[n:], wrench, x_d, x_d, x_d, 5.0, *extra)
        cpu[k] = (time.thread_time_ns() - c0) / 1e3
    return float(np.median(cpu))


def compare(name: str, old_class, blocks: int, calls: int) -> dict:
    scenario = load_scenario(name)
    station = add_scenario_station(DiagramBuilder(), scenario)
    c = build_controller(scenario, station, station.sensor.p_WSo)
    args = dict(controller_model=c.model, normal=c.normal, config=c.config, wrench_point=c.wrench_point)
    steps = {"old": old_class(**args), "new": ControllerStep(**args)}
    rng, ticks = np.random.default_rng(0), {"old": 0, "new": 0}
    medians = {"old": [], "new": []}
    for r in range(blocks + 1):
        for which in ("old", "new") if r % 2 == 0 else ("new", "old"):
            figure = block(steps[which], station.q0, scenario.control_period, calls, rng, ticks[which])
            ticks[which] += calls
            if r > 0:
                medians[which].append(figure)
    ratios = [b / a for a, b in zip(medians["old"], medians["new"], strict=True)]
    return {
        "old_us": round(statistics.median(medians["old"]), 2),
        "new_us": round(statistics.median(medians["new"]), 2),
        "ratio": round(statistics.median(ratios), 3),
        "ratio_range": [round(min(ratios), 3), round(max(ratios), 3)],
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", default="ffc8daf", help="the commit whose step.py is the old one")
    parser.add_argument("--blocks", type=int, default=19, help="blocks per step and arm (median)")
    parser.add_argument("--calls", type=int, default=2000, help="calls per block")
    args = parser.parse_args()
    old_class = old_step_class(args.against)
    out = {}
    for name, label in (("fig3", "4dof"), ("panda_wipe", "7dof")):
        out[label] = figures = compare(name, old_class, args.blocks, args.calls)
        print(
            f"{label} ({name}): CPU per call, median of {args.blocks} blocks of {args.calls}: old "
            f"{figures['old_us']} µs, new {figures['new_us']} µs, new/old {figures['ratio']} "
            f"(blocks {figures['ratio_range'][0]}–{figures['ratio_range'][1]})",
            flush=True,
        )
    print(json.dumps({"against": args.against, **out}))


if __name__ == "__main__":
    main()

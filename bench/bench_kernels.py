"""Benchmark: the kernels' compile on a fresh cache and their cost per tick, this tree
against another (issue 36: "compiled once per install, whatever the configuration").

    python bench/bench_kernels.py --old /tmp/kernels-old [--duration S] [--rounds N] [--calls N]

``--old`` is a checkout of the code to compare with (``git worktree add --detach
/tmp/kernels-old main``); both trees run with this interpreter, each from its own folder
(``PYTHONPATH``), in child processes, old and new interleaved so that both see the same
machine load.

- **first runs**: each tree gets an empty numba cache (``NUMBA_CACHE_DIR``), then runs
  ``nsdrake run`` of every shipped scenario in turn, fig3 first, each in a process of its
  own (as a user's commands): per run the wall time, the process's CPU time, the CPU time
  inside numba's compiles (outermost compiles; a listener of numba's compile events), the
  compiles and the compile notices printed. fig3's row is the first run after an install
  (``--duration`` shortens every run; the compile does not depend on it).
- **per tick** (``--rounds`` rounds, warm caches): the mean CPU time of
  ``ControllerStep.step`` over ``--calls`` calls at fresh states, fig3's controller (4 joints,
  position task) and panda_wipe's (7 joints, pose task, obstacles, joint limits), and
  fig3's whole simulation per control tick (``bench_controller.tick_us``); medians of the
  rounds, and new over old.

CPU times, not wall times, are what compares on a loaded machine; the load is printed
before and after. The last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]

# A command run under a listener of numba's compile events; writes its figures to BENCH_OUT.
RUN = """
import json, os, sys, time
from numba.core import event

class Compiles(event.Listener):
    def __init__(self):
        self.depth, self.cpu, self.count = 0, 0.0, 0
    def on_start(self, ev):
        if self.depth == 0:
            self.start = time.process_time()
        self.depth += 1
    def on_end(self, ev):
        self.depth -= 1
        if self.depth == 0:
            self.cpu += time.process_time() - self.start
            self.count += 1

compiles = Compiles()
event.register("numba:compile", compiles)
from nsdrake.cli import main
try:
    code = main(sys.argv[1:])
finally:
    with open(os.environ["BENCH_OUT"], "w") as f:
        json.dump({"compile_cpu": compiles.cpu, "compiles": compiles.count}, f)
sys.exit(code)
"""

# The cost per tick, with the tree's own bench_controller; prints one JSON object.
TICK = """
import json, sys, time
import numpy as np
import bench_controller as b
from nsdrake.experiment.scenario import load_scenario

def step_cpu_us(name, calls, seed=0):
    step, q0, period = b.scenario_step(name)
    n, m_t, rotational = step.model.n, step.plan.m_t, step.plan.m_r > 0
    rng = np.random.default_rng(seed)
    states = np.hstack([q0 + 0.05 * rng.standard_normal((512, n)), 0.2 * rng.standard_normal((512, n))])
    x_d, wrench = np.zeros(m_t), np.zeros(6)
    extra = (np.array([0.0, 1.0, 0.0, 0.0]), np.zeros(3), np.zeros(3)) if rotational else ()
    for k in range(-200, calls):  # 200 calls warm up
        if k == 0:
            c0 = time.process_time()
        s = states[k % 512]
        step.step((k + 200) * period, s[:n], s[n:], wrench, x_d, x_d, x_d, 5.0, *extra)
    return (time.process_time() - c0) / calls * 1e6

calls = int(sys.argv[1])
print(json.dumps({
    "step_fig3_us": step_cpu_us("fig3", calls),
    "step_panda_wipe_us": step_cpu_us("panda_wipe", calls),
    "tick_fig3_us": b.tick_us(load_scenario("fig3")),
}))
"""

SCENARIOS = (
    "fig3", "fig3_vertical", "force_step", "lyapunov", "panda_self_motion", "panda_wipe",
    "priority_demo", "self_motion",
)  # fmt: skip


def child(
    tree: Path, args: list[str], env: dict | None = None
) -> tuple[subprocess.CompletedProcess, float, float]:
    """Runs ``python args`` with ``tree`` first on the path: (result, wall s, CPU s of the child)."""
    path = os.pathsep.join([str(tree), str(tree / "bench"), os.environ.get("PYTHONPATH", "")])
    full_env = os.environ | {"PYTHONPATH": path} | (env or {})
    before = os.times()
    start = time.monotonic()
    done = subprocess.run([sys.executable, *args], env=full_env, capture_output=True, text=True, cwd=tree)
    wall = time.monotonic() - start
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return done, wall, cpu


def first_run(tree: Path, scenario: str, cache: Path, out: Path, duration: float | None) -> dict:
    figures = out / f"{scenario}.json"
    argv = ["-c", RUN, "run", scenario, "--out", str(out / scenario), "--no-replay"]
    if duration is not None:
        argv += ["--duration", str(duration)]
    done, wall, cpu = child(tree, argv, {"NUMBA_CACHE_DIR": str(cache), "BENCH_OUT": str(figures)})
    row = json.loads(figures.read_text()) if figures.exists() else {}
    row |= {
        "wall": round(wall, 1),
        "cpu": round(cpu, 1),
        "compile_cpu": round(row.get("compile_cpu", float("nan")), 1),
        "notices": done.stderr.count("compiling nsdrake's kernels"),
        "exit": done.returncode,
    }
    if done.returncode not in (0, 1):  # 1: a metric out of its bound (a shortened run)
        print(done.stderr[-2000:], file=sys.stderr)
    return row


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, required=True, help="checkout of the code to compare with")
    parser.add_argument(
        "--duration", type=float, help="simulated time of each first run [s] (default: the scenario's)"
    )
    parser.add_argument(
        "--keep", type=Path, help="keep the runs' folders here (old/, new/: compare the traces)"
    )
    parser.add_argument("--rounds", type=int, default=3, help="rounds of the per-tick figures (median)")
    parser.add_argument("--calls", type=int, default=5000, help="ControllerStep calls per figure")
    args = parser.parse_args()
    trees = {"old": args.old.resolve(), "new": HERE}
    load_before = os.getloadavg()
    print(f"load before: {load_before[0]:.1f} {load_before[1]:.1f} {load_before[2]:.1f}", flush=True)
    first: dict[str, dict[str, dict]] = {"old": {}, "new": {}}
    with tempfile.TemporaryDirectory(prefix="bench-kernels-") as scratch:
        tmp = args.keep or scratch
        for scenario in SCENARIOS:
            for name, tree in trees.items():
                folder = Path(tmp) / name
                row = first_run(tree, scenario, Path(scratch) / name / "numba-cache", folder, args.duration)
                first[name][scenario] = row
                print(
                    f"  {name} {scenario:18s} wall {row['wall']:6.1f} s  CPU {row['cpu']:6.1f} s  "
                    f"compiling {row['compile_cpu']:6.1f} s CPU ({row.get('compiles', 0)} compiles, "
                    f"{row['notices']} notice)",
                    flush=True,
                )
        ticks: dict[str, list[dict]] = {"old": [], "new": []}
        for k in range(args.rounds):
            for name, tree in trees.items():
                cache = {"NUMBA_CACHE_DIR": str(Path(scratch) / name / "numba-cache")}  # warm
                done, _, _ = child(tree, ["-c", TICK, str(args.calls)], cache)
                if done.returncode != 0:
                    print(done.stderr[-2000:], file=sys.stderr)
                    raise SystemExit(f"the per-tick run of {name} failed")
                ticks[name].append(json.loads(done.stdout.strip().splitlines()[-1]))
                print(f"  round {k + 1} {name}: {ticks[name][-1]}", flush=True)
    medians = {
        name: {key: round(statistics.median(r[key] for r in rows), 2) for key in rows[0]}
        for name, rows in ticks.items()
    }
    load_after = os.getloadavg()
    print("first run after an install, then the first run of each other scenario:")
    for name in trees:
        total = sum(r["compile_cpu"] for r in first[name].values())
        notices = sum(r["notices"] for r in first[name].values())
        later = sum(r["compile_cpu"] for s, r in first[name].items() if s != "fig3")
        fig3 = first[name]["fig3"]
        print(
            f"  {name}: fig3 {fig3['wall']:.1f} s wall, {fig3['cpu']:.1f} s CPU "
            f"({fig3['compile_cpu']:.1f} s compiling); the other seven compile "
            f"{later:.1f} s CPU; {total:.1f} s CPU compiling in all, {notices} notices"
        )
    print("per tick, CPU, median of the rounds (new / old):")
    for key in medians["new"]:
        print(f"  {key:20s} old {medians['old'][key]:8.1f} µs  new {medians['new'][key]:8.1f} µs  "
              f"({medians['new'][key] / medians['old'][key]:.2f})")  # fmt: skip
    print(f"load after: {load_after[0]:.1f} {load_after[1]:.1f} {load_after[2]:.1f}")
    print(json.dumps({"first_runs": first, "per_tick": medians, "load": [load_before, load_after]}))


if __name__ == "__main__":
    main()

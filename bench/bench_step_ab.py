"""Benchmark: panda_wipe's plain ControllerStep.step (7 joints) at two commits, A/B.

    python bench/bench_step_ab.py [--old ffc8daf] [--new HEAD] [--rounds 6] [--calls 5000]

Checks out both commits as detached git worktrees in a temporary folder (each compiles its
own kernels once, in a warm-up process not measured), then runs alternating rounds (old,
new, then new, old, ...), each measurement in a fresh process of its own checkout: the
checkout's ``bench/bench_controller.py`` ``scenario_step("panda_wipe")``, then ``--calls``
calls at fresh states one period apart (200 more first, to warm up), each call's thread CPU
time taken. Prints per round each side's median and p99.9 [µs] and the ratio new/old of the
medians (both sides of a round see about the same machine load: the ratio holds on a
shared machine where the microseconds do not), then the medians over rounds and the
machine's 1-minute load before and after; the last line is one JSON object. Whole-checkout
A/B: the kernels, the model and step.py all as at each commit (bench/bench_step_checks.py
swaps step.py alone).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

MEASURE = """
import json, sys, time
import numpy as np
sys.path[:0] = [{root!r}, {root!r} + "/bench"]
from bench_controller import scenario_step
step, q0, period = scenario_step("panda_wipe")
n, m_t, rotational = step.model.n, step.plan.m_t, step.plan.m_r > 0
rng = np.random.default_rng(0)
states = np.hstack([q0 + 0.05 * rng.standard_normal((512, n)), 0.2 * rng.standard_normal((512, n))])
x_d, wrench = np.zeros(m_t), np.zeros(6)
extra = (np.array([0.0, 1.0, 0.0, 0.0]), np.zeros(3), np.zeros(3)) if rotational else ()
cpu = np.empty({calls})
for k in range({calls} + 200):
    s = states[k % 512]
    c0 = time.thread_time_ns()
    step.step(k * period, s[:n], s[n:], wrench, x_d, x_d, x_d, 5.0, *extra)
    if k >= 200:
        cpu[k - 200] = (time.thread_time_ns() - c0) / 1e3
import nsdrake
assert nsdrake.__file__.startswith({root!r}), nsdrake.__file__
print(json.dumps({{"median": float(np.median(cpu)), "p999": float(np.percentile(cpu, 99.9))}}))
"""


def checkout(commit: str, folder: Path) -> Path:
    path = folder / commit.replace("/", "_")
    subprocess.run(["git", "worktree", "add", "--detach", str(path), commit], cwd=ROOT, check=True,
                   capture_output=True)  # fmt: skip
    return path


def measure(root: Path, calls: int) -> dict:
    code = MEASURE.format(root=str(root), calls=calls)
    env = dict(os.environ, PYTHONPATH=str(root))
    result = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True)
    if result.returncode:
        raise SystemExit(f"bench_step_ab: the measurement at {root} failed: {result.stderr.strip()[-2000:]}")
    return json.loads(result.stdout.strip().splitlines()[-1])


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", default="ffc8daf", help="the earlier commit")
    parser.add_argument("--new", default="HEAD", help="the later commit")
    parser.add_argument("--rounds", type=int, default=6, help="alternating rounds (median)")
    parser.add_argument("--calls", type=int, default=5000, help="calls per measurement")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="bench_step_ab-"))
    roots = {}
    try:
        for side in ("old", "new"):
            roots[side] = checkout(getattr(args, side), folder)
            measure(roots[side], 10)  # compiles the checkout's kernels, not measured
        load = [os.getloadavg()[0]]
        rounds = []
        for k in range(args.rounds):
            order = ("old", "new") if k % 2 == 0 else ("new", "old")
            figures = {side: measure(roots[side], args.calls) for side in order}
            figures["ratio"] = figures["new"]["median"] / figures["old"]["median"]
            rounds.append(figures)
            print(
                f"round {k + 1}: old {figures['old']['median']:.1f} µs (p99.9 {figures['old']['p999']:.1f}), "
                f"new {figures['new']['median']:.1f} µs (p99.9 {figures['new']['p999']:.1f}), "
                f"new/old {figures['ratio']:.3f}",
                flush=True,
            )
        load.append(os.getloadavg()[0])
    finally:
        for root in roots.values():
            subprocess.run(["git", "worktree", "remove", "--force", str(root)], cwd=ROOT, capture_output=True)
    summary = {
        "old": args.old, "new": args.new, "rounds": args.rounds, "calls": args.calls,
        "old_median_us": statistics.median(r["old"]["median"] for r in rounds),
        "new_median_us": statistics.median(r["new"]["median"] for r in rounds),
        "old_p999_us": statistics.median(r["old"]["p999"] for r in rounds),
        "new_p999_us": statistics.median(r["new"]["p999"] for r in rounds),
        "ratio_median": statistics.median(r["ratio"] for r in rounds),
        "ratio_range": [min(r["ratio"] for r in rounds), max(r["ratio"] for r in rounds)],
        "load_average_1min": load,
    }  # fmt: skip
    print(
        f"median over {args.rounds} rounds: old {summary['old_median_us']:.1f} µs, new "
        f"{summary['new_median_us']:.1f} µs, new/old {summary['ratio_median']:.3f} "
        f"({summary['ratio_range'][0]:.3f}-{summary['ratio_range'][1]:.3f}); load {load[0]:.2f}-{load[1]:.2f}"
    )
    print(json.dumps(summary))


if __name__ == "__main__":
    main()

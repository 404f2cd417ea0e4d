"""Benchmark: the kernels' compile on a fresh cache and their cost per tick, this tree
against another (issue 36: "compiled once per install, whatever the configuration").

    python bench/bench_kernels.py --old /tmp/kernels-old [--duration S] [--rounds N] [--calls N]
    python bench/bench_kernels.py --compile [--no-profile] [--old /tmp/kernels-old]
    python bench/bench_kernels.py --warm [--rounds N] [--caches DIR] [--old /tmp/kernels-old]

``--compile`` (issue 44, item 4) profiles ``compile_kernels()`` alone on an empty cache, each
tree in a child process of its own: the CPU time of each kernel's compile, exclusive of the
kernels it compiles on the way (numba compiles a kernel's callees inside its compile), split
by stage (numba's passes: typing, lowering, ...; LLVM: function passes, module passes,
machine code), from numba's compile and pass events and timers around LLVM's calls; the
kernels sorted by CPU time, each with the CPU time of the other tree's same kernel and
their ratio; then the compile as a run does it (with each tree's helper process on the
second core), the trees at once so that they see the same load (``--no-profile``: this
alone): its wall time and the CPU time of both processes. On a loaded machine, read the
CPU times and the ratios (the busier process's CPU time is what an idle machine's wall
time follows); the wall time counts only on an idle one (the load is printed).

``--warm`` (issue 44, item 2) measures a process's start with the kernels cached (each tree's
cache compiled first, in ``--caches`` DIR/<tree> if given, kept there for the next time):
the CPU time (process time) of ``import nsdrake``, of ``compile_kernels()`` (loads, or
nothing when all is cached), of building fig3's ``ControllerStep`` and of its first and
second step, which kernels the process loaded, and of ``import nsdrake.cli`` (every
command's and subprocess's import) in a process of its own; medians of ``--rounds``
rounds, the trees interleaved.

``--old`` is a checkout of the code to compare with (``git worktree add --detach
/tmp/kernels-old main``); both trees run with this interpreter, each from its own folder
(``PYTHONPATH``), in child processes, old and new interleaved so that both see the same
machine load.

- **first runs**: each tree gets an empty numba cache (``NUMBA_CACHE_DIR``), then runs
  ``nsdrake run`` of every shipped scenario in turn, fig3 first, each in a process of its
  own (as a user's commands): per run the wall time, the process's CPU time (its helper
  processes included), the CPU time inside numba's compiles in the process (outermost
  compiles; a listener of numba's compile events), the compiles and the compile notices
  printed; and whether the two trees' traces.csv are the same bytes (kernels changed for
  their compile time must compute the same numbers). fig3's row is the first run after an install
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
import threading
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

# compile_kernels() under listeners of numba's compile and pass events, with timers around
# LLVM's stages; writes {"kernels": {kernel: {stage: exclusive CPU s}}, ...} to argv[1].
PROFILE = """
import inspect, json, sys, time
from collections import defaultdict
from numba.core import codegen, event

clock, stack, order = time.process_time, [], []
kernels = defaultdict(lambda: defaultdict(float))

def push(kind, key):
    stack.append([kind, key, clock(), 0.0])

def pop():
    kind, key, start, children = stack.pop()
    total = clock() - start
    if stack:
        stack[-1][3] += total
    owner = next((f[1] for f in reversed(stack + [[kind, key]]) if f[0] == "compile"), "(none)")
    kernels[owner]["other" if kind == "compile" else key] += total - children
    if kind == "compile":
        kernels[key]["inclusive"] += total

class Compiles(event.Listener):
    def on_start(self, ev):
        f = ev.data["dispatcher"].py_func
        key = f"{f.__module__}.{f.__qualname__}({', '.join(str(a) for a in ev.data['args'])})"
        order.append(key)
        push("compile", key)
    def on_end(self, ev):
        pop()

class Passes(event.Listener):
    def on_start(self, ev):
        name = ev.data["name"].split(" [")[0]  # "native_lowering [run_stages]"
        stage = {"nopython_type_inference": "typing", "native_lowering": "lowering"}.get(name, "numba passes")
        push("pass", stage)
    def on_end(self, ev):
        pop()

def timed(cls, name, stage):
    original = getattr(cls, name)
    def wrapper(self, *args, **kwargs):
        push("llvm", stage)
        try:
            return original(self, *args, **kwargs)
        finally:
            pop()
    setattr(cls, name, wrapper)

timed(codegen.CPUCodeLibrary, "_optimize_functions", "LLVM function passes")
timed(codegen.CPUCodeLibrary, "_optimize_final_module", "LLVM module passes")
timed(codegen.JITCodeLibrary, "_finalize_specific", "machine code")
event.register("numba:compile", Compiles())
event.register("numba:run_pass", Passes())
import nsdrake.control
from nsdrake.control import kernels as k
start, wall = clock(), time.monotonic()
if "helper" in inspect.signature(k.compile_kernels).parameters:
    k.compile_kernels(helper=False)  # one process: each kernel's own time
else:
    k.compile_kernels()
out = {"cpu": clock() - start, "wall": time.monotonic() - wall, "compiles": len(order),
       "kernels": {key: dict(kernels[key]) for key in dict.fromkeys(order)}}
json.dump(out, open(sys.argv[1], "w"))
"""

# compile_kernels() as a run calls it; prints its wall time, this process's CPU time and
# its helper processes' (on an idle machine the wall time is about the larger CPU time).
COMPILE = """
import resource, time
import nsdrake.control
from nsdrake.control.kernels import compile_kernels
start, cpu = time.monotonic(), time.process_time()
compile_kernels()
helpers = resource.getrusage(resource.RUSAGE_CHILDREN)
print(time.monotonic() - start, time.process_time() - cpu, helpers.ru_utime + helpers.ru_stime)
"""

# A process's start with a warm cache, as a user's meets it; prints one JSON object.
WARM = """
import json, sys, time
clock = time.process_time
rows, c0 = {}, clock()
if sys.argv[1] == "cli":
    import nsdrake.cli
    cpu, pyplot = clock() - c0, "matplotlib" in sys.modules
    print(json.dumps({"import nsdrake.cli": cpu, "matplotlib imported": pyplot}))
    sys.exit(0)
def mark(name, start):
    rows[name] = clock() - start
    return clock()
c = c0
import nsdrake
c = mark("import nsdrake", c)
import bench_controller as b
import numpy as np
from nsdrake.control import kernels as k
c = mark("import bench_controller", c)
k.compile_kernels()
c = mark("compile_kernels()", c)
step, q0, period = b.scenario_step("fig3")
c = mark("fig3 ControllerStep built", c)
n, x = step.model.n, np.zeros(step.plan.m_t)
step.step(0.0, q0, np.zeros(n), np.zeros(6), x, x, x, 5.0)
c = mark("first step", c)
step.step(period, q0, np.zeros(n), np.zeros(6), x, x, x, 5.0)
c = mark("second step", c)
rows["to the second step"] = clock() - c0
rows["kernels loaded"] = sum(1 for d, _ in k._dispatchers() if d.overloads)
print(json.dumps(rows))
"""

STAGES = ("typing", "lowering", "numba passes", "LLVM function passes", "LLVM module passes")
STAGES += ("machine code", "other")

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


def as_a_run(trees: dict[str, Path], scratch: Path) -> dict:
    """compile_kernels as a run calls it (COMPILE), every tree at once on an empty cache
    of its own, so that all see the same load: {tree: figures}."""
    runs: dict[str, dict] = {}

    def run(name: str, tree: Path) -> None:
        cache = {"NUMBA_CACHE_DIR": str(scratch / name / "run-cache")}
        done, _, cpu = child(tree, ["-c", COMPILE], cache)
        if done.returncode != 0:
            print(done.stderr[-3000:], file=sys.stderr)
            return
        compile_wall, own, helpers = map(float, done.stdout.split()[-3:])
        runs[name] = {"compile_wall": compile_wall, "own_cpu": own, "helpers_cpu": helpers, "cpu": cpu}

    workers = [threading.Thread(target=run, args=item) for item in trees.items()]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join()
    if set(runs) != set(trees):
        raise SystemExit(f"the compile of {sorted(set(trees) - set(runs))} failed")
    return runs


def compile_profile(trees: dict[str, Path], profile: bool = True) -> dict:
    """The ``--compile`` figures (module docstring), printed; returned for the JSON line."""
    load_before = os.getloadavg()
    print(f"load before: {load_before[0]:.1f} {load_before[1]:.1f} {load_before[2]:.1f}", flush=True)
    profiles = {}
    with tempfile.TemporaryDirectory(prefix="bench-kernels-") as scratch:
        for name, tree in trees.items() if profile else ():
            out = Path(scratch) / f"{name}.json"
            cache = {"NUMBA_CACHE_DIR": str(Path(scratch) / name / "profile-cache")}
            done, wall, cpu = child(tree, ["-c", PROFILE, str(out)], cache)
            if done.returncode != 0:
                print(done.stderr[-3000:], file=sys.stderr)
                raise SystemExit(f"the compile profile of {name} failed")
            profiles[name] = json.loads(out.read_text()) | {"process_cpu": cpu, "process_wall": wall}
            print(f"  {name}: profiled", flush=True)
        runs = as_a_run(trees, Path(scratch))
    load_after = os.getloadavg()

    def exclusive(stages: dict) -> float:
        return sum(v for s, v in stages.items() if s != "inclusive")

    new = profiles.get("new", {}).get("kernels", {})
    other = {n: p["kernels"] for n, p in profiles.items() if n != "new"}
    if new:
        print("per kernel, CPU s of its own compile (exclusive of the kernels compiled inside it), new tree:")
        header = "  ".join(f"{s[:12]:>12s}" for s in STAGES)
        print(f"  {'own':>6s} {'incl.':>6s}  {'old':>6s} {'new/old':>7s}  {header}  kernel(argument types)")
    for key, stages in sorted(new.items(), key=lambda kv: -exclusive(kv[1])):
        old = other.get("old", {}).get(key)
        mine = exclusive(stages)
        ratio = f"{mine / exclusive(old):7.2f}" if old else "      -"
        cells = "  ".join(f"{stages.get(s, 0.0):12.2f}" for s in STAGES)
        old_cell = f"{exclusive(old):6.2f}" if old else "     -"
        print(f"  {mine:6.2f} {stages.get('inclusive', 0.0):6.2f}  {old_cell} {ratio}  {cells}  {key[:160]}")
    for name, kernels in other.items():
        gone = [key for key in kernels if key not in new]
        if gone:
            print(f"kernels the {name} tree compiles and the new one does not (CPU s):")
            for key in sorted(gone, key=lambda k: -exclusive(kernels[k])):
                print(f"  {exclusive(kernels[key]):6.2f}  {key[:160]}")
    print("in all (CPU s; compiles; by stage):" if profiles else "in all (CPU s):")
    for name, profile in profiles.items():
        totals = {s: sum(k.get(s, 0.0) for k in profile["kernels"].values()) for s in STAGES}
        stages = ", ".join(f"{s} {v:.1f}" for s, v in totals.items())
        print(f"  {name}: compile_kernels {profile['cpu']:.1f} s CPU in one process "
              f"({profile['compiles']} compiles; {stages})")  # fmt: skip
    for name, run in runs.items():
        idle = max(run["own_cpu"], run["helpers_cpu"])
        print(f"  {name}: compile_kernels as a run calls it: {run['compile_wall']:.1f} s wall, "
              f"{run['own_cpu']:.1f} s CPU in its process, {run['helpers_cpu']:.1f} s in its helper "
              f"(idle, the wall time would be about {idle:.1f} s)")  # fmt: skip
    if "old" in profiles:
        print(f"  new/old: CPU in one process {profiles['new']['cpu'] / profiles['old']['cpu']:.2f}")
    if "old" in runs:
        busier = {name: max(run["own_cpu"], run["helpers_cpu"]) for name, run in runs.items()}
        print(f"  new/old as a run: the busier process's CPU {busier['new'] / busier['old']:.2f}, "
              f"wall {runs['new']['compile_wall'] / runs['old']['compile_wall']:.2f}")  # fmt: skip
    print(f"load after: {load_after[0]:.1f} {load_after[1]:.1f} {load_after[2]:.1f}")
    return {"profiles": profiles, "runs": runs, "load": [load_before, load_after]}


def warm_start(trees: dict[str, Path], rounds: int, caches: Path | None) -> dict:
    """The ``--warm`` figures (module docstring), printed; returned for the JSON line."""
    load_before = os.getloadavg()
    print(f"load before: {load_before[0]:.1f} {load_before[1]:.1f} {load_before[2]:.1f}", flush=True)
    rows: dict[str, list[dict]] = {name: [] for name in trees}
    with tempfile.TemporaryDirectory(prefix="bench-kernels-") as scratch:
        root = caches or Path(scratch)
        env = {name: {"NUMBA_CACHE_DIR": str(root / name)} for name in trees}
        for name, tree in trees.items():  # the caches, compiled (or found warm)
            done, _, cpu = child(tree, ["-c", COMPILE], env[name])
            if done.returncode != 0:
                print(done.stderr[-3000:], file=sys.stderr)
                raise SystemExit(f"the compile of {name} failed")
            print(f"  {name}: cache ready ({cpu:.1f} s CPU)", flush=True)
        for k in range(rounds):
            for name, tree in trees.items():
                figures = {}
                for what in ("step", "cli"):
                    done, _, _ = child(tree, ["-c", WARM, what], env[name])
                    if done.returncode != 0:
                        print(done.stderr[-3000:], file=sys.stderr)
                        raise SystemExit(f"the warm start of {name} failed")
                    figures |= json.loads(done.stdout.strip().splitlines()[-1])
                rows[name].append(figures)
                print(f"  round {k + 1} {name}: {json.dumps(figures)}", flush=True)
    medians = {
        name: {key: statistics.median(r[key] for r in runs) for key in runs[0]} for name, runs in rows.items()
    }
    load_after = os.getloadavg()
    print("a process's start with the kernels cached, CPU s, median of the rounds:")
    for key in medians[next(iter(trees))]:
        cells = "  ".join(f"{name} {float(m[key]):7.3f}" for name, m in medians.items())
        print(f"  {key:28s} {cells}")
    print(f"load after: {load_after[0]:.1f} {load_after[1]:.1f} {load_after[2]:.1f}")
    return {"warm": medians, "rounds": rows, "load": [load_before, load_after]}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, help="checkout of the code to compare with")
    parser.add_argument("--compile", action="store_true", help="profile the compile alone, per kernel")
    parser.add_argument(
        "--no-profile", action="store_true", help="with --compile: only the compile as a run calls it"
    )
    parser.add_argument(
        "--duration", type=float, help="simulated time of each first run [s] (default: the scenario's)"
    )
    parser.add_argument(
        "--keep", type=Path, help="keep the runs' folders here (old/, new/: compare the traces)"
    )
    parser.add_argument("--warm", action="store_true", help="a process's start with the kernels cached")
    parser.add_argument("--caches", type=Path, help="with --warm: keep each tree's cache in DIR/<tree>")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of the per-tick figures (median)")
    parser.add_argument("--calls", type=int, default=5000, help="ControllerStep calls per figure")
    args = parser.parse_args()
    if args.compile:
        trees = {"new": HERE} | ({"old": args.old.resolve()} if args.old else {})
        print(json.dumps(compile_profile(trees, profile=not args.no_profile)))
        return
    if args.warm:
        trees = {"new": HERE} | ({"old": args.old.resolve()} if args.old else {})
        print(json.dumps(warm_start(trees, args.rounds, args.caches)))
        return
    if args.old is None:
        parser.error("--old is needed (but for --compile and --warm)")
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
            traces = [Path(tmp) / name / scenario / "traces.csv" for name in trees]
            same = all(t.is_file() for t in traces) and traces[0].read_bytes() == traces[1].read_bytes()
            first["new"][scenario]["traces_identical"] = same
            print(f"  {scenario}: traces.csv of old and new {'byte for byte the same' if same else 'DIFFER'}")
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

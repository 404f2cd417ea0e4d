"""Benchmark: where the test suite's CPU time goes, per test, per file and per kind.

    python bench/bench_test_cpu.py [PYTEST ARGS …]          # default: -m "not slow" -q
    python bench/bench_test_cpu.py --summarise FOLDER       # the tables again, from a run's records

Runs pytest (with the project's ``-n auto``, or the ``-n`` given) with this file as a plugin:
every worker records, for each test, the CPU time (user + sys) of its own process and of
the child processes it waited for (``getrusage``: variant and sweep processes, CLI
subprocesses, network-namespace runs, Chrome, Dask workers) over the test's set-up, call
and tear-down, and the CPU its start took before the first test (interpreter, imports,
collection). CPU, not wall time: on a shared machine the wall time of a test says how
busy the machine was, its CPU time what the test costs. The records go to a fresh folder
(one JSON line per test); the tables (top tests, files, kinds, and the sum against
``/usr/bin/time``'s figure for the whole pytest) are printed at the end, with a JSON line.

A test's kind is read from its file and name (:data:`KINDS`): an approximation that the
per-file table does not depend on. A child that outlives its test (a forkserver, a Dask
cluster kept for the session) is counted in the test that waits for it, or in nobody's.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import pytest

RECORDS = "NSDRAKE_TEST_CPU_RECORDS"  # the folder the workers write into

# (kind, substrings of the node id): the first match names the test's kind.
KINDS = (
    ("UDP / network namespace", ("udp", "netns", "namespace")),
    ("Ctrl-C / signals", ("interrupt", "ctrl_c", "sigint")),
    ("compare variant processes", ("test_compare.py", "settings_that_do_nothing", "laws_family")),
    ("sweep processes / Dask", ("test_sweep",)),
    ("CLI subprocess or in-process nsdrake run", ("test_cli.py", "drive_cli", "test_report", "test_output")),
    ("docs", ("tests/docs/",)),
    ("hypothesis / property", ("propert", "hypothesis")),
)


def _cpu(who) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def _now() -> tuple[float, float]:
    return _cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN)


_started: list = []


def pytest_configure(config):
    _started.append(_now())


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    folder = os.environ.get(RECORDS)
    before = _now()
    if folder and len(_started) == 1:  # the worker's start, once, before its first test
        _started.append(before)
        _write(folder, {"nodeid": "<worker start>", "self": before[0], "children": before[1]})
    yield
    after = _now()
    if folder:
        _write(
            folder, {"nodeid": item.nodeid, "self": after[0] - before[0], "children": after[1] - before[1]}
        )


def _write(folder: str, record: dict) -> None:
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    with open(Path(folder) / f"{worker}-{os.getpid()}.jsonl", "a") as f:
        f.write(json.dumps(record) + "\n")


def kind(nodeid: str) -> str:
    low = nodeid.lower()
    if nodeid == "<worker start>":
        return "worker start (imports, collection)"
    for name, needles in KINDS:
        if any(n in low for n in needles):
            return name
    return "other in-process tests"


def summarise(folder: Path, total: float | None = None, top: int = 30) -> dict:
    records = [
        json.loads(line) for p in sorted(folder.glob("*.jsonl")) for line in p.read_text().splitlines()
    ]
    per_test = [(r["self"] + r["children"], r["self"], r["children"], r["nodeid"]) for r in records]
    per_file: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0])
    per_kind: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0])
    for _, own, children, nodeid in per_test:
        for table, key in ((per_file, nodeid.split("::")[0]), (per_kind, kind(nodeid))):
            table[key][0] += own
            table[key][1] += children
            table[key][2] += 1
    summed = sum(t[0] for t in per_test)
    print(f"\n{len(per_test)} records; CPU-s summed over tests and worker starts: {summed:.1f}")
    if total is not None:
        print(f"pytest as a whole (its getrusage, children included): {total:.1f} CPU-s")
    print(f"\ntop {top} tests (CPU-s: total = own process + waited-for children)")
    for cpu, own, children, nodeid in sorted(per_test, reverse=True)[:top]:
        print(f"{cpu:7.2f} {own:7.2f} {children:7.2f}  {nodeid}")
    for title, table in (("files", per_file), ("kinds", per_kind)):
        print(f"\n{title} (CPU-s: total, own, children, tests)")
        for key, (own, children, n) in sorted(table.items(), key=lambda kv: -(kv[1][0] + kv[1][1])):
            print(f"{own + children:7.1f} {own:7.1f} {children:7.1f} {int(n):5d}  {key}")
    result = {
        "tests_cpu_s": round(summed, 1),
        "pytest_cpu_s": None if total is None else round(total, 1),
        "kinds": {k: round(v[0] + v[1], 1) for k, v in per_kind.items()},
    }
    print(json.dumps(result))
    return result


def main(argv: list[str]) -> int:
    if argv[:1] == ["--summarise"]:
        summarise(Path(argv[1]))
        return 0
    folder = Path(tempfile.mkdtemp(prefix="nsdrake-test-cpu-"))
    args = argv or ["-m", "not slow", "-q"]
    env = dict(os.environ, **{RECORDS: str(folder)})
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(Path(__file__).parent), env.get("PYTHONPATH")]))
    start, wall = _cpu(resource.RUSAGE_CHILDREN), time.monotonic()
    code = subprocess.call(
        [sys.executable, "-m", "pytest", "-p", "bench_test_cpu", "-p", "no:cacheprovider", *args], env=env
    )
    total = _cpu(resource.RUSAGE_CHILDREN) - start
    print(f"\npytest exit status {code}, {time.monotonic() - wall:.1f} s wall; records in {folder}")
    summarise(folder, total)
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""Benchmark: the CPU time of building a scenario's diagram, with the arm's reach disc
sampled on every build (as before issue 16, item 6) and cached per arm model.

    python bench/bench_build.py [--repeats N] [--scenario NAME]

After one warm-up build (imports, the numba cache), builds the diagram ``repeats``
times in each of two ways, interleaved so that both see the same machine load: with the
reach cache emptied before each build (the disc sampled, 2000 poses, as every build did
before) and with it kept (the disc sampled once per arm model and process). Prints the
process CPU time (``time.process_time``) of each build, the medians, the time saved per
build and the ratio of the medians. A ``nsdrake run`` builds two diagrams (with and
without the null-space task), a compare variant two, a sweep worker one per run.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import nsdrake.experiment.diagram as diagram
from nsdrake.experiment.scenario import load_scenario


def build_cpu(scenario, cached: bool) -> float:
    if not cached:
        diagram._REACH.clear()
    t0 = time.process_time()
    diagram.build_diagram(scenario)
    return time.process_time() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=21)
    parser.add_argument("--scenario", default="fig3")
    args = parser.parse_args()
    scenario = load_scenario(args.scenario)
    diagram.build_diagram(scenario)  # warm-up
    sampled, cached = [], []
    for _ in range(args.repeats):
        sampled.append(build_cpu(scenario, cached=False))
        cached.append(build_cpu(scenario, cached=True))
    for name, times in (("sampled", sampled), ("cached", cached)):
        print(f"{name:8s} build CPU [ms]: {[round(1e3 * t, 2) for t in times]}")
    m_sampled, m_cached = statistics.median(sampled), statistics.median(cached)
    print(
        f"{args.scenario}: median build {1e3 * m_sampled:.1f} ms with the reach sampled, "
        f"{1e3 * m_cached:.1f} ms cached: {1e3 * (m_sampled - m_cached):.1f} ms saved per build "
        f"(ratio {m_sampled / m_cached:.2f})"
    )
    print(json.dumps({"scenario": args.scenario, "sampled_ms": 1e3 * m_sampled, "cached_ms": 1e3 * m_cached}))


if __name__ == "__main__":
    main()

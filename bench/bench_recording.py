"""Benchmark: what recording the Meshcat replay adds to a run's wall time.

    python bench/bench_recording.py [--repeats N] [--duration SECONDS]

Two comparisons, each interleaved (unrecorded, recorded, unrecorded, …) so that
both see the same machine load, after one warm-up run:

- the simulation alone: ``simulate.run`` against a fresh Meshcat +
  ``simulate.run(meshcat=…)`` + ``write_replay`` (the recorded run as the
  runner does it);
- the whole run as ``nsdrake run`` does it: ``run_to_folder(replay=False)``
  against ``run_to_folder(replay=True)`` (comparison run, plots, diagram, report).

Prints every time, the medians, the ratio of the medians and the median of the
pairwise ratios (target: ≤ 1.20). The machines are noisy (±10–50% between runs):
read the ratios, not the seconds.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.simulate import run
from nsdrake.reporting.replay import write_replay
from nsdrake.reporting.run_folder import run_to_folder
from nsdrake.station.visualization import start_meshcat


def simulation(scenario, recorded: bool, folder: Path) -> float:
    t0 = time.perf_counter()
    if recorded:
        meshcat = start_meshcat(live=False)
        run(scenario, meshcat=meshcat)
        write_replay(meshcat, folder / "replay.html")
    else:
        run(scenario)
    return time.perf_counter() - t0


def whole_run(scenario, recorded: bool, folder: Path) -> float:
    with tempfile.TemporaryDirectory(dir=folder) as out:
        t0 = time.perf_counter()
        run_to_folder(scenario, Path(out), replay=recorded)
        return time.perf_counter() - t0


def compare(name: str, measure, scenario, repeats: int, folder: Path) -> float:
    measure(scenario, False, folder)  # warm-up: imports, first builds
    plain, recorded = [], []
    for _ in range(repeats):
        plain.append(measure(scenario, False, folder))
        recorded.append(measure(scenario, True, folder))
    p, r = statistics.median(plain), statistics.median(recorded)
    pairwise = statistics.median(b / a for a, b in zip(plain, recorded, strict=True))
    print(f"{name}, {scenario.duration:g} s simulated, {repeats} runs each [s]:")
    print(f"  unrecorded  {' '.join(f'{x:6.2f}' for x in plain)}   median {p:6.2f}")
    print(f"  recorded    {' '.join(f'{x:6.2f}' for x in recorded)}   median {r:6.2f}")
    print(f"  ratio recorded/unrecorded: of the medians {r / p:5.3f}, median pairwise {pairwise:5.3f}")
    print("  (target <= 1.20)")
    return r / p


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs per variant (median)")
    parser.add_argument("--duration", type=float, default=None, help="simulated time [s] (default: fig3's)")
    args = parser.parse_args()
    scenario = load_scenario("fig3", duration=args.duration)
    with tempfile.TemporaryDirectory() as folder:
        compare("simulation (main run only)", simulation, scenario, args.repeats, Path(folder))
        compare("whole run (nsdrake run)", whole_run, scenario, args.repeats, Path(folder))


if __name__ == "__main__":
    main()

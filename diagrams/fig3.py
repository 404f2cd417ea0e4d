"""Build and run the Fig. 3 diagram: python diagrams/fig3.py [OUT_DIR] [DURATION].

A thin script over the package: the same as `nsdrake run fig3 --out OUT_DIR`.
"""

import sys
from pathlib import Path

from nsdrake.experiment.scenario import load_scenario
from nsdrake.reporting.run_folder import prepare_output_folder, run_to_folder

if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("runs/fig3-script")
    duration = float(sys.argv[2]) if len(sys.argv) > 2 else None
    scenario = load_scenario("fig3", duration=duration)
    result = run_to_folder(scenario, prepare_output_folder(out, overwrite=False))
    for metric in result.metrics:
        print(f"{metric.name:38s} {metric.value:12.6g} {metric.unit}  {metric.bound}")
    sys.exit(0 if result.passed else 1)

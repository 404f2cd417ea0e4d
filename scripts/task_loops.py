"""The loops of the shipped scenarios as their reports show them (docs/laws.md, "With the
loop's delay"): the task's loops and the null-space loop, each with its damping ratio, its
slowest pole and its gain margin without and with one period of computation delay.

    python scripts/task_loops.py --out DIR

writes DIR/table.md from the functions a run's report calls
(``nsdrake.reporting.run_folder.controller_loops``, nsdrake/reporting/loops.py) on each
scenario's station, without simulating. scripts/regenerate_results.py --family task_loops
runs it into runs/results/task_loops and copies the table to docs/results/task_loops/.
"""

from __future__ import annotations

import sys

from pydrake.systems.framework import DiagramBuilder
from results_table import table_main

from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.reporting.run_folder import controller_loops

SCENARIOS = ("fig3", "panda_wipe")
HEADER = (
    "| loop | gains | damping_ratio | slowest_pole [rad/s] | gain_margin | gain_margin_delay |\n"
    "|---|---|---|---|---|---|\n"
)


def rows(name: str) -> list[str]:
    """The table's rows of scenario ``name``: one per loop of its report."""
    scenario = load_scenario(name)
    station = add_scenario_station(DiagramBuilder(), scenario, sensing=False)
    return [
        f"| {name} / {lp.name} | {lp.gains} | {lp.zeta or 'first order'} | {lp.slowest_pole:.4g} "
        f"| {lp.margin:.4g} | {lp.margin_delay:.4g} |"
        for lp in controller_loops(scenario, station)
    ]


def table() -> str:
    """The table.md this script writes."""
    return (
        "# task_loops\n\n"
        "The loops of the shipped scenarios as their reports show them (nsdrake/reporting/loops.py): "
        "each task direction under the impedance law with an exact model is a unit mass (normal to "
        "the plate in contact the contact's stiffness k_c adds K_f k_c), the null-space loop is the "
        "law's at the start posture; each sampled at the control period with the torque held. "
        "gain_margin is the factor on the loop's gain at which it turns unstable, gain_margin_delay "
        "the same with one period of computation delay (the torque computed from the sample at t_k "
        "applied from t_(k+1), as realism.delay and a real drive run it).\n\n"
        + HEADER
        + "\n".join(row for name in SCENARIOS for row in rows(name))
        + "\n"
    )


def main() -> int:
    return table_main(__doc__, table)


if __name__ == "__main__":
    sys.exit(main())

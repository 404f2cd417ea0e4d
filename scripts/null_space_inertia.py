"""The null-space inertias the tuning rule of docs/laws.md starts from, as
scripts/write_null_space_families.py computes them: at the start posture of
panda_self_motion (the Panda's tasks) and of fig3, the eigenvalues μ_i of M_n = Zᵀ H Z
and their geometric mean h_n (nsdrake/reporting/sampled_loops.py).

    python scripts/null_space_inertia.py --out DIR

writes DIR/table.md, without simulating. scripts/regenerate_results.py --family
null_space_inertia runs it into runs/results/null_space_inertia and copies the table to
docs/results/null_space_inertia/.
"""

from __future__ import annotations

import sys

import numpy as np
from results_table import table_main

from nsdrake.experiment.diagram import build_diagram
from nsdrake.experiment.scenario import load_scenario
from nsdrake.reporting.sampled_loops import null_space_inertia, null_space_masses

SCENARIOS = (("Panda", "panda_self_motion"), ("fig3's arm", "fig3"))


def row(name: str, scenario_name: str) -> str:
    """The table's row of one arm at its scenario's start posture."""
    scenario = load_scenario(scenario_name)
    arm = build_diagram(scenario).station.arm_model
    q0 = np.array([scenario.arm.initial_positions[j] for j in arm.joint_names])
    mu = null_space_masses(arm, q0)
    return (
        f"| {name} | {scenario_name} | {len(mu)} | {mu.min():.4g} | {mu.max():.4g} "
        f"| {null_space_inertia(arm, q0):.4g} |"
    )


def table() -> str:
    """The table.md this script writes."""
    return (
        "# null_space_inertia\n\n"
        "The null-space inertia at the start posture the tuning rule of the null_space_laws "
        "families uses (scripts/write_null_space_families.py): the eigenvalues mu_i of "
        "M_n = Z^T H Z (Z an orthonormal basis of J's null space) and their geometric mean h_n.\n\n"
        "| arm | start posture of | null-space directions | mu_min [kg m²] | mu_max [kg m²] | h_n [kg m²] |\n"
        "|---|---|---|---|---|---|\n" + "\n".join(row(*arm) for arm in SCENARIOS) + "\n"
    )


def main() -> int:
    return table_main(__doc__, table)


if __name__ == "__main__":
    sys.exit(main())

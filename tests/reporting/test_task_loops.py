"""The task's loops as a run's report and docs/results/task_loops/table.md give them
(nsdrake/reporting/loops.py, scripts/task_loops.py), against a construction of their own:
SciPy's zero-order-hold discretisation of the unit mass ẍ = a, the acceleration
a = −g (K x + D ẋ), and with a period's delay the command held one period more (an extra
state); the margin is the g at which the spectral radius reaches 1, found by bisection.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from pydrake.systems.framework import DiagramBuilder
from scipy.signal import cont2discrete

from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.reporting.run_folder import controller_loops

ROOT = Path(__file__).resolve().parents[2]


def spectral_radius(g: float, K: float, D: float, T: float, delayed: bool) -> float:
    mass = (np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), np.eye(2), 0)
    Ad, Bd, *_ = cont2discrete(mass, T)
    gains = g * np.array([[K, D]])
    if not delayed:  # the command computed at t_k acts over [t_k, t_k+1)
        return max(abs(np.linalg.eigvals(Ad - Bd @ gains)))
    # state [x, v, u]: u, computed at t_k, acts over [t_k+1, t_k+2)
    loop = np.block([[Ad, Bd], [-gains, np.zeros((1, 1))]])
    return max(abs(np.linalg.eigvals(loop)))


def margin(K: float, D: float, T: float, delayed: bool) -> float:
    low, high = 1e-3, 1e3
    for _ in range(80):
        mid = np.sqrt(low * high)
        low, high = (mid, high) if spectral_radius(mid, K, D, T, delayed) < 1 else (low, mid)
    return low


def test_fig3s_force_loop_as_the_report_models_it():
    """fig3 in contact as the report models it: ẍ = −(K_p,n + K_f k_c) x − K_v,n ẋ with
    K_p,n 100, K_f 1, k_c 50000 N/m, K_v,n 200, T 2 ms: margin 2/(K_v T) = 5 without delay
    and 1.106 with one period (the model's figure; the run's margin is larger: the slow
    test below). Catches the force loop built without the contact's stiffness (its delayed
    margin is then 2.5), the delayed margin computed without the delay (5), and either
    margin read at another period."""
    scenario = load_scenario("fig3")
    station = add_scenario_station(DiagramBuilder(), scenario, sensing=False)
    loops = {lp.name: lp for lp in controller_loops(scenario, station)}
    force = loops["task, normal to the plate, in contact (the force loop)"]
    imp, T = scenario.impedance, scenario.control_period
    K = imp.K_p_normal + imp.K_f * 50000.0  # the tool's and plate's stiffnesses in series
    assert "k_c 50000 N/m" in force.gains
    assert force.margin == pytest.approx(margin(K, imp.K_v_normal, T, delayed=False), rel=1e-3)
    assert force.margin_delay == pytest.approx(margin(K, imp.K_v_normal, T, delayed=True), rel=1e-3)
    along = loops["task, along the plate"]
    assert along.margin_delay == pytest.approx(
        margin(imp.K_p_tangent, imp.K_v_tangent, T, delayed=True), rel=1e-3
    )


def test_the_committed_table_is_what_the_script_writes():
    """docs/results/task_loops/table.md's rows are scripts/task_loops.py's rows today.
    Catches a change to the loops or to a shipped scenario's gains without the table
    regenerated (the pages cite its cells)."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import task_loops
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    committed = (ROOT / "docs" / "results" / "task_loops" / "table.md").read_text()
    written = [row for name in task_loops.SCENARIOS for row in task_loops.rows(name)]
    assert [line for line in committed.splitlines() if line.startswith("| ") and " / " in line] == written


@pytest.mark.slow
def test_fig3_with_a_periods_delay_diverges_above_the_approach_loops_margin_and_not_in_contact():
    """End to end, the project's own delay (``realism.delay``, one period) on fig3 with the
    normal loop's gains (K_p,n, K_v,n and K_f) scaled by g. The approach loop (normal to
    the plate before contact, delayed margin 2.499) is exact: at 1.05 × its margin the run
    diverges before contact, at 0.92 × it does not. The force loop's figure is a lower
    bound, not the margin: that same run at 0.92 × 2.499 = 2.3, twice the force loop's
    delayed margin (1.106), settles in contact (its force error over the last 0.3 s within
    1 N of f_d): the model sees the contact only through the sampled force term, not the
    plate's own push on the tool, which Drake's contact solves implicitly. 2.5 s runs. Catches an
    approach loop's delayed margin computed without the delay (5 would call 2.62 safe) and
    a report whose force-loop figure is taken for the loop's margin (the text says lower
    bound)."""
    import dataclasses

    from nsdrake.experiment.simulate import DivergenceError, run

    base = load_scenario("fig3", duration=2.5)
    station = add_scenario_station(DiagramBuilder(), base, sensing=False)
    loops = {lp.name: lp for lp in controller_loops(base, station)}
    approach = loops["task, normal to the plate, before contact"].margin_delay
    force = loops["task, normal to the plate, in contact (the force loop)"].margin_delay
    assert approach == pytest.approx(2.499, abs=1e-3) and 0.92 * approach > 2 * force

    def scaled(factor):
        imp = base.impedance
        impedance = dataclasses.replace(
            imp, K_p_normal=factor * imp.K_p_normal, K_v_normal=factor * imp.K_v_normal, K_f=factor * imp.K_f
        )
        delay = dataclasses.replace(base.realism.delay, enabled=True, periods=1)
        realism = dataclasses.replace(base.realism, delay=delay)
        return dataclasses.replace(base, impedance=impedance, realism=realism)

    traces, _ = run(scaled(0.92 * approach), null_space_task=False)
    t, error = traces["t"], traces["f_n"] - traces["f_d"]
    assert np.abs(error[t >= t[-1] - 0.3]).max() < 1.0  # in contact, settled
    with pytest.raises(DivergenceError) as diverged:
        run(scaled(1.05 * approach), null_space_task=False)
    assert diverged.value.t < 1.27  # before fig3's first contact: the approach loop


def test_the_committed_null_space_inertia_is_what_the_script_writes():
    """docs/results/null_space_inertia/table.md's rows are scripts/null_space_inertia.py's
    today, and its h_n is the geometric mean of the μ it lists (the Panda's one direction:
    μ itself). Catches a start posture or a model changed without the table regenerated
    (docs/laws.md cites h_n and fig3's lightest μ)."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import null_space_inertia
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    committed = (ROOT / "docs" / "results" / "null_space_inertia" / "table.md").read_text()
    rows = [line for line in committed.splitlines() if line.startswith("| ") and "[" not in line]
    assert rows == [null_space_inertia.row(*arm) for arm in null_space_inertia.SCENARIOS]
    for line in rows:
        directions, mu_min, mu_max, h_n = (float(c) for c in line.strip("| ").split(" | ")[2:])
        if directions == 2:
            assert h_n == pytest.approx(np.sqrt(mu_min * mu_max), rel=1e-3)
        else:
            assert mu_min == mu_max == h_n

"""Figures of nsdrake/reporting/metrics.py on traces made here, where the right answer is
known by construction (issue 45: a mode's time, the modes' bound, the contact transient)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nsdrake.experiment.traces import Traces
from nsdrake.reporting.metrics import contact_transient_metrics, priority_metrics

T = 0.002


def _priority_traces(duration: float, switch: float) -> Traces:
    t = np.round(np.arange(0.0, duration + T / 2, T), 9)  # 0 … duration, both ends
    mode = np.where(t < switch, 2.0, 3.0)
    columns = {"t": t, "mode": mode, "d_min": np.full_like(t, 0.1), "w": 0.01 + t, "p_tau": 10.0 - t}
    for i in range(1, 5):
        columns[f"tau{i}"] = np.sin(t * i)
    return Traces(columns)


def test_the_modes_times_add_up_to_the_run():
    """A 5 s run (rows at 0, 2 ms, …, 5 s) in mode 2 until 2 s, then mode 3: 2 s and 3 s,
    5 s together, the run's length (the last row, at the run's end, lasts no time).
    Catches a period counted for the last row (mode 3 3.002 s: 5.002 s in a 5 s run)."""
    by_name = {m.name: m for m in priority_metrics(_priority_traces(5.0, 2.0), blend_time=0.2)}
    assert by_name["mode2_time"].value == pytest.approx(2.0, abs=1e-9)
    assert by_name["mode3_time"].value == pytest.approx(3.0, abs=1e-9)
    assert by_name["mode1_time"].value == 0.0


def test_modes_visited_is_bounded_only_by_the_required_modes():
    """Without required modes modes_visited is a count with no bound (no bound text that a
    reader takes for one); with required modes 1 and 2, visiting 2 and 3 fails and names the
    mode missed. Catches a bound column that shows the visited list as if it were a bound."""
    traces = _priority_traces(1.0, 0.5)
    free = next(m for m in priority_metrics(traces, blend_time=0.2) if m.name == "modes_visited")
    assert (free.value, free.bound, free.passed) == (2.0, "", None)
    required = next(
        m
        for m in priority_metrics(traces, blend_time=0.2, required_modes=(1, 2))
        if m.name == "modes_visited"
    )
    assert required.passed is False and required.bound == "visits modes 1, 2 (missed 1)"


def _contact_traces(f_n: np.ndarray, f_d: float = 10.0) -> Traces:
    t = np.arange(len(f_n)) * T
    return Traces({"t": t, "f_n": f_n, "f_d": np.full_like(t, f_d)})


def test_the_contact_transient_of_a_second_order_step():
    """The force of an underdamped second-order step from the touch at 0.1 s, f_n =
    f_d (1 − e^{−ζω t}(cos ω_d t + ζ/√(1−ζ²) sin ω_d t)), ζ 0.3, ω 40 rad/s: the overshoot
    is e^{−πζ/√(1−ζ²)} (37.2%), the rise to 90% of f_d and the settling into ±5% of f_d
    are where the closed form first reaches 90% and last leaves the band (found here on
    a 1 µs grid), to a control period. Catches a rise or settling time measured from t = 0
    instead of the touch, an overshoot in N instead of a share of f_d, or a settling time
    taken at the first entry into the band."""
    zeta, omega, f_d, touch = 0.3, 40.0, 10.0, 0.1
    wd = omega * math.sqrt(1 - zeta**2)

    def step(s):
        s = np.maximum(s, 0.0)
        return f_d * (
            1 - np.exp(-zeta * omega * s) * (np.cos(wd * s) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * s))
        )

    t = np.arange(0.0, 2.0, T)
    f_n = np.where(t >= touch, np.maximum(step(t - touch), 0.6), 0.0)  # touches at 0.6 N
    by_name = {m.name: m for m in contact_transient_metrics(_contact_traces(f_n, f_d), contact_threshold=0.5)}
    fine = np.arange(0.0, 1.5, 1e-6)
    exact = step(fine)
    rise = fine[np.argmax(exact >= 0.9 * f_d)]
    settle = fine[np.flatnonzero(np.abs(exact - f_d) > 0.05 * f_d)[-1]]
    assert by_name["contact_overshoot"].value == pytest.approx(
        100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), rel=0.01
    )
    assert by_name["contact_rise_time"].value == pytest.approx(rise, abs=T + 1e-9)
    assert by_name["contact_settling_time"].value == pytest.approx(settle, abs=T + 1e-9)
    assert all(m.passed is None for m in by_name.values())  # the paper gives no bound


def test_a_force_that_never_settles_has_an_infinite_settling_time():
    """A force still 10% off f_d at the end: settling time ∞, no overshoot."""
    f_n = np.concatenate([np.zeros(50), np.full(500, 9.0)])
    by_name = {m.name: m for m in contact_transient_metrics(_contact_traces(f_n), contact_threshold=0.5)}
    assert by_name["contact_settling_time"].value == math.inf
    assert by_name["contact_overshoot"].value == 0.0
    assert by_name["contact_rise_time"].value == 0.0  # 9 N ≥ 90% of f_d at the touch

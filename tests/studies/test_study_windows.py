"""The studies' windows against the traces' own times (issue 37): hand-built traces whose
signals mark the rows on each side of every boundary, so that a window that starts or
ends a row early or late (or at the wrong event) changes a figure.

- ``nsdrake compare null_space_laws`` (:func:`law_figures`): the figures are taken from
  SETTLE_TIME after first contact (the first row at or after it) to the end;
- its push figures (:func:`push_figures`): the return time is the time from the push's
  start to the first sample of the tail that stays within RETURN_SHARE of the peak
  deviation (a sample exactly at the share is within), the error "before" the push is
  the row just before its start;
- the realism ladder (:func:`measure_realism`): the same settled window as the laws'.

The rows sit on the control period's grid, as a run logs them; the push's start and the
settled window's start each fall on a row, the boundary case.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import panda_arm

from nsdrake.experiment.traces import Traces
from nsdrake.reporting.metrics import SETTLE_TIME
from nsdrake.studies.compare import load_family, variant_scenario
from nsdrake.studies.null_space_laws import RETURN_SHARE, law_figures, push_figures

T = 1e-3
CONTACT_ROW = 1000  # the first row whose normal force reaches the threshold
TRANSIENT, AT_START, SETTLED = 5.0, 0.3, 0.1  # the marker: before the window, its first row, after


@pytest.fixture(scope="module")
def arm():
    return panda_arm()


def family_row(name: str):
    """A row of ``nsdrake compare null_space_laws``: its scenario, as the family runs it."""
    family = load_family("null_space_laws")
    index = next(i for i, v in enumerate(family.variants) if v.name == name)
    return variant_scenario(family, index, None, None)


@pytest.fixture(scope="module")
def wipe_scenario():
    return family_row("panda_wipe / paper")


@pytest.fixture(scope="module")
def push_scenario():
    """The "push / paper" row: a 50 ms push at 3.5 s."""
    return family_row("push / paper")


def times(rows: int) -> np.ndarray:
    return np.arange(rows) * T


def settled_row(t: np.ndarray) -> int:
    """The first row at or after SETTLE_TIME past first contact, from the traces' times."""
    return int(np.flatnonzero(t >= t[CONTACT_ROW] + SETTLE_TIME)[0])


def marker(t: np.ndarray) -> np.ndarray:
    """TRANSIENT up to the settled window, AT_START on its first row, SETTLED after."""
    k = settled_row(t)
    m = np.full(len(t), SETTLED)
    m[:k], m[k] = TRANSIENT, AT_START
    return m


def law_traces(rows: int, threshold: float, extra: dict | None = None) -> Traces:
    """Traces with the columns law_figures reads: contact at CONTACT_ROW (f_n from 0 to
    f_d + marker), the marker in every windowed error signal."""
    t = times(rows)
    m = marker(t)
    f_d = np.full(rows, 10.0)
    f_n = np.where(np.arange(rows) >= CONTACT_ROW, f_d + m, 0.0)
    assert f_n[CONTACT_ROW - 1] < threshold <= f_n[CONTACT_ROW]
    columns = {"t": t, "f_n": f_n, "f_d": f_d}
    for axis in ("x", "y", "z"):
        columns[axis], columns[f"{axis}_d"] = m / math.sqrt(3.0), np.zeros(rows)
    for name in (
        "rot_err",
        "task_disturbance",
        "posture_error",
        "posture_error_H",
        "posture_lag_predicted",
        "nu",
    ):
        columns[name] = m
    for j in range(1, 8):
        columns[f"tau0_{j}"] = m if j == 1 else np.zeros(rows)
    columns |= {"forbidden_contacts": np.zeros(rows), "tau0_scale": np.ones(rows)}
    return Traces(columns | (extra or {}))


def window_rms(values: np.ndarray, t: np.ndarray) -> float:
    k = settled_row(t)
    return float(np.sqrt(np.mean(values[k:] ** 2)))


def test_the_laws_figures_are_taken_from_settle_time_after_first_contact(wipe_scenario, arm):
    """The panda_wipe row, 2.5 s of traces, contact at 1.0 s: every windowed figure sees the marker
    from the row at 1.5 s on (its peak AT_START there, none of the transient before it).
    Catches the window from first contact (the transient's 5.0 taken), or one that starts
    a row late (AT_START missed: the peak would be SETTLED)."""
    scenario = wipe_scenario
    traces = law_traces(2500, scenario.reference.contact_threshold)
    row = law_figures(traces, SimpleNamespace(scenario=scenario, arm=arm))
    t, m = traces["t"], marker(traces["t"])
    assert "note" not in row, row["note"]
    assert row["force_error_peak"] == pytest.approx(AT_START, abs=1e-12)
    assert row["task_disturbance_peak"] == pytest.approx(AT_START, abs=1e-12)
    for name in ("force_error_rms", "position_error_rms", "orientation_error_rms", "posture_error_rms",
                 "posture_error_H_rms", "tau0_rms", "nu_rms", "task_disturbance_rms"):  # fmt: skip
        assert row[name] == pytest.approx(window_rms(m, t), rel=1e-12), name


def test_a_run_that_ends_before_the_window_has_no_figures(wipe_scenario, arm):
    """Traces that end one row before the window would start: no figures, and the note
    says why (the window is empty, not taken from contact)."""
    scenario = wipe_scenario
    rows = CONTACT_ROW + round(SETTLE_TIME / T)  # the last row is 0.499 s after contact
    t = times(rows + 1)
    traces = law_traces(rows + 1, scenario.reference.contact_threshold)
    assert t[-1] == pytest.approx(t[CONTACT_ROW] + SETTLE_TIME)  # this one ends exactly at it: figures
    assert "force_error_rms" in law_figures(traces, SimpleNamespace(scenario=scenario, arm=arm))
    shorter = Traces({name: traces[name][:-1] for name in traces.names})
    row = law_figures(shorter, SimpleNamespace(scenario=scenario, arm=arm))
    assert "force_error_rms" not in row and "no contact window" in row["note"]


def push_traces(
    push, threshold: float, *, deviation: np.ndarray, pos_before: float, limited: int
) -> tuple[Traces, int]:
    """law_traces for the push row's run (6 s), with the posture's deviation from where
    the push found it, the position error at the row before the push (the row at it 0.2 m
    off), and ``limited`` rows of τ₀ scaled down after the push; (traces, the push's row)."""
    rows = len(deviation)
    t = times(rows)
    start = int(np.flatnonzero(t >= push.start_time)[0])
    assert t[start] == pytest.approx(push.start_time)  # the push starts on a row: the boundary case
    scale = np.ones(rows)
    scale[start : start + limited] = 0.5
    scale[start - 3 : start] = 0.5  # before the push: not counted
    traces = law_traces(rows, threshold, {"posture_deviation": deviation, "tau0_scale": scale})
    columns = {name: traces[name] for name in traces.names}
    for axis in ("x", "y", "z"):
        columns[axis] = columns[axis].copy()
        columns[axis][start - 1] = pos_before / math.sqrt(3.0)
        columns[axis][start] = 0.2 / math.sqrt(3.0)
    return Traces(columns), start


def test_the_push_return_time_is_the_first_sample_of_the_tail_within_the_share(push_scenario):
    """The posture deviation rises to 1.0 rad 0.1 s after the push, stays above
    RETURN_SHARE of it up to a chosen row, is exactly at the share on the next row and
    below after: the return time is that next row's time minus the push's start (a
    sample at the share has returned). The position error before the push is the row
    just before it (0.07 m), the peak the row at it (0.2 m); τ₀ was limited for the 40
    rows from the push's start (those before it are not counted). Catches the return
    measured one sample early (at the last sample outside), a deviation at the share
    counted outside, or the "before" row taken at the push."""
    push = push_scenario.push
    rows = round(push_scenario.duration / T) + 1
    t = times(rows)
    deviation = np.zeros(rows)
    start = int(np.flatnonzero(t >= push.start_time)[0])
    peak_row, last_out = start + 100, start + 900
    deviation[start:peak_row] = np.linspace(0.0, 1.0, peak_row - start)
    deviation[peak_row : last_out + 1] = np.linspace(1.0, 0.051, last_out + 1 - peak_row)
    deviation[last_out + 1] = RETURN_SHARE * 1.0
    deviation[last_out + 2 :] = 0.02
    traces, start = push_traces(
        push, push_scenario.reference.contact_threshold, deviation=deviation, pos_before=0.07, limited=40
    )
    pos_err = np.linalg.norm(np.column_stack([traces[a] - traces[f"{a}_d"] for a in "xyz"]), axis=1)
    figures = push_figures(traces, push, pos_err)
    assert figures["push_return_time"] == pytest.approx(t[last_out + 1] - t[start], abs=1e-12)
    assert figures["push_posture_deviation_peak"] == 1.0
    assert figures["push_position_error_before"] == pytest.approx(0.07, abs=1e-12)
    assert figures["push_position_error_peak"] == pytest.approx(0.2, abs=1e-12)
    assert figures["push_tau0_limited_time"] == pytest.approx(40 * T, abs=1e-12)


def test_a_posture_outside_the_share_at_the_end_has_not_returned(push_scenario):
    """The deviation still above the share on the last row: the return time is infinite
    (not the run's length)."""
    push = push_scenario.push
    rows = round(push_scenario.duration / T) + 1
    t = times(rows)
    deviation = np.where(t >= push.start_time, 1.0, 0.0)
    deviation[-1] = 0.06
    traces, _ = push_traces(
        push, push_scenario.reference.contact_threshold, deviation=deviation, pos_before=0.0, limited=0
    )
    assert math.isinf(push_figures(traces, push, np.zeros(rows))["push_return_time"])


def test_the_push_figures_are_in_the_laws_row(push_scenario, arm):
    """law_figures on the push row's traces carries the push figures (the same numbers as
    push_figures' on its position error)."""
    push = push_scenario.push
    rows = round(push_scenario.duration / T) + 1
    deviation = np.where(times(rows) >= push.start_time + 0.01, 0.5, 0.0)
    traces, _ = push_traces(
        push, push_scenario.reference.contact_threshold, deviation=deviation, pos_before=0.07, limited=5
    )
    row = law_figures(traces, SimpleNamespace(scenario=push_scenario, arm=arm))
    assert row["push_position_error_before"] == pytest.approx(0.07, abs=1e-12)
    assert row["push_tau0_limited_time"] == pytest.approx(5 * T, abs=1e-12)
    assert math.isinf(row["push_return_time"])


def test_the_realism_ladder_measures_from_settle_time_after_first_contact():
    """The realism family's clean row (fig3), the same hand-built marker: its force,
    tangential position, ‖eⁿ‖ and ν figures see the window from the row at first contact
    + SETTLE_TIME on. Catches the window from first contact, or a row late."""
    from conftest import paper_arm

    from nsdrake.studies.compare import measure_realism

    family = load_family("realism")
    scenario = variant_scenario(family, 0, None, None)
    rows = 2500
    t = times(rows)
    m = marker(t)
    f_d = np.full(rows, 10.0)
    f_n = np.where(np.arange(rows) >= CONTACT_ROW, f_d + m, 0.0)
    zeros = np.zeros(rows)
    traces = Traces(
        {"t": t, "f_n": f_n, "f_d": f_d, "x": m, "x_d": zeros, "y": zeros, "y_d": zeros}
        | {"en1": m, "en2": zeros, "nu": m}
    )
    ctx = SimpleNamespace(
        scenario=scenario, arm=paper_arm(), tangent=np.array([1.0, 0.0]), normal=np.array([0.0, 1.0])
    )
    row = measure_realism(traces, ctx)
    assert row["first_contact_time"] == t[CONTACT_ROW] and "note" not in row, row.get("note")
    assert row["force_error_peak"] == pytest.approx(AT_START, abs=1e-12)
    for name in ("force_error_rms", "tangential_position_error_rms", "en_rms", "nu_rms"):
        assert row[name] == pytest.approx(window_rms(m, t), rel=1e-12), name

"""Acceptance figures, computed from the traces alone.

Each figure is a :class:`Metric` with its value, unit, the bound it must meet
and whether it does, so that metrics.json and the report show pass/fail.

- :func:`fig3_metrics`: the Fig. 3 experiment. The window runs from 0.5 s after
  first contact (the first row whose normal force reaches the contact threshold)
  to the end of the run.
- :func:`priority_metrics`: Fig. 1's switching: modes visited, each mode's
  criterion improving while the mode is active, torque steps at switches.
- :func:`joint_speed_metric`: the measured joint speeds against their limits.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .traces import Traces

SETTLE_TIME = 0.5  # [s] after first contact, start of the window
FORCE_RMS_BOUND = 0.02  # RMS(f_n − f_d) ≤ 2% of f_d
FORCE_MAX_BOUND = 0.10  # max |f_n − f_d| ≤ 10% of f_d
POSITION_RMS_BOUND = 1e-3  # RMS of the tangential position error ≤ 1 mm [m]
NULL_SPACE_RELATIVE_BOUND = 0.05  # RMS ‖eⁿ‖ ≤ 5% of RMS ‖q̇_dⁿ‖ …
NULL_SPACE_ABSOLUTE_BOUND = 1e-3  # … or 1e-3 rad/s, whichever is larger [rad/s]
D_MIN_AFTER = 1.0  # [s] from this time on, d_min must stay above d_lim
TORQUE_STEP_RATIO_BOUND = 2.0  # largest torque step at a switch ≤ 2 × the 99th percentile elsewhere
CONTACT_ONSET_EXCLUDED = (-0.01, 0.3)  # [s] around first contact, excluded from the torque-step baseline


@dataclass
class Metric:
    name: str
    value: float
    unit: str
    bound: str  # the acceptance bound, in words; "" for a figure reported without one
    passed: bool | None  # None when there is no bound

    def to_json(self) -> dict:
        d = asdict(self)
        d["value"] = _json_number(self.value)
        return d


def _json_number(x: float):
    x = float(x)
    return x if math.isfinite(x) else str(x)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else math.nan


def first_contact_index(traces: Traces, threshold: float) -> int | None:
    """The first row whose normal force reaches ``threshold``, or None."""
    hits = np.flatnonzero(traces["f_n"] >= threshold)
    return int(hits[0]) if hits.size else None


def fig3_metrics(
    traces: Traces,
    *,
    tangent: np.ndarray,
    task_axes: tuple[str, ...],
    contact_threshold: float,
    p_tau_without_null_space_task: float | None = None,
    d_lim: float | None = None,
) -> list[Metric]:
    """The acceptance figures of the fig3 issue from one run's traces.

    Args:
        traces: the run's traces (columns as written to traces.csv).
        tangent: (m,) unit direction along the plate, in task coordinates.
        task_axes: names of the task axes, e.g. ("x", "y").
        contact_threshold: normal force that counts as contact [N].
        p_tau_without_null_space_task: final joint-torque criterion of the same
            run with q̇_dⁿ = 0, if it was run.
        d_lim: the selector's obstacle limit: after the first second d_min must
            stay above it [m].
    """
    t = traces["t"]
    metrics: list[Metric] = []
    k0 = first_contact_index(traces, contact_threshold)
    if k0 is None:
        return [Metric("first_contact_time", math.inf, "s", "contact happens", False)]
    t_contact = float(t[k0])
    metrics.append(Metric("first_contact_time", t_contact, "s", "", None))
    window = t >= t_contact + SETTLE_TIME
    if not window.any():
        return metrics + [Metric("window_rows", 0, "rows", "> 0 rows after settling", False)]
    metrics.append(Metric("window_start", t_contact + SETTLE_TIME, "s", "", None))
    metrics.append(Metric("window_rows", int(window.sum()), "rows", "", None))

    f_n, f_d = traces["f_n"][window], traces["f_d"][window]
    f_ref = float(np.max(f_d))
    err = f_n - f_d
    metrics.append(
        Metric(
            "normal_force_min",
            float(f_n.min()),
            "N",
            "> 0 (tool never leaves the plate)",
            bool(f_n.min() > 0),
        )
    )
    rms_f = _rms(err)
    metrics.append(
        Metric(
            "force_error_rms",
            rms_f,
            "N",
            f"<= {FORCE_RMS_BOUND:.0%} of f_d = {FORCE_RMS_BOUND * f_ref:.4g} N",
            rms_f <= FORCE_RMS_BOUND * f_ref,
        )
    )
    max_f = float(np.max(np.abs(err)))
    metrics.append(
        Metric(
            "force_error_max",
            max_f,
            "N",
            f"<= {FORCE_MAX_BOUND:.0%} of f_d = {FORCE_MAX_BOUND * f_ref:.4g} N",
            max_f <= FORCE_MAX_BOUND * f_ref,
        )
    )
    x = np.column_stack([traces[a] for a in task_axes])[window]
    x_d = np.column_stack([traces[f"{a}_d"] for a in task_axes])[window]
    rms_x = _rms((x - x_d) @ tangent)
    metrics.append(
        Metric(
            "tangential_position_error_rms",
            rms_x,
            "m",
            f"<= {POSITION_RMS_BOUND:g} m",
            rms_x <= POSITION_RMS_BOUND,
        )
    )

    en = np.linalg.norm(traces.block("en")[window], axis=1)
    qns = np.linalg.norm(traces.block("qns")[window], axis=1)
    rms_en, rms_qns = _rms(en), _rms(qns)
    bound = max(NULL_SPACE_RELATIVE_BOUND * rms_qns, NULL_SPACE_ABSOLUTE_BOUND)
    metrics.append(Metric("null_space_command_rms", rms_qns, "rad/s", "", None))
    metrics.append(
        Metric(
            "null_space_error_rms",
            rms_en,
            "rad/s",
            f"<= max(5% of RMS ||qns|| , 1e-3 rad/s) = {bound:.3g} rad/s",
            rms_en <= bound,
        )
    )
    if d_lim is not None and "d_min" in traces:
        late = t >= D_MIN_AFTER
        d_late = float(traces["d_min"][late].min()) if late.any() else math.inf
        metrics.append(
            Metric(f"d_min_after_{D_MIN_AFTER:g}s", d_late, "m", f"> d_lim = {d_lim:g} m", d_late > d_lim)
        )
    forbidden = float(traces["forbidden_contacts"].max())
    metrics.append(
        Metric(
            "forbidden_contacts_max",
            forbidden,
            "contacts",
            "0 (only the tool touches the plate)",
            forbidden == 0,
        )
    )

    p_end = float(traces["p_tau"][-1])
    if p_tau_without_null_space_task is None:
        metrics.append(Metric("p_tau_end", p_end, "N^2 m^2", "", None))
    else:
        metrics.append(
            Metric(
                "p_tau_end",
                p_end,
                "N^2 m^2",
                f"< p_tau_end_without_null_space_task = {p_tau_without_null_space_task:.4g}",
                p_end < p_tau_without_null_space_task,
            )
        )
        metrics.append(
            Metric("p_tau_end_without_null_space_task", p_tau_without_null_space_task, "N^2 m^2", "", None)
        )
    return metrics


def joint_speed_metric(traces: Traces, limits: np.ndarray) -> Metric:
    """max over the run and the joints of |q̇_i| / limit_i (≤ 1: no joint exceeds its limit)."""
    v = np.abs(traces.block("v"))
    finite = np.isfinite(limits)
    if not finite.any():
        return Metric("joint_speed_ratio_max", 0.0, "-", "no joint has a speed limit", None)
    ratio = float(np.max(v[:, finite] / limits[finite]))
    return Metric("joint_speed_ratio_max", ratio, "-", "<= 1 (no joint exceeds its limit)", ratio <= 1.0)


def _intervals(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end] row indices of the runs of True in ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def torque_steps(traces: Traces) -> np.ndarray:
    """Δτ_k = max_i |τ_i(t_{k+1}) − τ_i(t_k)|, the largest change of commanded torque
    between consecutive control periods, per row k (len = rows − 1) [N m]."""
    return np.max(np.abs(np.diff(traces.block("tau"), axis=0)), axis=1)


def priority_metrics(
    traces: Traces,
    *,
    blend_time: float,
    contact_threshold: float | None = None,
    required_modes: tuple[int, ...] = (),
) -> list[Metric]:
    """Fig. 1's switching, from the ``mode``, ``d_min``, ``w``, ``p_tau`` and ``tau`` traces.

    - modes visited, with the time spent in each, and whether ``required_modes`` all appear;
    - in every interval of mode 1 (3, 2) that lasts at least ``blend_time`` (so
      its ordering is fully active), d_min (w) grows and p_tau falls from the
      interval's start to its end;
    - the largest torque step Δτ in the [switch, switch + blend_time] windows,
      against twice the 99th percentile of Δτ over the other rows, first contact
      ± (−0.01, 0.3) s excluded.
    """
    t = traces["t"]
    mode = traces["mode"].astype(int)
    h = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    metrics = []
    visited = sorted({int(m) for m in mode})
    if required_modes:
        missing = sorted(set(required_modes) - set(visited))
        metrics.append(
            Metric(
                "modes_visited",
                float(len(visited)),
                "modes",
                f"includes {list(required_modes)} (visited {visited}, missing {missing})",
                not missing,
            )
        )
    else:
        metrics.append(Metric("modes_visited", float(len(visited)), "modes", f"visited {visited}", None))
    criteria = {1: ("d_min", +1, "d_min grows"), 2: ("p_tau", -1, "p_tau falls"), 3: ("w", +1, "w grows")}
    for m, (column, sign, words) in criteria.items():
        spans = _intervals(mode == m)
        active = float(sum((t[b] - t[a] + h) for a, b in spans))
        metrics.append(Metric(f"mode{m}_time", active, "s", "", None))
        judged = [(a, b) for a, b in spans if t[b] - t[a] >= blend_time]
        if not judged:
            continue
        changes = [sign * (traces[column][b] - traces[column][a]) for a, b in judged]
        worst = float(min(changes))
        metrics.append(
            Metric(
                f"mode{m}_{column}_change_min",
                worst,
                {"d_min": "m", "p_tau": "N^2 m^2", "w": "m^2"}[column],
                f"> 0 in each of the {len(judged)} mode-{m} interval(s) of >= {blend_time:g} s ({words})",
                worst > 0,
            )
        )
    steps = torque_steps(traces)
    switches = np.flatnonzero(np.diff(mode) != 0) + 1  # rows where a new mode starts
    at_switch = np.zeros(len(steps), dtype=bool)
    for k in switches:
        at_switch[(t[:-1] >= t[k] - h / 2) & (t[:-1] <= t[k] + blend_time)] = True
    elsewhere = ~at_switch
    if contact_threshold is not None:
        k0 = first_contact_index(traces, contact_threshold)
        if k0 is not None:
            lo, hi = CONTACT_ONSET_EXCLUDED
            elsewhere &= ~((t[:-1] >= t[k0] + lo) & (t[:-1] <= t[k0] + hi))
    metrics.append(Metric("mode_switches", float(len(switches)), "switches", "", None))
    if len(switches) and elsewhere.any():
        largest = float(steps[at_switch].max())
        p99 = float(np.percentile(steps[elsewhere], 99))
        metrics.append(Metric("torque_step_p99_elsewhere", p99, "N m", "", None))
        metrics.append(
            Metric(
                "torque_step_at_switch_max",
                largest,
                "N m",
                f"<= {TORQUE_STEP_RATIO_BOUND:g} x p99 elsewhere = {TORQUE_STEP_RATIO_BOUND * p99:.4g} N m",
                largest <= TORQUE_STEP_RATIO_BOUND * p99,
            )
        )
    return metrics


def write_metrics(path: Path, metrics: list[Metric], extra: dict | None = None) -> None:
    """metrics.json: {"metrics": {name: {...}}, "all_passed": bool, **extra}."""
    body = {
        "all_passed": all(m.passed for m in metrics if m.passed is not None),
        "metrics": {m.name: m.to_json() for m in metrics},
    }
    if extra:
        body.update(extra)
    Path(path).write_text(json.dumps(body, indent=2) + "\n")


def contact_events(traces: Traces) -> list[tuple[str, float]]:
    """("contact", t) and ("lost", t) in time order, from the ``in_contact`` column."""
    if "in_contact" not in traces or len(traces) == 0:
        return []
    c, t = traces["in_contact"], traces["t"]
    events = [("contact", float(t[0]))] if c[0] else []
    for k in np.flatnonzero(np.diff(c)):
        events.append(("contact" if c[k + 1] else "lost", float(t[k + 1])))
    return events

"""Acceptance figures of the Fig. 3 experiment, computed from the traces alone.

Each figure is a :class:`Metric` with its value, unit, the bound it must meet
and whether it does, so that metrics.json and the report show pass/fail.

The window: from ``settle_time`` (0.5 s) after first contact (the first row
whose normal force reaches the contact threshold) to the end of the run.
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
) -> list[Metric]:
    """The acceptance figures of the fig3 issue from one run's traces.

    Args:
        traces: the run's traces (columns as written to traces.csv).
        tangent: (m,) unit direction along the plate, in task coordinates.
        task_axes: names of the task axes, e.g. ("x", "y").
        contact_threshold: normal force that counts as contact [N].
        p_tau_without_null_space_task: final joint-torque criterion of the same
            run with q̇_dⁿ = 0, if it was run.
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


def write_metrics(path: Path, metrics: list[Metric], extra: dict | None = None) -> None:
    """metrics.json: {"metrics": {name: {...}}, "all_passed": bool, **extra}."""
    body = {
        "all_passed": all(m.passed for m in metrics if m.passed is not None),
        "metrics": {m.name: m.to_json() for m in metrics},
    }
    if extra:
        body.update(extra)
    Path(path).write_text(json.dumps(body, indent=2) + "\n")

"""Acceptance figures, computed from the traces alone.

Each figure is a :class:`Metric` with its value, unit, the bound it must meet
and whether it does, so that metrics.json and the report show pass/fail.

- :func:`fig3_metrics`: the Fig. 3 experiment. The window runs from 0.5 s after
  first contact (the first row whose normal force reaches the contact threshold)
  to the end of the run.
- :func:`priority_metrics`: Fig. 1's switching: modes visited, each mode's
  criterion improving while the mode is active, torque steps at switches.
- :func:`joint_speed_metric`: the measured joint speeds against their limits.
- :func:`pose_metrics`: a pose task on a surface (panda_wipe): force, in-plane position
  and orientation tracking in the same window as fig3's, the smallest distance of the
  arm's links to each obstacle against the selector's d_lim, forbidden contacts, and
  every joint's closest approach to its position, speed and torque limits.
- :func:`self_motion_metrics`: the elbow's swivel while the tool holds its pose and force
  (panda_self_motion, Eq. 11 on a real arm).
- :func:`first_contact_metrics` (in both of these): the first contact's transition, which
  the window leaves out: the force's peak while it settles and the time the tool was off
  the surface after it; :func:`limit_metrics`: no row whose task torque was clipped.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from nsdrake.experiment.traces import Traces
from nsdrake.reporting.units import number, quantity, split_quantity

SETTLE_TIME = 0.5  # [s] after first contact, start of the window
FORCE_RMS_BOUND = 0.02  # RMS(f_n − f_d) ≤ 2% of f_d
FORCE_MAX_BOUND = 0.10  # max |f_n − f_d| ≤ 10% of f_d
POSITION_RMS_BOUND = 1e-3  # RMS of the tangential position error ≤ 1 mm [m]
ORIENTATION_RMS_BOUND = 0.5  # RMS of the orientation error ≤ 0.5° [deg]
ORIENTATION_MAX_BOUND = 2.0  # largest orientation error ≤ 2° [deg]
SWIVEL_RANGE_BOUND = 0.5  # the elbow swivels through at least 0.5 rad [rad]
NULL_SPACE_RELATIVE_BOUND = 0.05  # RMS ‖eⁿ‖ ≤ 5% of RMS ‖q̇_dⁿ‖ …
NULL_SPACE_ABSOLUTE_BOUND = 1e-3  # … or 1e-3 rad/s, whichever is larger [rad/s]
D_MIN_AFTER = 1.0  # [s] from this time on, d_min must stay above d_lim
TORQUE_STEP_RATIO_BOUND = 2.0  # largest torque step at a switch ≤ 2 × the 99th percentile elsewhere
CONTACT_PEAK_BOUND = FORCE_MAX_BOUND  # the force's peak while settling ≤ (1 + 10%) of f_d
OFF_SURFACE_BOUND = 0.0  # [s] time off the surface after first contact (the tool bounced)
CONTACT_ONSET_EXCLUDED = (-0.01, 0.3)  # [s] around first contact, excluded from the torque-step baseline
RISE_SHARE = 0.9  # the contact's rise time: from the touch until f_n first reaches this share of f_d
SETTLING_BAND = 0.05  # the contact's settling time: until f_n stays within ±5% of f_d
# The first contact's figures (first_contact_metrics, contact_transient_metrics)
FIRST_CONTACT_METRICS = (
    "contact_force_peak",
    "time_off_surface",
    "contact_rise_time",
    "contact_overshoot",
    "contact_settling_time",
)
NO_LAW_FIGURE = "n/a"  # the bound column of a metric the run's null-space law does not have


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


# What each metric measures, in words a reader of the report needs (no column names):
# (a pattern of metric names, its description). {1} is the pattern's first group.
# The window is WINDOW_WORDS.
WINDOW_WORDS = f"from {SETTLE_TIME:g} s after first contact to the end of the run"
DESCRIPTIONS: tuple[tuple[str, str], ...] = (
    (r"first_contact_time", "when the contact force first reached the contact threshold (the tool touches)"),
    (
        r"contact_force_peak",
        "largest contact force while the first contact settles (from the touch to the "
        "measuring window): how hard the tool hit the surface",
    ),
    (
        r"time_off_surface",
        "how long the tool was off the surface after it first touched it (0: it never bounced)",
    ),
    (
        r"contact_rise_time",
        f"time from the touch until the contact force first reached {RISE_SHARE:.0%} of f_d "
        "(f_d itself rises over reference.force_ramp_time)",
    ),
    (
        r"contact_overshoot",
        "how far the contact force rose above f_d while the first contact settled (from the "
        "touch to the measuring window), as a share of f_d (0: it never exceeded f_d)",
    ),
    (
        r"contact_settling_time",
        f"time from the touch until the contact force stayed within ±{SETTLING_BAND:.0%} of f_d "
        "to the end of the run (∞: it never did)",
    ),
    (r"window_start", f"start of the measuring window ({WINDOW_WORDS})"),
    (r"window_rows", "control periods in the measuring window (how many samples the figures below average)"),
    (r"normal_force_min", "smallest contact force in the window (0: the tool left the surface)"),
    (r"force_error_rms", "RMS of the contact force's error (measured minus desired) in the window"),
    (r"force_error_max", "largest contact force error in the window"),
    (r"tangential_position_error_rms", "RMS of the tool's position error along the plate in the window"),
    (r"position_error_rms", "RMS of the tool's position error along the surface in the window"),
    (r"position_error_max", "largest distance of the tool from where it should hold, while the elbow moves"),
    (r"orientation_error_rms", "RMS of the tool's orientation error (rotation angle) in the window"),
    (r"orientation_error_max", "largest orientation error of the tool in the window"),
    (
        r"null_space_command_rms",
        "RMS of the commanded null-space joint velocity q̇_dⁿ (what the arm's "
        "self-motion is asked to do) in the window",
    ),
    (
        r"null_space_error_rms",
        "RMS of the null-space velocity error eⁿ = q̇_dⁿ − N q̇ (how closely the "
        "self-motion follows its command, Eq. 14) in the window",
    ),
    (r"d_min_after_(.+)s", "closest distance of any link to an obstacle after the first {1} s"),
    (r"d_plate_min", "closest distance of any link (not the tool) to the plate over the run"),
    (r"d_(.+)_min", "closest distance of any link to the obstacle '{1}' over the run"),
    (
        r"forbidden_contacts_max",
        "most contacts at once between the arm and anything but the tool on the surface",
    ),
    (
        r"p_tau_end_without_null_space_task",
        "the same at the end of a second run with no null-space command "
        "(q̇_dⁿ = 0): what the null space has to improve on",
    ),
    (
        r"p_tau_end",
        "joint-torque criterion ‖Jᵀ F_d‖² (Eq. 32) at the end of the run: lower means the "
        "joints carry the contact force with less torque",
    ),
    (r"joint_speed_ratio_max", "largest joint speed over the run as a share of that joint's speed limit"),
    (r"modes_visited", "how many of Fig. 1's modes (which criterion is on level 2) the run visited"),
    (r"mode(\d)_time", "time spent in mode {1} of Fig. 1's decision tree"),
    (
        r"mode(\d)_(.+)_change_min",
        "in each stretch of mode {1} long enough to judge, how much {2} "
        "improved (the smallest improvement; > 0: it improved in every stretch)",
    ),
    (r"mode_switches", "how many times the mode (Fig. 1's decision tree) switched"),
    (
        r"torque_step_p99_elsewhere",
        "99th percentile of the joint torque's change from one control period to "
        "the next, away from switches and first contact: the run's ordinary torque steps",
    ),
    (
        r"torque_step_at_switch_max",
        "largest joint-torque change between two control periods just after a "
        "mode switch (a switch must not kick the arm)",
    ),
    (r"q_margin(\d+)_min", "joint {1}'s closest approach to its position limits (> 0: never reached)"),
    (r"v_margin(\d+)_min", "joint {1}'s closest approach to its speed limit (> 0: never reached)"),
    (r"tau_margin(\d+)_min", "joint {1}'s closest approach to its torque limit (>= 0: never exceeded)"),
    (
        r"saturated_joints_max_in_window",
        "most joints whose task torque had to be clipped to the actuator limits at once, in the window",
    ),
    (
        r"saturated_joints_max",
        "most joints whose task torque had to be clipped to the actuator limits at once",
    ),
    (
        r"swivel_range",
        "how far the elbow swivelled about the shoulder–wrist line while the tool held its pose",
    ),
)


# A mode's criterion (the traces' column) in words.
CRITERION_WORDS = {
    "d_min": "the closest link–obstacle distance",
    "p_tau": "the joint-torque criterion",
    "w": "the manipulability",
    "q_margin": "the smallest joint-limit margin",
}


def describe(name: str) -> str:
    """What the metric ``name`` measures, in words (DESCRIPTIONS); "" for a name without one."""
    for pattern, text in DESCRIPTIONS:
        match = re.fullmatch(pattern, name)
        if match:
            for k, group in enumerate(match.groups(), start=1):
                text = text.replace(f"{{{k}}}", CRITERION_WORDS.get(group, group))
            return text
    return ""


UNIT_WORDS = {"N^2 m^2": "N² m²", "m^2": "m²", "m/s^2": "m/s²", "-": "ratio", "rows": "control periods"}


def unit_words(unit: str) -> str:
    """A metric's unit as a reader writes it (N² m², not N^2 m^2; µm/s², a prefixed one)."""
    return UNIT_WORDS.get(unit, unit.replace("^2", "²").replace("^3", "³"))


def metric_line(m: Metric) -> str:
    """One metric as the terminal shows it: name, value in engineering units (62.91 µm),
    verdict (n/a where the run's law has no such figure) and bound."""
    value, unit = split_quantity(m.value, m.unit)
    if m.passed is None:
        mark = "  n/a" if m.bound.startswith(NO_LAW_FIGURE) else ""
    else:
        mark = "  pass" if m.passed else "  FAIL"
    bound = f"  (bound: {m.bound})" if m.bound and not m.bound.startswith(NO_LAW_FIGURE) else ""
    why = f"  ({m.bound})" if m.bound.startswith(NO_LAW_FIGURE) else ""
    return f"  {m.name:38s} {value:>12s} {unit_words(unit):14s}{mark}{bound}{why}"


def _json_number(x: float):
    x = float(x)
    return x if math.isfinite(x) else str(x)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else math.nan


def first_contact_index(traces: Traces, threshold: float) -> int | None:
    """The first row whose normal force reaches ``threshold``, or None."""
    hits = np.flatnonzero(traces["f_n"] >= threshold)
    return int(hits[0]) if hits.size else None


def measuring_window_gap(traces: Traces, contact_threshold: float, min_rows: int = 1) -> str | None:
    """Why a run has no force figures, in words a user can act on, or None when it has:
    the tool never reached the plate, or the window (from SETTLE_TIME after first contact
    to the end) starts after the run ends or holds fewer than ``min_rows`` periods. The figures of
    :func:`fig3_metrics`, the pose checks, ``nsdrake sweep`` and ``nsdrake compare``'s
    force measures all start there."""
    t = traces["t"]
    if not len(t):
        return "the run holds no control period: nothing to measure"
    k0 = first_contact_index(traces, contact_threshold)
    if k0 is None:
        return (
            f"no contact: the tool never pressed {contact_threshold:g} N on the plate in the "
            f"{t[-1]:.3g} s run, so the force figures are empty"
        )
    start = float(t[k0]) + SETTLE_TIME
    rows = int(np.sum(t >= start))
    if start > t[-1]:
        return (
            f"the measuring window starts {SETTLE_TIME:g} s after first contact ({t[k0]:.3g} s), at "
            f"{start:.3g} s, after the run ends at {t[-1]:.3g} s: its force figures are empty; run longer "
            "(--duration)"
        )
    if rows < min_rows:
        return (
            f"the measuring window (from {start:.3g} s, {SETTLE_TIME:g} s after first contact) holds {rows} "
            "control periods, too few to measure: its force figures are empty; run longer (--duration)"
        )
    return None


def fig3_metrics(
    traces: Traces,
    *,
    tangent: np.ndarray,
    task_axes: tuple[str, ...],
    contact_threshold: float,
    p_tau_without_null_space_task: float | None = None,
    d_lim: float | None = None,
    null_space_law: str = "paper",
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
        null_space_law: the run's ``null_space.law``; a law other than the paper's has no
            q̇_dⁿ and no eⁿ, and its null-space figures read n/a (:func:`_null_space_metrics`).
    """
    metrics, window = _window(traces, contact_threshold)
    if window is None:
        return metrics
    metrics += first_contact_metrics(traces, contact_threshold)
    metrics += contact_transient_metrics(traces, contact_threshold) + _force_metrics(traces, window)
    x = np.column_stack([traces[a] for a in task_axes])[window]
    x_d = np.column_stack([traces[f"{a}_d"] for a in task_axes])[window]
    rms_x = _rms((x - x_d) @ tangent)
    metrics.append(
        Metric(
            "tangential_position_error_rms",
            rms_x,
            "m",
            f"<= {quantity(POSITION_RMS_BOUND, 'm')}",
            rms_x <= POSITION_RMS_BOUND,
        )
    )
    metrics += _null_space_metrics(traces, window, null_space_law)
    if d_lim is not None and "d_min" in traces:
        metrics.append(_d_min_after_metric(traces, d_lim))
    metrics.append(forbidden_contacts_metric(traces))
    return metrics + _p_tau_metrics(traces, p_tau_without_null_space_task)


def _null_space_metrics(traces: Traces, window: np.ndarray, law: str = "paper") -> list[Metric]:
    """RMS ‖q̇_dⁿ‖ and RMS ‖eⁿ‖ over the window; the error's bound is relative to the
    command, with an absolute floor for a run that commands almost nothing. A law other
    than the paper's (a posture PD: a torque, no velocity command) has neither: both read
    n/a, ungraded (nan, no bound), not a failure."""
    if law != "paper":
        why = f"{NO_LAW_FIGURE}: the {law} law commands a torque, no q̇_dⁿ (no eⁿ)"
        return [
            Metric("null_space_command_rms", math.nan, "rad/s", why, None),
            Metric("null_space_error_rms", math.nan, "rad/s", why, None),
        ]
    en = np.linalg.norm(traces.block("en")[window], axis=1)
    qns = np.linalg.norm(traces.block("qns")[window], axis=1)
    rms_en, rms_qns = _rms(en), _rms(qns)
    bound = max(NULL_SPACE_RELATIVE_BOUND * rms_qns, NULL_SPACE_ABSOLUTE_BOUND)
    return [
        Metric("null_space_command_rms", rms_qns, "rad/s", "", None),
        Metric(
            "null_space_error_rms",
            rms_en,
            "rad/s",
            f"<= max(5% of RMS ||q̇_dⁿ||, {quantity(NULL_SPACE_ABSOLUTE_BOUND, 'rad/s')}) = "
            f"{quantity(bound, 'rad/s', 3)}",
            rms_en <= bound,
        ),
    ]


def _d_min_after_metric(traces: Traces, d_lim: float) -> Metric:
    """The smallest d_min from D_MIN_AFTER on, against the selector's d_lim."""
    late = traces["t"] >= D_MIN_AFTER
    d_late = float(traces["d_min"][late].min()) if late.any() else math.inf
    return Metric(
        f"d_min_after_{D_MIN_AFTER:g}s", d_late, "m", f"> d_lim = {quantity(d_lim, 'm')}", d_late > d_lim
    )


def _p_tau_metrics(traces: Traces, p_tau_without_null_space_task: float | None) -> list[Metric]:
    """The joint-torque criterion at the end, below the run without the null-space task's
    when that run was made."""
    p_end = float(traces["p_tau"][-1])
    if p_tau_without_null_space_task is None:
        return [Metric("p_tau_end", p_end, "N^2 m^2", "", None)]
    return [
        Metric(
            "p_tau_end",
            p_end,
            "N^2 m^2",
            f"< p_tau_end_without_null_space_task = {number(p_tau_without_null_space_task)} N² m²",
            p_end < p_tau_without_null_space_task,
        ),
        Metric("p_tau_end_without_null_space_task", p_tau_without_null_space_task, "N^2 m^2", "", None),
    ]


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
    """Fig. 1's switching, from the ``mode``, ``d_min``, ``w``, ``p_tau`` and ``tau`` traces
    (and ``q_margin`` for an arm with joint limits).

    - modes visited, with the time spent in each, and whether ``required_modes`` all appear;
    - in every interval of mode 1 (3, 4, 2) that lasts at least ``blend_time`` (so
      its ordering is fully active), d_min (w, q_margin) grows and p_tau falls from the
      interval's start to its end;
    - the largest torque step Δτ in the [switch, switch + blend_time] windows,
      against twice the 99th percentile of Δτ over the other rows, first contact
      ± (−0.01, 0.3) s excluded.
    """
    mode = traces["mode"].astype(int)
    metrics = [_modes_visited_metric(mode, required_modes)]
    for m, (column, sign, words) in _MODE_CRITERIA.items():
        if m == 4 and "q_margin" not in traces:  # mode 4 only on an arm with joint limits
            continue
        metrics += _mode_criterion_metrics(traces, mode, m, column, sign, words, blend_time)
    return metrics + _switch_step_metrics(traces, mode, blend_time, contact_threshold)


# Per mode: the criterion it puts on level 2, the sign of its improvement, in words.
_MODE_CRITERIA = {
    1: ("d_min", +1, "d_min grows"),
    2: ("p_tau", -1, "p_tau falls"),
    3: ("w", +1, "w grows"),
    4: ("q_margin", +1, "the smallest joint-limit margin grows"),
}
_CRITERION_UNITS = {"d_min": "m", "p_tau": "N^2 m^2", "w": "m^2", "q_margin": "rad"}


def _modes_visited_metric(mode: np.ndarray, required_modes: tuple[int, ...]) -> Metric:
    """How many modes the run visited; bounded only where the scenario requires modes
    (``report.required_modes``): then every one of them must be among those visited. (Which
    modes, in order: the report's modes section.)"""
    visited = sorted({int(m) for m in mode})
    if not required_modes:
        return Metric("modes_visited", float(len(visited)), "modes", "", None)
    missing = sorted(set(required_modes) - set(visited))
    words = ", ".join(str(m) for m in required_modes)
    return Metric(
        "modes_visited",
        float(len(visited)),
        "modes",
        f"visits modes {words}" + (f" (missed {', '.join(str(m) for m in missing)})" if missing else ""),
        not missing,
    )


def _control_period(traces: Traces) -> float:
    t = traces["t"]
    return float(np.median(np.diff(t))) if len(t) > 1 else 0.0


def _row_durations(t: np.ndarray) -> np.ndarray:
    """How long each row's state lasted: t_{k+1} − t_k, 0 for the last row (the run ends
    there), so the rows' durations sum to the run's t[-1] − t[0]."""
    return np.append(np.diff(t), 0.0) if len(t) else np.zeros(0)


def _mode_criterion_metrics(
    traces: Traces, mode: np.ndarray, m: int, column: str, sign: int, words: str, blend_time: float
) -> list[Metric]:
    """The time spent in mode ``m`` and, over its intervals of at least ``blend_time``,
    the smallest improvement of its criterion from the interval's start to its end."""
    t = traces["t"]
    spans = _intervals(mode == m)
    metrics = [Metric(f"mode{m}_time", float(np.sum(_row_durations(t)[mode == m])), "s", "", None)]
    judged = [(a, b) for a, b in spans if t[b] - t[a] >= blend_time]
    if not judged:
        return metrics
    worst = float(min(sign * (traces[column][b] - traces[column][a]) for a, b in judged))
    metrics.append(
        Metric(
            f"mode{m}_{column}_change_min",
            worst,
            _CRITERION_UNITS[column],
            f"> 0 in each of the {len(judged)} mode-{m} interval(s) of >= {blend_time:g} s ({words})",
            worst > 0,
        )
    )
    return metrics


def _switch_step_metrics(
    traces: Traces, mode: np.ndarray, blend_time: float, contact_threshold: float | None
) -> list[Metric]:
    """The number of switches, and the largest torque step within ``blend_time`` after a
    switch against twice the 99th percentile of the steps elsewhere (first contact's
    onset excluded)."""
    t, h = traces["t"], _control_period(traces)
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
    metrics = [Metric("mode_switches", float(len(switches)), "switches", "", None)]
    if not (len(switches) and elsewhere.any()):
        return metrics
    largest = float(steps[at_switch].max())
    p99 = float(np.percentile(steps[elsewhere], 99))
    return metrics + [
        Metric("torque_step_p99_elsewhere", p99, "N m", "", None),
        Metric(
            "torque_step_at_switch_max",
            largest,
            "N m",
            f"<= {TORQUE_STEP_RATIO_BOUND:g} x p99 elsewhere = "
            f"{quantity(TORQUE_STEP_RATIO_BOUND * p99, 'N m')}",
            largest <= TORQUE_STEP_RATIO_BOUND * p99,
        ),
    ]


def write_metrics(path: Path, metrics: list[Metric], extra: dict | None = None) -> None:
    """metrics.json: {"metrics": {name: {...}}, "all_passed": bool, **extra}."""
    body = {
        "all_passed": all(m.passed for m in metrics if m.passed is not None),
        "metrics": {m.name: m.to_json() for m in metrics},
    }
    if extra:
        body.update(extra)
    Path(path).write_text(json.dumps(body, indent=2) + "\n")


def _window(traces: Traces, contact_threshold: float) -> tuple[list[Metric], np.ndarray | None]:
    """The fig3 window (from SETTLE_TIME after first contact), with its metrics; None if empty."""
    t = traces["t"]
    k0 = first_contact_index(traces, contact_threshold)
    if k0 is None:
        return [Metric("first_contact_time", math.inf, "s", "contact happens", False)], None
    t_contact = float(t[k0])
    window = t >= t_contact + SETTLE_TIME
    metrics = [Metric("first_contact_time", t_contact, "s", "", None)]
    if not window.any():
        return metrics + [Metric("window_rows", 0, "rows", "> 0 rows after settling", False)], None
    metrics.append(Metric("window_start", t_contact + SETTLE_TIME, "s", "", None))
    metrics.append(Metric("window_rows", int(window.sum()), "rows", "", None))
    return metrics, window


def first_contact_metrics(traces: Traces, contact_threshold: float) -> list[Metric]:
    """The first contact's transition, from the first row whose normal force reaches the
    threshold: ``contact_force_peak``, the largest measured normal force f_n before the
    window starts (SETTLE_TIME later), bound (1 + 10%) of f_d; ``time_off_surface``, how
    long f_n was ≤ 0 (the tool off the plate: it bounced) from then to the end of the run,
    bound 0 s. Nothing when the tool never touched (:func:`_window` says so)."""
    k0 = first_contact_index(traces, contact_threshold)
    if k0 is None:
        return []
    t, f_n = traces["t"], traces["f_n"]
    f_ref = float(np.max(traces["f_d"]))
    settling = slice(k0, int(np.searchsorted(t, t[k0] + SETTLE_TIME)))
    peak = float(np.max(f_n[settling]))
    period = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    off = float(np.count_nonzero(f_n[k0:] <= 0.0)) * period
    return [
        Metric(
            "contact_force_peak",
            peak,
            "N",
            f"<= f_d + {CONTACT_PEAK_BOUND:.0%} = {quantity((1 + CONTACT_PEAK_BOUND) * f_ref, 'N')}",
            peak <= (1 + CONTACT_PEAK_BOUND) * f_ref,
        ),
        Metric(
            "time_off_surface",
            off,
            "s",
            f"<= {quantity(OFF_SURFACE_BOUND, 's')} (the tool never leaves the plate once it touched)",
            off <= OFF_SURFACE_BOUND,
        ),
    ]


def contact_transient_metrics(traces: Traces, contact_threshold: float) -> list[Metric]:
    """The first contact's transient, from the first row whose normal force reaches the
    threshold (the touch): ``contact_rise_time``, until f_n first reaches RISE_SHARE of f_d
    (its final value); ``contact_overshoot``, the largest f_n − f_d before the measuring
    window (SETTLE_TIME after the touch) over f_d [1], 0 if f_n never exceeded f_d;
    ``contact_settling_time``, until |f_n − f_d| stays within SETTLING_BAND of f_d to the
    end of the run (inf if it is outside at the end). The paper gives no bound for any of
    them: reported, not graded. Nothing when the tool never touched."""
    k0 = first_contact_index(traces, contact_threshold)
    if k0 is None:
        return []
    t, f_n = traces["t"], traces["f_n"]
    f_ref = float(np.max(traces["f_d"]))
    after = np.arange(len(t)) >= k0
    reached = np.flatnonzero(after & (f_n >= RISE_SHARE * f_ref))
    rise = float(t[reached[0]] - t[k0]) if reached.size else math.inf
    settling = after & (t < t[k0] + SETTLE_TIME)
    overshoot = max(0.0, float(np.max(f_n[settling]) - f_ref) / f_ref) if f_ref > 0 else math.nan
    outside = np.flatnonzero(after & (np.abs(f_n - f_ref) > SETTLING_BAND * f_ref))
    if not outside.size:
        settle = 0.0
    elif outside[-1] + 1 < len(t):
        settle = float(t[outside[-1] + 1] - t[k0])
    else:
        settle = math.inf
    return [
        Metric("contact_rise_time", rise, "s", "", None),
        Metric("contact_overshoot", overshoot * 100.0, "%", "", None),
        Metric("contact_settling_time", settle, "s", "", None),
    ]


def _force_metrics(traces: Traces, window: np.ndarray) -> list[Metric]:
    f_n, f_d = traces["f_n"][window], traces["f_d"][window]
    f_ref = float(np.max(f_d))
    err = f_n - f_d
    rms_f, max_f = _rms(err), float(np.max(np.abs(err)))
    return [
        Metric(
            "normal_force_min",
            float(f_n.min()),
            "N",
            "> 0 (tool never leaves the plate)",
            bool(f_n.min() > 0),
        ),
        Metric(
            "force_error_rms",
            rms_f,
            "N",
            f"<= {FORCE_RMS_BOUND:.0%} of f_d = {quantity(FORCE_RMS_BOUND * f_ref, 'N')}",
            rms_f <= FORCE_RMS_BOUND * f_ref,
        ),
        Metric(
            "force_error_max",
            max_f,
            "N",
            f"<= {FORCE_MAX_BOUND:.0%} of f_d = {quantity(FORCE_MAX_BOUND * f_ref, 'N')}",
            max_f <= FORCE_MAX_BOUND * f_ref,
        ),
    ]


def in_plane_errors(traces: Traces, normal: np.ndarray, task_axes: tuple[str, ...]) -> np.ndarray:
    """‖(I − n nᵀ)(x − x_d)‖ per row: the position error along the surface (the normal
    coordinate is force-controlled). (rows,) [m]."""
    x = np.column_stack([traces[a] for a in task_axes])
    x_d = np.column_stack([traces[f"{a}_d"] for a in task_axes])
    e = x - x_d
    return np.linalg.norm(e - np.outer(e @ normal, normal), axis=1)


def _orientation_metrics(traces: Traces, window: np.ndarray) -> list[Metric]:
    if "rot_err" not in traces:
        return []
    rot = np.degrees(traces["rot_err"][window])
    rms, largest = _rms(rot), float(np.max(rot))
    return [
        Metric(
            "orientation_error_rms",
            rms,
            "deg",
            f"<= {ORIENTATION_RMS_BOUND:g} deg",
            rms <= ORIENTATION_RMS_BOUND,
        ),
        Metric(
            "orientation_error_max",
            largest,
            "deg",
            f"<= {ORIENTATION_MAX_BOUND:g} deg",
            largest <= ORIENTATION_MAX_BOUND,
        ),
    ]


def limit_metrics(traces: Traces) -> list[Metric]:
    """Every joint's closest approach to its position, speed and torque limits over the
    whole run (the q_margin, v_margin, tau_margin columns; > 0: never reached), and how
    often the task torque itself had to be clipped."""
    metrics = []
    words = {
        "q": ("rad", "position"),
        "v": ("rad/s", "speed (the model's velocity limit)"),
        "tau": ("N m", "torque (the actuator limit)"),
    }
    for kind, (unit, what) in words.items():
        block = traces.block(f"{kind}_margin")
        for i in range(block.shape[1]):
            closest = float(np.min(block[:, i]))
            if not math.isfinite(closest):
                continue
            bound = (
                ">= 0 (the applied torque never exceeds it)"
                if kind == "tau"
                else f"> 0 (never reaches its {what} limit)"
            )
            passed = closest >= 0 if kind == "tau" else closest > 0
            metrics.append(Metric(f"{kind}_margin{i + 1}_min", closest, unit, bound, passed))
    clipped = float(traces["saturated_joints"].max())
    metrics.append(
        Metric(
            "saturated_joints_max",
            clipped,
            "joints",
            "0 (the task torque never clipped to the actuator limits)",
            clipped == 0,
        )
    )
    return metrics


def _clearance_metrics(traces: Traces, d_lim: float, obstacles: tuple[str, ...]) -> list[Metric]:
    """The closest each obstacle (beyond d_lim) and the plate (beyond 0) came to the links."""
    metrics = []
    for name in obstacles:
        closest = float(traces[f"d_{name}"].min())
        metrics.append(
            Metric(f"d_{name}_min", closest, "m", f"> d_lim = {quantity(d_lim, 'm')}", closest > d_lim)
        )
    if "d_plate" in traces:
        closest = float(traces["d_plate"].min())
        metrics.append(Metric("d_plate_min", closest, "m", "> 0 (no link touches the plate)", closest > 0))
    return metrics


def pose_metrics(
    traces: Traces,
    *,
    normal: np.ndarray,
    task_axes: tuple[str, ...],
    contact_threshold: float,
    d_lim: float,
    obstacles: tuple[str, ...],
) -> list[Metric]:
    """The acceptance figures of a pose task on a surface (panda_wipe), from the traces.

    Args:
        traces: the run's traces (with rot_err, d_<obstacle>, the margin columns).
        normal: (m_t,) unit push direction on the translational task axes.
        task_axes: the translational task axes, e.g. ("x", "y", "z").
        contact_threshold: normal force that counts as contact [N].
        d_lim: the selector's obstacle limit; every obstacle but the plate must stay
            farther than this from the arm's links throughout [m].
        obstacles: names of the obstacles besides the plate.
    """
    metrics, window = _window(traces, contact_threshold)
    if window is None:
        return metrics
    metrics += first_contact_metrics(traces, contact_threshold)
    metrics += contact_transient_metrics(traces, contact_threshold) + _force_metrics(traces, window)
    rms_x = _rms(in_plane_errors(traces, normal, task_axes)[window])
    metrics.append(
        Metric(
            "position_error_rms",
            rms_x,
            "m",
            f"<= {quantity(POSITION_RMS_BOUND, 'm')}",
            rms_x <= POSITION_RMS_BOUND,
        )
    )
    metrics += _orientation_metrics(traces, window) + _clearance_metrics(traces, d_lim, obstacles)
    forbidden = float(traces["forbidden_contacts"].max())
    metrics.append(
        Metric(
            "forbidden_contacts_max",
            forbidden,
            "contacts",
            "0 (only the tool touches the plate and the obstacles)",
            forbidden == 0,
        )
    )
    clipped = float(traces["saturated_joints"][window].max())
    metrics.append(
        Metric(
            "saturated_joints_max_in_window",
            clipped,
            "joints",
            "0 (the task torque never clipped while in contact)",
            clipped == 0,
        )
    )
    return metrics + limit_metrics(traces)


def self_motion_metrics(
    traces: Traces, *, normal: np.ndarray, task_axes: tuple[str, ...], contact_threshold: float
) -> list[Metric]:
    """The elbow's swivel (max − min of the ``swivel`` column over the window) while the
    tool holds its pose and force: the largest in-plane position error and the force
    error's RMS in the same window (fig3's, from 0.5 s after first contact), the
    orientation error, forbidden contacts, and the joints' closest approach to their
    limits (:func:`limit_metrics`)."""
    metrics, window = _window(traces, contact_threshold)
    if window is None:
        return metrics
    metrics += first_contact_metrics(traces, contact_threshold)
    metrics += contact_transient_metrics(traces, contact_threshold)
    swivel = traces["swivel"][window]
    travel = float(swivel.max() - swivel.min())
    metrics.append(
        Metric(
            "swivel_range",
            travel,
            "rad",
            f">= {SWIVEL_RANGE_BOUND:g} rad (the elbow sweeps through the null space)",
            travel >= SWIVEL_RANGE_BOUND,
        )
    )
    largest = float(np.max(in_plane_errors(traces, normal, task_axes)[window]))
    metrics.append(
        Metric(
            "position_error_max",
            largest,
            "m",
            f"<= {quantity(POSITION_RMS_BOUND, 'm')}",
            largest <= POSITION_RMS_BOUND,
        )
    )
    metrics += [m for m in _force_metrics(traces, window) if m.name != "force_error_max"]
    metrics += _orientation_metrics(traces, window)
    metrics.append(forbidden_contacts_metric(traces))
    return metrics + (limit_metrics(traces) if "q_margin1" in traces else [])


def contact_events(traces: Traces) -> list[tuple[str, float]]:
    """("contact", t) and ("lost", t) in time order, from the ``in_contact`` column."""
    if "in_contact" not in traces or len(traces) == 0:
        return []
    c, t = traces["in_contact"], traces["t"]
    events = [("contact", float(t[0]))] if c[0] else []
    for k in np.flatnonzero(np.diff(c)):
        events.append(("contact" if c[k + 1] else "lost", float(t[k + 1])))
    return events


def forbidden_contacts_metric(traces: Traces) -> Metric:
    """The largest number of contacts between the plate or an obstacle and any body but
    the tool; bound 0."""
    forbidden = float(traces["forbidden_contacts"].max())
    return Metric(
        "forbidden_contacts_max", forbidden, "contacts", "0 (only the tool touches the plate)", forbidden == 0
    )

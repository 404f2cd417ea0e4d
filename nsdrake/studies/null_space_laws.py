"""Issues 19 and 25: which null-space law? The figures of ``nsdrake compare null_space_laws``
and ``nsdrake compare null_space_bandwidth``.

The families run each law of :mod:`nsdrake.control.null_space_laws` on each task with the
same task impedance and the same secondary objective, a posture q_d. Each law is tuned by
one written rule of this project's (:func:`tuned_gains`; a rule, not the libraries' own
gains, which are rows of their own: :data:`FRANKA_ROS_GAINS`, :data:`ROBOSUITE_GAINS`):
stable at the control period and about critically damped, for a null-space bandwidth
ω [rad/s], the rate of the slowest pole of the posture's return, equal for every law.

The rule comes from the null-space loop with the task held: in coordinates s of J's null
space (q − q* = Z s, Z an orthonormal basis), Zᵀ H Z s̈ = Zᵀ τ₀, since Zᵀ Jᵀ = 0; with
M_n = Zᵀ H Z (its eigenvalues μ_i, the null-space inertias, :func:`null_space_masses`) and q_d
on the self-motion (q* − q_d ∈ range Z):

- kinematic posture PD and dynamically consistent torque PD: Zᵀ (I − Jᵀ (Jᵀ)⁺_λ) = Zᵀ and
  Zᵀ (I − Jᵀ J̄ᵀ) = Zᵀ, so μ s̈ + D_ns ṡ + K_ns s = 0 per direction; the rule
  K_ns = ω² h_n, D_ns = 2 ω h_n gives a double pole at −ω where μ = h_n (λ does not enter:
  it changes what τ₀ does to the task, not to s);
- dynamically consistent posture PD (multiplied by H): s̈ + D_ns ṡ + K_ns s = 0 in every
  direction; the rule K_ns = ω², D_ns = 2 ω;
- the paper's law (Eq. 21 with Eq. 30 on p = ½‖q − q_d‖²): (I − J̄ J) H⁻¹ = Z M_n⁻¹ Zᵀ, so
  q̇_dⁿ = K Z M_n⁻¹ s and the commanded ṡ_d = −a s with a = |K|/μ (through J⁺: a = |K|); the
  velocity loop with its feedforward q̈_dⁿ gives s̈ = s̈_d + K_n (ṡ_d − ṡ), poles −a and −K_n.
  The rule a = ω, K_n = 2 ω: K = −ω h_n (K = −ω with J⁺), poles −ω and −2ω, a damping ratio
  (a + K_n)/(2 √(a K_n)) = 3/(2√2) = 1.06.

h_n is the geometric mean of the μ_i at the start posture (the Panda's pose task leaves one
direction, fig3's position task two): where the μ_i differ the rule is exact for none and
the damping ratio spans a range, reported per row (:func:`null_space_loop`) with the
discrete-time pole radius ρ_T of the sampled loop at the control period T (the torque held
over each period; ρ_T < 1 is stable; a sampled damper alone diverges once T D/μ > 2) and
the gain margin, without and with one period of computation delay (the torque computed
from the sample at t_k applied from t_{k+1}, as ``realism.delay`` and a drive that
answers status k with the command the robot applies at k + 1 run it).

The figures (:func:`law_figures`), from the traces and the arm's model only, the same
for every law:

- force error f_n − f_d and the tool's position and orientation error in the window
  (from first contact + :data:`~nsdrake.reporting.metrics.SETTLE_TIME` to the end);
- the task disturbance by the null space, J H⁻¹ τ₀ (τ₀ the applied null-space torque,
  logged: ``report.null_space_torque``), its translational part [m/s²];
- the posture error, the part of q − q_d(t) the self-motion can remove, in two metrics:
  joint space ‖(I − J⁺ J) e‖ (orthogonal projector) [rad], and the inertia metric
  ‖(I − J̄ J) e‖_H / √h_n (the H-orthogonal projector, scaled to rad by the start's h_n);
  the laws that settle in joint space bring the first to zero, the H-weighted PD the second;
- after a push (``push``): the largest tool position error, and the time from the push's
  start until the posture's deviation from where the push found it stays within 5% of
  its peak;
- the effort RMS ‖τ₀‖, and ν (Eq. 23) where the law has it;
- when a link (not the tool) first touched the plate or an obstacle, if one did (no
  criterion guards the links in this family: the posture is the only objective).
"""

from __future__ import annotations

import math

import numpy as np

from nsdrake.control.null_space_laws import posture_target
from nsdrake.experiment.traces import Traces
from nsdrake.reporting.metrics import SETTLE_TIME, first_contact_index
from nsdrake.reporting.sampled_loops import (  # noqa: F401 (the loop figures, re-exported for the study)
    FRANKA_ROS_GAINS,
    FRANKA_ROS_LAMBDA,
    GAIN_MARGIN_MAX,
    LAW_KEYS,
    ROBOSUITE_GAINS,
    RUN_SAMPLE,
    TASK_AXIS,
    UNIT_MASS_LAWS,
    VELOCITY_LOOP,
    _continuous_poles,
    _loop_parts,
    _pole_radius,
    _sampled_loop,
    _span,
    damping_ratio,
    gain_margin,
    law_key,
    loop_along_run,
    loop_figures,
    null_space_inertia,
    null_space_loop,
    null_space_masses,
    paper_poles_gains,
    row_gains,
    tuned_gains,
)

RETURN_SHARE = 0.05  # the posture has returned once its deviation stays within this share of its peak


def self_motion_posture(arm, q0: np.ndarray, arc: float, steps: int = 200) -> np.ndarray:
    """The posture reached from q0 by moving ``arc`` [rad, Euclidean joint-space length]
    along the self-motion (J q̇ = 0, the first joint's component positive), each step
    corrected back to the start's task pose by Gauss–Newton: a posture with the tool where
    it was (for a reachable q_d offset)."""
    context = arm.plant.CreateDefaultContext()
    zero = np.zeros(arm.n)

    def pose(q):
        arm.plant.SetPositions(context, q)
        X = arm.plant.CalcRelativeTransform(context, arm.plant.world_frame(), arm.tool_frame)
        return X.translation(), X.rotation().matrix()

    p0, R0 = pose(q0)
    q = np.array(q0, dtype=float)
    for _ in range(steps):
        J = arm.terms(context, q, zero, coriolis=False).J
        z = np.linalg.svd(J)[2][-1]
        q = q + (arc / steps) * (z if z[0] >= 0 else -z)
        for _ in range(3):
            p, R = pose(q)
            J = arm.terms(context, q, zero, coriolis=False).J
            error = _pose_error(arm, p0 - p, R0 @ R.T)
            q = q + np.linalg.pinv(J) @ error
    return q


def _pose_error(arm, dp: np.ndarray, R_err: np.ndarray) -> np.ndarray:
    """The task-axis error [dp on the translational axes; the rotation vector of R_err on the
    rotational ones]."""
    from pydrake.math import RotationMatrix

    angle_axis = RotationMatrix(R_err).ToAngleAxis()
    w = angle_axis.axis() * angle_axis.angle()
    return np.concatenate([dp[arm.rows], w[arm.rot_rows]])


# --- the figures ---------------------------------------------------------------------------


def law_columns(traces: Traces, scenario, arm) -> Traces:
    """The traces with the figures' per-row signals added: ``task_disturbance`` ‖(J H⁻¹ τ₀)
    translational‖ [m/s²], ``task_disturbance_rot`` (rotational rows, [rad/s²]; 0 without)
    ``posture_error`` ‖(I − J⁺ J)(q − q_d(t))‖ [rad], ``posture_error_H`` ‖(I − J̄ J)(q −
    q_d(t))‖_H / √h_n, h_n at the first row's q [rad] (module docstring) and, with a push,
    ``posture_deviation`` ‖(I − J⁺ J)(q − q_push)‖ from the posture q_push at its start
    [rad] (0 without), and ``posture_lag_predicted`` ‖Zᵀ H J⁺ ẋ‖ / |K| [rad], ẋ = J q̇: the
    posture error the paper's law through J̄ keeps while the tool moves (:func:`posture_lag`;
    nan for the other laws)."""
    q, tau0 = traces.block("q"), traces.block("tau0_")
    t = traces["t"]
    p = scenario.desired_null_space.posture
    names = arm.joint_names
    q_d0, offset = (np.array([table.get(j, 0.0) for j in names]) for table in (p.q_d, p.offset))
    push = scenario.push
    q_push = q[min(int(np.searchsorted(t, push.start_time)), len(t) - 1)] if push.enabled else None
    context = arm.plant.CreateDefaultContext()
    zero = np.zeros(arm.n)
    h_n = null_space_inertia(arm, q[0])
    v = traces.block("v")
    jbar = (
        scenario.null_space.law == "paper" and scenario.null_space.pseudo_inverse == "dynamically_consistent"
    )
    out = np.zeros((len(traces), 6))
    for k in range(len(traces)):
        terms = arm.terms(context, q[k], zero, coriolis=False)
        H_inv_Jt = terms.H_inv @ terms.J.T
        a = terms.J @ (terms.H_inv @ tau0[k])
        J_pinv = np.linalg.pinv(terms.J)
        e = q[k] - posture_target(q_d0, offset, float(t[k]), float(p.offset_time), float(p.offset_ramp_time))
        d = q[k] - q_push if push.enabled else zero
        null_e, null_d = e - J_pinv @ (terms.J @ e), d - J_pinv @ (terms.J @ d)
        null_e_H = e - H_inv_Jt @ np.linalg.solve(terms.J @ H_inv_Jt, terms.J @ e)  # (I − J̄ J) e
        out[k] = (
            np.linalg.norm(a[: arm.m_t]),
            np.linalg.norm(a[arm.m_t :]),
            *np.linalg.norm([null_e, null_d], axis=1),
            math.sqrt(max(0.0, null_e_H @ terms.H @ null_e_H) / h_n),
            posture_lag(terms, v[k], p.gain) if jbar else math.nan,
        )
    columns = {name: traces[name] for name in traces.names}
    for i, name in enumerate(
        (
            "task_disturbance",
            "task_disturbance_rot",
            "posture_error",
            "posture_deviation",
            "posture_error_H",
            "posture_lag_predicted",
        )
    ):
        columns[name] = out[:, i]
    return Traces(columns)


def posture_lag(terms, v: np.ndarray, K: float) -> float:
    """The posture error the paper's law through J̄ holds while the tool moves at ẋ = J q̇:
    ‖Zᵀ H J⁺ ẋ‖ / |K| [rad]. J̄'s null-space velocity (I − J̄ J) q̇ = q̇ − J̄ ẋ contains
    (I − J̄ J) J⁺ ẋ = Z M_n⁻¹ Zᵀ H J⁺ ẋ, part of the tool's own motion; the velocity loop
    makes it equal q̇_dⁿ = K Z M_n⁻¹ Zᵀ (q − q_d), so in the quasi-static limit (ṡ ≪)
    Zᵀ (q − q_d) = Zᵀ H J⁺ ẋ / K: the inertia M_n cancels. Through J⁺, (I − J⁺ J) J⁺ = 0 and
    the term vanishes."""
    J = terms.J
    Z = np.linalg.svd(J)[2][J.shape[0] :].T
    return float(np.linalg.norm(Z.T @ terms.H @ np.linalg.pinv(J) @ (J @ v)) / abs(K))


def _rms(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x * x))) if x.size else math.nan


def law_figures(traces: Traces, ctx) -> dict:
    """One row of the table (module docstring)."""
    s = ctx.scenario
    t = traces["t"]
    every = max(1, round(RUN_SAMPLE / s.control_period))
    q_run = traces.block("q")[::every] if "q1" in traces else None  # a run's postures, where logged
    row: dict = {
        "law": law_key(s.null_space, s.desired_null_space.posture),
        **loop_figures(s, ctx.arm, q_run),
    }
    k0 = first_contact_index(traces, s.reference.contact_threshold)
    if k0 is None or t[-1] < t[k0] + SETTLE_TIME:
        return {**row, "note": "no contact window (no contact, or the run ends within 0.5 s of it)"}
    window = t >= t[k0] + SETTLE_TIME
    f_err = (traces["f_n"] - traces["f_d"])[window]
    pos_err = np.linalg.norm(
        np.column_stack([traces[a] - traces[f"{a}_d"] for a in traces.task_axes]), axis=1
    )
    row |= {
        "force_error_rms": _rms(f_err),
        "force_error_peak": float(np.abs(f_err).max()),
        "position_error_rms": _rms(pos_err[window]),
        "orientation_error_rms": _rms(traces["rot_err"][window]) if "rot_err" in traces else "",
        "task_disturbance_rms": _rms(traces["task_disturbance"][window]),
        "task_disturbance_peak": float(traces["task_disturbance"][window].max()),
        "posture_error_rms": _rms(traces["posture_error"][window]),
        "posture_error_end": float(traces["posture_error"][-1]),
        "posture_error_H_rms": _rms(traces["posture_error_H"][window]),
        "posture_error_H_end": float(traces["posture_error_H"][-1]),
        "posture_lag_predicted_rms": _rms(traces["posture_lag_predicted"][window])
        if np.isfinite(traces["posture_lag_predicted"][window]).all()
        else "",
        "tau0_rms": _rms(np.linalg.norm(traces.block("tau0_")[window], axis=1)),
        "nu_rms": _rms(traces["nu"][window]) if np.isfinite(traces["nu"][window]).all() else "",
    }
    touched = np.flatnonzero(traces["forbidden_contacts"] > 0)
    if touched.size:  # nothing guards the links here: a law that folds the arm into the plate says so
        row["link_contact_at"] = float(t[touched[0]])
    if s.push.enabled and t[-1] > s.push.start_time:
        row |= push_figures(traces, s.push, pos_err)
    elif s.push.enabled:
        row["note"] = f"the run ends before the push at {s.push.start_time:g} s"
    return row


def push_figures(traces: Traces, push, pos_err: np.ndarray) -> dict:
    """After the push: the largest tool position error (and the error just before it), the
    posture's largest deviation from where the push found it (``posture_deviation``) and
    its return time (module docstring; inf if it has not returned by the end), and how long
    the actuator limits scaled τ₀ down after it."""
    t = traces["t"]
    start = int(np.searchsorted(t, push.start_time))
    after = t >= push.start_time
    deviation = traces["posture_deviation"]
    peak = float(deviation[after].max())
    outside = np.flatnonzero(after & (deviation > RETURN_SHARE * peak))
    returned = outside.size and outside[-1] + 1 < len(t)
    period = float(np.median(np.diff(t)))
    return {
        # how long the actuator limits scaled τ₀ down after the push (s < 1) [s]
        "push_tau0_limited_time": float(np.sum(traces["tau0_scale"][after] < 1.0) * period),
        "push_position_error_peak": float(pos_err[after].max()),
        "push_position_error_before": float(pos_err[max(0, start - 1)]),
        "push_posture_deviation_peak": peak,
        "push_return_time": float(t[outside[-1] + 1] - push.start_time) if returned else math.inf,
    }


# --- the tables ----------------------------------------------------------------------------

# The family's table in parts (issue 45: 28 columns scrolled the variant out of view): the
# loops in table.md, the rest in further tables beside it (NAME/table.md), each headed by
# its columns with their units; the push table has the push rows only. table.csv keeps
# every column. By table: (folder, "" for table.md itself; its columns, (key, unit)).
LAW_TABLES = (
    (
        "",
        (
            ("law", ""),
            ("damping_ratio", ""),
            ("slowest_pole", "rad/s"),
            ("pole_radius_T", ""),
            ("gain_margin", ""),
            ("gain_margin_delay", ""),
            ("damping_ratio_run", ""),
            ("slowest_pole_run", "rad/s"),
            ("gain_margin_run_min", ""),
            ("gain_margin_delay_run_min", ""),
        ),
    ),
    (
        "task",
        (
            ("force_error_rms", "N"),
            ("force_error_peak", "N"),
            ("position_error_rms", "m"),
            ("orientation_error_rms", "rad"),
            ("task_disturbance_rms", "m/s²"),
            ("task_disturbance_peak", "m/s²"),
            ("link_contact_at", "s"),
        ),
    ),
    (
        "posture",
        (
            ("posture_error_rms", "rad"),
            ("posture_error_end", "rad"),
            ("posture_error_H_rms", "rad"),
            ("posture_error_H_end", "rad"),
            ("posture_lag_predicted_rms", "rad"),
            ("tau0_rms", "N m"),
            ("nu_rms", "J"),
        ),
    ),
    (
        "push",
        (
            ("push_tau0_limited_time", "s"),
            ("push_position_error_peak", "m"),
            ("push_position_error_before", "m"),
            ("push_posture_deviation_peak", "rad"),
            ("push_return_time", "s"),
        ),
    ),
)


def table_parts(rows: list[dict]) -> list[tuple[str, list[str], list[dict]]]:
    """The family's rows as :data:`LAW_TABLES`' tables: (folder, header, rows), each row
    keyed by its header (the column with its unit, "slowest_pole [rad/s]"); the variant
    first, and why a variant has no figures ("note", "error") in every table; a table's
    rows are those with at least one of its figures (every row for the first)."""
    parts = []
    for k, (folder, columns) in enumerate(LAW_TABLES):
        why = [key for key in ("note", "error") if any(key in row for row in rows)]
        header = ["variant", *why, *(f"{key} [{unit}]" if unit else key for key, unit in columns)]
        keys = ["variant", *why, *(key for key, _ in columns)]
        mine = [row for row in rows if k == 0 or any(key in row for key, _ in columns)]
        parts.append(
            (
                folder,
                header,
                [{h: row.get(key, "") for h, key in zip(header, keys, strict=True)} for row in mine],
            )
        )
    return parts


# --- the plot ------------------------------------------------------------------------------


def plot_laws(path, family, rows: list[dict], traces: list[Traces]) -> None:
    """Per task (a column; a variant is named "TASK / LAW"), one line per law: the normal
    force's error, the task disturbance ‖J H⁻¹ τ₀‖ (translational) and the posture error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = list(dict.fromkeys(row["variant"].split(" / ")[0] for row in rows))
    fig, axes = plt.subplots(
        3, len(tasks), figsize=(4.2 * len(tasks), 8), squeeze=False, constrained_layout=True
    )
    for row, tr in zip(rows, traces, strict=True):
        task, _, law = row["variant"].partition(" / ")
        column = axes[:, tasks.index(task)]
        t = tr["t"]
        column[0].plot(t, tr["f_n"] - tr["f_d"], lw=0.8, label=law)
        column[1].semilogy(t, np.maximum(tr["task_disturbance"], 1e-12), lw=0.8)
        column[2].plot(t, tr["posture_error"], lw=0.8)
    for j, task in enumerate(tasks):
        axes[0, j].set_title(task, fontsize=9)
        axes[0, j].set_yscale("symlog", linthresh=0.01)  # 10 mN to the hundreds a failed run reaches
        axes[2, j].set_xlabel("time [s]")
    axes[0, 0].set_ylabel(r"force error $f_n - f_d$ [N]")
    axes[1, 0].set_ylabel(r"$\|J H^{-1} \tau_0\|$ [m/s²]")
    axes[2, 0].set_ylabel(r"posture error $\|(I - J^+J)(q - q_d)\|$ [rad]")
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.suptitle(f"{family.name}: force, task disturbance by the null space, posture error", fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_bandwidth(path, family, rows: list[dict]) -> None:
    """Per law (a variant is named "ω rad/s / LAW"), the task disturbance ‖J H⁻¹ τ₀‖ RMS, the
    orientation error RMS and the posture error RMS in joint space and in the inertia metric:
    in the top row against the row's slowest null-space pole (``slowest_pole``, not the
    nominal ω of its name: on the Panda they agree, and the paper's law has its second pole
    at 2ω, so at one slowest pole its loop is the stiffer), in the bottom row against the
    effort it took, ‖τ₀‖ RMS (``tau0_rms``), which puts the laws on an equal footing."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    panels = (
        ("task_disturbance_rms", r"$\|J H^{-1} \tau_0\|$ RMS [m/s²]"),
        ("orientation_error_rms", "orientation error RMS [rad]"),
        ("posture_error_rms", "posture error RMS, joint space [rad]"),
        ("posture_error_H_rms", "posture error RMS, inertia metric [rad]"),
    )
    abscissae = (
        ("slowest_pole", "slowest null-space pole [rad/s]\n(the paper's law: a second pole at 2ω)"),
        ("tau0_rms", r"effort $\|\tau_0\|$ RMS [N m]"),
    )
    fig, axes = plt.subplots(2, len(panels), figsize=(4.2 * len(panels), 7.6), constrained_layout=True)
    laws = list(dict.fromkeys(row["variant"].partition(" / ")[2] for row in rows))
    # the sweep's poles to one digit, once each (79.15 and 80 would print on one another)
    poles = sorted({float(f"{float(row['slowest_pole']):.1g}") for row in rows if "force_error_rms" in row})
    for law in laws:
        mine = [row for row in rows if row["variant"].partition(" / ")[2] == law and "force_error_rms" in row]
        for line, (x_key, _) in zip(axes, abscissae, strict=True):
            x = [float(row[x_key]) for row in mine]
            for ax, (key, _) in zip(line, panels, strict=True):
                plot = ax.loglog if x_key == "slowest_pole" else ax.semilogy  # the effort: one decade
                plot(x, [max(float(row[key]), 1e-18) for row in mine], "o-", lw=1, ms=4, label=law)
    for line, (x_key, x_label) in zip(axes, abscissae, strict=True):
        for ax, (_, label) in zip(line, panels, strict=True):
            ax.set_xlabel(x_label, fontsize=8)
            ax.set_ylabel(label, fontsize=8)
            ax.grid(True, which="both", lw=0.3)
            if x_key == "slowest_pole":  # the sweep's poles, written out (no overlapping labels)
                ax.xaxis.set_major_locator(FixedLocator([p for p in poles if p > 0]))
                ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
                ax.xaxis.set_minor_locator(FixedLocator([]))
                ax.xaxis.set_minor_formatter(NullFormatter())
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.suptitle(
        f"{family.name}: task disturbance and posture error against the slowest null-space pole (top) "
        "and against the effort (bottom)",
        fontsize=9,
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)

"""Issue 19: which null-space law? The figures of ``nsdrake compare null_space_laws``.

The family (``families/null_space_laws.yaml``) runs each law of
:mod:`nsdrake.control.null_space_laws` on each task with the same task impedance and the
same secondary objective, a posture q_d. Its gains are matched here (:func:`matched_gains`)
so that every law has the same null-space natural frequency ω = K_n / 2 (critical damping
for the paper's velocity loop of gain K_n), with h_n the null-space inertia at the start
posture (:func:`null_space_inertia`):

- paper, J̄ (Eq. 30 on p = ½‖q − q_d‖², W = I): ω² = K_n |K| / h_n, so K = −ω² h_n / K_n;
- paper, J⁺ (no H⁻¹ in Eq. 28's step): ω² = K_n |K|, so K = −ω² / K_n;
- dynamically consistent posture PD (acceleration units): K_ns = ω², D_ns = 2 ω = K_n;
- kinematic posture PD (torque units): K_ns = ω² h_n [N m/rad]; its damping is 2 √K_ns by
  its form, a damping ratio ζ = 1 / √h_n (h_n in kg m²), not 1.

With a one-dimensional null space (the Panda's pose task) h_n = zᵀ H z, z the unit
null-space direction, and the match is exact at the start posture; with more (fig3's arm,
two) h_n is the geometric mean of the eigenvalues of Zᵀ H Z, and the laws' stiffness
differs by direction (the PD law in acceleration units is the same in every direction,
the others scale with the inverse null-space inertia).

The figures (:func:`law_figures`), from the traces and the arm's model only, the same
for every law:

- force error f_n − f_d and the tool's position and orientation error in the window
  (from first contact + :data:`~nsdrake.reporting.metrics.SETTLE_TIME` to the end);
- the task disturbance by the null space, J H⁻¹ τ₀ (τ₀ the applied null-space torque,
  logged: ``report.null_space_torque``), its translational part [m/s²];
- the elbow's drift: the posture error ‖(I − J⁺ J)(q − q_d(t))‖, the part of q − q_d the
  self-motion can remove (orthogonal projector, the same metric for every law);
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

RETURN_SHARE = 0.05  # the posture has returned once its deviation stays within this share of its peak


def null_space_inertia(arm, q: np.ndarray) -> float:
    """h_n at q: the geometric mean of the eigenvalues of Zᵀ H Z, Z an orthonormal basis of
    the null space of J (module docstring) [kg m²]."""
    terms = arm.terms(arm.plant.CreateDefaultContext(), q, np.zeros(arm.n), coriolis=False)
    _, _, Vt = np.linalg.svd(terms.J)
    Z = Vt[terms.J.shape[0] :].T
    return float(np.linalg.det(Z.T @ terms.H @ Z) ** (1.0 / Z.shape[1]))


def matched_gains(h_n: float, K_n: float) -> dict[str, dict]:
    """The gains of each law for the natural frequency ω = K_n / 2 (module docstring), by
    the family's law names."""
    omega2 = (K_n / 2.0) ** 2
    return {
        "paper": {"gain": -omega2 * h_n / K_n},
        "paper_moore_penrose": {"gain": -omega2 / K_n},
        "kinematic_posture_pd": {"posture_stiffness": omega2 * h_n},
        "dynamically_consistent_posture_pd": {"posture_stiffness": omega2, "posture_damping": K_n},
    }


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
    ``posture_error`` ‖(I − J⁺ J)(q − q_d(t))‖ [rad] (module docstring) and, with a push,
    ``posture_deviation`` ‖(I − J⁺ J)(q − q_push)‖ from the posture q_push at its start
    [rad] (0 without)."""
    q, tau0 = traces.block("q"), traces.block("tau0_")
    t = traces["t"]
    p = scenario.desired_null_space.posture
    names = arm.joint_names
    q_d0, offset = (np.array([table.get(j, 0.0) for j in names]) for table in (p.q_d, p.offset))
    push = scenario.push
    q_push = q[min(int(np.searchsorted(t, push.start_time)), len(t) - 1)] if push.enabled else None
    context = arm.plant.CreateDefaultContext()
    zero = np.zeros(arm.n)
    out = np.zeros((len(traces), 4))
    for k in range(len(traces)):
        terms = arm.terms(context, q[k], zero, coriolis=False)
        a = terms.J @ (terms.H_inv @ tau0[k])
        J_pinv = np.linalg.pinv(terms.J)
        e = q[k] - posture_target(q_d0, offset, t[k], p.offset_time, p.offset_ramp_time)
        d = q[k] - q_push if push.enabled else zero
        null_e, null_d = e - J_pinv @ (terms.J @ e), d - J_pinv @ (terms.J @ d)
        out[k] = (
            np.linalg.norm(a[: arm.m_t]),
            np.linalg.norm(a[arm.m_t :]),
            *np.linalg.norm([null_e, null_d], axis=1),
        )
    columns = {name: traces[name] for name in traces.names}
    for i, name in enumerate(
        ("task_disturbance", "task_disturbance_rot", "posture_error", "posture_deviation")
    ):
        columns[name] = out[:, i]
    return Traces(columns)


def law_name(scenario) -> str:
    ns = scenario.null_space
    if ns.law == "paper":
        return "paper" if ns.pseudo_inverse == "dynamically_consistent" else f"paper ({ns.pseudo_inverse})"
    return ns.law


def _rms(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x * x))) if x.size else math.nan


def law_figures(traces: Traces, ctx) -> dict:
    """One row of the table (module docstring)."""
    s = ctx.scenario
    t = traces["t"]
    row: dict = {"law": law_name(s)}
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
    fig.suptitle(f"{family.name}: force, task disturbance by the null space, elbow drift", fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)

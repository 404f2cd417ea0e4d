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

RETURN_SHARE = 0.05  # the posture has returned once its deviation stays within this share of its peak


def null_space_masses(arm, q: np.ndarray) -> np.ndarray:
    """The eigenvalues μ_i of M_n = Zᵀ H Z at q, Z an orthonormal basis of the null space of J
    (module docstring), ascending [kg m²]."""
    terms = arm.terms(arm.plant.CreateDefaultContext(), q, np.zeros(arm.n), coriolis=False)
    _, _, Vt = np.linalg.svd(terms.J)
    Z = Vt[terms.J.shape[0] :].T
    return np.linalg.eigvalsh(Z.T @ terms.H @ Z)


def null_space_inertia(arm, q: np.ndarray) -> float:
    """h_n at q: the geometric mean of the μ_i (:func:`null_space_masses`) [kg m²]."""
    mu = null_space_masses(arm, q)
    return float(np.exp(np.mean(np.log(mu))))


# The rows of the families, by key: (law, pseudo-inverse or λ) as the configuration writes them.
LAW_KEYS = (
    "paper",
    "paper_moore_penrose",
    "kinematic_posture_pd",
    "kinematic_posture_pd_damped",
    "dynamically_consistent_posture_pd",
    "dynamically_consistent_torque_pd",
)
FRANKA_ROS_LAMBDA = 0.2  # λ of franka_ros's Cartesian impedance example's damped (Jᵀ)⁺


def tuned_gains(law: str, omega: float, h_n: float) -> dict[str, float]:
    """The rule (module docstring): the gains of ``law`` (one of :data:`LAW_KEYS`) for the
    null-space bandwidth ω [rad/s] at the null-space inertia h_n [kg m²], by configuration
    field: ``gain`` (Eq. 30's K), ``K_n``, ``posture_stiffness``, ``posture_damping``,
    ``projector_damping``."""
    if law == "paper":
        return {"gain": -omega * h_n, "K_n": 2.0 * omega}
    if law == "paper_moore_penrose":
        return {"gain": -omega, "K_n": 2.0 * omega}
    if law == "dynamically_consistent_posture_pd":
        return {"posture_stiffness": omega**2, "posture_damping": 2.0 * omega}
    torque = {"posture_stiffness": omega**2 * h_n, "posture_damping": 2.0 * omega * h_n}
    if law == "kinematic_posture_pd_damped":
        return {**torque, "projector_damping": FRANKA_ROS_LAMBDA}
    if law in ("kinematic_posture_pd", "dynamically_consistent_torque_pd"):
        return torque
    raise ValueError(f"unknown law {law!r}; the laws are {', '.join(LAW_KEYS)}")


def paper_poles_gains(omega: float, h_n: float) -> dict[str, float]:
    """The torque PD (dynamically consistent or kinematic) with the paper's law's poles under
    the rule, −ω and −2ω where μ = h_n: μ s̈ + D ṡ + K s = μ (s + ω)(s + 2ω), so
    K_ns = 2 ω² h_n, D_ns = 3 ω h_n (twice the rule's stiffness, 1.5 × its damping)."""
    return {"posture_stiffness": 2.0 * omega**2 * h_n, "posture_damping": 3.0 * omega * h_n}


# Gains as two libraries ship them (not the rule): the variants "… franka_ros's initial gains" and
# "… robosuite's gains" of null_space_laws.
# franka_ros, franka_example_controllers CartesianImpedanceExampleController: the null-space
# stiffness starts at 20 (nullspace_stiffness_{20.0} in its header), damping 2√K, through
# the damped (Jᵀ)⁺ with λ = 0.2 (FRANKA_ROS_LAMBDA); its dynamic_reconfigure default
# (cfg/compliance_param.cfg) is 0, which switches the posture off once the reconfigure
# server's first call has been filtered in.
FRANKA_ROS_GAINS = {
    "posture_stiffness": 20.0,
    "posture_damping": 2.0 * math.sqrt(20.0),
    "projector_damping": FRANKA_ROS_LAMBDA,
}
# robosuite, utils/control_utils.py nullspace_torques (its OSC controllers): joint_kp = 10,
# joint_kv = 2√joint_kp, multiplied by H and projected by (I − J̄ J)ᵀ: the H-weighted PD.
ROBOSUITE_GAINS = {"posture_stiffness": 10.0, "posture_damping": 2.0 * math.sqrt(10.0)}


def law_key(null_space, posture) -> str:
    """The :data:`LAW_KEYS` entry of a configuration (``null_space``, ``desired_null_space.posture``)."""
    if null_space.law == "paper":
        return "paper" if null_space.pseudo_inverse == "dynamically_consistent" else "paper_moore_penrose"
    if null_space.law == "kinematic_posture_pd" and null_space.projector_damping > 0:
        return "kinematic_posture_pd_damped"
    return null_space.law


# Two loops beside the laws' null-space loops, for a run's report (nsdrake/reporting/loops.py):
# a task axis under the impedance law, ẍ = −K_p x − K_v ẋ (Eq. 10 with an exact model: each
# task direction a unit mass, as the H-weighted posture PD's null-space directions), and the
# paper's null-space velocity loop ėⁿ = −K_n eⁿ where q̇_dⁿ does not depend on the posture
# (criteria, sweep), a first-order loop.
TASK_AXIS = "task_axis"
VELOCITY_LOOP = "velocity_loop"
UNIT_MASS_LAWS = ("dynamically_consistent_posture_pd", TASK_AXIS)


def _loop_parts(law: str, gains: dict, mu: float, T: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The null-space loop along a direction of inertia μ (module docstring), sampled at T,
    as (Φ, Γ, F): x_{k+1} = Φ x_k + Γ u with u the acceleration held over the period, and
    the law's acceleration computed from the sample x_k, u_k = F x_k. The state is (s, ṡ)
    for the PD laws, (s, ṡ, ṡ_d of the previous period) for the paper's (its feedforward
    q̈_dⁿ is the backward difference of q̇_dⁿ; Φ's last row stores ṡ_d,k = −a s_k)."""
    if law.startswith("paper"):
        a = abs(gains["gain"]) / (mu if law == "paper" else 1.0)
        K_n = gains["K_n"]
        Phi = np.zeros((3, 3))
        Phi[:2, :2] = [[1.0, T], [0.0, 1.0]]
        Phi[2, 0] = -a
        # acc_k = (ṡ_d,k − ṡ_d,k−1)/T + K_n (ṡ_d,k − ṡ_k), ṡ_d,k = −a s_k
        return Phi, np.array([T * T / 2.0, T, 0.0]), np.array([-a / T - K_n * a, -K_n, -1.0 / T])
    if law == VELOCITY_LOOP:  # ėⁿ = −K_n eⁿ: state eⁿ, acceleration −K_n eⁿ
        return np.array([[1.0]]), np.array([T]), np.array([-gains["K_n"]])
    K, D = gains["posture_stiffness"], gains["posture_damping"]
    scale = 1.0 if law in UNIT_MASS_LAWS else 1.0 / mu
    return np.array([[1.0, T], [0.0, 1.0]]), np.array([T * T / 2.0, T]), np.array([-K * scale, -D * scale])


def _sampled_loop(law: str, gains: dict, mu: float, T: float, g: float = 1.0, delay: int = 0) -> np.ndarray:
    """The transition matrix over one period T of the null-space loop along a direction of
    inertia μ (:func:`_loop_parts`), the acceleration held over the period. ``g`` multiplies
    the acceleration the torque produces (the loop gain: an arm whose null-space inertia is
    μ/g where the law assumes μ, or whose torque is g times the commanded). ``delay``: 0, the
    acceleration computed from the sample at t_k is applied over [t_k, t_{k+1}); 1, over
    [t_{k+1}, t_{k+2}), as ``realism.delay`` (one period) and a drive that answers status k
    with the command the robot applies at k + 1 run it: the state then carries the pending
    acceleration u_{k−1}, x_{k+1} = Φ x_k + g Γ u_{k−1}, u_k = F x_k."""
    Phi, Gamma, F = _loop_parts(law, gains, mu, T)
    if delay == 0:
        return Phi + g * np.outer(Gamma, F)
    if delay != 1:
        raise ValueError(f"delay must be 0 or 1 period, got {delay!r}")
    n = len(Gamma)
    A = np.zeros((n + 1, n + 1))
    A[:n, :n], A[:n, n], A[n, :n] = Phi, g * Gamma, F
    return A


def _continuous_poles(law: str, gains: dict, mu: float) -> np.ndarray:
    """The null-space loop's poles along a direction of inertia μ (module docstring)."""
    if law.startswith("paper"):
        a = abs(gains["gain"]) / (mu if law == "paper" else 1.0)
        return np.array([-a, -gains["K_n"]], dtype=complex)
    if law == VELOCITY_LOOP:
        return np.array([-gains["K_n"]], dtype=complex)
    K, D = gains["posture_stiffness"], gains["posture_damping"]
    scale = 1.0 if law in UNIT_MASS_LAWS else 1.0 / mu
    return np.roots([1.0, D * scale, K * scale]).astype(complex)


def damping_ratio(poles: np.ndarray) -> float:
    """ζ of a pair of poles: −(p₁ + p₂) / (2 √(p₁ p₂)) (1 for a double pole, > 1 real);
    nan for a first-order loop (one pole: no ζ)."""
    if len(poles) == 1:
        return math.nan
    p1, p2 = poles
    return float((-(p1 + p2) / (2.0 * np.sqrt(p1 * p2))).real)


def _pole_radius(law: str, gains: dict, mu: float, period: float, g: float = 1.0, delay: int = 0) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(_sampled_loop(law, gains, mu, period, g, delay)))))


GAIN_MARGIN_MAX = 1e4  # the search's end: a margin beyond it is reported as this


def gain_margin(law: str, gains: dict, mu: float, period: float, delay: int = 0) -> float:
    """The loop's gain margin along a direction of inertia μ: the factor g by which the
    acceleration its torque produces may grow (:func:`_sampled_loop`) before the sampled
    loop's pole radius reaches 1 (< 1 where the loop is unstable as tuned); ``delay`` 1 for
    the loop with one period of computation delay (:func:`_sampled_loop`). Found on a
    logarithmic grid, then by bisection to 1e-6 relative; :data:`GAIN_MARGIN_MAX` where the
    loop stays stable up to it. For a PD held over the period without delay the Jury test
    gives it in closed form, 2μ/(D T) where K T < 2 D (2/(D T) for the H-weighted PD;
    tests/studies/test_null_space_laws_family.py)."""

    def stable(g: float) -> bool:
        return _pole_radius(law, gains, mu, period, g, delay) < 1.0

    if not stable(1.0):
        low, high = 0.0, 1.0
    else:
        low, high = 1.0, None
        for g in np.geomspace(1.0, GAIN_MARGIN_MAX, 161)[1:]:
            if not stable(float(g)):
                high = float(g)
                break
            low = float(g)
        if high is None:
            return GAIN_MARGIN_MAX
    while high - low > 1e-6 * high:
        middle = 0.5 * (low + high)
        low, high = (middle, high) if stable(middle) else (low, middle)
    return 0.5 * (low + high)


def null_space_loop(law: str, gains: dict, masses: np.ndarray, period: float) -> dict:
    """The row's loop figures over the null-space directions of inertias ``masses``: the
    damping ratios' range, the slowest pole's rate [rad/s], the largest discrete-time pole
    radius ρ_T at the control period (< 1: stable; module docstring) and the smallest gain
    margin (:func:`gain_margin`), without and with one period of computation delay."""
    zetas, slow, rho, margin, delayed = [], math.inf, 0.0, math.inf, math.inf
    for mu in masses:
        poles = _continuous_poles(law, gains, float(mu))
        zetas.append(damping_ratio(poles))
        slow = min(slow, float(np.min(-poles.real)))
        rho = max(rho, _pole_radius(law, gains, float(mu), period))
        margin = min(margin, gain_margin(law, gains, float(mu), period))
        delayed = min(delayed, gain_margin(law, gains, float(mu), period, delay=1))
    return {
        "zeta_min": min(zetas),
        "zeta_max": max(zetas),
        "slowest_pole": slow,
        "pole_radius": rho,
        "gain_margin": margin,
        "gain_margin_delay": delayed,
    }


def loop_along_run(law: str, gains: dict, arm, q: np.ndarray, period: float) -> dict:
    """:func:`null_space_loop` at each posture of ``q`` (rows of a run's traces): the range
    over the run of the damping ratio and of the slowest pole, and the smallest gain
    margins (without and with a period's delay). The null-space inertias change with the
    posture (the start's figures hold there only)."""
    loops = [null_space_loop(law, gains, null_space_masses(arm, qk), period) for qk in q]
    return {
        "zeta_min": min(lp["zeta_min"] for lp in loops),
        "zeta_max": max(lp["zeta_max"] for lp in loops),
        "slowest_pole_min": min(lp["slowest_pole"] for lp in loops),
        "slowest_pole_max": max(lp["slowest_pole"] for lp in loops),
        "gain_margin_min": min(lp["gain_margin"] for lp in loops),
        "gain_margin_delay_min": min(lp["gain_margin_delay"] for lp in loops),
    }


def row_gains(scenario) -> dict[str, float]:
    """The gains :func:`tuned_gains` names, as ``scenario`` sets them."""
    ns = scenario.null_space
    return {
        "gain": scenario.desired_null_space.posture.gain,
        "K_n": ns.K_n,
        "posture_stiffness": ns.posture_stiffness,
        "posture_damping": ns.posture_damping,
        "projector_damping": ns.projector_damping,
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


def _span(low: float, high: float) -> str:
    """A range as the table prints it (3 digits): one figure where both ends print alike."""
    low_text, high_text = f"{low:.3g}", f"{high:.3g}"
    return low_text if low_text == high_text else f"{low_text}–{high_text}"


RUN_SAMPLE = 0.01  # [s] the postures of a run at which its loop is evaluated (loop_along_run)


def loop_figures(scenario, arm, q_run: np.ndarray | None = None) -> dict:
    """The row's null-space loop from its own gains and period (:func:`null_space_loop`)
    at the start posture: damping ratio, slowest pole, pole radius ρ_T, gain margin without
    and with a period's delay; and
    with the run's postures ``q_run``, the same along the run (:func:`loop_along_run`)."""
    key = law_key(scenario.null_space, scenario.desired_null_space.posture)
    q0 = np.array([scenario.arm.initial_positions[j] for j in arm.joint_names])
    gains, T = row_gains(scenario), scenario.control_period
    loop = null_space_loop(key, gains, null_space_masses(arm, q0), T)
    row = {
        "damping_ratio": _span(loop["zeta_min"], loop["zeta_max"]),
        "slowest_pole": loop["slowest_pole"],
        "pole_radius_T": loop["pole_radius"],
        "gain_margin": loop["gain_margin"],
        "gain_margin_delay": loop["gain_margin_delay"],
    }
    if q_run is not None and len(q_run):
        run = loop_along_run(key, gains, arm, q_run, T)
        row |= {
            "damping_ratio_run": _span(run["zeta_min"], run["zeta_max"]),
            "slowest_pole_run": _span(run["slowest_pole_min"], run["slowest_pole_max"]),
            "gain_margin_run_min": run["gain_margin_min"],
            "gain_margin_delay_run_min": run["gain_margin_delay_min"],
        }
    return row


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

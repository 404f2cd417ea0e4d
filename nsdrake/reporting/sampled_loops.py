"""The null-space and task loops of a control law as sampled loops: damping ratio, poles,
pole radius and gain margin, without and with one period of computation delay (the loop
``realism.delay`` and the drive run). The study :mod:`nsdrake.studies.null_space_laws`
tabulates them per law; a run's report (:mod:`nsdrake.reporting.loops`) shows them for the
run's own controller. The laws and their loops are described in that study's docstring."""

from __future__ import annotations

import math

import numpy as np


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

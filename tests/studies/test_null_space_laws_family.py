"""``nsdrake compare null_space_laws`` (issue 19): the family's set-up and a short run.

The full family (four tasks, about 50 s simulated per law) runs from the command line
(README, "Which null-space law?"); here its gains are checked against the matching rule
of nsdrake.studies.null_space_laws, and one task, shortened, runs end to end.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import panda_arm, paper_arm
from reference_math import dynamically_consistent_inverse
from scipy.signal import cont2discrete

from nsdrake.control.null_space_laws import (
    dynamically_consistent_posture_torque,
    dynamically_consistent_torque_pd,
    kinematic_posture_torque,
)
from nsdrake.experiment.diagram import build_diagram
from nsdrake.experiment.scenario import ScenarioError
from nsdrake.studies.compare import load_family, run_family, variant_scenario
from nsdrake.studies.null_space_laws import (
    FRANKA_ROS_GAINS,
    LAW_KEYS,
    LAW_TABLES,
    ROBOSUITE_GAINS,
    _continuous_poles,
    damping_ratio,
    gain_margin,
    law_key,
    loop_along_run,
    null_space_inertia,
    null_space_loop,
    null_space_masses,
    paper_poles_gains,
    row_gains,
    table_parts,
    tuned_gains,
)

LAWS = (
    "paper",
    "paper, Moore-Penrose",
    "kinematic PD",
    "kinematic PD, damped inverse",
    "dyn. consistent PD (H)",
    "dyn. consistent PD (torque)",
)
TASKS = ["panda_wipe", "panda_self_motion", "panda_off_path", "fig3", "push"]
# the rows beside the rule's (referee, issue 38), on panda_wipe and panda_self_motion
EXTRAS = {
    "dyn. consistent PD (torque), the paper's poles": "paper_poles",
    "kinematic PD, damped inverse, franka_ros's initial gains": "franka_ros",
    "dyn. consistent PD (H), robosuite's gains": "robosuite",
}


def test_every_task_runs_every_law():
    family = load_family("null_space_laws")
    names = [v.name.split(" / ") for v in family.variants]
    tasks = list(dict.fromkeys(task for task, _ in names))
    assert tasks == TASKS
    extra = [(t, law) for t in ("panda_wipe", "panda_self_motion") for law in EXTRAS]
    assert sorted(map(tuple, names)) == sorted([(t, law) for t in tasks for law in LAWS] + extra)


def _expected_gains(name: str, variant, h_n: float) -> dict[str, float]:
    """The gains a variant should have: the rule's, or an extra row's own (EXTRAS)."""
    law = variant.name.split(" / ")[1]
    if law in EXTRAS:
        return {
            "paper_poles": paper_poles_gains(_bandwidth(name, variant), h_n),
            "franka_ros": FRANKA_ROS_GAINS,
            "robosuite": ROBOSUITE_GAINS,
        }[EXTRAS[law]]
    return None


def test_the_extra_rows_gains_are_their_sources():
    """The torque PD at the paper's poles has μ s² + D s + K = μ (s + ω)(s + 2ω) at μ = h_n
    (catches a pole pair that is not the paper's, e.g. the rule's double pole). The two
    libraries' gains are transcribed, not derived, and this test only pins them to the
    sources' words so that an edit is seen: frankaemika/franka_ros,
    franka_example_controllers/include/.../cartesian_impedance_example_controller.h
    (nullspace_stiffness_{20.0}), its .cpp (damping (2.0 * sqrt(nullspace_stiffness_))) and
    franka_example_controllers/include/.../pseudo_inversion.h (λ 0.2); ARISE-Initiative/
    robosuite, robosuite/utils/control_utils.py nullspace_torques (joint_kp=10, joint_kv =
    np.sqrt(joint_kp) * 2, multiplied by the mass matrix)."""
    h_n, omega = 0.0263, 20.0
    g = paper_poles_gains(omega, h_n)
    poles = np.sort(np.roots([h_n, g["posture_damping"], g["posture_stiffness"]]).real)
    np.testing.assert_allclose(poles, [-2 * omega, -omega], rtol=1e-12)
    assert FRANKA_ROS_GAINS == {
        "posture_stiffness": 20.0,
        "posture_damping": 2 * 20**0.5,
        "projector_damping": 0.2,
    }
    assert ROBOSUITE_GAINS == {"posture_stiffness": 10.0, "posture_damping": 2 * 10**0.5}


def _bandwidth(family_name: str, variant) -> float:
    if family_name == "null_space_bandwidth":
        return float(variant.name.split(" rad/s")[0])
    return 50.0 if variant.scenario == "fig3" else 20.0  # the scenarios' K_n / 2


@pytest.mark.parametrize("name", ["null_space_laws", "null_space_bandwidth"])
def test_the_gains_follow_the_tuning_rule(name):
    """Each variant's gains are tuned_gains(its law, its bandwidth, h_n at the start posture)
    to the 4 significant digits the family file writes, and every law has the same q_d: the
    start posture. Catches a family file edited by hand or written from another rule."""
    family = load_family(name)
    inertia = {}
    for i, variant in enumerate(family.variants):
        s = variant_scenario(family, i, None, 0.01)
        if variant.scenario not in inertia:
            station = build_diagram(s).station
            inertia[variant.scenario] = null_space_inertia(station.arm_model, station.q0)
        assert s.desired_null_space.posture.q_d == pytest.approx(dict(s.arm.initial_positions), abs=5e-4)
        key = law_key(s.null_space, s.desired_null_space.posture)
        given = row_gains(s)
        h_n = inertia[variant.scenario]
        expected = _expected_gains(name, variant, h_n) or tuned_gains(key, _bandwidth(name, variant), h_n)
        for field, value in expected.items():
            assert given[field] == pytest.approx(value, rel=5e-4), (variant.name, field)


def _constrained_poles(arm, q_star, torque, eps=1e-6) -> np.ndarray:
    """The poles of the null-space motion with the task held exactly: q = q* + Z s, q̇ = Z ṡ,
    s̈ = Zᵀ (I − J̄ J) H⁻¹ τ₀(q, q̇) (the constrained acceleration), linearised by central
    differences at s = ṡ = 0; ``torque(T, q, v)`` gives τ₀ with the terms T at q."""
    context = arm.plant.CreateDefaultContext()
    J = arm.terms(context, q_star, np.zeros(arm.n), coriolis=False).J
    Z = np.linalg.svd(J)[2][J.shape[0] :].T
    r = Z.shape[1]

    def sdd(x):
        q, v = q_star + Z @ x[:r], Z @ x[r:]
        T = arm.terms(context, q, v, coriolis=False)
        J_bar = dynamically_consistent_inverse(T.J, T.H_inv)
        return Z.T @ ((np.eye(arm.n) - J_bar @ T.J) @ (T.H_inv @ torque(T, q, v)))

    B = np.column_stack([(sdd(eps * e) - sdd(-eps * e)) / (2 * eps) for e in np.eye(2 * r)])
    A = np.block([[np.zeros((r, r)), np.eye(r)], [B]])
    return np.sort_complex(np.linalg.eigvals(A))


def _paper_torque(K, K_n):
    """Eq. 21 with Eq. 30's step on p = ½‖q − q_d‖² through J̄, written here in continuous
    time: τ₀ = H N̄ (q̈_dⁿ + K_n (q̇_dⁿ − q̇)), q̇_dⁿ = K N̄ H⁻¹ (q − q_d), q̈_dⁿ = K N̄ H⁻¹ q̇ (its
    derivative where q = q_d, where the linearisation is taken)."""

    def torque(T, q, v, q_d):
        N_bar = np.eye(len(q)) - dynamically_consistent_inverse(T.J, T.H_inv) @ T.J
        qdot = K * N_bar @ T.H_inv @ (q - q_d)
        qddot = K * N_bar @ T.H_inv @ v
        return T.H @ N_bar @ (qddot + K_n * (qdot - v))

    return torque


@pytest.mark.parametrize("arm_name", ["panda", "arm4"])
@pytest.mark.parametrize("law", ["paper", *LAW_KEYS[2:]])
def test_the_rules_poles_are_the_closed_loop_poles(arm_name, law):
    """The poles the rule predicts per null-space direction (:func:`_continuous_poles`, with
    μ_i the eigenvalues of Zᵀ H Z), hence its damping ratios, against the eigenvalues of the
    linearised null-space motion under each law's torque (the shipped law functions; the
    paper's law written above), on the Panda (one direction) and on fig3's arm (two), to
    1e-4. Catches a rule with the wrong inertia (h_n where H cancels, or none where it does
    not), a paper's-law pole without the feedforward's zero, or 2√K-style damping."""
    arm = panda_arm() if arm_name == "panda" else paper_arm()
    q_star = (
        np.array([0.0, 0.182, 0.0, -2.4, 0.0, 2.582, 0.785])
        if arm_name == "panda"
        else np.array([0.401, 0.972, 1.012, 0.614])
    )
    omega = 20.0
    masses = null_space_masses(arm, q_star)
    h_n = null_space_inertia(arm, q_star)
    g = tuned_gains(law, omega, h_n)
    K, D = g.get("posture_stiffness"), g.get("posture_damping")
    lam = g.get("projector_damping", 0.0)
    torque = {
        "paper": lambda T, q, v: _paper_torque(g.get("gain"), g.get("K_n"))(T, q, v, q_star),
        "kinematic_posture_pd": lambda T, q, v: kinematic_posture_torque(T.J, q, v, q_star, K, D, 0.0),
        "kinematic_posture_pd_damped": lambda T, q, v: kinematic_posture_torque(T.J, q, v, q_star, K, D, lam),
        "dynamically_consistent_posture_pd": lambda T, q, v: dynamically_consistent_posture_torque(
            T.H, T.H_inv, T.J, q, v, q_star, K, D
        ),
        "dynamically_consistent_torque_pd": lambda T, q, v: dynamically_consistent_torque_pd(
            T.H_inv, T.J, q, v, q_star, K, D
        ),
    }[law]
    measured = _constrained_poles(arm, q_star, torque)
    predicted = np.sort_complex(np.concatenate([_continuous_poles(law, g, mu) for mu in masses]))
    np.testing.assert_allclose(measured, predicted, rtol=1e-4, atol=1e-4 * omega)
    if len(masses) == 1:  # one direction: the rule's design point
        assert damping_ratio(predicted) == pytest.approx(
            1.0 if law != "paper" else 3 / (2 * np.sqrt(2)), rel=1e-9
        )
        assert float(np.min(-predicted.real)) == pytest.approx(omega, rel=1e-6)


def _scipy_sampled_loop(law: str, g: dict, mu: float, T: float, gain: float = 1.0) -> np.ndarray:
    """The law's null-space loop sampled at T, built with SciPy: the plant s̈ = u/μ
    discretised with a zero-order hold (cont2discrete), the law's torque computed from the
    samples (the paper's with its backward-difference feedforward, one more state), the
    plant's input scaled by ``gain``."""
    Ad, Bd, *_ = cont2discrete(
        (np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), np.eye(2), np.zeros((2, 1))),
        T,
        method="zoh",
    )
    if law.startswith("paper"):
        a = abs(g["gain"]) / (mu if law == "paper" else 1.0)
        # state (s, ṡ, ṡ_d previous); u = (ṡ_d − ṡ_d,prev)/T + K_n (ṡ_d − ṡ), ṡ_d = −a s
        F = np.array([[-a / T - g["K_n"] * a, -g["K_n"], -1.0 / T]])
        A = np.zeros((3, 3))
        A[:2, :] = np.hstack([Ad, np.zeros((2, 1))]) + gain * (Bd @ F)
        A[2, 0] = -a
        return A
    scale = 1.0 if law == "dynamically_consistent_posture_pd" else 1.0 / mu  # what τ₀ does per unit
    return Ad + gain * (Bd @ (scale * np.array([[-g["posture_stiffness"], -g["posture_damping"]]])))


@pytest.mark.parametrize(
    "law", ["paper", "paper_moore_penrose", "kinematic_posture_pd", "dynamically_consistent_posture_pd"]
)
@pytest.mark.parametrize(
    "omega, mu, T", [(20.0, 0.026, 0.001), (50.0, 0.0018, 0.002), (400.0, 0.0018, 0.004)]
)
def test_the_discrete_pole_radius_is_the_sampled_loops(law, omega, mu, T):
    """ρ_T of :func:`null_space_loop` against the sampled loop built with SciPy
    (:func:`_scipy_sampled_loop`), to 1e-9. The last case is unstable for some laws (ρ > 1),
    so the test also sees the radius cross 1. Catches a hold formula off by the T²/2 term or
    a feedforward that uses the current instead of the previous sample."""
    g = tuned_gains(law, omega, 0.026)
    expected = np.max(np.abs(np.linalg.eigvals(_scipy_sampled_loop(law, g, mu, T))))
    got = null_space_loop(law, g, np.array([mu]), T)["pole_radius"]
    assert got == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("law", ["kinematic_posture_pd", "dynamically_consistent_posture_pd"])
@pytest.mark.parametrize("omega, mu, T", [(20.0, 0.026, 0.001), (50.0, 0.0018, 0.002), (5.0, 0.05, 0.001)])
def test_a_pds_gain_margin_is_the_jury_bound(law, omega, mu, T):
    """A PD held over the period, acceleration g (−k s − d ṡ): its characteristic
    polynomial z² − (2 − g k T²/2 − g d T) z + (1 − g d T + g k T²/2) is stable (Jury) iff
    k T < 2 d and g d T < 2, so the margin is 2/(d T), d = D/μ (D for the H-weighted PD),
    where k T < 2 d holds (it does for every row here): 1/(ωT) = 50 for the Panda's rule
    (d = 2ω = 40 rad/s, T = 1 ms). Catches a margin read off the wrong crossing, a
    scale on K only, or a bisection that stops early (to 1e-5)."""
    g = tuned_gains(law, omega, 0.026)
    d = g["posture_damping"] / (1.0 if law == "dynamically_consistent_posture_pd" else mu)
    k = g["posture_stiffness"] / (1.0 if law == "dynamically_consistent_posture_pd" else mu)
    assert k * T < 2 * d
    assert gain_margin(law, g, mu, T) == pytest.approx(2.0 / (d * T), rel=1e-5)


@pytest.mark.parametrize("law", ["paper", "paper_moore_penrose"])
def test_the_papers_gain_margin_is_where_scipys_sampled_loop_turns_unstable(law):
    """The paper's loop (3 states, its backward-difference feedforward), rebuilt with SciPy's
    zero-order hold as the pole-radius test does, with the plant's input scaled by g: stable
    just below the margin :func:`gain_margin` reports (g × 0.999) and unstable just above it
    (× 1.001), on the Panda's rule (ω = 20 rad/s, μ = h_n) and on a light direction at a 4 ms
    period (the J̄ law unstable there as tuned: a margin below 1); stable on a grid of every
    gain below it; and the law's difference equations (ṡ_d = −a s, the backward-difference
    feed-forward, the torque held over the period), stepped 20 000 periods, decay at
    0.98 × the margin and grow at 1.02 ×. Catches a margin of another loop, or one that is
    not the first crossing."""
    h_n = 0.026
    for omega, mu, T in ((20.0, h_n, 0.001), (50.0, 0.0018, 0.004)):
        g = tuned_gains(law, omega, h_n)
        margin = gain_margin(law, g, mu, T)
        a = abs(g["gain"]) / (mu if law == "paper" else 1.0)

        def radius(gain, g=g, mu=mu, T=T):
            return np.max(np.abs(np.linalg.eigvals(_scipy_sampled_loop(law, g, mu, T, gain))))

        assert 0.0 < margin < 1e4 and (margin > 1.0) == (radius(1.0) < 1.0)
        assert radius(0.999 * margin) < 1.0 < radius(1.001 * margin), (omega, margin)
        # the first crossing: stable everywhere below it
        assert all(radius(x) < 1.0 for x in np.linspace(0.001, 0.999, 400) * margin)
        # and the law's own difference equations, stepped, decay below it and grow above
        for factor, grows in ((0.98, False), (1.02, True)):
            s, v, sd_prev = 1e-3, 0.0, -a * 1e-3  # at rest before the first period
            for _ in range(20000):
                sd = -a * s  # ṡ_d = −a s
                acc = factor * margin * ((sd - sd_prev) / T + g["K_n"] * (sd - v))
                s, v, sd_prev = s + T * v + 0.5 * T * T * acc, v + T * acc, sd
                if abs(s) > 1.0:  # grown a thousandfold
                    break
            assert abs(s) > 1.0 if grows else abs(s) < 1e-6, (omega, factor, s)


def _delayed_characteristic_roots(law: str, g: dict, mu: float, T: float, gain: float) -> np.ndarray:
    """The closed-loop poles of the law's null-space loop with one period of computation
    delay, from transfer-function polynomials (not a state matrix): the plant s̈ = u/μ
    discretised with SciPy's zero-order hold (cont2discrete, then ss2tf: s = n_s(z)/den(z) u,
    ṡ = n_v(z)/den(z) u), the law's torque u_k = c_s(z) s + c_v ṡ (the paper's c_s with its
    backward difference, a z⁻¹ term), applied a period late (z⁻¹) and scaled by ``gain``:
    den(z) z² − gain · (z c_s(z) n_s(z) + z c_v n_v(z)) = 0."""
    from scipy.signal import ss2tf

    Ad, Bd, *_ = cont2discrete(
        (np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), np.eye(2), np.zeros((2, 1))),
        T,
        method="zoh",
    )
    num, den = ss2tf(Ad, Bd, np.eye(2), np.zeros((2, 1)))
    n_s, n_v = num[0], num[1]
    if law.startswith("paper"):
        a = abs(g["gain"]) / (mu if law == "paper" else 1.0)
        z_c_s = np.array([-a / T - g["K_n"] * a, a / T])  # z (−a(1 − z⁻¹)/T − K_n a)
        z_c_v = np.array([-g["K_n"], 0.0])
    else:
        scale = 1.0 if law == "dynamically_consistent_posture_pd" else 1.0 / mu
        z_c_s = np.array([-scale * g["posture_stiffness"], 0.0])
        z_c_v = np.array([-scale * g["posture_damping"], 0.0])
    loop = np.polyadd(np.polymul(z_c_s, n_s), np.polymul(z_c_v, n_v))
    return np.roots(np.polysub(np.polymul(den, [1.0, 0.0, 0.0]), gain * loop))


@pytest.mark.parametrize(
    "law", ["paper", "paper_moore_penrose", "kinematic_posture_pd", "dynamically_consistent_posture_pd"]
)
@pytest.mark.parametrize("omega, h_n, mu, T", [(20.0, 0.0263, 0.0263, 0.001), (50.0, 0.0049, 0.0018, 0.002)])
def test_the_delayed_gain_margin_is_where_the_delayed_loops_polynomial_turns_unstable(law, omega, h_n, mu, T):
    """gain_margin with one period of delay against the roots of the delayed loop's
    characteristic polynomial built from SciPy's transfer functions
    (:func:`_delayed_characteristic_roots`): stable at 0.999 × the margin and on a grid
    below it, unstable at 1.001 ×; and the delay costs margin (below the delay-free one).
    The Panda's rule (μ = h_n) and fig3's light direction. Catches a delayed loop that
    applies u_k at once (the delay-free margin: 50, not 24.9 for the Panda's PDs), a
    pending torque not scaled by g, or a margin that is not the first crossing."""
    g = tuned_gains(law, omega, h_n)
    margin = gain_margin(law, g, mu, T, delay=1)

    def radius(gain):
        return np.max(np.abs(_delayed_characteristic_roots(law, g, mu, T, gain)))

    assert 1.0 < margin < gain_margin(law, g, mu, T)
    assert radius(0.999 * margin) < 1.0 < radius(1.001 * margin)
    assert all(radius(x) < 1.0 for x in np.linspace(0.001, 0.999, 200) * margin)


@pytest.mark.slow
def test_a_run_with_a_periods_delay_settles_below_the_delayed_margin_and_diverges_above():
    """End to end, the project's own delay (``realism.delay``, one period) on fig3 with the
    rule's torque PD (``fig3 / dyn. consistent PD (torque)``), its K and D scaled by g: at
    0.92 × the delayed margin (``gain_margin_delay`` at the start, 1.80) the posture's
    ring after first contact dies out (‖τ₀‖ over the last 0.5 s below a tenth of its peak
    after contact); at 1.05 × it diverges; without the delay the same 1.05 × settles (the
    delay-free margin is 3.69). 3 s runs. Catches a delayed margin computed without the
    delay (0.92 × 3.69 diverges) or one that is not the loop the drive runs."""
    from nsdrake.experiment.simulate import DivergenceError, run
    from nsdrake.studies.null_space_laws import loop_figures

    family = load_family("null_space_laws")
    index = [v.name for v in family.variants].index("fig3 / dyn. consistent PD (torque)")
    base = variant_scenario(family, index, None, 3.0)
    arm = build_diagram(base).station.arm_model
    margin = loop_figures(base, arm)["gain_margin_delay"]
    assert 1.7 < margin < 1.9

    def scaled(factor, delayed=True):
        ns = dataclasses.replace(
            base.null_space,
            posture_stiffness=factor * base.null_space.posture_stiffness,
            posture_damping=factor * base.null_space.posture_damping,
        )
        delay = dataclasses.replace(base.realism.delay, enabled=delayed, periods=1)
        return dataclasses.replace(
            base, null_space=ns, realism=dataclasses.replace(base.realism, delay=delay)
        )

    def settles(scenario):
        try:
            traces, _ = run(scenario)
        except DivergenceError:
            return False
        t, tau0 = traces["t"], np.linalg.norm(traces.block("tau0_"), axis=1)
        contact = t[np.flatnonzero(traces["f_n"] >= scenario.reference.contact_threshold)[0]]
        return tau0[t >= t[-1] - 0.5].max() < 0.1 * tau0[t >= contact].max()

    assert settles(scaled(0.92 * margin))
    assert not settles(scaled(1.05 * margin))
    assert settles(scaled(1.05 * margin, delayed=False))


def test_the_loop_along_a_run_spans_its_postures():
    """loop_along_run over a few postures of fig3's arm: the range of ζ is the range of the
    per-posture damping ratios computed here from Drake's own mass matrix and Jacobian
    (H from CalcMassMatrix, J the tool's translational Jacobian, Z from SciPy's null_space),
    ζ = D/(2√(K μ)) for the torque PD; the slowest pole's range over the run the range of
    each posture's slowest root of μ s² + D s + K (NumPy's roots); the smallest margin the
    smallest of 2μ/(D T). Every output is checked. Catches figures taken at the start
    posture only, from the wrong inertia, or the range's upper end taken with min (the
    range collapsed to its lower end: issue 46, mistake 12)."""
    from pydrake.multibody.tree import JacobianWrtVariable
    from scipy.linalg import null_space

    arm = paper_arm()
    plant, context = arm.plant, arm.plant.CreateDefaultContext()
    q0 = np.array([0.401, 0.972, 1.012, 0.614])
    qs = np.array([q0 + d for d in (0.0, 0.15, -0.2, 0.3)])
    g = tuned_gains("dynamically_consistent_torque_pd", 50.0, 0.0049)
    T = 0.001
    zetas, margins, slowest, mus = [], [], [], []
    for q in qs:
        plant.SetPositions(context, q)
        H = plant.CalcMassMatrix(context)
        J = plant.CalcJacobianTranslationalVelocity(
            context,
            JacobianWrtVariable.kV,
            arm.tool_frame,
            np.zeros(3),
            plant.world_frame(),
            plant.world_frame(),
        )[arm.rows]
        Z = null_space(J)
        mus += list(np.linalg.eigvalsh(Z.T @ H @ Z))
        rates = []
        for mu in np.linalg.eigvalsh(Z.T @ H @ Z):
            zetas.append(g["posture_damping"] / (2 * np.sqrt(g["posture_stiffness"] * mu)))
            margins.append(2 * mu / (g["posture_damping"] * T))
            # μ s² + D s + K = 0: the direction's poles (NumPy's roots), its slowest rate
            rates.append(np.min(-np.roots([mu, g["posture_damping"], g["posture_stiffness"]]).real))
        slowest.append(min(rates))  # the posture's slowest pole
    run = loop_along_run("dynamically_consistent_torque_pd", g, arm, qs, T)
    delayed = min(gain_margin("dynamically_consistent_torque_pd", g, mu, T, delay=1) for mu in mus)
    expected = {
        "zeta_min": (min(zetas), 1e-6),
        "zeta_max": (max(zetas), 1e-6),
        "slowest_pole_min": (min(slowest), 1e-9),
        "slowest_pole_max": (max(slowest), 1e-9),
        "gain_margin_min": (min(margins), 1e-5),
        "gain_margin_delay_min": (delayed, 1e-9),
    }
    assert set(run) == set(expected)  # every output checked
    for name, (value, rel) in expected.items():
        assert run[name] == pytest.approx(value, rel=rel), name
    assert max(zetas) / min(zetas) > 1.05  # the postures differ enough to tell
    assert max(slowest) / min(slowest) > 1.05  # … and so does the slowest pole's range


def test_the_moved_posture_keeps_the_tool_where_it_was():
    """panda_self_motion's q_d offset is a self-motion: the tool's pose at q_d + Δq is its
    pose at q_d within the rounding of the family file's 4 decimals."""
    family = load_family("null_space_laws")
    index = [v.name for v in family.variants].index("panda_self_motion / paper")
    s = variant_scenario(family, index, None, 0.01)
    arm = build_diagram(s).station.arm_model
    p = s.desired_null_space.posture
    q_d = np.array([p.q_d[j] for j in arm.joint_names])
    offset = np.array([p.offset[j] for j in arm.joint_names])
    context = arm.plant.CreateDefaultContext()
    poses = []
    for q in (q_d, q_d + offset):
        arm.plant.SetPositions(context, q)
        poses.append(arm.plant.CalcRelativeTransform(context, arm.plant.world_frame(), arm.tool_frame))
    assert np.linalg.norm(offset) > 0.45
    assert np.linalg.norm(poses[0].translation() - poses[1].translation()) < 5e-5
    assert poses[0].rotation().InvertAndCompose(poses[1].rotation()).ToAngleAxis().angle() < 1e-4


def test_a_variant_with_an_unknown_scenario_is_refused(tmp_path, monkeypatch):
    import nsdrake.studies.compare as compare

    monkeypatch.setattr(compare, "FAMILY_DIR", tmp_path)
    (tmp_path / "bad.yaml").write_text("scenario: fig3\nmeasure: fig3\nvariants: [{name: a, scenario: fig9}]")
    with pytest.raises(ScenarioError, match=r"variants\[0\]\.scenario: unknown scenario 'fig9'"):
        load_family("bad")


@pytest.mark.slow
def test_short_family_dynamically_consistent_laws_leave_the_task_alone(tmp_path):
    """panda_wipe to 2.2 s (contact at 1.44 s, a 0.26 s window): the four dynamically
    consistent rows' J H⁻¹ τ₀ is rounding (< 1e-9 m/s²), the kinematic projector's is not
    (either inverse); ν exists for the paper's law only; every row is stable at its period."""
    family = load_family("null_space_laws")
    family = dataclasses.replace(family, variants=family.variants[:6])
    result = run_family(family, tmp_path, duration=2.2)
    rows = {row["variant"].split(" / ")[1]: row for row in result.rows}
    assert not result.failures
    for law in ("paper", "paper, Moore-Penrose", "dyn. consistent PD (H)", "dyn. consistent PD (torque)"):
        assert rows[law]["task_disturbance_peak"] < 1e-9
    for law in ("kinematic PD", "kinematic PD, damped inverse"):
        assert rows[law]["task_disturbance_peak"] > 1e-4
    for row in rows.values():
        assert row["pole_radius_T"] < 1.0
    assert math.isfinite(rows["paper"]["nu_rms"]) and rows["kinematic PD"]["nu_rms"] == ""
    for name in ("table.md", "table.csv", "laws.png", "task/table.md", "posture/table.md"):
        assert (tmp_path / name).stat().st_size > 0
    # every figure a row has is in one of the markdown tables (none only in table.csv)
    shown = {key for _, columns in LAW_TABLES for key, _ in columns} | {"variant", "note", "error"}
    assert {key for row in result.rows for key in row} <= shown


@pytest.mark.parametrize("arm_name", ["panda", "arm4"])
def test_posture_lag_is_the_share_of_the_tool_motion_in_j_bars_null_space(arm_name):
    """posture_lag's premise, at seeded random states: (I − J̄ J) J⁺ ẋ = Z M_n⁻¹ Zᵀ H J⁺ ẋ
    (J̄ formed here), so the quasi-static s solving M_n⁻¹ Zᵀ H J⁺ ẋ = K M_n⁻¹ s is
    Zᵀ H J⁺ ẋ / K, whose norm posture_lag returns; and through J⁺ the same term
    (I − J⁺ J) J⁺ ẋ is zero. Catches a lag with M_n left in, or H left out."""
    from models import random_states

    from nsdrake.studies.null_space_laws import posture_lag

    arm = panda_arm() if arm_name == "panda" else paper_arm()
    context = arm.plant.CreateDefaultContext()
    K = -0.5
    for q, v in random_states(arm.n, 6, seed=12):
        T = arm.terms(context, q, v, coriolis=False)
        J_pinv, xdot = np.linalg.pinv(T.J), T.J @ v
        Z = np.linalg.svd(T.J)[2][T.J.shape[0] :].T
        M = Z.T @ T.H @ Z
        N_bar = np.eye(arm.n) - dynamically_consistent_inverse(T.J, T.H_inv) @ T.J
        lhs = N_bar @ J_pinv @ xdot
        np.testing.assert_allclose(
            lhs, Z @ np.linalg.solve(M, Z.T @ T.H @ J_pinv @ xdot), atol=1e-10 * np.linalg.norm(lhs)
        )
        s = np.linalg.solve(K * np.linalg.inv(M), np.linalg.solve(M, Z.T @ T.H @ J_pinv @ xdot))
        assert posture_lag(T, v, K) == pytest.approx(np.linalg.norm(s), rel=1e-9)
        assert np.linalg.norm((np.eye(arm.n) - J_pinv @ T.J) @ J_pinv @ xdot) < 1e-10 * np.linalg.norm(xdot)


def test_the_off_path_posture_is_off_the_self_motion():
    """panda_off_path's q_d offset has no part the self-motion can remove at the start
    posture (‖Z Zᵀ Δ‖ < 1e-9 ‖Δ‖), but a part the H-weighted PD's equilibrium sees
    (‖Zᵀ H Δ‖ > 1e-3 ‖H Δ‖): the row where the joint-space laws stay and the H-weighted PD
    moves. Catches an "off-path" offset that the self-motion can in fact reach."""
    family = load_family("null_space_laws")
    index = [v.name for v in family.variants].index("panda_off_path / paper")
    s = variant_scenario(family, index, None, 0.01)
    arm = panda_arm()
    p = s.desired_null_space.posture
    q_d = np.array([p.q_d[j] for j in arm.joint_names])
    offset = np.array([p.offset.get(j, 0.0) for j in arm.joint_names])
    T = arm.terms(arm.plant.CreateDefaultContext(), q_d, np.zeros(arm.n), coriolis=False)
    Z = np.linalg.svd(T.J)[2][T.J.shape[0] :].T
    assert np.linalg.norm(offset) == pytest.approx(0.3)
    assert np.linalg.norm(Z @ (Z.T @ offset)) < 1e-9 * np.linalg.norm(offset)
    assert np.linalg.norm(Z.T @ T.H @ offset) > 1e-3 * np.linalg.norm(T.H @ offset)


def test_the_table_parts_show_each_figure_once_with_its_unit_and_the_push_rows_alone():
    """table_parts on two rows, a task's and a push's, each with every figure: each figure
    is a column of exactly one table, headed with its unit where it has one
    ("force_error_rms [N]"), the variant first in every table; the push table holds the
    push row only, the others both. Catches a figure in two tables or none, a header
    without its unit, or push columns blank on every other row (the 28-column table)."""
    keys = [key for _, columns in LAW_TABLES for key, _ in columns]
    push_keys = {key for folder, columns in LAW_TABLES if folder == "push" for key, _ in columns}
    task_row = {"variant": "panda_wipe / paper", **{k: 1.0 for k in keys if k not in push_keys}}
    push_row = {"variant": "push / paper", **{k: 2.0 for k in keys}}
    parts = {folder: (header, rows) for folder, header, rows in table_parts([task_row, push_row])}
    assert set(parts) == {"", "task", "posture", "push"}
    headers = [h for header, _ in parts.values() for h in header if h != "variant"]
    assert sorted(h.split(" [")[0] for h in headers) == sorted(keys)
    assert "force_error_rms [N]" in parts["task"][0] and "slowest_pole [rad/s]" in parts[""][0]
    assert all(header[0] == "variant" for header, _ in parts.values())
    assert [row["variant"] for row in parts["push"][1]] == ["push / paper"]
    assert [row["variant"] for row in parts["task"][1]] == ["panda_wipe / paper", "push / paper"]
    assert parts["push"][1][0]["push_return_time [s]"] == 2.0

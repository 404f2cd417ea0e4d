"""Property tests of the paper's identities on 1000 states each (Hypothesis, derandomised:
the same states on every run), a fifth of them within 1e-3 rad of a singular pose.

    Eq. 11   J H⁻¹ τ₀ = 0 for the Eq. 21 law, with J̄ and with J⁺
    Eq. 19   eⁿᵀ H J̄ = 0 for eⁿ in the null space of I − J̄J
    Eq. 26   (I − J̄J) H⁻¹ Jᵀ F = 0, and it fails for J⁺
             (I − J̄J)² = I − J̄J
    Eq. 24   ν̇ = −K_n eⁿᵀ H eⁿ in the closed loop with full compensation

Tolerances are relative, scaled by the magnitudes involved: 1e-8 for the algebraic
identities and 1e-7 for ν̇. Near a singular pose, Λ = (J H⁻¹ Jᵀ)⁻¹ has a condition
number up to ~1e6 (σ_min(J) ~ 1e-3), and products with it lose that many digits of
the ~1e-16 working precision: ~1e-10, well inside 1e-8. A wrong formula is off by O(1).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import paper_arm, terms_at
from drake_reference import AutoDiffArm
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from nsdrake.control.impedance import primary_torque
from nsdrake.control.null_space import null_space_torque
from nsdrake.control.pseudo_inverse import GeneralizedInverse, PseudoInverseKind

ARM = paper_arm()
AD = AutoDiffArm(ARM)
DC = GeneralizedInverse()
MP = GeneralizedInverse(PseudoInverseKind.moore_penrose)
EXAMPLES = 1000
SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
vectors = st.lists(finite, min_size=4, max_size=4).map(np.array)

pytestmark = pytest.mark.slow  # 1000 states each


offsets = st.tuples(st.sampled_from([-1.0, 1.0]), st.floats(5e-4, 1e-3)).map(lambda p: p[0] * p[1])


@st.composite
def states(draw):
    """(q, v): random, or (one draw in five) between 5e-4 and 1e-3 rad from a singular
    pose on every joint. J̄ does not exist at a singular pose (Λ = (J H⁻¹ Jᵀ)⁻¹), so
    states whose smallest singular value of J is below 1e-5 m are rejected: Hypothesis
    likes q = 0, the stretched arm."""
    if draw(st.integers(0, 4)) == 0:
        q = np.array(
            [draw(st.floats(-np.pi, np.pi))] + [draw(st.sampled_from([0.0, np.pi])) for _ in range(3)]
        )
        q = q + np.array([draw(offsets) for _ in range(4)])
    else:
        q = np.array([draw(st.floats(-np.pi, np.pi)) for _ in range(4)])
    J = terms_at(ARM, q, np.zeros(4), coriolis=False).J
    assume(np.linalg.svd(J, compute_uv=False)[-1] > 1e-5)
    return q, 2.0 * draw(vectors)


def scale(*arrays) -> float:
    return max(1.0, *(float(np.max(np.abs(a))) for a in arrays))


@SETTINGS
@given(states(), vectors, vectors, st.sampled_from([DC, MP]), st.floats(0.1, 100.0))
def test_eq11_tau0_never_accelerates_the_task(state, qd, qdd, inverse, K_n):
    T = terms_at(ARM, *state)
    tau0 = null_space_torque(T, inverse, qd, qdd, K_n).tau0
    a = T.H_inv @ tau0
    assert np.max(np.abs(T.J @ a)) <= 1e-8 * scale(a) * scale(T.J)


@SETTINGS
@given(states(), vectors)
def test_eq19_lemma(state, e):
    T = terms_at(ARM, *state, coriolis=False)
    inv = DC.at(T)
    e_n = inv.N @ e
    assert np.max(np.abs(e_n @ T.H @ inv.J_pinv)) <= 1e-8 * scale(e_n) * scale(T.H) * scale(inv.J_pinv)


@SETTINGS
@given(states(), st.lists(finite, min_size=2, max_size=2).map(np.array))
def test_eq26_and_idempotence_for_the_dc_projector(state, F):
    T = terms_at(ARM, *state, coriolis=False)
    N = DC.at(T).N
    a = T.H_inv @ T.J.T @ F
    assert np.max(np.abs(N @ a)) <= 1e-8 * scale(N) * scale(a)
    assert np.max(np.abs(N @ N - N)) <= 1e-8 * scale(N) ** 2


def test_eq26_fails_for_moore_penrose_on_1000_states():
    """With J⁺ a contact force does accelerate the null space, in (almost) every state:
    the share of H⁻¹ Jᵀ F left in the null space is above 1e-3 in 99% of 1000 states."""
    rng = np.random.default_rng(2026)
    shares = []
    for k in range(EXAMPLES):
        q = rng.uniform(-np.pi, np.pi, 4)
        if k % 5 == 0:
            q = np.concatenate([q[:1], rng.choice([0.0, np.pi], 3)]) + rng.uniform(-1e-3, 1e-3, 4)
        T = terms_at(ARM, q, np.zeros(4), coriolis=False)
        a = T.H_inv @ T.J.T @ rng.standard_normal(2)
        shares.append(np.linalg.norm(MP.at(T).N @ a) / np.linalg.norm(a))
    assert np.mean(np.array(shares) > 1e-3) > 0.99


@SETTINGS
@given(
    states(), vectors, vectors, st.lists(finite, min_size=2, max_size=2).map(np.array), st.floats(0.1, 100.0)
)
def test_eq24_lyapunov_derivative(state, qd_raw, qdd, xddot_c, K_n):
    """ν̇ = eᵀ H ė + ½ eᵀ Ḣ e with ė from the closed loop (q̈ = H⁻¹(τ − C q̇ − g),
    τ = primary law + τ₀, Ṅ from AutoDiff) equals −K_n eᵀ H e."""
    q, v = state
    T = terms_at(ARM, q, v)
    N = DC.at(T).N
    qd = N @ qd_raw
    tau = primary_torque(T, xddot_c, np.zeros(6)) + null_space_torque(T, DC, qd, qdd, K_n).tau0
    qddot = T.H_inv @ (tau - T.Cv - T.g)
    Jbar, Jbar_dot = AD.Jbar_and_dot(q, v)
    N_dot = -(Jbar_dot @ T.J + Jbar @ AD.Jdot(q, v))
    e = qd - N @ v
    e_dot = qdd - N_dot @ v - N @ qddot
    nu_dot = e @ T.H @ e_dot + 0.5 * e @ AD.Hdot(q, v) @ e
    expected = -K_n * e @ T.H @ e
    assert abs(nu_dot - expected) <= 1e-7 * max(abs(expected), scale(T.H) * scale(e) ** 2 * scale(e_dot))

"""The null-space controller (Eqs. 11, 14, 21–24) as pure functions.

Tolerances as in test_pseudo_inverse (1e-9 relative) for exact identities; the
independent rebuild of τ₀ uses AutoDiff for J̄̇ and the Christoffel formula on
AutoDiff ∂H/∂q for C, the same algebra in another order, so 1e-9 as well.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import terms_at
from drake_reference import AutoDiffArm, christoffel_C
from models import random_states
from reference_math import (
    H_inv_dot,
    null_space_projector,
    pinv_derivative,
    pinv_of,
    task_velocity_compensation,
)

from nsdrake.control.impedance import primary_torque
from nsdrake.control.null_space import lyapunov, null_space_torque, null_space_velocity_error
from nsdrake.control.pseudo_inverse import GeneralizedInverse, PseudoInverseKind

TOL = 1e-9
DC = GeneralizedInverse(PseudoInverseKind.dynamically_consistent)
MP = GeneralizedInverse(PseudoInverseKind.moore_penrose)


def rel(a, scale):
    return float(np.max(np.abs(a))) / max(float(scale), 1e-300)


def random_null_space_inputs(arm, T, rng, inverse=DC):
    N = inverse.at(T).N
    return N @ rng.standard_normal(arm.n), rng.standard_normal(arm.n)


@pytest.mark.parametrize("inverse", [DC, MP], ids=["dc", "mp"])
def test_eq11_tau0_causes_no_task_acceleration_whichever_inverse(arm, inverse):
    """J H⁻¹ τ₀ = 0 with the Eq. 21 law, for J̄ and for J⁺ (Section 3.3's claim)."""
    rng = np.random.default_rng(21 + 1000)
    for q, v in random_states(arm.n, 20, seed=21):
        T = terms_at(arm, q, v)
        qd, qdd = rng.standard_normal(arm.n), rng.standard_normal(arm.n)  # arbitrary, even outside N
        tau0 = null_space_torque(T, inverse, qd, qdd, K_n=30.0).tau0
        a = T.H_inv @ tau0
        assert rel(T.J @ a, np.max(np.abs(T.J)) * np.max(np.abs(a))) < TOL


def test_tau0_rebuilt_independently(arm):
    """Eq. 21 from AutoDiff J̄̇ and the Christoffel formula, against null_space_torque."""
    rng = np.random.default_rng(22 + 1000)
    ad = AutoDiffArm(arm)
    for q, v in random_states(arm.n, 8, seed=22):
        T = terms_at(arm, q, v)
        qd, qdd = random_null_space_inputs(arm, T, rng)
        K_n = 25.0
        Jbar, Jbar_dot = ad.Jbar_and_dot(q, v)
        N = null_space_projector(T.J, Jbar)
        e = qd - N @ v
        C = christoffel_C(arm, q, v)
        comp = task_velocity_compensation(T.J, ad.Jdot(q, v), Jbar, Jbar_dot, v)
        expected = T.H @ N @ (qdd + comp + K_n * e + np.linalg.solve(T.H, C @ e))
        result = null_space_torque(T, DC, qd, qdd, K_n)
        assert rel(result.tau0 - expected, np.max(np.abs(expected))) < TOL
        assert rel(result.e_n - e, np.max(np.abs(e))) < TOL
        assert abs(result.nu - 0.5 * e @ T.H @ e) <= TOL * abs(result.nu)


def test_switches_remove_exactly_their_term(arm4):
    rng = np.random.default_rng(23 + 1000)
    q, v = next(random_states(4, 1, seed=23))
    T = terms_at(arm4, q, v)
    qd, qdd = random_null_space_inputs(arm4, T, rng)
    full = null_space_torque(T, DC, qd, qdd, 10.0).tau0
    no_cor = null_space_torque(T, DC, qd, qdd, 10.0, coriolis_comp=False).tau0
    no_tvc = null_space_torque(T, DC, qd, qdd, 10.0, task_velocity_comp=False).tau0
    none = null_space_torque(T, DC, qd, qdd, 10.0, False, False).tau0
    N, e = DC.at(T).N, qd - DC.at(T).N @ v
    assert rel(full - no_cor - T.H @ N @ T.H_inv @ T.C @ e, np.max(np.abs(full))) < TOL
    assert rel((full - no_tvc) - (no_cor - none), np.max(np.abs(full))) < TOL
    assert np.max(np.abs(full - no_cor)) > 1e-6 and np.max(np.abs(full - no_tvc)) > 1e-6


def nu_dot_closed_loop(arm, q, v, qd, qdd, xddot_c, K_n, inverse, coriolis_comp=True):
    """ν̇ from the free-motion closed loop: q̈ = H⁻¹(τ − C q̇ − g), τ = primary + τ₀;
    ė = q̈_dⁿ − Ṅ q̇ − N q̈ (Eq. 15) with Ṅ from AutoDiff; ν̇ = eᵀ H ė + ½ eᵀ Ḣ e."""
    T = terms_at(arm, q, v)
    ad = AutoDiffArm(arm)
    tau = (
        primary_torque(T, xddot_c, np.zeros(6))
        + null_space_torque(T, inverse, qd, qdd, K_n, coriolis_comp=coriolis_comp).tau0
    )
    qddot = T.H_inv @ (tau - T.Cv - T.g)
    if inverse is DC:
        Jp, Jp_dot = ad.Jbar_and_dot(q, v)
    else:
        Jp = pinv_of(inverse, T.J, T.H_inv)
        Jp_dot = pinv_derivative(inverse, T.J, T.Jdot, T.H_inv, H_inv_dot(T))
    N = null_space_projector(T.J, Jp)
    N_dot = -(Jp_dot @ T.J + Jp @ ad.Jdot(q, v))
    e = qd - N @ v
    e_dot = qdd - N_dot @ v - N @ qddot
    return e @ T.H @ e_dot + 0.5 * e @ ad.Hdot(q, v) @ e, e, T


def test_eq24_lyapunov_derivative_with_full_compensation(arm):
    """ν̇ = −K_n eⁿᵀ H eⁿ exactly (Eq. 24), for any q̈_dⁿ and task command."""
    rng = np.random.default_rng(24 + 1000)
    for q, v in random_states(arm.n, 10, seed=24):
        T = terms_at(arm, q, v)
        qd, qdd = random_null_space_inputs(arm, T, rng)
        K_n = 15.0
        nu_dot, e, T = nu_dot_closed_loop(arm, q, v, qd, qdd, rng.standard_normal(arm.m), K_n, DC)
        expected = -K_n * e @ T.H @ e
        assert abs(nu_dot - expected) <= TOL * abs(expected)


def test_eq24_needs_the_coriolis_compensation(arm4):
    """Without H⁻¹ C eⁿ, ν̇ picks up ½ eᵀ Ḣ e − eᵀ C e… which is not zero in general."""
    rng = np.random.default_rng(25 + 1000)
    gaps = []
    for q, v in random_states(4, 10, seed=25, speed=2.0):
        T = terms_at(arm4, q, v)
        qd, qdd = random_null_space_inputs(arm4, T, rng)
        nu_dot, e, T = nu_dot_closed_loop(arm4, q, v, qd, qdd, np.zeros(2), 15.0, DC, coriolis_comp=False)
        expected = -15.0 * e @ T.H @ e
        gaps.append(abs(nu_dot - expected) / abs(expected))
    assert max(gaps) > 1e-3


def test_pure_helpers():
    H = np.diag([2.0, 3.0])
    e = np.array([1.0, -2.0])
    assert lyapunov(H, e) == pytest.approx(0.5 * (2 + 12))
    N = np.array([[1.0, 0.0], [0.0, 0.0]])
    assert np.allclose(null_space_velocity_error(np.array([1.0, 0.0]), N, np.array([0.5, 9.0])), [0.5, 0.0])

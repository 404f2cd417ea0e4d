"""Generalised inverses (Section 3.2): the identities the paper relies on, on seeded
random states of every test arm.

Tolerances: the identities are exact in exact arithmetic; on these well-scaled
arms (H and J entries O(0.01–10)) they hold to ~1e-13, so 1e-9 relative leaves
margin for conditioning without hiding a wrong formula (a wrong one is off by O(1)).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import terms_at
from drake_reference import AutoDiffArm
from models import random_states
from reference_math import (
    H_inv_dot,
    dynamically_consistent_inverse,
    moore_penrose_inverse,
    null_space_projector,
    pinv_derivative,
    pinv_of,
    task_space_inertia,
    task_velocity_compensation,
    weighted_inverse,
)

from nsdrake.control.null_space import task_velocity_compensation_at
from nsdrake.control.pseudo_inverse import GeneralizedInverse, PseudoInverseKind

TOL = 1e-9
KINDS = [
    GeneralizedInverse(PseudoInverseKind.dynamically_consistent),
    GeneralizedInverse(PseudoInverseKind.moore_penrose),
    GeneralizedInverse(PseudoInverseKind.damped_least_squares, 0.05),
]


def rel(a, scale=1.0):
    return float(np.max(np.abs(a))) / max(scale, 1.0)


def test_right_inverse_and_idempotent_projector(arm):
    for q, v in random_states(arm.n, 30, seed=11):
        T = terms_at(arm, q, v, coriolis=False)
        for inverse in KINDS[:2]:
            pinv = inverse.at(T)
            assert rel(T.J @ pinv.J_pinv - np.eye(arm.m)) < TOL
            assert rel(pinv.N @ pinv.N - pinv.N) < TOL  # (I − J^# J)² = I − J^# J
            assert rel(T.J @ pinv.N, np.max(np.abs(T.J))) < TOL


def test_eq13_matches_its_definition(arm):
    for q, v in random_states(arm.n, 10, seed=12):
        T = terms_at(arm, q, v, coriolis=False)
        expected = T.H_inv @ T.J.T @ task_space_inertia(T.J, T.H_inv)  # Eq. 13 as written
        assert rel(dynamically_consistent_inverse(T.J, T.H_inv) - expected, np.max(np.abs(expected))) < TOL
        assert rel(KINDS[0].at(T).J_pinv - expected, np.max(np.abs(expected))) < TOL
        assert rel(moore_penrose_inverse(T.J) - np.linalg.pinv(T.J), 10) < TOL


def test_eq26_contact_forces_leave_the_dc_null_space_alone(arm):
    """(I − J̄ J) H⁻¹ Jᵀ F = 0 for every F (Eq. 26)."""
    rng = np.random.default_rng(13 + 1000)
    for q, v in random_states(arm.n, 30, seed=13):
        T = terms_at(arm, q, v, coriolis=False)
        N = KINDS[0].at(T).N
        F = rng.standard_normal(arm.m)
        a = T.H_inv @ T.J.T @ F
        assert rel(N @ a, np.max(np.abs(a))) < TOL


def test_eq26_fails_for_moore_penrose(arm):
    """With J⁺ the same force does accelerate the null space, by a clearly non-zero share."""
    rng = np.random.default_rng(14 + 1000)
    shares = []
    for q, v in random_states(arm.n, 30, seed=14):
        T = terms_at(arm, q, v, coriolis=False)
        N = null_space_projector(T.J, moore_penrose_inverse(T.J))
        a = T.H_inv @ T.J.T @ rng.standard_normal(arm.m)
        shares.append(np.linalg.norm(N @ a) / np.linalg.norm(a))
    assert np.median(shares) > 0.05


def test_eq19_lemma(arm):
    """eⁿᵀ H J̄ = 0 for eⁿ in the null space of the dynamically consistent projector."""
    rng = np.random.default_rng(15 + 1000)
    for q, v in random_states(arm.n, 30, seed=15):
        T = terms_at(arm, q, v, coriolis=False)
        pinv = KINDS[0].at(T)
        e_n = pinv.N @ rng.standard_normal(arm.n)
        assert rel(e_n @ T.H @ pinv.J_pinv, np.linalg.norm(e_n) * np.max(np.abs(T.H))) < TOL


def test_dc_inverse_derivative_matches_autodiff(arm):
    ad = AutoDiffArm(arm)
    for q, v in random_states(arm.n, 15, seed=16):
        T = terms_at(arm, q, v)
        _, Jbar_dot = ad.Jbar_and_dot(q, v)
        ours = pinv_derivative(KINDS[0], T.J, T.Jdot, T.H_inv, H_inv_dot(T))
        assert rel(ours - Jbar_dot, np.max(np.abs(Jbar_dot))) < TOL


@pytest.mark.parametrize("inverse", KINDS, ids=lambda k: k.kind.value)
def test_inverse_derivative_matches_central_differences_in_time(arm4, inverse):
    """d/dt J^# along q(t) = q + t q̇, by central differences (h = 1e-6: error ~1e-10)."""
    h = 1e-6
    for q, v in random_states(4, 10, seed=17):
        T = terms_at(arm4, q, v)
        ours = pinv_derivative(inverse, T.J, T.Jdot, T.H_inv, H_inv_dot(T))
        plus, minus = terms_at(arm4, q + h * v, v), terms_at(arm4, q - h * v, v)
        fd = (pinv_of(inverse, plus.J, plus.H_inv) - pinv_of(inverse, minus.J, minus.H_inv)) / (2 * h)
        assert rel(ours - fd, np.max(np.abs(fd))) < 1e-6


@pytest.mark.parametrize("inverse", KINDS, ids=lambda k: k.kind.value)
def test_vector_task_velocity_compensation_matches_the_matrix_form(arm, inverse):
    for q, v in random_states(arm.n, 15, seed=18):
        T = terms_at(arm, q, v)
        pinv = inverse.at(T)
        J_pinv_dot = pinv_derivative(inverse, T.J, T.Jdot, T.H_inv, H_inv_dot(T))
        expected = task_velocity_compensation(T.J, T.Jdot, pinv.J_pinv, J_pinv_dot, v)
        got = task_velocity_compensation_at(T, pinv, inverse.inertia_weighted)
        assert rel(got - expected, np.max(np.abs(expected))) < TOL


def test_damping_costs_the_right_inverse_property(arm4):
    q, v = next(random_states(4, 1, seed=19))
    T = terms_at(arm4, q, v, coriolis=False)
    J_dls = weighted_inverse(T.J, np.eye(4), 0.05)
    assert np.max(np.abs(T.J @ J_dls - np.eye(2))) > 1e-4


@pytest.mark.parametrize(
    ("kind", "damping", "message"),
    [
        ("damped_least_squares", 0.0, "needs a damping"),
        ("moore_penrose", 0.1, "only used by"),
        ("dynamically_consistent", -1.0, "finite number >= 0"),
        ("dynamically_consistent", float("nan"), "finite number >= 0"),
    ],
)
def test_inconsistent_inverse_settings_are_refused(kind, damping, message):
    with pytest.raises(ValueError, match=message):
        GeneralizedInverse(PseudoInverseKind(kind), damping)

"""Gradient projection (Eqs. 28–30) and joint-speed scaling."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import terms_at
from models import random_states

from nsdrake.gradient_projection import gradient_step, scale_to_speed_limits
from nsdrake.pseudo_inverse import GeneralizedInverse, PseudoInverseKind

DC = GeneralizedInverse(PseudoInverseKind.dynamically_consistent)
MP = GeneralizedInverse(PseudoInverseKind.moore_penrose)


def test_eq30_step_never_worsens_the_criterion_to_first_order(arm):
    """ṗ = Φᵀ q̇_dⁿ = K Φᵀ (I − J̄J) H⁻¹ Φ has the sign of K, for any Φ (Section 3.4)."""
    rng = np.random.default_rng(41 + 1000)
    for q, v in random_states(arm.n, 40, seed=41):
        T = terms_at(arm, q, v, coriolis=False)
        N = DC.at(T).N
        M = N @ T.H_inv
        assert np.max(np.abs(M - M.T)) <= 1e-9 * np.max(np.abs(M))  # symmetric …
        assert np.linalg.eigvalsh(0.5 * (M + M.T)).min() >= -1e-9 * np.max(np.abs(M))  # … and PSD
        Phi = rng.standard_normal(arm.n)
        assert Phi @ gradient_step(N, T.H_inv, Phi, +1.0, rotate=True) >= 0
        assert Phi @ gradient_step(N, T.H_inv, Phi, -1.0, rotate=True) <= 0


def test_dc_projection_without_the_rotation_can_worsen_the_criterion(arm4):
    """Φᵀ (I − J̄J) Φ is not a symmetric form and takes negative values: the
    unrotated step with J̄ can decrease a maximised criterion (why Eq. 30 rotates)."""
    rng = np.random.default_rng(42 + 1000)
    found = 0
    for q, v in random_states(4, 200, seed=42):
        T = terms_at(arm4, q, v, coriolis=False)
        Phi = rng.standard_normal(4)
        if Phi @ gradient_step(DC.at(T).N, T.H_inv, Phi, +1.0, rotate=False) < -1e-6 * Phi @ Phi:
            found += 1
    assert found > 0


def test_eq28_moore_penrose_step_is_always_an_ascent(arm4):
    rng = np.random.default_rng(43 + 1000)
    for q, v in random_states(4, 100, seed=43):
        T = terms_at(arm4, q, v, coriolis=False)
        Phi = rng.standard_normal(4)
        assert Phi @ gradient_step(MP.at(T).N, T.H_inv, Phi, +1.0, rotate=False) >= -1e-12


def test_speed_scaling_keeps_direction_and_limits():
    rng = np.random.default_rng(44)
    for _ in range(200):
        qdot = 3 * rng.standard_normal(5)
        limits = rng.uniform(0.2, 2.0, 5)
        scaled, s = scale_to_speed_limits(qdot, limits)
        assert 0 < s <= 1
        assert np.all(np.abs(scaled) <= limits * (1 + 1e-12))
        assert np.allclose(scaled, s * qdot)
        if s < 1:  # the binding joint sits exactly at its limit
            assert np.isclose(np.max(np.abs(scaled) / limits), 1.0)
    unlimited = np.full(3, np.inf)
    qdot = np.array([1.0, -2.0, 3.0])
    assert scale_to_speed_limits(qdot, unlimited)[1] == 1.0


@pytest.mark.parametrize("rotate", [True, False])
def test_step_lies_in_the_null_space(arm, rotate):
    rng = np.random.default_rng(45 + 1000)
    for q, v in random_states(arm.n, 10, seed=45):
        T = terms_at(arm, q, v, coriolis=False)
        step = gradient_step(DC.at(T).N, T.H_inv, rng.standard_normal(arm.n), 0.7, rotate)
        assert np.max(np.abs(T.J @ step)) <= 1e-9 * max(1.0, np.max(np.abs(step)))

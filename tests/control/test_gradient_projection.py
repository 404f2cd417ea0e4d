"""Gradient projection (Eqs. 28–30) and joint-speed scaling."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import terms_at
from models import random_states

from nsdrake.control.gradient_projection import gradient_step
from nsdrake.control.priority import joint_speed_scale
from nsdrake.control.pseudo_inverse import GeneralizedInverse, PseudoInverseKind

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


def test_speed_scaling_keeps_the_total_speed_within_limits_and_is_smooth():
    """joint_speed_scale: |a + s b| ≤ L for every joint; s never exceeds the hard bound
    min(1, b_i) and stays within (1 + n)^(-1/p) of it; s is 1 far from every limit."""
    rng = np.random.default_rng(44)
    n, p = 5, 8
    for _ in range(300):
        limits = rng.uniform(0.4, 2.0, n)
        a = limits * rng.uniform(-0.9, 0.9, n)  # the task part alone within the limits
        b = 3 * rng.standard_normal(n)
        s = joint_speed_scale(a, b, limits)
        assert 0.0 <= s <= 1.0
        assert np.all(np.abs(a + s * b) <= limits * (1 + 1e-12))
        hard = min(
            [1.0]
            + [((L - ai) if bi > 0 else (L + ai)) / abs(bi) for ai, bi, L in zip(a, b, limits, strict=True)]
        )
        assert s <= hard + 1e-12
        assert s >= hard * (1 + n) ** (-1 / p) - 1e-12
    assert joint_speed_scale(np.zeros(3), np.array([1.0, -2.0, 3.0]), np.full(3, np.inf)) == 1.0
    assert joint_speed_scale(np.zeros(3), np.array([1e-4, 0, 0]), np.ones(3)) > 1 - 1e-12
    assert (
        joint_speed_scale(np.array([2.0]), np.array([1.0]), np.array([1.0])) == 0.0
    )  # the task alone is too fast


def test_speed_scale_has_no_kink_where_a_limit_engages():
    """Along a command that grows through a limit, s(t) q̇ⁿ(t) has a continuous
    derivative: its second differences stay O(Δt²)-small, unlike the hard min."""
    ts = np.linspace(0.0, 2.0, 2001)
    command = np.outer(ts, [1.0, 0.3])  # joint 1 reaches its 1 rad/s limit at t = 1
    limits = np.array([1.0, 1.0])
    smooth = np.array([joint_speed_scale(np.zeros(2), c, limits) * c for c in command])
    hard = np.array([min(1.0, 1.0 / c[0]) * c if c[0] > 0 else c for c in command])
    jump = lambda x: np.max(np.abs(np.diff(x[:, 0], 2)))  # noqa: E731
    assert jump(hard) > 100 * jump(smooth)


@pytest.mark.parametrize("rotate", [True, False])
def test_step_lies_in_the_null_space(arm, rotate):
    rng = np.random.default_rng(45 + 1000)
    for q, v in random_states(arm.n, 10, seed=45):
        T = terms_at(arm, q, v, coriolis=False)
        step = gradient_step(DC.at(T).N, T.H_inv, rng.standard_normal(arm.n), 0.7, rotate)
        assert np.max(np.abs(T.J @ step)) <= 1e-9 * max(1.0, np.max(np.abs(step)))

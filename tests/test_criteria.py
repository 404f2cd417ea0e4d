"""Criterion gradients against central finite differences and AutoDiff (Eqs. 32–33).

Tolerances: the analytic gradient and the AutoDiff one are the same derivative in
another order of operations, ~1e-14 relative; checked to 1e-9. Central
differences (h = 1e-6) carry O(h²) truncation and O(ε/h) rounding, ~1e-10
relative; checked to 1e-6.
"""

from __future__ import annotations

import numpy as np
from conftest import terms_at
from drake_reference import AutoDiffArm
from models import random_states

from nsdrake.criteria.joint_torque import joint_torque_criterion


def p_tau(arm, q, F):
    T = terms_at(arm, q, np.zeros(arm.n), coriolis=False)
    tau = T.J.T @ F
    return tau @ tau


def test_joint_torque_value_and_gradient(arm):
    rng = np.random.default_rng(31 + 1000)
    ad = AutoDiffArm(arm)
    h = 1e-6
    for q, _ in random_states(arm.n, 25, seed=31):
        F = 10 * rng.standard_normal(arm.m)
        T = terms_at(arm, q, np.zeros(arm.n), coriolis=False)
        p, Phi = joint_torque_criterion(T.J, T.dJ_dq, F)
        assert abs(p - p_tau(arm, q, F)) <= 1e-12 * max(1.0, p)
        # AutoDiff: ∂p/∂q_j = 2 τᵀ (∂J/∂q_j)ᵀ F with ∂J/∂q from Drake's AutoDiffXd plant
        tau = T.J.T @ F
        Phi_ad = np.array([2 * tau @ (dJk.T @ F) for dJk in ad.dJ_dq(q)])
        scale = max(1.0, np.max(np.abs(Phi_ad)))
        assert np.max(np.abs(Phi - Phi_ad)) <= 1e-9 * scale
        fd = np.array(
            [(p_tau(arm, q + h * e, F) - p_tau(arm, q - h * e, F)) / (2 * h) for e in np.eye(arm.n)]
        )
        assert np.max(np.abs(Phi - fd)) <= 1e-6 * scale

"""RobotTerms against Drake: analytic ∂J/∂q, J̇, the Christoffel C and Ḣ − 2C skew-symmetry.

Tolerances: the analytic and AutoDiff results are the same algebra evaluated in a
different order, so they agree to rounding, ~1e-15 relative; 1e-10 leaves room for
conditioning. Central finite differences with step h = 1e-6 have truncation error
O(h²) ≈ 1e-12 and rounding error O(ε/h) ≈ 1e-10, so they are checked to 1e-7.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import terms_at
from drake_reference import AutoDiffArm, plant_terms
from models import random_states

from nsdrake.control.dynamics import coriolis_matrix

EXACT = 1e-10
FD = 1e-7


def close(a, b, tol):
    scale = max(1.0, float(np.max(np.abs(b))))
    return np.max(np.abs(np.asarray(a) - np.asarray(b))) <= tol * scale


def test_terms_match_plain_plant_calls(arm):
    for q, v in random_states(arm.n, 20, seed=1):
        T = terms_at(arm, q, v)
        ref = plant_terms(arm, q, v)
        for name in ("H", "Cv", "g", "J", "J_spatial", "x", "p_WT"):
            assert close(getattr(T, name), ref[name], EXACT), name
        assert close(T.H_inv @ T.H, np.eye(arm.n), EXACT)


def test_jacobian_partials_match_autodiff(arm):
    ad = AutoDiffArm(arm)
    for q, v in random_states(arm.n, 25, seed=2):
        assert close(terms_at(arm, q, v, coriolis=False).dJ_dq, ad.dJ_dq(q), EXACT)


def test_jacobian_partials_match_central_differences(arm4):
    h = 1e-6
    for q, v in random_states(4, 25, seed=3):
        dJ = terms_at(arm4, q, v, coriolis=False).dJ_dq
        for k in range(4):
            e = np.zeros(4)
            e[k] = h
            fd = (plant_terms(arm4, q + e, v)["J"] - plant_terms(arm4, q - e, v)["J"]) / (2 * h)
            assert close(dJ[k], fd, FD)


def test_jdot_qdot_matches_drake_bias_acceleration(arm):
    ad = AutoDiffArm(arm)
    for q, v in random_states(arm.n, 20, seed=4):
        T = terms_at(arm, q, v, coriolis=False)
        assert close(T.Jdot_v, plant_terms(arm, q, v)["Jdot_v"], EXACT)
        assert close(T.Jdot, ad.Jdot(q, v), EXACT)


def test_coriolis_matrix_reproduces_the_bias_term(arm):
    for q, v in random_states(arm.n, 20, seed=5, speed=3.0):
        T = terms_at(arm, q, v)
        assert close(T.C @ v, T.Cv, EXACT)


def test_hdot_minus_2c_is_skew_symmetric_for_the_christoffel_c(arm):
    ad = AutoDiffArm(arm)
    for q, v in random_states(arm.n, 20, seed=6, speed=2.0):
        T = terms_at(arm, q, v)
        Hdot = ad.Hdot(q, v)
        S = Hdot - 2 * T.C
        assert close(S + S.T, np.zeros_like(S), EXACT)
        assert close(T.Hdot, Hdot, EXACT)


def test_a_non_christoffel_factorisation_is_not_skew():
    """C' = C + D with D v = 0 and D not skew also gives C' v = b but breaks the
    skew property: the test above would catch a C that only reproduced the bias term."""
    from conftest import paper_arm

    arm = paper_arm()
    ad = AutoDiffArm(arm)
    q, v = next(random_states(4, 1, seed=7))
    T = terms_at(arm, q, v)
    rng = np.random.default_rng(70)
    b = rng.standard_normal(4)
    b -= (b @ v) / (v @ v) * v  # b ⊥ v
    D = np.outer(rng.standard_normal(4), b)  # D v = 0, and D is not skew
    C_other = T.C + D
    assert close(C_other @ v, T.Cv, EXACT)
    S = ad.Hdot(q, v) - 2 * C_other
    assert np.max(np.abs(S + S.T)) > 1e-3


def test_coriolis_matrix_from_a_known_quadratic():
    """C(v) from b(v) = Γ(v, v) for a random symmetric bilinear Γ: exactly Γ(v, ·)."""
    rng = np.random.default_rng(8)
    G = rng.standard_normal((3, 3, 3))
    G = G + G.transpose(0, 2, 1)  # symmetric in the last two indices

    def bias(w):
        return np.einsum("ijk,j,k->i", G, w, w)

    v = rng.standard_normal(3)
    assert close(coriolis_matrix(bias, v), np.einsum("ijk,j->ik", G, v), 1e-13)


@pytest.mark.parametrize("bad", ["w", "xy"])
def test_task_axes_are_checked(arm4, bad):
    from nsdrake.control.dynamics import ArmModel

    with pytest.raises(ValueError, match="task axes"):
        ArmModel(arm4.plant, arm4.tool_frame, [bad])

"""Near and at singular poses (issue: safe when things go wrong): the task inertia Λ is
capped (nsdrake.control.dynamics.task_inertia), the law is unchanged away from singularity,
and the controller's torque stays finite and bounded at the stretched arm."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import paper_arm, terms_at
from reference_math import task_space_inertia

from nsdrake.control.dynamics import task_inertia

CAP = 50.0  # [kg] the default ImpedanceConfig.max_task_inertia


def test_lambda_is_the_exact_inverse_away_from_singular_poses():
    """Where every eigenvalue of J H⁻¹ Jᵀ exceeds 1/cap, Λ is (J H⁻¹ Jᵀ)⁻¹ to rounding:
    the paper's law is untouched. A treatment that always damps fails."""
    arm = paper_arm()
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(200):
        q = rng.uniform(-np.pi, np.pi, 4)
        T = terms_at(arm, q, np.zeros(4), coriolis=False)
        A = T.J @ np.linalg.inv(T.H) @ T.J.T
        if np.linalg.eigvalsh(A)[0] < 1.0 / CAP:
            continue
        checked += 1
        exact = np.linalg.inv(A)
        assert np.max(np.abs(task_inertia(A, 1.0 / CAP) - exact)) <= 1e-12 * np.max(np.abs(exact))
    assert checked > 100


def test_damping_starts_without_a_step():
    """Λ is continuous, with a continuous slope, where λ_min crosses 1/cap: on
    A(t) = R diag(t, 1) Rᵀ the one-sided difference quotients at t = λ₀ agree. A
    damping that starts at a non-zero δ², or grows linearly, fails."""
    lam0 = 1.0 / CAP
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.array([[c, -s], [s, c]])

    def L(t):
        return task_inertia(R @ np.diag([t, 1.0]) @ R.T, lam0)

    h = 1e-7 * lam0
    assert np.max(np.abs(L(lam0 + h) - L(lam0 - h))) < 1e-5 * np.max(np.abs(L(lam0)))
    right = (L(lam0 + 2 * h) - L(lam0)) / (2 * h)
    left = (L(lam0) - L(lam0 - 2 * h)) / (2 * h)
    assert np.max(np.abs(right - left)) < 1e-4 * np.max(np.abs(right))


def test_lambda_is_bounded_into_the_stretched_pose():
    """Bending the arm straight (q₂…q₄ → 0), the exact Λ blows up; the capped Λ stays
    finite and below 4/3 of the cap."""
    arm = paper_arm()
    largest = []
    for e in np.concatenate([np.geomspace(0.3, 1e-6, 200), [0.0]]):
        T = terms_at(arm, [0.4, e, -e, e], np.zeros(4), coriolis=False)
        L = task_inertia(T.J @ np.linalg.inv(T.H) @ T.J.T, 1.0 / CAP)
        assert np.all(np.isfinite(L))
        largest.append(np.linalg.eigvalsh(L)[-1])
    assert max(largest) <= 4.0 / 3.0 * CAP * (1 + 1e-9)
    assert max(largest) > 0.5 * CAP  # the cap is what bounds it here
    T = terms_at(arm, [0.4, 1e-4, -1e-4, 1e-4], np.zeros(4), coriolis=False)
    exact = task_space_inertia(T.J, np.linalg.inv(T.H))
    assert np.linalg.eigvalsh(exact)[-1] > 1e3 * CAP  # without the cap it would be huge


@pytest.mark.parametrize("stretch", [0.0, 1e-3])
def test_controller_torque_is_finite_and_bounded_at_the_stretched_arm(stretch):
    """The whole controller at (and 1e-3 rad from) the singular stretched pose, with a
    tracking error of 1 cm and a measured force: τ finite and of the order of the
    gains × the capped inertia, not the 1e6 N m the exact Λ would give."""
    from test_controller import fig3_controller

    from nsdrake.experiment.scenario import load_scenario

    controller, station, _ = fig3_controller(load_scenario("fig3"))
    context = controller.CreateDefaultContext()
    q = np.array([0.4, stretch, -stretch, stretch])
    controller.GetInputPort("estimated_state").FixValue(context, np.concatenate([q, np.full(4, 0.1)]))
    x = controller.GetOutputPort("task_position").Eval(context)
    for name, value in (
        ("measured_wrench", [0, 0, 0, 1.0, 5.0, 0]),
        ("desired_position", x + [0.01, 0.01]),
        ("desired_velocity", [0.0, 0.0]),
        ("desired_acceleration", [0.0, 0.0]),
        ("desired_force", [10.0]),
    ):
        controller.GetInputPort(name).FixValue(context, value)
    tau = controller.GetOutputPort("generalized_force").Eval(context)
    assert np.all(np.isfinite(tau))
    assert np.max(np.abs(tau)) < 1e3


def test_the_cap_is_judged_in_each_parts_own_unit():
    """A pose task's Λ has kg on its translational rows and kg m² on its rotational ones
    (issue 18, item 7), so each part has its own cap and the cap is judged on the
    dimensionless F^{-1/2} A F^{-1/2}. Then a change of length unit for the translation
    (m to mm: J's translational rows ×1e3, A' = D A D with D = diag(1e3 I, I), Λ's
    translational block and its cap ×1e-6, the floor 1/cap ×1e6) gives Λ' = D⁻¹ Λ D⁻¹
    exactly, whether the cap binds or not. Catches one number compared with eigenvalues that mix the
    parts: the old rule, inactive in metres, switches on in millimetres. Here the
    rotational part (about 2 kg m²) is above its 1 kg m² cap and the translational part
    (about 5 kg) far below its 50 kg."""
    rng = np.random.default_rng(7)
    coupling = 0.02 * rng.standard_normal((3, 3))
    A = np.block([[np.diag([0.2, 0.25, 0.3]), coupling], [coupling.T, np.diag([0.5, 0.6, 0.7])]])
    floor_t, floor_r = 1.0 / 50.0, 1.0 / 1.0
    D = np.diag([1e3, 1e3, 1e3, 1.0, 1.0, 1.0])
    Di = np.linalg.inv(D)
    L = task_inertia(A, floor_t, floor_r, 3)
    L_mm = task_inertia(D @ A @ D, 1e6 * floor_t, floor_r, 3)
    np.testing.assert_allclose(L_mm, Di @ L @ Di, rtol=1e-9, atol=0)
    assert np.abs(L - np.linalg.inv(A)).max() > 1e-3  # the rotational cap binds
    # one number for both parts does not transform so
    L_one = task_inertia(A, floor_t)
    L_one_mm = task_inertia(D @ A @ D, 1e6 * floor_t)
    np.testing.assert_allclose(L_one, np.linalg.inv(A), rtol=1e-12)  # inactive in metres
    assert np.abs(L_one_mm - Di @ L_one @ Di).max() > 1e-3 * np.abs(L_one).max()  # active in mm

"""The null-space laws of issue 19, each on its own (nsdrake.control.null_space_laws).

Each law's defining property, at seeded random states of the Panda (pose task, one
redundant joint) and of the paper's planar arm (position task, two), against matrices
formed here with NumPy (tests/reference_math.py), not by the functions under test:

- dynamically consistent posture PD: J H⁻¹ τ₀ = 0 (no task acceleration), and τ₀ equals
  (I − Jᵀ J̄ᵀ) H (K_ns (q_d − q) − D_ns q̇);
- kinematic posture PD: (Jᵀ)⁺ τ₀ = 0 (no task force), while J H⁻¹ τ₀ is not zero (the
  task acceleration the comparison measures), and τ₀ equals (I − Jᵀ(Jᵀ)⁺)(K (q_d − q) − D q̇);
  with franka_ros's damped inverse (λ = 0.2) τ₀ equals the projector built from the SVD of
  Jᵀ with the singular values σ/(σ² + λ²), and leaves λ²/(σ² + λ²) of τ_p along each left
  singular vector of Jᵀ;
- dynamically consistent torque PD (mjctrl's form, no H): J H⁻¹ τ₀ = 0, and τ₀ equals
  (I − Jᵀ J̄ᵀ)(K (q_d − q) − D q̇);
- the paper's law with the posture criterion: J H⁻¹ τ₀ = 0 (Eq. 11).

The same properties through the controller's stage (ControllerStep, the code all three
ways run), so a law wired to the other law's projector fails here: checked by hand by
swapping the two projectors in stages._posture_law (both tests below then fail).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import panda_arm, panda_configurations, paper_arm
from models import random_states
from reference_math import dynamically_consistent_inverse

from nsdrake import ControllerConfig, ControllerModel, ControllerStep
from nsdrake.control.config import DesiredNullSpaceConfig, NullSpaceConfig, PostureConfig
from nsdrake.control.criteria.posture import posture_criterion
from nsdrake.control.null_space_laws import (
    dynamically_consistent_posture_torque,
    dynamically_consistent_torque_pd,
    kinematic_posture_torque,
    posture_target,
)
from nsdrake.control.validation import ControllerConfigError, config_problems
from nsdrake.station.models import models_dir

ZERO = 1e-10  # relative: ‖property‖ / ‖the same map applied to the unprojected torque‖


def states(arm, count, seed):
    if arm.n == 7:
        rng = np.random.default_rng(seed)
        for q in panda_configurations(count, seed):
            yield q, rng.standard_normal(7)
    else:
        yield from random_states(arm.n, count, seed)


def arms():
    return [panda_arm(), paper_arm()]


def terms(arm, q, v):
    return arm.terms(arm.plant.CreateDefaultContext(), q, v, coriolis=False)


@pytest.mark.parametrize("arm", arms(), ids=["panda", "arm4"])
def test_dynamically_consistent_posture_pd_causes_no_task_acceleration(arm):
    rng = np.random.default_rng(1)
    for q, v in states(arm, 12, seed=2):
        T = terms(arm, q, v)
        q_d = q + rng.uniform(-0.5, 0.5, arm.n)
        tau0 = dynamically_consistent_posture_torque(T.H, T.H_inv, T.J, q, v, q_d, 400.0, 40.0)
        a = T.H @ (400.0 * (q_d - q) - 40.0 * v)
        J_bar = dynamically_consistent_inverse(T.J, T.H_inv)
        expected = (np.eye(arm.n) - T.J.T @ J_bar.T) @ a
        assert np.linalg.norm(tau0 - expected) <= 1e-9 * np.linalg.norm(a)
        assert np.linalg.norm(T.J @ T.H_inv @ tau0) <= ZERO * np.linalg.norm(T.J @ T.H_inv @ a)


@pytest.mark.parametrize("arm", arms(), ids=["panda", "arm4"])
def test_kinematic_posture_pd_exerts_no_task_force_but_accelerates_the_task(arm):
    rng = np.random.default_rng(3)
    accelerations = []
    for q, v in states(arm, 12, seed=4):
        T = terms(arm, q, v)
        q_d = q + rng.uniform(-0.5, 0.5, arm.n)
        K, D = 10.0, 0.7
        tau0 = kinematic_posture_torque(T.J, q, v, q_d, K, D, 0.0)
        tau_p = K * (q_d - q) - D * v
        Jt_pinv = np.linalg.pinv(T.J.T)
        assert np.linalg.norm(tau0 - (tau_p - T.J.T @ (Jt_pinv @ tau_p))) <= 1e-9 * np.linalg.norm(tau_p)
        assert np.linalg.norm(Jt_pinv @ tau0) <= ZERO * np.linalg.norm(Jt_pinv @ tau_p)
        accelerations.append(np.linalg.norm(T.J @ T.H_inv @ tau0) / np.linalg.norm(T.J @ T.H_inv @ tau_p))
    assert min(accelerations) > 1e-3  # τ₀ moves the task at every state: not a DC projector


@pytest.mark.parametrize("arm", arms(), ids=["panda", "arm4"])
def test_damped_kinematic_projector_is_franka_ros_svd_form(arm):
    """τ₀ with λ = 0.2 against (I − Jᵀ M)τ_p, M = V diag(σ/(σ² + λ²)) Uᵀ from the SVD
    Jᵀ = U Σ Vᵀ (the damped pseudo-inverse as franka_ros's example forms it), to 1e-9;
    and the share of τ_p left along Jᵀ's i-th left singular vector u_i is λ²/(σ_i² + λ²).
    Catches λ entering unsquared, the damping on the wrong side of J, or λ ignored."""
    lam, K, D = 0.2, 10.0, 0.7
    rng = np.random.default_rng(8)
    for q, v in states(arm, 8, seed=9):
        T = terms(arm, q, v)
        q_d = q + rng.uniform(-0.5, 0.5, arm.n)
        tau_p = K * (q_d - q) - D * v
        U, sigma, Vt = np.linalg.svd(T.J.T, full_matrices=False)
        M = Vt.T @ np.diag(sigma / (sigma**2 + lam**2)) @ U.T
        tau0 = kinematic_posture_torque(T.J, q, v, q_d, K, D, lam)
        expected = tau_p - T.J.T @ (M @ tau_p)
        assert np.linalg.norm(tau0 - expected) <= 1e-9 * np.linalg.norm(tau_p)
        np.testing.assert_allclose(
            U.T @ tau0, lam**2 / (sigma**2 + lam**2) * (U.T @ tau_p), rtol=1e-8, atol=1e-12
        )


@pytest.mark.parametrize("arm", arms(), ids=["panda", "arm4"])
def test_dynamically_consistent_torque_pd_is_the_projected_torque_pd(arm):
    """τ₀ = (I − Jᵀ J̄ᵀ)(K (q_d − q) − D q̇) with J̄ formed here, to 1e-9, and J H⁻¹ τ₀ = 0.
    Catches an H left in (the other form) or the Euclidean projector in its place."""
    rng = np.random.default_rng(10)
    for q, v in states(arm, 12, seed=11):
        T = terms(arm, q, v)
        q_d = q + rng.uniform(-0.5, 0.5, arm.n)
        tau_p = 12.0 * (q_d - q) - 0.9 * v
        tau0 = dynamically_consistent_torque_pd(T.H_inv, T.J, q, v, q_d, 12.0, 0.9)
        J_bar = dynamically_consistent_inverse(T.J, T.H_inv)
        expected = (np.eye(arm.n) - T.J.T @ J_bar.T) @ tau_p
        assert np.linalg.norm(tau0 - expected) <= 1e-9 * np.linalg.norm(tau_p)
        assert np.linalg.norm(T.J @ T.H_inv @ tau0) <= ZERO * np.linalg.norm(T.J @ T.H_inv @ tau_p)


def test_posture_criterion_gradient_matches_finite_differences():
    rng = np.random.default_rng(5)
    q, q_d, w = rng.uniform(-2, 2, 7), rng.uniform(-2, 2, 7), rng.uniform(0.5, 2, 7)
    p, Phi = posture_criterion(q, q_d, w)
    assert p == pytest.approx(0.5 * np.sum(w * (q - q_d) ** 2), rel=1e-14)
    h = 1e-6
    fd = [(posture_criterion(q + h * e, q_d, w)[0] - posture_criterion(q - h * e, q_d, w)[0]) / (2 * h)
          for e in np.eye(7)]  # fmt: skip
    np.testing.assert_allclose(Phi, fd, rtol=1e-7, atol=1e-9)


def test_posture_target_moves_by_the_offset_with_a_smoothstep():
    q_d, offset = np.array([0.1, 0.2]), np.array([1.0, -2.0])
    np.testing.assert_array_equal(posture_target(q_d, offset, 0.9, 1.0, 0.5), q_d)
    np.testing.assert_allclose(posture_target(q_d, offset, 1.25, 1.0, 0.5), q_d + 0.5 * offset, rtol=1e-15)
    np.testing.assert_allclose(posture_target(q_d, offset, 2.0, 1.0, 0.5), q_d + offset, rtol=1e-15)
    np.testing.assert_allclose(posture_target(q_d, offset, 1.0, 1.0, 0.0), q_d + offset, rtol=1e-15)


# --- through the controller's stage -------------------------------------------------------------

PANDA_JOINTS = tuple(f"panda_joint{k}" for k in range(1, 8))


def panda_step(law: str, **ns) -> ControllerStep:
    model = ControllerModel.from_urdf(
        str(models_dir() / "panda.urdf"), tool_frame="tool", task_axes=("x", "y", "z", "rx", "ry", "rz")
    )
    source = "posture" if law == "paper" else "criteria"
    # Eq. 30's gain only where the posture source reads it (an unused one is refused)
    # a posture within the joints' limits (urdf/README's start, moved by 0.1 k rad on joint k)
    start = (0.0, 0.182, 0.0, -2.4, 0.0, 2.582, 0.785)
    posture = PostureConfig(
        q_d={j: start[k] + 0.1 * k for k, j in enumerate(PANDA_JOINTS)}, gain=-0.3 if law == "paper" else 0.0
    )
    config = ControllerConfig(
        null_space=NullSpaceConfig(law=law, **ns),
        desired_null_space=DesiredNullSpaceConfig(source=source, posture=posture),
    )
    config.desired_null_space.criteria.joint_limits.gain = 0.0
    config.actuator_limits.torque = dict.fromkeys(PANDA_JOINTS, 1e6)  # random states: no limit binds
    # Λ uncapped: the cap damps J̄ near singular poses (README), and Eq. 11 holds below it only
    config.impedance.max_task_inertia = config.impedance.max_task_rotational_inertia = np.inf
    return ControllerStep(controller_model=model, normal=[0.0, 0.0, -1.0], config=config)


def stage_torques(step: ControllerStep, count: int, seed: int):
    """(terms, τ₀) of the controller's stage at seeded random states (one fresh tick each)."""
    arm = step.model.arm
    rng = np.random.default_rng(seed)
    zero3 = np.zeros(3)
    for q, v in states(arm, count, seed):
        step.reset()
        x = terms(arm, q, v).x
        step.step(0.0, q, v, np.zeros(6), x + rng.uniform(-0.01, 0.01, 3), zero3, zero3, 5.0,
                  np.array([1.0, 0.0, 0.0, 0.0]), zero3, zero3)  # fmt: skip
        assert step.result.saturation[0] == 1.0  # τ₀ as the law gave it
        yield terms(arm, q, v), step.result.null_space_torque.copy()


@pytest.mark.parametrize(
    "law, gains",
    [("dynamically_consistent_posture_pd", {"posture_stiffness": 400.0, "posture_damping": 40.0}),
     ("dynamically_consistent_torque_pd", {"posture_stiffness": 10.0, "posture_damping": 1.0}),
     ("paper", {})],
)  # fmt: skip
def test_stage_dynamically_consistent_laws_cause_no_task_acceleration(law, gains):
    for T, tau0 in stage_torques(panda_step(law, **gains), 8, seed=6):
        assert np.linalg.norm(tau0) > 1e-6  # the law acts
        scale = np.linalg.norm(T.J @ T.H_inv) * np.linalg.norm(tau0)
        assert np.linalg.norm(T.J @ T.H_inv @ tau0) <= ZERO * scale


def test_stage_kinematic_law_uses_the_moore_penrose_projector():
    step = panda_step("kinematic_posture_pd", posture_stiffness=10.0, posture_damping=1.0)
    for T, tau0 in stage_torques(step, 8, seed=7):
        Jt_pinv = np.linalg.pinv(T.J.T)
        scale = np.linalg.norm(Jt_pinv) * np.linalg.norm(tau0)
        assert np.linalg.norm(Jt_pinv @ tau0) <= ZERO * scale
        assert np.linalg.norm(T.J @ T.H_inv @ tau0) > 1e-3 * np.linalg.norm(T.J @ T.H_inv) * np.linalg.norm(
            tau0
        )


ARM4_JOINTS = ("joint1", "joint2", "joint3", "joint4")


@pytest.mark.parametrize(
    "weight, w",
    [({"joint2": 3.0}, [1.0, 3.0, 1.0, 1.0]), ({}, [1.0, 1.0, 1.0, 1.0])],
    ids=["one joint weighted", "no weight given"],
)
def test_posture_criterion_pulls_an_unweighted_joint_with_weight_one(weight, w):
    """The paper's law with the posture criterion (source: posture): q̇_dⁿ = K N H⁻¹ W (q − q_d)
    (Eq. 30, W = diag(w)) at seeded states of the paper's arm, a joint missing from
    ``posture.weight`` weighing 1 as the configuration says, against N and H⁻¹ formed here
    from the plant's terms (1e-9 relative). Catches a missing joint weighing 0 (not pulled
    towards q_d at all), or the weight given to the wrong joint."""
    model = ControllerModel.from_urdf(
        str(models_dir() / "arm4.urdf"), tool_frame="tool", task_axes=("x", "y")
    )
    q_d = dict(zip(ARM4_JOINTS, [0.5, 1.1, 0.8, 0.3], strict=True))
    posture = PostureConfig(q_d=q_d, weight=weight, gain=-0.2)
    config = ControllerConfig(desired_null_space=DesiredNullSpaceConfig(source="posture", posture=posture))
    config.desired_null_space.criteria.obstacle.gain = 0.0  # the URDF alone knows no obstacles
    config.impedance.max_task_inertia = np.inf  # N from the exact J̄
    step = ControllerStep(controller_model=model, normal=[0.0, 1.0], config=config)
    arm = model.arm
    for q, v in random_states(4, 6, seed=8):
        step.reset()
        T = terms(arm, q, v)
        step.step(0.0, q, v, np.zeros(6), T.x, np.zeros(2), np.zeros(2), 0.0)
        H_inv = np.linalg.inv(T.H)
        N = np.eye(4) - dynamically_consistent_inverse(T.J, H_inv) @ T.J
        expected = -0.2 * N @ H_inv @ (np.asarray(w) * (q - list(q_d.values())))
        got = step.result.desired_null_space_velocity
        assert np.linalg.norm(got - expected) <= 1e-9 * np.linalg.norm(expected)


# --- configuration --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "change, where",
    [
        ({"law": "khatib"}, "null_space.law"),
        ({"law": "paper", "posture_stiffness": 3.0}, "null_space.posture_stiffness"),
        ({"law": "kinematic_posture_pd"}, "null_space.posture_stiffness"),
        ({"law": "kinematic_posture_pd", "posture_stiffness": 3.0}, "null_space.posture_damping"),
        ({"law": "kinematic_posture_pd", "posture_stiffness": 3.0, "posture_damping": 1.0,
          "projector_damping": -0.1}, "null_space.projector_damping"),
        ({"law": "dynamically_consistent_posture_pd", "posture_stiffness": 3.0},
         "null_space.posture_damping"),
        ({"law": "dynamically_consistent_torque_pd", "posture_stiffness": 3.0, "posture_damping": 1.0,
          "projector_damping": 0.2}, "null_space.projector_damping"),
        ({"law": "paper", "projector_damping": 0.2}, "null_space.projector_damping"),
    ],
)  # fmt: skip
def test_law_fields_are_checked(change, where):
    config = ControllerConfig()
    config.null_space = dataclasses.replace(config.null_space, **change)
    assert where in [w for w, _ in config_problems(config)]


def test_posture_objective_needs_every_joint():
    with pytest.raises(ControllerConfigError, match=r"posture\.q_d.*missing panda_joint7"):
        step = panda_step("paper")
        config = step.config
        del config.desired_null_space.posture.q_d["panda_joint7"]
        ControllerStep(controller_model=step.model, normal=[0.0, 0.0, -1.0], config=config)


def test_posture_gain_must_minimise():
    config = ControllerConfig()
    config.desired_null_space.posture.gain = 0.5
    assert "desired_null_space.posture.gain" in [w for w, _ in config_problems(config)]

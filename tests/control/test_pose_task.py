"""Pose tasks on the Panda: the spatial Jacobian's task rows and their ∂J/∂q, the
orientation error, and the controller's τ for a 6-D (and a 3-D) task against an
independent rebuild from plain plant calls.

Tolerances: analytic against AutoDiff or Drake's own calls is the same algebra in
another order, exact to rounding (~1e-15 relative); 1e-10 leaves room for
conditioning. Central differences of the orientation error with h = 1e-6 have
truncation O(h²) and rounding O(ε/h) ≈ 1e-10, checked to 1e-7.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import PANDA_POSE_AXES, PANDA_Q0, panda_arm, panda_configurations, terms_at
from drake_reference import AutoDiffArm, christoffel_C, plant_terms
from pydrake.common.eigen_geometry import AngleAxis, Quaternion
from pydrake.math import RotationMatrix
from reference_math import null_space_projector, task_space_inertia, task_velocity_compensation

from nsdrake import ControllerConfig, ControllerModel, NullSpaceImpedanceController
from nsdrake.control.controller import ControllerConfigError
from nsdrake.control.dynamics import ArmModel
from nsdrake.control.orientation import (
    orientation_error,
    quaternion_to_rotation,
    rotation_log,
    rotation_to_quaternion,
)
from nsdrake.station.models import models_dir

EXACT = 1e-10
FD = 1e-7
PANDA = models_dir() / "panda.urdf"


def close(a, b, tol):
    scale = max(1.0, float(np.max(np.abs(b))))
    return np.max(np.abs(np.asarray(a) - np.asarray(b))) <= tol * scale


@pytest.fixture(scope="module")
def panda():
    return panda_arm()


def random_velocity(rng):
    return rng.uniform(-1.0, 1.0, 7)


# ---------------------------------------------------------------- the task rows of J


def test_pose_jacobian_rows_are_the_spatial_jacobians(panda):
    """J's rows for (x, y, z, rx, ry, rz) are J_v then J_w of the tool, and x, R_WT are the
    tool's pose, all against plain plant calls; J̇ q̇ is the tool's spatial acceleration
    bias [a; α] (CalcBiasSpatialAcceleration). Catches rotational rows taken from the
    wrong half of the spatial Jacobian, in the wrong order, or a J̇ q̇ that drops the
    angular bias."""
    rng = np.random.default_rng(1)
    for q in panda_configurations(15, seed=1):
        v = random_velocity(rng)
        T, ref = terms_at(panda, q, v), plant_terms(panda, q, v)
        for name in ("J", "x", "R_WT", "Jdot_v"):
            assert close(getattr(T, name), ref[name], EXACT), name
        assert close(T.J[:3], ref["J_spatial"][3:], EXACT) and close(T.J[3:], ref["J_spatial"][:3], EXACT)


def test_angular_rows_of_dJ_dq_match_autodiff(panda):
    """∂J/∂q_k (n × 6 × 7) from the analytic formula (w_k × J_w,i for k inboard of i) against
    Drake's AutoDiffXd of the spatial Jacobian, at 25 random Panda poses and 5 near
    singular ones. Catches a missing angular term, one that also applies the outboard
    rule to the angular rows (axes do not move with outboard joints), or a sign error."""
    ad = AutoDiffArm(panda)
    for q in panda_configurations(25, seed=2, near_singular=5):
        dJ = terms_at(panda, q, np.zeros(7), coriolis=False).dJ_dq
        assert dJ.shape == (7, 6, 7)
        assert close(dJ, ad.dJ_dq(q), EXACT)


@pytest.mark.parametrize(
    "axes", [("x", "y", "z"), ("x", "z", "ry"), ("rx", "ry", "rz"), ("y", "rz")], ids=lambda a: "-".join(a)
)
def test_partial_task_axes_select_rows_and_their_partials(axes):
    """Any subset of the six axes (translational first) gives those rows of J and of ∂J/∂q
    (AutoDiff) on the Panda: 3-D position only, mixed, rotations only. Catches rows
    indexed by the axis's position in the list instead of its world axis."""
    arm = panda_arm(axes)
    ad = AutoDiffArm(arm)
    full = panda_arm()
    index = {a: i for i, a in enumerate(PANDA_POSE_AXES)}
    for q in panda_configurations(5, seed=3):
        T, F = terms_at(arm, q, np.zeros(7), False), terms_at(full, q, np.zeros(7), False)
        assert close(T.J, F.J[[index[a] for a in axes]], EXACT)
        assert close(T.dJ_dq, ad.dJ_dq(q), EXACT)


@pytest.mark.parametrize("axes", [("rx", "x"), ("x", "x"), ("x", "roll"), ()])
def test_task_axes_are_refused_in_one_line(panda, axes):
    """Unknown, repeated, empty or rotational-before-translational axes are a one-line
    ValueError naming the axes. Catches axes that would silently take the wrong rows of
    the spatial Jacobian (a rotation listed first would be read as a position row)."""
    with pytest.raises(ValueError, match="task axes") as error:
        ArmModel(panda.plant, panda.tool_frame, axes)
    assert "\n" not in str(error.value)


def test_a_task_the_arm_cannot_span_is_refused():
    """A planar arm asked for a vertical axis (its J row for z is zero at every pose), or
    for a rotation out of its plane, is refused by the controller with one line that
    names the axis. Catches a controller that builds and then divides by a singular
    J H⁻¹ Jᵀ."""
    from conftest import paper_arm

    urdf = models_dir() / "arm4.urdf"
    for axes, missing in ((("x", "y", "z"), "z"), (("x", "rx"), "rx")):
        with pytest.raises(ControllerConfigError, match=f"cannot span.*{missing}") as error:
            NullSpaceImpedanceController(
                controller_model=ControllerModel.from_urdf(urdf, tool_frame="tool", task_axes=axes),
                normal=[1.0] + [0.0] * (len([a for a in axes if not a.startswith("r")]) - 1),
                config=ControllerConfig(),
            )
        assert "\n" not in str(error.value)
    assert paper_arm().m == 2  # the planar task itself is fine


# ---------------------------------------------------------------- the orientation error


def random_rotation(rng, angle=None):
    u = rng.standard_normal(3)
    u /= np.linalg.norm(u)
    angle = rng.uniform(0.0, np.pi) if angle is None else angle
    return AngleAxis(angle, u).rotation(), angle, u


def test_orientation_error_is_zero_iff_aligned_and_its_size_is_the_angle():
    """e_o = log(R_d Rᵀ): exactly zero for R_d = R; otherwise ‖e_o‖ is the angle of R_d Rᵀ
    (Drake's AngleAxis) and e_o is along its axis, from 1e-9 rad to π − 1e-9 (both ends
    of the series and of the near-π branch). Catches log(Rᵀ R_d) (the body-frame error:
    right size, wrong axis), sin θ u (size wrong beyond small angles), an arccos that
    loses small angles, and an axis lost near π."""
    rng = np.random.default_rng(4)
    for _ in range(20):
        R, _, _ = random_rotation(rng)
        assert np.array_equal(orientation_error(R, R), np.zeros(3))
    for angle in (1e-9, 1e-6, 1e-4, 1e-2, 0.5, 2.0, 3.0, 3.1, np.pi - 1e-6, np.pi - 1e-9):
        for _ in range(5):
            R, _, _ = random_rotation(rng)
            R_e, _, u = random_rotation(rng, angle)
            e = orientation_error(R_e @ R, R)
            # R_e R and R_d Rᵀ carry ~1e-16 of rounding: absolute 1e-14 besides relative 1e-9.
            assert abs(np.linalg.norm(e) - angle) <= 1e-12 * max(1.0, angle)
            if angle < 3.14:
                assert np.linalg.norm(e - angle * u) <= 1e-9 * angle + 1e-14
            else:  # within 1e-6 of π the axis is known to ~1e-8 (sin θ ~ 1e-6), either sign: one rotation
                assert min(np.linalg.norm(e - angle * u), np.linalg.norm(e + angle * u)) <= 1e-6


def test_orientation_error_rate_and_the_angle_identity():
    """Along R(t) = exp([ω t]×) R₀ and R_d(t) = exp([ω_d t]×) R_d0, the central difference of
    e_o equals J_l⁻¹(e_o)(ω_d − R_e ω) (R_e = R_d Rᵀ, J_l the left Jacobian of SO(3)), and
    e_oᵀ ė_o = e_oᵀ (ω_d − ω): the identity behind the closed loop's energy function
    (nsdrake.control.orientation). Catches an error measure whose angle does not change at the
    rate of the angular-velocity error along its axis (e.g. the body-frame log with
    world-frame ω, or the quaternion vector part)."""
    rng = np.random.default_rng(5)
    h = 1e-6
    for _ in range(30):
        R0, _, _ = random_rotation(rng)
        R_e, _, _ = random_rotation(rng, rng.uniform(0.05, 2.8))
        R_d0 = R_e @ R0
        w, w_d = rng.standard_normal(3), rng.standard_normal(3)

        def e_at(t, R0=R0, R_d0=R_d0, w=w, w_d=w_d):
            R = AngleAxis(np.linalg.norm(w) * t, w / np.linalg.norm(w)).rotation() @ R0
            R_d = AngleAxis(np.linalg.norm(w_d) * t, w_d / np.linalg.norm(w_d)).rotation() @ R_d0
            return orientation_error(R_d, R)

        e = e_at(0.0)
        rate = (e_at(h) - e_at(-h)) / (2 * h)
        theta = np.linalg.norm(e)
        K = np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
        coefficient = 1 / theta**2 - (1 + np.cos(theta)) / (2 * theta * np.sin(theta))
        J_l_inv = np.eye(3) - 0.5 * K + coefficient * K @ K
        assert close(rate, J_l_inv @ (w_d - R_e @ w), FD)
        assert abs(e @ rate - e @ (w_d - w)) <= FD * max(1.0, np.linalg.norm(e) * np.linalg.norm(w_d - w))


def test_quaternions_round_trip():
    """[w, x, y, z] → R → [w, x, y, z] (w ≥ 0) against Drake's Quaternion, unnormalised
    input normalised. Catches an [x, y, z, w] ordering or a transposed matrix."""
    rng = np.random.default_rng(6)
    for _ in range(20):
        q = rng.standard_normal(4)
        q /= np.linalg.norm(q)
        R = quaternion_to_rotation(3.0 * q)
        assert close(R, RotationMatrix(Quaternion(q)).matrix(), 1e-14)
        assert close(rotation_to_quaternion(R), q * np.sign(q[0]), 1e-14)
    assert np.array_equal(rotation_log(np.eye(3)), np.zeros(3))


# ---------------------------------------------------------------- the controller's τ


def panda_controller(axes, rotate_gradient: bool = True, **criteria):
    """The controller on urdf/panda.urdf for ``axes``, pushing along world −z, with the
    joint-torque and manipulability criteria on (gains overridable)."""
    config = ControllerConfig()
    config.desired_null_space.rotate_gradient = rotate_gradient
    crit = config.desired_null_space.criteria
    crit.joint_torque.gain = criteria.get("joint_torque", -0.002)
    crit.manipulability.gain = criteria.get("manipulability", 0.5)
    model = ControllerModel.from_urdf(PANDA, tool_frame="tool", task_axes=axes)
    m_t = model.arm.m_t
    normal = np.zeros(m_t)
    normal[list(model.arm.rows).index(2) if 2 in model.arm.rows else 0] = -1.0
    return NullSpaceImpedanceController(controller_model=model, normal=normal, config=config), config


def fixed_pose_inputs(controller, context, q, v, rng):
    m_t = controller.model.arm.m_t
    x = plant_terms(panda_arm(), q, v)["p_WT"][controller.model.arm.rows]
    inputs = {
        "estimated_state": np.concatenate([q, v]),
        "measured_wrench": rng.standard_normal(6) * [0.05, 0.05, 0.05, 1.0, 1.0, 5.0],
        "desired_position": x + 0.005 * rng.standard_normal(m_t),
        "desired_velocity": 0.01 * rng.standard_normal(m_t),
        "desired_acceleration": 0.1 * rng.standard_normal(m_t),
        "desired_force": [7.0],
    }
    if controller.model.arm.m_r:
        # 0.05 rad from the tool's orientation at q, as a non-unit quaternion (normalised inside)
        R = plant_terms(panda_arm(), q, v)["R_WT"]
        R_d = random_rotation(rng, 0.05)[0] @ R
        q_d = RotationMatrix(R_d).ToQuaternion()
        inputs["desired_orientation"] = 2.0 * np.array([q_d.w(), q_d.x(), q_d.y(), q_d.z()])
        inputs["desired_angular_velocity"] = 0.02 * rng.standard_normal(3)
        inputs["desired_angular_acceleration"] = 0.3 * rng.standard_normal(3)
    for name, value in inputs.items():
        controller.GetInputPort(name).FixValue(context, value)
    return inputs


def expected_pose_torque(arm, config, inputs, qdot_ns_d, previous):
    """τ of Eqs. 6–8 and 21 for a pose task from plain plant calls, Drake's AngleAxis for the
    orientation error, AutoDiff for J̄̇ and the Christoffel C: none of nsdrake's math."""
    n = arm.n
    q, v = inputs["estimated_state"][:n], inputs["estimated_state"][n:]
    ref = plant_terms(arm, q, v)
    H, J = ref["H"], ref["J"]
    H_inv = np.linalg.inv(H)
    Lam = task_space_inertia(J, H_inv)
    Jbar, Jbar_dot = AutoDiffArm(arm).Jbar_and_dot(q, v)
    N = null_space_projector(J, Jbar)
    imp = config.impedance
    W = inputs["measured_wrench"]  # about the tool point (no wrench_point)
    m_t, rot = arm.m_t, arm.rot_rows
    nrm = np.zeros(m_t)
    nrm[list(arm.rows).index(2) if 2 in arm.rows else 0] = -1.0
    P_n = np.outer(nrm, nrm)
    P_t = np.eye(m_t) - P_n
    e_x = inputs["desired_position"] - ref["x"]
    xdot = J @ v
    f_n = nrm @ W[3:][arm.rows]
    acc_t = (
        inputs["desired_acceleration"]
        + (imp.K_v_tangent * P_t + imp.K_v_normal * P_n) @ (inputs["desired_velocity"] - xdot[:m_t])
        + (imp.K_p_tangent * P_t + imp.K_p_normal * P_n) @ e_x
        + nrm * imp.K_f * (inputs["desired_force"][0] - f_n)
    )
    xddot_c = acc_t
    if len(rot):
        q_d = inputs["desired_orientation"] / np.linalg.norm(inputs["desired_orientation"])
        R_d = RotationMatrix(Quaternion(q_d)).matrix()
        aa = AngleAxis(R_d @ ref["R_WT"].T)
        e_o = (aa.angle() * aa.axis())[rot]
        acc_r = (
            inputs["desired_angular_acceleration"][rot]
            + imp.K_v_rotation * (inputs["desired_angular_velocity"][rot] - xdot[m_t:])
            + imp.K_p_rotation * e_o
        )
        xddot_c = np.concatenate([acc_t, acc_r])
    tau = J.T @ Lam @ (xddot_c - ref["Jdot_v"]) + ref["J_spatial"].T @ W + ref["Cv"] + ref["g"]
    ns = config.null_space
    e = qdot_ns_d - N @ v
    Jdot = AutoDiffArm(arm).Jdot(q, v)
    a = ns.K_n * e + (qdot_ns_d - previous) / config.period
    a = a + task_velocity_compensation(J, Jdot, Jbar, Jbar_dot, v)
    a = a + H_inv @ christoffel_C(arm, q, v) @ e
    return tau + H @ N @ a


@pytest.mark.parametrize("rotate_gradient", [True, False], ids=["rotate_gradient", "no rotate_gradient"])
@pytest.mark.parametrize("axes", [PANDA_POSE_AXES, ("x", "y", "z")], ids=["pose6", "position3"])
def test_panda_generalized_force_matches_an_independent_rebuild(axes, rotate_gradient):
    """τ of the whole controller for the Panda's full pose task (m = 6, one redundant
    joint) and its position task (m = 3, four), at fixed inputs near the table-wiping
    start and a stored previous q̇_dⁿ, against Eqs. 6–8 and 21 rebuilt from Drake's plant
    calls (spatial Jacobian, spatial bias acceleration), Drake's AngleAxis for the
    orientation error and AutoDiff for J̄̇ and C. The controller's terms come from
    Pinocchio, so agreement to 1e-10 is two independent computations agreeing. Catches a
    wrong or missing orientation term (sign, frame, ω_d or ω̇_d feed-forward), rows of
    Λ or J̇ q̇ mixed up, the measured moment left out of J_Tᵀ W_T, a force term acting on
    rotational rows, and any null-space term the fig3 rebuild catches. Crossed with the
    selector's rotate_gradient flag (a null-space setting, which must not change the task's
    kind: issue 46, mistake 10, the pose task chosen from the flag, lost its rotational
    torque with the flag off); two states with the flag off, four with it on."""
    controller, config = panda_controller(axes, rotate_gradient)
    assert controller.model.dynamics == "pinocchio"
    arm = panda_arm(axes)
    rng = np.random.default_rng(9)
    for _ in range(4 if rotate_gradient else 2):
        context = controller.CreateDefaultContext()
        q, v = PANDA_Q0 + 0.1 * rng.standard_normal(7), 0.05 * rng.standard_normal(7)
        inputs = fixed_pose_inputs(controller, context, q, v, rng)
        context.SetTime(1.0)
        selector = controller.GetSubsystemByName("priority_selector")
        selector.GetMyMutableContextFromRoot(context).get_mutable_discrete_state(0).SetFromVector(
            [2.0, 2.0, -np.inf]
        )
        qdot_ns_d = controller.GetOutputPort("desired_null_space_velocity").Eval(context)
        assert np.linalg.norm(qdot_ns_d) > 1e-4
        previous = qdot_ns_d + config.period * rng.standard_normal(7)  # q̈_dⁿ of ~1 rad/s²
        ns = controller.GetSubsystemByName("null_space_controller")
        ns.GetMyMutableContextFromRoot(context).get_mutable_discrete_state(0).SetFromVector(
            np.append(previous, 1.0)
        )
        got = controller.GetOutputPort("generalized_force").Eval(context)
        want = expected_pose_torque(arm, config, inputs, qdot_ns_d, previous)
        assert np.all(np.abs(want) < [87.0] * 4 + [12.0] * 3)  # no actuator limit binds
        assert np.max(np.abs(got - want)) <= EXACT * np.max(np.abs(want))


def test_rotational_ports_exist_only_for_rotational_tasks():
    """A pose task adds desired_orientation, desired_angular_velocity and
    desired_angular_acceleration; a position task has exactly fig3's ports. Catches
    ports that a position-only user would have to feed."""
    names = {
        axes: {controller.get_input_port(i).get_name() for i in range(controller.num_input_ports())}
        for axes in (PANDA_POSE_AXES, ("x", "y", "z"))
        for controller in [panda_controller(axes)[0]]
    }
    rotational = {"desired_orientation", "desired_angular_velocity", "desired_angular_acceleration"}
    assert rotational <= names[PANDA_POSE_AXES]
    assert not rotational & names[("x", "y", "z")]
    assert names[PANDA_POSE_AXES] - rotational == names[("x", "y", "z")]

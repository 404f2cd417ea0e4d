"""The primary task law (Eqs. 6–10): its LeafSystem against an independent rebuild
from plant calls, and its closed loop ẍ = ẍ_c.

Tolerance 1e-9 relative: the rebuild is the same algebra from Drake's own calls
(no nsdrake code), exact to rounding.
"""

from __future__ import annotations

import numpy as np
from conftest import terms_at
from drake_reference import plant_terms
from models import random_states
from pydrake.common.value import AbstractValue
from reference_math import task_space_inertia

from nsdrake import ControllerConfig, ControllerModel
from nsdrake.control.impedance import ImpedanceGains, command_acceleration, primary_torque, wrench_at_tool
from nsdrake.control.plan import ControllerPlan
from nsdrake.control.systems import ImpedanceController
from nsdrake.control.systems._values import TermsValue

TOL = 1e-9


def gains():
    return ImpedanceGains.along_surface(np.array([0.0, 1.0]), 400.0, 100.0, 40.0, 200.0, 1.5)


def test_gains_are_diagonal_in_the_surface_frame():
    n = np.array([1.0, 1.0]) / np.sqrt(2)
    g = ImpedanceGains.along_surface(n, 400.0, 100.0, 40.0, 200.0, 1.0)
    t = np.array([1.0, -1.0]) / np.sqrt(2)
    assert np.allclose(g.K_p @ n, 100 * n) and np.allclose(g.K_p @ t, 400 * t)
    assert np.allclose(g.K_v @ n, 200 * n) and np.allclose(g.K_v @ t, 40 * t)


def test_command_acceleration_signs_follow_eq10():
    """Behind the reference, slower than it, pressing too little: every term pushes forward."""
    g = gains()
    a = command_acceleration(
        x=np.array([0.0, 0.0]),
        xdot=np.array([0.0, 0.0]),
        x_d=np.array([0.01, 0.0]),
        xdot_d=np.array([0.1, 0.0]),
        xddot_d=np.zeros(2),
        F=np.array([0.0, 5.0]),
        f_d=10.0,
        gains=g,
    )
    assert np.isclose(a[0], 400 * 0.01 + 40 * 0.1)
    assert np.isclose(a[1], 1.5 * (10.0 - 5.0))


def impedance_plan(arm, p_WSo) -> ControllerPlan:
    """The plan of a controller on ``arm`` (Drake terms) with :func:`gains`' values."""
    config = ControllerConfig()
    imp = config.impedance
    imp.K_p_tangent, imp.K_p_normal, imp.K_v_tangent, imp.K_v_normal, imp.K_f = 400.0, 100.0, 40.0, 200.0, 1.5
    imp.max_task_inertia = np.inf
    model = ControllerModel.from_plant(arm.plant, tool_frame="tool", task_axes=("x", "y"))
    return ControllerPlan(model=model, config=config, normal=np.array([0.0, 1.0]), wrench_point=p_WSo)


def test_impedance_system_matches_an_independent_rebuild(arm4):
    rng = np.random.default_rng(51 + 1000)
    p_WSo = np.array([0.1, 0.6, 0.0])
    plan = impedance_plan(arm4, p_WSo)
    system = ImpedanceController(plan=plan)
    scratch = plan.create_scratch()
    for q, v in random_states(4, 10, seed=51):
        terms = plan.allocate_terms()
        plan.terms(scratch, q, v, terms)  # stage 1, the system's input
        ref = plant_terms(arm4, q, v)
        x_d, xd_d, xdd_d = rng.standard_normal((3, 2))
        f_d = 8.0
        W_So = rng.standard_normal(6)
        context = system.CreateDefaultContext()
        system.GetInputPort("robot_terms").FixValue(context, AbstractValue.Make(TermsValue(terms)))
        for name, value in (
            ("x_d", x_d),
            ("xdot_d", xd_d),
            ("xddot_d", xdd_d),
            ("f_d", [f_d]),
            ("measured_wrench", W_So),
        ):
            system.GetInputPort(name).FixValue(context, value)
        got = system.get_output_port().Eval(context)

        # Rebuild: move the moment to the tool point by hand, then Eqs. 6–8.
        f = W_So[3:]
        M_T = W_So[:3] + np.cross(p_WSo - ref["p_WT"], f)
        F = f[:2]
        x, xdot = ref["x"], ref["J"] @ v
        n, t = np.array([0.0, 1.0]), np.array([1.0, 0.0])
        xddot_c = (
            xdd_d
            + t * (40 * t @ (xd_d - xdot) + 400 * t @ (x_d - x))
            + n * (200 * n @ (xd_d - xdot) + 100 * n @ (x_d - x) + 1.5 * (f_d - n @ F))
        )
        Lam = task_space_inertia(ref["J"], np.linalg.inv(ref["H"]))
        expected = (
            ref["J"].T @ Lam @ (xddot_c - ref["Jdot_v"])
            + ref["J_spatial"][:3].T @ M_T
            + ref["J_spatial"][3:].T @ f
            + ref["Cv"]
            + ref["g"]
        )
        assert np.max(np.abs(got - expected)) <= TOL * np.max(np.abs(expected))


def test_closed_loop_task_acceleration_is_the_command(arm):
    """Eq. 10: with τ = primary + τ₀ (τ₀ in the null space) and the contact wrench W
    both acting and compensated, the forward dynamics give ẍ = J q̈ + J̇ q̇ = ẍ_c."""
    rng = np.random.default_rng(52 + 1000)
    for q, v in random_states(arm.n, 10, seed=52):
        T = terms_at(arm, q, v)
        xddot_c = rng.standard_normal(arm.m)
        W_T = rng.standard_normal(6)
        tau = primary_torque(T, xddot_c, W_T)
        # Eq. 5 with the wrench the tool exerts on the environment: H q̈ + C q̇ + g + J_Tᵀ W = τ
        qddot = T.H_inv @ (tau - T.Cv - T.g - T.J_spatial.T @ W_T)
        xddot = T.J @ qddot + T.Jdot_v
        assert np.max(np.abs(xddot - xddot_c)) <= TOL * max(1.0, np.max(np.abs(xddot_c)))


def test_wrench_transport():
    W = np.array([0.0, 0.0, 1.0, 2.0, 0.0, 0.0])  # 1 N m about z at So, 2 N along x
    out = wrench_at_tool(W, p_WSo=np.array([0.0, 1.0, 0.0]), p_WT=np.zeros(3))
    # M_T = M_So + (p_So − p_T) × f = [0,0,1] + [0,1,0] × [2,0,0] = [0, 0, 1 − 2]
    assert np.allclose(out, [0.0, 0.0, -1.0, 2.0, 0.0, 0.0])

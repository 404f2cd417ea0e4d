"""ImpedanceController: stage 4, the primary task law of Eqs. 6–8."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from nsdrake.control.plan import ControllerPlan
from nsdrake.control.stages import task_torque_stage
from nsdrake.control.systems._values import TermsValue


class ImpedanceController(LeafSystem):
    """τ − τ₀ = Jᵀ Λ (ẍ_c − J̇ q̇) + J_Tᵀ W_T + C q̇ + g, with
    ẍ_c = ẍ_d + K_v (ẋ_d − ẋ) + K_p (x_d − x) + n K_f (f_d − nᵀF)
    (:mod:`nsdrake.control.impedance` gives the law, why the measured wrench W_T
    replaces Eq. 6's F, and the law's steady-state force error).

    .. pydrake_system::

        name: ImpedanceController
        input_ports:
        - robot_terms
        - x_d
        - xdot_d
        - xddot_d
        - f_d
        - measured_wrench
        - R_d (with rotational task axes)
        - omega_d (with rotational task axes)
        - omegadot_d (with rotational task axes)
        output_ports:
        - generalized_force

    x_d, xdot_d, xddot_d have one entry per translational task axis (m_t) [m, m/s,
    m/s²]; f_d is the desired normal force [N]; ``measured_wrench`` is the sensor's
    [M_So; f] (6) [N m, N] about its origin So (the plan's wrench point; none: about
    the tool point), world; F is its force on the translational task rows and its
    moment at the tool point on the rotational ones. A task with rotational axes also
    takes the desired tool orientation ``R_d`` as a quaternion [w, x, y, z] (4), and
    ω_d, ω̇_d (3 each) [rad/s, rad/s²], world frame; their task rows enter the law with
    the orientation error log(R_d R_WTᵀ) (:mod:`nsdrake.control.orientation`).
    ``generalized_force`` (n) [N m] is in velocity order.
    """

    def __init__(self, *, plan: ControllerPlan):
        super().__init__()
        self._plan = plan
        m_t = plan.m_t
        self._terms = self.DeclareAbstractInputPort(
            "robot_terms", AbstractValue.Make(TermsValue(plan.allocate_terms()))
        )
        self._x_d = self.DeclareVectorInputPort("x_d", m_t)
        self._xdot_d = self.DeclareVectorInputPort("xdot_d", m_t)
        self._xddot_d = self.DeclareVectorInputPort("xddot_d", m_t)
        self._f_d = self.DeclareVectorInputPort("f_d", 1)
        self._wrench = self.DeclareVectorInputPort("measured_wrench", 6)
        inputs = [self._terms, self._x_d, self._xdot_d, self._xddot_d, self._f_d, self._wrench]
        self._rotation = None
        if plan.m_r:
            self._rotation = [
                self.DeclareVectorInputPort(name, size)
                for name, size in (("R_d", 4), ("omega_d", 3), ("omegadot_d", 3))
            ]
            inputs += self._rotation
        self._no_rotation = (np.zeros(4), np.zeros(3), np.zeros(3))
        self.DeclareVectorOutputPort(
            "generalized_force",
            plan.n,
            self._calc,
            prerequisites_of_calc={self.input_port_ticket(p.get_index()) for p in inputs},
        )

    def _calc(self, context, output):
        p = self._plan
        rotation = self._no_rotation
        if self._rotation is not None:
            rotation = [port.Eval(context) for port in self._rotation]
        task_torque_stage(
            self._terms.Eval(context).buffer, p.plan, p.index, p.dims, self._wrench.Eval(context),
            self._x_d.Eval(context), self._xdot_d.Eval(context), self._xddot_d.Eval(context),
            self._f_d.Eval(context)[0], *rotation, output.get_mutable_value(),
        )  # fmt: skip

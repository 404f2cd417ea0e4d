"""ImpedanceController: the primary task law of Eqs. 6–8."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from nsdrake.control.dynamics import RobotTerms
from nsdrake.control.impedance import (
    ImpedanceGains,
    command_acceleration_from_error,
    pose_error,
    position_task_torque,
    primary_torque,
    task_wrench,
    wrench_at_tool,
)
from nsdrake.control.orientation import quaternion_to_rotation


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
    [M_So; f] (6) [N m, N] about its origin So (``p_WSo``; None: about the tool
    point), world; F is its force on the translational task rows and its moment at
    the tool point on the rotational ones. A task with rotational axes
    (``rot_rows``) also takes the desired tool orientation ``R_d`` as a quaternion
    [w, x, y, z] (4), and ω_d, ω̇_d (3 each) [rad/s, rad/s²], world frame; their
    rows ``rot_rows`` enter the law with the orientation error log(R_d R_WTᵀ)
    (:mod:`nsdrake.control.orientation`). ``generalized_force`` (n) [N m] is in velocity order.
    """

    def __init__(
        self,
        *,
        gains: ImpedanceGains,
        task_rows: np.ndarray,
        p_WSo: np.ndarray | None,
        gravity_compensation: bool,
        model_terms: RobotTerms,
        rot_rows: np.ndarray = (),
    ):
        super().__init__()
        n = model_terms.n
        self._gains = gains
        self._p_WSo = None if p_WSo is None else np.asarray(p_WSo, dtype=float)
        self._rows = np.asarray(task_rows, dtype=int)
        self._rot_rows = np.asarray(rot_rows, dtype=int)
        self._gravity = gravity_compensation
        m = len(self._rows)
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        self._x_d = self.DeclareVectorInputPort("x_d", m)
        self._xdot_d = self.DeclareVectorInputPort("xdot_d", m)
        self._xddot_d = self.DeclareVectorInputPort("xddot_d", m)
        self._f_d = self.DeclareVectorInputPort("f_d", 1)
        self._wrench = self.DeclareVectorInputPort("measured_wrench", 6)
        inputs = (self._terms, self._x_d, self._xdot_d, self._xddot_d, self._f_d, self._wrench)
        if len(self._rot_rows):
            self._R_d = self.DeclareVectorInputPort("R_d", 4)
            self._omega_d = self.DeclareVectorInputPort("omega_d", 3)
            self._omegadot_d = self.DeclareVectorInputPort("omegadot_d", 3)
            inputs += (self._R_d, self._omega_d, self._omegadot_d)
        self.DeclareVectorOutputPort(
            "generalized_force",
            n,
            self._calc,
            prerequisites_of_calc={self.input_port_ticket(p.get_index()) for p in inputs},
        )

    def _calc(self, context, output):
        terms = self._terms.Eval(context)
        W = self._wrench.Eval(context)
        W_T = W if self._p_WSo is None else wrench_at_tool(W, self._p_WSo, terms.p_WT)
        if len(self._rot_rows):
            output.SetFromVector(self._pose_torque(context, terms, W_T))
            return
        tau = position_task_torque(
            terms,
            self._x_d.Eval(context),
            self._xdot_d.Eval(context),
            self._xddot_d.Eval(context),
            self._f_d.Eval(context)[0],
            W_T,
            self._rows,
            self._gains,
            self._gravity,
        )
        output.SetFromVector(tau)

    def _pose_torque(self, context, terms, W_T):
        rot = self._rot_rows
        error = pose_error(
            terms.x, self._x_d.Eval(context), terms.R_WT, quaternion_to_rotation(self._R_d.Eval(context)), rot
        )
        xdot_d = np.concatenate([self._xdot_d.Eval(context), self._omega_d.Eval(context)[rot]])
        xddot_d = np.concatenate([self._xddot_d.Eval(context), self._omegadot_d.Eval(context)[rot]])
        xddot_c = command_acceleration_from_error(
            error,
            terms.xdot,
            xdot_d,
            xddot_d,
            task_wrench(W_T, self._rows, rot),
            self._f_d.Eval(context)[0],
            self._gains,
        )
        return primary_torque(terms, xddot_c, W_T, self._gravity)

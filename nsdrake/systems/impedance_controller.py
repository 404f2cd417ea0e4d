"""ImpedanceController: the primary task law of Eqs. 6–8."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from ..dynamics import RobotTerms
from ..impedance import ImpedanceGains, command_acceleration, primary_torque, wrench_at_tool


class ImpedanceController(LeafSystem):
    """τ − τ₀ = Jᵀ Λ (ẍ_c − J̇ q̇) + J_Tᵀ W_T + C q̇ + g, with
    ẍ_c = ẍ_d + K_v (ẋ_d − ẋ) + K_p (x_d − x) + n K_f (f_d − nᵀF)
    (:mod:`nsdrake.impedance` gives the law, why the measured wrench W_T
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
        output_ports:
        - generalized_force

    Task-space inputs have m entries [m, m/s, m/s²]; f_d is the desired normal
    force [N]; ``measured_wrench`` is the sensor's [M_So; f] (6) [N m, N] about
    its origin So (``p_WSo``; None: about the tool point), world; the task rows of f are F.
    ``generalized_force`` (n) [N m] is in velocity order.
    """

    def __init__(
        self,
        *,
        gains: ImpedanceGains,
        task_rows: np.ndarray,
        p_WSo: np.ndarray | None,
        gravity_compensation: bool,
        model_terms: RobotTerms,
    ):
        super().__init__()
        n = model_terms.n
        self._gains = gains
        self._p_WSo = None if p_WSo is None else np.asarray(p_WSo, dtype=float)
        self._rows = np.asarray(task_rows)
        self._gravity = gravity_compensation
        m = len(self._rows)
        self._terms = self.DeclareAbstractInputPort("robot_terms", AbstractValue.Make(model_terms))
        self._x_d = self.DeclareVectorInputPort("x_d", m)
        self._xdot_d = self.DeclareVectorInputPort("xdot_d", m)
        self._xddot_d = self.DeclareVectorInputPort("xddot_d", m)
        self._f_d = self.DeclareVectorInputPort("f_d", 1)
        self._wrench = self.DeclareVectorInputPort("measured_wrench", 6)
        inputs = (self._terms, self._x_d, self._xdot_d, self._xddot_d, self._f_d, self._wrench)
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
        F = W_T[3:][self._rows]
        xddot_c = command_acceleration(
            terms.x,
            terms.xdot,
            self._x_d.Eval(context),
            self._xdot_d.Eval(context),
            self._xddot_d.Eval(context),
            F,
            self._f_d.Eval(context)[0],
            self._gains,
        )
        output.SetFromVector(primary_torque(terms, xddot_c, W_T, self._gravity))

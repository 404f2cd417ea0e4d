"""ImpedanceController: stage 4, the primary task law of Eqs. 6–8."""

from __future__ import annotations

from nsdrake.control.plan import ControllerPlan
from nsdrake.control.stages import TASK
from nsdrake.control.systems._values import COMMAND_PORTS, StageSystem, check_inputs, evaluated


class ImpedanceController(StageSystem):
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
    ``generalized_force`` (n) [N m] is in velocity order. An input that is not finite, or
    a zero quaternion, raises :class:`nsdrake.control.validation.ControllerInputError`
    naming the controller's input port, as does an input never connected nor fixed.
    """

    def __init__(self, *, plan: ControllerPlan):
        super().__init__(plan)
        m_t = plan.m_t
        # In the order of the packed commands (nsdrake.control.stages.commands_views).
        sizes = {"measured_wrench": 6, "x_d": m_t, "xdot_d": m_t, "xddot_d": m_t, "f_d": 1}
        if plan.m_r:
            sizes |= {"R_d": 4, "omega_d": 3, "omegadot_d": 3}
        self._inputs, start = [], 0
        for (name, size), public in zip(sizes.items(), COMMAND_PORTS, strict=False):
            port = self.DeclareVectorInputPort(name, size)
            self._inputs.append((port, slice(start, start + size), public))
            start += size
        ports = [self._terms] + [port for port, _, _ in self._inputs]
        self.DeclareVectorOutputPort(
            "generalized_force",
            plan.n,
            self._calc,
            prerequisites_of_calc={self.input_port_ticket(p.get_index()) for p in ports},
        )

    def _calc(self, context, output):
        b = self.buffers(context)
        for port, where, public in self._inputs:
            b.commands[where] = evaluated(self, context, port, public)
        plan = self._plan
        check_inputs(self, context, b.commands, plan.input_names["commands"], plan.commands_quaternion)
        self.run(context, TASK, b)
        output.SetFromVector(b.part("task"))

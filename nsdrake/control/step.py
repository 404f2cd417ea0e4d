"""ControllerStep: the whole controller as one plain call, for loops outside a Simulator.

A real robot's loop (or an LCM driver) receives the measured state once per control
period T and must answer with a torque::

    step = ControllerStep(controller_model=model, normal=[0, 0, -1], config=config)
    while running:
        t, q, v, wrench = receive()
        out = step.step(t, q, v, wrench, x_d, xdot_d, xddot_d, f_d)
        send(out.tau)

It runs the stages of :mod:`nsdrake.control.stages` on preallocated arrays, with the
same model, task and :class:`ControllerConfig` as :class:`nsdrake.NullSpaceImpedanceController`,
and gives the same τ, tick by tick, as that Diagram in a Simulator whose plant steps
once per period (the stages module says why, and when that holds). The discrete
state (the selector's switch state, the previous q̇_dⁿ, the previous τ) lives in
:attr:`ControllerStep.state`; :meth:`ControllerStep.reset` starts over.

In steady state a call allocates no Python object that outlives it (the result's
arrays are views into one buffer, rewritten by the next call), so Python's garbage
collector never has work to do on its account.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from pydrake.multibody.plant import MultibodyPlant

from nsdrake.control.config import ControllerConfig
from nsdrake.control.model import ControllerModel
from nsdrake.control.plan import ControllerPlan, StageBuffers
from nsdrake.control.stages import (
    COMMIT,
    CRITERIA,
    DESIRED,
    PLAIN_STEP,
    SELECTION,
    initial_state,
    state_parts,
)
from nsdrake.control.validation import validate_controller


class StepResult:
    """One tick's outputs, as views into the step's buffers (valid until the next call).
    The names and units are those of the controller's output ports:

    - ``tau`` τ (n) [N m], ``saturation`` [s, clipped joints], ``null_space_torque`` s τ₀ (n)
      [N m] (Eq. 21's τ₀ as it is in τ, after the actuator limits, as the controller's
      port), ``task_torque`` τ − τ₀ (n) [N m] (before the actuator limits);
    - ``null_space_velocity_error`` eⁿ (n) [rad/s], ``lyapunov`` ν (1) [J],
      ``desired_null_space_velocity`` q̇_dⁿ (n) [rad/s], ``mode`` (1), ``speed_scale`` (1);
    - ``criteria`` (4, n + 3): one [Φ; p; s; a] row per criterion (obstacle, joint torque,
      manipulability, joint limits), so ``d_min`` = criteria[0, n + 1],
      ``manipulability`` = criteria[2, n]; ``task_position`` x (m_t) [m].
    """

    def __init__(self, buffers: StageBuffers, n: int):
        part = buffers.part
        self.tau, self.saturation = part("limited")[:n], part("limited")[n:]
        self._tau0 = part("null_space")[:n]
        self.null_space_torque = np.zeros(n)  # s τ₀, rewritten by each call (:meth:`update`)
        self.null_space_velocity_error = part("null_space")[n : 2 * n]
        self.lyapunov = part("null_space")[2 * n :]
        self.mode, self.speed_scale = part("selection")[n : n + 1], part("selection")[n + 1 :]
        self.desired_null_space_velocity = part("qdot")
        self.task_torque = part("task")
        self.criteria = part("criteria")
        self.task_position = part("x")

    def update(self) -> None:
        """The derived outputs after a tick: s τ₀."""
        np.multiply(self.saturation[0], self._tau0, out=self.null_space_torque)


class ControllerStep:
    """The controller of :class:`nsdrake.NullSpaceImpedanceController` as one call per
    tick (module docstring).

    Args: as :class:`nsdrake.NullSpaceImpedanceController` (``controller_model``, ``normal``,
    ``config``, ``tool_frame``, ``task_axes``, ``wrench_point``).

    Call :meth:`step` once per control period ``config.period``, with the time and the
    state of that tick.
    """

    def __init__(
        self,
        *,
        controller_model: ControllerModel | MultibodyPlant | str | Path,
        config: ControllerConfig,
        normal: Sequence[float] | None = None,
        tool_frame: str = "tool",
        task_axes: Sequence[str] = ("x", "y"),
        wrench_point: Sequence[float] | None = None,
    ):
        from nsdrake.control.controller import as_controller_model

        model = as_controller_model(controller_model, tool_frame, task_axes)
        normal = validate_controller(config=config, model=model, normal=normal, wrench_point=wrench_point)
        self.plan = plan = ControllerPlan(
            model=model, config=config, normal=normal, wrench_point=wrench_point
        )
        self.model, self.config = model, config
        self._buffers = StageBuffers(plan, scratch=plan.create_scratch())
        self._terms = plan.allocate_terms()
        self._m_t = plan.m_t
        self.result = StepResult(self._buffers, plan.n)
        # g(q) (n) [N m] of the last call's q, the model's gravity term (τ = … + g, the torque
        # that holds the arm against gravity): a view, rewritten by each call
        self.gravity = plan.terms_field(self._terms, "g")
        self.reset()

    @property
    def state(self) -> np.ndarray:
        """The discrete state [switch (3); previous q̇_dⁿ (n + 1); previous τ (n + 1)], a view."""
        b = self._buffers
        return np.concatenate([b.switch, b.previous_qdot, b.previous_tau])

    def reset(self) -> None:
        """Forget the discrete state: the next call is the first tick (no previous q̇_dⁿ or τ,
        the selector in mode 0, blending in from rest)."""
        b = self._buffers
        for part, value in zip(
            (b.switch, b.previous_qdot, b.previous_tau),
            state_parts(initial_state(self.plan.n), self.plan.n),
            strict=True,
        ):
            part[:] = value
        self._t_previous = None

    def step(
        self,
        t: float,
        q: np.ndarray,
        v: np.ndarray,
        wrench: np.ndarray | None,
        x_d: np.ndarray,
        xdot_d: np.ndarray,
        xddot_d: np.ndarray,
        f_d: float | None,
        R_d: np.ndarray | None = None,
        omega_d: np.ndarray | None = None,
        omegadot_d: np.ndarray | None = None,
        *,
        desired_null_space_velocity: np.ndarray | None = None,
    ) -> StepResult:
        """τ and the diagnostics at time t [s] for the measured q [rad], q̇ [rad/s] (model's
        velocity order), the measured wrench [M; f] (6) [N m, N] (as the ``measured_wrench``
        port), the desired x_d, ẋ_d, ẍ_d (m_t each) [m, m/s, m/s²] and f_d [N]; with
        rotational task axes the desired orientation R_d as a quaternion [w, x, y, z] and
        ω_d, ω̇_d (3 each) [rad/s, rad/s²] (kept from the previous call when None). Without a
        force axis (``normal`` None) ``wrench`` and ``f_d`` may be None (zero), as the
        controller's optional ports. ``desired_null_space_velocity`` q̇_dⁿ (n) [rad/s], when
        given, replaces the configured source's, as the controller's input of that name.
        Returns :attr:`result`, rewritten in place."""
        b, m_t, plan = self._buffers, self._m_t, self.plan
        if (wrench is None or f_d is None) and plan.has_force_axis:
            raise ValueError("wrench and f_d are needed: the task has a force axis (normal)")
        c = b.commands
        c[:6] = 0.0 if wrench is None else wrench
        c[6 : 6 + m_t], c[6 + m_t : 6 + 2 * m_t], c[6 + 2 * m_t : 6 + 3 * m_t] = x_d, xdot_d, xddot_d
        c[6 + 3 * m_t] = 0.0 if f_d is None else f_d
        if R_d is not None:
            c[7 + 3 * m_t : 11 + 3 * m_t] = R_d
        if omega_d is not None:
            c[11 + 3 * m_t : 14 + 3 * m_t] = omega_d
        if omegadot_d is not None:
            c[14 + 3 * m_t : 17 + 3 * m_t] = omegadot_d
        plan.terms(b.scratch, np.asarray(q, dtype=float), np.asarray(v, dtype=float), self._terms)
        stages = (
            PLAIN_STEP if self._t_previous is not None else PLAIN_STEP & ~COMMIT
        )  # first tick: none pending
        t_previous = 0.0 if self._t_previous is None else self._t_previous
        if desired_null_space_velocity is None:
            plan.run(stages, t, t_previous, self._terms, b)
        else:  # the selector still runs (mode, scale), its q̇_dⁿ replaced before it is used
            first = stages & (CRITERIA | COMMIT | SELECTION | DESIRED)
            plan.run(first, t, t_previous, self._terms, b)
            b.part("qdot")[:] = desired_null_space_velocity
            plan.run(stages & ~first, t, t_previous, self._terms, b)
        self._t_previous = t
        self.result.update()
        return self.result

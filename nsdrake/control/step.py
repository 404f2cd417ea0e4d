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

Every call checks its arguments before anything is computed: real numbers
(:func:`nsdrake.control.validation.is_real_array`), their sizes (the copy into the
step's input buffer, with the lengths compared), ``t`` one period on (or whole periods:
:meth:`ControllerStep.step`), then one compiled pass over all of them for a value that
is not finite (:func:`nsdrake.control.validation.inputs_problem`);
a wrong one raises :class:`nsdrake.control.validation.ControllerInputError` naming the
argument (and the joint or entry), and the step's state is left as it was.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from pydrake.multibody.plant import MultibodyPlant

from nsdrake.control.config import ControllerConfig
from nsdrake.control.model import ControllerModel
from nsdrake.control.plan import ControllerPlan, StageBuffers, torque_limits
from nsdrake.control.stages import (
    COMMIT,
    CRITERIA,
    DESIRED,
    PLAIN_STEP,
    SELECTION,
    commands_size,
    initial_state,
    state_parts,
)
from nsdrake.control.validation import (
    ControllerConfigError,
    ControllerInputError,
    entry_names,
    finite_problem,
    inputs_problem,
    is_number,
    is_real_array,
    show,
    validate_controller,
    vector_size_problem,
)

# [-] how far from a whole number of periods the advance of t may be, in periods: float
# rounding of k T or of t += T (1e-13 s after 1000 s at 1 kHz), never a late tick of a loop
# that reads a wall clock (give such a loop's t as k T, its tick count).
TIME_SLACK = 1e-3


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
    ``config``, ``tool_frame``, ``task_axes``, ``wrench_point``), and ``robot_adds_gravity``:
    the robot adds g(q) to the torque it is sent (Franka's torque interface does), so the
    loop sends τ − g(q) (:attr:`gravity`) and the actuator limits bound that, not τ: the
    torque window is centred on g(q) (τ − g(q) ∈ ±τ_max) and the torque-rate limit's
    reference, the previous τ, is moved by g's change since the previous call (the change
    of τ − g(q) at most ρ_max T). False (the default, and the Diagram's only way): the
    actuators apply τ, the windows about 0.

    Call :meth:`step` once per control period ``config.period``, with the time and the
    state of that tick.

    One thread: a ControllerStep belongs to the thread of its first :meth:`step` (its
    result is a view into buffers that the next call rewrites, so a lock around the call
    would not make a second thread's τ its own). A call from any other thread raises
    :class:`nsdrake.control.validation.ControllerInputError`; make one ControllerStep per
    thread, or :meth:`reset` it to hand it to another thread.
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
        robot_adds_gravity: bool = False,
    ):
        from nsdrake.control.controller import as_controller_model

        model = as_controller_model(controller_model, tool_frame, task_axes)
        normal = validate_controller(config=config, model=model, normal=normal, wrench_point=wrench_point)
        if not isinstance(robot_adds_gravity, bool):
            raise ControllerConfigError(
                "robot_adds_gravity", f"must be True or False, got {robot_adds_gravity!r}"
            )
        self.robot_adds_gravity = robot_adds_gravity
        self.plan = plan = ControllerPlan(
            model=model,
            config=config,
            normal=normal,
            wrench_point=wrench_point,
            limits_about_gravity=robot_adds_gravity,
        )
        self.model, self.config = model, config
        n, m_t = plan.n, plan.m_t
        # The inputs of a call in one flat buffer [t; q (n); v (n); commands], so that one
        # compiled pass checks them all; the commands are the stages' own (a view).
        self._inputs = np.zeros(1 + 2 * n + commands_size(m_t, plan.m_r))
        self._q, self._v = self._inputs[1 : 1 + n], self._inputs[1 + n : 1 + 2 * n]
        commands = self._inputs[1 + 2 * n :]
        self._quaternion = -1
        if plan.m_r:
            self._quaternion = 1 + 2 * n + 7 + 3 * m_t
            commands[7 + 3 * m_t] = 1.0  # R_d = I until given
        self._kept_rotation = commands[7 + 3 * m_t :].copy()  # R_d, ω_d, ω̇_d of the last call
        self._buffers = StageBuffers(plan, scratch=plan.create_scratch(), commands=commands)
        self._terms = plan.allocate_terms()
        self._m_t = m_t
        self._n = n
        self._period = config.period
        self._slack = TIME_SLACK * config.period  # [s] rounding of t, far below a period
        joints, axes = list(model.joint_names), list(model.arm.task_axes[:m_t])
        parts = [("t", 1), ("q", joints), ("v", joints), ("wrench", 6)]
        parts += [(name, axes) for name in ("x_d", "xdot_d", "xddot_d")] + [("f_d", 1)]
        if plan.m_r:
            parts += [("R_d", ["w", "x", "y", "z"]), ("omega_d", 3), ("omegadot_d", 3)]
        self._names = entry_names(parts)
        self._qdot_names = entry_names([("desired_null_space_velocity", joints)])
        self._thread, self._claim_lock = None, threading.Lock()
        self.result = StepResult(self._buffers, n)
        # g(q) (n) [N m] of the last call's q, the model's gravity term (τ = … + g, the torque
        # that holds the arm against gravity): a view, rewritten by each call
        self.gravity = plan.terms_field(self._terms, "g")
        self._gravity_previous = np.zeros(n)  # g(q) of the last call (robot_adds_gravity)
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
        self._rotation_needed = self.plan.m_r > 0  # R_d, ω_d, ω̇_d: given again after a reset
        self._thread = None  # the next call's thread owns the step (class docstring)

    def hold_torque(self, torque: np.ndarray) -> None:
        """The torque the actuators apply before the first call (n) [N m], in the convention
        the limits act on (τ − g(q) when ``robot_adds_gravity``: what a Panda reports as
        ``joint_torque_desired``; else τ): the first call's torque-rate limit is centred on
        it, as every later call's is on the previous τ (without it the first call's change is
        unbounded). Only before the first call (since construction or :meth:`reset`, which
        forgets it); refused with ControllerInputError, the state unchanged, for a torque
        that is not n finite numbers within the torque limits (no actuator applies it)."""
        problem = vector_size_problem(torque, self._n, f"{self._n} joint torques [N m]")
        problem = problem and f"torque {problem}"
        if problem is None:
            torque = np.asarray(torque, dtype=float)
            problem = inputs_problem(torque, entry_names([("torque", list(self.model.joint_names))]))
        if problem is None and self._t_previous is not None:
            problem = "called after the first step: the rate limit already has the previous τ"
        limits = torque_limits(self.config, self.model)
        if problem is None and not (np.abs(torque) <= limits).all():
            k = int(np.argmax(np.abs(torque) - limits))
            problem = (
                f"torque[{self.model.joint_names[k]}] {torque[k]:g} N m is beyond the joint's torque limit "
                f"{limits[k]:g} N m: "
                "no actuator applies it"
            )
        if problem is not None:
            raise ControllerInputError("ControllerStep.hold_torque", problem)
        previous = self._buffers.previous_tau
        previous[: self._n], previous[self._n] = torque, 1.0
        # the first call moves the reference by g(q) − this: τ_prev = torque + g(q) of its own q
        self._gravity_previous[:] = 0.0

    def _claim(self) -> None:
        """The calling thread takes the step if no thread has it; else refused."""
        with self._claim_lock:
            if self._thread is None:
                self._thread = threading.get_ident()
            elif self._thread != threading.get_ident():
                raise ControllerInputError(
                    "ControllerStep.step",
                    "called from a second thread: a ControllerStep belongs to the thread of its "
                    "first call (its result is rewritten by every call); make one per thread",
                )

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
        ω_d, ω̇_d (3 each) [rad/s, rad/s²]: held from the previous call when None, so the
        first call after the step was made or :meth:`reset` must give all three (refused
        otherwise). Nothing else is held. Without a force axis (``normal`` None) ``wrench``
        and ``f_d`` may be None (zero), as the controller's optional ports.
        ``desired_null_space_velocity`` q̇_dⁿ (n) [rad/s], when given, replaces the
        configured source's at this call, as the controller's input of that name.

        Numbers are real numbers or arrays of them (text, booleans, complex values refused;
        integers taken). ``t`` is the tick's time k T (T = ``config.period``): the first
        call's any finite time, each later one a whole number of periods after the
        previous call's (the same time, a time between periods or an earlier one refused);
        two or more periods on skips the ticks between (taken, as nsdrake's drive skips
        the statuses it could not answer: the q̈_dⁿ feed-forward and the torque-rate limit
        take the last call's state as one period old; a loop that calls every 2T runs the
        gains at a period they were not checked for: give config.period its period).
        docs/own_diagram.md, "The contract".
        Returns :attr:`result`, rewritten in place."""
        if self._thread != threading.get_ident():
            self._claim()
        try:
            t = self._take(t, q, v, wrench, x_d, xdot_d, xddot_d, f_d, R_d, omega_d, omegadot_d)
        except (
            TypeError,
            ValueError,
            IndexError,
            OverflowError,
            _RefusedError,
        ):  # an int beyond float's range
            raise self._refuse(self._argument_problem(locals())) from None
        problem = inputs_problem(self._inputs, self._names, self._quaternion)
        if problem is None and desired_null_space_velocity is not None:
            qdot, problem = self._prescribed_velocity(desired_null_space_velocity)
        if problem is not None:
            raise self._refuse(problem)
        if R_d is not None or omega_d is not None or omegadot_d is not None:  # held for calls passing None
            self._kept_rotation[:] = self._buffers.commands[7 + 3 * self._m_t :]
            self._rotation_needed = False
        return self._tick(t, None if desired_null_space_velocity is None else qdot)

    def _take(self, t, q, v, wrench, x_d, xdot_d, xddot_d, f_d, R_d, omega_d, omegadot_d) -> float:
        """The arguments into the step's input buffer, their types, sizes and ``t`` checked
        (anything else raises, and :meth:`_argument_problem` says what); returns t as a float
        (an integer t would make numba compile the kernels anew for int)."""
        m_t, n, plan, c = self._m_t, self._n, self.plan, self._buffers.commands
        if not (is_number(t) and is_real_array(q) and is_real_array(v) and is_real_array(x_d)
                and is_real_array(xdot_d) and is_real_array(xddot_d)):  # fmt: skip
            raise _RefusedError  # text, booleans, complex values (validation.is_real_array)
        if len(q) != n or len(v) != n or len(x_d) != m_t or len(xdot_d) != m_t or len(xddot_d) != m_t:
            raise _RefusedError  # numpy's copy would take a scalar, or a 1-vector, for any size
        t = float(t)
        previous = self._t_previous
        if (
            previous is not None
            and not abs(t - previous - self._period) <= self._slack
            and self._time_problem(t)
        ):
            raise _RefusedError  # not one period on, nor whole periods (skipped ticks)
        self._inputs[0] = t
        self._q[:], self._v[:] = q, v
        if wrench is None or f_d is None or not plan.has_force_axis:
            self._optional_force(wrench, f_d)
        else:
            if not (is_real_array(wrench) and is_number(f_d)) or len(wrench) != 6:
                raise _RefusedError
            c[:6], c[6 + 3 * m_t] = wrench, f_d
        c[6 : 6 + m_t], c[6 + m_t : 6 + 2 * m_t], c[6 + 2 * m_t : 6 + 3 * m_t] = x_d, xdot_d, xddot_d
        if R_d is not None or omega_d is not None or omegadot_d is not None or self._rotation_needed:
            self._rotation(R_d, omega_d, omegadot_d)
        return t

    def _tick(self, t: float, qdot: np.ndarray | None) -> StepResult:
        """The stages on the checked inputs (``qdot``: a prescribed q̇_dⁿ, or None)."""
        b, plan = self._buffers, self.plan
        plan.terms(b.scratch, self._q, self._v, self._terms)
        if self.robot_adds_gravity:  # the rate limit on τ − g(q): its reference moved by g's change
            previous = b.previous_tau
            if previous[self._n] != 0.0:
                previous[: self._n] += self.gravity - self._gravity_previous
            self._gravity_previous[:] = self.gravity
        stages = PLAIN_STEP if self._t_previous is not None else PLAIN_STEP & ~COMMIT  # first: none pending
        t_previous = 0.0 if self._t_previous is None else self._t_previous
        if qdot is None:
            plan.run(stages, t, t_previous, self._terms, b)
        else:  # the selector still runs (mode, scale), its q̇_dⁿ replaced before it is used
            first = stages & (CRITERIA | COMMIT | SELECTION | DESIRED)
            plan.run(first, t, t_previous, self._terms, b)
            b.part("qdot")[:] = qdot
            plan.run(stages & ~first, t, t_previous, self._terms, b)
        self._t_previous = t
        self.result.update()
        return self.result

    def _optional_force(self, wrench, f_d) -> None:
        """The wrench and f_d of a call where one is None or the task has no force axis."""
        c, m_t = self._buffers.commands, self._m_t
        if self.plan.has_force_axis:  # one of them None
            raise _RefusedError
        if f_d is not None:  # a force along no axis would do nothing
            raise _RefusedError
        if wrench is None:
            c[:6] = 0.0
        else:
            if not is_real_array(wrench) or len(wrench) != 6:
                raise _RefusedError
            c[:6] = wrench
        c[6 + 3 * m_t] = 0.0

    def _rotation(self, R_d, omega_d, omegadot_d) -> None:
        """R_d, ω_d, ω̇_d (each held from the previous call when None; all three needed by
        the first call since construction or :meth:`reset`)."""
        if not self.plan.m_r:
            raise _RefusedError
        c, o = self._buffers.commands, 7 + 3 * self._m_t
        for value, start, size in ((R_d, o, 4), (omega_d, o + 4, 3), (omegadot_d, o + 7, 3)):
            if value is None:
                if self._rotation_needed:  # never given: nothing to hold
                    raise _RefusedError
            else:
                if not is_real_array(value) or len(value) != size:
                    raise _RefusedError
                c[start : start + size] = value

    def _time_problem(self, t: float) -> str | None:
        """Why ``t``, not the previous call's plus one period T, is refused, or None: earlier
        or the same (refused), not a whole number of periods later (refused), or k ≥ 2
        periods later (taken: k − 1 ticks skipped, as nsdrake's drive skips the statuses a
        late tick could not answer, nsdrake/driver/loop.py; the state is the last call's,
        and this call's q̈_dⁿ feed-forward and torque-rate limit take it as one period old).
        Skips are taken however many in a row: a late loop skips at every call for as long
        as it is late, which a loop at half the rate cannot be told from here (the drive
        tells them apart by its statuses' own clock, driver.faults.slow_stream_problem)."""
        previous, T = self._t_previous, self._period
        if not math.isfinite(t):
            return f"t {finite_problem(t)} [s]"
        if t < previous:
            return f"t = {t:g} s is before the previous call's {previous:g} s: reset() to start over"
        periods = (t - previous) / T
        k = round(periods)
        if abs(periods - k) * T > self._slack:
            return (
                f"t = {t:g} s is {periods:.4g} periods after the previous call's {previous:g} s: t must "
                f"advance by whole periods T = {T:g} s (config.period), the controller's sampled time"
            )
        if k == 0:
            return (
                f"t = {t:g} s is the previous call's time again: each call is one tick, t advancing by "
                f"the period T = {T:g} s (config.period)"
            )
        return None

    def _prescribed_velocity(self, qdot) -> tuple[np.ndarray, str | None]:
        """q̇_dⁿ as an array, and why it cannot be taken (or None)."""
        problem = vector_size_problem(qdot, self._n, f"{self._n} joint speeds [rad/s] (q̇_dⁿ)")
        if problem is not None:
            return qdot, f"desired_null_space_velocity {problem}"
        qdot = np.asarray(qdot, dtype=float)
        return qdot, inputs_problem(qdot, self._qdot_names)

    def _refuse(self, problem: str) -> ControllerInputError:
        """The error of a refused call, the step as it was before it (the kept R_d, ω_d, ω̇_d
        restored; the discrete state is only written by a call that computes)."""
        if self.plan.m_r:
            self._buffers.commands[7 + 3 * self._m_t :] = self._kept_rotation
        return ControllerInputError("ControllerStep.step", problem)

    def _argument_problem(self, arguments: dict) -> str:
        """What is wrong with the first argument of a call that :meth:`step` could not take."""
        n, m_t, plan = self._n, self._m_t, self.plan
        axes = list(self.model.arm.task_axes[:m_t])
        t = arguments["t"]
        problem = finite_problem(t)
        if problem:
            return f"t {problem} [s]"
        if self._t_previous is not None:
            problem = self._time_problem(float(t))
            if problem:
                return problem
        joints = list(self.model.joint_names)
        expected = [
            ("q", n, f"{n} joint positions [rad], the joints {joints}"),
            ("v", n, f"{n} joint speeds [rad/s]"),
        ]
        expected += [
            (name, m_t, f"{m_t} numbers, the task axes {axes}") for name in ("x_d", "xdot_d", "xddot_d")
        ]
        for name, size, what in expected:
            problem = vector_size_problem(arguments[name], size, what)
            if problem:
                return f"{name} {problem}"
        wrench, f_d = arguments["wrench"], arguments["f_d"]
        if plan.has_force_axis and (wrench is None or f_d is None):
            return f"{'wrench' if wrench is None else 'f_d'} is None, but the task has a force axis (normal)"
        if not plan.has_force_axis and f_d is not None:
            return (
                f"f_d is {show(f_d)}, but the task has no force axis (normal None), so a desired force "
                "would do nothing: pass None"
            )
        if wrench is not None:
            problem = vector_size_problem(wrench, 6, "[M; f] (6) [N m, N]")
            if problem:
                return f"wrench {problem}"
        if not is_number(f_d) and f_d is not None:
            return f"f_d must be a number [N], got {show(f_d)}"
        rotation = (("R_d", 4, "a quaternion [w, x, y, z]"), ("omega_d", 3, "3 numbers [rad/s]"),
                    ("omegadot_d", 3, "3 numbers [rad/s²]"))  # fmt: skip
        for name, size, what in rotation:
            value = arguments[name]
            if value is not None and not plan.m_r:
                return f"{name} is given, but the task has no rotational axes: pass None"
            if value is None and self._rotation_needed:
                axes = list(self.model.arm.task_axes[m_t:])
                return (
                    f"{name} is None on the first call (since the step was made or reset()), but the task "
                    f"has rotational axes {axes}: give {what}; later calls may pass None to hold it"
                )
            problem = None if value is None else vector_size_problem(value, size, what)
            if problem:
                return f"{name} {problem}"
        return "its arguments do not match its signature (see its docstring)"


class _RefusedError(Exception):
    """An argument of the wrong size (the slow path names it)."""

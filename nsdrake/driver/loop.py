"""The controller side's loop: one command per status, on the robot's clock.

Why a loop of plain calls and not a Drake ``Simulator``: the robot owns the clock. Each
status k:

1. arrives (the bus delivers every queued message, :mod:`nsdrake.driver.bus`; each one's
   arrival is stamped on the wall clock) and every status received since the last tick
   is checked in order: decodable, its clock (``robot_utime`` where the driver sends
   it, else ``utime``) advancing by half a period to the silence bound, ``driver.expire_sec``
   in periods (:func:`nsdrake.driver.faults.clock_problem`);
2. the newest is taken (the others are counted in ``skipped``: a missed period is a
   skipped tick, never replayed). Its age is then at most a period plus the time the
   bus took to deliver it: every status that arrived is read before one is chosen (a
   stamp taken when the loop reads a message says nothing more, since the loop reads
   the socket itself), and none queued before the controller was ready is answered
   (:meth:`ControllerLoop.ready`);
3. its q, q̇ (and τ_ext) are checked (finite, within the Panda's limits, no move faster than
   its velocity limits allow and none its reported velocity does not explain), the
   controller's time set from its clock (:func:`nsdrake.driver.faults.elapsed_periods`,
   re-anchored every tick), the wrench taken (the newest force-torque message, which
   must have arrived within the silence bound) and the controller side ticks once
   (:class:`nsdrake.driver.controller_side.ControllerSide`);
4. the command passes the last gate before the wire (:func:`nsdrake.driver.panda.command_problem`:
   the Panda's published torque and torque-rate limits on what is sent, τ − g(q) when the
   robot adds g, after everything that shaped it; a command beyond them stops the drive
   and is not sent), then it is sent, stamped with the status's ``utime``, and the tick
   recorded.

Silence is the wall-clock time since the last status arrived (not counting the
controller's own compute: a status that arrived during a long tick is not silence).
A status two periods or more after the one answered before, within the bound, is a
glitch: counted by its length (``gap_counts``, :data:`nsdrake.driver.timing.GAP_BINS`).
A fault (:class:`DriveFaultError`) or Ctrl-C (:mod:`nsdrake.driver.stop`) stops
commanding at once: nothing is sent after it.

Every tick's rules run in compiled code (:mod:`nsdrake.driver.tick`: the statuses' and the
sensor's bytes decoded and checked, the torques, the last gate, the command's bytes), the
Python loop doing the socket, the clock, the reference and the step's call; whatever the
compiled path refuses (or cannot tell: over :data:`COMPILED_INBOX` statuses at once, a gap
over :data:`COMPILED_GAP` periods) goes through the same rules in Python, which say why
in words (``ControllerLoop.compiled = False``: all of it in Python, the reference the
compiled path is tested against).
"""

from __future__ import annotations

import time

import numpy as np

from nsdrake.control.validation import ControllerInputError
from nsdrake.driver.bus import Bus
from nsdrake.driver.controller_side import ControllerSide, Recorder
from nsdrake.driver.faults import (
    anchor_step,
    clock_problem,
    elapsed_periods,
    jump_problem,
    slow_stream_problem,
    start_problem,
    velocity_mismatch_problem,
)
from nsdrake.driver.panda import (
    ENVELOPE_CENTRE,
    ENVELOPE_HALF_WIDTH,
    NUM_JOINTS,
    command_problem,
    joint_step_allowance,
    limit_problem,
    velocity_mismatch_allowance,
)
from nsdrake.driver.stop import StopRequest
from nsdrake.driver.tick import (
    F_BOUND,
    F_LAST,
    F_MEASURED,
    F_PERIOD,
    F_SUCCESS_MIN,
    FLOATS,
    I_ACCEPTED,
    I_ANCHOR,
    I_COMMANDS,
    I_GAPS,
    I_LAST_CLOCK,
    I_LONG_GAPS,
    I_LONGEST_GAP,
    I_PERIOD_US,
    I_PERIODS,
    I_ROBOT_CLOCK,
    I_UTIME,
    INTS,
    SCRATCH,
    decode_force_torque,
    finish_tick,
    gate_bounds,
    limit_table,
    motion_table,
    robot_torques,
    take_statuses,
)
from nsdrake.driver.timing import GAP_BINS, TickTimes, gap_bin
from nsdrake.driver.wire import STATUS_SIZE, CommandBuffer, ForceTorqueBuffer, StatusBuffer
from nsdrake.experiment.driver_config import silence_bound_periods

SUCCESS_RATE_WINDOW = 100  # libfranka's control_command_success_rate is over its last 100 cycles
ROBOT_MODE_MOVE = 2  # lcmt_panda_status.kMove: the only mode in which a Panda takes torque commands
# Statuses a tick's compiled path takes at once (more queued: the Python path, the same rules)
COMPILED_INBOX = 64
# Periods between two statuses answered up to which the compiled path holds the motion
# allowances (nsdrake/driver/tick.py's motion_table); a longer gap within the silence
# bound goes through the Python path
COMPILED_GAP = 100
ROBOT_MODES = {0: "kOther", 1: "kIdle", 2: "kMove", 3: "kGuiding", 4: "kReflex", 5: "kUserStopped",
               6: "kAutomaticErrorRecovery"}  # fmt: skip


class DriveFaultError(RuntimeError):
    """The controller stopped commanding; the message is one line saying why."""

    def __init__(self, t: float | None, problem: str, commands: int):
        self.t, self.problem, self.commands = t, problem, commands
        where = "before the first command" if t is None else f"at t = {t:.3f} s"
        super().__init__(f"{where}: {problem}; stopped commanding after {commands} command(s)")


class DriveInterruptedError(DriveFaultError):
    """Ctrl-C stopped the controller (:mod:`nsdrake.driver.stop`): nothing was sent after it."""

    def __init__(self, t: float | None, commands: int):
        super().__init__(t, "interrupted (Ctrl-C)", commands)


def warm_up(side: ControllerSide) -> None:
    """One tick at the scenario's start pose, then the controller side reset: the first
    call in a process loads the compiled kernels from numba's cache (about 0.1 s for the
    Panda's), which must not happen inside the first tick, where the driver's command
    deadline runs. A side that has run before is reset first (its step refuses a time
    before its previous call's)."""
    station = side.station
    side.reset()
    side.tick(0.0, station.q0, station.v0, np.zeros(6))
    side.estimated_wrench(station.q0, np.zeros(NUM_JOINTS))
    side.reset()


def _state(index: int, kind=int):
    """An attribute of the loop kept in its compiled state (``_ints`` or ``_floats``)."""
    array = "_ints" if kind is int else "_floats"
    return property(
        lambda self: kind(getattr(self, array)[index]),
        lambda self, value: getattr(self, array).__setitem__(index, value),
    )


class ControllerLoop:
    """Runs a :class:`nsdrake.driver.controller_side.ControllerSide` on ``bus`` (module
    docstring).

    ``start()`` waits for the first status that arrives after it was called and answers
    it; each ``tick()`` answers the newest status since; ``run(duration)`` does both until
    the controller's clock reaches ``duration``. ``times`` holds each tick's time from the
    status's arrival to the command's publish [s], wall clock and the thread's CPU time;
    ``commands`` counts the commands sent, ``skipped`` the statuses superseded by a newer
    one before the controller could act on them. ``clock`` is the clock [s] the timing
    rules (silence, a status's age) are measured on: the wall clock against a robot; the
    simulated driver's time in lockstep, where the robot waits for the controller; a
    test's own, with a bus that advances it. The ticks' own times are always the wall
    clock's.
    """

    compiled = True  # False: every tick in Python, step by step (the compiled path's reference)
    # the state the compiled tick (nsdrake/driver/tick.py) reads and moves on
    commands = _state(I_COMMANDS)
    periods = _state(I_PERIODS)  # control periods since the first status, on the robot's clock
    longest_gap = _state(I_LONGEST_GAP)  # [periods] the longest glitch (0: none)
    success_rate_min = _state(F_SUCCESS_MIN, float)
    _last_clock, _anchor = _state(I_LAST_CLOCK), _state(I_ANCHOR)
    _accepted = _state(I_ACCEPTED)  # statuses taken after the first (faults.anchor_step)
    _long_gaps = _state(I_LONG_GAPS)  # statuses in a row two periods or more after the previous

    def __init__(self, side: ControllerSide, bus: Bus, *, capacity: int = 0, clock=time.perf_counter):
        self.side = self.drive = side
        self._ints, self._floats = np.zeros(INTS, dtype=np.int64), np.zeros(FLOATS)
        self.bus = bus
        scenario = side.scenario
        self.config = c = scenario.driver
        self.period = scenario.control_period
        self.period_us = round(self.period * 1e6)
        self.bound_periods = silence_bound_periods(c, self.period)  # the silence bound, in periods
        self.bound = self.bound_periods * self.period  # [s]
        self._ints[I_PERIOD_US] = self.period_us
        self._floats[[F_PERIOD, F_BOUND]] = self.period, self.bound_periods
        self.skipped = 0
        self.compiled_ticks = 0  # ticks whose statuses the compiled path took (the others: Python's)
        capacity = capacity or int(round(scenario.duration / self.period)) + 2
        self.times = TickTimes(capacity)
        self.recorder = Recorder(side, capacity)
        self.stop = StopRequest()  # Ctrl-C's flag, read at each status (Drive.run sets it)
        self.clock_name = "utime"
        # the lowest control_command_success_rate the robot reported once the drive had sent
        # SUCCESS_RATE_WINDOW commands (drake-franka-driver sends
        # libfranka's: the fraction of its last 100 cycles that received a command in time)
        self.success_rate_min = float("nan")
        self._clock = clock
        self._names = side.station.arm_model.joint_names
        self._inbox: list[
            tuple[float, float, float, bytes]
        ] = []  # (arrival, wall, CPU, bytes) since last tick
        self._force_torque: tuple[float, bytes] | None = None  # the newest, not yet loaded
        self._force_torque_arrival = -np.inf
        self._status, self._wrench_message, self._command = (
            StatusBuffer(),
            ForceTorqueBuffer(),
            CommandBuffer(),
        )
        self._compiled_buffers()
        f = self._floats
        self._measured = f[F_MEASURED : F_MEASURED + 3 * NUM_JOINTS].reshape(3, NUM_JOINTS)  # a view
        self._q, self._v, self._tau_ext = self._measured
        self._q_last, self._v_last = f[F_LAST : F_LAST + NUM_JOINTS], f[F_LAST + NUM_JOINTS : F_LAST + 14]
        # glitches: answered statuses 2, 3-10, 11-50, over 50 periods after the previous one
        self.gap_counts = self._ints[I_GAPS : I_GAPS + len(GAP_BINS)]
        self._deviation = np.zeros((2, NUM_JOINTS))
        self._at_robot = np.zeros(NUM_JOINTS)  # what the last command asked of the robot (the rate check)

        self._wrench = np.zeros(6)
        self._last_arrival = 0.0
        # the longest silence the silence rule measured once started [s]: from the answered
        # status's arrival to the next arrival, when the loop had to wait for it (statuses that
        # arrived during a tick are no silence): how near the stream came to the bound
        self.longest_silence = 0.0
        self.time = 0.0
        self.started = self._ready = False
        bus.subscribe(c.status_channel, self._on_status)
        if side.sensor:
            bus.subscribe(c.force_torque_channel, self._on_force_torque)
        warm_up(side)

    def _compiled_buffers(self) -> None:
        """The compiled tick's arrays (nsdrake/driver/tick.py) beside its state."""
        self._raw = np.zeros((COMPILED_INBOX, STATUS_SIZE), dtype=np.uint8)  # the statuses' bytes
        self._lengths = np.zeros(COMPILED_INBOX, dtype=np.int64)
        self._scratch = np.zeros(SCRATCH)
        self._limits, self._gate = limit_table(), gate_bounds()
        self._motion_config = self._motion = None  # the allowances' table, and the config it is of
        self._fingerprint = np.frombuffer(self._status._fingerprint, dtype=np.uint8).copy()
        self._ft_fingerprint = np.frombuffer(self._wrench_message._fingerprint, dtype=np.uint8).copy()
        self._command_bytes = np.frombuffer(self._command.buffer, dtype=np.uint8)  # a view: set in place

    def _on_status(self, data: bytes) -> None:
        self._inbox.append((self._clock(), time.perf_counter(), time.thread_time(), data))

    def _on_force_torque(self, data: bytes) -> None:
        self._force_torque = (self._clock(), data)

    def _fault(self, problem: str) -> DriveFaultError:
        return DriveFaultError(self.time if self.started else None, problem, self.commands)

    def _check_stop(self) -> None:
        if self.stop.requested:
            raise DriveInterruptedError(self.time if self.started else None, self.commands)

    def ready(self) -> None:
        """The controller is ready: what arrived before now is discarded (a status queued
        during the warm-up or the folder's claim is stale), and ``start()`` waits for a
        status that arrives after this call."""
        self._handle(0)
        self._inbox.clear()
        self._force_torque = None
        self._ready = True

    def _handle(self, timeout_ms: int) -> int:
        """``bus.handle``, with Ctrl-C told from a failing bus: SIGINT during the wait makes
        LCM's select() return EINTR, which the ``lcm`` package raises as an OSError
        ("lcm_handle_timeout() returned -1"), before or after the handler set the stop flag
        (Python runs it at its next check). So on an OSError: Ctrl-C if the flag is set,
        else one more try (another signal's EINTR passes), and the bus's own error if that
        fails too (a socket that is really broken fails again)."""
        try:
            return self.bus.handle(timeout_ms)
        except OSError:
            self._check_stop()
            try:
                return self.bus.handle(0)
            except OSError:
                self._check_stop()
                raise

    def _check_motion(self, periods: int) -> None:
        """The status just loaded against the previous one answered, ``periods`` apart: a
        glitch counted (two periods or more; beyond the silence bound a fault, also when
        each status came on time and the controller itself was late: the driver has
        expired its command meanwhile, and a command now would be a torque step from the
        damping that the controller's rate limiter never saw), then no joint moved more
        than its velocity limit allows (or than ``driver.max_joint_step`` per period, when
        set), and every joint's move agrees with its reported velocities
        (nsdrake/driver/panda.py's bounds)."""
        if periods >= 2:
            if periods > self.bound_periods:  # every status was on time, the controller was not
                raise self._fault(
                    f"status refused: {periods} periods since the status answered before it, beyond "
                    f"{self._bound_words()}: the driver has dropped the last command and damped"
                )
            self.gap_counts[gap_bin(periods)] += 1
            self.longest_gap = max(self.longest_gap, periods)
        elapsed = periods * self.period
        (allowance, why), (mismatch, _) = self._allowances(periods)
        problem = jump_problem(self._q, self._q_last, allowance, periods, self._names, why)
        if problem is None:
            problem = velocity_mismatch_problem(
                self._q, self._q_last, self._v, self._v_last, elapsed, mismatch, self._names
            )
        if problem:
            raise self._fault(f"status refused: {problem}")

    def _allowances(self, periods: int) -> tuple[tuple[np.ndarray, str], tuple[np.ndarray, str]]:
        """How far each joint may move from the status answered before, ``periods`` apart,
        and where that comes from; how far its move may differ from its reported velocities'
        (nsdrake/driver/panda.py): the Python path's and the compiled tick's
        (:func:`nsdrake.driver.tick.motion_table`) alike."""
        elapsed = periods * self.period
        step = self.config.max_joint_step
        if step > 0:
            jump = (np.full(NUM_JOINTS, step * periods), f"of driver.max_joint_step {step:g} rad per period")
        else:
            jump = (joint_step_allowance(elapsed), "its velocity limit allows (nsdrake/driver/panda.py)")
        return jump, (velocity_mismatch_allowance(elapsed), "")

    def _motion_table(self) -> np.ndarray:
        """The allowances of :meth:`_allowances` for the compiled path, up to COMPILED_GAP
        periods (or the silence bound): :func:`nsdrake.driver.tick.motion_table`."""
        longest = int(min(COMPILED_GAP, self.bound_periods))
        return motion_table(lambda k: [allowance for allowance, _ in self._allowances(k)], longest)

    def _bound_words(self) -> str:
        expire = self.config.expire_sec
        return f"the silence bound: driver.expire_sec {expire:g} s, {self.bound_periods:g} periods"

    def start(self) -> None:
        """``ready()`` (unless called already), then waits (up to
        ``driver.first_status_timeout``) for a status (and, with the sensor, a force-torque
        message), checks it against the scenario's start pose and answers it."""
        c = self.config
        if not self._ready:
            self.ready()
        deadline = self._clock() + c.first_status_timeout
        while not self._inbox or (self.side.sensor and self._force_torque is None):
            self._check_stop()
            remaining = deadline - self._clock()
            if remaining <= 0:
                raise self._fault(self._silence_at_start())
            self._handle(max(1, min(100, int(remaining * 1e3))))
        self._check_stop()
        arrival, wall, cpu, data = self._inbox[-1]
        self.skipped += len(self._inbox) - 1
        self._inbox.clear()
        self._load(data, "first status refused: ")
        clock = self._status.robot_utime(data)
        self.clock_name = "robot_utime" if clock else "utime"
        self._ints[I_ROBOT_CLOCK] = bool(clock)
        self._anchor = self._last_clock = clock or self._status.utime(data)
        self._accepted = 0
        problem = start_problem(self._q, self.side.station.q0, c.start_tolerance, self._names)
        if problem:
            raise self._fault(f"first status refused: {problem}")
        self._hold_applied_torque()
        self._answer(data, arrival, wall, cpu)
        self.started = True

    def _hold_applied_torque(self) -> None:
        """The first command's rate reference: the first status's ``joint_torque_desired``,
        the torque the robot's interface applies now (libfranka's τ_J_d, gravity excluded:
        τ − g(q) in both gravity setups, what the limiter and the gate bound; drake-franka-driver
        copies it in as it is), so that the first command, like every later one, differs from
        what the robot applies by at most ρ_max T (1 N m) and the last gate checks that too.
        Without it the first command's change was unbounded: a drive started on a robot held
        by another controller stepped its torque at once."""
        held = np.array(self._status.tau_desired, dtype=float)
        try:
            self.side.step.hold_torque(held)
        except ControllerInputError as e:
            raise self._fault(f"first status refused: joint_torque_desired: {e.problem}") from None
        self._at_robot[:] = held

    def _wait_for_a_status(self) -> None:
        """Until the inbox holds a status; silence beyond the bound, on the wall clock from
        the last status's arrival, is a fault."""
        deadline = self._last_arrival + self.bound
        self._handle(0)
        waited = not self._inbox
        while not self._inbox:
            self._check_stop()
            now = self._clock()
            if now > deadline:
                # drained once more first: a status that arrived while this thread was
                # descheduled between the last drain and the clock's reading is not silence
                self._handle(0)
                if self._inbox:
                    break
                self.longest_silence = max(self.longest_silence, now - self._last_arrival)
                raise self._fault(
                    f"no lcmt_panda_status on {self.config.status_channel} for "
                    f"{(now - self._last_arrival) * 1e3:.1f} ms ({self._bound_words()})"
                )
            remaining = deadline - now
            self._handle(1 if remaining > 1e-3 else 0)
            self._handle(0)  # the force-torque message of the same instant, and any newer status
        if waited:
            self.longest_silence = max(self.longest_silence, self._inbox[0][0] - self._last_arrival)

    def tick(self) -> None:
        """Waits for the next status and answers the newest (module docstring): its rules in
        compiled code (:func:`nsdrake.driver.tick.take_statuses`), or, where that refuses or
        cannot tell, in Python (:meth:`_take_in_python`), which says why in words."""
        self._wait_for_a_status()
        self._check_stop()
        inbox = self._inbox
        count = len(inbox)
        if self.compiled and count <= COMPILED_INBOX:
            if self._motion_config is not self.config:  # driver.max_joint_step sets the allowances
                self._motion, self._motion_config = self._motion_table(), self.config
            raw, lengths = self._raw, self._lengths
            for k, (_, _, _, data) in enumerate(inbox):
                size = lengths[k] = len(data)
                raw[k, : min(size, STATUS_SIZE)] = np.frombuffer(data, np.uint8, min(size, STATUS_SIZE))
            if not take_statuses(
                raw, lengths, count, self._fingerprint, self._ints, self._floats, self._limits, self._motion,
                self._scratch,
            ):  # fmt: skip
                arrival, wall, cpu, data = inbox[-1]
                self.compiled_ticks += 1
                self.skipped += count - 1
                inbox.clear()
                self.time = self.periods * self.period
                self._answer(data, arrival, wall, cpu)
                return
        self._take_in_python()

    def _take_in_python(self) -> None:
        """:meth:`tick`'s rules on the inbox, step by step in Python: the same rules as the
        compiled path's, each refusal in words."""
        inbox = self._inbox
        for _, _, _, data in inbox:  # every status received, in order: their clocks, whatever the inbox holds
            problem = self._status.problem(data)
            if problem:
                raise self._fault(f"status refused: {problem}")
            clock = (
                self._status.robot_utime(data)
                if self.clock_name == "robot_utime"
                else self._status.utime(data)
            )
            problem = clock_problem(
                clock,
                self._last_clock,
                self._anchor,
                self.period_us,
                self.bound_periods,
                self.clock_name,
            )
            if problem:
                raise self._fault(f"status refused: {problem}")
            gap_periods = elapsed_periods(clock, self._anchor, self.period_us) - elapsed_periods(
                self._last_clock, self._anchor, self.period_us
            )
            self._long_gaps = self._long_gaps + 1 if gap_periods >= 2 else 0
            problem = slow_stream_problem(
                self._long_gaps, clock - self._last_clock, self.period_us, self.clock_name
            )
            if problem:
                raise self._fault(f"status refused: {problem}")
            self._last_clock = clock
            self._anchor += anchor_step(clock, self._anchor, self.period_us, self._accepted)
            self._accepted += 1
        arrival, wall, cpu, data = inbox[-1]
        self.skipped += len(inbox) - 1
        inbox.clear()
        periods = elapsed_periods(self._last_clock, self._anchor, self.period_us)
        self._q_last[:], self._v_last[:] = self._q, self._v
        self._load(data, "status refused: ", checked=True)  # decodable: checked with its clock above
        self._check_motion(periods - self.periods)
        self.periods = periods
        self.time = periods * self.period
        self._answer(data, arrival, wall, cpu)

    def run(self, duration: float, progress=None) -> None:
        """start(), then tick() until the controller's clock reaches ``duration`` [s]."""
        self.start()
        while self.time < duration - 0.5 * self.period:
            self.tick()
            if progress is not None and self.commands % 1000 == 0:
                progress(min(1.0, self.time / duration))

    def _load(self, data: bytes, refused: str, checked: bool = False) -> None:
        """The status's q, q̇, τ_ext into the loop's arrays, checked: decodable, finite,
        within the Panda's limits."""
        status = self._status
        problem = None if checked else status.problem(data)
        if problem:
            raise self._fault(refused + problem)
        status.load(data)
        self._ints[I_UTIME] = status.utime(data)  # the command's stamp (tick.finish_tick)
        measured = self._measured  # rows q, q̇, τ_ext: one finiteness test, one limit test
        measured[0], measured[1], measured[2] = status.q, status.v, status.tau_ext
        if not np.isfinite(measured.sum()):
            names = ("joint_position", "joint_velocity", "joint_torque_external")
            for name, values in zip(names, measured, strict=True):
                bad = np.flatnonzero(~np.isfinite(values))
                if bad.size:
                    raise self._fault(f"{refused}{name}[{bad[0]}] is {float(values[bad[0]])!r}")
        deviation = self._deviation  # |[q; q̇] − centre| ≤ half-width: within the limits, in 3 operations
        np.subtract(measured[:2], ENVELOPE_CENTRE, out=deviation)
        np.abs(deviation, out=deviation)
        if not (deviation <= ENVELOPE_HALF_WIDTH).all():
            problem = limit_problem(self._q, self._v, self._names)
            if problem:
                raise self._fault(refused + problem)
        if status.robot_utime(data):  # a driver that reports the robot's own state (drake-franka-driver)
            mode = status.robot_mode
            if mode != ROBOT_MODE_MOVE:
                name = ROBOT_MODES.get(mode, "unknown")
                raise self._fault(
                    f"{refused}the robot is in mode {name} ({mode}), not kMove ({ROBOT_MODE_MOVE}): "
                    "it applies no torque command"
                )
            if self.commands >= SUCCESS_RATE_WINDOW:  # before, the rate counts cycles before the drive
                rate = status.success_rate
                self.success_rate_min = rate if not rate >= self.success_rate_min else self.success_rate_min

    def _measured_wrench(self, arrival: float) -> np.ndarray:
        """The wrench for the status that arrived at ``arrival``: estimated, or the newest
        force-torque message, which must have arrived within the silence bound before the
        status (both stamped as the loop drains the bus: a tick preempted after the drain
        is not the sensor's silence)."""
        side = self.side
        if not side.sensor:
            return side.estimated_wrench(self._q, self._tau_ext)
        message = self._wrench_message
        if self._force_torque is not None:
            self._force_torque_arrival, data = self._force_torque
            self._force_torque = None
            if not self.compiled or decode_force_torque(  # compiled: into message.wrench, else
                np.frombuffer(data, np.uint8), self._ft_fingerprint, self._scratch, message.wrench
            ):  # the Python path, which says why it refuses  # fmt: skip
                problem = message.problem(data)
                if problem:
                    raise self._fault(
                        f"force-torque message refused on {self.config.force_torque_channel}: {problem}"
                    )
                message.load(data)
        silent = arrival - self._force_torque_arrival
        if silent > self.bound:
            raise self._fault(
                f"no lcmt_force_torque on {self.config.force_torque_channel} for {silent * 1e3:.1f} ms "
                f"({self._bound_words()})"
            )
        return message.wrench

    def _answer(self, data: bytes, arrival: float, wall: float, cpu: float) -> None:
        """The controller side's tick for the loaded status, its command sent and recorded:
        the torques, the last gate and the command's bytes in compiled code
        (:func:`nsdrake.driver.tick.finish_tick`), the gate's refusal in words from
        :func:`nsdrake.driver.panda.command_problem`."""
        wrench = self._measured_wrench(arrival)
        np.copyto(self._wrench, wrench)
        side = self.side
        desired, result = side.compute(self.time, self._q, self._v, self._wrench)
        if not self.compiled:
            robot_torques(result.tau, side.step.gravity, side.adds_gravity, side.at_robot, side.command)
            self._gate_in_python(data)
        elif finish_tick(
            result.tau, side.step.gravity, side.adds_gravity, side.at_robot, side.command, self._at_robot,
            self._gate, self._ints, self._command_bytes, self._scratch,
        ):  # fmt: skip
            self._gate_in_python(data)
        self.bus.publish(self.config.command_channel, self._command.buffer)
        self.commands += 1
        self._last_arrival = arrival
        self.times.record(time.perf_counter() - wall, time.thread_time() - cpu)
        self.recorder.record(
            self.time,
            self._q,
            self._v,
            self._wrench,
            desired,
            result,
            side.command,
            side.reference.in_contact,
        )

    def _gate_in_python(self, data: bytes) -> None:
        """The last gate in words (what the robot's torque interface is asked for, the
        command or τ − g(q) when the driver subtracts its g(q): driver.robot_adds_gravity
        false); a command it passes is encoded here."""
        side = self.side
        problem = command_problem(side.at_robot, self._at_robot, self._names)  # the first: the status's
        if problem and not side.adds_gravity:
            problem = f"with the driver's g(q) subtracted (driver.robot_adds_gravity false): {problem}"
        if problem:  # the last gate: nothing beyond the robot's published limits leaves
            raise self._fault(f"command refused, not sent: {problem}")
        self._command.set(self._status.utime(data), side.command)
        self._at_robot[:] = side.at_robot

    def _silence_at_start(self) -> str:
        c = self.config
        if not self._inbox:
            return (
                f"no lcmt_panda_status on {c.status_channel} within {c.first_status_timeout:g} s; "
                "nothing was sent"
            )
        return (
            f"no lcmt_force_torque on {c.force_torque_channel} within {c.first_status_timeout:g} s "
            f"although {len(self._inbox)} lcmt_panda_status arrived (driver.force_source: sensor; "
            "drake-franka-driver publishes none: use driver.force_source: external_torque); nothing was sent"
        )

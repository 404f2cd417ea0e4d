"""What the controller must know about a Franka Panda behind its LCM driver.

The published limits (Franka Emika's FCI documentation, "Robot and interface
specifications": joint torque limits 87 N m for joints 1–4 and 12 N m for joints
5–7, torque-rate limit 1000 N m/s for every joint) are applied twice:

- by the controller's own actuator limits (:mod:`nsdrake.control.actuator_limits`) to
  what the joints are asked for: τ of the law when the robot applies it, the command
  τ − g(q) when the robot adds g itself (Franka's torque interface checks its limits on
  that command, the torque it is asked for on top of its own gravity compensation): the
  limiter's torque window is then centred on g(q) and its rate reference follows g
  (:class:`nsdrake.control.step.ControllerStep`'s ``robot_adds_gravity``);
- by the last gate before the wire (:func:`command_problem`) to what is sent, after
  everything that shapes it. The limiter keeps every command inside, so the gate catches
  faults only (a limiter on τ alone sent issue 43's 431 N m on joint 2 with 100 kg): it
  stops the drive before such a command leaves.

A payload heavier than the Panda's published rating (:data:`RATED_PAYLOAD`) is refused
before anything is built (:func:`payload_rating_problem`), and so is a world gravity no
robot on Earth has (:func:`robot_gravity_problem`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from nsdrake.control.config import ActuatorLimitsConfig

NUM_JOINTS = 7  # pydrake.manipulation.kPandaArmNumJoints
TORQUE_LIMITS = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])  # [N m], joints 1–7
TORQUE_RATE_LIMIT = 1000.0  # [N m/s], every joint
ROBOT_CYCLE = 1e-3  # [s] the Panda's control cycle (1 kHz): a new command acts within one
# Franka's published payload (datasheet, "Payload 3 kg"): everything the flange carries, a
# Franka Hand (about 0.7 kg) included, so a payload beside a hand may weigh that much less.
RATED_PAYLOAD = 3.0  # [kg]
MASS_ROUNDING = 1e-9  # [kg] what the rating forgives: the rounding of a sum of the model's masses
# The size of gravity anywhere a robot stands on Earth's surface: from 9.7639 m/s² (the top
# of Nevado Huascarán) to 9.8337 m/s² (the Arctic Ocean's surface) (C. Hirt et al., "New
# ultrahigh-resolution picture of Earth's gravity field", Geophys. Res. Lett. 40 (2013)
# 4279–4283), rounded outward. The robot adds g(q) of its own model on Earth; a controller
# whose model has another gravity subtracts something else, and the difference drives the arm.
EARTH_GRAVITY = (9.76, 9.84)  # [m/s²]
# What the gate forgives beyond a limit: the rounding of τ − g and of the limiter's clip
# (a few units of the last place of 100 N m), far below any torque the robot resolves.
COMMAND_ROUNDING = 1e-9  # [N m]


class PandaLimitError(ValueError):
    """Limits or a model that do not fit the Panda; the message is one line."""


def command_rate_limit(period: float) -> float:
    """The largest |dτ/dt| [N m/s] a limiter sampled every ``period`` [s] may allow on the
    Panda: the robot applies each new command at its next :data:`ROBOT_CYCLE`, so
    consecutive commands may differ by TORQUE_RATE_LIMIT × ROBOT_CYCLE at most (the gate's
    bound, :func:`command_problem`), whatever the period: 1000 N m/s at 1 ms, 500 at 2 ms."""
    return float(TORQUE_RATE_LIMIT) * min(1.0, ROBOT_CYCLE / period)


def panda_actuator_limits(
    limits: ActuatorLimitsConfig, joint_names: tuple[str, ...], *, period: float
) -> ActuatorLimitsConfig:
    """The scenario's actuator limits with the Panda's published ones wherever the scenario
    gives none, joint k of the model being the Panda's joint k + 1; the torque rate at the
    control period ``period`` [s] (:func:`command_rate_limit`). A scenario limit above those
    is refused (never clamped silently): PandaLimitError naming it."""
    if len(joint_names) != NUM_JOINTS:
        raise PandaLimitError(
            f"the Panda driver speaks {NUM_JOINTS} joints; the scenario's arm has {len(joint_names)}"
        )
    torque, rate = dict(limits.torque), dict(limits.torque_rate)
    rate_limit = command_rate_limit(period)
    at_period = (
        ""
        if rate_limit == TORQUE_RATE_LIMIT
        else f" over its {ROBOT_CYCLE * 1e3:g} ms cycle, {rate_limit:g} N m/s at a {period * 1e3:g} ms "
        "control period (each command reaches the robot within one cycle)"
    )
    for k, name in enumerate(joint_names):
        for kind, table, published, unit, why in (
            ("torque", torque, TORQUE_LIMITS[k], "N m", ""),
            ("torque_rate", rate, rate_limit, "N m/s", at_period),
        ):
            if name not in table:
                table[name] = float(published)
            elif table[name] > published:
                quoted = TORQUE_RATE_LIMIT if kind == "torque_rate" else published
                raise PandaLimitError(
                    f"actuator_limits.{kind}.{name}: {table[name]:g} {unit} is above the Panda's "
                    f"published limit {quoted:g} {unit} for joint {k + 1}{why}"
                )
    return dataclasses.replace(limits, torque=torque, torque_rate=rate)


# Franka's published joint limits (FCI documentation, "Limits for Panda"), joints 1–7.
POSITION_LOWER = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])  # [rad]
POSITION_UPPER = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])  # [rad]
VELOCITY_LIMIT = np.array([2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100])  # [rad/s]
# How far a status may report a joint beyond them before the controller stops: the robot
# itself stops with a reflex at the limits, so a reading beyond them by more than its
# sensing noise (≈ 1e-4 rad, 1e-2 rad/s) is a robot out of its envelope or a broken
# stream: 0.01 rad of position, 5% of the velocity limit.
POSITION_MARGIN = 0.01  # [rad]
VELOCITY_MARGIN = 0.05  # [-] of VELOCITY_LIMIT


_LOWER, _UPPER = POSITION_LOWER - POSITION_MARGIN, POSITION_UPPER + POSITION_MARGIN
# The same limits as a box around a centre, rows q and q̇: |[q; q̇] − centre| ≤ half-width
ENVELOPE_CENTRE = np.array([(_LOWER + _UPPER) / 2, np.zeros(7)])
ENVELOPE_HALF_WIDTH = np.array([(_UPPER - _LOWER) / 2, VELOCITY_LIMIT * (1.0 + VELOCITY_MARGIN)])
_FAST = VELOCITY_LIMIT * (1.0 + VELOCITY_MARGIN)


def limit_problem(q: np.ndarray, v: np.ndarray, joint_names) -> str | None:
    """A joint position or velocity beyond the Panda's published limits by more than the
    margins above (the worst joint named), else None."""
    if (
        (q >= _LOWER).all() and (q <= _UPPER).all() and (v <= _FAST).all() and (v >= -_FAST).all()
    ):  # the usual case, in four array comparisons (this runs inside every tick)
        return None
    below = POSITION_LOWER - POSITION_MARGIN - q
    above = q - POSITION_UPPER - POSITION_MARGIN
    fast = np.abs(v) - VELOCITY_LIMIT * (1.0 + VELOCITY_MARGIN)
    for excess, kind in ((below, "below"), (above, "above")):
        k = int(np.argmax(excess))
        if excess[k] > 0.0:
            limit = POSITION_LOWER[k] if kind == "below" else POSITION_UPPER[k]
            return (
                f"{joint_names[k]} is at {q[k]:.4f} rad, {kind} the Panda's limit {limit:g} rad "
                f"by more than {POSITION_MARGIN:g} rad"
            )
    k = int(np.argmax(fast))
    return (
        f"{joint_names[k]} moves at {v[k]:.4g} rad/s, beyond the Panda's limit {VELOCITY_LIMIT[k]:g} rad/s "
        f"by more than {VELOCITY_MARGIN:.0%}"
    )


# A status's position against Franka's velocity limits and against its own reported velocity
# (nsdrake.driver.faults.jump_problem, velocity_mismatch_problem). Both allow the sensing noise
# of the two readings compared (POSITION_NOISE each). The second compares the position change
# Δq over Δt with the trapezoid of the two reported velocities, (q̇₀ + q̇₁) Δt / 2. For any
# motion, Δq − (q̇₀ + q̇₁) Δt / 2 = ∫₀^Δt (Δt/2 − s) q̈(s) ds: the acceleration weighted by at
# most Δt/2. So with |q̈| ≤ A (Franka's published acceleration limit of the joint) and an
# impact that changes the joint's velocity by at most ΔV at any instant, the gap is at most
# A Δt²/4 + ΔV Δt/2, and exactly that for the motion that accelerates at +A for half the
# interval and −A for the other (the impact at one end): the bound is tight at every Δt,
# and nothing else is allowed but the noise of the two velocity readings (VELOCITY_NOISE
# each, 2 × VELOCITY_NOISE × Δt/2). The velocity limit never binds first within the
# silence bound: A Δt / 2 ≤ 20 rad/s² × 0.05 s = 1 rad/s, below every joint's limit.
# (Before issue 43 one acceleration of 100 rad/s², five times the largest published, held
# over the whole interval: 0.063 rad over 50 ms, so a joint could creep at 1.2 rad/s across
# a gap of the silence bound while its velocity read zero; now 7.9e-3 rad on joint 2.)
# IMPACT_VELOCITY_CHANGE is the velocity change that rule allowed within one period
# (100 rad/s² × 1 ms), kept so that a contact's impact passes as before: one period's
# allowance is 2.6e-4 rad (2.35e-4 rad before), and a position that creeps at 0.3 rad/s
# while its velocity reads zero is still refused at one period; over 50 periods the
# allowance is 7.9e-3 rad on joint 2, 1.6e-2 on joints 6-7 (joint 2 creeping at
# 0.16 rad/s, joint 7 at 0.32 rad/s across the longest gap is refused).
POSITION_NOISE = 1e-4  # [rad] per reading
VELOCITY_NOISE = 1e-2  # [rad/s] per reading
# Franka's published joint acceleration limits (FCI documentation, "Limits for Panda"), joints 1–7
ACCELERATION_LIMIT = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])  # [rad/s²]
IMPACT_VELOCITY_CHANGE = 0.1  # [rad/s] the most one impact changes a joint's velocity by


def joint_step_allowance(elapsed: float) -> np.ndarray:
    """The most each joint may move in ``elapsed`` [s] [rad]: its velocity limit with
    VELOCITY_MARGIN, plus the noise of two readings."""
    return VELOCITY_LIMIT * (1.0 + VELOCITY_MARGIN) * elapsed + 2.0 * POSITION_NOISE


def slowest_joint_speed() -> float:
    """The smallest of Franka's published joint velocity limits [rad/s]."""
    return float(VELOCITY_LIMIT.min())


def velocity_mismatch_allowance(elapsed: float) -> np.ndarray:
    """The most each joint's position change over ``elapsed`` [s] may differ from the
    trapezoid of its two reported velocities [rad]: A Δt²/4 + ΔV Δt/2 with the noise of the
    readings (the comment above argues each term)."""
    return (
        2.0 * POSITION_NOISE
        + VELOCITY_NOISE * elapsed
        + ACCELERATION_LIMIT * elapsed**2 / 4.0
        + IMPACT_VELOCITY_CHANGE * elapsed / 2.0
    )


START_TOLERANCE_PERIODS = 2  # driver.start_tolerance's bound, in periods at the slowest joint's limit


def panda_driver_problems(driver, period: float):
    """Yields (field, problem) for the scenario's ``driver`` settings (a
    :class:`nsdrake.experiment.driver_config.DriverConfig`) beyond what the Panda allows at
    the control period [s]: ``start_tolerance`` above what its slowest joints move in
    START_TOLERANCE_PERIODS periods at their velocity limit (the field's comment argues
    the bound), ``max_joint_step`` above one period's allowance of the slowest joint."""
    tolerance = START_TOLERANCE_PERIODS * slowest_joint_speed() * period
    if driver.start_tolerance > tolerance:
        yield (
            "start_tolerance",
            f"must be at most {tolerance:.4g} rad (what the Panda's slowest joints move in "
            f"{START_TOLERANCE_PERIODS} control periods at their velocity limit), "
            f"got {driver.start_tolerance!r}",
        )
    step = float(joint_step_allowance(period).min())
    if driver.max_joint_step > step:
        yield (
            "max_joint_step",
            f"must be at most {step:.4g} rad (a period at the slowest joint's velocity limit, with the "
            f"margins of nsdrake/driver/panda.py), got {driver.max_joint_step!r}",
        )


def robot_gravity_problem(gravity) -> str | None:
    """A world gravity [gx, gy, gz] [m/s²] no robot on Earth's surface has: its size outside
    :data:`EARTH_GRAVITY` (None: within it). Its direction is the robot's mounting, which
    only the user knows (docs/real_arm.md, "Gravity")."""
    size = float(np.linalg.norm(np.asarray(gravity, dtype=float)))
    low, high = EARTH_GRAVITY
    if not low <= size <= high:
        return (
            f"{size:.4g} m/s² is not the gravity of a robot on Earth ({low:g}-{high:g} m/s² anywhere on its "
            "surface): the robot adds g(q) of its own model on Earth, and the controller would subtract "
            "another g(q)"
        )
    return None


def flange_load(plant, last_joint, leave_out=None) -> tuple[float, tuple[str, ...]]:
    """What the arm's flange carries in ``plant``'s model, as Franka's rating counts it
    (:data:`RATED_PAYLOAD`): the mass [kg] of every body that ``last_joint`` moves but its
    own child link and ``leave_out`` (a body, or None) — a tool, a hand, fingers locked to
    it, a welded payload — and their names. Plain Drake calls on the finalized plant."""
    moved = plant.GetBodiesKinematicallyAffectedBy([last_joint.index()])
    skip = {last_joint.child_body().index()} | ({leave_out.index()} if leave_out is not None else set())
    bodies = [plant.get_body(b) for b in moved if b not in skip]
    carried = [b for b in bodies if b.default_mass() > 0.0]
    return float(sum(b.default_mass() for b in carried)), tuple(b.name() for b in carried)


def payload_rating_problem(mass, carried: float = 0.0, names: tuple[str, ...] = ()) -> str | None:
    """A payload of ``mass`` [kg] on top of the ``carried`` kg the model's flange already
    holds (:func:`flange_load`: the bodies ``names``) heavier than the Panda's published
    rating, :data:`RATED_PAYLOAD` (None: within it)."""
    if mass + carried > RATED_PAYLOAD + MASS_ROUNDING:
        model = f" and the model's {carried:g} kg beyond the flange ({', '.join(names)})" if carried else ""
        return (
            f"{mass:g} kg{model} is above the Panda's published payload of {RATED_PAYLOAD:g} kg (everything "
            "the flange carries counts, a Franka Hand's mass too): the arm is not rated to carry it"
        )
    return None


_COMMAND_BOUND = TORQUE_LIMITS + COMMAND_ROUNDING
_RATE_BOUND = TORQUE_RATE_LIMIT * ROBOT_CYCLE + COMMAND_ROUNDING  # [N m] per robot cycle


def command_problem(command: np.ndarray, previous: np.ndarray | None, joint_names) -> str | None:
    """The last gate before the wire: why the torque ``command`` about to be sent breaks the
    Panda's published limits (the worst joint named), else None. Its magnitude against
    :data:`TORQUE_LIMITS`; with ``previous`` (the command sent before it; None for a drive's
    first), its change against :data:`TORQUE_RATE_LIMIT` over one :data:`ROBOT_CYCLE`:
    the robot applies each new command at its next 1 kHz cycle, so a status the controller
    skipped does not spread a step over the periods missed. Both with
    :data:`COMMAND_ROUNDING`. A command that is not finite is refused too."""
    size = np.abs(command)
    if previous is None:
        if (size <= _COMMAND_BOUND).all():  # the usual case, two array operations (every tick)
            return None
    else:
        change = np.abs(np.subtract(command, previous))
        if (size <= _COMMAND_BOUND).all() and (change <= _RATE_BOUND).all():
            return None
    bad = np.flatnonzero(~np.isfinite(command))
    if bad.size:
        return f"{joint_names[bad[0]]}'s command is {float(command[bad[0]])!r}"
    excess = size - TORQUE_LIMITS
    k = int(np.argmax(excess))
    if excess[k] > COMMAND_ROUNDING:
        return (
            f"{joint_names[k]} would be sent {command[k]:.4g} N m, beyond the Panda's published "
            f"{TORQUE_LIMITS[k]:g} N m for joint {k + 1}"
        )
    rate = change / ROBOT_CYCLE
    k = int(np.argmax(rate))
    return (
        f"{joint_names[k]}'s command would change by {command[k] - previous[k]:.4g} N m in one "
        f"{ROBOT_CYCLE * 1e3:g} ms cycle ({rate[k]:.4g} N m/s), beyond the Panda's published "
        f"{TORQUE_RATE_LIMIT:g} N m/s"
    )

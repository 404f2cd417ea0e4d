"""The realism ladder: effects of the paper's real robot that its simulations left out.

(No ``from __future__ import annotations`` here: Drake's ``yaml_load_typed`` reads
the dataclass field types at run time.)

Section 4 of the paper: on the real arm the force "is rather noisy and oscillates
around the desired force", and the authors blame "the excessive elasticity of the
drive belts between the robot motors and the robot joints and friction in the
gears". A scenario's ``realism`` section switches on, one by one, the effects that
separate a clean simulation from that robot. Every rung is off by default (a
scenario without a ``realism`` section simulates exactly as before), and every
default value below says where it comes from; where no datasheet of the paper's
hardware exists, the value is a stated choice.

- ``physics``: the plant steps ``substeps`` times per control period while the
  controller is sampled and held at the control period, a 500 Hz digital
  controller on a (nearly) continuous robot (:mod:`nsdrake.station.control_hold`).
- ``force_sensor``: the JR3 under the plate, with noise, bias, its own sampling
  and its low-pass filter (:mod:`nsdrake.realism.wiring`).
- ``friction``: smoothed Coulomb and viscous friction in every joint's gear
  (:mod:`nsdrake.station.friction`).
- ``belt``: each joint driven by a motor with rotor inertia through the paper's
  gear ratio of 6 and an elastic belt (:mod:`nsdrake.station.elastic`); the controller
  measures the motor side, as the real one did.
- ``delay``: whole control periods between sampling and applying the torque.
- ``model_error``: the controller's model with the link and tool masses off by a
  fraction (:mod:`nsdrake.realism.model_error`).
"""

import math
from dataclasses import dataclass, field


@dataclass
class PhysicsConfig:
    """The plant steps finer than the controller, which is sampled and held."""

    # Turn this rung on; every rung is off by default [-].
    enabled: bool = False
    # Plant steps per control period, a power of two (2 ms / 4 = 0.5 ms): then every
    # controller event falls on a plant step at exactly the same floating-point time,
    # which Drake needs to order the controller's sample before the plant's step.
    # Choice: the 0.25–0.5 ms range [-].
    substeps: int = 4


@dataclass
class ForceSensorConfig:
    """The six-axis sensor under the plate (the paper's JR3), as a signal chain:
    true wrench + bias + white noise, sampled every ``sample_period``, then a
    first-order low-pass filter; the controller reads the filter's output.

    JR3's DSP-based sensors of the 1990s sample their strain gauges internally at
    kilohertz rates and offer a cascade of fixed digital low-pass filters (one of
    them is characterised in Kaczmarczyk et al., Electronics 9 (2020) 1291). The
    numbers below are choices in that class, not read off the paper's sensor's
    datasheet, which is not available: an 8 kHz internal rate, a 125 Hz cutoff,
    and noise and bias of the order of a few counts of a ±100 N sensor.
    """

    # Turn this rung on; every rung is off by default [-].
    enabled: bool = False
    # Standard deviation of the white noise on each force axis, per internal sample,
    # before the filter (the filter leaves ≈ 0.22 of it at the defaults) [N].
    noise_force: float = 0.3
    # The same on each moment axis [N m].
    noise_moment: float = 0.01
    # Constant bias of the reading, in the sensor's frame (the plate frame: +y is the
    # push), e.g. what a tare leaves after a temperature drift [N].
    bias_force: list[float] = field(default_factory=lambda: [0.0, 0.1, 0.0])
    # The same for the moment [N m].
    bias_moment: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    # The sensor's own sampling period (8 kHz); a power-of-two fraction of the
    # control period, for the same reason as physics.substeps [s].
    sample_period: float = 1.25e-4
    # Cutoff of the first-order low-pass filter, f_c = 1/(2π τ); 0 leaves it out [Hz].
    filter_cutoff: float = 125.0
    # Seed of the noise: the same seed gives the same traces, another seed others [-].
    seed: int = 1


@dataclass
class FrictionConfig:
    """Gear friction in every joint, τ_f = −(τ_c tanh(v/v_s) + b v) (:mod:`nsdrake.station.friction`).

    Acting at the gear output: on the joint of the rigid arm, on the motor side of
    the belt with ``belt`` on. The plant then steps at least ``min_substeps`` times
    per control period (friction needs it; finer physics alone changes fig3's figures
    by less than 0.005 N, see the table in docs/claims.md). The numbers are choices for a light arm with
    low-ratio gears (the paper gives none): τ_c is 3–6% of the 1.6–2.9 N m joints 1–3
    carry in fig3 while pressing 10 N (a quarter of joint 4's 0.4 N m).
    """

    # Turn this rung on; every rung is off by default [-].
    enabled: bool = False
    # Coulomb friction torque τ_c [N m].
    coulomb: float = 0.1
    # Viscous friction coefficient b [N m s/rad].
    viscous: float = 0.02
    # Speed v_s over which the Coulomb torque changes sign (tanh). It sets the friction's
    # slope τ_c/v_s + b at rest, which the discrete plant applies explicitly, from the
    # state at the start of its step: without chatter only while (τ_c/v_s + b) h max λ(H⁻¹)
    # < 1. For fig3's arm max λ(H⁻¹) ≈ 1.1e3 /(kg m²) over all poses, so at h = 0.5 ms:
    # v_s = 0.08 gives 0.70 (0.05 would give 1.12) [rad/s].
    smoothing_speed: float = 0.08
    # The plant steps at least this many times per control period while friction is on
    # (a power of two): 2 ms is too coarse for any v_s that leaves friction Coulomb-like
    # (at 2 ms the joints chatter as they break away from rest, measured). The margin is
    # checked against the model before a run [-].
    min_substeps: int = 4


@dataclass
class BeltConfig:
    """Belt elasticity: each joint driven by a motor through the paper's gear ratio
    and an elastic belt, Spong's flexible-joint model (:mod:`nsdrake.station.elastic`):
    the motor (rotor inertia I_m, reflected N² I_m) sits on the previous link and
    drives the link through a torsional spring–damper. The controller measures the
    motor encoders, q̂ = q_m/N, as the paper's controller did, and its model stays
    the rigid arm.
    """

    # Turn this rung on; every rung is off by default [-].
    enabled: bool = False
    # Gear ratio N between motor and joint (paper, Section 4: "low gear ratios (6)") [-].
    gear_ratio: float = 6.0
    # Rotor inertia of each motor I_m, on the motor shaft; the joint sees N² I_m. Choice
    # forced by stability, not a datasheet: 3e-3 kg m² (0.108 kg m² reflected) is the
    # lightest of 1e-4, 2e-4, 4e-4, 1e-3, 1.5e-3, 3e-3 with which fig3's controller stays
    # stable with every other rung on (1.5e-3 without the delay). A real 400–750 W AC
    # servo's rotor, ~1e-4 (1 kg cm²), makes it diverge within 20 ms: the belt leaves the
    # rotor alone at high frequency, and the velocity gains, computed with the link
    # inertia H, then give T K H / (N² I_m) > 2 on it [kg m²].
    rotor_inertia: float = 3.0e-3
    # Torsional stiffness of each belt, at the joint: choice, a timing belt of some
    # 0.5 m span (specific stiffness ~3e5 N) on a 3 cm pulley, 2 c/L r² ≈ 1e3 [N m/rad].
    stiffness: float = 1000.0
    # Damping of the belt, at the joint: choice, a damping ratio of ≈ 0.05 against a
    # link of 0.05 kg m² (belts are lightly damped) [N m s/rad].
    damping: float = 0.7


@dataclass
class DelayConfig:
    """Computation delay: the torque computed from the sample at t_k is applied from
    t_{k+periods} (a controller that sends its output at the next tick)."""

    # Turn this rung on; every rung is off by default [-].
    enabled: bool = False
    # Whole control periods of delay [-].
    periods: int = 1


@dataclass
class ModelErrorConfig:
    """The controller's model with every link mass and the tool mass (and with them
    the inertias) scaled by (1 + mass_error); the simulated arm keeps the URDF's."""

    # Turn this rung on; every rung is off by default [-].
    enabled: bool = False
    # Relative error of the model's masses. Choice: −20%, a model lighter than the
    # arm, as the paper's would be (belts, pulleys, bearings, cables and the rotors'
    # reflected inertia are not in a link-mass model) [-].
    mass_error: float = -0.2


@dataclass
class RealismConfig:
    """The rungs of the realism ladder; each off by default."""

    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    force_sensor: ForceSensorConfig = field(default_factory=ForceSensorConfig)
    friction: FrictionConfig = field(default_factory=FrictionConfig)
    belt: BeltConfig = field(default_factory=BeltConfig)
    delay: DelayConfig = field(default_factory=DelayConfig)
    model_error: ModelErrorConfig = field(default_factory=ModelErrorConfig)

    @property
    def any(self) -> bool:
        """Whether any rung is on."""
        return any(getattr(self, name).enabled for name in RUNGS)


RUNGS = ("physics", "force_sensor", "friction", "belt", "delay", "model_error")


# Physical ranges: beyond them a setting is no real device's, and a run would take hours.
SHORTEST_STEP = 1e-5  # [s] no plant step (control period / substeps) nor sensor sample shorter: 100 kHz
LONGEST_DELAY = 100  # [periods] of computation delay (0.2 s at fig3's 2 ms); the hold keeps each one
LARGEST_SEED = 2**32 - 1  # Drake's RandomGenerator (a 32-bit Mersenne twister) keeps 32 bits of a seed


def substeps(realism: RealismConfig) -> int:
    """Plant steps per control period: the physics rung's, at least the friction rung's
    minimum, else 1."""
    k = realism.physics.substeps if realism.physics.enabled else 1
    return max(k, realism.friction.min_substeps) if realism.friction.enabled else k


def is_power_of_two(k: int) -> bool:
    return k >= 1 and (k & (k - 1)) == 0


def realism_problems(realism: RealismConfig, control_period: float):
    """Yields (field, problem) for every invalid realism setting. Each value is checked
    whether or not its rung is on; how it must relate to the control period, only when
    the rung is on (the default sensor rate fits the default 2 ms period only)."""
    p = realism.physics
    if isinstance(p.substeps, bool) or not is_power_of_two(p.substeps):
        yield "physics.substeps", f"must be a power of two >= 1 (1, 2, 4, 8, …), got {p.substeps!r}"
    yield from _sensor_problems(realism.force_sensor, control_period)
    f = realism.friction
    for name in ("coulomb", "viscous"):
        value = getattr(f, name)
        if not _finite(value) or value < 0:
            yield f"friction.{name}", f"must be a finite number >= 0, got {value!r}"
    if not _finite(f.smoothing_speed) or f.smoothing_speed <= 0:
        yield "friction.smoothing_speed", f"must be > 0, got {f.smoothing_speed!r}"
    if isinstance(f.min_substeps, bool) or not is_power_of_two(f.min_substeps):
        yield "friction.min_substeps", f"must be a power of two >= 1 (1, 2, 4, 8, …), got {f.min_substeps!r}"
    b = realism.belt
    for name in ("gear_ratio", "rotor_inertia", "stiffness"):
        value = getattr(b, name)
        if not _finite(value) or value <= 0:
            yield f"belt.{name}", f"must be > 0, got {value!r}"
    if not _finite(b.damping) or b.damping < 0:
        yield "belt.damping", f"must be a finite number >= 0, got {b.damping!r}"
    periods = realism.delay.periods
    if isinstance(periods, bool) or not isinstance(periods, int) or periods < 0:
        yield "delay.periods", f"must be an integer >= 0, got {periods!r}"
    elif periods > LONGEST_DELAY:
        yield (
            "delay.periods",
            f"must be at most {LONGEST_DELAY} periods (no real controller lags further), got {periods!r}",
        )
    e = realism.model_error.mass_error
    if not _finite(e) or e <= -1.0:
        yield "model_error.mass_error", f"must be a finite number > -1 (masses stay positive), got {e!r}"


def _sensor_problems(s: ForceSensorConfig, control_period: float):
    """The force sensor's values, its sample period within range and, when on, a power-of-two
    fraction of the control period."""
    for name in ("noise_force", "noise_moment", "filter_cutoff"):
        value = getattr(s, name)
        if not _finite(value) or value < 0:
            yield f"force_sensor.{name}", f"must be a finite number >= 0, got {value!r}"
    for name in ("bias_force", "bias_moment"):
        value = getattr(s, name)
        if len(value) != 3 or not all(_finite(v) for v in value):
            yield f"force_sensor.{name}", f"must be three finite numbers [x, y, z], got {value!r}"
    if not _finite(s.sample_period) or s.sample_period <= 0:
        yield "force_sensor.sample_period", f"must be > 0, got {s.sample_period!r}"
    elif s.sample_period < SHORTEST_STEP:
        yield (
            "force_sensor.sample_period",
            f"{s.sample_period:g} s is shorter than {SHORTEST_STEP:g} s: no force sensor samples faster than "
            f"{1 / SHORTEST_STEP / 1000:g} kHz",
        )
    elif s.enabled:
        ratio = control_period / s.sample_period
        if abs(ratio - round(ratio)) > 1e-9 * ratio or not is_power_of_two(round(ratio)):
            yield (
                "force_sensor.sample_period",
                f"{s.sample_period:g} s must be the control period {control_period:g} s divided by a "
                "power of two",
            )
    if isinstance(s.seed, bool) or not isinstance(s.seed, int) or s.seed < 0:
        yield "force_sensor.seed", f"must be an integer >= 0, got {s.seed!r}"
    elif s.seed > LARGEST_SEED:
        yield (
            "force_sensor.seed",
            f"must be at most {LARGEST_SEED} (Drake's random generator keeps 32 bits of it), got {s.seed!r}",
        )


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

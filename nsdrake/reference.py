"""Desired task trajectories: the Fig. 3 task of Section 4, and a closed path on a surface.

"x is the ramp function with the constant velocity; y changes until the robot
hits the wall", then the desired force is tracked. :class:`SlideAndPress`
gives, at time t and for a contact time t_c (∞ before contact):

- along the plate (unit tangent t): a constant-velocity ramp that reaches its
  speed v_t from rest over ``blend_time``, the speed following a smoothstep so
  that the acceleration starts and ends at zero (no torque step);
- normal to the plate (unit normal n): the same profile at the approach speed
  v_a, frozen where contact was detected;
- the desired normal force f_d: 0 before contact, then a smoothstep from 0 to
  ``force`` over ``force_ramp_time``; optionally a step to ``step_force`` at
  ``step_time`` after contact (the Eq. 26 experiment).

:class:`CircleOnSurface` is the wiping task (panda_wipe): the same approach and
press, then, ``delay`` after contact, the tool follows a circle of radius r on the
surface, ``laps`` times round at speed v, starting and ending at rest (speed
blended with the same smoothstep as the ramp), and stays where it started.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np


def ramp_profile(t: float, speed: float, blend_time: float) -> tuple[float, float, float]:
    """(s, ṡ, s̈) of a ramp that starts at rest and moves at ``speed`` after
    ``blend_time``, with ṡ = speed · smoothstep(t / blend_time) in between (so s̈ is
    continuous and zero at both ends). s(0) = 0."""
    if t <= 0.0:
        return 0.0, 0.0, 0.0
    if blend_time > 0.0 and t < blend_time:
        u = t / blend_time
        # ∫ smoothstep = u³ − u⁴/2; smoothstep' = 6u(1 − u)
        return (
            speed * blend_time * (u**3 - 0.5 * u**4),
            speed * u * u * (3.0 - 2.0 * u),
            speed * 6.0 * u * (1.0 - u) / blend_time,
        )
    return speed * (t - 0.5 * blend_time), speed, 0.0


def smoothstep(u: float) -> float:
    """3u² − 2u³ on [0, 1], 0 below, 1 above."""
    if u <= 0.0:
        return 0.0
    if u >= 1.0:
        return 1.0
    return u * u * (3.0 - 2.0 * u)


@dataclass(frozen=True)
class SlideAndPress:
    """The Fig. 3 reference. m task axes; see the module docstring."""

    x0: np.ndarray  # (m,) tool position at t = 0 [m]
    tangent: np.ndarray  # (m,) unit direction of the ramp along the plate
    normal: np.ndarray  # (m,) unit direction toward (into) the plate
    tangent_speed: float  # [m/s]
    approach_speed: float  # [m/s]
    blend_time: float  # [s]
    force: float  # [N]
    force_ramp_time: float  # [s]
    step_time: float = math.inf  # [s] after contact; ∞: no step
    step_force: float = 0.0  # [N] desired force after the step

    def at(self, t: float, t_contact: float = math.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(x_d, ẋ_d, ẍ_d, f_d) at time t, given the contact time (∞ before contact)."""
        s, sd, sdd = ramp_profile(t, self.tangent_speed, self.blend_time)
        if t < t_contact:
            r, rd, rdd = ramp_profile(t, self.approach_speed, self.blend_time)
            f_d = 0.0
        else:
            r = ramp_profile(t_contact, self.approach_speed, self.blend_time)[0]
            rd = rdd = 0.0
            if t - t_contact >= self.step_time:
                f_d = self.step_force
            elif self.force_ramp_time > 0.0:
                f_d = self.force * smoothstep((t - t_contact) / self.force_ramp_time)
            else:
                f_d = self.force
        x_d = self.x0 + s * self.tangent + r * self.normal
        xdot_d = sd * self.tangent + rd * self.normal
        xddot_d = sdd * self.tangent + rdd * self.normal
        return x_d, xdot_d, xddot_d, f_d


def detect_contact(t: float, t_contact: float, f_n: float, threshold: float) -> float:
    """The contact time: unchanged once set, else t when the normal force reaches ``threshold``."""
    if math.isfinite(t_contact):
        return t_contact
    return t if f_n >= threshold else math.inf


def there_and_back(t: float, length: float, speed: float, blend_time: float) -> tuple[float, float, float]:
    """(s, ṡ, s̈) of a move of ``length`` from rest to rest: :func:`ramp_profile` up to the
    middle, its mirror image after, so ṡ rises to ``speed`` and falls back to 0 with a
    smoothstep over ``blend_time`` at each end. It lasts length/speed + blend_time; s
    stays at ``length`` after. Needs length ≥ speed · blend_time."""
    duration = length / speed + blend_time
    if t <= 0.0:
        return 0.0, 0.0, 0.0
    if t >= duration:
        return length, 0.0, 0.0
    if t <= 0.5 * duration:
        return ramp_profile(t, speed, blend_time)
    s, sd, sdd = ramp_profile(duration - t, speed, blend_time)
    return length - s, sd, -sdd


@dataclass(frozen=True)
class CircleOnSurface:
    """Approach and press as :class:`SlideAndPress` (without sliding), then a circle on the
    surface. m = 3 translational task axes; see the module docstring.

    The circle lies in the plane of the unit tangents t₁ and t₂ = t₁ × n (for a plate,
    its x and z axes). It starts at the contact point p_c, at the angle φ₀ =
    ``start_angle`` on the circle (measured from t₁ toward t₂): its centre is
    c = p_c − r u(φ₀), u(φ) = cos φ t₁ + sin φ t₂, and x_d = c + r u(φ₀ + s/r) with s the
    arc length (:func:`there_and_back`); a negative speed goes round clockwise.
    """

    x0: np.ndarray  # (3,) tool position at t = 0 [m]
    tangent: np.ndarray  # (3,) t₁, unit, in the surface
    normal: np.ndarray  # (3,) n, unit, into the surface
    radius: float  # r [m]
    laps: float  # times round [-]
    speed: float  # v along the circle; negative: clockwise from t₁ toward −t₂ [m/s]
    start_angle: float  # φ₀ [rad]
    delay: float  # [s] from contact to the start of the circle
    approach_speed: float  # [m/s]
    blend_time: float  # [s]
    force: float  # [N]
    force_ramp_time: float  # [s]

    @cached_property
    def tangent2(self) -> np.ndarray:
        """t₂ = t₁ × n, the surface's second tangent. (3,)."""
        return np.cross(self.tangent, self.normal)

    @cached_property
    def _start(self) -> tuple[np.ndarray, float]:
        """u(φ₀), and the circle's length [m]."""
        phi0 = self.start_angle
        return math.cos(phi0) * self.tangent + math.sin(
            phi0
        ) * self.tangent2, 2.0 * math.pi * self.radius * self.laps

    @property
    def duration(self) -> float:
        """Time from the start of the circle to its end [s]."""
        return 2.0 * math.pi * self.radius * self.laps / abs(self.speed) + self.blend_time

    def at(self, t: float, t_contact: float = math.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(x_d, ẋ_d, ẍ_d, f_d) at time t, given the contact time (∞ before contact)."""
        n, t1, t2 = self.normal, self.tangent, self.tangent2
        if t < t_contact:
            r, rd, rdd = ramp_profile(t, self.approach_speed, self.blend_time)
            return self.x0 + r * n, rd * n, rdd * n, 0.0
        r = ramp_profile(t_contact, self.approach_speed, self.blend_time)[0]
        if self.force_ramp_time > 0.0:
            f_d = self.force * smoothstep((t - t_contact) / self.force_ramp_time)
        else:
            f_d = self.force
        u0, length = self._start
        s, sd, sdd = there_and_back(t - t_contact - self.delay, length, abs(self.speed), self.blend_time)
        sign = 1.0 if self.speed >= 0 else -1.0
        s, sd, sdd = sign * s, sign * sd, sign * sdd
        phi = self.start_angle + s / self.radius
        u = math.cos(phi) * t1 + math.sin(phi) * t2
        du = -math.sin(phi) * t1 + math.cos(phi) * t2  # du/dφ
        centre = self.x0 + r * n - self.radius * u0
        x_d = centre + self.radius * u
        xdot_d = sd * du
        xddot_d = sdd * du - (sd * sd / self.radius) * u
        return x_d, xdot_d, xddot_d, f_d

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

from nsdrake.control.smoothing import smoothstep
from nsdrake.control.validation import (
    finite_problem,
    is_index_array,
    is_number,
    non_negative_problem,
    positive_problem,
    show,
    vector_problem,
)

UNIT_TOLERANCE = 1e-6  # how far from 1 a unit direction's norm, and from 0 two directions' product, may be


class TaskReferenceError(ValueError):
    """A task reference (:class:`SlideAndPress`, :class:`CircleOnSurface`,
    :class:`nsdrake.SurfaceReference`) that cannot be built; one line, ``where: problem``."""

    def __init__(self, where: str, problem: str):
        self.where, self.problem = where, problem
        super().__init__(f"{where}: {problem}")


def _raise_first(where: str, problems) -> None:
    for name, problem in problems:
        if problem is not None:
            raise TaskReferenceError(f"{where}.{name}", problem)


def _direction_problem(value, size: int) -> str | None:
    """``value`` is a unit direction of ``size`` entries."""
    problem = vector_problem(value, size, f"a unit direction of {size} numbers (one per axis of x0)")
    if problem is None and abs(float(np.linalg.norm(value)) - 1.0) > UNIT_TOLERANCE:
        problem = f"must be a unit direction (norm 1), got norm {float(np.linalg.norm(value)):.6g}"
    return problem


def _as_arrays(path, names) -> None:
    """The vector fields of a checked (frozen) path as float arrays (a list is taken too)."""
    for name in names:
        if getattr(path, name) is not None:
            object.__setattr__(path, name, np.asarray(getattr(path, name), dtype=float))


def _path_problems(path) -> list[tuple[str, str | None]]:
    """The fields both paths share: the start, the directions, the approach and the press."""
    x0 = np.asarray(path.x0, dtype=float) if vector_problem(path.x0, np.size(path.x0), "") is None else None
    if x0 is None or x0.ndim != 1 or x0.size == 0:
        return [("x0", f"must be the tool position, finite numbers on the task axes, got {show(path.x0)}")]
    m = x0.size
    problems = [("normal", _direction_problem(path.normal, m))]
    speed = getattr(path, "tangent_speed", None)
    no_slide = is_number(speed) and speed == 0.0  # SlideAndPress without the slide: t may be 0
    tangent = np.asarray(path.tangent, dtype=float) if vector_problem(path.tangent, m, "") is None else None
    if not (no_slide and tangent is not None and not tangent.any()):
        problems.append(("tangent", _direction_problem(path.tangent, m)))
    if all(p is None for _, p in problems) and tangent.any():
        along = float(tangent @ np.asarray(path.normal, dtype=float))
        if abs(along) > UNIT_TOLERANCE:
            problems.append(
                ("tangent", f"must be perpendicular to normal, got tangent . normal = {along:.6g}")
            )
    return problems + [
        ("approach_speed", non_negative_problem(path.approach_speed)),
        ("blend_time", non_negative_problem(path.blend_time)),
        ("force", non_negative_problem(path.force)),
        ("force_ramp_time", non_negative_problem(path.force_ramp_time)),
        ("max_overtravel", non_negative_problem(path.max_overtravel)),
    ]


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


@dataclass(frozen=True)
class ContactState:
    """The reference's view of the contact, from the measured normal force alone."""

    t_contact: float = math.inf  # [s] start of the current (or last) contact; ∞: none yet
    r_contact: float = math.nan  # [m] normal offset of x_d frozen at that contact
    t_lost: float = math.inf  # [s] when that contact was declared lost; ∞: not lost
    t_low: float = math.inf  # [s] since when, in contact, the force has been below the threshold

    @property
    def in_contact(self) -> bool:
        return math.isfinite(self.t_contact) and not math.isfinite(self.t_lost)


@dataclass(frozen=True)
class SlideAndPress:
    """The Fig. 3 reference. m task axes; see the module docstring.

    Contact loss (the tool slides off the plate, the plate is out of reach): while
    the normal force stays below the contact threshold for ``loss_time`` the
    contact is declared lost (:func:`update_contact`); from then on f_d falls to 0
    over ``force_ramp_time`` (no force is commanded into free space) and the
    normal reference approaches at most ``max_overtravel`` beyond where the contact
    was, then holds. When the force returns above the threshold, contact resumes
    as at the first contact. The ramp along the plate stops where x_d would leave
    the disc of radius ``reach`` around ``centre`` (the arm's reach, less a margin).
    """

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
    max_overtravel: float = 0.02  # [m] approach beyond a lost contact's surface, at most
    centre: np.ndarray | None = None  # (m,) centre of the reachable disc; None: no limit
    reach: float = math.inf  # [m] its radius

    def __post_init__(self):
        """Every field checked (:class:`TaskReferenceError` naming the first wrong one)."""
        problems = _path_problems(self)
        m = np.size(self.x0)
        problems += [("tangent_speed", finite_problem(self.tangent_speed))]
        step = None if self.step_time == math.inf else positive_problem(self.step_time)
        problems += [
            ("step_time", step and f"{step} (math.inf: no step)"),
            ("step_force", finite_problem(self.step_force)),
        ]
        if self.centre is not None:
            problems.append(
                ("centre", vector_problem(self.centre, m, f"{m} numbers (the task axes) or None"))
            )
        reach = None if self.reach == math.inf else positive_problem(self.reach)
        problems.append(("reach", reach and f"{reach} (math.inf: no limit)"))
        _raise_first("SlideAndPress", problems)
        _as_arrays(self, ("x0", "tangent", "normal", "centre"))

    def at(
        self,
        t: float,
        t_contact: float = math.inf,
        state: ContactState | None = None,
        t_first: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(x_d, ẋ_d, ẍ_d, f_d) at time t, given the contact time (∞ before contact)
        or the whole contact ``state``. (``t_first``, the first contact's time, is
        :class:`CircleOnSurface`'s; the slide is timed from t = 0.)"""
        state = state or ContactState(t_contact=t_contact)
        s, sd, sdd = ramp_profile(t, self.tangent_speed, self.blend_time)
        r, rd, rdd = self._normal(t, state)
        if self.centre is not None:  # first the approach, then the slide, stop at the reach
            r, rd, rdd = self._within_reach(s * self.tangent, self.normal, r, rd, rdd)
            s, sd, sdd = self._within_reach(r * self.normal, self.tangent, s, sd, sdd)
        f_d = self._force(t, state)
        x_d = self.x0 + s * self.tangent + r * self.normal
        xdot_d = sd * self.tangent + rd * self.normal
        xddot_d = sdd * self.tangent + rdd * self.normal
        return x_d, xdot_d, xddot_d, f_d

    def _normal(self, t: float, state: ContactState) -> tuple[float, float, float]:
        """(r, ṙ, r̈): the normal offset of x_d from x0."""
        if t < state.t_contact:
            return ramp_profile(t, self.approach_speed, self.blend_time)
        r_contact = state.r_contact
        if math.isnan(r_contact):  # the first contact, given by its time alone
            r_contact = ramp_profile(state.t_contact, self.approach_speed, self.blend_time)[0]
        if t < state.t_lost:
            return r_contact, 0.0, 0.0
        r, rd, rdd = ramp_profile(t - state.t_lost, self.approach_speed, self.blend_time)
        if r >= self.max_overtravel:
            return r_contact + self.max_overtravel, 0.0, 0.0
        return r_contact + r, rd, rdd

    def _within_reach(self, offset, direction, u, ud, udd) -> tuple[float, float, float]:
        """(u, u̇, ü) of the motion x0 + offset + u·direction, stopped (u̇ = ü = 0) where it
        would leave the disc of radius max(reach, |x0 − centre|) around the centre."""
        if ud == 0.0:
            return u, ud, udd
        a = self.x0 + offset - self.centre
        radius = max(self.reach, float(np.linalg.norm(self.x0 - self.centre)))
        along = float(a @ direction)
        root = math.sqrt(max(along * along - float(a @ a) + radius * radius, 0.0))
        limit = -along + root if ud > 0 else -along - root
        if (u - limit) * ud >= 0.0:
            return limit, 0.0, 0.0
        return u, ud, udd

    def _force(self, t: float, state: ContactState) -> float:
        if t < state.t_contact:
            return 0.0
        f_d = self._pressing(min(t, state.t_lost) - state.t_contact)
        if t >= state.t_lost and self.force_ramp_time > 0.0:
            return f_d * (1.0 - smoothstep((t - state.t_lost) / self.force_ramp_time))
        return 0.0 if t >= state.t_lost else f_d

    def _pressing(self, since_contact: float) -> float:
        if since_contact >= self.step_time:
            return self.step_force
        if self.force_ramp_time > 0.0:
            return self.force * smoothstep(since_contact / self.force_ramp_time)
        return self.force


def update_contact(
    state: ContactState, t: float, f_n: float, threshold: float, loss_time: float, r_now: float
) -> ContactState:
    """The contact state after a measured normal force f_n at time t: contact begins
    when f_n reaches ``threshold`` (the normal reference frozen at its current offset
    ``r_now``), and is lost once f_n has stayed below it for ``loss_time``."""
    if state.in_contact:
        if f_n >= threshold:
            return ContactState(state.t_contact, state.r_contact, math.inf, math.inf)
        t_low = min(state.t_low, t)
        if t - t_low + 1e-9 >= loss_time:  # 1 ns of slack for the rounding of sample times
            return ContactState(state.t_contact, state.r_contact, t, math.inf)
        return ContactState(state.t_contact, state.r_contact, math.inf, t_low)
    if f_n >= threshold:
        return ContactState(t, r_now, math.inf, math.inf)
    return state


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
    """Approach and press as :class:`SlideAndPress` without sliding (contact loss handled
    the same way), then a circle on the surface. m = 3 translational task axes; see the
    module docstring.

    The circle lies in the plane of the unit tangents t₁ and t₂ = t₁ × n (for a plate,
    its x and z axes). It starts at the contact point p_c, at the angle φ₀ =
    ``start_angle`` on the circle (measured from t₁ toward t₂): its centre is
    c = p_c − r u(φ₀), u(φ) = cos φ t₁ + sin φ t₂, and x_d = c + r u(φ₀ + s/r) with s the
    arc length (:func:`there_and_back`), from ``delay`` after the *first* contact (a
    contact lost and regained does not restart it); a negative speed goes round
    clockwise.
    """

    x0: np.ndarray  # (3,) tool position at t = 0 [m]
    tangent: np.ndarray  # (3,) t₁, unit, in the surface
    normal: np.ndarray  # (3,) n, unit, into the surface
    radius: float  # r [m]
    laps: float  # times round [-]
    speed: float  # v along the circle; negative: clockwise from t₁ toward −t₂ [m/s]
    start_angle: float  # φ₀ [rad]
    delay: float  # [s] from the first contact to the start of the circle
    approach_speed: float  # [m/s]
    blend_time: float  # [s]
    force: float  # [N]
    force_ramp_time: float  # [s]
    max_overtravel: float = 0.02  # [m] approach beyond a lost contact's surface, at most

    def __post_init__(self):
        """Every field checked (:class:`TaskReferenceError` naming the first wrong one)."""
        problems = [
            ("x0", vector_problem(self.x0, 3, "[x, y, z], the tool position on the task axes x, y, z"))
        ]
        if problems[0][1] is None:
            problems = _path_problems(self)
        problems += [
            ("radius", positive_problem(self.radius)),
            ("laps", positive_problem(self.laps)),
            ("speed", finite_problem(self.speed)),
            ("start_angle", finite_problem(self.start_angle)),
            ("delay", non_negative_problem(self.delay)),
        ]
        if all(p is None for _, p in problems):
            length = 2.0 * math.pi * self.radius * self.laps
            if self.speed == 0.0:
                problems.append(
                    ("speed", "must not be zero: the circle would never be drawn (and lasts length/speed)")
                )
            elif length < abs(self.speed) * self.blend_time:
                problems.append((
                    "laps",
                    f"the circle ({length:.4g} m) is shorter than its speed blends need "
                    f"(|speed| x blend_time = {abs(self.speed) * self.blend_time:.4g} m)",
                ))  # fmt: skip
        _raise_first("CircleOnSurface", problems)
        _as_arrays(self, ("x0", "tangent", "normal"))

    @cached_property
    def press(self) -> SlideAndPress:
        """The approach and press: :class:`SlideAndPress` without the slide."""
        return SlideAndPress(
            x0=self.x0,
            tangent=self.tangent,
            normal=self.normal,
            tangent_speed=0.0,
            approach_speed=self.approach_speed,
            blend_time=self.blend_time,
            force=self.force,
            force_ramp_time=self.force_ramp_time,
            max_overtravel=self.max_overtravel,
        )

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

    def at(
        self,
        t: float,
        t_contact: float = math.inf,
        state: ContactState | None = None,
        t_first: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(x_d, ẋ_d, ẍ_d, f_d) at time t, given the contact time (∞ before contact) or
        the whole contact ``state``, and the first contact's time (default: the state's)."""
        state = state or ContactState(t_contact=t_contact)
        x_d, xdot_d, xddot_d, f_d = self.press.at(t, state=state)
        t_first = state.t_contact if t_first is None else t_first
        u0, length = self._start
        s, sd, sdd = there_and_back(t - t_first - self.delay, length, abs(self.speed), self.blend_time)
        if s == 0.0 and sd == 0.0:
            return x_d, xdot_d, xddot_d, f_d
        sign = 1.0 if self.speed >= 0 else -1.0
        s, sd, sdd = sign * s, sign * sd, sign * sdd
        phi = self.start_angle + s / self.radius
        u = math.cos(phi) * self.tangent + math.sin(phi) * self.tangent2
        du = -math.sin(phi) * self.tangent + math.cos(phi) * self.tangent2  # du/dφ
        return (
            x_d + self.radius * (u - u0),
            xdot_d + sd * du,
            xddot_d + sdd * du - (sd * sd / self.radius) * u,
            f_d,
        )


def reference_problem(reference, task_rows, contact_threshold, period, loss_time) -> tuple[str, str] | None:
    """(argument, problem) of the first argument
    :class:`nsdrake.experiment.reference_system.SurfaceReferenceSystem` and
    :class:`PlainSurfaceReference` cannot take, or None: ``reference`` a path with ``at``,
    ``x0`` and ``normal`` (:class:`SlideAndPress`, :class:`CircleOnSurface`), ``task_rows``
    one distinct force row (0, 1, 2: x, y, z) per axis of the path, given as integer
    indices (:func:`nsdrake.control.validation.is_index_array`: booleans, which numpy
    takes as the rows 1 and 0, and floats refused), and positive, finite
    ``contact_threshold``, ``period`` and ``loss_time``."""
    if not all(hasattr(reference, name) for name in ("at", "x0", "normal")):
        return "reference", f"must be a SlideAndPress or a CircleOnSurface, got {type(reference).__name__}"
    m = np.size(reference.x0)
    rows = np.asarray(task_rows) if is_index_array(task_rows) else None
    if (
        rows is None
        or rows.shape != (m,)
        or not np.all((rows >= 0) & (rows <= 2))
        or len(set(rows.tolist())) != m
    ):
        return "task_rows", (
            f"must be {m} distinct rows of the measured force as indices (0, 1, 2: x, y, z; "
            f"integers, not booleans or floats), one per axis of the reference's x0, got {show(task_rows)}"
        )
    for name, value in (
        ("contact_threshold", contact_threshold),
        ("period", period),
        ("loss_time", loss_time),
    ):
        problem = positive_problem(value)
        if problem:
            return name, problem
    return None


class PlainSurfaceReference:
    """:class:`nsdrake.experiment.reference_system.SurfaceReferenceSystem` as plain calls,
    for a loop outside a Simulator (``nsdrake drive``): the same path and the same contact
    detection (:func:`update_contact`), in the same order as Drake runs them.

    Once per tick, with the time t_k of the tick and the wrench W_k measured at t_k:
    :meth:`tick` first updates the contact state as the system's periodic update at the
    previous tick's time t_j does (Drake runs it when it advances from t_j: it sees the
    measurement of t_k, and the normal offset of x_d(t_j)), then returns (x_d, ẋ_d, ẍ_d,
    f_d) at t_k. A tick that follows a skipped period (t_k − t_j of two periods or more)
    updates once, at t_j: a missed period is not replayed. The first tick only evaluates.
    Arguments the system would refuse (:func:`reference_problem`) are refused here too,
    with :class:`TaskReferenceError`.
    """

    def __init__(
        self,
        *,
        reference: SlideAndPress | CircleOnSurface,
        task_rows: np.ndarray,
        contact_threshold: float,
        period: float,
        loss_time: float = 0.05,
    ):
        problem = reference_problem(reference, task_rows, contact_threshold, period, loss_time)
        if problem is not None:
            raise TaskReferenceError(f"PlainSurfaceReference.{problem[0]}", problem[1])
        self.path, self._rows = reference, np.asarray(task_rows, dtype=int)
        self._threshold, self._loss_time = contact_threshold, loss_time
        self._offset0 = float(reference.x0 @ reference.normal)
        self.reset()

    def reset(self) -> None:
        self.state, self.first = ContactState(), math.inf
        self._t_previous, self._r_previous = None, 0.0

    def tick(self, t: float, wrench: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """(x_d, ẋ_d, ẍ_d, f_d) at ``t`` [s] after the contact update with ``wrench`` [M; f]
        (6) [N m, N] (class docstring). Refuses (:class:`TaskReferenceError`) a ``t`` that is
        not a finite number or is before the previous tick's, and a wrench that is not 6
        finite real numbers."""
        problem = finite_problem(t) or vector_problem(wrench, 6, "[M; f] (6) [N m, N]")
        if problem is None and self._t_previous is not None and t < self._t_previous:
            problem = (
                f"t = {t:g} s is before the previous tick's {self._t_previous:g} s: reset() to start over"
            )
        if problem is not None:
            where = "t" if finite_problem(t) or problem.startswith("t =") else "wrench"
            raise TaskReferenceError(f"PlainSurfaceReference.tick.{where}", problem)
        if self._t_previous is not None:
            f_n = float(self.path.normal @ wrench[3:][self._rows])
            new = update_contact(
                self.state, self._t_previous, f_n, self._threshold, self._loss_time, self._r_previous
            )
            self.state, self.first = new, min(self.first, new.t_contact)
        out = self.path.at(t, state=self.state, t_first=self.first)
        self._t_previous, self._r_previous = t, float(out[0] @ self.path.normal) - self._offset0
        return out

    @property
    def in_contact(self) -> bool:
        return self.state.in_contact

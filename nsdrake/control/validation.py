"""What the controller refuses: the one home of every rule its inputs must meet.

Each rule is written once, here, and read by everyone who takes those inputs:
:class:`nsdrake.ControllerConfig` (when it is made), :class:`nsdrake.NullSpaceImpedanceController`
(when it is built, since a configuration can change after it was made),
:meth:`nsdrake.ControllerModel.from_urdf`, and the scenario reader
(:mod:`nsdrake.experiment.scenario`), which names the same fields after a scenario's
sections. So the Python API and the command line cannot disagree.

- :func:`config_problems`: every field of a ``ControllerConfig`` on its own (types,
  signs, finiteness, choices, the relations between criteria and selector limits);
- :func:`stability_problems`: the sampled loops at the control period;
- :func:`task_axes_problem`, :func:`arm_problem`, :func:`gravity_problem`,
  :func:`vector_problem`: the task, the arm's joints, gravity and the controller's
  vector arguments;
- :func:`check_against_model` and :func:`check_task_span`: what needs the model (joint
  names, obstacle geometry, redundancy, task axes the arm can span);
- :func:`validate_controller`: all of it, for the controller's constructor;
- :func:`inputs_problem`: what the controller is given at run time, each tick
  (:meth:`nsdrake.ControllerStep.step`'s arguments, the values of the controller's input
  ports), from one compiled pass over the inputs (:func:`nsdrake.control.layout.input_fault`).

Every rule yields or raises one line: ``where: problem``, ``where`` naming the argument
and the field (``config.impedance.K_f``, ``normal``, ``controller_model``). The errors
are :class:`ControllerConfigError`, and at run time :class:`ControllerInputError`.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterator, Sequence

import numpy as np

from nsdrake.control.dynamics import AXIS_NAMES, ROTATION_AXIS_NAMES, parse_task_axes
from nsdrake.control.layout import input_fault
from nsdrake.control.pseudo_inverse import GeneralizedInverse, PseudoInverseKind

NULL_SPACE_SOURCES = ("criteria", "sweep", "posture")
NULL_SPACE_LAWS = (
    "paper",
    "kinematic_posture_pd",
    "dynamically_consistent_posture_pd",
    "dynamically_consistent_torque_pd",
)
REAL_KINDS = "iuf"  # numpy's dtype kinds of real numbers: signed and unsigned integers, floats
SHOW_LENGTH = 80  # [characters] longest echo of a user's value in an error message
# [m/s²] the largest gravity a model may have: 100 g (Earth's 9.81, Jupiter's 24.8; an arm
# in a centrifuge test at most some tens of g). Beyond it the model terms are dominated by
# g, and the 1e-9 agreement of two libraries is rounding, not physics.
LARGEST_GRAVITY = 1000.0
# [m] the largest length or distance from the world origin a model may have: no robot cell
# is larger, and far beyond it the obstacle criterion's cubes overflow (1e200 m → inf).
LARGEST_LENGTH = 100.0
# [rad] the largest posture q_d or offset of a joint: one turn either way holds every pose
# of a revolute joint (for a prismatic one the same number in metres, beyond any arm's
# travel); far beyond it the posture's torque overflows (1e300 rad → inf).
LARGEST_POSTURE = 2.0 * math.pi
# [-] the largest posture weight w (W = diag(w), 1 where not given): six orders of
# magnitude between joints is more than any weighting asks; 1e300 overflows the criterion.
LARGEST_POSTURE_WEIGHT = 1e6


class ControllerConfigError(ValueError):
    """A configuration, model or argument the controller cannot work with; the message
    is one line, ``where: problem``, naming the argument and field (``where``)."""

    def __init__(self, where: str, problem: str | None = None):
        self.where, self.problem = (where, problem) if problem is not None else ("", where)
        super().__init__(f"{where}: {problem}" if problem is not None else where)


class ControllerInputError(ValueError):
    """An input the controller cannot compute a torque from, at run time: an argument of
    :meth:`nsdrake.ControllerStep.step` or the value of an input port of
    :class:`nsdrake.NullSpaceImpedanceController` (the wrong size, a value that is not
    finite, a zero quaternion, a port the task has no use for). One line, ``where:
    problem``, ``where`` naming the argument or the port (and the time)."""

    def __init__(self, where: str, problem: str):
        self.where, self.problem = where, problem
        super().__init__(f"{where}: {problem}")


def entry_names(parts: Sequence[tuple[str, Sequence[str] | int]]) -> list[str]:
    """The name of every entry of a flat input, from its parts in order: (name, size), an
    entry ``name[i]`` each (``name`` alone for size 1), or (name, labels), an entry
    ``name[label]`` each (a joint's name, an axis)."""
    out = []
    for name, labels in parts:
        if isinstance(labels, int):
            labels = [str(i) for i in range(labels)] if labels != 1 else None
        out.extend([name] if labels is None else [f"{name}[{label}]" for label in labels])
    return out


def inputs_problem(values: np.ndarray, names: Sequence[str], quaternion: int = -1) -> str | None:
    """Why the flat inputs ``values`` (entries named ``names``, :func:`entry_names`) give no
    torque, or None: an entry that is not finite, or the desired orientation (the four
    entries from ``quaternion``, when ≥ 0) zero. One compiled pass (about 0.1 µs)."""
    k = input_fault(values, quaternion)
    if k < 0:
        return None
    if k == len(values):
        return f"{names[quaternion].split('[')[0]} is the zero quaternion: it must be a rotation [w, x, y, z]"
    return f"{names[k]} is {values[k]}: must be finite"


# --- values -------------------------------------------------------------------------------


def one_line(text) -> str:
    return " ".join(str(text).split())


def show(value) -> str:
    """``repr(value)`` on one line, cut to SHOW_LENGTH characters with "…"."""
    text = one_line(repr(value))
    return text if len(text) <= SHOW_LENGTH else text[: SHOW_LENGTH - 1] + "…"


def damping_time_problem(damping_time) -> str | None:
    """Why ``damping_time`` (None, or T_D [s]: :class:`nsdrake.control.model.ControllerModel`)
    is no such time, or None."""
    if damping_time is None:
        return None
    if not is_number(damping_time):
        return f"must be a time [s] or None, got {show(damping_time)}"
    if not (math.isfinite(damping_time) and damping_time >= 0.0):
        return f"must be a finite time >= 0 [s] (a plant's step, half a control period), got {damping_time!r}"
    return None


def is_number(value) -> bool:
    """A real number (numpy's too), not a bool nor a string."""
    if type(value) in _PLAIN_NUMBERS:  # the usual case, without the ABC's isinstance (per tick)
        return True
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


_PLAIN_NUMBERS = frozenset((float, int, np.float64, np.int64))


def finite_problem(value) -> str | None:
    if not is_number(value) or not _finite(value):
        return f"must be a finite number, got {show(value)}"
    return None


def _finite(value) -> bool:
    try:
        return math.isfinite(value)
    except OverflowError:  # an int beyond float's range (10**400)
        return False


def positive_problem(value) -> str | None:
    problem = finite_problem(value)
    if problem is None and value <= 0:
        return f"must be > 0, got {show(value)}"
    return problem


def non_negative_problem(value) -> str | None:
    problem = finite_problem(value)
    if problem is None and value < 0:
        return f"must be >= 0, got {show(value)}"
    return problem


def choice_problem(value, choices) -> str | None:
    if not isinstance(value, str) or value not in choices:
        return f"must be one of {', '.join(choices)}, got {show(value)}"
    return None


def switch_problem(value) -> str | None:
    if not isinstance(value, (bool, np.bool_)):
        return f"must be true or false, got {show(value)}"
    return None


def fraction_problem(value) -> str | None:
    """A share in [0, 1)."""
    problem = non_negative_problem(value)
    if problem is None and value >= 1.0:
        return f"must be below 1, got {show(value)}"
    return problem


def is_real_array(value) -> bool:
    """``value`` is real numbers: a real number (:func:`is_number`), a numpy array of
    integers or floats, or a list or tuple (nested or not) of real numbers. Text (numpy
    would read "0.4" as 0.4), booleans (True as 1), complex values (their imaginary part
    dropped), None and object arrays are not. The one rule of every public numeric
    argument, its shape checked after it (:func:`vector_size_problem`); integers are
    taken, and converted to float before any compiled code sees them."""
    if type(value) is np.ndarray or isinstance(value, np.ndarray):
        return value.dtype.kind in REAL_KINDS
    if isinstance(value, (list, tuple)):
        return all(is_real_array(v) for v in value)
    return is_number(value)


def is_index_array(value) -> bool:
    """``value`` is indices: a numpy array of integers, or a list or tuple of integers
    (Python's or numpy's). Not booleans (numpy would take [True, False] as the rows
    [1, 0]), not floats, even whole ones ([0.0, 1.0]: an index is counted, not measured)."""
    if isinstance(value, np.ndarray):
        return value.dtype.kind in "iu"
    if isinstance(value, (list, tuple)):
        return all(isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)) for v in value)
    return False


def real_problem(value, what: str) -> str | None:
    """Why ``value`` is not real numbers (:func:`is_real_array`), naming ``what`` it must
    be and what was given instead (text, booleans, complex values, objects), or None."""
    if is_real_array(value):
        return None
    return f"must be {what} as real numbers ({_kind(value)} refused), got {show(value)}"


def _kind(value) -> str:
    """What a refused value is made of, in words."""
    kinds = {"U": "text", "S": "text", "b": "booleans", "c": "complex values", "O": "objects"}
    if value is None or isinstance(value, (str, bytes)):
        return "None" if value is None else "text"
    try:
        kind = np.asarray(value).dtype.kind
    except (TypeError, ValueError):
        return "a ragged or unknown value"
    if kind in REAL_KINDS:  # numpy made numbers of a list with a bool among them
        return "booleans"
    return kinds.get(kind, type(value).__name__)


def vector_size_problem(value, size: int, what: str) -> str | None:
    """``value`` is ``size`` real numbers (:func:`is_real_array`); ``what`` says what they
    are ("[x, y, z]")."""
    problem = real_problem(value, what)
    if problem is None:
        try:
            shape = np.shape(value)
        except ValueError:  # a ragged list
            shape = None
        if shape != (size,):
            problem = f"must be {what}, got {show(value)}"
    return problem


def vector_problem(value, size: int, what: str) -> str | None:
    """``value`` is ``size`` finite numbers; ``what`` says what they are ("[x, y, z]")."""
    if type(value) is np.ndarray and value.shape == (size,) and value.dtype.kind in REAL_KINDS:
        # the usual case, a real array of the size (is_real_array's and the shape's verdict),
        # in one operation: this runs in every tick of a drive (PlainSurfaceReference.tick)
        return None if np.isfinite(value).all() else f"must be finite, got {show(value)}"
    problem = vector_size_problem(value, size, what)
    if problem is not None:
        return problem
    if not np.all(np.isfinite(np.asarray(value, dtype=float))):
        return f"must be finite, got {show(value)}"
    return None


def table_problems(where: str, table, rule) -> Iterator[tuple[str, str]]:
    """A mapping of joint name to a number, each number checked by ``rule``."""
    if not isinstance(table, dict):
        yield where, f"must be a mapping of joint name to number, got {show(table)}"
        return
    for name, value in table.items():
        if not isinstance(name, str):
            yield where, f"keys must be joint names, got {show(name)}"
            return
        problem = rule(value)
        if problem:
            yield f"{where}.{one_line(name)[:SHOW_LENGTH]}", problem


def _fields(section, where: str, names: Sequence[str]) -> Iterator[tuple[str, str]]:
    """A section is an object with these fields (a ``ControllerConfig`` section)."""
    missing = [n for n in names if not hasattr(section, n)]
    if missing:
        yield where, f"must have the fields {', '.join(names)} (missing {missing[0]}), got {show(section)}"


# --- the configuration's fields --------------------------------------------------------------

_POSITIVE_GAINS = ("K_p_tangent", "K_v_tangent", "K_v_normal", "K_f", "K_p_rotation", "K_v_rotation")
_SWITCHES = ("task_velocity_compensation", "coriolis_compensation", "acceleration_feedforward")
_SELECTOR = ("d_lim", "w_lim", "d_band", "w_band", "q_lim", "q_band", "blend_time")


def config_problems(config) -> Iterator[tuple[str, str]]:
    """(field, problem) for every field of ``config`` (a :class:`nsdrake.ControllerConfig`,
    or any object with its fields) that the controller cannot work with, fields named
    from the configuration's root (``impedance.K_f``). Checks each value on its own and
    the relations between them; nothing here needs the model."""
    sections = ("period", "impedance", "null_space", "desired_null_space", "actuator_limits", "nominal_force")
    problems = list(_fields(config, "config", sections))
    if problems:
        yield from problems
        return
    for where, problem in (("period", positive_problem(config.period)),
                           ("nominal_force", positive_problem(config.nominal_force))):  # fmt: skip
        if problem:
            yield where, problem
    yield from _impedance_problems(config.impedance)
    problems = list(_null_space_problems(config.null_space))
    problems += desired_null_space_problems(config.desired_null_space)
    yield from problems
    if not problems:  # the sections' own rules hold: the fields that read each other
        yield from unused_posture_problems(config.null_space, config.desired_null_space)
    limits = config.actuator_limits
    problems = list(_fields(limits, "actuator_limits", ("torque", "torque_rate")))
    yield from problems
    if not problems:
        for kind in ("torque", "torque_rate"):
            yield from table_problems(f"actuator_limits.{kind}", getattr(limits, kind), positive_problem)


def _impedance_problems(imp) -> Iterator[tuple[str, str]]:
    names = (
        *_POSITIVE_GAINS, "K_p_normal", "gravity_compensation",
        "max_task_inertia", "max_task_rotational_inertia",
    )  # fmt: skip
    problems = list(_fields(imp, "impedance", names))
    if problems:
        yield from problems
        return
    checks = [(name, positive_problem(getattr(imp, name))) for name in _POSITIVE_GAINS]
    checks.append(("K_p_normal", non_negative_problem(imp.K_p_normal)))
    checks.append(("gravity_compensation", switch_problem(imp.gravity_compensation)))
    for name in ("max_task_inertia", "max_task_rotational_inertia"):
        cap = getattr(imp, name)
        if not is_number(cap) or math.isnan(cap) or cap <= 0:
            checks.append((name, f"must be > 0 (inf: no cap), got {show(cap)}"))
    yield from ((f"impedance.{name}", p) for name, p in checks if p)


def _null_space_problems(ns) -> Iterator[tuple[str, str]]:
    problems = list(_fields(ns, "null_space", ("K_n", "pseudo_inverse", "damping", *_SWITCHES)))
    if problems:
        yield from problems
        return
    checks = [
        ("K_n", positive_problem(ns.K_n)),
        ("pseudo_inverse", choice_problem(ns.pseudo_inverse, [k.value for k in PseudoInverseKind])),
        ("damping", non_negative_problem(ns.damping)),
        *((name, switch_problem(getattr(ns, name))) for name in _SWITCHES),
    ]
    checks += _law_problems(ns)
    if not any(p for _, p in checks[1:3]):
        try:
            GeneralizedInverse(PseudoInverseKind(ns.pseudo_inverse), ns.damping)
        except ValueError as e:
            checks.append(("damping", one_line(e)))
    yield from ((f"null_space.{name}", p) for name, p in checks if p)


def _law_problems(ns) -> list[tuple[str, str | None]]:
    """The null-space law and its posture gains: K_ns > 0 and D_ns > 0 for a posture law,
    λ ≥ 0 for the kinematic one, each 0 where the law does not use it."""
    fields = ("posture_stiffness", "posture_damping", "projector_damping")
    missing = [n for n in ("law", *fields) if not hasattr(ns, n)]
    if missing:
        return [(missing[0], "missing")]
    law = choice_problem(ns.law, NULL_SPACE_LAWS)
    if law:
        return [("law", law)]
    pd = ("posture_stiffness", "posture_damping")
    uses = {"paper": (), "kinematic_posture_pd": (*pd, "projector_damping")}.get(ns.law, pd)
    out = []
    for name in fields:
        value = getattr(ns, name)
        if name == "projector_damping" and name in uses:
            out.append((name, non_negative_problem(value)))
        elif name in uses:
            out.append((name, positive_problem(value)))
        elif not is_number(value) or value != 0:
            out.append((name, f"must be 0: the law {ns.law} does not use it, got {show(value)}"))
    return out


def desired_null_space_problems(d) -> Iterator[tuple[str, str]]:
    """The desired null-space velocity's section: its source, the prescribed sweep, the
    criteria, the selector and the joint-speed limits."""
    where = "desired_null_space"
    names = (
        "source",
        "sweep",
        "posture",
        "rotate_gradient",
        "criteria",
        "selector",
        "joint_speed_limits",
        "speed_headroom",
    )
    problems = list(_fields(d, where, names))
    if problems:
        yield from problems
        return
    for name, problem in (
        ("source", choice_problem(d.source, NULL_SPACE_SOURCES)),
        ("rotate_gradient", switch_problem(d.rotate_gradient)),
        ("speed_headroom", fraction_problem(d.speed_headroom)),
    ):
        if problem:
            yield f"{where}.{name}", problem
    yield from _sweep_problems(d.sweep, d.source == "sweep")
    yield from _posture_problems(d.posture)
    yield from _criteria_problems(d.criteria, d.selector)
    yield from table_problems(f"{where}.joint_speed_limits", d.joint_speed_limits, positive_problem)


def _sweep_problems(sweep, used: bool) -> Iterator[tuple[str, str]]:
    where = "desired_null_space.sweep"
    names = ("direction", "amplitude", "frequency", "start_time", "ramp_time")
    problems = list(_fields(sweep, where, names))
    if problems:
        yield from problems
        return
    direction = list(table_problems(f"{where}.direction", sweep.direction, finite_problem))
    yield from direction
    for name in names[1:]:
        problem = non_negative_problem(getattr(sweep, name))
        if problem:
            yield f"{where}.{name}", problem
    if used and not direction and not any(sweep.direction.values()):
        yield f"{where}.direction", "a sweep needs a non-zero direction"


def _posture_problems(posture) -> Iterator[tuple[str, str]]:
    where = "desired_null_space.posture"
    names = ("q_d", "weight", "gain", "offset", "offset_time", "offset_ramp_time")
    problems = list(_fields(posture, where, names))
    if problems:
        yield from problems
        return
    yield from table_problems(f"{where}.q_d", posture.q_d, _posture_angle_problem)
    yield from table_problems(f"{where}.offset", posture.offset, _posture_angle_problem)
    yield from table_problems(f"{where}.weight", posture.weight, _posture_weight_problem)
    gain = finite_problem(posture.gain)
    if gain is None and posture.gain > 0:
        gain = f"must be <= 0 (a negative gain minimises the distance to q_d), got {show(posture.gain)}"
    for name, problem in (
        ("gain", gain),
        ("offset_time", non_negative_problem(posture.offset_time)),
        ("offset_ramp_time", non_negative_problem(posture.offset_ramp_time)),
    ):
        if problem:
            yield f"{where}.{name}", problem


def _posture_angle_problem(value) -> str | None:
    problem = finite_problem(value)
    if problem is None and abs(value) > LARGEST_POSTURE:
        problem = f"must be within ±{LARGEST_POSTURE:.4g} [rad] (one turn either way), got {show(value)}"
    return problem


def _posture_weight_problem(value) -> str | None:
    problem = positive_problem(value)
    if problem is None and value > LARGEST_POSTURE_WEIGHT:
        problem = f"must be in (0, {LARGEST_POSTURE_WEIGHT:g}], got {show(value)}"
    return problem


def unused_posture_problems(null_space, desired) -> Iterator[tuple[str, str]]:
    """A posture setting nothing reads, refused as an unused posture gain of the laws is
    (:func:`_law_problems`): q_d and its offset are read by the posture laws and by the
    source ``posture``; the weight and Eq. 30's gain by the source ``posture`` alone."""
    p, law, source = desired.posture, null_space.law, desired.source
    why = f"nothing uses it (desired_null_space.source is {source} and null_space.law is {law})"
    uses_q_d, uses_gain = law != "paper" or source == "posture", source == "posture"
    where = "desired_null_space.posture"
    for name, used, unset in (
        ("q_d", uses_q_d, p.q_d == {}),
        ("offset", uses_q_d, p.offset == {}),
        ("offset_time", uses_q_d, p.offset_time == 0),
        ("offset_ramp_time", uses_q_d, p.offset_ramp_time == 0),
        ("weight", uses_gain, p.weight == {}),
        ("gain", uses_gain, p.gain == 0),
    ):
        if not used and not unset:
            empty = "empty" if isinstance(getattr(p, name), dict) else "0"
            yield f"{where}.{name}", f"must be {empty}: {why}, got {show(getattr(p, name))}"


def _criteria_problems(crit, sel) -> Iterator[tuple[str, str]]:
    where = "desired_null_space.criteria"
    problems = list(_fields(crit, where, ("obstacle", "joint_torque", "manipulability", "joint_limits")))
    problems += _fields(sel, "desired_null_space.selector", _SELECTOR)
    if problems:
        yield from problems
        return
    checks = [
        ("obstacle.gain", non_negative_problem(crit.obstacle.gain)),
        ("obstacle.influence_distance", positive_problem(crit.obstacle.influence_distance)),
        ("joint_torque.gain", finite_problem(crit.joint_torque.gain)),
        ("manipulability.gain", non_negative_problem(crit.manipulability.gain)),
        ("joint_limits.gain", non_negative_problem(crit.joint_limits.gain)),
        ("joint_limits.influence", positive_problem(crit.joint_limits.influence)),
    ]
    if checks[2][1] is None and crit.joint_torque.gain > 0:
        gain = crit.joint_torque.gain
        checks[2] = (checks[2][0], f"must be <= 0 (a negative gain minimises the torque), got {gain}")
    yield from ((f"{where}.{name}", p) for name, p in checks if p)
    selector = [(name, non_negative_problem(getattr(sel, name))) for name in _SELECTOR]
    yield from ((f"desired_null_space.selector.{name}", p) for name, p in selector if p)
    if any(p for _, p in checks + selector):
        return
    influence = crit.joint_limits.influence
    if sel.q_lim > 0 and _below(influence, sel.q_lim + sel.q_band):
        yield (
            f"{where}.joint_limits.influence",
            f"{influence} rad must be >= selector.q_lim + q_band = {sel.q_lim + sel.q_band:g} rad, or "
            "joint-limit avoidance would have no gradient when it takes level 2",
        )
    distance = crit.obstacle.influence_distance
    if _below(distance, sel.d_lim + sel.d_band):
        yield (
            f"{where}.obstacle.influence_distance",
            f"{distance} m must be >= selector.d_lim + d_band = {sel.d_lim + sel.d_band:g} m, or obstacle "
            "avoidance would have no gradient when it takes level 2",
        )


def _below(value: float, bound: float) -> bool:
    """value < bound beyond rounding: the sum of two decimals a user wrote (0.05 + 0.01 is
    0.060000000000000005 in binary) is not above the same total written as one number."""
    return value < bound and not math.isclose(value, bound, rel_tol=1e-12)


def validate_config(config, name: str = "config") -> None:
    """Raises :class:`ControllerConfigError` for the first of :func:`config_problems`,
    naming it ``name.field``."""
    for where, problem in config_problems(config):
        raise ControllerConfigError(f"{name}.{where}" if where != "config" else name, problem)


# --- the sampled loops ---------------------------------------------------------------------


def sampled_loop_radius(K: float, D: float, T: float) -> float:
    """Spectral radius of one task direction's loop with stiffness K [1/s²] and damping
    D [1/s] sampled at T [s]: semi-implicit Euler of ẍ = −D ẋ − K x, the torque held over
    the step, v' = v + T (−D v − K x), x' = x + T v' (exact model: each task direction
    a unit mass, ẍ = ẍ_c)."""
    M = np.array([[1.0 - T * T * K, T * (1.0 - T * D)], [-T * K, 1.0 - T * D]])
    return float(np.max(np.abs(np.linalg.eigvals(M))))


def stability_problems(config, rotational: bool) -> Iterator[tuple[str, str]]:
    """The impedance loops along the plate, normal to it and (``rotational``: a pose task)
    on the rotational rows must have a spectral radius below 1 at the period T, and the
    null-space loop ėⁿ = −K_n eⁿ sampled at T needs K_n T < 2. Assumes config_problems
    found nothing."""
    imp, T = config.impedance, config.period
    loops = [
        ("K_p_tangent, K_v_tangent", imp.K_p_tangent, imp.K_v_tangent),
        ("K_p_normal, K_v_normal", imp.K_p_normal, imp.K_v_normal),
    ]
    if rotational:
        loops.append(("K_p_rotation, K_v_rotation", imp.K_p_rotation, imp.K_v_rotation))
    for where, K, D in loops:
        radius = sampled_loop_radius(K, D, T)
        if not radius < 1.0:
            yield (
                f"impedance.{where}",
                f"({K:g}, {D:g}) sampled every {T:g} s is unstable (spectral radius {radius:.3g} ≥ 1); "
                "lower the gains or the period",
            )
    K_n = config.null_space.K_n
    if K_n * T >= 2.0:
        yield (
            "null_space.K_n",
            f"K_n T = {K_n * T:.3g} ≥ 2: beyond the discrete stability bound of ėⁿ = −K_n eⁿ sampled every "
            f"{T:g} s (K_n < {2.0 / T:g})",
        )


# --- the task, the arm, gravity ------------------------------------------------------------


def task_axes_problem(axes) -> tuple[str, str] | None:
    """(index, problem) unless ``axes`` are distinct names among x, y, z, rx, ry, rz, the
    translational ones first; ``index`` is "[i]" for an axis that is no axis name, else ""."""
    valid = AXIS_NAMES + ROTATION_AXIS_NAMES
    if isinstance(axes, str) or not isinstance(axes, Sequence):
        return "", f"must be a list of axes among {', '.join(valid)}, got {show(axes)}"
    for i, a in enumerate(axes):
        problem = choice_problem(a, valid)
        if problem:
            return f"[{i}]", problem
    if not axes or len(set(axes)) != len(axes):
        return "", f"must be distinct axes, got {show(list(axes))}"
    try:
        parse_task_axes(axes)
    except ValueError as e:
        return "", one_line(e)
    return None


def arm_problem(n: int, m: int, task_axes) -> tuple[str, str] | None:
    """(argument, problem) unless the arm has joints, and more of them than task axes (a
    null space): ``controller_model`` or ``task_axes``."""
    if n == 0:
        return "controller_model", "the arm has no revolute or prismatic joint: nothing to control"
    if m >= n:
        return (
            "task_axes",
            f"{list(task_axes)} on an arm of {n} joint{'s' if n > 1 else ''} leave no redundancy for a null "
            "space (the controller needs more joints than task axes)",
        )
    return None


def length_problem(values, what: str) -> str | None:
    """Lengths or coordinates [m] finite and within LARGEST_LENGTH; ``what`` names them."""
    values = np.asarray(values, dtype=float).ravel()
    if not np.all(np.isfinite(values)):
        return f"{what} must be finite, got {show(values.tolist())}"
    if values.size and np.max(np.abs(values)) > LARGEST_LENGTH:
        return f"{what} {np.max(np.abs(values)):.3g} m is beyond the {LARGEST_LENGTH:g} m nsdrake models"
    return None


def gravity_problem(gravity) -> str | None:
    """[gx, gy, gz], finite, at most LARGEST_GRAVITY long."""
    problem = vector_problem(gravity, 3, "[gx, gy, gz]")
    if problem is None and np.linalg.norm(np.asarray(gravity, dtype=float)) > LARGEST_GRAVITY:
        size = float(np.linalg.norm(np.asarray(gravity, dtype=float)))
        return f"{size:.3g} m/s² is beyond the {LARGEST_GRAVITY:g} m/s² (100 g) nsdrake models"
    return problem


# --- what needs the model ------------------------------------------------------------------


def check_against_model(config, model, name: str = "config") -> None:
    """Refuses, in one line, what the model cannot do: joint names it does not have,
    obstacle avoidance without link and obstacle geometry, a task with no redundancy,
    task axes the arm cannot span."""
    d = config.desired_null_space
    for where, table in (
        ("desired_null_space.joint_speed_limits", d.joint_speed_limits),
        ("desired_null_space.sweep.direction", d.sweep.direction),
        ("desired_null_space.posture.q_d", d.posture.q_d),
        ("desired_null_space.posture.weight", d.posture.weight),
        ("desired_null_space.posture.offset", d.posture.offset),
        ("actuator_limits.torque", config.actuator_limits.torque),
        ("actuator_limits.torque_rate", config.actuator_limits.torque_rate),
    ):
        for joint in table:
            if joint not in model.joint_names:
                raise ControllerConfigError(
                    f"{name}.{where}.{joint}",
                    f"unknown joint; the arm's joints are {', '.join(model.joint_names)}",
                )
    if d.criteria.obstacle.gain > 0 and not model.has_geometry:
        raise ControllerConfigError(
            f"{name}.desired_null_space.criteria.obstacle.gain",
            "the controller model has no link collision geometry or no obstacles to keep away from "
            "(set the gain to 0, or build the model with obstacles)",
        )
    uses_posture = config.null_space.law != "paper" or d.source == "posture"
    missing = [j for j in model.joint_names if j not in d.posture.q_d]
    if uses_posture and missing:
        raise ControllerConfigError(
            f"{name}.desired_null_space.posture.q_d",
            f"the posture objective needs every joint; missing {', '.join(missing)}",
        )
    if uses_posture:
        posture_limit_problem(d.posture, model, name)
    problem = arm_problem(model.n, model.m, model.arm.task_axes)
    if problem:
        raise ControllerConfigError(*problem)
    check_task_span(model)


def posture_limit_problem(posture, model, name: str = "config") -> None:
    """Refuses a posture q_d, or q_d plus its offset, outside a joint's position limits (the
    model's URDF limits, where finite): the posture would drive the joint into its stop."""
    lower, upper = model.plant.GetPositionLowerLimits(), model.plant.GetPositionUpperLimits()
    for joint, lo, hi in zip(model.joint_names, lower, upper, strict=True):
        q_d = posture.q_d[joint]
        for what, value in (("q_d", q_d), ("q_d + offset", q_d + posture.offset.get(joint, 0.0))):
            if not lo <= value <= hi:
                raise ControllerConfigError(
                    f"{name}.desired_null_space.posture.q_d.{joint}",
                    f"{what} = {value:.6g} is outside the joint's limits [{lo:.6g}, {hi:.6g}] "
                    "(the posture would drive it into its stop)",
                )


SPAN_SAMPLES = 8  # random poses at which the task Jacobian's rank is checked
SPAN_TOLERANCE = 1e-8  # σ_min / σ_max of J below this counts as rank-deficient


def check_task_span(model, seed: int = 0) -> None:
    """Refuses, in one line, task axes the arm cannot span: J (m × n) rank-deficient at
    every one of SPAN_SAMPLES seeded random poses within the joint limits (e.g. a
    vertical axis, or a rotation out of the plane, for a planar arm). The message names
    the task axes that the missing direction involves."""
    plant = model.plant
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    lower = np.where(np.isfinite(lower), lower, -np.pi)
    upper = np.where(np.isfinite(upper), upper, np.pi)
    rng = np.random.default_rng(seed)
    context = plant.CreateDefaultContext()
    zero = np.zeros(model.n)
    best, direction = 0.0, None
    for _ in range(SPAN_SAMPLES):
        J = model.arm.terms(context, rng.uniform(lower, upper), zero, False).J
        U, sigma, _ = np.linalg.svd(J)
        ratio = sigma[-1] / sigma[0] if sigma[0] > 0 else 0.0
        if ratio > SPAN_TOLERANCE:
            return
        if direction is None or ratio >= best:
            best, direction = ratio, U[:, -1]
    axes = model.arm.task_axes
    involved = [a for a, u in zip(axes, direction, strict=True) if abs(u) > 0.1]
    raise ControllerConfigError(
        f"task axes {list(axes)}: the arm cannot span them (J has rank < {model.m} at every sampled pose; "
        f"no joint moves the tool along {' + '.join(involved)})"
    )


def validate_controller(*, config, model, normal, wrench_point) -> np.ndarray | None:
    """Every check of :class:`nsdrake.NullSpaceImpedanceController`'s arguments, in one
    call, before any system is built: the configuration's fields, its sampled loops at
    its period, ``normal`` and ``wrench_point``, then what needs the model. Returns the
    unit normal: ``normal`` is a direction, normalised here (any finite non-zero length
    is taken as that direction); None (no force axis: a free-space position or pose
    task) stays None. Raises :class:`ControllerConfigError`."""
    validate_config(config, "config")
    for where, problem in stability_problems(config, rotational=model.arm.m_r > 0):
        raise ControllerConfigError(f"config.{where}", problem)
    m_t = model.arm.m_t
    axes = list(model.arm.task_axes[:m_t])
    problem = None
    if normal is not None:
        problem = vector_problem(normal, m_t, f"{m_t} numbers, a direction on the task axes {axes}, or None")
    if problem is None and normal is not None and not np.linalg.norm(np.asarray(normal, dtype=float)) > 0:
        problem = (
            f"must be a non-zero direction on the task axes {axes} (or None: no force axis), "
            f"got {show(normal)}"
        )
    if problem:
        raise ControllerConfigError("normal", problem)
    if wrench_point is not None:
        problem = vector_problem(wrench_point, 3, "[x, y, z] or None")
        if problem:
            raise ControllerConfigError("wrench_point", problem)
    check_against_model(config, model)
    if normal is None:
        return None
    unit = np.asarray(normal, dtype=float)
    return unit / np.linalg.norm(unit)

"""Where the controller's tick keeps its numbers: flat float arrays with named views.

The compiled stages (:mod:`nsdrake.control.stages`) take a few flat arrays instead of
dozens of small ones (each argument of a compiled call costs its dispatch time), and
read them through views that name their parts:

- the **plan** (:func:`plan_views`): the controller's constants (gains, limits, the
  criteria's settings, the geometry of links and obstacles), built once from the model,
  the task and the :class:`ControllerConfig` (:mod:`nsdrake.control.plan`); its integer
  part (task rows, orderings, joint indices) in a second array (:func:`index_views`);
- the **terms** (:func:`terms_views`): the model terms at the measured state, written by
  the first stage and read by all the others;
- the **tick** (:func:`tick_views`): every stage's output, in the order of the fused
  system's packed output port.

``dims`` is an int64 array [n, m, m_t, m_r, nj, k, o]: joints, task axes (translational,
rotational), joint poses kept for the obstacle criterion, link geometries, obstacles.
Each views function checks that the buffer it is given has exactly the size of its
layout; its ``*_size`` twin computes that size, so the two never drift apart unnoticed.
The views are numba namedtuples: a stage reads ``T.H`` or ``P.K_n`` by name.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba import njit

N_, M_, MT_, MR_, NJ_, K_, O_ = range(7)  # entries of dims
CRITERIA = 4  # criterion rows, in nsdrake.control.priority.Criterion's order
CRITERION_WIDTH_EXTRA = 3  # [Φ (n); p; s; a]
LINK_WIDTH = (
    8  # per link geometry: axis centre (3) and direction (3) in its joint's frame, half length, radius
)
OBSTACLE_WIDTH = (
    16  # per obstacle: kind (0 box, 1 sphere), R_WO (9, row-major), p_WO (3), half sizes or radius (3)
)
MODES = 5  # nsdrake.control.priority.Mode
POSTURE_SCALARS = 8  # the null-space law's code, K_ns, D_ns, λ and the posture objective's scalars

TermsView = namedtuple(
    "TermsView",
    (
        "q", "v", "H", "H_inv", "Cv", "g", "C", "J", "J_spatial", "dJ_dq", "Jdot", "Jdot_v", "xdot",
        "H_inv_Jt", "Lambda", "J_pinv", "N", "A_inv", "p_WT", "R_WT", "x", "X_joints", "J_joints",
    ),
)  # fmt: skip

PlanView = namedtuple(
    "PlanView",
    (
        # task torque (Eqs. 6–8)
        "K_p", "K_v", "normal", "K_f", "p_WSo", "has_p_WSo", "gravity",
        # model terms: Λ's caps 1/Λ_max (translational rows [1/kg], rotational [1/(kg m²)]),
        # the inverse (Eq. 13 or not, λ), C wanted
        "inertia_floor", "rotational_inertia_floor", "inertia_weighted", "damping", "coriolis",
        # criteria
        "F_d", "lower", "upper", "limits_influence", "has_limits",
        "obstacle_mode", "obstacle_influence", "links", "link_support", "obstacles",
        # selector and sweep
        "gains", "selector_limits", "blend_time", "rotate", "active", "command_limits",
        "sweep", "direction", "sweep_wave",
        # null space (Eq. 21) and actuator limits
        "K_n", "period", "task_velocity_compensation", "coriolis_compensation", "feedforward",
        "tau_max", "rate_max",
        # the torque window about g(q), not 0: the robot adds g(q) to the command τ − g(q)
        # (nsdrake.control.actuator_limits; ControllerStep's robot_adds_gravity)
        "limits_about_gravity",
        # the null-space law (nsdrake.control.null_space_laws) and the posture objective
        "law", "posture_stiffness", "posture_damping", "projector_damping", "posture_source", "posture_gain",
        "posture_offset_time", "posture_ramp_time", "q_d", "posture_offset", "posture_weight",
    ),
)  # fmt: skip

IndexView = namedtuple(
    "IndexView",
    (
        "rows",
        "rot_rows",
        "spatial_rows",
        "own",
        "other",
        "order",
        "tool_support",
        "orderings",
        "counts",
        "link_joint",
    ),
)

TickView = namedtuple("TickView", ("limited", "null_space", "selection", "qdot", "task", "criteria", "x"))


@njit(cache=True, inline="always")
def _take(buf, o, k):
    return buf[o : o + k], o + k


@njit(cache=True)
def terms_size(dims) -> int:
    n, m, m_t, nj = dims[N_], dims[M_], dims[MT_], dims[NJ_]
    # in the order of terms_views
    return (
        n + n + n * n + n * n + n + n + n * n + m * n + 6 * n + n * m * n + m * n + m + m
        + n * m + m * m + n * m + n * n + m * m + 3 + 9 + m_t + 12 * nj + 6 * n
    )  # fmt: skip


@njit(cache=True, inline="always")
def terms_views(buf, dims) -> TermsView:
    """The model terms at one state (:class:`nsdrake.control.dynamics.RobotTerms` names them)."""
    if buf.shape[0] != terms_size(dims):
        raise ValueError("terms buffer of the wrong size")
    n, m, m_t, nj = dims[N_], dims[M_], dims[MT_], dims[NJ_]
    q, o = _take(buf, 0, n)
    v, o = _take(buf, o, n)
    H, o = _take(buf, o, n * n)
    H_inv, o = _take(buf, o, n * n)
    Cv, o = _take(buf, o, n)
    g, o = _take(buf, o, n)
    C, o = _take(buf, o, n * n)
    J, o = _take(buf, o, m * n)
    J_spatial, o = _take(buf, o, 6 * n)
    dJ_dq, o = _take(buf, o, n * m * n)
    Jdot, o = _take(buf, o, m * n)
    Jdot_v, o = _take(buf, o, m)
    xdot, o = _take(buf, o, m)
    H_inv_Jt, o = _take(buf, o, n * m)
    Lambda, o = _take(buf, o, m * m)
    J_pinv, o = _take(buf, o, n * m)
    N, o = _take(buf, o, n * n)
    A_inv, o = _take(buf, o, m * m)
    p_WT, o = _take(buf, o, 3)
    R_WT, o = _take(buf, o, 9)
    x, o = _take(buf, o, m_t)
    X_joints, o = _take(buf, o, 12 * nj)
    J_joints, o = _take(buf, o, 6 * n)
    return TermsView(
        q, v, H.reshape((n, n)), H_inv.reshape((n, n)), Cv, g, C.reshape((n, n)), J.reshape((m, n)),
        J_spatial.reshape((6, n)), dJ_dq.reshape((n, m, n)), Jdot.reshape((m, n)), Jdot_v, xdot,
        H_inv_Jt.reshape((n, m)), Lambda.reshape((m, m)), J_pinv.reshape((n, m)), N.reshape((n, n)),
        A_inv.reshape((m, m)), p_WT, R_WT.reshape((3, 3)), x, X_joints.reshape((nj, 3, 4)),
        J_joints.reshape((6, n)),
    )  # fmt: skip


@njit(cache=True)
def plan_size(dims) -> int:
    n, m, k, o = dims[N_], dims[M_], dims[K_], dims[O_]
    # in the order of plan_views
    return (
        m * m + m * m + m + 7 + 3 + m + n + n + 5 + k * LINK_WIDTH + k * n + o * OBSTACLE_WIDTH
        + CRITERIA + 6 + 4 + n + n + 4 + 5 + n + n + 1 + POSTURE_SCALARS + 3 * n
    )  # fmt: skip


@njit(cache=True, inline="always")
def plan_views(buf, dims) -> PlanView:
    """The controller's constants (module docstring; :mod:`nsdrake.control.plan` fills them)."""
    if buf.shape[0] != plan_size(dims):
        raise ValueError("plan buffer of the wrong size")
    n, m, k, n_obs = dims[N_], dims[M_], dims[K_], dims[O_]
    K_p, o = _take(buf, 0, m * m)
    K_v, o = _take(buf, o, m * m)
    normal, o = _take(buf, o, m)
    s, o = _take(
        buf, o, 7
    )  # K_f, has_p_WSo, gravity, inertia_floor, inertia_weighted, damping, rotational floor
    p_WSo, o = _take(buf, o, 3)
    F_d, o = _take(buf, o, m)
    lower, o = _take(buf, o, n)
    upper, o = _take(buf, o, n)
    c, o = _take(buf, o, 5)  # coriolis, limits_influence, has_limits, obstacle_mode, obstacle_influence
    links, o = _take(buf, o, k * LINK_WIDTH)
    link_support, o = _take(buf, o, k * n)
    obstacles, o = _take(buf, o, n_obs * OBSTACLE_WIDTH)
    gains, o = _take(buf, o, CRITERIA)
    selector_limits, o = _take(buf, o, 6)
    e, o = _take(buf, o, 4)  # blend_time, rotate, active, sweep
    command_limits, o = _take(buf, o, n)
    direction, o = _take(buf, o, n)
    sweep_wave, o = _take(buf, o, 4)
    ns, o = _take(buf, o, 5)  # K_n, period, task velocity, Coriolis, feedforward
    tau_max, o = _take(buf, o, n)
    rate_max, o = _take(buf, o, n)
    about_gravity, o = _take(buf, o, 1)
    # law, K_ns, D_ns, λ, posture source, K of Eq. 30, offset time, offset ramp time
    law, o = _take(buf, o, POSTURE_SCALARS)
    q_d, o = _take(buf, o, n)
    posture_offset, o = _take(buf, o, n)
    posture_weight, o = _take(buf, o, n)
    return PlanView(
        K_p.reshape((m, m)), K_v.reshape((m, m)), normal, s[0], p_WSo, s[1] != 0.0, s[2] != 0.0,
        s[3], s[6], s[4] != 0.0, s[5], c[0] != 0.0,
        F_d, lower, upper, c[1], c[2] != 0.0,
        int(c[3]), c[4], links.reshape((k, LINK_WIDTH)), link_support.reshape((k, n)),
        obstacles.reshape((n_obs, OBSTACLE_WIDTH)),
        gains, selector_limits, e[0], e[1] != 0.0, e[2] != 0.0, command_limits,
        e[3] != 0.0, direction, sweep_wave,
        ns[0], ns[1], ns[2] != 0.0, ns[3] != 0.0, ns[4] != 0.0,
        tau_max, rate_max, about_gravity[0] != 0.0,
        int(law[0]), law[1], law[2], law[3], law[4] != 0.0, law[5], law[6], law[7],
        q_d, posture_offset, posture_weight,
    )  # fmt: skip


@njit(cache=True)
def index_size(dims) -> int:
    n, m, m_t, m_r, k = dims[N_], dims[M_], dims[MT_], dims[MR_], dims[K_]
    # in the order of index_views
    return m_t + m_r + m + n * n + n * n + n + n + MODES * CRITERIA + MODES + k


@njit(cache=True, inline="always")
def index_views(buf, dims) -> IndexView:
    """The plan's integer part: task rows, the joint-pair masks of ∂J/∂q, the joint order
    of the model library, the tool's supporting joints, Fig. 1's orderings, each link
    geometry's joint."""
    if buf.shape[0] != index_size(dims):
        raise ValueError("index buffer of the wrong size")
    n, m, m_t, m_r, k = dims[N_], dims[M_], dims[MT_], dims[MR_], dims[K_]
    rows, o = _take(buf, 0, m_t)
    rot_rows, o = _take(buf, o, m_r)
    spatial_rows, o = _take(buf, o, m)
    own, o = _take(buf, o, n * n)
    other, o = _take(buf, o, n * n)
    order, o = _take(buf, o, n)
    tool_support, o = _take(buf, o, n)
    orderings, o = _take(buf, o, MODES * CRITERIA)
    counts, o = _take(buf, o, MODES)
    link_joint, o = _take(buf, o, k)
    return IndexView(
        rows, rot_rows, spatial_rows, own.reshape((n, n)) != 0, other.reshape((n, n)) != 0, order,
        tool_support, orderings.reshape((MODES, CRITERIA)), counts, link_joint,
    )  # fmt: skip


@njit(cache=True)
def tick_size(dims) -> int:
    n, m_t = dims[N_], dims[MT_]
    # in the order of tick_views
    return (n + 2) + (2 * n + 1) + (n + 2) + n + n + CRITERIA * (n + CRITERION_WIDTH_EXTRA) + m_t


@njit(cache=True, inline="always")
def tick_views(buf, dims) -> TickView:
    """Every stage's output: ``limited`` [τ (n); s; clipped] (actuator limits), ``null_space``
    [τ₀ (n); eⁿ (n); ν] (Eq. 21), ``selection`` [the selector's q̇_dⁿ (n); mode; speed scale],
    ``qdot`` the q̇_dⁿ used (the selector's or the sweep's), ``task`` τ − τ₀ (Eqs. 6–8),
    ``criteria`` (4, n + 3) one [Φ; p; s; a] row per criterion, ``x`` the task position."""
    if buf.shape[0] != tick_size(dims):
        raise ValueError("tick buffer of the wrong size")
    n, m_t = dims[N_], dims[MT_]
    limited, o = _take(buf, 0, n + 2)
    null_space, o = _take(buf, o, 2 * n + 1)
    selection, o = _take(buf, o, n + 2)
    qdot, o = _take(buf, o, n)
    task, o = _take(buf, o, n)
    criteria, o = _take(buf, o, CRITERIA * (n + CRITERION_WIDTH_EXTRA))
    x, o = _take(buf, o, m_t)
    return TickView(limited, null_space, selection, qdot, task, criteria.reshape((CRITERIA, n + 3)), x)


def tick_parts(n: int, m_t: int) -> dict[str, int]:
    """The tick buffer's parts as the fused system's Demultiplexer splits them, in order,
    with their sizes: each of the controller's output ports is one part."""
    criterion = ("gradient", "value", "switching", "activation")
    parts = {
        "generalized_force": n, "saturation": 2,
        "null_space_torque": n, "null_space_velocity_error": n, "lyapunov": 1,
        "selector_velocity": n, "mode": 1, "speed_scale": 1,
        "desired_null_space_velocity": n, "task_torque": n,
    }  # fmt: skip
    for c in ("obstacle", "joint_torque", "manipulability", "joint_limits"):
        parts |= {f"{c}_{part}": size for part, size in zip(criterion, (n, 1, 1, 1), strict=True)}
    parts["task_position"] = m_t
    return parts


def make_dims(n: int, m: int, m_t: int, m_r: int, nj: int, k: int, o: int) -> np.ndarray:
    return np.array([n, m, m_t, m_r, nj, k, o], dtype=np.int64)


def field_slices(views, size: int, dims: np.ndarray) -> dict[str, tuple[int, tuple[int, ...]]]:
    """{field: (start, shape)} of the array fields of a views function over a float buffer
    of ``size``, read off the views of a buffer whose entries are their own indices: the
    Python side's cheap way to one field (:func:`field`), from the one layout."""
    probe = views.py_func(np.arange(size, dtype=float), dims)  # in Python: nothing to compile
    out = {}
    for name, view in zip(probe._fields, probe, strict=True):
        if isinstance(view, np.ndarray):
            out[name] = (int(view.flat[0]) if view.size else 0, view.shape)
    return out


def field(buffer: np.ndarray, slices: dict, name: str) -> np.ndarray:
    """The view of ``buffer`` that :func:`field_slices` names ``name``."""
    start, shape = slices[name]
    return buffer[start : start + int(np.prod(shape))].reshape(shape)


@njit(cache=True)
def input_fault(values: np.ndarray, quaternion: int) -> int:
    """-1 when every entry of ``values`` is finite and, for ``quaternion`` ≥ 0, the four
    entries from there (a desired orientation [w, x, y, z]) are not all zero; else the index
    of the first non-finite entry, or ``values``' length for a zero quaternion. The one
    run-time check of the controller's inputs (:mod:`nsdrake.control.validation`), a single
    compiled pass: about a tenth of a microsecond."""
    for i in range(values.shape[0]):
        if not math.isfinite(values[i]):
            return i
    if quaternion >= 0:
        s = 0.0
        for i in range(quaternion, quaternion + 4):
            s += values[i] * values[i]
        if s == 0.0:  # as nsdrake.control.orientation.quaternion_to_rotation tests it
            return values.shape[0]
    return -1

"""The controller's tick: one ordered sequence of stages over preallocated arrays.

This module is the one home of the stages and their order. Each stage reads the flat
arrays of :mod:`nsdrake.control.layout` (the plan's constants, the model terms, the
criteria, the discrete state, the inputs) and writes its output into the tick buffer;
the math inside each stage is the math of its own module, called, never restated:

1. **model terms** (:func:`terms_stage` from Pinocchio's arrays, or the Drake fallback
   then :func:`complete_terms`): H, H⁻¹, C q̇, g, C, J, ∂J/∂q, J̇ q̇, ẋ, Λ and the
   generalised inverse J^#, N (:mod:`dynamics`, :mod:`pseudo_inverse`), read in place from
   Pinocchio's arrays, with the joint poses the obstacle criterion needs;
2. **criteria** (``CRITERIA``): [Φ; p; s; a] of the obstacle (Eq. 31, closed forms over the
   link poses of stage 1), joint-torque (Eqs. 32–33), manipulability and joint-limit
   criteria (:mod:`criteria`);
3. **desired null-space velocity** (``SELECTION``, then ``DESIRED``): Fig. 1's priority
   selector on the stored switch state (:mod:`priority`), then q̇_dⁿ, the selector's or the
   prescribed sweep's (:mod:`self_motion`);
4. **task torque** (``TASK``): τ − τ₀ of Eqs. 6–8 (:mod:`impedance`);
5. **null-space torque** (``NULL_SPACE``): τ₀ of Eq. 21 (:mod:`null_space`), q̈_dⁿ the
   backward difference from the stored previous q̇_dⁿ; or, with ``null_space.law`` a
   posture law, that law's τ₀ (:mod:`null_space_laws`);
6. **actuator limits** (``LIMITS``): τ = τ_task + s τ₀ within the torque and rate windows
   (:mod:`actuator_limits`), from the stored previous τ; the torque window about g(q) of
   stage 1 for a robot that adds g itself (the plan's ``limits_about_gravity``).

Stages 2–6 and the two discrete updates are one function, :func:`run_stages`, which runs
the stages it is asked for (a bit set) in this order; each named system asks for its own
stage, the fused system and :class:`nsdrake.ControllerStep` for all of them. One function,
its four stage kernels each compiled once, for every way of running the controller.

**The discrete state** is three arrays, never hidden in a stage: the selector's switch
state [mode, mode blended from, switch time], the previous q̇_dⁿ [q̇_dⁿ (n); 1 if it
exists] and the previous τ [τ (n); 1 if it exists]. (The reference's contact state is
the reference's, outside the controller.)

**Event semantics** (Drake's, which all three ways of running the stages reproduce).
Drake advances a discrete MultibodyPlant in an *unrestricted* update, and at one instant
every unrestricted update runs before every discrete update. So at t_k, with the state
x_k the plant reached at t_k:

- the output τ_k = tick(t_k, x_k) is computed once and drives the plant's step to x_{k+1};
- the controller's own unrestricted update, from the same context, stores the q̇_dⁿ and
  the τ just output (``STORE``), as the values used over the step;
- then, *still at time t_k but from the post-step state x_{k+1}*, the selector's discrete
  update selects a mode from the criteria at x_{k+1} and commits it with switch time t_k
  (``COMMIT``);
- at t_{k+1}, the output again evaluates Fig. 1's tree on x_{k+1} from the committed
  switch state (a tentative switch at t_{k+1}, not stored).

A plain loop that receives x_{k+1} and calls the step once reproduces this exactly
(``PLAIN_STEP``): the criteria at x_{k+1}, the pending discrete update with them at time
t_k, the output stages at t_{k+1}, then the stores. The criteria at x_{k+1} serve both,
so they are computed once (in the fused system, a cache entry that depends on the state
alone). This holds as long as the state the step receives at t_{k+1} is the one Drake's
discrete update at t_k sees: one plant step per control period and no sampled rung
between the plant and the controller. (A plant stepping finer than the controller, the
realism ladder's physics rung, has its discrete update see the state one *plant* step
after t_k; the named systems and the fused system, which keep Drake's events, follow
it exactly.)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from nsdrake.control.actuator_limits import limited_torque
from nsdrake.control.criteria.distance import segments_box, segments_sphere
from nsdrake.control.criteria.joint_limits import joint_limits_criterion
from nsdrake.control.criteria.joint_torque import joint_torque_criterion
from nsdrake.control.criteria.manipulability import manipulability
from nsdrake.control.criteria.posture import posture_criterion
from nsdrake.control.dynamics import _cross, _jacobian_partials, derived_terms, task_inertia
from nsdrake.control.gradient_projection import gradient_step
from nsdrake.control.impedance import _position_task_torque, pose_task_torque, wrench_at_tool
from nsdrake.control.layout import index_views, plan_views, terms_views, tick_views
from nsdrake.control.model import symmetric_and_inverse
from nsdrake.control.null_space import _null_space_law
from nsdrake.control.null_space_laws import (
    DYNAMICALLY_CONSISTENT_POSTURE_PD,
    KINEMATIC_POSTURE_PD,
    PAPER,
    dynamically_consistent_posture_torque,
    dynamically_consistent_torque_pd,
    kinematic_posture_torque,
    posture_target,
)
from nsdrake.control.orientation import quaternion_to_rotation
from nsdrake.control.priority import (
    INITIAL_SWITCH_STATE,
    blend_weight_code,
    select_mode_code,
    selected_velocity,
    switch_state_update,
)
from nsdrake.control.pseudo_inverse import inverse_at_state
from nsdrake.control.self_motion import sweep_amplitude, sweep_velocity
from nsdrake.control.smoothing import activation

OBSTACLES_NONE, OBSTACLES_CLOSED_FORM, OBSTACLES_QUERIED = 0, 1, 2  # PlanView.obstacle_mode

# The stages run_stages can run, in the order it runs them (a bit set).
CRITERIA = 1  # stage 2 into ``criteria``
COMMIT = 2  # the selector's discrete update: the switch committed at t_previous
SELECTION = 4  # stage 3, the selector, into tick.selection
DESIRED = 8  # stage 3, q̇_dⁿ into tick.qdot: the sweep's (source: sweep) or the selector's
SWEEP = 16  # the sweep alone into tick.qdot (the named self-motion system)
TASK = 32  # stage 4 into tick.task
NULL_SPACE = 64  # stage 5 (q̇_dⁿ from tick.qdot) into tick.null_space
LIMITS = 128  # stage 6 (from tick.task and tick.null_space) into tick.limited
COPY = 256  # the criteria and x into the tick (the fused system's packed output)
STORE = 512  # the unrestricted update: tick.qdot and tick.limited's τ as the previous values
TICK = SELECTION | DESIRED | TASK | NULL_SPACE | LIMITS | COPY  # the output, stages 3–6
PLAIN_STEP = CRITERIA | COMMIT | TICK | STORE  # a plain loop's tick after stage 1


# ---------------------------------------------------------------- 1. model terms


def terms_stage(M, nle, g, C, J_pin, X_pin, R_tool, p_tool, q, v, plan, index, dims, terms):
    """Stage 1 from Pinocchio's arrays, read in place after ``computeAllTerms`` (M, nle, g,
    the world joint Jacobians J_pin, the joint poses X_pin (nj, 3, 4)),
    ``computeCoriolisMatrix`` (C, when the plan wants it) and ``updateFramePlacement``
    (the tool's R_tool, p_tool), all in Pinocchio's joint order; q, v in the model's:
    :func:`pinocchio_terms`, then :func:`complete_terms`, which the Drake terms' path calls
    too: two kernels, since one kernel calling both would compile complete_terms' code a
    second time (:func:`run_stages`)."""
    pinocchio_terms(M, nle, g, C, J_pin, X_pin, R_tool, p_tool, q, v, plan, index, dims, terms)
    complete_terms(terms, plan, index, dims)


@njit(cache=True)
def pinocchio_terms(M, nle, g, C, J_pin, X_pin, R_tool, p_tool, q, v, plan, index, dims, terms):
    """Stage 1's first part from Pinocchio's arrays (:func:`terms_stage`): q, v, H, H⁻¹,
    C q̇, g, C (when the plan wants it), the joint Jacobians and poses, the tool's pose and
    its Jacobian J_spatial, in the model's joint order."""
    T, P, ix = terms_views(terms, dims), plan_views(plan, dims), index_views(index, dims)
    n, o = T.q.shape[0], ix.order
    H, H_inv = symmetric_and_inverse(M)
    T.q[:], T.v[:] = q, v
    for i in range(n):
        T.Cv[i], T.g[i] = nle[o[i]] - g[o[i]], g[o[i]]
        for j in range(n):
            T.H[i, j], T.H_inv[i, j] = H[o[i], o[j]], H_inv[o[i], o[j]]
            if P.coriolis:
                T.C[i, j] = C[o[i], o[j]]
        T.J_joints[:, i] = J_pin[:, o[i]]
    T.p_WT[:], T.R_WT[:] = p_tool, R_tool
    T.X_joints[:] = X_pin
    _tool_jacobian(T.J_joints, p_tool, ix.tool_support, T.J_spatial)


@njit(cache=True, inline="always")
def _tool_jacobian(J_joints, p, support, out):
    """[J_w; J_v] of the tool point p from the world joint Jacobians [v_O; ω] (velocity
    of the point at the world origin): J_v = v_O − p × ω on the tool's supporting joints,
    as Pinocchio's LOCAL_WORLD_ALIGNED frame Jacobian. (6, n), Drake's row order."""
    out[:] = 0.0
    for j in range(J_joints.shape[1]):
        if support[j]:
            w0, w1, w2 = J_joints[3, j], J_joints[4, j], J_joints[5, j]
            c0, c1, c2 = _cross(p[0], p[1], p[2], w0, w1, w2)
            out[0, j], out[1, j], out[2, j] = w0, w1, w2
            out[3, j], out[4, j], out[5, j] = J_joints[0, j] - c0, J_joints[1, j] - c1, J_joints[2, j] - c2


@njit(cache=True)
def complete_terms(terms, plan, index, dims):
    """Stage 1, the part common to both model libraries (the Drake fallback calls it after
    writing q, v, H, H⁻¹, C q̇, g, C, J_spatial, p_WT, R_WT): the task rows J, ∂J/∂q, J̇, J̇ q̇,
    ẋ, H⁻¹ Jᵀ, Λ (capped, :func:`task_inertia`), the generalised inverse J^#, N, A⁻¹ and x."""
    _complete_terms(terms_views(terms, dims), plan_views(plan, dims), index_views(index, dims))


@njit(cache=True, inline="always")
def _complete_terms(T, P, ix):
    for r in range(ix.spatial_rows.shape[0]):
        T.J[r] = T.J_spatial[ix.spatial_rows[r]]
    # contiguous views (no copy), typed as Python's callers pass them: one compiled version
    J_w, J_v = np.ascontiguousarray(T.J_spatial[:3]), np.ascontiguousarray(T.J_spatial[3:])
    T.dJ_dq[:] = _jacobian_partials(J_w, J_v, ix.own, ix.other, ix.rows, ix.rot_rows)
    Jdot, Jdot_v, xdot, H_inv_Jt = derived_terms(T.H_inv, T.J, T.dJ_dq, T.v)
    T.Jdot[:], T.Jdot_v[:], T.xdot[:], T.H_inv_Jt[:] = Jdot, Jdot_v, xdot, H_inv_Jt
    T.Lambda[:] = task_inertia(
        T.J @ T.H_inv_Jt, P.inertia_floor, P.rotational_inertia_floor, ix.rows.shape[0]
    )
    J_pinv, N, A_inv = inverse_at_state(P.inertia_weighted, P.damping, T.H_inv_Jt, T.Lambda, T.J)
    T.J_pinv[:], T.N[:], T.A_inv[:] = J_pinv, N, A_inv
    for r in range(ix.rows.shape[0]):
        T.x[r] = T.p_WT[ix.rows[r]]


# ---------------------------------------------------------------- stages 2–6 and the updates


def run_stages(
    stages, t, t_previous, plan, index, dims, terms, criteria, switch, previous_qdot, previous_tau,
    commands, tick,
) -> bool:  # fmt: skip
    """The ``stages`` (a bit set of this module's constants) at time t, in their order:
    CRITERIA, COMMIT (at ``t_previous``), SELECTION, DESIRED or SWEEP, TASK, NULL_SPACE,
    LIMITS, COPY, STORE. ``criteria`` (4, n + 3), the discrete state ``switch`` (3),
    ``previous_qdot`` and ``previous_tau`` (n + 1 each), the packed ``commands``
    (:func:`commands_views`) and ``tick`` (:func:`nsdrake.control.layout.tick_views`) are
    read and written in place. Returns True, having run nothing after CRITERIA, when its
    obstacle row needs Drake's queries: the caller computes that row, then the remaining
    stages (:meth:`nsdrake.control.plan.ControllerPlan.run`).

    What a controller uses (rotational task axes, a prescribed sweep, joint limits,
    obstacles in closed form) is read from the plan and the index at run time, never
    specialised at compile time: one compiled version serves every controller, and the
    arguments' types never change (an int, two floats, float64 and int64 arrays,
    C-contiguous), so that numba compiles its kernels once per install
    (:mod:`nsdrake.control.kernels`).

    The stages are two kernels over the same flat arrays, stages 2–3 (:func:`front_stage`)
    and 4–6 (:func:`torque_stage`), called in turn from here: numba compiles and caches
    each on its own, so that the first run's two processes compile them at once
    (:func:`nsdrake.control.kernels.compile_kernels`). One kernel calling the two would
    compile their code a second time (numba links a callee's code into its caller, then
    optimises and emits it again), for one call's dispatch less per tick. The body stays
    numba's subset: ``njit`` compiles it as it is for a kernel that needs the whole tick
    inside compiled code."""
    front = stages & (CRITERIA | COMMIT | SELECTION | SWEEP | DESIRED)
    if front and front_stage(stages, t, t_previous, plan, index, dims, terms, criteria, switch, tick):
        return True
    if stages & (TASK | NULL_SPACE | LIMITS | COPY | STORE):
        torque_stage(
            stages, t, plan, index, dims, terms, criteria, previous_qdot, previous_tau, commands, tick
        )
    return False


@njit(cache=True)
def front_stage(stages, t, t_previous, plan, index, dims, terms, criteria, switch, tick) -> bool:
    """CRITERIA (stage 2 into ``criteria``; True, and nothing more, when its obstacle row
    needs Drake's queries), COMMIT (the selector's discrete update at ``t_previous``),
    SELECTION (stage 3's selector into tick.selection), then DESIRED or SWEEP: q̇_dⁿ into
    tick.qdot, the posture criterion's, the sweep's or the selector's."""
    T, P, ix = terms_views(terms, dims), plan_views(plan, dims), index_views(index, dims)
    out = tick_views(tick, dims)
    if stages & CRITERIA and _criteria_rows(T, P, ix, criteria):
        return True
    if stages & COMMIT:
        _commit_switch(P, criteria, switch, t_previous)
    if stages & SELECTION:
        _selection(T, P, ix, criteria, switch, t, out.selection)
    if stages & (SWEEP | DESIRED):
        if P.posture_source:
            out.qdot[:] = _posture_velocity(T, P, t)
        elif P.sweep:
            w = P.sweep_wave
            out.qdot[:] = sweep_velocity(T.N, P.direction, sweep_amplitude(t, w[0], w[1], w[2], w[3]))
        else:
            out.qdot[:] = out.selection[: T.q.shape[0]]
    return False


@njit(cache=True)
def torque_stage(stages, t, plan, index, dims, terms, criteria, previous_qdot, previous_tau, commands, tick):
    """TASK (stage 4 into tick.task, a pose or a position task), NULL_SPACE (stage 5, q̇_dⁿ
    from tick.qdot, into tick.null_space: the paper's law or a posture law), LIMITS (stage 6,
    from tick.task and tick.null_space, into tick.limited), COPY (the criteria and x into
    the tick) and STORE (tick.qdot and tick.limited's τ as the previous values)."""
    T, P, ix = terms_views(terms, dims), plan_views(plan, dims), index_views(index, dims)
    out = tick_views(tick, dims)
    n = T.q.shape[0]
    if stages & TASK:
        if ix.rot_rows.shape[0]:
            _pose_task(T, P, ix, commands, out.task)
        else:
            _position_task(T, P, ix, commands, out.task)
    if stages & NULL_SPACE:
        if P.law == PAPER:
            _null_space(T, P, out.qdot, previous_qdot, out.null_space)
        else:
            _posture_law(T, P, t, out.null_space)
    if stages & LIMITS:
        _actuator_limits(T, P, out.task, out.null_space[:n], previous_tau, out.limited)
    if stages & COPY:
        out.criteria[:], out.x[:] = criteria, T.x
    if stages & STORE:
        previous_qdot[:n], previous_qdot[n] = out.qdot, 1.0
        previous_tau[:n], previous_tau[n] = out.limited[:n], 1.0


# ---------------------------------------------------------------- 2. criteria


@njit(cache=True, inline="always")
def _criteria_rows(T, P, ix, criteria) -> bool:
    """Stage 2: the four rows of ``criteria`` in Criterion's order, the obstacle row last.
    Returns True, with that row packed empty, when it needs Drake's queries (the caller
    fills it; the other rows are complete)."""
    n = T.q.shape[0]
    _torque_and_manipulability_rows(T, P, criteria)
    if P.has_limits:
        _joint_limits_row(T, P, criteria[3])
    else:
        pack_criterion(criteria[3], np.zeros(n), 0.0, np.inf, 0.0)
    pack_criterion(criteria[0], np.zeros(n), 0.0, np.inf, 0.0)  # no obstacle geometry: d_min = ∞
    if P.obstacle_mode != OBSTACLES_CLOSED_FORM:
        return P.obstacle_mode == OBSTACLES_QUERIED
    return _obstacle_row(T, P, ix, criteria[0])


@njit(cache=True, inline="always")
def pack_criterion(row, Phi, p, s, a):
    """row = [Φ; p; s; a]: gradient, value, the quantity Fig. 1's tree compares, activation."""
    n = Phi.shape[0]
    row[:n] = Phi
    row[n], row[n + 1], row[n + 2] = p, s, a


@njit(cache=True, inline="always")
def _torque_and_manipulability_rows(T, P, out):
    """Stage 2's joint-torque (Eqs. 32–33) and manipulability rows of ``out`` (4, n + 3), in
    Criterion's order. F_d is the nominal force along n (``config.nominal_force``), a
    constant: a criterion that followed the desired force input would rise with every
    force ramp whatever the posture does (docs/open_choices.md)."""
    p, Phi = joint_torque_criterion(T.J, T.dJ_dq, P.F_d)
    pack_criterion(out[1], Phi, p, p, 1.0)
    w, Phi = manipulability(T.J, T.dJ_dq)
    pack_criterion(out[2], Phi, w, w, 1.0)


@njit(cache=True, inline="always")
def _joint_limits_row(T, P, out):
    """Stage 2's joint-limit row [Φ; p; the smallest margin; its activation]."""
    p, Phi, margin = joint_limits_criterion(T.q, P.lower, P.upper, P.limits_influence)
    pack_criterion(out, Phi, p, margin, activation(margin, P.limits_influence))


@njit(cache=True, inline="always")
def link_segments(X_joints, links, link_joint):
    """(A, B): each link capsule's axis segment, world (k, 3) each, from the pose of its
    joint and the axis centre and direction in that joint's frame."""
    k = links.shape[0]
    A, B = np.empty((k, 3)), np.empty((k, 3))
    for i in range(k):
        X = X_joints[link_joint[i]]
        for r in range(3):
            centre = X[r, 0] * links[i, 0] + X[r, 1] * links[i, 1] + X[r, 2] * links[i, 2] + X[r, 3]
            axis = X[r, 0] * links[i, 3] + X[r, 1] * links[i, 4] + X[r, 2] * links[i, 5]
            A[i, r], B[i, r] = centre - links[i, 6] * axis, centre + links[i, 6] * axis
    return A, B


@njit(cache=True, inline="always")
def obstacle_rows(A, B, obstacles):
    """(o, k, 7): rows [φ, ∇φ, S] of :mod:`nsdrake.control.criteria.distance` per obstacle."""
    out = np.empty((obstacles.shape[0], A.shape[0], 7))
    for j in range(obstacles.shape[0]):
        ob = obstacles[j]
        if ob[0] == 0.0:
            out[j] = segments_box(A, B, ob[1:10].copy().reshape((3, 3)), ob[10:13].copy(), ob[13:16].copy())
        else:
            out[j] = segments_sphere(A, B, ob[10:13].copy(), ob[13])
    return out


@njit(cache=True, inline="always")
def point_gradient(normal, S, J_joints, support):
    """∂d/∂q = n̂ᵀ J_S: the distance's gradient through the translational Jacobian of the
    link point S (world), J_S = v_O + ω × S on the joints that move the link. (n,)."""
    n = J_joints.shape[1]
    out = np.zeros(n)
    for j in range(n):
        if support[j] != 0.0:
            c0, c1, c2 = _cross(J_joints[3, j], J_joints[4, j], J_joints[5, j], S[0], S[1], S[2])
            out[j] = (
                normal[0] * (J_joints[0, j] + c0)
                + normal[1] * (J_joints[1, j] + c1)
                + normal[2] * (J_joints[2, j] + c2)
            )
    return out


@njit(cache=True, inline="always")
def _obstacle_row(T, P, ix, out) -> bool:
    """The obstacle criterion's [Φ; p; d_min; a] (Eq. 31, :mod:`nsdrake.control.criteria.obstacle`)
    from the closed-form distances of every link–obstacle pair, link by link; True (and out
    unchanged) if a pair touches (no unique normal: the caller asks Drake)."""
    n, d_inf = T.q.shape[0], P.obstacle_influence
    A, B = link_segments(T.X_joints, P.links, ix.link_joint)
    rows = obstacle_rows(A, B, P.obstacles)
    p, Phi, d_min = 0.0, np.zeros(n), np.inf
    for i in range(rows.shape[1]):
        for j in range(rows.shape[0]):
            row = rows[j, i]
            if math.isnan(row[0]):
                return True
            d = row[0] - P.links[i, 7]
            d_min = min(d_min, d)
            depth = d_inf - d
            if depth > 0.0:
                p -= depth**3 / 3.0
                Phi += depth * depth * point_gradient(row[1:4], row[4:7], T.J_joints, P.link_support[i])
    pack_criterion(out, Phi, p, d_min, activation(d_min, d_inf))
    return False


# ---------------------------------------------------------------- 3. desired null-space velocity


@njit(cache=True, inline="always")
def _select(P, criteria, switch, t, out):
    """out = the switch state after Fig. 1's tree on the criteria's switching quantities
    (d_min, w, the joint-limit margin), selected at time t (unchanged when no criterion)."""
    if not P.active:
        out[:] = switch
        return
    s = criteria[:, criteria.shape[1] - 2]
    switch_state_update(switch, t, select_mode_code(s[0], s[2], s[3], int(switch[0]), P.selector_limits), out)


@njit(cache=True, inline="always")
def _commit_switch(P, criteria, switch, t):
    """The selector's discrete update at t_k: the switch state committed in place from the
    criteria at the post-step state, with switch time t_k."""
    committed = np.empty(3)
    _select(P, criteria, switch, t, committed)
    switch[:] = committed


@njit(cache=True, inline="always")
def _selection(T, P, ix, criteria, switch, t, out):
    """Stage 3, the selector: out = [q̇_dⁿ (n); mode; speed scale] from the criteria, the
    tentative switch at time t on the stored ``switch`` state, the blend after a switch and
    the joint-speed scaling (:func:`nsdrake.control.priority.selected_velocity`)."""
    n = T.q.shape[0]
    state = np.empty(3)
    _select(P, criteria, switch, t, state)
    mode, previous = int(state[0]), int(state[1])
    out[:n] = 0.0
    out[n], out[n + 1] = state[0], 1.0
    if not P.active or mode == 0:
        return
    if P.inertia_weighted:
        W, W_inv = T.H, T.H_inv
    else:
        W = W_inv = np.eye(n)
    activations = np.where(P.gains != 0.0, criteria[:, n + 2], 0.0)  # a level without gain: none
    qdot, scale = selected_velocity(
        T.N, W, W_inv, np.ascontiguousarray(criteria[:, :n]), P.gains, activations,
        ix.orderings[mode, : ix.counts[mode]], ix.orderings[previous, : ix.counts[previous]],
        blend_weight_code(state[2], t, P.blend_time), P.rotate, T.J_pinv @ T.xdot, P.command_limits,
    )  # fmt: skip
    out[:n], out[n + 1] = qdot, scale


# ---------------------------------------------------------------- 4.–6. torques


@njit(cache=True, inline="always")
def commands_views(commands, m_t):
    """The position part of stage 4's packed inputs [wrench (6); x_d, ẋ_d, ẍ_d (m_t each);
    f_d; with rotational axes R_d (4), ω_d (3), ω̇_d (3)]: (wrench, x_d, ẋ_d, ẍ_d, f_d)."""
    c = commands
    return c[:6], c[6 : 6 + m_t], c[6 + m_t : 6 + 2 * m_t], c[6 + 2 * m_t : 6 + 3 * m_t], c[6 + 3 * m_t]


def commands_size(m_t: int, m_r: int) -> int:
    """Length of the packed commands of :func:`commands_views`."""
    return 7 + 3 * m_t + (10 if m_r else 0)


@njit(cache=True, inline="always")
def _position_task(T, P, ix, commands, out):
    """Stage 4 for a position task: out = τ − τ₀ (Eqs. 6–8) with the measured wrench moved to
    the tool point."""
    wrench, x_d, xdot_d, xddot_d, f_d = commands_views(commands, ix.rows.shape[0])
    W_T = wrench_at_tool(wrench, P.p_WSo, T.p_WT) if P.has_p_WSo else wrench
    out[:] = _position_task_torque(
        T.x, T.xdot, x_d, xdot_d, xddot_d, f_d, W_T, ix.rows, P.K_p, P.K_v, P.K_f, P.normal,
        T.J, T.Lambda, T.Jdot_v, T.J_spatial, T.Cv, T.g, P.gravity,
    )  # fmt: skip


@njit(cache=True, inline="always")
def _pose_task(T, P, ix, commands, out):
    """Stage 4 for a pose task, with R_d (quaternion [w, x, y, z]), ω_d, ω̇_d after the
    position commands."""
    wrench, x_d, xdot_d, xddot_d, f_d = commands_views(commands, ix.rows.shape[0])
    o = 7 + 3 * ix.rows.shape[0]
    R_d, omega_d, omegadot_d = commands[o : o + 4], commands[o + 4 : o + 7], commands[o + 7 : o + 10]
    W_T = wrench_at_tool(wrench, P.p_WSo, T.p_WT) if P.has_p_WSo else wrench
    out[:] = pose_task_torque(
        T.x, T.xdot, T.R_WT, x_d, xdot_d, xddot_d, f_d, quaternion_to_rotation(R_d), omega_d,
        omegadot_d, W_T, ix.rows, ix.rot_rows, P.K_p, P.K_v, P.K_f, P.normal, T.J, T.Lambda,
        T.Jdot_v, T.J_spatial, T.Cv, T.g, P.gravity,
    )  # fmt: skip


@njit(cache=True, inline="always")
def _null_space(T, P, qdot_ns, previous, out):
    """Stage 5: out = [τ₀ (n); eⁿ (n); ν] (Eqs. 21, 14, 23), q̈_dⁿ the backward difference of
    q̇_dⁿ from ``previous`` = [q̇_dⁿ (n); 1 if stored] over one period (0 without it)."""
    n = T.q.shape[0]
    qddot_ns = np.zeros(n)
    if P.feedforward and previous[n] != 0.0:
        qddot_ns = (qdot_ns - previous[:n]) / P.period
    W_inv = T.H_inv if P.inertia_weighted else np.eye(n)
    tau0, e_n, nu = _null_space_law(
        T.H, T.H_inv, T.C, T.J, T.Jdot, T.v, T.xdot, T.Jdot_v, T.J_pinv, T.N, T.A_inv, W_inv,
        qdot_ns, qddot_ns, P.K_n, P.task_velocity_compensation, P.coriolis_compensation,
        P.inertia_weighted,
    )  # fmt: skip
    out[:n], out[n : 2 * n], out[2 * n] = tau0, e_n, nu


@njit(cache=True, inline="always")
def _posture_law(T, P, t, out):
    """Stage 5 with a posture law (:mod:`nsdrake.control.null_space_laws`): out = [τ₀ (n);
    nan (n); nan], eⁿ and ν being the paper's (Eqs. 14, 23), undefined for these laws."""
    n = T.q.shape[0]
    q_d = posture_target(P.q_d, P.posture_offset, t, P.posture_offset_time, P.posture_ramp_time)
    if P.law == KINEMATIC_POSTURE_PD:
        out[:n] = kinematic_posture_torque(
            T.J, T.q, T.v, q_d, P.posture_stiffness, P.posture_damping, P.projector_damping
        )
    elif P.law == DYNAMICALLY_CONSISTENT_POSTURE_PD:
        out[:n] = dynamically_consistent_posture_torque(
            T.H, T.H_inv, T.J, T.q, T.v, q_d, P.posture_stiffness, P.posture_damping
        )
    else:
        out[:n] = dynamically_consistent_torque_pd(
            T.H_inv, T.J, T.q, T.v, q_d, P.posture_stiffness, P.posture_damping
        )
    out[n:] = np.nan


@njit(cache=True, inline="always")
def _posture_velocity(T, P, t):
    """Stage 3 with the posture criterion (source: posture): q̇_dⁿ = K N W⁻¹ Φ (Eq. 30),
    Φ = W_p (q − q_d(t)) (:mod:`nsdrake.control.criteria.posture`), W⁻¹ the inverse's metric
    (H⁻¹ for J̄), used as given (no joint-speed scaling, as the sweep's)."""
    n = T.q.shape[0]
    q_d = posture_target(P.q_d, P.posture_offset, t, P.posture_offset_time, P.posture_ramp_time)
    _, Phi = posture_criterion(T.q, q_d, P.posture_weight)
    W_inv = T.H_inv if P.inertia_weighted else np.eye(n)
    return gradient_step(T.N, W_inv, Phi, P.posture_gain, P.rotate)


@njit(cache=True, inline="always")
def _actuator_limits(T, P, tau_task, tau0, previous, out):
    """Stage 6: out = [τ (n); s; clipped] within the torque window (about g(q) when the
    robot adds g itself, else 0), narrowed by the rate limit around ``previous`` = [τ (n);
    1 if stored]."""
    n = tau_task.shape[0]
    centre = T.g if P.limits_about_gravity else np.zeros(n)
    out[:] = limited_torque(
        tau_task, tau0, P.tau_max, P.rate_max, P.period, previous[:n], previous[n] != 0.0, centre
    )


# ---------------------------------------------------------------- the discrete state


def initial_state(n: int) -> np.ndarray:
    """The discrete state before the first tick, [switch (3); previous q̇_dⁿ (n + 1);
    previous τ (n + 1)]: the selector in mode 0 (the first selection blends in from rest),
    no previous q̇_dⁿ, no previous τ."""
    return np.concatenate([INITIAL_SWITCH_STATE, np.zeros(2 * n + 2)])


def state_parts(state: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(switch (3), previous q̇_dⁿ (n + 1), previous τ (n + 1)): views of :func:`initial_state`'s parts."""
    return state[:3], state[3 : n + 4], state[n + 4 : 2 * n + 5]

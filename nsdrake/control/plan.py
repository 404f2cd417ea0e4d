"""ControllerPlan: a controller's constants, laid out for the compiled stages, and the
two stages that call a model library (model terms, criteria).

Built once from the :class:`ControllerModel`, the task (its direction ``normal``, the
point the measured moment is about) and the :class:`ControllerConfig`; shared by the
named systems, the fused system and :class:`nsdrake.ControllerStep`, which therefore
run the same stages on the same numbers (:mod:`nsdrake.control.stages`).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property

import numpy as np
from pydrake.geometry import Box, Capsule, Sphere

from nsdrake.control.config import ControllerConfig
from nsdrake.control.criteria.obstacle import ObstacleDistances, obstacle_potential
from nsdrake.control.impedance import ImpedanceGains
from nsdrake.control.kernels import compile_kernels
from nsdrake.control.layout import (
    CRITERIA,
    LINK_WIDTH,
    OBSTACLE_WIDTH,
    field,
    field_slices,
    index_size,
    make_dims,
    plan_size,
    terms_size,
    terms_views,
    tick_size,
    tick_views,
)
from nsdrake.control.model import ControllerModel, ModelScratch
from nsdrake.control.null_space_laws import LAWS
from nsdrake.control.priority import Criterion, SelectorLimits, ordering_table
from nsdrake.control.pseudo_inverse import GeneralizedInverse, PseudoInverseKind
from nsdrake.control.smoothing import activation
from nsdrake.control.stages import (
    CRITERIA as CRITERIA_STAGE,
)
from nsdrake.control.stages import (
    OBSTACLES_CLOSED_FORM,
    OBSTACLES_NONE,
    OBSTACLES_QUERIED,
    commands_size,
    complete_terms,
    initial_state,
    pack_criterion,
    run_stages,
    state_parts,
    terms_stage,
)
from nsdrake.control.validation import entry_names


def generalized_inverse(config: ControllerConfig) -> GeneralizedInverse:
    ns = config.null_space
    return GeneralizedInverse(PseudoInverseKind(ns.pseudo_inverse), ns.damping)


def torque_limits(config: ControllerConfig, model: ControllerModel) -> np.ndarray:
    """|τ| limit per joint (velocity order): the configuration's, else the model's
    actuator effort limit, else unlimited. [N m]."""
    plant = model.plant
    effort = {}
    for index in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(index)
        effort[actuator.joint().name()] = actuator.effort_limit()
    return np.array([config.actuator_limits.torque.get(j, effort.get(j, np.inf)) for j in model.joint_names])


def speed_limits(config: ControllerConfig, model: ControllerModel) -> np.ndarray:
    """Joint-speed limit per joint (velocity order) for q̇_dⁿ's scaling: the configuration's,
    else the model's velocity limit (URDF ``<limit velocity>``; zero or none counts as
    unlimited, as URDF writers use 0 for "not given"). [rad/s]."""
    model_limits = model.plant.GetVelocityUpperLimits()
    table = config.desired_null_space.joint_speed_limits
    return np.array(
        [
            table.get(j, limit if limit > 0 else np.inf)
            for j, limit in zip(model.joint_names, model_limits, strict=True)
        ]
    )


def posture_constants(config: ControllerConfig, joints: Sequence[str]) -> list:
    """The plan's null-space law and posture objective (:func:`nsdrake.control.layout.plan_views`):
    [law code, K_ns, D_ns, λ, posture source, K of Eq. 30, offset time, ramp time], then q_d,
    the offset and the weight per joint (velocity order; q_d 0 where none is given, which
    only a controller that does not use it may have)."""
    ns, d = config.null_space, config.desired_null_space
    p = d.posture
    return [
        [LAWS[ns.law], ns.posture_stiffness, ns.posture_damping, ns.projector_damping,
         d.source == "posture", p.gain,
         p.offset_time, p.offset_ramp_time],
        [p.q_d.get(j, 0.0) for j in joints], [p.offset.get(j, 0.0) for j in joints],
        [p.weight.get(j, 1.0) for j in joints],
    ]  # fmt: skip


def selector_limits(config: ControllerConfig) -> SelectorLimits:
    sel = config.desired_null_space.selector
    return SelectorLimits(
        d_lim=sel.d_lim,
        w_lim=sel.w_lim,
        d_band=sel.d_band,
        w_band=sel.w_band,
        q_lim=sel.q_lim,
        q_band=sel.q_band,
    )


def criterion_gains(config: ControllerConfig) -> np.ndarray:
    """K of Eq. 30 per criterion, in Criterion's order. (4,)."""
    c = config.desired_null_space.criteria
    gains = {
        Criterion.obstacle: c.obstacle.gain,
        Criterion.joint_torque: c.joint_torque.gain,
        Criterion.manipulability: c.manipulability.gain,
        Criterion.joint_limits: c.joint_limits.gain,
    }
    return np.array([float(gains[c]) for c in Criterion])


class ControllerPlan:
    """The constants of one controller (module docstring).

    Attributes:
        model: the :class:`ControllerModel`; config: the :class:`ControllerConfig`.
        normal: (m_t,) unit direction in which the tool pushes, on the translational axes;
            zeros when the task has no force axis (``has_force_axis`` False).
        dims, plan, index: the flat arrays of :mod:`nsdrake.control.layout`.
        n, m, m_t, m_r: joints, task axes (translational, rotational).
        limits_about_gravity: the torque window is centred on g(q), for a robot that adds
            g(q) to the command τ − g(q) it is sent (:mod:`nsdrake.control.actuator_limits`).
    """

    def __init__(
        self,
        *,
        model: ControllerModel,
        config: ControllerConfig,
        normal: np.ndarray | None,
        wrench_point: Sequence[float] | None,
        limits_about_gravity: bool = False,
    ):
        compile_kernels()  # every configuration's kernels at once, the first time (issue 36)
        self.model, self.config = model, config
        arm = model.arm
        self.n, self.m, self.m_t, self.m_r = arm.n, arm.m, arm.m_t, arm.m_r
        # No force axis (normal None): n = 0 on the translational axes (ImpedanceGains).
        self.has_force_axis = normal is not None
        self.normal = np.zeros(self.m_t) if normal is None else np.asarray(normal, dtype=float)
        self.inverse = generalized_inverse(config)
        self.limits_about_gravity = bool(limits_about_gravity)
        pin = model.pinocchio
        self._distances = _obstacle_distances(model)
        self.obstacle_mode = _obstacle_mode(model, self._distances)
        links, supports, joints = _link_table(model, self._distances, self.obstacle_mode)
        obstacles = _obstacle_table(model, self._distances, self.obstacle_mode)
        self.dims = make_dims(
            self.n, self.m, self.m_t, self.m_r, pin.num_joint_poses if pin else 0, len(links), len(obstacles)
        )
        self.plan = self._plan_array(wrench_point, links, supports, obstacles)
        self.index = self._index_array(joints)
        self._terms_fields = field_slices(terms_views, self.terms_length, self.dims)
        self._tick_fields = field_slices(tick_views, self.tick_length, self.dims)

    def terms_field(self, terms: np.ndarray, name: str) -> np.ndarray:
        """A view of one field of a terms buffer (:class:`nsdrake.control.layout.TermsView`'s names)."""
        return field(terms, self._terms_fields, name)

    def tick_field(self, tick: np.ndarray, name: str) -> np.ndarray:
        """A view of one field of a tick buffer (:class:`nsdrake.control.layout.TickView`'s names)."""
        return field(tick, self._tick_fields, name)

    @cached_property
    def input_names(self) -> dict[str, list[str]]:
        """The name of every entry of the controller's inputs, by input port
        (``estimated_state``, ``desired_null_space_velocity``) and for the packed
        ``commands``, each entry named after its port (``desired_position[y]``): what a
        run-time error names (:func:`nsdrake.control.validation.inputs_problem`)."""
        joints, axes = list(self.model.joint_names), list(self.model.arm.task_axes[: self.m_t])
        commands = [("measured_wrench", 6), ("desired_position", axes), ("desired_velocity", axes)]
        commands += [("desired_acceleration", axes), ("desired_force", 1)]
        if self.m_r:
            commands += [("desired_orientation", ["w", "x", "y", "z"]), ("desired_angular_velocity", 3)]
            commands += [("desired_angular_acceleration", 3)]
        return {
            "estimated_state": entry_names(
                [("estimated_state", [f"q {j}" for j in joints] + [f"v {j}" for j in joints])]
            ),
            "desired_null_space_velocity": entry_names([("desired_null_space_velocity", joints)]),
            "commands": entry_names(commands),
        }

    @property
    def commands_quaternion(self) -> int:
        """Where R_d starts in the packed commands; -1 without rotational task axes."""
        return 7 + 3 * self.m_t if self.m_r else -1

    @property
    def rate_limits(self) -> np.ndarray:
        """|dτ/dt| limit per joint (velocity order) [N m/s]; inf where none."""
        rates = self.config.actuator_limits.torque_rate
        return np.array([rates.get(j, np.inf) for j in self.model.joint_names])

    @property
    def coriolis(self) -> bool:
        """Whether the terms need the Coriolis matrix C (either compensation of Eq. 21)."""
        ns = self.config.null_space
        return ns.task_velocity_compensation or ns.coriolis_compensation

    def _plan_array(self, wrench_point, links, supports, obstacles) -> np.ndarray:
        """The float constants in :func:`nsdrake.control.layout.plan_views`' order."""
        config, model, m_r = self.config, self.model, self.m_r
        imp, ns, d = config.impedance, config.null_space, config.desired_null_space
        gains = ImpedanceGains.along_surface(
            self.normal, imp.K_p_tangent, imp.K_p_normal, imp.K_v_tangent, imp.K_v_normal, imp.K_f,
            imp.K_p_rotation, imp.K_v_rotation, m_r,
        )  # fmt: skip
        lower, upper = model.plant.GetPositionLowerLimits(), model.plant.GetPositionUpperLimits()
        has_limits = np.isfinite(lower).any() or np.isfinite(upper).any()
        speed = (1.0 - d.speed_headroom) * speed_limits(config, model)
        sw = d.sweep
        parts = [
            gains.K_p, gains.K_v, gains.normal,
            [gains.K_f, wrench_point is not None, imp.gravity_compensation],
            [1.0 / imp.max_task_inertia, self.inverse.inertia_weighted, self.inverse.damping,
             1.0 / imp.max_task_rotational_inertia],
            np.zeros(3) if wrench_point is None else wrench_point,
            config.nominal_force * gains.normal, lower, upper,
            [self.coriolis, d.criteria.joint_limits.influence, has_limits, self.obstacle_mode,
             d.criteria.obstacle.influence_distance],
            links, supports, obstacles,
            criterion_gains(config), selector_limits(config).as_array(),
            [d.selector.blend_time, d.rotate_gradient, criterion_gains(config).any(), d.source == "sweep"],
            speed, [sw.direction.get(j, 0.0) for j in model.joint_names],
            [sw.amplitude, sw.frequency, sw.start_time, sw.ramp_time],
            [ns.K_n, config.period, ns.task_velocity_compensation, ns.coriolis_compensation,
             ns.acceleration_feedforward],
            torque_limits(config, model), self.rate_limits, [self.limits_about_gravity],
            *posture_constants(config, model.joint_names),
        ]  # fmt: skip
        plan = np.concatenate([np.asarray(p, dtype=float).ravel() for p in parts])
        assert plan.shape[0] == plan_size.py_func(self.dims)
        return plan

    def _index_array(self, joints) -> np.ndarray:
        """The integer constants in :func:`nsdrake.control.layout.index_views`' order."""
        arm, pin, n = self.model.arm, self.model.pinocchio, self.n
        partials = arm._partials
        orderings, counts = ordering_table()
        parts = [
            arm.rows, arm.rot_rows, arm.spatial_rows, partials._own, partials._other,
            pin.order if pin else np.arange(n), pin.tool_support() if pin else np.ones(n),
            orderings, counts, joints,
        ]  # fmt: skip
        index = np.concatenate([np.asarray(p, dtype=np.int64).ravel() for p in parts])
        assert index.shape[0] == index_size.py_func(self.dims)
        return index

    # ------------------------------------------------ buffers

    def allocate_terms(self) -> np.ndarray:
        return np.zeros(self.terms_length)

    @property
    def terms_length(self) -> int:
        return int(terms_size.py_func(self.dims))

    def allocate_criteria(self) -> np.ndarray:
        return np.zeros((CRITERIA, self.n + 3))

    def allocate_tick(self) -> np.ndarray:
        return np.zeros(self.tick_length)

    @property
    def tick_length(self) -> int:
        return int(tick_size.py_func(self.dims))

    def create_scratch(self) -> ModelScratch:
        return self.model.create_scratch()

    # ------------------------------------------------ the stages

    def terms(self, scratch: ModelScratch, q: np.ndarray, v: np.ndarray, terms: np.ndarray) -> None:
        """Stage 1 at (q, q̇) into ``terms``: Pinocchio's arrays read in place, or Drake's calls."""
        pin = self.model.pinocchio
        if pin is None:
            self._drake_terms(scratch, q, v, terms)
            return
        s = scratch.pinocchio
        pin.update(s, q, v, self.coriolis)
        terms_stage(
            s.M, s.nle, s.g, s.C, s.J, pin.joint_poses(s), s.R_tool, s.p_tool, q, v,
            self.plan, self.index, self.dims, terms,
        )  # fmt: skip

    def _drake_terms(self, scratch: ModelScratch, q, v, terms) -> None:
        arm = self.model.arm
        H, H_inv, Cv, g, J_spatial, p_WT, R_WT, C = arm.plant_terms(
            self.model.plant_context(scratch), q, v, self.coriolis
        )
        for name, value in (("q", q), ("v", v), ("H", H), ("H_inv", H_inv), ("Cv", Cv), ("g", g)):
            self.terms_field(terms, name)[:] = value
        self.terms_field(terms, "J_spatial")[:], self.terms_field(terms, "p_WT")[:] = J_spatial, p_WT
        if R_WT is not None:
            self.terms_field(terms, "R_WT")[:] = R_WT
        if C is not None:
            self.terms_field(terms, "C")[:] = C
        complete_terms(terms, self.plan, self.index, self.dims)

    def run(self, stages: int, t: float, t_previous: float, terms, buffers: StageBuffers) -> None:
        """:func:`nsdrake.control.stages.run_stages` on ``buffers``' arrays; the obstacle row
        from Drake's queries where the closed forms cannot answer (a link touching an
        obstacle, other shapes, Drake terms)."""
        b = buffers
        self.run_arrays(
            stages, t, t_previous, terms, b.criteria, b.switch, b.previous_qdot, b.previous_tau,
            b.commands, b.tick, b.scratch,
        )  # fmt: skip

    def run_arrays(
        self,
        stages,
        t,
        t_previous,
        terms,
        criteria,
        switch,
        previous_qdot,
        previous_tau,
        commands,
        tick,
        scratch,
    ) -> None:
        """:meth:`run` with each array given (views of a system's ports and state). The times
        and the stages go as a float and an int whatever the caller's numbers, so that
        :func:`run_stages`' kernels keep their one compiled signature."""
        if run_stages(
            int(stages), float(t), float(t_previous), self.plan, self.index, self.dims, terms, criteria,
            switch, previous_qdot, previous_tau, commands, tick,
        ):  # fmt: skip
            self._queried_obstacle_row(scratch, self.terms_field(terms, "q"), criteria[0])
            rest = stages & ~CRITERIA_STAGE
            if rest:
                self.run_arrays(
                    rest,
                    t,
                    t_previous,
                    terms,
                    criteria,
                    switch,
                    previous_qdot,
                    previous_tau,
                    commands,
                    tick,
                    scratch,
                )

    def front(
        self, scratch: ModelScratch, q: np.ndarray, v: np.ndarray, terms, buffers: StageBuffers
    ) -> None:
        """Stages 1 and 2 at (q, q̇) into ``terms`` and ``buffers.criteria``."""
        self.terms(scratch, q, v, terms)
        self.run(CRITERIA_STAGE, 0.0, 0.0, terms, buffers)

    def criteria(self, scratch: ModelScratch, terms: np.ndarray, out: np.ndarray) -> None:
        """Stage 2 at the state of ``terms`` into ``out`` (4, n + 3)."""
        self.run(CRITERIA_STAGE, 0.0, 0.0, terms, StageBuffers(self, criteria=out, scratch=scratch))

    def _queried_obstacle_row(self, scratch: ModelScratch, q: np.ndarray, row: np.ndarray) -> None:
        if scratch is None:
            raise ValueError("the obstacle criterion needs Drake's queries here: pass a model scratch")
        model, influence = self.model, self.config.desired_null_space.criteria.obstacle.influence_distance
        plant_context = model.plant_context(scratch)
        model.plant.SetPositions(plant_context, q)
        pairs = self._distances.pairs(plant_context, influence, query=lambda: model.query_object(scratch))
        p, Phi = obstacle_potential(pairs, influence, self.n)
        d_min = float(min((pair.distance for pair in pairs), default=np.inf))
        # floats, whatever the configuration's numbers: the kernels' one list of types
        pack_criterion(row, Phi, float(p), d_min, activation(d_min, float(influence)))


def _obstacle_distances(model: ControllerModel) -> ObstacleDistances | None:
    if not model.has_geometry:
        return None
    inspector = model.scene_graph.model_inspector()
    return ObstacleDistances(model.plant, model.link_geometries, model.obstacle_geometries, inspector)


def _obstacle_mode(model: ControllerModel, distances: ObstacleDistances | None) -> int:
    """How the obstacle criterion is computed: none (no geometry), in closed form over
    Pinocchio's link poses (capsule and sphere links, box and sphere obstacles), or by
    Drake's queries (other shapes, or Drake terms)."""
    if distances is None:
        return OBSTACLES_NONE
    inspector = model.scene_graph.model_inspector()
    links = all(isinstance(inspector.GetShape(g), Capsule | Sphere) for g in model.link_geometries)
    obstacles = all(isinstance(inspector.GetShape(g), Box | Sphere) for g in model.obstacle_geometries)
    closed = model.pinocchio is not None and links and obstacles
    return OBSTACLES_CLOSED_FORM if closed else OBSTACLES_QUERIED


def _link_table(model, distances, mode) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per link geometry (closed forms only): [axis centre (3), axis direction (3) in its
    joint's frame, half length, radius], the joints that move it (n,) and its joint."""
    if mode != OBSTACLES_CLOSED_FORM:
        return np.zeros((0, LINK_WIDTH)), np.zeros((0, model.n)), np.zeros(0, dtype=np.int64)
    rows, supports, joints = [], [], []
    for k, (_, _, body, _, axis) in enumerate(distances._links):
        joint, X_JB, support = model.pinocchio.body_in_joint(body.name())
        R_JB, p_JB = X_JB[:, :3], X_JB[:, 3]
        centre, direction = R_JB @ distances._p_BG[k] + p_JB, R_JB @ distances._z_BG[k]
        rows.append([*centre, *direction, axis[1], axis[0]])
        supports.append(support)
        joints.append(joint)
    return np.array(rows), np.array(supports, dtype=float), np.array(joints, dtype=np.int64)


def _obstacle_table(model, distances, mode) -> np.ndarray:
    """Per obstacle (closed forms only): [kind (0 box, 1 sphere), R_WO (9), p_WO (3), half
    sizes (3) or (radius, 0, 0)], world."""
    if mode != OBSTACLES_CLOSED_FORM:
        return np.zeros((0, OBSTACLE_WIDTH))
    plant = model.plant
    context = plant.CreateDefaultContext()
    rows = []
    for shape, (body, X_BG) in zip(distances._shapes, distances._poses, strict=True):
        X_WG = plant.EvalBodyPoseInWorld(context, body) @ X_BG
        R, p = X_WG.rotation().matrix(), X_WG.translation()
        if isinstance(shape, Box):
            rows.append(
                [0.0, *R.ravel(), *p, *(0.5 * np.array([shape.width(), shape.depth(), shape.height()]))]
            )
        else:
            rows.append([1.0, *R.ravel(), *p, shape.radius(), 0.0, 0.0])
    return np.array(rows)


class StageBuffers:
    """The arrays :meth:`ControllerPlan.run` passes to the stages: ``criteria`` (4, n + 3),
    the discrete ``state`` [switch (3); previous q̇_dⁿ (n + 1); previous τ (n + 1)] with views
    ``switch``, ``previous_qdot``, ``previous_tau``, the packed ``commands``, the ``tick``
    and a model ``scratch`` (for the obstacle criterion's Drake queries). Each may be given
    (a view of someone's memory, e.g. a system's output or discrete state); the rest are
    allocated here. A copy (Drake copies a context's values) copies the numbers and makes a
    fresh scratch."""

    def __init__(self, plan: ControllerPlan, **given):
        n = plan.n
        self.plan = plan
        self.criteria = given.get("criteria", plan.allocate_criteria())
        state = initial_state(n)
        self.switch, self.previous_qdot, self.previous_tau = state_parts(state, n)
        for name in ("switch", "previous_qdot", "previous_tau", "commands", "tick", "scratch"):
            if name in given:
                setattr(self, name, given[name])
        if "commands" not in given:
            self.commands = np.zeros(commands_size(plan.m_t, plan.m_r))
            if plan.m_r:
                self.commands[7 + 3 * plan.m_t] = 1.0  # R_d = I until given
        if "tick" not in given:
            self.tick = plan.allocate_tick()
        if "scratch" not in given:
            self.scratch = plan.create_scratch() if plan.obstacle_mode != OBSTACLES_NONE else None

    def part(self, name: str) -> np.ndarray:
        """A view of one part of the tick (:class:`nsdrake.control.layout.TickView`'s names)."""
        return self.plan.tick_field(self.tick, name)

    def __deepcopy__(self, memo):
        out = StageBuffers(self.plan)
        for name in ("criteria", "switch", "previous_qdot", "previous_tau", "commands", "tick"):
            getattr(out, name)[:] = getattr(self, name)
        return out

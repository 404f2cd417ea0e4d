"""Settings that cannot work, refused before anything is simulated, each with its reason.

- (the model files themselves are checked by :mod:`nsdrake.station.model_checks`
  when the station is built)
- :func:`check_with_model`: what needs the arm: the task axes the arm cannot span
  at its initial pose (rank of J), the discrete stability of the sampled loops
  for the chosen period, and a period too long for the contact.

Discrete stability (exact model, so each task direction is a unit mass, ẍ = ẍ_c):
the plant steps with semi-implicit Euler at the control period T and the torque is
held over the step, so along one direction with stiffness K and damping D

    v' = v + T (−D v − K x),   x' = x + T v'

whose matrix must have spectral radius < 1
(:func:`nsdrake.control.validation.sampled_loop_radius`, the controller's own rule). This is
checked along the plate (K_p,t, K_v,t), normal to it in free motion (K_p,n,
K_v,n) and, for a pose task, on the rotational rows (K_p,r, K_v,r: ω̇ = ω̇_c there
too). The null-space loop ėⁿ = −K_n eⁿ sampled at T needs K_n T < 2.

In contact, the force loop adds the stiffness K_f k_c (k_c: the tool's and the
plate's point stiffnesses in series). Drake's discrete contact is implicit, so
the explicit model above is too pessimistic there; measured on fig3, the force
loop is well behaved up to ω T = 2.2 (T = 10 ms) and breaks by ω T = 2.7 (12 ms),
ω = √(K_p,n + K_f k_c). Periods with ω T > CONTACT_OMEGA_T are refused.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from nsdrake.control.validation import stability_problems
from nsdrake.experiment.scenario import Scenario, ScenarioError, controller_fields
from nsdrake.station.friction import explicit_friction_margin, friction_slope, largest_inverse_inertia

CONTACT_OMEGA_T = 2.5  # [-] largest ω T of the force loop in contact (module docstring)
LARGEST_TRACES = 4 * 2**30  # [bytes] traces kept in memory and written as CSV


def _fail(where: str, problem: str):
    raise ScenarioError(f"{where}: {problem}")


def check_storage(scenario: Scenario, columns: int) -> None:
    """The traces of the whole run fit in memory (and on disk)."""
    rows = scenario.duration / scenario.control_period
    size = rows * columns * 8 * 2  # the run and its comparison
    if size > LARGEST_TRACES:
        _fail(
            f"{scenario.source or 'scenario'}: duration",
            f"{scenario.duration:g} s at {scenario.control_period:g} s per period is {rows:.3g} rows of "
            f"traces ({size / 2**30:.3g} GiB), more than the {LARGEST_TRACES / 2**30:g} GiB nsdrake keeps",
        )


def check_with_model(scenario: Scenario, station) -> None:
    """Rank, stability and contact-period checks that need the station (module docstring)."""
    src = scenario.source or "scenario"
    T = scenario.control_period
    # joint columns, task columns, scalars, and an arm with limits' margins and distances
    check_storage(scenario, columns=11 * station.arm_model.n + 4 * station.arm_model.m + 24)
    _check_rank(scenario, station, src)
    # The sampled loops: the controller's own rule (its Python API refuses the same gains).
    config = SimpleNamespace(**controller_fields(scenario))
    for where, problem in stability_problems(config, rotational=station.arm_model.m_r > 0):
        _fail(f"{src}: {where}", problem)
    _check_friction_step(scenario, station, src)
    imp = scenario.impedance
    omega = math.sqrt(imp.K_p_normal + imp.K_f * contact_stiffness(station))
    if omega * T > CONTACT_OMEGA_T:
        _fail(
            f"{src}: control_period",
            f"{T:g} s is too long for the force loop in contact (ω = √(K_p,n + K_f k_c) = {omega:.3g} rad/s, "
            f"ω T = {omega * T:.3g} > {CONTACT_OMEGA_T:g}); the longest is {CONTACT_OMEGA_T / omega:.3g} s",
        )


def contact_stiffness(station) -> float:
    """k_c: the tool's and the plate's point-contact stiffnesses in series [N/m]."""
    inspector = station.scene_graph.model_inspector()
    plant = station.plant

    def stiffness(body_indices) -> float:
        values = []
        for b in body_indices:
            for g in plant.GetCollisionGeometriesForBody(plant.get_body(b)):
                props = inspector.GetProximityProperties(g)
                if props is not None and props.HasProperty("material", "point_contact_stiffness"):
                    values.append(props.GetProperty("material", "point_contact_stiffness"))
        return max(values) if values else math.inf

    k_tool = stiffness([station.tool_body.index()])
    k_plate = stiffness(plant.GetBodyIndices(station.plate))
    return 1.0 / (1.0 / k_tool + 1.0 / k_plate)


def _check_rank(scenario: Scenario, station, src: str) -> None:
    arm = station.arm_model
    T = arm.terms(arm.plant.CreateDefaultContext(), station.q0, np.zeros(arm.n), False)
    singular_values = np.linalg.svd(T.J, compute_uv=False)
    rank = int(np.sum(singular_values > 1e-6 * max(singular_values[0], 1e-12)))
    if rank < arm.m:
        _fail(
            f"{src}: task.axes",
            f"{list(arm.task_axes)}: at the initial pose the arm's Jacobian has rank {rank} < {arm.m}, "
            "it cannot move its tool along every task axis",
        )


def _check_friction_step(scenario: Scenario, station, src: str) -> None:
    """The friction rung's explicit friction must be resolved by the plant's step."""
    f = scenario.realism.friction
    if not f.enabled:
        return
    plant = station.plant
    if station.elastic is not None:
        dofs = station.elastic.motor_v
    else:
        dofs = [j.velocity_start() for j in station.arm_model.joints]
    slope = friction_slope(f.coulomb, f.viscous, f.smoothing_speed)
    margin = explicit_friction_margin(slope, plant.time_step(), largest_inverse_inertia(plant, dofs))
    if margin >= 1.0:
        _fail(
            f"{src}: realism.friction",
            f"slope τ_c/v_s + b = {slope:.3g} N m s/rad × plant step {plant.time_step():g} s × max λ(H⁻¹) "
            f"= {margin:.3g} ≥ 1: the plant would chatter at zero speed; raise friction.min_substeps "
            "or friction.smoothing_speed",
        )

"""The controller as a run sets it up, for the top of its report: the box (period, the
task's gains per axis, the force loop, the null-space law and its gains) and the loops'
figures (the task's loops and the null-space loop: damping ratio ζ, slowest pole, gain
margin without and with one period of computation delay).

The loops are the sampled loops of :mod:`nsdrake.studies.null_space_laws` (the torque
held over the period, the acceleration it produces scaled by the margin's g): each task
direction under the impedance law with an exact model is a unit mass, ẍ = −K_p x − K_v ẋ
(Eq. 10); normal to the plate in contact the surface adds its stiffness through the force
term, ẍ = −(K_p,n + K_f k_c) x − K_v,n ẋ (k_c the tool's and the plate's point-contact
stiffnesses in series); the null-space loop is the law's (:func:`loop_figures`: the
posture laws' and the paper's with a posture objective, at the start posture) or, where
q̇_dⁿ does not depend on the posture (criteria, sweep), the paper's velocity loop
ėⁿ = −K_n eⁿ (Eq. 21), first order: no ζ.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nsdrake.reporting.sampled_loops import (
    TASK_AXIS,
    VELOCITY_LOOP,
    law_key,
    loop_figures,
    null_space_loop,
)
from nsdrake.reporting.units import number, quantity

LAW_WORDS = {
    "paper": "the paper's null-space velocity law (Eq. 21)",
    "kinematic_posture_pd": "kinematic posture PD, τ₀ = (I − Jᵀ(Jᵀ)⁺)(K_ns (q_d − q) − D_ns q̇)",
    "dynamically_consistent_posture_pd": "dynamically consistent posture PD, "
    "τ₀ = (I − Jᵀ J̄ᵀ) H (K_ns (q_d − q) − D_ns q̇)",
    "dynamically_consistent_torque_pd": "dynamically consistent torque PD, "
    "τ₀ = (I − Jᵀ J̄ᵀ)(K_ns (q_d − q) − D_ns q̇)",
}
INVERSE_WORDS = {
    "dynamically_consistent": "the dynamically consistent J̄ = H⁻¹Jᵀ(J H⁻¹ Jᵀ)⁻¹ (Eq. 13)",
    "moore_penrose": "the Moore–Penrose J⁺",
    "damped_least_squares": "the damped least-squares inverse",
}


@dataclass(frozen=True)
class Loop:
    """One loop's figures: ``zeta`` (text: one value or a range; "" for a first-order
    loop), ``slowest_pole`` [rad/s], ``margin`` and ``margin_delay`` (the factor on the
    loop's gain at which it turns unstable, without and with a period's delay)."""

    name: str
    gains: str  # the gains, with units
    zeta: str
    slowest_pole: float
    margin: float
    margin_delay: float


def _span(low: float, high: float) -> str:
    if not math.isfinite(low):
        return ""
    low_text, high_text = f"{low:.3g}", f"{high:.3g}"
    return low_text if low_text == high_text else f"{low_text}–{high_text}"


def _task_loop(name: str, gains: str, K: float, D: float, T: float) -> Loop:
    loop = null_space_loop(TASK_AXIS, {"posture_stiffness": K, "posture_damping": D}, np.ones(1), T)
    return Loop(
        name,
        gains,
        _span(loop["zeta_min"], loop["zeta_max"]),
        loop["slowest_pole"],
        loop["gain_margin"],
        loop["gain_margin_delay"],
    )


def task_loops(scenario, station) -> list[Loop]:
    """The task's loops: along the plate, normal to it before contact and in contact (the
    force loop), and the rotation's for a pose task (module docstring)."""
    from nsdrake.experiment.checks import contact_stiffness

    imp, T = scenario.impedance, scenario.control_period
    loops = [
        _task_loop(
            "task, along the plate",
            f"K_p {number(imp.K_p_tangent)} 1/s², K_v {number(imp.K_v_tangent)} 1/s",
            imp.K_p_tangent,
            imp.K_v_tangent,
            T,
        )
    ]
    if np.linalg.norm(station.normal) > 0:
        k_c = contact_stiffness(station)
        loops.append(
            _task_loop(
                "task, normal to the plate, before contact",
                f"K_p {number(imp.K_p_normal)} 1/s², K_v {number(imp.K_v_normal)} 1/s",
                imp.K_p_normal,
                imp.K_v_normal,
                T,
            )
        )
        if math.isfinite(k_c):
            stiffness = imp.K_p_normal + imp.K_f * k_c
            loops.append(
                _task_loop(
                    "task, normal to the plate, in contact (the force loop)",
                    f"K_p + K_f k_c = {number(stiffness)} 1/s² (k_c {number(k_c)} N/m), "
                    f"K_v {number(imp.K_v_normal)} 1/s",
                    stiffness,
                    imp.K_v_normal,
                    T,
                )
            )
    if station.arm_model.m_r > 0:
        loops.append(
            _task_loop(
                "task, rotation",
                f"K_p {number(imp.K_p_rotation)} 1/s², K_v {number(imp.K_v_rotation)} 1/s",
                imp.K_p_rotation,
                imp.K_v_rotation,
                T,
            )
        )
    return loops


def null_space_loop_of(scenario, station) -> Loop:
    """The null-space loop of the run's law at its start posture (module docstring)."""
    ns, source = scenario.null_space, scenario.desired_null_space.source
    T = scenario.control_period
    if ns.law == "paper" and source != "posture":
        loop = null_space_loop(VELOCITY_LOOP, {"K_n": ns.K_n}, np.ones(1), T)
        return Loop(
            "null space: the velocity loop ėⁿ = −K_n eⁿ",
            f"K_n {number(ns.K_n)} 1/s",
            "",
            loop["slowest_pole"],
            loop["gain_margin"],
            loop["gain_margin_delay"],
        )
    row = loop_figures(scenario, station.arm_model)
    key = law_key(ns, scenario.desired_null_space.posture)
    if key.startswith("paper"):
        gains = f"K {number(scenario.desired_null_space.posture.gain)}, K_n {number(ns.K_n)} 1/s"
    else:
        unit = ("1/s²", "1/s") if key == "dynamically_consistent_posture_pd" else ("N m/rad", "N m s/rad")
        gains = f"K_ns {number(ns.posture_stiffness)} {unit[0]}, D_ns {number(ns.posture_damping)} {unit[1]}"
    return Loop(
        "null space: the posture's return, at the start posture",
        gains,
        row["damping_ratio"],
        row["slowest_pole"],
        row["gain_margin"],
        row["gain_margin_delay"],
    )


def controller_box(scenario, station) -> list[tuple[str, str]]:
    """The controller as set up, as (what, value) rows: the period, the task's K and D
    per axis, the force gains and f_d, the null-space law, its projector and its gains."""
    imp, T = scenario.impedance, scenario.control_period
    arm = station.arm_model
    normal = np.asarray(station.normal, dtype=float)
    n = normal / np.linalg.norm(normal) if np.linalg.norm(normal) > 0 else normal
    rows = [("control period T", _seconds(T))]
    delay = scenario.realism.delay
    rows.append(
        (
            "computation delay",
            f"{delay.periods} period(s) (realism.delay)"
            if delay.enabled
            else "none (the torque computed from the sample at t_k is applied from t_k)",
        )
    )
    for i, axis in enumerate(arm.task_axes[: arm.m_t]):
        share = float(n[i] ** 2) if n.size else 0.0  # K_p = k_t (I − n nᵀ) + k_n n nᵀ
        K = imp.K_p_tangent + (imp.K_p_normal - imp.K_p_tangent) * share
        D = imp.K_v_tangent + (imp.K_v_normal - imp.K_v_tangent) * share
        where = "normal to the plate" if share > 0.999 else "along the plate" if share < 1e-9 else "mixed"
        rows.append((f"task axis {axis} ({where})", f"K_p {number(K)} 1/s², K_v {number(D)} 1/s"))
    for axis in arm.task_axes[arm.m_t :]:
        rows.append(
            (
                f"task axis {axis} (rotation)",
                f"K_p {number(imp.K_p_rotation)} 1/s², K_v {number(imp.K_v_rotation)} 1/s",
            )
        )
    if n.size and np.linalg.norm(n) > 0:
        rows.append(("force gain K_f", f"{number(imp.K_f)} m/(s² N)"))
        rows.append(
            (
                "desired force f_d",
                f"{number(scenario.reference.force)} N (from contact, "
                f"over {_seconds(scenario.reference.force_ramp_time)})",
            )
        )
    return rows + _null_space_rows(scenario)


def _null_space_rows(scenario) -> list[tuple[str, str]]:
    """:func:`controller_box`'s rows of the null-space law: the law, its projector, its gains."""
    ns, rows = scenario.null_space, []
    if ns.law == "paper":
        source = scenario.desired_null_space.source
        law = f"{LAW_WORDS['paper']}, q̇_dⁿ from the {source}"
        projector = f"I − J̄ J with {INVERSE_WORDS.get(ns.pseudo_inverse, ns.pseudo_inverse)}"
        if ns.pseudo_inverse == "damped_least_squares":
            projector += f", λ {number(ns.damping)} m"
    else:
        law = LAW_WORDS.get(ns.law, ns.law)
        if ns.law == "kinematic_posture_pd":
            projector = "I − Jᵀ(Jᵀ)⁺" + (
                f"_λ, λ {number(ns.projector_damping)}" if ns.projector_damping > 0 else ""
            )
        else:
            projector = "I − Jᵀ J̄ᵀ (dynamically consistent)"
    rows.append(("null-space law", law))
    rows.append(("null-space projector", projector))
    rows.append(
        (
            "null-space velocity gain K_n",
            f"{number(ns.K_n)} 1/s" if ns.law == "paper" else "n/a (a torque law)",
        )
    )
    posture = scenario.desired_null_space.posture
    if ns.law == "paper" and scenario.desired_null_space.source == "posture":
        rows.append(("posture gain K (Eq. 30)", f"{number(posture.gain)}"))
    elif ns.law != "paper":
        unit = ("1/s²", "1/s") if ns.law == "dynamically_consistent_posture_pd" else ("N m/rad", "N m s/rad")
        rows.append(
            (
                "posture gains",
                f"K_ns {number(ns.posture_stiffness)} {unit[0]}, D_ns {number(ns.posture_damping)} {unit[1]}",
            )
        )
    return rows


def _seconds(value: float) -> str:
    return quantity(value, "s")


def loops_json(loops: list[Loop]) -> list[dict]:
    """The loops for metrics.json (a margin beyond the search's end is its end)."""
    return [
        {
            "name": lp.name,
            "gains": lp.gains,
            "damping_ratio": lp.zeta,
            "slowest_pole": lp.slowest_pole,
            "gain_margin": lp.margin,
            "gain_margin_delay": lp.margin_delay,
        }
        for lp in loops
    ]

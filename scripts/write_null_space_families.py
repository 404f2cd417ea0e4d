"""Writes the families null_space_laws and null_space_bandwidth from the tuning rule.

    python scripts/write_null_space_families.py

Every law's gains come from :func:`nsdrake.studies.null_space_laws.tuned_gains` at the
start posture's null-space inertia h_n (4 significant digits in the file;
tests/studies/test_null_space_laws_family.py checks them against the rule). Run it after
changing the rule, the tasks or the bandwidths below, then regenerate the tables
(scripts/regenerate_results.py).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nsdrake.experiment.diagram import build_diagram
from nsdrake.experiment.scenario import load_scenario
from nsdrake.studies.null_space_laws import (
    FRANKA_ROS_GAINS,
    LAW_KEYS,
    ROBOSUITE_GAINS,
    null_space_inertia,
    null_space_loop,
    null_space_masses,
    paper_poles_gains,
    self_motion_posture,
    tuned_gains,
)

FAMILIES = Path(__file__).resolve().parents[1] / "nsdrake" / "studies" / "families"
NAMES = {
    "paper": "paper",
    "paper_moore_penrose": "paper, Moore-Penrose",
    "kinematic_posture_pd": "kinematic PD",
    "kinematic_posture_pd_damped": "kinematic PD, damped inverse",
    "dynamically_consistent_posture_pd": "dyn. consistent PD (H)",
    "dynamically_consistent_torque_pd": "dyn. consistent PD (torque)",
}
# [rad/s] the rule's ω: the scenarios' K_n / 2 (40 and 100); on fig3 the slowest pole of the
# laws whose poles see the null-space inertia is below it (the family's description)
PANDA_OMEGA, FIG3_OMEGA = 20.0, 50.0
BANDWIDTHS = (5.0, 10.0, 20.0, 40.0, 80.0)  # [rad/s] null_space_bandwidth's sweep
# [rad] q_d's offset off the self-motion: joint 4 toward straight (from -2.4), the elbow opens
OFF_PATH = {"panda_joint4": 0.3}
PUSH = {"body": "panda_link4", "force": [0.0, 20.0, 0.0], "start_time": 3.5, "duration": 0.05}


def _g(x: float) -> float:
    return float(f"{x:.4g}")


def _flow(value) -> str:
    """A YAML flow rendering of ``value`` (mappings, lists, numbers, strings)."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_flow(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list):
        return "[" + ", ".join(_flow(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return ".inf" if value == float("inf") else repr(value)
    return str(value)


def law_overrides(law: str, gains: dict, posture: dict, criteria_off: dict) -> dict:
    """The overrides that make ``law`` (a :data:`LAW_KEYS` entry) with ``gains`` (as the
    file writes them, by configuration field) the variant's null-space law."""
    gains = dict(gains)
    ns: dict = {"K_n": gains.pop("K_n")} if "K_n" in gains else {}
    if law.startswith("paper"):
        posture = {**posture, "gain": gains.pop("gain")}
        source = "posture"
        if law == "paper_moore_penrose":
            ns["pseudo_inverse"] = "moore_penrose"
    else:
        source = "criteria"
        ns["law"] = law.removesuffix("_damped")
        ns |= gains
    dns = {**criteria_off, "source": source, "posture": posture}
    return {"desired_null_space": dns, "null_space": ns, "report": {"null_space_torque": True}}


def rule_gains(law: str, omega: float, h_n: float) -> dict:
    """The rule's gains for ``law`` at bandwidth ω, to the 4 digits the file writes."""
    return {k: _g(v) for k, v in tuned_gains(law, omega, h_n).items()}


# Rows beside the rule's, on the tasks named (referee, issue 38): the torque PD at the paper's
# poles (equal poles, not only an equal slowest pole), and two laws at their library's gains;
# by name: (law, gains at bandwidth ω and null-space inertia h_n)
EXTRA_TASKS = ("panda_wipe", "panda_self_motion")
EXTRAS = {
    "dyn. consistent PD (torque), the paper's poles": (
        "dynamically_consistent_torque_pd",
        paper_poles_gains,
    ),
    "kinematic PD, damped inverse, franka_ros's initial gains": (
        "kinematic_posture_pd_damped",
        lambda omega, h_n: FRANKA_ROS_GAINS,
    ),
    "dyn. consistent PD (H), robosuite's gains": (
        "dynamically_consistent_posture_pd",
        lambda omega, h_n: ROBOSUITE_GAINS,
    ),
}


def extra_gains(name: str, omega: float, h_n: float) -> tuple[str, dict]:
    """An :data:`EXTRAS` row's law and gains, to 10 digits, not the rule rows' 4 (2√10
    rounded to 6.325 split robosuite's double pole)."""
    law, gains = EXTRAS[name]
    return law, {k: float(f"{v:.10g}") for k, v in gains(omega, h_n).items()}


def _variant(name: str, scenario: str, overrides: dict) -> str:
    return f"  - name: {name}\n    scenario: {scenario}\n    overrides: {_flow(overrides)}\n"


def main() -> None:
    panda = load_scenario("panda_self_motion")
    arm = build_diagram(panda).station.arm_model
    q0 = np.array([panda.arm.initial_positions[j] for j in arm.joint_names])
    h_panda = null_space_inertia(arm, q0)
    q_d = {j: _g(v) for j, v in zip(arm.joint_names, q0, strict=True)}
    along = self_motion_posture(arm, q0, 0.5)
    on_path = {j: round(float(d), 4) for j, d in zip(arm.joint_names, along - q0, strict=True)}
    fig3 = load_scenario("fig3")
    arm3 = build_diagram(fig3).station.arm_model
    q3 = np.array([fig3.arm.initial_positions[j] for j in arm3.joint_names])
    h_fig3 = null_space_inertia(arm3, q3)
    q_d3 = {j: _g(v) for j, v in zip(arm3.joint_names, q3, strict=True)}

    wipe_off = {"criteria": {"obstacle": {"gain": 0.0}, "joint_limits": {"gain": 0.0}}}
    fig3_off = {
        "criteria": {
            "obstacle": {"gain": 0.0},
            "joint_torque": {"gain": 0.0},
            "manipulability": {"gain": 0.0},
        }
    }
    moved = {"offset_time": 2.3, "offset_ramp_time": 1.0}
    on, off = {"q_d": q_d, "offset": on_path, **moved}, {"q_d": q_d, "offset": OFF_PATH, **moved}
    push = {"duration": 6.0, "push": PUSH}
    panda = (PANDA_OMEGA, h_panda)
    tasks = [  # (task name, base scenario, extra overrides, posture, criteria switched off, ω, h_n)
        ("panda_wipe", "panda_wipe", {"obstacles": []}, {"q_d": q_d}, wipe_off, *panda),
        ("panda_self_motion", "panda_self_motion", {}, on, {}, *panda),
        ("panda_off_path", "panda_self_motion", {}, off, {}, *panda),
        ("fig3", "fig3", {}, {"q_d": q_d3}, fig3_off, FIG3_OMEGA, h_fig3),
        # with the Panda's 1000 N m/s torque-rate limit, which the push does not make bind
        # (push_tau0_limited_time): a twin without it gave the same rows to the last digit
        ("push", "panda_self_motion", push, {"q_d": q_d}, {}, *panda),
    ]
    # fig3's slowest poles under the rule: ω where the law's poles do not see the inertia
    # (J⁺, the H-weighted PD), less in the heavier direction where they do
    masses3 = null_space_masses(arm3, q3)
    fig3_poles = {
        law: null_space_loop(law, tuned_gains(law, FIG3_OMEGA, h_fig3), masses3, fig3.control_period)[
            "slowest_pole"
        ]
        for law in LAW_KEYS
    }
    slow3 = min(fig3_poles.values())
    text = [
        "# Written by scripts/write_null_space_families.py from the tuning rule of\n"
        "# nsdrake/studies/null_space_laws.py (tuned_gains); do not edit by hand.\n"
        "description: >-\n"
        "  Which null-space law? Five laws (the paper's through J-bar and through the Moore-Penrose\n"
        "  inverse, the kinematic posture PD with the exact and with franka_ros's damped inverse,\n"
        "  the dynamically consistent posture PD multiplied by H and the same on a torque PD) on the\n"
        "  same arm, task impedance and posture objective q_d, each tuned by this project's rule (a rule,\n"
        "  not the libraries' own defaults) for the\n"
        f"  same null-space bandwidth omega ({PANDA_OMEGA:g} rad/s on the Panda, every law's slowest pole;\n"
        f"  {FIG3_OMEGA:g} rad/s on fig3, at the geometric mean of its two null-space inertias, which puts\n"
        f"  the slowest pole at {slow3:.4g} rad/s for the four laws that see the inertia and\n"
        f"  at {FIG3_OMEGA:g} for the paper's law through the Moore-Penrose inverse and the H-weighted PD),\n"
        "  about critically damped and stable at the control period (damping_ratio and pole_radius_T\n"
        "  per row). Tasks: panda_wipe, q_d moved along the self-motion (panda_self_motion) and off it\n"
        "  (panda_off_path: joint 4 0.3 rad toward straight, the elbow opened), fig3, and a 20 N,\n"
        "  50 ms push on the\n"
        "  Panda's elbow, with its 1000 N m/s torque-rate limit. On panda_wipe and\n"
        "  panda_self_motion also the torque PD at the paper's poles (-w and -2w) and two laws at\n"
        "  their library's gains (franka_ros's kinematic PD at its header's initial stiffness,\n"
        "  robosuite's H-weighted PD).\n"
        "scenario: panda_wipe\nmeasure: null_space_laws\nvariants:\n"
    ]
    for task, base, extra, posture, off, omega, h_n in tasks:
        for law in LAW_KEYS:
            text.append(
                _variant(
                    f"{task} / {NAMES[law]}",
                    base,
                    extra | law_overrides(law, rule_gains(law, omega, h_n), posture, off),
                )
            )
        if task in EXTRA_TASKS:
            for name in EXTRAS:
                over = extra | law_overrides(*extra_gains(name, omega, h_n), posture, off)
                text.append(_variant(f"{task} / {name}", base, over))
    (FAMILIES / "null_space_laws.yaml").write_text("".join(text))

    bandwidth = [
        "# Written by scripts/write_null_space_families.py from the tuning rule of\n"
        "# nsdrake/studies/null_space_laws.py (tuned_gains); do not edit by hand.\n"
        "description: >-\n"
        "  The null-space laws against their bandwidth: each law tuned by the rule for a slowest\n"
        f"  null-space pole of {', '.join(f'{w:g}' for w in BANDWIDTHS)} rad/s, on panda_self_motion\n"
        "  (q_d moved\n"
        "  0.5 rad along the self-motion from 2.3 s while the tool presses 10 N): task disturbance\n"
        "  and posture error (joint space and inertia metric) against the bandwidth (bandwidth.png).\n"
        "scenario: panda_self_motion\nmeasure: null_space_bandwidth\nvariants:\n"
    ]
    for omega in BANDWIDTHS:
        for law in LAW_KEYS:
            if law == "kinematic_posture_pd_damped":
                continue  # its null-space loop is the exact-inverse one's (module docstring)
            posture = {"q_d": q_d, "offset": on_path, **moved}
            over = law_overrides(law, rule_gains(law, omega, h_panda), posture, {})
            bandwidth.append(_variant(f"{omega:g} rad/s / {NAMES[law]}", "panda_self_motion", over))
    (FAMILIES / "null_space_bandwidth.yaml").write_text("".join(bandwidth))
    print(
        f"h_n: Panda {h_panda:.4g} kg m², fig3 {h_fig3:.4g} kg m²; "
        "wrote null_space_laws.yaml, null_space_bandwidth.yaml"
    )


if __name__ == "__main__":
    main()

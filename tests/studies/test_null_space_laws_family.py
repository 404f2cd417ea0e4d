"""``nsdrake compare null_space_laws`` (issue 19): the family's set-up and a short run.

The full family (four tasks, about 50 s simulated per law) runs from the command line
(README, "Which null-space law?"); here its gains are checked against the matching rule
of nsdrake.studies.null_space_laws, and one task, shortened, runs end to end.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from nsdrake.experiment.diagram import build_diagram
from nsdrake.experiment.scenario import ScenarioError
from nsdrake.studies.compare import load_family, run_family, variant_scenario
from nsdrake.studies.null_space_laws import matched_gains, null_space_inertia

LAWS = ("paper", "paper, Moore-Penrose", "kinematic posture PD", "dynamically consistent posture PD")
KEY = dict(
    zip(
        LAWS,
        ("paper", "paper_moore_penrose", "kinematic_posture_pd", "dynamically_consistent_posture_pd"),
        strict=True,
    )
)


def test_every_task_runs_every_law():
    family = load_family("null_space_laws")
    names = [v.name.split(" / ") for v in family.variants]
    tasks = list(dict.fromkeys(task for task, _ in names))
    assert tasks == ["panda_wipe", "panda_self_motion", "fig3", "push"]
    assert sorted(map(tuple, names)) == sorted((t, law) for t in tasks for law in LAWS)


def test_the_gains_match_one_null_space_natural_frequency():
    """Each variant's gains are matched_gains(h_n at the start posture, K_n) to the 4
    significant digits the family file writes, and every law has the same q_d."""
    family = load_family("null_space_laws")
    inertia = {}
    for i, variant in enumerate(family.variants):
        s = variant_scenario(family, i, None, 0.01)
        if variant.scenario not in inertia:
            station = build_diagram(s).station
            inertia[variant.scenario] = null_space_inertia(station.arm_model, station.q0)
            assert s.desired_null_space.posture.q_d == dict(s.arm.initial_positions)
        expected = matched_gains(inertia[variant.scenario], s.null_space.K_n)[
            KEY[variant.name.split(" / ")[1]]
        ]
        given = {
            "gain": s.desired_null_space.posture.gain,
            "posture_stiffness": s.null_space.posture_stiffness,
            "posture_damping": s.null_space.posture_damping,
        }
        for name, value in expected.items():
            assert given[name] == pytest.approx(value, rel=5e-4), (variant.name, name)


def test_the_moved_posture_keeps_the_tool_where_it_was():
    """panda_self_motion's q_d offset is a self-motion: the tool's pose at q_d + Δq is its
    pose at q_d within the rounding of the family file's 4 decimals."""
    family = load_family("null_space_laws")
    index = [v.name for v in family.variants].index("panda_self_motion / paper")
    s = variant_scenario(family, index, None, 0.01)
    arm = build_diagram(s).station.arm_model
    p = s.desired_null_space.posture
    q_d = np.array([p.q_d[j] for j in arm.joint_names])
    offset = np.array([p.offset[j] for j in arm.joint_names])
    context = arm.plant.CreateDefaultContext()
    poses = []
    for q in (q_d, q_d + offset):
        arm.plant.SetPositions(context, q)
        poses.append(arm.plant.CalcRelativeTransform(context, arm.plant.world_frame(), arm.tool_frame))
    assert np.linalg.norm(offset) > 0.45
    assert np.linalg.norm(poses[0].translation() - poses[1].translation()) < 5e-5
    assert poses[0].rotation().InvertAndCompose(poses[1].rotation()).ToAngleAxis().angle() < 1e-4


def test_a_variant_with_an_unknown_scenario_is_refused(tmp_path, monkeypatch):
    import nsdrake.studies.compare as compare

    monkeypatch.setattr(compare, "FAMILY_DIR", tmp_path)
    (tmp_path / "bad.yaml").write_text("scenario: fig3\nmeasure: fig3\nvariants: [{name: a, scenario: fig9}]")
    with pytest.raises(ScenarioError, match=r"variants\[0\]\.scenario: unknown scenario 'fig9'"):
        load_family("bad")


@pytest.mark.slow
def test_short_family_dynamically_consistent_laws_leave_the_task_alone(tmp_path):
    """panda_wipe to 2 s (contact at 1.27 s, a 0.23 s window): the three dynamically
    consistent rows' J H⁻¹ τ₀ is rounding (< 1e-9 m/s²), the kinematic projector's is not
    (3.6e-3 m/s² measured); ν exists for the paper's law only."""
    family = load_family("null_space_laws")
    family = dataclasses.replace(family, variants=family.variants[:4])
    result = run_family(family, tmp_path, duration=2.0)
    rows = {row["variant"].split(" / ")[1]: row for row in result.rows}
    assert not result.failures
    for law in ("paper", "paper, Moore-Penrose", "dynamically consistent posture PD"):
        assert rows[law]["task_disturbance_peak"] < 1e-9
    assert rows["kinematic posture PD"]["task_disturbance_peak"] > 1e-4
    assert math.isfinite(rows["paper"]["nu_rms"]) and rows["kinematic posture PD"]["nu_rms"] == ""
    for name in ("table.md", "table.csv", "laws.png"):
        assert (tmp_path / name).stat().st_size > 0

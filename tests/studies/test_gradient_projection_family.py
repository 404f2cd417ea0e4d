"""Section 3.4's claim in closed loop (``nsdrake compare gradient_projection``): with the
dynamically consistent J̄, Eq. 28's unrotated gradient step can worsen the criterion,
Eq. 30's H⁻¹-rotated one cannot, and neither can Eq. 28 with the Moore–Penrose inverse
(which drives a link into the plate when nothing guards the links: a failed row).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from conftest import paper_arm
from pydrake.systems.framework import DiagramBuilder

from nsdrake.control.criteria.joint_torque import joint_torque_criterion
from nsdrake.control.pseudo_inverse import GeneralizedInverse, PseudoInverseKind
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.experiment.traces import Traces
from nsdrake.studies.compare import (
    RunFacts,
    load_family,
    measure_gradient_projection,
    run_family,
    variant_scenario,
)

Q0_FIG3 = np.array([0.401, 0.972, 1.012, 0.614])  # fig3's initial pose [rad]
F_D = np.array([0.0, 10.0])  # fig3's desired force, along the plate's normal +y [N]


def test_at_fig3s_start_the_unrotated_step_with_j_bar_makes_the_torque_worse():
    """Φᵀ(I − J̄J)Φ = −330 < 0 at fig3's initial pose (the family's description quotes
    it), while Φᵀ(I − J̄J)H⁻¹Φ > 0 and Φᵀ(I − J⁺J)Φ > 0: with K < 0, only Eq. 28's
    unrotated step with J̄ raises the joint-torque criterion. Catches a family whose
    base pose cannot show the claim, or a description that misstates it."""
    arm = paper_arm()
    terms = arm.terms(arm.plant.CreateDefaultContext(), Q0_FIG3, np.zeros(4), coriolis=False)
    _, Phi = joint_torque_criterion(terms.J, terms.dJ_dq, F_D)
    N_dc = GeneralizedInverse().at(terms).N
    N_mp = GeneralizedInverse(PseudoInverseKind.moore_penrose).at(terms).N
    description = load_family("gradient_projection").description
    quoted = re.search(r"negative: (-?\d+) at the initial pose", description)
    assert Phi @ N_dc @ Phi == pytest.approx(float(quoted.group(1)), abs=1)  # the figure the table prints
    assert Phi @ N_dc @ Phi == pytest.approx(-330, abs=1)
    assert Phi @ N_dc @ terms.H_inv @ Phi > 0
    assert Phi @ N_mp @ Phi > 0


def test_the_family_gives_every_variant_the_same_first_step():
    """The gains are set so that the unscaled q̇_dⁿ has the same size at the initial pose
    in every variant (1.94–1.96 rad/s, within 2%): the rows compare directions, not gains.
    Catches a gain edited in one row only, and a description or page that quotes another
    step (they said 1.96 for all three)."""
    arm = paper_arm()
    terms = arm.terms(arm.plant.CreateDefaultContext(), Q0_FIG3, np.zeros(4), coriolis=False)
    _, Phi = joint_torque_criterion(terms.J, terms.dJ_dq, F_D)
    family = load_family("gradient_projection")
    sizes = []
    for i in range(len(family.variants)):
        s = variant_scenario(family, i, None, None)
        d = s.desired_null_space
        assert d.criteria.obstacle.gain == 0.0 and d.criteria.manipulability.gain == 0.0
        kind = PseudoInverseKind(s.null_space.pseudo_inverse)
        N = GeneralizedInverse(kind).at(terms).N
        W_inv = terms.H_inv if d.rotate_gradient else np.eye(4)
        sizes.append(abs(d.criteria.joint_torque.gain) * np.linalg.norm(N @ W_inv @ Phi))
    np.testing.assert_allclose(sizes, 1.96, rtol=0.02)
    # the steps' range as the family's description (its table's text) and docs/claims.md quote it
    for text in (family.description, (Path(__file__).parents[2] / "docs" / "claims.md").read_text()):
        low, high = re.search(r"(\d+\.\d+)[-–](\d+\.\d+) rad/s before the", text).groups()
        assert (round(min(sizes), 2), round(max(sizes), 2)) == (float(low), float(high))


@pytest.mark.slow
def test_eq30_never_moves_the_criterion_the_wrong_way_and_eq28_with_j_bar_does(tmp_path):
    """2 s of the family: the commanded step Φᵀ q̇_dⁿ never points the wrong way with
    Eq. 30 or with Moore–Penrose, and does in a large share of periods with Eq. 28's
    unrotated step and J̄, which ends with a higher criterion than Eq. 30; Moore–Penrose
    drives a link into the plate at about 0.6 s and its row says so. Catches a rotation
    applied in every variant (or in none)."""
    result = run_family(load_family("gradient_projection"), tmp_path, duration=2.0, jobs=2)
    eq30, eq28_dc, mp = result.rows
    assert eq30["rotate_gradient"] and not eq28_dc["rotate_gradient"]
    assert eq30["joint_torque_active_periods"] > 900
    assert eq30["joint_torque_commanded_step_wrong_share"] == 0.0
    assert eq30["joint_torque_wrong_way_share"] == 0.0
    assert mp["joint_torque_commanded_step_wrong_share"] == 0.0
    # Moore–Penrose drives a link into the plate (nothing guards the links): a failed row.
    assert "failed_at" not in eq30 and "failed_at" not in eq28_dc
    assert 0.5 < float(mp["failed_at"].split(" s:")[0]) < 0.7
    assert eq28_dc["joint_torque_commanded_step_wrong_share"] > 0.3
    assert eq28_dc["joint_torque_end"] > 1.5 * eq30["joint_torque_end"]


def test_a_run_whose_link_touches_the_plate_is_marked_failed_and_measured_before_it():
    """Twelve control periods on level 2 with p_tau falling, then a link touches the plate
    at row 8 and p_tau keeps falling (the jammed arm): the row says when it failed, and
    the criterion figures end at row 7, while d_min and the contacts cover the whole run.
    Catches a failed row that is not marked, or figures that include the jammed arm."""
    family = load_family("gradient_projection")
    scenario = variant_scenario(family, 0, None, None)
    station = add_scenario_station(DiagramBuilder(), scenario)
    rows = 12
    columns = {"t": 0.002 * np.arange(rows), "mode": np.full(rows, 2.0)}
    for i in range(4):
        columns[f"q{i + 1}"] = np.full(rows, Q0_FIG3[i])
        columns[f"qns{i + 1}"] = np.full(rows, 0.1 * (i + 1))
    columns["p_tau"] = 40.0 - np.arange(rows)
    columns["p_obstacle"] = columns["w"] = np.zeros(rows)
    columns["d_min"] = np.where(np.arange(rows) < 8, 0.01, -0.001)
    columns["forbidden_contacts"] = np.where(np.arange(rows) < 8, 0.0, 2.0)
    columns["f_n"] = np.where(np.arange(rows) < 8, 10.0, 60.0)
    row = measure_gradient_projection(Traces(columns), RunFacts(scenario, station))
    assert row["failed_at"].startswith("0.016 s: a link touched")
    assert "60 N" in row["failed_at"]
    assert row["joint_torque_active_periods"] == 7
    assert row["joint_torque_end"] == 33.0
    assert row["d_min_min"] == -0.001 and row["forbidden_contacts_max"] == 2
    columns["forbidden_contacts"] = np.zeros(rows)
    row = measure_gradient_projection(Traces(columns), RunFacts(scenario, station))
    assert "failed_at" not in row and row["joint_torque_end"] == 29.0

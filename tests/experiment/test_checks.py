"""Settings that cannot work are refused before simulating, each with one line naming
the file or field and the reason (nsdrake/checks.py)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from conftest import fig3_with

from nsdrake.control.validation import sampled_loop_radius
from nsdrake.experiment.scenario import ScenarioError
from nsdrake.reporting.run_folder import check_scenario
from nsdrake.station.models import models_dir

T = 0.002  # fig3's period [s]


def refused(tmp_path, overlay: str) -> str:
    with pytest.raises(ScenarioError) as info:
        check_scenario(fig3_with(tmp_path, overlay))
    message = str(info.value)
    assert "\n" not in message
    return message


def broken_arm(tmp_path: Path, old: str, new: str) -> str:
    text = (models_dir() / "arm4.urdf").read_text()
    assert old in text
    path = tmp_path / "arm.urdf"
    path.write_text(text.replace(old, new, 1))
    return f"arm: {{urdf: {path}}}\n"


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('<mass value="0.4"/>', '<mass value="-0.4"/>', "arm.urdf: link 'link1': mass -0.4 kg must be > 0"),
        (
            '<capsule radius="0.01" length="0.25"/>',
            '<capsule radius="0.01" length="-0.25"/>',
            "capsule length -0.25",
        ),
        ('ixx="0.00002"', 'ixx="-0.00002"', "link 'link1': inertia must be positive definite"),
        ('iyy="0.00209"', 'iyy="0.00002"', "link 'link1': inertia breaks the triangle inequality"),
    ],
    ids=["negative mass", "negative length", "inertia not positive", "triangle inequality"],
)
def test_physically_invalid_models_are_named(tmp_path, old, new, message):
    """Drake simulates a negative mass, repairs a bad inertia with a warning, and fails
    on a negative length with a raw parser line; nsdrake names file, link and problem."""
    assert message in refused(tmp_path, broken_arm(tmp_path, old, new))


def test_sampled_loop_radius_is_the_textbook_one():
    """Semi-implicit Euler of ẍ = −D ẋ − K x: stable for the fig3 gains, unstable once
    T²K exceeds 2(2 − T D) (the characteristic polynomial's bound at z = −1)."""
    assert sampled_loop_radius(400.0, 40.0, T) < 1.0
    D = 200.0
    K_edge = 2.0 * (2.0 - T * D) / T**2
    assert sampled_loop_radius(0.99 * K_edge, D, T) < 1.0
    assert sampled_loop_radius(1.01 * K_edge, D, T) > 1.0


def test_null_space_gain_beyond_the_discrete_bound_is_refused_and_below_accepted(tmp_path):
    """K_n T ≥ 2 makes ėⁿ = −K_n eⁿ sampled at T unstable: refused; 0.9 of the bound runs."""
    message = refused(tmp_path, "null_space: {K_n: 1000.0}\n")
    assert "null_space.K_n: K_n T = 2 ≥ 2" in message and "K_n < 1000" in message
    check_scenario(fig3_with(tmp_path, "null_space: {K_n: 900.0}\n"))


def test_unstable_impedance_gains_are_refused(tmp_path):
    message = refused(tmp_path, "impedance: {K_v_tangent: 1100.0}\n")
    assert re.search(
        r"impedance\.K_p_tangent, K_v_tangent: \(400, 1100\) sampled every 0\.002 s is unstable", message
    )


def test_a_period_too_long_for_the_loops_is_refused(tmp_path):
    """20 ms (the issue's crash): the normal impedance loop is unstable at that period.
    With a damping that the period allows, the force loop in contact is still
    under-sampled at 12 ms (measured: it breaks there); 9 ms is accepted."""
    message = refused(tmp_path, "control_period: 0.02\n")
    assert "impedance.K_p_normal, K_v_normal: (100, 200) sampled every 0.02 s is unstable" in message
    message = refused(tmp_path, "control_period: 0.012\nimpedance: {K_v_normal: 50.0}\n")
    assert "control_period: 0.012 s is too long for the force loop in contact" in message
    check_scenario(fig3_with(tmp_path, "control_period: 0.009\n"))


def test_a_duration_too_long_to_store_is_refused(tmp_path):
    assert "GiB nsdrake keeps" in refused(tmp_path, "duration: 1000000000.0\n")


def test_task_axes_the_arm_cannot_span_are_refused(tmp_path):
    """The planar arm cannot move its tool along z: [x, y, z] would end in NaN torques."""
    message = refused(tmp_path, "task: {axes: [x, y, z]}\n")
    assert "task.axes: ['x', 'y', 'z']: at the initial pose the arm's Jacobian has rank 2 < 3" in message

"""Settings outside a documented physical range are refused with the bound named, before
anything runs (issue 15, items 4 and 5): beyond them a run would take hours (a plant
step of nanoseconds, a delay of a million periods), overflow (an obstacle of 1e200 m),
alias another setting (a seed Drake keeps 32 bits of) or make the model checks meaningless
(a gravity of 10⁴ g). The bounds: README "What nsdrake refuses, and why"."""

from __future__ import annotations

import time

import pytest
from conftest import fig3_with

from nsdrake.cli import main
from nsdrake.experiment.scenario import ScenarioError
from nsdrake.reporting.run_folder import check_scenario
from nsdrake.station.models import models_dir

RANGES = [
    (
        "realism: {physics: {enabled: true, substeps: 256}}",
        "realism.physics.substeps: a plant step of 7.81e-06 s (0.002 s / 256) is shorter than 1e-05 s: "
        "more than 100,000 plant steps per simulated second",
    ),
    (
        "realism: {friction: {enabled: true, min_substeps: 1048576}}",
        "realism.friction.min_substeps: a plant step of 1.91e-09 s (0.002 s / 1048576)",
    ),
    ("control_period: 5.0e-6\nduration: 0.01", "control_period: a plant step of 5e-06 s (5e-06 s / 1)"),
    (
        "realism: {force_sensor: {sample_period: 1.0e-9}}",
        "realism.force_sensor.sample_period: 1e-09 s is shorter than 1e-05 s: no force sensor samples "
        "faster than 100 kHz",
    ),
    ("realism: {delay: {periods: 1000000}}", "realism.delay.periods: must be at most 100 periods"),
    (
        "realism: {force_sensor: {seed: 4294967296}}",
        "realism.force_sensor.seed: must be at most 4294967295 (Drake's random generator keeps 32 bits",
    ),
    (
        "realism: {force_sensor: {seed: 18446744073709551616}}",
        "realism.force_sensor.seed: must be at most 4294967295",
    ),
    ("gravity: [0.0, -1.0e12, 0.0]", "gravity: 1e+12 m/s² is beyond the 1000 m/s² (100 g) nsdrake models"),
    (
        "obstacles: [{name: big, shape: sphere, size: [1.0e200], position: [5.0, 5.0, 0.0]}]",
        "obstacles[0].size: its size 1e+200 m is beyond the 100 m nsdrake models",
    ),
    (
        "obstacles: [{name: far, shape: box, size: [0.1, 0.1, 0.1], position: [1.0e6, 0.0, 0.0]}]",
        "obstacles[0].position: its distance from the origin 1e+06 m is beyond the 100 m",
    ),
    (
        "plate: {position: [0.0, 1.0e4, 0.0]}",
        "plate.position: its distance from the origin 1e+04 m is beyond",
    ),
]


@pytest.mark.parametrize(("overlay", "message"), RANGES, ids=[r[1].split(":")[0] for r in RANGES])
def test_settings_beyond_a_physical_range_are_refused_naming_the_bound(tmp_path, overlay, message):
    """Catches each of these starting a run that hangs, overflows into a traceback or
    silently simulates another setting, instead of one line with the bound."""
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, overlay + "\n")
    assert message in str(info.value) and "\n" not in str(info.value), str(info.value)


@pytest.mark.parametrize(
    "overlay",
    [
        "realism: {physics: {enabled: true, substeps: 128}}",  # 15.6 µs: the finest step at 2 ms
        "realism: {force_sensor: {enabled: true, sample_period: 1.5625e-5}}",  # 64 kHz
        "realism: {delay: {enabled: true, periods: 100}}",
        "realism: {force_sensor: {seed: 4294967295}}",
        "gravity: [0.0, -900.0, 0.0]",
        "obstacles: [{name: wall, shape: box, size: [100.0, 0.1, 2.0], position: [0.0, 1.5, 0.0]}]",
    ],
)
def test_settings_at_the_edge_of_the_range_are_accepted(tmp_path, overlay):
    """A bound too tight fails here: the last value inside each range passes validate."""
    fig3_with(tmp_path, overlay + "\n")


def test_a_model_with_a_kinematic_loop_is_one_line_naming_the_file_and_link(tmp_path):
    """Issue 15, item 5: Drake refused the loop when the plant was finalized, with a
    traceback of its long message."""
    text = (models_dir() / "arm4.urdf").read_text()
    loop = '<joint name="loop_joint" type="continuous"><parent link="base"/><child link="link3"/></joint>'
    (tmp_path / "loop.urdf").write_text(text.replace("</robot>", loop + "</robot>"))
    with pytest.raises(ScenarioError) as info:
        check_scenario(fig3_with(tmp_path, f"arm: {{urdf: {tmp_path / 'loop.urdf'}}}\n"))
    assert str(info.value).endswith(
        "loop.urdf: link 'link3': child of two joints ('joint3' and 'loop_joint'): a kinematic loop; "
        "nsdrake's arms are trees of joints"
    )


def test_the_command_line_refuses_them_in_one_line_before_anything_is_written(tmp_path, capsys):
    """The whole path, for a delay of a million periods (it ran for hours) and an obstacle of
    1e200 m (an OverflowError traceback): exit 2, one line, no folder, within seconds."""
    for overlay in RANGES[4][0], RANGES[8][0]:
        config = tmp_path / "c.yaml"
        config.write_text(overlay + "\n")
        start = time.perf_counter()
        assert main(["run", "fig3", "--config", str(config), "--out", str(tmp_path / "out")]) == 2
        assert time.perf_counter() - start < 30
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("nsdrake: error: ")
        assert not (tmp_path / "out").exists()

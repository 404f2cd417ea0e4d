"""The reach disc the Fig. 3 reference stays within (nsdrake.experiment.diagram.arm_reach):
sampled once per arm model, keyed by what determines it, and the same as a fresh sample."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from conftest import arm_from_urdf_text
from models import serial_arm_urdf

import nsdrake.experiment.diagram as diagram
from nsdrake.experiment.diagram import arm_reach, build_diagram, sampled_reach
from nsdrake.experiment.scenario import load_scenario


@pytest.fixture
def counted(monkeypatch):
    """An empty cache, and the number of discs actually sampled since."""
    monkeypatch.setattr(diagram, "_REACH", {})
    calls = []

    def sample(arm, samples):
        calls.append(arm)
        return sampled_reach(arm, samples)

    monkeypatch.setattr(diagram, "sampled_reach", sample)
    return calls


def test_every_diagram_of_one_arm_samples_its_reach_once(counted):
    """fig3 with and without the null-space task, and fig3_vertical (the same arm, another
    gravity): one sampling, and the disc is the one a fresh sampling gives."""
    built = [build_diagram(load_scenario("fig3"), null_space_task=flag) for flag in (True, False)]
    built.append(build_diagram(load_scenario("fig3_vertical")))
    assert len(counted) == 1
    centre, radius = arm_reach(built[0].station)
    fresh_centre, fresh_radius = sampled_reach(built[0].station.arm_model, 2000)
    assert radius == fresh_radius and np.array_equal(centre, fresh_centre)
    assert radius == pytest.approx(1.0, abs=1e-3)  # arm4: four 0.25 m links, stretched (urdf/README)


def test_the_cache_key_is_the_urdfs_content_the_tool_frame_and_the_task_axes(tmp_path, counted):
    """An edited URDF at the same path, or other task axes, is a new arm; the same content
    at another path is not. Catches a cache keyed by the file's path, or one that ignores
    the axes."""
    path = tmp_path / "arm.urdf"

    def station(lengths, axes=("x", "y"), where=path):
        text = serial_arm_urdf(["z", "z", "z"], lengths, [1.0, 1.0, 1.0])
        where.write_text(text)
        return SimpleNamespace(arm_model=arm_from_urdf_text(text, axes), arm_file=where)

    _, short = arm_reach(station([0.3, 0.3, 0.3]))
    _, longer = arm_reach(station([0.3, 0.3, 0.5]))
    assert short == pytest.approx(0.9, rel=1e-3) and longer == pytest.approx(1.1, rel=1e-3)
    assert len(counted) == 2
    centre, _ = arm_reach(station([0.3, 0.3, 0.5], axes=("x", "y", "z")))
    assert len(counted) == 3 and centre.shape == (3,)
    arm_reach(station([0.3, 0.3, 0.5], where=tmp_path / "copy.urdf"))
    assert len(counted) == 3


def test_a_caller_cannot_change_the_cached_disc(counted):
    built = build_diagram(load_scenario("fig3"))
    centre, _ = arm_reach(built.station)
    centre += 1.0
    assert np.array_equal(arm_reach(built.station)[0], np.zeros(2))

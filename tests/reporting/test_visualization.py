"""Meshcat replay and the diagram's picture: what they contain, and that recording
changes nothing in the simulation."""

from __future__ import annotations

import re
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pydot
import pytest
from conftest import SHORT_RUN_DURATION, fig3_with
from replay_reader import animation_tracks, replay_commands

from nsdrake.experiment.diagram import build_diagram
from nsdrake.experiment.simulate import run
from nsdrake.experiment.traces import Traces
from nsdrake.reporting.metrics import first_contact_index
from nsdrake.reporting.replay import write_diagram_picture
from nsdrake.station.visualization import start_meshcat, visual_body_paths, visualizer_period

# The contact-force arrow between the tool sphere and the plate: Drake names the pair by
# geometry (body.geometry) because the tool body carries two collision shapes.
CONTACT_ARROW = "/drake/contact_forces/point/tool.tool_collision+plate"

ROLE_NAME = re.compile(r"^[a-z][a-z0-9_]*$")


@pytest.mark.parametrize("live", [False, True], ids=["recorded", "live"])
def test_recording_leaves_the_traces_byte_identical(tmp_path, live):
    """Through first contact (≈ 1.27 s) and into the press: the visualizers only
    publish, so the plant steps exactly as without them (live: also at real time)."""
    scenario = fig3_with(tmp_path, duration=1.5)
    plain, _ = run(scenario)
    recorded, built = run(scenario, meshcat=start_meshcat(live=False), live=live)
    assert built.visualizers is not None
    plain.write_csv(tmp_path / "plain.csv")
    recorded.write_csv(tmp_path / "recorded.csv")
    assert (tmp_path / "plain.csv").read_bytes() == (tmp_path / "recorded.csv").read_bytes()
    assert first_contact_index(plain, 0.5) is not None  # the comparison covers contact


@pytest.mark.parametrize("period", [0.001, 0.002, 0.005, 0.0333, 0.05])
def test_visualizer_period_is_a_whole_number_of_control_periods(period):
    p = visualizer_period(period)
    k = p / period
    assert abs(k - round(k)) < 1e-9 and round(k) >= 1
    if period < 1 / 60:  # fine control periods: the frame rate is the target's, within half a period
        assert 1 / (1 / 32 + period / 2) <= 1 / p <= 1 / (1 / 32 - period / 2)


def test_replay_is_self_contained(short_run):
    out, _ = short_run
    text = (out / "replay.html").read_text(encoding="utf-8")
    assert not re.search(r"<script[^>]*\bsrc\s*=", text, flags=re.I)
    assert not re.search(r"<link[^>]*\bhref\s*=", text, flags=re.I)
    assert not re.search(r"""fetch\(\s*["'](?!data:)""", text)


def test_replay_animates_every_body_and_the_contact_force(short_run):
    out, _ = short_run
    commands = replay_commands(out / "replay.html")
    objects = {c["path"] for c in commands if c.get("type") == "set_object"}
    station = build_diagram(fig3_with(out, duration=SHORT_RUN_DURATION)).station
    bodies = visual_body_paths(station)
    assert {
        "/drake/visualizer/arm4/link1",
        "/drake/visualizer/arm4/tool",
        "/drake/visualizer/plate/plate",
    } <= set(bodies)
    for path in bodies:  # each body's geometry is in the scene …
        assert any(o.startswith(path + "/") for o in objects), path
    fps, tracks = animation_tracks(commands)
    traces = Traces.read_csv(out / "traces.csv")
    frames = int(np.floor(SHORT_RUN_DURATION * fps)) + 1
    for path in bodies:  # … and moves over the whole run, one key per frame
        keys = tracks[(path, ".position")]
        assert len(keys) == frames and keys[-1]["time"] == frames - 1, path
    # The tool's last recorded position is where the traces put it (it slides at 5 cm/s).
    tool = tracks[("/drake/visualizer/arm4/tool", ".position")][-1]["value"]
    t_last = (frames - 1) / fps
    k = int(np.searchsorted(traces["t"], t_last - 1e-9))
    assert np.allclose(tool[:2], [traces["x"][k], traces["y"][k]], atol=1e-9)
    # The contact-force arrow appears once the tool touches the plate, not before.
    visible = tracks[(CONTACT_ARROW, ".visible")]
    shown = [key["time"] / fps for key in visible if key["value"]]
    t_contact = traces["t"][first_contact_index(traces, 0.5)]
    assert shown and abs(shown[0] - t_contact) <= 2 / fps
    assert all(not key["value"] for key in visible if key["time"] / fps < t_contact - 2 / fps)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # pydot's parser uses old pyparsing names
def test_diagram_dot_names_every_system_after_its_role(short_run, tmp_path):
    out, _ = short_run
    built = build_diagram(fig3_with(tmp_path, duration=SHORT_RUN_DURATION), meshcat=start_meshcat(live=False))
    names = [s.get_name() for s in built.diagram.GetSystems()]
    names += [s.get_name() for s in built.controller.GetSystems()]
    assert [n for n in names if not ROLE_NAME.match(n)] == []
    expected = {
        "plant",
        "controller",
        "robot_terms",
        "force_sensor",
        "impedance_controller",
        "null_space_controller",
        "priority_selector",
        "criteria",
        "actuator_limits",
        "meshcat_visualizer",
        "contact_visualizer",
    }
    assert expected <= set(names)
    text = (out / "diagram.dot").read_text()
    (graph,) = pydot.graph_from_dot_data(text)
    assert graph.get_type() == "digraph"
    labelled = set(re.findall(r"^name=([^<\n]*)", text, flags=re.M))
    assert set(names) <= labelled


@pytest.mark.skipif(
    shutil.which("dot") is None, reason="Graphviz's dot is not installed (apt-get install graphviz)"
)
def test_diagram_svg_shows_every_system(short_run):
    out, _ = short_run
    root = ET.parse(out / "diagram.svg").getroot()
    assert root.tag.endswith("svg")
    texts = " ".join(t.text or "" for t in root.iter() if t.tag.endswith("text"))
    built = build_diagram(fig3_with(out, duration=SHORT_RUN_DURATION), meshcat=start_meshcat(live=False))
    for system in built.diagram.GetSystems():
        assert f"name={system.get_name()}" in texts, system.get_name()


def test_without_dot_only_the_source_is_written_and_the_note_says_how_to_render(tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    built = build_diagram(fig3_with(tmp_path, duration=0.1))
    picture = write_diagram_picture(built.diagram, tmp_path)
    assert picture.dot.is_file() and picture.svg is None
    assert not (tmp_path / "diagram.svg").exists()
    assert "\n" not in picture.note
    assert f"dot -Tsvg {picture.dot} -o {tmp_path / 'diagram.svg'}" in picture.note

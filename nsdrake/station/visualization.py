"""The station in Meshcat, live or recorded for the replay.

- :func:`add_visualizers` adds Drake's ``MeshcatVisualizer`` (the arm, the plate
  and any other obstacle, every illustration geometry of the scene graph) and
  ``ContactVisualizer`` (each contact force as an arrow) to a builder, both
  publishing at :func:`visualizer_period`, a whole number of control periods.
- :class:`Visualizers` starts and publishes the recording that
  :func:`nsdrake.reporting.replay.write_replay` saves as ``replay.html``: ``Meshcat.StaticHtml()``, the
  three.js viewer with its scripts inlined and the recording as an animation
  with a time slider; it opens from the file system with no network.

The visualizers only read the plant's outputs in publish events: a run with them
steps the plant exactly as one without (tests/reporting/test_visualization.py compares the
traces byte for byte).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

from pydrake.geometry import Meshcat, MeshcatParams, MeshcatVisualizer, MeshcatVisualizerParams, Rgba
from pydrake.multibody.meshcat import ContactVisualizer, ContactVisualizerParams
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import DiagramBuilder

from nsdrake.station.plant import Station

# Target frame rate of the visualizers [1/s]; the period is rounded to whole control periods.
FRAME_RATE = 32.0
# Length of the contact-force arrow per newton [m/N]: 10 N, fig3's force, is 0.2 m.
ARROW_METERS_PER_NEWTON = 0.02
# Where the camera looks from and at, world frame [m]: above the arm's base, in
# front of the plate (at y = 0.6 m in fig3), tilted so the links' height shows.
CAMERA_POSITION = (0.0, -0.15, 0.8)
CAMERA_TARGET = (0.0, 0.3, 0.0)


def visualizer_period(control_period: float, frame_rate: float = FRAME_RATE) -> float:
    """The publish period closest to 1/``frame_rate`` that is a whole number (≥ 1) of
    control periods [s], so that publish events fall on plant steps."""
    return max(1, round(1.0 / (frame_rate * control_period))) * control_period


def start_meshcat(*, live: bool) -> Meshcat:
    """A Meshcat server on localhost only: on Drake's usual port (7000, or the next
    free one) when ``live``, so the URL is the familiar one; else on any free port,
    as a recorder nobody watches. Drake's "listening" log line is left out."""
    params = MeshcatParams()
    params.host = "localhost"
    if not live:
        params.port = 0
    drake_logger = logging.getLogger("drake")
    level = drake_logger.level
    drake_logger.setLevel(logging.WARNING)
    try:
        return Meshcat(params)
    finally:
        drake_logger.setLevel(level)


@dataclass
class Visualizers:
    """The Meshcat systems of one diagram."""

    meshcat: Meshcat
    visualizer: MeshcatVisualizer
    contact_visualizer: ContactVisualizer

    def start_recording(self, *, live: bool) -> None:
        """Call before ``Simulator.Initialize``. Unless ``live``, frames are only
        recorded, not also sent to a browser that is not there."""
        self.visualizer.StartRecording(set_transforms_while_recording=live)

    def publish_recording(self) -> None:
        """Ends the recording and hands it to the viewer (live browsers get the
        time slider; :func:`write_replay` saves it)."""
        self.visualizer.StopRecording()
        self.visualizer.PublishRecording()


def add_visualizers(
    builder: DiagramBuilder, station: Station, meshcat: Meshcat, *, period: float, camera=((), ())
) -> Visualizers:
    """Adds ``meshcat_visualizer`` and ``contact_visualizer`` to ``builder``, publishing
    every ``period`` seconds, and points the camera at the arm and the plate: from
    ``camera`` = (position, target) [m], world, where given (each may be empty: the
    default view)."""
    visualizer = MeshcatVisualizer.AddToBuilder(
        builder,
        station.scene_graph,
        meshcat,
        MeshcatVisualizerParams(publish_period=period, prefix="visualizer"),
    )
    visualizer.set_name("meshcat_visualizer")
    contact = ContactVisualizer.AddToBuilder(
        builder,
        station.plant,
        meshcat,
        ContactVisualizerParams(
            publish_period=period,
            newtons_per_meter=1.0 / ARROW_METERS_PER_NEWTON,
            radius=0.005,
            color=Rgba(0.1, 0.75, 0.2, 1.0),
            prefix="contact_forces",
        ),
    )
    contact.set_name("contact_visualizer")
    position, target = camera
    meshcat.SetCameraPose(list(position or CAMERA_POSITION), list(target or CAMERA_TARGET))
    return Visualizers(meshcat=meshcat, visualizer=visualizer, contact_visualizer=contact)


def visual_body_paths(station: Station, prefix: str = "visualizer") -> list[str]:
    """The Meshcat path of every body with illustration geometry (the arm's links,
    the plate, obstacles), as the visualizer names them: /drake/PREFIX/MODEL/BODY."""
    plant = station.plant
    paths = []
    for k in range(plant.num_bodies()):
        body = plant.get_body(BodyIndex(k))
        if plant.GetVisualGeometriesForBody(body):
            model = plant.GetModelInstanceName(body.model_instance())
            paths.append(f"/drake/{prefix}/{model}/{body.name()}")
    return paths

"""Running a scenario: build the diagram, simulate, gather the traces."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.analysis import Simulator

from .diagram import ControlledStation, build_diagram
from .scenario import Scenario
from .traces import Traces


def run(
    scenario: Scenario,
    *,
    null_space_task: bool = True,
    progress: Callable[[float], None] | None = None,
    meshcat: Meshcat | None = None,
    live: bool = False,
) -> tuple[Traces, ControlledStation]:
    """Simulates ``scenario`` for its duration; returns the traces and the diagram handles.

    ``progress`` is called with the fraction done, about a hundred times per run.
    With a ``meshcat``, the run is recorded and the recording published to it
    (``visualization.write_replay`` saves it); ``live`` also sends every frame to
    the browsers watching and paces the run at real time. Neither changes the traces.
    """
    built = build_diagram(scenario, null_space_task=null_space_task, meshcat=meshcat)
    station = built.station
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant_context = station.plant.GetMyMutableContextFromRoot(context)
    station.plant.SetPositions(plant_context, station.q0)
    station.plant.SetVelocities(plant_context, station.v0)
    if built.visualizers is not None:
        built.visualizers.start_recording(live=live)
    if live:
        simulator.set_target_realtime_rate(1.0)
    simulator.Initialize()
    if progress is None:
        simulator.AdvanceTo(scenario.duration)
    else:
        chunks = 100
        for k in range(1, chunks + 1):
            simulator.AdvanceTo(scenario.duration * k / chunks)
            progress(k / chunks)
    if built.visualizers is not None:
        built.visualizers.publish_recording()
    return collect_traces(built, context), built


def collect_traces(built: ControlledStation, root_context) -> Traces:
    """The loggers' records as named columns (see README for the column list)."""
    arm = built.station.arm_model
    n = arm.n
    logs = {name: logger.FindLog(root_context) for name, logger in built.loggers.items()}
    t = logs["state"].sample_times()
    columns: dict[str, np.ndarray] = {"t": t}

    def add(prefix: str, data: np.ndarray, names):
        for i, name in enumerate(names):
            columns[f"{prefix}{name}"] = data[i]

    axes = arm.task_axes
    state = logs["state"].data()
    add("", task_positions(built, state[:n]), axes)
    add("", logs["x_d"].data(), [f"{a}_d" for a in axes])
    force = logs["f"].data()[arm.rows]
    add("f_", force, axes)
    columns["f_n"] = built.station.normal @ force
    columns["f_d"] = logs["f_d"].data()[0]
    joints = [str(k + 1) for k in range(n)]
    add("q", state[:n], joints)
    add("v", state[n:], joints)
    add("tau", logs["tau"].data(), joints)
    add("qns", logs["qns"].data(), joints)
    add("en", logs["en"].data(), joints)
    columns["nu"] = logs["nu"].data()[0]
    columns["mode"] = logs["mode"].data()[0]
    columns["w"] = logs["w"].data()[0]
    columns["d_min"] = logs["d_min"].data()[0]
    columns["p_tau"] = logs["p_tau"].data()[0]
    columns["p_obstacle"] = logs["p_obstacle"].data()[0]
    columns["speed_scale"] = logs["speed_scale"].data()[0]
    columns["forbidden_contacts"] = logs["forbidden_contacts"].data()[0]
    columns["tau0_scale"] = logs["saturation"].data()[0]
    columns["saturated_joints"] = logs["saturation"].data()[1]
    return Traces(columns)


def task_positions(built: ControlledStation, q: np.ndarray) -> np.ndarray:
    """x = p(q) (Eq. 1) for each column of ``q`` (n, k). (m, k) [m]."""
    plant, arm = built.station.plant, built.station.arm_model
    context = plant.CreateDefaultContext()
    out = np.empty((arm.m, q.shape[1]))
    for k in range(q.shape[1]):
        plant.SetPositions(context, q[:, k])
        out[:, k] = arm.task_position(context)
    return out

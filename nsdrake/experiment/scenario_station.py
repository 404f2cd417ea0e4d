"""A scenario's station: the station's settings taken from the scenario, and the checks
that need both (joint names of the controller's tables, the swivel frames, a circle's
plane)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from pydrake.systems.framework import DiagramBuilder

from nsdrake.experiment.scenario import Scenario, ScenarioError, check_against_plant
from nsdrake.realism.config import substeps
from nsdrake.station.config import StationError
from nsdrake.station.plant import Station, add_station, has_joint_limits

GRAVITY = 9.81  # [m/s²]


def gravity_vector(scenario: Scenario) -> np.ndarray:
    """World gravity: the scenario's ``gravity`` if given, else along −z for a
    horizontal arm's plane and −y for a vertical one. (3,) [m/s²]."""
    if scenario.gravity:
        return np.asarray(scenario.gravity, dtype=float)
    return (
        np.array([0.0, 0.0, -GRAVITY]) if scenario.plane == "horizontal" else np.array([0.0, -GRAVITY, 0.0])
    )


def add_scenario_station(builder: DiagramBuilder, scenario: Scenario, *, sensing: bool = True) -> Station:
    """The station of ``scenario`` (plant step: the control period over the physics rung's
    substeps; belts with the belt rung), checked against the scenario's joint and frame
    names; every problem is a one-line ScenarioError. ``sensing``: as
    :func:`nsdrake.station.plant.add_station`."""
    src = scenario.source or "scenario"
    belt = scenario.realism.belt
    try:
        station = add_station(
            builder,
            arm=scenario.arm,
            plate=scenario.plate,
            contact=scenario.contact,
            obstacles=scenario.obstacles,
            task_axes=scenario.task.axes,
            gravity=gravity_vector(scenario),
            time_step=scenario.control_period / substeps(scenario.realism),
            belt=belt if belt.enabled else None,
            base_dir=Path(scenario.base_dir) if scenario.base_dir else None,
            source=src,
            sensing=sensing,
        )
    except StationError as e:
        raise ScenarioError(str(e)) from None
    check_against_plant(scenario, station.arm_model.joint_names)
    for name in scenario.report.swivel_frames:
        if not station.plant.HasFrameNamed(name, station.arm):
            raise ScenarioError(f"{src}: report.swivel_frames: no frame '{name}' in {station.arm_file.name}")
    if scenario.reference.path == "circle" and np.linalg.norm(station.tangent) < 0.99:
        raise ScenarioError(f"{src}: plate: the plate's x axis leaves the task axes {scenario.task.axes}")
    for where, problem in check_needs_model(scenario, station):
        raise ScenarioError(f"{src}: {where}: {problem}")
    return station


def check_needs_model(scenario: Scenario, station: Station):
    """(field, problem) for what a check of report.checks needs from the arm: the pose
    check's joint margins and obstacle distances are traced only for an arm with joint
    position limits (nsdrake/experiment/simulate.py, collect_traces), as is the mode-4
    branch a required mode 4 needs. (What needs the scenario alone:
    :func:`nsdrake.experiment.scenario.check_needs`.)"""
    if has_joint_limits(station):
        return
    model = station.arm_file.name
    report = scenario.report
    if "pose" in report.checks:
        yield (
            f"report.checks[{report.checks.index('pose')}]",
            f"pose reports each joint's margin to its position limits, and {model} has no joint "
            "position limits; use fig3 for the force and position figures",
        )
    if 4 in report.required_modes:
        yield (
            f"report.required_modes[{report.required_modes.index(4)}]",
            f"mode 4 (joint-limit avoidance) needs joint position limits, and {model} has none",
        )

"""The controller side of ``nsdrake drive``: the scenario's reference and controller as
plain calls, one tick per status (no Drake diagram runs per tick).

::

    status (q, q̇, τ_ext) ─► W: the sensor's lcmt_force_torque, or (J Jᵀ)⁻¹ J τ_ext
      ─► reference.tick(t_k, W)          PlainSurfaceReference: contact update, x_d … f_d at t_k
      ─► step.step(t_k, q, q̇, W, …)      ControllerStep: the scenario's controller, τ
      ─► command = τ − g(q) (robot_adds_gravity) ─► lcmt_panda_command (the status's utime)

What the robot's torque interface is asked for is τ − g(q) in both setups (the command
when the robot adds g(q); with ``driver.robot_adds_gravity`` false the command is τ and the
driver subtracts its own g(q) before the robot adds it back, drake-franka-driver's
``--remove_gravity_compensation``, the controller model's g(q) standing for the driver's),
and Franka's limits bound that (:attr:`ControllerSide.at_robot`): the step is built with
``robot_adds_gravity`` (:class:`nsdrake.control.step.ControllerStep`), so the controller's
actuator limits act on τ − g(q), their torque window centred on g(q) (τ − g(q) within ±τ_max however much
of τ_max the gravity of the arm and a payload takes) and their rate limit's reference
moved by g's change under a moving arm (the command changes by at most ρ_max T per tick).
What is sent then passes the last gate (:func:`nsdrake.driver.panda.command_problem`, in
the loop), which catches only faults: the limiter keeps every command inside.

The controller is the one ``nsdrake run`` builds for the scenario
(:func:`nsdrake.experiment.diagram.build_controller`: its model, task, normal, wrench point
and configuration), run through :class:`nsdrake.control.step.ControllerStep`, which gives
the Diagram's τ tick by tick; the reference is the scenario's path with the same contact
detection (:class:`nsdrake.experiment.reference.PlainSurfaceReference`). Each tick's
signals are recorded into preallocated rows (:class:`Recorder`) and become the run's
traces, with the columns ``nsdrake run`` writes.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import Diagram, DiagramBuilder

from nsdrake.control.controller import NullSpaceImpedanceController
from nsdrake.control.orientation import rotation_to_quaternion
from nsdrake.control.step import ControllerStep
from nsdrake.driver.panda import (
    NUM_JOINTS,
    PandaLimitError,
    flange_load,
    panda_actuator_limits,
    panda_driver_problems,
    payload_rating_problem,
    robot_gravity_problem,
)
from nsdrake.driver.rows import Rows
from nsdrake.driver.tick import robot_torques
from nsdrake.driver.wrench import wrench_from_external_torques
from nsdrake.experiment.checks import check_with_model
from nsdrake.experiment.diagram import build_controller, surface_path
from nsdrake.experiment.reference import PlainSurfaceReference
from nsdrake.experiment.scenario import Scenario, ScenarioError
from nsdrake.experiment.scenario_station import add_scenario_station, gravity_vector
from nsdrake.station.plant import Station, desired_tool_orientation, has_joint_limits


@dataclass
class ControllerSide:
    """What :func:`build_controller_side` returns (``station``, ``controller``, ``scenario``
    and ``desired_orientation`` as :class:`nsdrake.experiment.diagram.ControlledStation`
    has them, so that the traces are collected the same way)."""

    scenario: Scenario  # with the Panda's published actuator limits filled in
    station: Station  # the scenario's station, never simulated here: the model's geometry
    station_diagram: Diagram  # the diagram holding ``station`` (a context of it for geometry queries)
    controller: NullSpaceImpedanceController  # never simulated: the step's model and configuration
    step: ControllerStep
    reference: PlainSurfaceReference
    sensor: bool  # the wrench from lcmt_force_torque messages (else estimated from τ_ext)
    desired_orientation: np.ndarray | None = None  # R_d (3, 3), for a pose task
    wrench_point: np.ndarray | None = None  # the point the measured moment is about; None: the tool

    def __post_init__(self):
        model = self.controller.model
        self._plant = model.plant
        self._context = model.plant.CreateDefaultContext()
        self._quaternion = (
            None if self.desired_orientation is None else rotation_to_quaternion(self.desired_orientation)
        )
        self._zero3 = np.zeros(3)
        self.command = np.zeros(NUM_JOINTS)
        # What the robot's torque interface is asked for on top of its own g(q): the command
        # when the robot adds g; else τ − g(q), since a driver that takes τ with g included
        # (drake-franka-driver's --remove_gravity_compensation) subtracts its g(q) before the
        # robot adds it back. The controller model's g stands for the driver's.
        self.at_robot = np.zeros(NUM_JOINTS)
        self.adds_gravity = bool(self.scenario.driver.robot_adds_gravity)

    def reset(self) -> None:
        self.step.reset()
        self.reference.reset()

    def estimated_wrench(self, q: np.ndarray, tau_ext: np.ndarray) -> np.ndarray:
        """W_T from the external joint torques (nsdrake/driver/wrench.py), J of the
        controller's own model at q."""
        plant, context = self._plant, self._context
        plant.SetPositions(context, q)
        J = plant.CalcJacobianSpatialVelocity(
            context,
            JacobianWrtVariable.kV,
            self.controller.model.arm.tool_frame,
            self._zero3,
            plant.world_frame(),
            plant.world_frame(),
        )
        return wrench_from_external_torques(J, tau_ext)

    def tick(self, t: float, q: np.ndarray, v: np.ndarray, wrench: np.ndarray):
        """The reference and the controller at t [s] for the measured q, q̇ and wrench;
        returns (the reference's (x_d, ẋ_d, ẍ_d, f_d), the step's result); the torque to
        send is in :attr:`command` (τ − g(q) when the robot adds g, g the controller model's
        own gravity term, which the step has just computed at q: :func:`robot_torques`)."""
        desired, result = self.compute(t, q, v, wrench)
        robot_torques(result.tau, self.step.gravity, self.adds_gravity, self.at_robot, self.command)
        return desired, result

    def compute(self, t: float, q: np.ndarray, v: np.ndarray, wrench: np.ndarray):
        """:meth:`tick` without the torques sent (the drive's loop has them from its
        compiled tick, nsdrake/driver/tick.py)."""
        desired = self.reference.tick(t, wrench)
        rotation = () if self._quaternion is None else (self._quaternion, self._zero3, self._zero3)
        return desired, self.step.step(t, q, v, wrench, *desired, *rotation)


def drive_scenario(scenario: Scenario, station: Station) -> Scenario:
    """``scenario`` with the Panda's published torque and torque-rate limits wherever it
    gives none (:func:`nsdrake.driver.panda.panda_actuator_limits`); one-line ScenarioError
    for limits above them, an arm that is not a 7-joint one, a payload heavier than the
    Panda is rated for (declared or not: the arm carries it either way), a gravity no robot
    on Earth has (:func:`nsdrake.driver.panda.robot_gravity_problem`), or ``driver``
    settings beyond what the Panda allows (:func:`nsdrake.driver.panda.panda_driver_problems`)."""
    for where, problem in panda_driver_problems(scenario.driver, scenario.control_period):
        raise ScenarioError(f"{scenario.source or 'scenario'}: driver.{where}: {problem}")
    problem = payload_rating_problem(scenario.arm.payload.mass, *_model_flange_load(station))
    if problem:
        raise ScenarioError(f"{scenario.source or 'scenario'}: arm.payload.mass: {problem}")
    problem = robot_gravity_problem(gravity_vector(scenario))
    if problem:
        raise ScenarioError(f"{scenario.source or 'scenario'}: gravity: {problem}")
    try:
        limits = panda_actuator_limits(
            scenario.actuator_limits, station.arm_model.joint_names, period=scenario.control_period
        )
    except PandaLimitError as e:
        raise ScenarioError(f"{scenario.source or 'scenario'}: {e}") from None
    return dataclasses.replace(scenario, actuator_limits=limits)


def _model_flange_load(station: Station) -> tuple[float, tuple[str, ...]]:
    """What the arm's model file welds beyond its flange (:func:`nsdrake.driver.panda.flange_load`),
    the scenario's own ``arm.payload`` left out (the station welds it to the tool as the arm's
    body "payload", a name the file cannot also use)."""
    plant, arm = station.plant, station.arm_model
    own = None if station.payload is None else plant.GetBodyByName("payload", station.arm)
    return flange_load(plant, plant.GetJointByName(arm.joint_names[-1], station.arm), own)


def check_drive_scenario(scenario: Scenario) -> Scenario:
    """``scenario`` as a drive runs it (:func:`drive_scenario`), or a one-line
    ScenarioError: realism rungs on, a model that is not a 7-joint arm, limits above the
    Panda's. Cheap (the station's model only): ``nsdrake sim-driver`` checks with it."""
    if scenario.realism.any:
        raise ScenarioError(
            f"{scenario.source or 'scenario'}: realism: nsdrake drive runs the controller against a robot "
            "(or the simulated driver, which models none of the realism rungs); turn them off"
        )
    builder = DiagramBuilder()
    station = add_scenario_station(builder, scenario)
    check_with_model(scenario, station)
    return drive_scenario(scenario, station)


def build_controller_side(scenario: Scenario) -> ControllerSide:
    """The controller side for ``scenario`` (module docstring); the force source and the
    gravity setting come from ``scenario.driver``. Every problem with the scenario is a
    one-line ScenarioError, before anything listens or sends."""
    if scenario.realism.any:
        raise ScenarioError(
            f"{scenario.source or 'scenario'}: realism: nsdrake drive runs the controller against a robot "
            "(or the simulated driver, which models none of the realism rungs); turn them off"
        )
    station_builder = DiagramBuilder()
    station = add_scenario_station(station_builder, scenario)
    check_with_model(scenario, station)
    station_diagram = station_builder.Build()
    scenario = drive_scenario(scenario, station)
    sensor = scenario.driver.force_source == "sensor"
    wrench_point = station.sensor.p_WSo if sensor else None
    controller = build_controller(scenario, station, wrench_point, structure="fused")
    step = ControllerStep(
        controller_model=controller.model,
        normal=controller.normal,
        config=controller.config,
        wrench_point=controller.wrench_point,
        # its limits on τ − g(q), what the robot's torque interface is asked for in both setups
        # (driver.robot_adds_gravity false: the driver subtracts its g(q) before the robot adds it)
        robot_adds_gravity=True,
    )
    path, common = surface_path(scenario, station)
    R_d = None
    if station.arm_model.m_r:
        R_d = desired_tool_orientation(station, scenario.reference.orientation)
    return ControllerSide(
        scenario=scenario,
        station=station,
        station_diagram=station_diagram,
        controller=controller,
        step=step,
        reference=PlainSurfaceReference(reference=path, **common),
        sensor=sensor,
        desired_orientation=R_d,
        wrench_point=wrench_point,
    )


class Recorder:
    """Each tick's signals in preallocated rows (no allocation per tick), and the logs
    :func:`nsdrake.experiment.simulate.collect_traces` reads (``sample_times()``, ``data()``)."""

    def __init__(self, side: ControllerSide, capacity: int):
        n, m_t = side.station.arm_model.n, side.station.arm_model.m_t
        self._n = n
        sizes = {
            "state": 2 * n, "wrench": 6, "x_d": m_t, "f_d": 1, "in_contact": 1, "tau": n, "qns": n,
            "mode": 1, "speed_scale": 1, "w": 1, "d_min": 1, "p_obstacle": 1, "en": n, "nu": 1,
            "p_tau": 1, "saturation": 2, "command": n,
        }  # fmt: skip
        if has_joint_limits(side.station):
            sizes["p_joint_limits"] = 1
        if side.scenario.report.null_space_torque:
            sizes["tau0"] = n
        self._rows = Rows(sizes, capacity)
        self.slices = self._rows.slices

    @property
    def count(self) -> int:
        """The ticks recorded."""
        return self._rows.count

    @property
    def rows(self) -> np.ndarray:
        """The rows (column 0 the time, then each signal's ``slices[name]``); the first
        :attr:`count` are recorded."""
        return self._rows.rows

    def record(self, t: float, q, v, wrench, desired, result, command, in_contact: bool) -> None:
        row, s, n = self._rows.next_row(), self.slices, self._n
        row[0] = t
        state = row[s["state"]]
        state[:n], state[n:] = q, v
        row[s["wrench"]] = wrench
        row[s["x_d"]] = desired[0]
        row[s["f_d"]] = desired[3]
        row[s["in_contact"]] = in_contact
        row[s["tau"]] = result.tau
        row[s["qns"]] = result.desired_null_space_velocity
        row[s["mode"]] = result.mode
        row[s["speed_scale"]] = result.speed_scale
        c = result.criteria  # one [Φ (n); p; s; a] row per criterion: obstacle, τ, manipulability, limits
        row[s["w"]], row[s["d_min"]], row[s["p_obstacle"]], row[s["p_tau"]] = (
            c[2, n],
            c[0, n + 1],
            c[0, n],
            c[1, n],
        )
        row[s["en"]] = result.null_space_velocity_error
        row[s["nu"]] = result.lyapunov
        row[s["saturation"]] = result.saturation
        row[s["command"]] = command
        if "p_joint_limits" in s:
            row[s["p_joint_limits"]] = c[3, n]
        if "tau0" in s:
            row[s["tau0"]] = result.null_space_torque
        self._rows.done()

    def logs(self) -> dict:
        return self._rows.logs()

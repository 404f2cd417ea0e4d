"""Running a scenario: build the diagram, simulate, gather the traces."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from pydrake.common import RandomGenerator
from pydrake.geometry import Meshcat
from pydrake.systems.analysis import Simulator, SimulatorStatus
from pydrake.systems.framework import EventStatus

from nsdrake.control.controller import torque_limits
from nsdrake.control.criteria.obstacle import ObstacleDistances
from nsdrake.control.orientation import orientation_error
from nsdrake.experiment.diagram import ControlledStation, build_diagram
from nsdrake.experiment.scenario import Scenario
from nsdrake.experiment.traces import Traces
from nsdrake.realism.wiring import add_realism_columns
from nsdrake.station.plant import has_joint_limits


class DivergenceError(RuntimeError):
    """The simulation left the bounds of a meaningful run (non-finite or out-of-bound
    state or torque) or Drake could not take a step. Carries the traces up to that
    moment and the diagram handles."""

    def __init__(self, t: float, reason: str, traces: Traces, built: ControlledStation):
        self.t, self.reason, self.traces, self.built = t, reason, traces, built
        super().__init__(f"diverged at t = {t:.4f} s: {reason}")


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) stopped the simulation. A KeyboardInterrupt, so that whoever does
    not keep the partial run still stops; carries the traces up to that moment and the
    diagram handles, as DivergenceError does."""

    def __init__(self, t: float, traces: Traces, built: ControlledStation):
        self.t, self.traces, self.built = t, traces, built
        when = f"at t = {t:.4f} s" if len(traces) else "before its first step"  # no row logged
        self.reason = f"interrupted {when} (Ctrl-C)"
        super().__init__(self.reason)


def state_problem(built: ControlledStation, limits, root_context) -> str | None:
    """Why the run at ``root_context`` is no longer meaningful, or None: the plant's state
    non-finite or a joint faster than ``limits.max_joint_speed``, or the torque the plant
    receives non-finite or beyond ``limits.max_torque`` (a torque that cannot even be
    computed is left to the caller's error)."""
    plant = built.station.plant
    n = plant.num_positions()
    state = plant.get_state_output_port().Eval(plant.GetMyContextFromRoot(root_context))
    if not np.all(np.isfinite(state)):
        return "the joint state is not finite"
    if np.max(np.abs(state[n:])) > limits.max_joint_speed:
        speed = np.max(np.abs(state[n:]))
        return f"a joint speed reached {speed:.3g} rad/s (bound {limits.max_joint_speed:g})"
    # What the plant receives: between control instants of a plant stepping finer than
    # the controller (realism.physics) it is the held torque, and reading it does not
    # evaluate the controller at every plant step.
    actuation = built.diagram.GetSubsystemByName("actuation_map")
    try:
        tau = actuation.get_output_port().Eval(actuation.GetMyContextFromRoot(root_context))
    except (RuntimeError, ValueError, ArithmeticError):
        return None
    if not np.all(np.isfinite(tau)):
        return "the commanded torque is not finite"
    if np.max(np.abs(tau)) > limits.max_torque:
        return f"a commanded torque reached {np.max(np.abs(tau)):.3g} N m (bound {limits.max_torque:g})"
    return None


def divergence_monitor(built: ControlledStation, scenario: Scenario):
    """A Simulator monitor that ends the run, with its reason, at the first step whose
    state or commanded torque is non-finite or beyond ``scenario.divergence``."""

    def monitor(root_context):
        problem = state_problem(built, scenario.divergence, root_context)
        if problem is None:
            return EventStatus.Succeeded()
        return EventStatus.ReachedTermination(built.diagram, problem)

    return monitor


def _one_line(text) -> str:
    line = " ".join(str(text).split())
    return line if len(line) <= 200 else line[:199] + "…"


def run(
    scenario: Scenario,
    *,
    null_space_task: bool = True,
    progress: Callable[[float], None] | None = None,
    meshcat: Meshcat | None = None,
    live: bool = False,
    auto_structure: str = "systems",
) -> tuple[Traces, ControlledStation]:
    """Simulates ``scenario`` for its duration; returns the traces and the diagram handles.

    ``auto_structure``: the controller's structure ("systems" or "fused") when the
    scenario's ``controller_structure`` is auto; both give the same traces.

    ``progress`` is called with the fraction done, about a hundred times per run.
    With a ``meshcat``, the run is recorded and the recording published to it
    (``visualization.write_replay`` saves it); ``live`` also sends every frame to
    the browsers watching and paces the run at real time. Neither changes the traces.
    """
    built = build_diagram(
        scenario, null_space_task=null_space_task, meshcat=meshcat, auto_structure=auto_structure
    )
    station = built.station
    simulator = Simulator(built.diagram)
    context = simulator.get_mutable_context()
    plant_context = station.plant.GetMyMutableContextFromRoot(context)
    if scenario.realism.force_sensor.enabled:  # seeds the sensor's noise (same seed, same traces)
        built.diagram.SetRandomContext(context, RandomGenerator(scenario.realism.force_sensor.seed))
    q0 = station.q0 if station.plant_q0 is None else station.plant_q0  # (elastic plants differ)
    v0 = station.v0 if station.plant_v0 is None else station.plant_v0
    station.plant.SetPositions(plant_context, q0)
    station.plant.SetVelocities(plant_context, v0)
    if built.visualizers is not None:
        built.visualizers.start_recording(live=live)
    if live:
        simulator.set_target_realtime_rate(1.0)
    simulator.set_monitor(divergence_monitor(built, scenario))
    _advance(simulator, built, scenario, progress)
    if built.visualizers is not None:
        built.visualizers.publish_recording()
    traces = collect_traces(built, context)
    if progress is not None:
        # the end reported again with the traces in hand: a Ctrl-C held back while their
        # kernels compiled (a first run compiles some here; nsdrake/ctrl_c.py) stops the run
        # now, keeping them
        try:
            progress(1.0)
        except KeyboardInterrupt:
            raise RunInterrupted(context.get_time(), traces, built) from None
    return traces, built


def _advance(simulator: Simulator, built: ControlledStation, scenario: Scenario, progress) -> None:
    """Simulates to the scenario's duration. A step the monitor stops, a step Drake or a
    system cannot take, and Ctrl-C each end the run with the traces so far (DivergenceError,
    RunInterrupted)."""
    context = simulator.get_context()
    chunks = 100 if progress is not None else 1
    try:
        simulator.Initialize()
        for k in range(1, chunks + 1):
            status = simulator.AdvanceTo(scenario.duration * k / chunks)
            if status.reason() == SimulatorStatus.ReturnReason.kReachedTerminationCondition:
                raise DivergenceError(
                    context.get_time(), status.message(), collect_traces(built, context), built
                )
            if progress is not None:
                progress(k / chunks)
    except KeyboardInterrupt:
        raise RunInterrupted(context.get_time(), collect_traces(built, context), built) from None
    except (RuntimeError, ValueError, ArithmeticError) as e:
        if isinstance(e, DivergenceError):
            raise
        # Drake failed inside a step (e.g. its contact solver) or a system raised (a linear
        # solve on a state gone non-finite, an overflow): where the state or torque explains
        # it, the monitor's words, else the error's.
        reason = state_problem(built, scenario.divergence, context) or _one_line(e)
        raise DivergenceError(context.get_time(), reason, collect_traces(built, context), built) from None


def collect_traces(built: ControlledStation, root_context, logs: dict | None = None) -> Traces:
    """The loggers' records as named columns (docs/command_line.md, "traces.csv", for the column list).

    ``logs``: the records by logger name (each with ``sample_times()`` and ``data()``),
    when the loggers do not live in ``root_context``'s diagram (``nsdrake drive``: the
    controller side's); ``root_context`` is then a context of the diagram that holds
    ``built.station``, for its geometry."""
    arm = built.station.arm_model
    n = arm.n
    logs = _complete_rows(
        logs if logs is not None else {n: g.FindLog(root_context) for n, g in built.loggers.items()}
    )
    t = logs["state"].sample_times()
    columns: dict[str, np.ndarray] = {"t": t}

    def add(prefix: str, data: np.ndarray, names):
        for i, name in enumerate(names):
            columns[f"{prefix}{name}"] = data[i]

    axes = arm.task_axes[: arm.m_t]  # the translational ones
    state = logs["state"].data()
    add("", task_positions(built, state[:n]), axes)
    add("", logs["x_d"].data(), [f"{a}_d" for a in axes])
    force = logs["wrench"].data()[3:][arm.rows]
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
    columns["in_contact"] = logs["in_contact"].data()[0]
    if "tau0" in logs:  # report.null_space_torque
        add("tau0_", logs["tau0"].data(), joints)
    columns["tau0_scale"] = logs["saturation"].data()[0]
    columns["saturated_joints"] = logs["saturation"].data()[1]
    if built.desired_orientation is not None:
        columns["rot_err"] = orientation_errors(built, state[:n])
    if has_joint_limits(built.station):
        columns["p_joint_limits"] = logs["p_joint_limits"].data()[0]
        margins = limit_margins(built, state[:n], state[n:], logs["tau"].data())
        for kind in ("q", "v", "tau"):
            add(f"{kind}_margin", margins[kind], joints)
        columns["q_margin"] = np.min(margins["q"], axis=0)
        for name, d in obstacle_distances(built, root_context, state[:n]).items():
            columns[f"d_{name}"] = d
    if built.scenario.report.swivel_frames:
        columns["swivel"] = swivel_angles(built, state[:n], built.scenario.report.swivel_frames)
    add_realism_columns(built, logs, columns)
    return Traces(columns)


def _complete_rows(found: dict) -> dict:
    """The logs cut to their last complete row: a run stopped inside a step (Ctrl-C, an
    exception) may have logged a row in some loggers and not yet in the others."""
    rows = min(len(log.sample_times()) for log in found.values())
    return {name: _Rows(log, rows) for name, log in found.items()}


class _Rows:
    """A VectorLog's first ``rows`` samples, read as the log is."""

    def __init__(self, log, rows: int):
        self._times, self._data = log.sample_times()[:rows], log.data()[:, :rows]

    def sample_times(self) -> np.ndarray:
        return self._times

    def data(self) -> np.ndarray:
        return self._data


def task_positions(built: ControlledStation, q: np.ndarray) -> np.ndarray:
    """x = p(q) (Eq. 1), the translational task axes, for each column of ``q`` (n, k). (m_t, k) [m]."""
    arm = built.station.arm_model
    plant = arm.plant
    context = plant.CreateDefaultContext()
    out = np.empty((arm.m_t, q.shape[1]))
    for k in range(q.shape[1]):
        plant.SetPositions(context, q[:, k])
        out[:, k] = arm.task_position(context)
    return out


def orientation_errors(built: ControlledStation, q: np.ndarray) -> np.ndarray:
    """rot_err: the angle between the desired tool orientation and the simulated tool's,
    ‖log(R_d R_WTᵀ)‖, for each column of ``q`` (n, k). (k,) [rad]."""
    plant, tool = built.station.plant, built.station.arm_model.tool_frame
    context = plant.CreateDefaultContext()
    R_d = np.ascontiguousarray(built.desired_orientation, dtype=float)  # the compiled kernel's types
    out = np.empty(q.shape[1])
    for k in range(q.shape[1]):
        plant.SetPositions(context, q[:, k])
        R_WT = np.ascontiguousarray(tool.CalcPoseInWorld(context).rotation().matrix())
        out[k] = np.linalg.norm(orientation_error(R_d, R_WT))
    return out


def limit_margins(built: ControlledStation, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> dict:
    """Per joint and row, how far each joint is from its limits (negative: beyond):
    q: min(q − q_min, q_max − q) [rad]; v: v_max − |q̇| [rad/s], v_max the model's velocity
    limit; tau: τ_max − |τ| [N m], τ_max the actuator limit the controller applies (the
    scenario's, else the model's effort limit). Each (n, k); inf where there is no limit."""
    plant = built.station.plant
    lower, upper = plant.GetPositionLowerLimits()[:, None], plant.GetPositionUpperLimits()[:, None]
    v_max = plant.GetVelocityUpperLimits()[:, None]
    v_max = np.where(v_max > 0, v_max, np.inf)
    tau_max = torque_limits(built.controller.config, built.controller.model)[:, None]
    return {"q": np.minimum(q - lower, upper - q), "v": v_max - np.abs(v), "tau": tau_max - np.abs(tau)}


def obstacle_distances(built: ControlledStation, root_context, q: np.ndarray) -> dict[str, np.ndarray]:
    """The smallest signed distance between the arm's moving links (not the tool, not the
    welded base) and each obstacle of the simulated station, per column of ``q`` (n, k):
    {"plate": (k,), <obstacle name>: (k,), …} [m]. From the station's own geometry, not
    the controller's model."""
    station = built.station
    plant, scene_graph = station.plant, station.scene_graph
    inspector = scene_graph.model_inspector()
    moving = moving_link_geometries(station)
    context = root_context.Clone()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    names = {}
    for g in station.obstacle_geometries:
        body = plant.GetBodyFromFrameId(inspector.GetFrameId(g))
        names[inspector.GetName(g)] = "plate" if body.model_instance() == station.plate else body.name()
    distances = ObstacleDistances(plant, moving, station.obstacle_geometries, inspector)
    out = {name: np.full(q.shape[1], np.inf) for name in dict.fromkeys(names.values())}
    for k in range(q.shape[1]):
        plant.SetPositions(plant_context, q[:, k])
        query = lambda: scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))  # noqa: E731
        for pair in distances.pairs(plant_context, -np.inf, query=query):
            column = out[names[pair.obstacle]]
            column[k] = min(column[k], pair.distance)
    return out


def moving_link_geometries(station) -> list:
    """The station's link geometries on bodies that some joint moves (the base excepted)."""
    plant, inspector = station.plant, station.scene_graph.model_inspector()
    joints = [j for j in plant.GetJointIndices() if plant.get_joint(j).num_velocities()]
    moving = {int(b) for b in plant.GetBodiesKinematicallyAffectedBy(joints)}
    return [
        g
        for g in station.link_geometries
        if int(plant.GetBodyFromFrameId(inspector.GetFrameId(g)).index()) in moving
    ]


def swivel_angles(built: ControlledStation, q: np.ndarray, frames) -> np.ndarray:
    """The elbow's swivel angle ψ about the shoulder–wrist line, per column of ``q`` (n, k),
    unwrapped. With S, E, W the origins of the three ``frames`` and a = (W − S)/‖W − S‖:
    ψ is the angle of E's offset from the line, e = (E − S) − ((E − S)·a) a, measured about
    a from the world's vertical projected off the line. While the tool holds its pose S and
    W stay put (for a shoulder fixed to the base and a wrist frame rigid with the tool), so
    ψ moves only with the self-motion. (k,) [rad]."""
    plant = built.station.plant
    context = plant.CreateDefaultContext()
    shoulder, elbow, wrist = (plant.GetFrameByName(f) for f in frames)
    out = np.empty(q.shape[1])
    for k in range(q.shape[1]):
        plant.SetPositions(context, q[:, k])
        S, E, W = (f.CalcPoseInWorld(context).translation() for f in (shoulder, elbow, wrist))
        a = (W - S) / np.linalg.norm(W - S)
        e = (E - S) - ((E - S) @ a) * a
        r0 = np.array([0.0, 0.0, 1.0]) - a[2] * a
        out[k] = np.arctan2(a @ np.cross(r0, e), r0 @ e)
    return np.unwrap(out)

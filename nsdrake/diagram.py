"""Wiring: the station and the controller stack in one Drake diagram.

::

    plant.state ─► robot_terms ─┬──────────────────────────────► impedance_controller ─┐
                                ├─► obstacle_criterion ───────┐                       │
    scene_graph.query ──────────┘   joint_torque_criterion ───┼─► priority_selector   │
                                    manipulability_criterion ─┘         │             │
                                                                        ▼             ▼
                                                        null_space_controller ─► torque_sum
    plant.reaction_forces ─► force_sensor ─┬─► reference ─► impedance_controller      │
                                           └─► impedance_controller                   ▼
                                                          plant.actuation ◄─ actuation_map

Every system is named after its role, and every signal the traces need is
logged once per control period by a ``VectorLogSink``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Adder, LogVectorOutput, MatrixGain, VectorLogSink

from .criteria.obstacle import ObstacleDistances
from .impedance import ImpedanceGains
from .plant import Station, add_station
from .priority import Criterion, SelectorLimits
from .reference import SlideAndPress
from .scenario import Scenario, ScenarioError
from .systems import (
    ContactMonitor,
    ForceSensor,
    ImpedanceController,
    JointTorqueCriterionSystem,
    ManipulabilityCriterionSystem,
    NullSpaceController,
    ObstacleCriterionSystem,
    PrioritySelector,
    RobotTermsSystem,
    SelfMotionSweep,
    SlideAndPressReference,
)
from .visualization import Visualizers, add_visualizers, visualizer_period


@dataclass
class ControlledStation:
    """What :func:`build_diagram` returns."""

    diagram: Diagram
    station: Station
    loggers: dict[str, VectorLogSink]
    scenario: Scenario
    visualizers: Visualizers | None = None  # when built with a Meshcat

    def system(self, name: str):
        return self.diagram.GetSubsystemByName(name)


def initial_task_position(station: Station) -> np.ndarray:
    """x = p(q0), the tool's task position at the initial pose. (m,) [m]."""
    context = station.plant.CreateDefaultContext()
    station.plant.SetPositions(context, station.q0)
    return station.arm_model.task_position(context)


def speed_limit_vector(scenario: Scenario, joint_names: tuple[str, ...]) -> np.ndarray:
    limits = scenario.desired_null_space.joint_speed_limits
    return np.array([limits.get(name, np.inf) for name in joint_names])


def build_diagram(
    scenario: Scenario, *, null_space_task: bool = True, meshcat: Meshcat | None = None
) -> ControlledStation:
    """The Fig. 3 diagram for ``scenario``.

    q̇_dⁿ comes from the priority selector, or from a prescribed self-motion sweep
    when the scenario says ``desired_null_space.source: sweep`` (the selector and
    criteria still run, for their traces). ``null_space_task`` False sets every
    criterion gain and the sweep to zero (q̇_dⁿ = 0): the null-space controller
    then only damps self-motion. With a ``meshcat``, the diagram also has the
    Meshcat visualizers (nsdrake/visualization.py).
    """
    builder = DiagramBuilder()
    station = add_station(builder, scenario)
    plant, arm = station.plant, station.arm_model
    n, T = arm.n, scenario.control_period
    ns = scenario.null_space
    inverse = scenario.generalized_inverse()

    robot_terms = builder.AddNamedSystem(
        "robot_terms",
        RobotTermsSystem(
            arm_model=arm, coriolis_matrix=ns.task_velocity_compensation or ns.coriolis_compensation
        ),
    )
    builder.Connect(plant.get_state_output_port(), robot_terms.get_input_port())
    model_terms = arm.terms(plant.CreateDefaultContext(), station.q0, station.v0, True)

    sensor = builder.AddNamedSystem(
        "force_sensor", ForceSensor(plant=plant, sensor_joint=station.sensor_joint)
    )
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.get_input_port())

    r = scenario.reference
    reference = builder.AddNamedSystem(
        "reference",
        SlideAndPressReference(
            reference=SlideAndPress(
                x0=initial_task_position(station),
                tangent=station.tangent,
                normal=station.normal,
                tangent_speed=r.tangent_speed,
                approach_speed=r.approach_speed,
                blend_time=r.blend_time,
                force=r.force,
                force_ramp_time=r.force_ramp_time,
                step_time=r.step_time if r.step_time > 0 else math.inf,
                step_force=r.step_force,
            ),
            task_rows=arm.rows,
            contact_threshold=r.contact_threshold,
            period=T,
        ),
    )
    builder.Connect(sensor.GetOutputPort("force"), reference.GetInputPort("measured_force"))

    imp = scenario.impedance
    impedance = builder.AddNamedSystem(
        "impedance_controller",
        ImpedanceController(
            gains=ImpedanceGains.along_surface(
                station.normal, imp.K_p_tangent, imp.K_p_normal, imp.K_v_tangent, imp.K_v_normal, imp.K_f
            ),
            task_rows=arm.rows,
            p_WSo=sensor.p_WSo,
            gravity_compensation=imp.gravity_compensation,
            model_terms=model_terms,
        ),
    )
    builder.Connect(robot_terms.GetOutputPort("robot_terms"), impedance.GetInputPort("robot_terms"))
    for name in ("x_d", "xdot_d", "xddot_d", "f_d"):
        builder.Connect(reference.GetOutputPort(name), impedance.GetInputPort(name))
    builder.Connect(sensor.GetOutputPort("wrench"), impedance.GetInputPort("measured_wrench"))

    d = scenario.desired_null_space
    crit = d.criteria
    if crit.obstacle.gain > 0 and not station.link_geometries:
        raise ScenarioError(
            f"{scenario.source or 'scenario'}: desired_null_space.criteria.obstacle.gain: the arm has no "
            "link collision geometry to keep away from obstacles (set the gain to 0)"
        )
    terms_port = robot_terms.GetOutputPort("robot_terms")
    joint_torque = builder.AddNamedSystem(
        "joint_torque_criterion",
        JointTorqueCriterionSystem(F_d=r.force * station.normal, model_terms=model_terms),
    )
    manipulability = builder.AddNamedSystem(
        "manipulability_criterion", ManipulabilityCriterionSystem(model_terms=model_terms)
    )
    obstacle = builder.AddNamedSystem(
        "obstacle_criterion",
        ObstacleCriterionSystem(
            distances=ObstacleDistances(
                plant,
                station.link_geometries,
                station.obstacle_geometries,
                station.scene_graph.model_inspector(),
            ),
            influence_distance=crit.obstacle.influence_distance,
            model_terms=model_terms,
        ),
    )
    builder.Connect(station.scene_graph.get_query_output_port(), obstacle.GetInputPort("geometry_query"))
    criteria = {
        Criterion.obstacle: (obstacle, crit.obstacle.gain),
        Criterion.joint_torque: (joint_torque, crit.joint_torque.gain),
        Criterion.manipulability: (manipulability, crit.manipulability.gain),
    }
    sel = d.selector
    selector = builder.AddNamedSystem(
        "priority_selector",
        PrioritySelector(
            inverse=inverse,
            gains={c: (gain if null_space_task else 0.0) for c, (_, gain) in criteria.items()},
            limits=SelectorLimits(d_lim=sel.d_lim, w_lim=sel.w_lim, d_band=sel.d_band, w_band=sel.w_band),
            blend_time=sel.blend_time,
            rotate_gradient=d.rotate_gradient,
            speed_limits=speed_limit_vector(scenario, arm.joint_names),
            speed_headroom=d.speed_headroom,
            period=T,
            model_terms=model_terms,
        ),
    )
    builder.Connect(terms_port, selector.GetInputPort("robot_terms"))
    for c, (system, _) in criteria.items():
        builder.Connect(terms_port, system.GetInputPort("robot_terms"))
        builder.Connect(system.GetOutputPort("gradient"), selector.GetInputPort(f"{c.value}_gradient"))
    builder.Connect(obstacle.GetOutputPort("d_min"), selector.GetInputPort("d_min"))
    builder.Connect(manipulability.GetOutputPort("value"), selector.GetInputPort("manipulability"))
    builder.Connect(obstacle.GetOutputPort("activation"), selector.GetInputPort("obstacle_activation"))

    null_space = builder.AddNamedSystem(
        "null_space_controller",
        NullSpaceController(
            inverse=inverse,
            K_n=ns.K_n,
            period=T,
            task_velocity_compensation=ns.task_velocity_compensation,
            coriolis_compensation=ns.coriolis_compensation,
            acceleration_feedforward=ns.acceleration_feedforward,
            model_terms=model_terms,
        ),
    )
    builder.Connect(robot_terms.GetOutputPort("robot_terms"), null_space.GetInputPort("robot_terms"))
    command = selector.GetOutputPort("desired_null_space_velocity")
    if d.source == "sweep":
        sw = d.sweep
        sweep = builder.AddNamedSystem(
            "self_motion_sweep",
            SelfMotionSweep(
                inverse=inverse,
                direction=np.array([sw.direction.get(j, 0.0) for j in arm.joint_names]),
                amplitude=sw.amplitude if null_space_task else 0.0,
                frequency=sw.frequency,
                start_time=sw.start_time,
                ramp_time=sw.ramp_time,
                model_terms=model_terms,
            ),
        )
        builder.Connect(terms_port, sweep.get_input_port())
        command = sweep.get_output_port()
    builder.Connect(command, null_space.GetInputPort("desired_null_space_velocity"))

    torque_sum = builder.AddNamedSystem("torque_sum", Adder(2, n))
    builder.Connect(impedance.get_output_port(), torque_sum.get_input_port(0))
    builder.Connect(null_space.GetOutputPort("generalized_force"), torque_sum.get_input_port(1))
    # τ = B u with B the plant's actuation matrix (a permutation here): u = Bᵀ τ.
    actuation = builder.AddNamedSystem("actuation_map", MatrixGain(plant.MakeActuationMatrix().T))
    builder.Connect(torque_sum.get_output_port(), actuation.get_input_port())
    builder.Connect(actuation.get_output_port(), plant.get_actuation_input_port())

    tool_body = arm.tool_frame.body().index()
    monitor = builder.AddNamedSystem(
        "contact_monitor",
        ContactMonitor(
            plant=plant,
            watched={*plant.GetBodyIndices(station.plate), *(b.index() for b in station.obstacle_bodies)},
            allowed={tool_body},
        ),
    )
    builder.Connect(plant.get_contact_results_output_port(), monitor.get_input_port())

    signals = {
        "x_d": reference.GetOutputPort("x_d"),
        "f": sensor.GetOutputPort("force"),
        "f_d": reference.GetOutputPort("f_d"),
        "state": plant.get_state_output_port(),
        "tau": torque_sum.get_output_port(),
        "qns": command,
        "mode": selector.GetOutputPort("mode"),
        "speed_scale": selector.GetOutputPort("speed_scale"),
        "w": manipulability.GetOutputPort("value"),
        "d_min": obstacle.GetOutputPort("d_min"),
        "p_obstacle": obstacle.GetOutputPort("value"),
        "en": null_space.GetOutputPort("null_space_velocity_error"),
        "nu": null_space.GetOutputPort("lyapunov"),
        "p_tau": joint_torque.GetOutputPort("value"),
        "forbidden_contacts": monitor.get_output_port(),
    }
    loggers = {}
    for name, port in signals.items():
        logger = LogVectorOutput(port, builder, publish_period=T)
        logger.set_name(f"log_{name}")
        loggers[name] = logger
    visualizers = None
    if meshcat is not None:
        visualizers = add_visualizers(builder, station, meshcat, period=visualizer_period(T))
    diagram = builder.Build()
    diagram.set_name("nsdrake")
    return ControlledStation(
        diagram=diagram, station=station, loggers=loggers, scenario=scenario, visualizers=visualizers
    )

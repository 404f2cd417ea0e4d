"""Wiring of the realism ladder (:mod:`nsdrake.realism.config`) into the fig3 diagram.

With any rung on, :func:`plug_realism` plugs the rungs into the station's ports
(:class:`nsdrake.station.plant.StationPorts`) before the controller is connected to them::

    plant ─state─► [motor encoders: θ_m, θ̇_m (belt)] ─────────────► controller.estimated_state
    force_sensor ─► [bias + noise → sample → low-pass (force_sensor)] ─► controller.measured_wrench
    controller.generalized_force ─► [control_hold: sample, hold, delay] ─► actuation_map ─► plant
    plant ─state─► [joint_friction (friction)] ─► plant.applied_generalized_force

Every rung left off leaves its box out. The extra loggers give the traces the true
contact force beside the measured one (``f_n_true``), the applied torque
(``tau_applied*``) and, with the belt, the motor side (``qm*``, ``vm*``).
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.common import RandomDistribution
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import (
    Adder,
    ConstantVectorSource,
    FirstOrderLowPassFilter,
    LogVectorOutput,
    MatrixGain,
    RandomSource,
    ZeroOrderHold,
)

from nsdrake.realism.config import ForceSensorConfig, FrictionConfig, RealismConfig
from nsdrake.station.control_hold import ControlHold
from nsdrake.station.joint_friction import JointFriction


class ForceSensorModel(Diagram):
    """The six-axis sensor's signal chain (:class:`nsdrake.realism.config.ForceSensorConfig`)::

        measured = LPF( ZOH_Ts( W + b + Σ w ) )

    W the true wrench [M_So; f] (world), b the bias (given in the sensor frame,
    rotated to the world), w unit white Gaussian noise drawn every T_s (Drake's
    ``RandomSource``, seeded through the context's random generator), Σ the
    diagonal of standard deviations, ZOH_Ts the sensor's own sampling, LPF a
    first-order low-pass filter of cutoff f_c (τ = 1/(2π f_c)).

    .. pydrake_system::

        name: ForceSensorModel
        input_ports:
        - true_wrench
        output_ports:
        - wrench
        - force

    ``true_wrench`` and ``wrench`` are [M; f] (6) [N m, N], world; ``force`` (3) [N]
    is f of ``wrench``.
    """

    def __init__(self, *, config: ForceSensorConfig, R_WS: np.ndarray):
        super().__init__()
        builder = DiagramBuilder()
        Ts = config.sample_period
        noise = builder.AddNamedSystem("noise", RandomSource(RandomDistribution.kGaussian, 6, Ts))
        sigma = np.array([config.noise_moment] * 3 + [config.noise_force] * 3)
        scale = builder.AddNamedSystem("noise_sigma", MatrixGain(np.diag(sigma)))
        builder.Connect(noise.get_output_port(), scale.get_input_port())
        self.bias_W = np.concatenate([R_WS @ config.bias_moment, R_WS @ config.bias_force])
        bias = builder.AddNamedSystem("bias", ConstantVectorSource(self.bias_W))
        total = builder.AddNamedSystem("sum", Adder(3, 6))
        builder.Connect(scale.get_output_port(), total.get_input_port(1))
        builder.Connect(bias.get_output_port(), total.get_input_port(2))
        sample = builder.AddNamedSystem("sample", ZeroOrderHold(Ts, 6))
        builder.Connect(total.get_output_port(), sample.get_input_port())
        out = sample.get_output_port()
        if config.filter_cutoff > 0:
            lowpass = builder.AddNamedSystem(
                "low_pass", FirstOrderLowPassFilter(1.0 / (2.0 * math.pi * config.filter_cutoff), 6)
            )
            builder.Connect(out, lowpass.get_input_port())
            out = lowpass.get_output_port()
        force = builder.AddNamedSystem("force_of_wrench", MatrixGain(np.eye(6)[3:]))
        builder.Connect(out, force.get_input_port())
        builder.ExportInput(total.get_input_port(0), "true_wrench")
        builder.ExportOutput(out, "wrench")
        builder.ExportOutput(force.get_output_port(), "force")
        builder.BuildInto(self)


def plug_realism(builder, station, realism: RealismConfig, control_period: float) -> None:
    """Plugs the rungs that are on into the station's ports (module docstring), so that
    a controller connected to ``station.ports`` afterwards reads the modelled sensor and
    drives the plant through the hold (and delay), with friction in the joints."""
    ports = station.ports
    if realism.force_sensor.enabled:  # the measured sensor (noise, bias, sampling, filter)
        plant = station.plant
        R_WS = station.sensor_joint.frame_on_child().CalcPoseInWorld(plant.CreateDefaultContext()).rotation()
        model = builder.AddSystem(ForceSensorModel(config=realism.force_sensor, R_WS=R_WS.matrix()))
        model.set_name("force_sensor_model")
        builder.Connect(ports.true_wrench, model.GetInputPort("true_wrench"))
        ports.wrench = model.GetOutputPort("wrench")
    # Always held: with one plant step per period and no delay the hold passes the
    # torque through at every plant step, and it keeps the controller from being
    # evaluated at the events in between (finer plant steps, the sensor's samples).
    delay = realism.delay.periods if realism.delay.enabled else 0
    hold = builder.AddNamedSystem(
        "control_hold", ControlHold(size=station.arm_model.n, period=control_period, delay_periods=delay)
    )
    builder.Connect(hold.get_output_port(), ports.actuation)
    ports.actuation = hold.get_input_port()
    if realism.friction.enabled:
        _add_friction(builder, station, realism.friction)


def _add_friction(builder, station, f: FrictionConfig) -> None:
    plant = station.plant
    if station.elastic is not None:  # in the gears: on the motor side of the belt
        dofs = station.elastic.motor_v
    else:
        dofs = [j.velocity_start() for j in station.arm_model.joints]
    friction = builder.AddNamedSystem(
        "joint_friction",
        JointFriction(
            nq=plant.num_positions(),
            nv=plant.num_velocities(),
            dofs=dofs,
            coulomb=f.coulomb,
            viscous=f.viscous,
            smoothing_speed=f.smoothing_speed,
        ),
    )
    builder.Connect(plant.get_state_output_port(), friction.get_input_port())
    builder.Connect(friction.get_output_port(), plant.get_applied_generalized_force_input_port())


def add_realism_loggers(builder, station, period: float) -> dict:
    """Loggers of the true force, the applied torque and the motor side (belt)."""
    ports = {
        "f_true": station.sensor.GetOutputPort("force"),
        "tau_applied": builder.GetSubsystemByName("actuation_map").get_output_port(),
    }
    if station.elastic is not None:
        ports["motor_state"] = builder.GetSubsystemByName("motor_encoders").get_output_port()
    loggers = {}
    for name, port in ports.items():
        logger = LogVectorOutput(port, builder, publish_period=period)
        logger.set_name(f"log_{name}")
        loggers[name] = logger
    return loggers


def add_realism_columns(built, logs: dict, columns: dict) -> None:
    """The realism loggers' columns, when the diagram has them: ``f_n_true`` [N], the
    normal contact force the ideal sensor reads; ``tau_applied1…`` [N m], the torque
    the plant received at each control instant (actuator order); ``qm1…``, ``vm1…``
    [rad, rad/s], the motor side θ_m, θ̇_m (belt)."""
    if "f_true" not in logs:
        return
    arm = built.station.arm_model
    columns["f_n_true"] = built.station.normal @ logs["f_true"].data()[arm.rows]
    for i, row in enumerate(logs["tau_applied"].data()):
        columns[f"tau_applied{i + 1}"] = row
    if "motor_state" in logs:
        data = logs["motor_state"].data()
        for i in range(arm.n):
            columns[f"qm{i + 1}"] = data[i]
            columns[f"vm{i + 1}"] = data[arm.n + i]

"""The controller's configuration: one typed dataclass tree, read from YAML by
the scenario loader and passed to :class:`nsdrake.NullSpaceImpedanceController`.
What each field must be is checked by :mod:`nsdrake.control.validation`.

(No ``from __future__ import annotations`` here: Drake's ``yaml_load_typed``
reads the dataclass field types at run time.) Every field names its unit.
"""

from dataclasses import dataclass, field

from nsdrake.control.validation import NULL_SPACE_SOURCES, validate_config  # noqa: F401 (re-exported)


@dataclass
class ImpedanceConfig:
    """Gains of the primary task law, Eqs. 6–8 (acceleration units: the law multiplies by Λ)."""

    # Position gain along the plate [1/s²].
    K_p_tangent: float = 400.0
    # Velocity gain along the plate [1/s].
    K_v_tangent: float = 40.0
    # Position gain normal to the plate [1/s²].
    K_p_normal: float = 100.0
    # Velocity gain normal to the plate [1/s].
    K_v_normal: float = 200.0
    # Force gain normal to the plate [m/(s² N)].
    K_f: float = 1.0
    # Rotational stiffness k_p,r on the orientation error log(R_d R_WTᵀ), for pose tasks [1/s²].
    K_p_rotation: float = 400.0
    # Rotational damping k_v,r on the angular-velocity error, for pose tasks [1/s].
    K_v_rotation: float = 40.0
    # Add the gravity torques g of Eq. 7 (needed in the vertical plane) [-].
    gravity_compensation: bool = True
    # Largest translational task inertia Λ the law may use: near a singular pose
    # Λ = (J H⁻¹ Jᵀ)⁻¹ grows without bound, and above this cap it is damped
    # (nsdrake.control.dynamics.task_inertia, judged in a dimensionless form with the
    # rotational cap below); below it the law is exactly the paper's. inf turns the
    # treatment off for the translational rows [kg].
    max_task_inertia: float = 50.0
    # The same for the rotational rows of a pose task [kg m²].
    max_task_rotational_inertia: float = 50.0


@dataclass
class NullSpaceConfig:
    """The null-space velocity controller, Eq. 21."""

    # Null-space velocity gain K_n (a scalar: Eq. 24 needs K_n H positive definite) [1/s].
    K_n: float = 40.0
    # Generalised inverse: dynamically_consistent (Eq. 13), moore_penrose, damped_least_squares [-].
    pseudo_inverse: str = "dynamically_consistent"
    # Damping λ of the damped least-squares inverse [m]; 0 for the others.
    damping: float = 0.0
    # Task-velocity compensation (J̄̇ J + J̄ J̇) q̇ of Eq. 21 [-].
    task_velocity_compensation: bool = True
    # Coriolis compensation H⁻¹ C eⁿ of Eq. 21 [-].
    coriolis_compensation: bool = True
    # Feed forward q̈_dⁿ, the backward difference of q̇_dⁿ over one control period [-].
    acceleration_feedforward: bool = True
    # The null-space law (nsdrake.control.null_space_laws): paper (Eq. 21, the velocity law
    # above), kinematic_posture_pd ((I − Jᵀ(Jᵀ)⁺_λ)(K_ns(q_d − q) − D_ns q̇)),
    # dynamically_consistent_posture_pd ((I − Jᵀ J̄ᵀ) H (K_ns(q_d − q) − D_ns q̇)) or
    # dynamically_consistent_torque_pd ((I − Jᵀ J̄ᵀ)(K_ns(q_d − q) − D_ns q̇)); the posture
    # laws take q_d from desired_null_space.posture and ignore q̇_dⁿ [-].
    law: str = "paper"
    # K_ns of the posture laws: [N m/rad] for kinematic_posture_pd and
    # dynamically_consistent_torque_pd (a joint stiffness), [1/s²] for
    # dynamically_consistent_posture_pd (multiplied by H); 0 with the paper's law.
    posture_stiffness: float = 0.0
    # D_ns of the posture laws: [N m s/rad] (kinematic_posture_pd, dynamically_consistent_torque_pd;
    # the Cartesian impedance examples use 2√K_ns), [1/s] (dynamically_consistent_posture_pd);
    # 0 with the paper's law.
    posture_damping: float = 0.0
    # λ of kinematic_posture_pd's damped inverse (Jᵀ)⁺_λ = (J Jᵀ + λ² I)⁻¹ J; 0: the
    # Moore–Penrose inverse; franka_ros's example uses 0.2 [-, J's units]. 0 for the other laws.
    projector_damping: float = 0.0


@dataclass
class ObstacleCriterionConfig:
    """Obstacle avoidance, Eq. 31 (nsdrake/control/criteria/obstacle.py): p = −⅓ Σ max(0, d_∞ − d)³."""

    # Step gain K of Eq. 30; >= 0, a positive gain pushes the links away [rad/s per m³/(kg m²)].
    gain: float = 0.0
    # Influence distance d_∞: links farther than this from every obstacle feel nothing [m].
    influence_distance: float = 0.1


@dataclass
class JointTorqueCriterionConfig:
    """Joint torque due to the desired end-effector force, Eqs. 32–33: p = ‖Jᵀ F_d‖²."""

    # Step gain K of Eq. 30; <= 0, a negative gain minimises p [rad/s per N² m²/(kg m²)].
    gain: float = 0.0


@dataclass
class ManipulabilityCriterionConfig:
    """Manipulability (Yoshikawa): w = √det(J Jᵀ)."""

    # Step gain K of Eq. 30; >= 0, a positive gain maximises w [rad/s per m²/(kg m²)].
    gain: float = 0.0


@dataclass
class JointLimitsCriterionConfig:
    """Joint-limit avoidance (nsdrake/control/criteria/joint_limits.py): p = −⅓ Σ max(0, ρ − margin)³,
    the limits read from the controller's model."""

    # Step gain K of Eq. 30; >= 0, a positive gain pushes the joints away from their limits
    # [rad/s per rad³/(kg m²)].
    gain: float = 0.0
    # Influence distance ρ: joints farther than this from both limits feel nothing [rad].
    influence: float = 0.3


@dataclass
class CriteriaConfig:
    """The criteria of Section 3.5, and joint limits. A zero gain keeps a criterion in the
    hierarchy with no effect."""

    obstacle: ObstacleCriterionConfig = field(default_factory=ObstacleCriterionConfig)
    joint_torque: JointTorqueCriterionConfig = field(default_factory=JointTorqueCriterionConfig)
    manipulability: ManipulabilityCriterionConfig = field(default_factory=ManipulabilityCriterionConfig)
    joint_limits: JointLimitsCriterionConfig = field(default_factory=JointLimitsCriterionConfig)


@dataclass
class SelectorConfig:
    """Fig. 1's decision tree (nsdrake/control/priority.py)."""

    # A link closer than this to an obstacle puts obstacle avoidance on level 2 [m].
    d_lim: float = 0.05
    # Hysteresis: obstacle avoidance leaves level 2 only beyond d_lim + d_band [m].
    d_band: float = 0.01
    # Manipulability below this puts its maximisation on level 2 (above: joint torque) [m²].
    w_lim: float = 0.01
    # Hysteresis: manipulability leaves level 2 only above w_lim + w_band [m²].
    w_band: float = 0.005
    # A joint closer than this to one of its limits puts joint-limit avoidance on level 2
    # (checked after the obstacle); 0 turns the branch off [rad].
    q_lim: float = 0.0
    # Hysteresis: joint-limit avoidance leaves level 2 only beyond q_lim + q_band [rad].
    q_band: float = 0.0
    # After a switch, q̇_dⁿ blends from the old ordering to the new over this time [s].
    blend_time: float = 0.2


@dataclass
class SweepConfig:
    """A prescribed self-motion: q̇_dⁿ = a(t) N d / ‖N d‖, d a fixed joint-space direction."""

    # Direction d, keyed by joint name (missing joints 0) [-].
    direction: dict[str, float] = field(default_factory=dict)
    # Amplitude of the commanded null-space speed ‖q̇_dⁿ‖ [rad/s].
    amplitude: float = 0.5
    # Frequency of a(t) = amplitude sin(2π f (t − start)); 0 holds a constant speed [Hz].
    frequency: float = 1.0
    # Time the sweep starts [s].
    start_time: float = 0.0
    # a(t) rises from 0 with a smoothstep over this time [s].
    ramp_time: float = 0.2


@dataclass
class PostureConfig:
    """A desired posture q_d: the posture laws' target, and for the paper's law (source:
    posture) the criterion p = ½ (q − q_d)ᵀ W (q − q_d) through Eq. 30
    (nsdrake/control/criteria/posture.py)."""

    # q_d keyed by joint name; every joint of the arm when used [rad].
    q_d: dict[str, float] = field(default_factory=dict)
    # W = diag(w) keyed by joint name, missing joints 1 [-].
    weight: dict[str, float] = field(default_factory=dict)
    # Step gain K of Eq. 30 (source: posture); <= 0, a negative gain minimises p
    # [kg m²/s with J̄, whose step rotates Φ by H⁻¹; 1/s with the other inverses].
    gain: float = 0.0
    # An offset Δq added to q_d from offset_time, keyed by joint name (missing joints 0) [rad].
    offset: dict[str, float] = field(default_factory=dict)
    # Time the offset starts [s].
    offset_time: float = 0.0
    # The offset rises with a smoothstep over this time; 0 is a step [s].
    offset_ramp_time: float = 0.0


@dataclass
class DesiredNullSpaceConfig:
    """The desired null-space velocity q̇_dⁿ by gradient projection (Eqs. 28–30), prioritised."""

    # Where q̇_dⁿ comes from: criteria (Fig. 1's priority selector), sweep (a prescribed
    # self-motion, for the experiments of nsdrake compare) or posture (Eq. 30 on the
    # posture criterion of `posture`) [-].
    source: str = "criteria"
    sweep: SweepConfig = field(default_factory=SweepConfig)
    posture: PostureConfig = field(default_factory=PostureConfig)
    # Rotate each gradient by H⁻¹ before projecting (Eq. 30); false gives Eq. 28's form [-].
    rotate_gradient: bool = True
    criteria: CriteriaConfig = field(default_factory=CriteriaConfig)
    selector: SelectorConfig = field(default_factory=SelectorConfig)
    # Largest joint speed, keyed by joint name: q̇_dⁿ is scaled, keeping its direction, so
    # that no joint's commanded speed (task part plus q̇_dⁿ) exceeds it. Missing joints take
    # the model's velocity limit (URDF <limit velocity>; unlimited if it has none) [rad/s].
    joint_speed_limits: dict[str, float] = field(default_factory=dict)
    # Fraction of each speed limit kept free for the null-space tracking error: commands
    # stay within (1 − headroom) × limit, so the measured speeds stay within the limit [-].
    speed_headroom: float = 0.05


@dataclass
class ActuatorLimitsConfig:
    """Drive limits, enforced with the primary task first (nsdrake/control/actuator_limits.py)."""

    # Largest |τ| per joint, keyed by joint name; missing joints take the model's actuator
    # effort limit (URDF <limit effort>), unlimited if it has none [N m].
    torque: dict[str, float] = field(default_factory=dict)
    # Largest |dτ/dt| per joint, keyed by joint name; missing joints are unlimited [N m/s].
    torque_rate: dict[str, float] = field(default_factory=dict)


@dataclass
class ControllerConfig:
    """Everything :class:`nsdrake.NullSpaceImpedanceController` needs besides its model
    and task: gains, the pseudo-inverse, the compensation switches, the criteria, the
    selector's limits and the joint-speed limits."""

    # Control period T: the controller is sampled every T (q̈_dⁿ, the selector) [s].
    period: float = 0.002
    impedance: ImpedanceConfig = field(default_factory=ImpedanceConfig)
    null_space: NullSpaceConfig = field(default_factory=NullSpaceConfig)
    desired_null_space: DesiredNullSpaceConfig = field(default_factory=DesiredNullSpaceConfig)
    actuator_limits: ActuatorLimitsConfig = field(default_factory=ActuatorLimitsConfig)
    # Magnitude of the desired contact force F_d = f n that the joint-torque criterion
    # (Eq. 32) optimises for, before contact too [N].
    nominal_force: float = 10.0

    def __post_init__(self):
        """Every field is checked as it is made (nsdrake.control.validation: the rules
        the scenario reader applies too); ControllerConfigError names the first that is
        wrong. The controller checks again when it is built, so a field changed after
        this (``config.impedance.K_f = …``) is checked too."""
        validate_config(self, "ControllerConfig")

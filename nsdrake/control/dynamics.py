"""The terms of the equation of motion (Eq. 5) and of the task kinematics (Eqs. 1–2).

    τ = H q̈ + C q̇ + g + Jᵀ F                                         (Eq. 5)

:class:`RobotTerms` holds, for one state (q, q̇), every model quantity the
controllers and criteria use, so that a diagram evaluates the plant once per
control period and the math downstream is plain numpy. :class:`ArmModel`
computes it from a Drake ``MultibodyPlant``:

- H, C q̇ and g come from ``CalcMassMatrix``, ``CalcBiasTerm`` and
  ``CalcGravityGeneralizedForces`` (Drake's τ_g is the gravity *force*, so
  g = −τ_g).
- C itself, when asked for, is the Coriolis matrix built from the Christoffel
  symbols, the one for which Ḣ − 2C is skew-symmetric (used by Eq. 24). Drake
  gives b(q, v) = C(q, v) v, a quadratic form in v whose polarisation is
  C(q, v) e, so column j is C e_j = (b(q, v + s e_j) − b(q, v − s e_j)) / (4 s)
  for any s > 0 (b is quadratic in v). Then Ḣ = C + Cᵀ.
- J is the spatial Jacobian of the tool point T in the world, restricted to the
  task axes: the rows of its translational part J_v (velocity of T) for the
  translational axes ``x``, ``y``, ``z``, then the rows of its angular part J_w
  (angular velocity of the tool) for the rotational axes ``rx``, ``ry``, ``rz``.
  So ẋ = J q̇ = [v_T; ω] on those axes: m = 3 for a position task, 6 for a full
  pose. ∂J/∂q_k is analytic for revolute and prismatic joints: with w_k the axis
  of a revolute joint (column k of J_w) and J_v,i, J_w,i the i-th columns,
      ∂J_v,i/∂q_k = w_k × J_v,i   if joint k is joint i or inboard of it (k revolute),
      ∂J_v,i/∂q_k = w_i × J_v,k   if joint k is outboard of joint i (i revolute),
      ∂J_w,i/∂q_k = w_k × J_w,i   if joint k is joint i or inboard of it (k revolute),
  and zero otherwise (an axis moves only with the joints inboard of it; a
  prismatic joint's J_w column is zero). J̇ = Σ_k ∂J/∂q_k q̇_k, and J̇ q̇ follows;
  for the rotational rows J̇ q̇ is the angular part of the tool's spatial
  acceleration bias, ω̇ − J_w q̈.

Nothing here assumes four joints or a planar task: n comes from the plant and m
from the task axes. The tool's orientation R_WT is part of the terms whenever the
task has rotational axes (the pose error of :mod:`nsdrake.control.orientation` needs it).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numba import njit
from pydrake.math import inv  # Eigen's: a third of numpy's cost on small matrices
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, JacobianWrtVariable
from pydrake.systems.framework import Context

AXIS_NAMES = ("x", "y", "z")  # translational task axes: rows of J_v
ROTATION_AXIS_NAMES = ("rx", "ry", "rz")  # rotational task axes: rows of J_w


def parse_task_axes(task_axes: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """(rows, rot_rows): the world axes (0, 1, 2) of the translational and of the
    rotational task axes. Axes must be distinct names among x, y, z, rx, ry, rz, the
    translational ones first; ValueError (one line) otherwise."""
    axes = list(task_axes)
    valid = AXIS_NAMES + ROTATION_AXIS_NAMES
    bad = [a for a in axes if a not in valid]
    if bad or len(set(axes)) != len(axes) or not axes:
        raise ValueError(f"task axes must be distinct names among {valid}, got {axes}")
    kinds = [a in ROTATION_AXIS_NAMES for a in axes]
    if kinds != sorted(kinds):
        raise ValueError(f"task axes: the translational axes come before the rotational ones, got {axes}")
    rows = np.array([AXIS_NAMES.index(a) for a in axes if a in AXIS_NAMES], dtype=int)
    rot_rows = np.array([ROTATION_AXIS_NAMES.index(a) for a in axes if a in ROTATION_AXIS_NAMES], dtype=int)
    return rows, rot_rows


@dataclass(frozen=True)
class RobotTerms:
    """Model terms at one state; see the module docstring. n joints, m task axes.

    The derived quantities J̇, J̇ q̇, ẋ and H⁻¹ Jᵀ are computed at construction, in one
    compiled call, Λ on first use, so every consumer of the same RobotTerms shares one evaluation;
    :meth:`memo` keeps further ones (the generalised inverses).
    """

    q: np.ndarray  # (n,) joint positions [rad]
    v: np.ndarray  # (n,) joint velocities q̇ [rad/s]
    H: np.ndarray  # (n, n) joint-space inertia, plus the joints' damping T_D D (ArmModel) [kg m²]
    H_inv: np.ndarray  # (n, n) its inverse
    Cv: np.ndarray  # (n,) Coriolis and centrifugal torques C q̇, plus the joints' damping D q̇ [N m]
    g: np.ndarray  # (n,) gravity torques of Eq. 5 [N m]
    x: np.ndarray  # (m_t,) task position of the tool point on the translational axes [m]
    p_WT: np.ndarray  # (3,) tool point T in the world [m]
    J: np.ndarray  # (m, n) task Jacobian: translational rows [m/rad], then rotational rows [rad/rad]
    J_spatial: np.ndarray  # (6, n) [angular; translational] Jacobian of T in the world
    dJ_dq: np.ndarray  # (n, m, n) dJ_dq[k] = ∂J/∂q_k [m/rad²]
    C: np.ndarray | None = None  # (n, n) Christoffel Coriolis matrix [N m s], if computed
    R_WT: np.ndarray | None = None  # (3, 3) tool orientation in the world, for tasks with rotational axes
    # Cap on the task inertia Λ near singular poses (see Lambda) [kg; kg m² for rotations].
    max_task_inertia: float = math.inf
    _memo: dict = field(default_factory=dict, repr=False, compare=False)
    # Derived at construction, in one compiled call (:func:`derived_terms`):
    Jdot: np.ndarray = field(init=False, repr=False, compare=False)  # (m, n) J̇ = Σ_k ∂J/∂q_k q̇_k
    Jdot_v: np.ndarray = field(init=False, repr=False, compare=False)  # (m,) J̇ q̇ [m/s², rad/s²]
    xdot: np.ndarray = field(init=False, repr=False, compare=False)  # (m,) ẋ = J q̇ (Eq. 2)
    H_inv_Jt: np.ndarray = field(init=False, repr=False, compare=False)  # (n, m) H⁻¹ Jᵀ

    def __post_init__(self):
        # H⁻¹ C-contiguous, as the stages pass it: one compiled version (nsdrake.control.kernels)
        derived = derived_terms(np.ascontiguousarray(self.H_inv), self.J, self.dJ_dq, self.v)
        for name, value in zip(("Jdot", "Jdot_v", "xdot", "H_inv_Jt"), derived, strict=True):
            object.__setattr__(self, name, value)

    @cached_property
    def Lambda(self) -> np.ndarray:
        """Λ = (J H⁻¹ Jᵀ)⁻¹, the operational-space inertia (Section 3.1), made robust near
        singular poses (:func:`task_inertia`); on first use, as it does not exist at an
        exactly singular pose without a cap. (m, m) [kg; kg m² on rotational rows]."""
        return task_inertia(self.J @ self.H_inv_Jt, 1.0 / self.max_task_inertia)

    @property
    def n(self) -> int:
        return self.q.shape[0]

    @property
    def m(self) -> int:
        return self.J.shape[0]

    def memo(self, key, compute: Callable[[], object]):
        """``compute()``, evaluated once per RobotTerms and ``key``."""
        try:
            return self._memo[key]
        except KeyError:
            value = self._memo[key] = compute()
            return value

    @property
    def Hdot(self) -> np.ndarray:
        """Ḣ = C + Cᵀ (needs C). (n, n)."""
        if self.C is None:
            raise ValueError("Ḣ needs the Coriolis matrix C; compute the terms with coriolis=True")
        return self.C + self.C.T


@njit(cache=True)
def derived_terms(H_inv, J, dJ_dq, v):
    """(J̇, J̇ q̇, ẋ, H⁻¹ Jᵀ) at one state (:class:`RobotTerms`): J̇ = Σ_k ∂J/∂q_k q̇_k and
    ẋ = J q̇ (Eq. 2)."""
    n, m = J.shape[1], J.shape[0]
    Jdot = (v @ np.ascontiguousarray(dJ_dq).reshape(n, m * n)).reshape(m, n)
    return Jdot, Jdot @ v, J @ v, H_inv @ np.ascontiguousarray(J.T)


@njit(cache=True)
def task_inertia(A: np.ndarray, floor: float, rotational_floor: float = -1.0, m_t: int = -1) -> np.ndarray:
    """Λ = (A + δ² F)⁻¹ for A = J H⁻¹ Jᵀ, each part of the task capped in its own unit:
    F = diag(f), f = ``floor`` = 1 / the largest translational task inertia allowed [1/kg]
    on the first ``m_t`` rows and ``rotational_floor`` = 1 / the largest rotational one
    [1/(kg m²)] on the others (-1: the same as ``floor``; ``m_t`` -1: every row
    translational). The cap is judged on the dimensionless Ã = F^{-1/2} A F^{-1/2}, whose
    eigenvalues are 1 where a direction's inertia is exactly at its part's cap: while the
    smallest λ̃_min < 1, δ² = (1 − λ̃_min)², else δ = 0. With one part (or equal floors)
    this is δ² = λ₀ (1 − λ_min/λ₀)² with λ₀ = ``floor``, as before the parts had caps of
    their own; a cap of inf (f = 0) for one part is taken as 1e12 times the other's.

    Away from singular poses (λ̃_min ≥ 1) this is the exact Λ of Section 3.1, and the
    law is the paper's. As J loses rank, λ_min → 0 and the exact Λ, and with it
    J̄ = H⁻¹ Jᵀ Λ and the torque Jᵀ Λ ẍ_c, grow without bound; the damping keeps every
    eigenvalue of F^{1/2} Λ F^{1/2} at most 4/3, and δ² and its derivative vanish at
    λ̃_min = 1, so Λ stays continuous and smooth through the switch. The price, only
    there: J̄ is no longer an exact right inverse (J J̄ = I − δ² Λ F), so τ₀ may leak into
    the task, as with the damped least-squares inverse. (m, m).
    """
    m = A.shape[0]
    t = m if m_t < 0 else m_t
    f = np.empty(m)
    f[:t] = floor
    f[t:] = floor if rotational_floor < 0.0 else rotational_floor
    top = f.max()
    if top > 0.0:
        f = np.maximum(f, 1e-12 * top)
        s = 1.0 / np.sqrt(f)
        lam_min = np.linalg.eigvalsh(A * np.outer(s, s))[0]
        if lam_min < 1.0:
            A = A + (1.0 - lam_min) ** 2 * np.diag(f)
    return np.ascontiguousarray(np.linalg.inv(A))


class JacobianPartials:
    """∂J/∂q_k for every k, analytically (module docstring), for a fixed topology
    and a fixed set of task rows.

    Args:
        revolute: (n,) bool, joint k is revolute (else prismatic).
        inboard: (n, n) bool, inboard[k, i] = joint k is joint i or inboard of it.
        rows: indices of the world axes kept in J's translational rows.
        rot_rows: indices of the world axes kept in J's rotational rows (after them).
    """

    def __init__(self, revolute: np.ndarray, inboard: np.ndarray, rows=(0, 1, 2), rot_rows=()):
        revolute = np.asarray(revolute, dtype=bool)
        inboard = np.asarray(inboard, dtype=bool)
        # D[k, :, i] = w_k × J_i where joint k is joint i or inboard of it (k revolute),
        #            = w_i × J_k where joint k is outboard of joint i (i revolute; translational rows).
        self._own = inboard & revolute[:, None]
        self._other = ~inboard & revolute[None, :]
        self._rows = np.asarray(rows, dtype=np.int64)
        self._rot_rows = np.asarray(rot_rows, dtype=np.int64)

    def __call__(self, J_w: np.ndarray, J_v: np.ndarray) -> np.ndarray:
        """(n, m, n) array D with D[k] = ∂J/∂q_k (the task rows: translational rows of
        J_v, then rotational rows of J_w), from the (3, n) angular Jacobian J_w (column
        k is the world axis of revolute joint k) and the (3, n) translational Jacobian
        J_v of the tool point."""
        # C-contiguous (Drake's Jacobian rows are not): the kernel's one list of types
        J_w, J_v = np.ascontiguousarray(J_w, dtype=float), np.ascontiguousarray(J_v, dtype=float)
        return _jacobian_partials(J_w, J_v, self._own, self._other, self._rows, self._rot_rows)


@njit(cache=True, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def _jacobian_partials(J_w, J_v, own, other, rows, rot_rows):
    """:class:`JacobianPartials`'s D, in one compiled pass over the joint pairs (k, i)."""
    n, m_t, m_r = J_w.shape[1], rows.shape[0], rot_rows.shape[0]
    D = np.zeros((n, m_t + m_r, n))
    c = np.empty(3)
    for k in range(n):
        for i in range(n):
            if own[k, i]:  # w_k × J_v,i and, on rotational rows, w_k × J_w,i
                c[0], c[1], c[2] = _cross(J_w[0, k], J_w[1, k], J_w[2, k], J_v[0, i], J_v[1, i], J_v[2, i])
                for r in range(m_t):
                    D[k, r, i] = c[rows[r]]
                if m_r:
                    c[0], c[1], c[2] = _cross(
                        J_w[0, k], J_w[1, k], J_w[2, k], J_w[0, i], J_w[1, i], J_w[2, i]
                    )
                    for r in range(m_r):
                        D[k, m_t + r, i] = c[rot_rows[r]]
            elif other[k, i]:  # w_i × J_v,k
                c[0], c[1], c[2] = _cross(J_w[0, i], J_w[1, i], J_w[2, i], J_v[0, k], J_v[1, k], J_v[2, k])
                for r in range(m_t):
                    D[k, r, i] = c[rows[r]]
    return D


def coriolis_matrix(bias: Callable[[np.ndarray], np.ndarray], v: np.ndarray) -> np.ndarray:
    """C(q, v) from the bias term b(v) = C(q, v) v by polarisation.

    C e_j = (b(v + s e_j) − b(v − s e_j)) / (4 s); s = max(‖v‖, 1) keeps the
    rounding error of the difference near machine precision relative to C.
    """
    n = v.shape[0]
    s = max(float(np.linalg.norm(v)), 1.0)
    probes = v + s * np.vstack([np.eye(n), -np.eye(n)])  # (2n, n): v ± s e_j
    b = np.array([bias(w) for w in probes])
    return (b[:n] - b[n:]).T / (4.0 * s)


class ArmModel:
    """Reads :class:`RobotTerms` off a finalized ``MultibodyPlant``.

    The plant's generalized velocities must all belong to revolute or prismatic
    joints of the arm (the plate and obstacles are welded), and nq == nv.

    A joint's viscous damping D (URDF ``<dynamics damping>``; the plant applies −D q̇) enters
    the terms twice, so that the law's model (Eq. 5) is the arm's motion over one command's
    hold, not at an instant only:

    - D q̇ of the tick's state in C q̇, so that a law that cancels C q̇ cancels it;
    - T_D D on H's diagonal (T_D = ``damping_time`` [s]): over a command held for a period T
      the damping also opposes the velocity the command itself builds up, −D (q̇ₙ₊₁ − q̇ₙ),
      which the arm feels as an extra inertia. Drake's discrete plant integrates joint
      damping implicitly, M (q̇ₙ₊₁ − q̇ₙ) = h (τ − b − D q̇ₙ₊₁) over its step h, i.e.
      (M + h D) q̈ = τ − b − D q̇ₙ: exactly T_D = h when it steps once per control period.
      With k steps h = T/k per period, or continuous damping (a real arm, k → ∞) under a
      held command, the same first-order expansion in T D H⁻¹ gives T_D = (T + h)/2, and
      T/2 for the real arm (exact only while T D ≪ H: the damping's own time constant
      H_jj / D_j longer than the period). Without T_D D the law's H, Λ = (J H⁻¹ Jᵀ)⁻¹,
      J̄ = H⁻¹ Jᵀ Λ (Eq. 13) and null-space projector are those of a lighter arm than the one
      the command moves: the xArm7's wrist (D 2 N m s/rad, H_jj ≈ 1.4e-4 kg m²) has
      T D / H_jj ≈ 14 at 1 kHz, and its 1 ms pose hold leaves 18 µm instead of 0.05 µm
      (docs/results/vendor_arms).

    Args:
        plant: the finalized plant.
        tool_frame: the frame whose origin is the task point (the tool tip).
        task_axes: world axes of the task, e.g. ("x", "y"), ("x", "y", "z") or the
            full pose ("x", "y", "z", "rx", "ry", "rz"); m = len(task_axes).
        damping_time: T_D above [s], finite and ≥ 0; 0 compensates D q̇ only.
    """

    def __init__(
        self, plant: MultibodyPlant, tool_frame: Frame, task_axes: Sequence[str], damping_time: float = 0.0
    ):
        if not plant.is_finalized():
            raise ValueError("ArmModel needs a finalized MultibodyPlant")
        if plant.num_positions() != plant.num_velocities():
            floating = [b.name() for b in map(plant.get_body, plant.GetFloatingBaseBodies())]
            if floating:
                raise ValueError(
                    f"the body '{floating[0]}' has a floating base (no joint to the world): weld it to the "
                    "world (plant.WeldFrames, or ControllerModel.from_file, which welds it)"
                )
            raise ValueError(
                "nsdrake needs nq == nv (revolute and prismatic joints only); "
                f"the plant has nq={plant.num_positions()}, nv={plant.num_velocities()}"
            )
        self.rows, self.rot_rows = parse_task_axes(task_axes)
        self.plant = plant
        self.tool_frame = tool_frame
        self.task_axes = tuple(task_axes)
        self.n = plant.num_velocities()
        self.m = len(task_axes)
        self.m_t, self.m_r = len(self.rows), len(self.rot_rows)
        # Rows of Drake's spatial Jacobian [J_w; J_v] that make J.
        self.spatial_rows = np.concatenate([3 + self.rows, self.rot_rows])
        self.joints = self._joints_by_velocity_index()
        self.joint_names = tuple(j.name() for j in self.joints)
        self.revolute = np.array([j.type_name() == "revolute" for j in self.joints])
        # D, the joints' viscous damping as the model declares it (URDF <dynamics damping>):
        # the plant applies −D q̇, so the terms' C q̇ carries + D q̇ and the law compensates it;
        # and T_D D, the inertia it adds over a held command, is on H's diagonal (class docstring).
        self.damping = np.array([j.default_damping() for j in self.joints], dtype=float)
        self._damped = bool(np.any(self.damping))
        # ControllerModel refuses a bad damping_time in one line (validation.damping_time_problem,
        # which imports this module); here only what makes the term meaningless is stopped
        self.damping_time = float(damping_time)
        if not (math.isfinite(self.damping_time) and self.damping_time >= 0.0):
            raise ValueError(f"damping_time: must be a finite time >= 0 [s], got {damping_time!r}")
        self.damping_inertia = self.damping_time * self.damping  # (n,) T_D D [kg m² or kg]
        self._damping_inertia = bool(np.any(self.damping_inertia))
        self.inboard = self._inboard_matrix()
        self._partials = JacobianPartials(self.revolute, self.inboard, self.rows, self.rot_rows)
        self._origin = np.zeros(3)
        self._world = plant.world_frame()

    def _joints_by_velocity_index(self):
        plant = self.plant
        joints = [None] * self.n
        for index in plant.GetJointIndices():
            joint = plant.get_joint(index)
            if joint.num_velocities() == 0:
                continue
            if joint.type_name() not in ("revolute", "prismatic"):
                raise ValueError(
                    f"joint '{joint.name()}' is {joint.type_name()}; nsdrake's analytic ∂J/∂q "
                    "supports revolute and prismatic joints only"
                )
            joints[joint.velocity_start()] = joint
        return joints

    def _inboard_matrix(self) -> np.ndarray:
        plant = self.plant
        inboard = np.zeros((self.n, self.n), dtype=bool)
        for k, joint_k in enumerate(self.joints):
            outboard = set(plant.GetBodiesKinematicallyAffectedBy([joint_k.index()]))
            for i, joint_i in enumerate(self.joints):
                inboard[k, i] = joint_i.child_body().index() in outboard
        return inboard

    def joint_index(self, name: str) -> int:
        """Velocity index of the joint called ``name``; ValueError lists the valid names."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise ValueError(
                f"unknown joint '{name}'; the arm's joints are {', '.join(self.joint_names)}"
            ) from None

    def task_position(self, context: Context) -> np.ndarray:
        """x = p(q) (Eq. 1), the translational task axes, for the positions already in
        ``context``. (m_t,) [m]."""
        p = self.plant.CalcPointsPositions(context, self.tool_frame, self._origin, self._world)
        return p[self.rows, 0]

    def terms(
        self,
        context: Context,
        q: np.ndarray,
        v: np.ndarray,
        coriolis: bool,
        max_task_inertia: float = math.inf,
    ) -> RobotTerms:
        """Sets (q, v) into the plant ``context`` and evaluates every term.

        ``coriolis`` also computes the full matrix C (2n more bias evaluations).
        """
        H, H_inv, Cv, g, J_spatial, p_WT, R_WT, C = self.plant_terms(context, q, v, coriolis)
        return RobotTerms(
            q=q.copy(),
            v=v.copy(),
            H=H,
            H_inv=H_inv,
            Cv=Cv,
            g=g,
            x=p_WT[self.rows],
            p_WT=p_WT,
            J=J_spatial[self.spatial_rows],
            J_spatial=J_spatial,
            dJ_dq=self._partials(J_spatial[:3], J_spatial[3:]),
            C=C,
            R_WT=R_WT,
            max_task_inertia=max_task_inertia,
        )

    def plant_terms(self, context: Context, q: np.ndarray, v: np.ndarray, coriolis: bool) -> tuple:
        """(H, H⁻¹, C q̇, g, [J_w; J_v] (6, n), p_WT, R_WT or None, C or None) from the plant's
        own calls at (q, q̇), set into ``context`` (module docstring)."""
        plant = self.plant
        plant.SetPositionsAndVelocities(context, np.concatenate([q, v]))
        H = plant.CalcMassMatrix(context)
        Cv = plant.CalcBiasTerm(context)
        if self._damped:
            Cv = Cv + self.damping * v
        if self._damping_inertia:
            H = H + np.diag(self.damping_inertia)
        g = -plant.CalcGravityGeneralizedForces(context)
        J_spatial = plant.CalcJacobianSpatialVelocity(
            context, JacobianWrtVariable.kV, self.tool_frame, self._origin, self._world, self._world
        )
        p_WT = plant.CalcPointsPositions(context, self.tool_frame, self._origin, self._world)[:, 0]
        R_WT = self.tool_frame.CalcPoseInWorld(context).rotation().matrix() if self.m_r else None
        C = None
        if coriolis:
            C = coriolis_matrix(lambda w: self._bias(context, w), v)
            plant.SetVelocities(context, v)
        return H, inv(H), Cv, g, J_spatial, p_WT, R_WT, C

    def _bias(self, context: Context, v: np.ndarray) -> np.ndarray:
        self.plant.SetVelocities(context, v)
        return self.plant.CalcBiasTerm(context)

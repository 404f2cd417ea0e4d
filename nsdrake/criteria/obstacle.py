"""Obstacle avoidance (Eq. 31), with every link's closest point.

The paper pushes the *joints* away from the obstacle with a potential field,
∂p/∂q = Σᵢ dᵢᵀ J^{0,i}. nsdrake uses, for every pair (link geometry ℓ, obstacle
geometry o), the signed distance d_ℓo and the closest point C_ℓo on the link that
Drake's scene-graph query returns, and the potential

    p = −⅓ Σ_ℓo max(0, d_∞ − d_ℓo)³                (maximise: K > 0 in Eq. 30)

which is zero while every link is farther than the influence distance d_∞ and
grows more negative the deeper a link enters it. Its gradient is

    Φ = ∂p/∂q = Σ_ℓo max(0, d_∞ − d_ℓo)² n̂_ℓoᵀ J_C,ℓo,

with n̂ the unit normal from the obstacle toward the link and J_C the translational
Jacobian of the link's closest point: ∂d/∂q = n̂ᵀ J_C because the witness points
slide on the surfaces (envelope theorem). This is Eq. 31's "imaginary force along
the distance vector, applied to the robot" with the force applied at the closest
point of each link rather than at its joints, and weighted by how far inside the
influence distance the link is. The cube makes Φ continuously differentiable where
a link enters the influence zone: with a square, Φ would have a kink there, and
the feed-forward of q̈_dⁿ would turn it into a torque step.

The function below is the math; :class:`ObstacleDistances` reads the pairs from a
plant and a scene-graph ``QueryObject``.

Precision. Drake computes the distance between a capsule and a box with an
iterative (GJK-type) algorithm: the distance is accurate, but the witness point
on the link can be off by ~1e-5 m, and n̂ᵀ J_C inherits a ~1e-6 relative error
from it. For capsule and sphere links (the arm's), nsdrake therefore takes the
witness only as a starting point: the link's capsule is its axis segment swollen
by its radius r, so d = min_s φ_o(S(s)) − r, with φ_o Drake's *exact*
point-to-shape signed distance (``ComputeSignedDistanceToPoint``, errors ~1e-15 m)
and S(s) the axis point. A bracketed root search on the axis finds the minimising
S; then ∂d/∂q = ∇φ_o(S)ᵀ J_S, the envelope theorem again. Other link shapes, and a link
that already penetrates an obstacle (d ≤ 0, outside the domain the criterion
is meant to keep the arm in), use the witness directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Capsule, QueryObject, Role, Sphere
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import Context

from ..reference import smoothstep


@dataclass(frozen=True)
class DistancePair:
    """One link–obstacle pair at one configuration."""

    distance: float  # signed distance d_ℓo [m]
    d_distance_dq: np.ndarray | None  # (n,) ∂d/∂q [m/rad], None when not needed (out of range)
    link: str  # link geometry name
    obstacle: str  # obstacle geometry name


def activation(d_min: float, influence: float) -> float:
    """How much the obstacle level counts in the projection of the levels below it
    (:mod:`nsdrake.priority`): 0 while every link is beyond the influence distance
    d_∞, rising with a smoothstep to 1 once a link is at d_∞/2 or closer."""
    return smoothstep(2.0 * (influence - d_min) / influence)


def obstacle_potential(pairs: list[DistancePair], influence: float, n: int) -> tuple[float, np.ndarray]:
    """(p, Φ) of the potential in the module docstring, influence distance d_∞ [m].
    No pairs (an arm without link geometry) gives p = 0, Φ = 0."""
    p, Phi = 0.0, np.zeros(n)
    for pair in pairs:
        depth = influence - pair.distance
        if depth > 0.0:
            p -= depth**3 / 3.0
            Phi += depth * depth * pair.d_distance_dq
    return p, Phi


class ObstacleDistances:
    """Signed distances and their gradients between the arm's link geometries and
    the obstacle geometries, from Drake's geometry queries.

    Args:
        plant: the finalized plant (registered with a SceneGraph).
        link_geometries: proximity GeometryIds of the arm's links (not the tool).
        obstacle_geometries: proximity GeometryIds of the obstacles (plate included).
        inspector: the SceneGraph's inspector (names, frames, poses, shapes).
    """

    MAX_ITERATIONS = 60  # false-position steps on a capsule's axis (typically < 10)

    def __init__(self, plant: MultibodyPlant, link_geometries, obstacle_geometries, inspector):
        self.plant = plant
        self._world = plant.world_frame()
        self._links = []
        for g in link_geometries:
            body = plant.GetBodyFromFrameId(inspector.GetFrameId(g))
            X_BG = inspector.GetPoseInFrame(g).GetAsMatrix34()  # plain array: p_B = R p_G + t
            shape = inspector.GetShape(g)
            if isinstance(shape, Capsule):
                axis = (shape.radius(), 0.5 * shape.length())
            elif isinstance(shape, Sphere):
                axis = (shape.radius(), 0.0)
            else:
                axis = None  # use the witness point as it is
            self._links.append((g, inspector.GetName(g), body.body_frame(), X_BG, axis))
        self._obstacles = [(g, inspector.GetName(g)) for g in obstacle_geometries]

    @property
    def num_pairs(self) -> int:
        return len(self._links) * len(self._obstacles)

    def pairs(self, query: QueryObject, plant_context: Context, gradient_within: float) -> list[DistancePair]:
        """Every link–obstacle pair; ∂d/∂q only for pairs closer than ``gradient_within``.

        ``plant_context`` must hold the same positions the query was evaluated at.
        """
        out = []
        for g_link, link_name, body_frame, X_BG, axis in self._links:
            X_WG = query.GetPoseInWorld(g_link)
            for g_obs, obs_name in self._obstacles:
                r = query.ComputeSignedDistancePairClosestPoints(g_link, g_obs)
                distance, grad = r.distance, None
                if distance < gradient_within:
                    if axis is None or distance <= 0.0:
                        p_BC = X_BG[:, :3] @ r.p_ACa + X_BG[:, 3]  # the witness, in the link's body frame
                        n_W = r.nhat_BA_W
                    else:
                        radius, half_length = axis
                        distance, n_W, p_GS = self._refine(query, g_obs, X_WG, radius, half_length, distance)
                        p_BC = X_BG[:, :3] @ p_GS + X_BG[:, 3]
                    J_C = self.plant.CalcJacobianTranslationalVelocity(
                        plant_context, JacobianWrtVariable.kV, body_frame, p_BC, self._world, self._world
                    )
                    grad = n_W @ J_C
                out.append(DistancePair(distance, grad, link_name, obs_name))
        return out

    def _refine(self, query, g_obs, X_WG, radius, half_length, distance):
        """(d, ∇φ, p_GS): the axis point S of a capsule (or sphere) nearest the obstacle,
        the exact distance d = φ_o(S) − r and the gradient ∇φ_o(S) (separated pairs).

        φ_o, the distance to a convex obstacle, is convex along the axis, so its
        slope g(s) = ∇φ_o(S(s)) · axis is non-decreasing: the minimum is at an end
        of the segment where g does not change sign, else at the root of g, found by
        false position with the Illinois modification (superlinear, bracketed).
        """
        M = X_WG.GetAsMatrix34()  # plain arrays: RigidTransform.multiply is slow from Python
        axis_W, origin_W = M[:, 2], M[:, 3]  # the capsule's axis is the geometry frame's z
        # Every axis point is within 2 × half_length of the nearest one, so φ_o ≤ d + r + 2 half_length:
        # obstacles farther than that cannot answer and are skipped by the query.
        threshold = distance + radius + 2.0 * half_length + 1e-3

        def at(s):
            phi, grad = self._point_distance(query, g_obs, origin_W + s * axis_W, threshold)
            return phi, grad, float(axis_W @ grad)

        if half_length == 0.0:  # a sphere: its centre
            phi, grad, _ = at(0.0)
            return phi - radius, grad, np.zeros(3)
        a, b = -half_length, half_length
        phi, grad, g_a = at(a)
        s = a
        if g_a < 0.0:
            phi, grad, g_b = at(b)
            s = b
            if g_b > 0.0:
                side = 0
                for _ in range(self.MAX_ITERATIONS):
                    s = b - g_b * (b - a) / (g_b - g_a)
                    phi, grad, g = at(s)
                    if abs(g) <= 1e-13 or b - a <= 1e-13:
                        break
                    if g > 0.0:
                        b, g_b = s, g
                        if side == 1:
                            g_a *= 0.5
                        side = 1
                    else:
                        a, g_a = s, g
                        if side == -1:
                            g_b *= 0.5
                        side = -1
        return phi - radius, grad, np.array([0.0, 0.0, s])

    @staticmethod
    def _point_distance(query, g_obs, p_W, threshold) -> tuple[float, np.ndarray]:
        for result in query.ComputeSignedDistanceToPoint(p_W, threshold):
            if result.id_G == g_obs:
                return float(result.distance), np.asarray(result.grad_W)
        raise RuntimeError("the obstacle geometry does not support point distance queries")


def proximity_geometries(inspector, plant: MultibodyPlant, bodies) -> list:
    """The proximity-role GeometryIds attached to ``bodies`` (body indices)."""
    wanted = {int(b) for b in bodies}
    out = []
    for g in inspector.GetAllGeometryIds(Role.kProximity):
        body = plant.GetBodyFromFrameId(inspector.GetFrameId(g))
        if body is not None and int(body.index()) in wanted:
            out.append(g)
    return out

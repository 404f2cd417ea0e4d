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

Precision and speed. For capsule and sphere links against box and sphere obstacles
(the shipped scenes) d and its minimiser come in closed form
(:mod:`nsdrake.control.criteria.distance`): exact, and without a geometry engine. Other
shapes use Drake's queries: Drake computes the distance between a capsule and a
box with an iterative (GJK-type) algorithm whose witness point on the link can be
off by ~1e-5 m, so nsdrake takes the witness only as a starting point there: the
link's capsule is its axis segment swollen by its radius r, so d = min_s φ_o(S(s))
− r, with φ_o Drake's *exact* point-to-shape signed distance
(``ComputeSignedDistanceToPoint``), and a bracketed root search on the axis finds
the minimising S; then ∂d/∂q = ∇φ_o(S)ᵀ J_S, the envelope theorem again. Other link
shapes, and a link that already penetrates an obstacle (d ≤ 0, outside the domain
the criterion is meant to keep the arm in), use the witness directly.
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

import numpy as np
from numba import njit
from pydrake.geometry import Box, Capsule, Role, Sphere
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import Context

from nsdrake.control.criteria.distance import _rotate, segments_box, segments_sphere


class DistancePair(NamedTuple):
    """One link–obstacle pair at one configuration (a NamedTuple: the criterion builds a
    few per control tick, and a frozen dataclass costs several times more to create)."""

    distance: float  # signed distance d_ℓo [m]
    d_distance_dq: np.ndarray | None  # (n,) ∂d/∂q [m/rad], None when not needed (out of range)
    link: str  # link geometry name
    obstacle: str  # obstacle geometry name


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
    the obstacle geometries of a plant registered with a SceneGraph.

    Capsule and sphere links against box and sphere obstacles use the closed forms
    of :mod:`nsdrake.control.criteria.distance` (exact, no geometry engine, the link poses
    from the plant); other shapes, and pairs that touch, use Drake's geometry
    queries (module docstring), asked for only then.

    Obstacles must be fixed in the world (welded, or registered on the world body).

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
            self._links.append((g, inspector.GetName(g), body, X_BG, axis))
        self._bodies = [body for _, _, body, _, _ in self._links]
        self._p_BG = np.array([X_BG[:, 3] for _, _, _, X_BG, _ in self._links]).reshape(-1, 3)
        self._z_BG = np.array([X_BG[:, 2] for _, _, _, X_BG, _ in self._links]).reshape(-1, 3)
        self._half_lengths = np.array([axis[1] if axis else 0.0 for _, _, _, _, axis in self._links])
        self._obstacles = [(g, inspector.GetName(g)) for g in obstacle_geometries]
        self._shapes = [inspector.GetShape(g) for g in obstacle_geometries]
        self._poses = [
            (plant.GetBodyFromFrameId(inspector.GetFrameId(g)), inspector.GetPoseInFrame(g))
            for g in obstacle_geometries
        ]
        self._closed_forms = None  # per obstacle, set on the first call (needs a context)

    @property
    def num_pairs(self) -> int:
        return len(self._links) * len(self._obstacles)

    def _obstacle_forms(self, plant_context) -> list:
        """Per obstacle: a function of the links' segments (A, B) for its closed form, or None."""
        forms = []
        for shape, (body, X_BG) in zip(self._shapes, self._poses, strict=True):
            X_WG = self.plant.EvalBodyPoseInWorld(plant_context, body) @ X_BG
            # C-contiguous, writable: the types the stages call the closed forms with (one compile)
            R, p = np.ascontiguousarray(X_WG.rotation().matrix()), np.array(X_WG.translation())
            if isinstance(shape, Box):
                half = 0.5 * np.array([shape.width(), shape.depth(), shape.height()])
                forms.append(partial(_box_form, R, p, half))
            elif isinstance(shape, Sphere):
                forms.append(partial(_sphere_form, p, shape.radius()))
            else:
                forms.append(None)
        return forms

    def _segments(self, plant_context) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The links' body poses M = [R_WB | p_WB] (k, 3, 4) and their axis segments A, B
        (k, 3), world (a link without an axis gets a zero-length segment at its
        geometry's origin, never used)."""
        M = np.array([self.plant.EvalBodyPoseInWorld(plant_context, b).GetAsMatrix34() for b in self._bodies])
        A, B = _axis_segments(M, self._p_BG, self._z_BG, self._half_lengths)
        return M, A, B

    def pairs(self, plant_context: Context, gradient_within: float, query=None) -> list[DistancePair]:
        """Every link–obstacle pair; ∂d/∂q only for pairs closer than ``gradient_within``.

        ``query``: a QueryObject at the positions of ``plant_context``, or a function
        returning one; asked for only by pairs without a closed form.
        """
        if self._closed_forms is None:
            self._closed_forms = self._obstacle_forms(plant_context)
        M, A, B = self._segments(plant_context)
        # Per obstacle with a closed form: rows [φ, ∇φ, S] per link, and S in each link's body frame.
        rows = [None if form is None else form(A, B) for form in self._closed_forms]
        in_body = [None if r is None else _in_body_frames(M, r[:, 4:7]) for r in rows]
        plant, out = self.plant, []
        for k, (g_link, link_name, body, X_BG, axis) in enumerate(self._links):
            for o, (g_obs, obs_name) in enumerate(self._obstacles):
                row = rows[o][k] if rows[o] is not None and axis is not None else None
                if row is not None and not math.isnan(row[0]):
                    distance, n_W, p_BC = row[0] - axis[0], row[1:4], in_body[o][k]
                else:
                    if callable(query):
                        query = query()
                    distance, n_W, p_BC = self._queried(query, g_link, g_obs, X_BG, axis, gradient_within)
                grad = None
                if distance < gradient_within:
                    J_C = plant.CalcJacobianTranslationalVelocity(
                        plant_context,
                        JacobianWrtVariable.kV,
                        body.body_frame(),
                        p_BC,
                        self._world,
                        self._world,
                    )
                    grad = n_W @ J_C
                out.append(DistancePair(float(distance), grad, link_name, obs_name))
        return out

    def _queried(self, query, g_link, g_obs, X_BG, axis, gradient_within):
        """(d, n̂, p_BC) from Drake's queries: the witness, refined on a capsule's axis."""
        r = query.ComputeSignedDistancePairClosestPoints(g_link, g_obs)
        distance, n_W = r.distance, r.nhat_BA_W
        if axis is None or distance <= 0.0 or distance >= gradient_within:
            return distance, n_W, X_BG[:, :3] @ r.p_ACa + X_BG[:, 3]
        radius, half_length = axis
        X_WG = query.GetPoseInWorld(g_link)
        distance, n_W, p_GS = self._refine(query, g_obs, X_WG, radius, half_length, distance)
        return distance, n_W, X_BG[:, :3] @ p_GS + X_BG[:, 3]

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


@njit(cache=True)
def _axis_segments(M, p_BG, z_BG, half_lengths):
    """(A, B): each link's axis segment, world, from its body pose M[k] = [R_WB | p_WB], its
    geometry origin p_BG[k] and axis z_BG[k] in the body frame, and half length."""
    k = M.shape[0]
    A, B = np.empty((k, 3)), np.empty((k, 3))
    for i in range(k):
        R = M[i, :, :3]
        centre = _rotate(R, p_BG[i], False) + M[i, :, 3]
        half_axis = half_lengths[i] * _rotate(R, z_BG[i], False)
        A[i], B[i] = centre - half_axis, centre + half_axis
    return A, B


@njit(cache=True)
def _in_body_frames(M, p_W):
    """p_B = R_WBᵀ (p_W − p_WB) for each link's pose M[k] and world point p_W[k]. (k, 3)."""
    out = np.empty((M.shape[0], 3))
    for i in range(M.shape[0]):
        out[i] = _rotate(M[i, :, :3], p_W[i] - M[i, :, 3], True)
    return out


def _box_form(R_WO, p_WO, half, A, B):
    return segments_box(A, B, R_WO, p_WO, half)


def _sphere_form(centre, radius, A, B):
    return segments_sphere(A, B, centre, radius)


def proximity_geometries(inspector, plant: MultibodyPlant, bodies) -> list:
    """The proximity-role GeometryIds attached to ``bodies`` (body indices)."""
    wanted = {int(b) for b in bodies}
    out = []
    for g in inspector.GetAllGeometryIds(Role.kProximity):
        body = plant.GetBodyFromFrameId(inspector.GetFrameId(g))
        if body is not None and int(body.index()) in wanted:
            out.append(g)
    return out

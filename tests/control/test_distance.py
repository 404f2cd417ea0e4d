"""The closed-form segment–obstacle distances (nsdrake/criteria/distance.py) against
Drake's exact point-to-shape signed distance, minimised along the segment by golden
section (φ is convex along a segment), on seeded random segments and poses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydrake.geometry import Box, ProximityProperties, Sphere
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from nsdrake.control.criteria.distance import segments_box, segments_sphere

TOL = 1e-9  # [m] the golden-section reference resolves s to ~1e-12; φ is Lipschitz with constant ‖B − A‖


def scene(shape, X_WO):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    geometry = plant.RegisterCollisionGeometry(
        plant.world_body(), X_WO, shape, "obstacle", ProximityProperties()
    )
    plant.Finalize()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
    scene.keep_alive = (diagram, context)  # the query refers into the context
    return query, geometry


def drake_minimum(query, geometry, A, B):
    """(min_s φ(S(s)), ∇φ at the minimiser, S) by golden section on Drake's point distance."""

    def phi(s):
        (result,) = [
            r for r in query.ComputeSignedDistanceToPoint(A + s * (B - A), 100.0) if r.id_G == geometry
        ]
        return result.distance, np.asarray(result.grad_W)

    lo, hi = 0.0, 1.0
    g = (math.sqrt(5.0) - 1.0) / 2.0
    for _ in range(80):
        a, b = hi - g * (hi - lo), lo + g * (hi - lo)
        if phi(a)[0] <= phi(b)[0]:
            hi = b
        else:
            lo = a
    s = 0.5 * (lo + hi)
    d, grad = phi(s)
    return d, grad, A + s * (B - A)


def random_cases(rng, count, spread):
    for _ in range(count):
        A = rng.uniform(-spread, spread, 3)
        B = A + rng.normal(0.0, 0.3, 3)
        yield A, B


@pytest.mark.parametrize("seed", [1, 2])
def test_segment_box_matches_drake_point_distance_minimised(seed):
    """φ, its unit gradient and the minimiser S for a rotated, offset box. A wrong
    piece coefficient, a missing breakpoint or a frame mix-up (R vs Rᵀ) fails."""
    rng = np.random.default_rng(seed)
    half = np.array([0.3, 0.1, 0.2])
    X_WO = RigidTransform(RollPitchYaw(rng.uniform(-np.pi, np.pi, 3)), rng.uniform(-0.2, 0.2, 3))
    query, geometry = scene(Box(*(2 * half)), X_WO)
    checked = 0
    for A, B in random_cases(rng, 60, 1.0):
        (row,) = segments_box(A[None], B[None], X_WO.rotation().matrix(), X_WO.translation(), half)
        d, grad, S = drake_minimum(query, geometry, A, B)
        if d <= 1e-6:
            assert np.isnan(row[0]) or d > -1e-12  # touching or inside: no closed form
            continue
        checked += 1
        assert row[0] == pytest.approx(d, abs=TOL)
        assert np.allclose(row[1:4], grad, atol=1e-6)  # the normal at a nearly-flat minimum
        # S itself is unique only where the minimum is strict; φ(S) must equal the minimum.
        (at_S,) = [r for r in query.ComputeSignedDistanceToPoint(row[4:7], 100.0) if r.id_G == geometry]
        assert at_S.distance == pytest.approx(d, abs=TOL)
    assert checked > 30


def test_segment_sphere_matches_drake_and_detects_contact():
    """The sphere's closed form; a segment through the sphere gives NaN (no unique normal)."""
    rng = np.random.default_rng(5)
    centre, radius = np.array([0.1, -0.2, 0.3]), 0.15
    query, geometry = scene(Sphere(radius), RigidTransform(centre))
    for A, B in random_cases(rng, 40, 1.0):
        (row,) = segments_sphere(A[None], B[None], centre, radius)
        d, grad, _ = drake_minimum(query, geometry, A, B)
        if d <= 1e-6:
            continue
        assert row[0] == pytest.approx(d, abs=TOL)
        assert np.allclose(row[1:4], grad, atol=1e-9)
    (row,) = segments_sphere(np.array([[0.1, -0.5, 0.3]]), np.array([[0.1, 0.5, 0.3]]), centre, radius)
    assert np.isnan(row[0])


def test_segment_box_of_zero_length_is_the_point_distance():
    """A sphere link is a segment of zero length: its distance is the point's."""
    half = np.array([0.5, 0.5, 0.5])
    A = np.array([[0.0, 0.0, 2.0]])
    (row,) = segments_box(A, A, np.eye(3), np.zeros(3), half)
    assert row[0] == pytest.approx(1.5, abs=1e-15)
    assert np.allclose(row[1:4], [0.0, 0.0, 1.0])

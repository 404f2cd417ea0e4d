"""Criterion gradients (Section 3.5) against central finite differences and Drake's AutoDiffXd,
on 100 seeded random configurations of the paper's arm and 40 within 1e-3 rad of a singular one.

Tolerances, relative to the largest gradient entry: analytic vs AutoDiff 1e-7 (the
same derivative in another order of operations: ~1e-14 away from singular poses;
within 1e-3 rad of one, det(J Jᵀ) ~ 1e-7 has lost ~7 digits to cancellation in
both computations, and they agree to ~2e-8); analytic vs
central differences 1e-6 (Richardson-extrapolated, h = 1e-5: O(h⁴) truncation and
O(ε/h) rounding give ~1e-10 for these smooth functions, near-singular poses included).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import paper_arm, terms_at
from drake_reference import AutoDiffArm
from models import random_states
from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff
from pydrake.systems.framework import DiagramBuilder
from reference_math import moore_penrose_inverse

from nsdrake.control.criteria.joint_torque import joint_torque_criterion
from nsdrake.control.criteria.manipulability import manipulability
from nsdrake.control.criteria.obstacle import ObstacleDistances, obstacle_potential
from nsdrake.experiment.scenario_station import add_scenario_station

AD_TOL = 1e-7
FD_TOL = 1e-6
H = 1e-6
RANDOM = 100
NEAR_SINGULAR = 40


def near_singular_offset(rng, size):
    """Offsets between 5e-4 and 1e-3 rad in size, random sign: within 1e-3 rad of the
    singular pose, but not so close that w ~ 1e-7 drowns central differences in
    rounding (w then carries ~1e-16 / w relative noise)."""
    return rng.choice([-1.0, 1.0], size) * rng.uniform(5e-4, 1e-3, size)


def configurations(seed=31):
    """100 random q, then 40 within 1e-3 rad of a singular pose of the planar arm
    (every relative angle q2…q4 at 0 or π: all links collinear)."""
    rng = np.random.default_rng(seed)
    out = [q for q, _ in random_states(4, RANDOM, seed=seed)]
    for _ in range(NEAR_SINGULAR):
        singular = np.concatenate([[rng.uniform(-np.pi, np.pi)], rng.choice([0.0, np.pi], size=3)])
        out.append(singular + near_singular_offset(rng, 4))
    return out


def relative_error(got, expected):
    return np.max(np.abs(got - expected)) / max(np.max(np.abs(expected)), 1e-300)


def central_differences(f, q, h=1e-5):
    """Richardson-extrapolated central differences, error O(h⁴): near a singular pose
    (w ~ 1e-3 rad from it) plain central differences lose accuracy as (h / 1e-3)²."""

    def d(step):
        return np.array([(f(q + step * e) - f(q - step * e)) / (2 * step) for e in np.eye(len(q))])

    return (4 * d(h / 2) - d(h)) / 3


@pytest.fixture(scope="module")
def arm():
    return paper_arm()


@pytest.fixture(scope="module")
def ad(arm):
    return AutoDiffArm(arm)


def test_near_singular_configurations_are_near_singular(arm):
    ws = [manipulability(*_J_dJ(arm, q))[0] for q in configurations()[RANDOM:]]
    assert max(ws) < 5e-3  # vs ~0.1–0.3 away from singular poses


def _J_dJ(arm, q):
    T = terms_at(arm, q, np.zeros(4), coriolis=False)
    return T.J, T.dJ_dq


def test_joint_torque_gradient(arm, ad):
    rng = np.random.default_rng(1031)
    for q in configurations():
        F = 10 * rng.standard_normal(2)
        f = F
        p, Phi = joint_torque_criterion(*_J_dJ(arm, q), F)
        J = _J_dJ(arm, q)[0]
        assert abs(p - (J.T @ F) @ (J.T @ F)) <= 1e-12 * max(1.0, p)
        tau = J.T @ F
        Phi_ad = np.array([2 * tau @ (dJk.T @ F) for dJk in ad.dJ_dq(q)])
        assert relative_error(Phi, Phi_ad) < AD_TOL
        fd = central_differences(lambda x, f=f: joint_torque_criterion(*_J_dJ(arm, x), f)[0], q)
        assert relative_error(Phi, fd) < FD_TOL


def test_manipulability_gradient(arm, ad):
    for q in configurations(seed=32):
        w, Phi = manipulability(*_J_dJ(arm, q))
        J = _J_dJ(arm, q)[0]
        assert abs(w - np.sqrt(np.linalg.det(J @ J.T))) <= 1e-12
        # AutoDiff of w = √det(J Jᵀ) with J from Drake's AutoDiffXd plant.
        J_ad = ad._jacobian(InitializeAutoDiff(q))
        A = J_ad @ J_ad.T
        det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
        Phi_ad = ExtractGradient(np.array([det]))[0] / (2 * w)
        assert relative_error(Phi, Phi_ad) < AD_TOL
        fd = central_differences(lambda x: manipulability(*_J_dJ(arm, x))[0], q)
        assert relative_error(Phi, fd) < FD_TOL


def test_manipulability_formula_is_the_trace_form(arm):
    """∂w/∂q_j = w tr(J⁺ ∂J/∂q_j) (READING_NOTES), with the reference form of J⁺."""
    q = configurations()[5]
    J, dJ = _J_dJ(arm, q)
    w, Phi = manipulability(J, dJ)
    J_pinv = moore_penrose_inverse(J)
    assert relative_error(Phi, np.array([w * np.trace(J_pinv @ dJ[j]) for j in range(4)])) < 1e-12


# --- obstacle avoidance ---------------------------------------------------------------

OBSTACLE_SCENE = """
plate: {position: [0.0, 0.6, 0.0]}
obstacles:
  - {name: ball, shape: sphere, size: [0.04], position: [0.35, 0.1, 0.0]}
  - {name: post, shape: cylinder, size: [0.03, 0.2], position: [-0.3, 0.25, 0.0]}
  - {name: block, shape: box, size: [0.08, 0.05, 0.2], position: [0.1, -0.35, 0.0], yaw: 0.4}
"""


class ObstacleScene:
    """The paper's arm with the plate and three obstacles (sphere, cylinder, box), in a
    plain plant + scene graph diagram that Drake can convert to AutoDiffXd."""

    def __init__(self, tmp_path_factory):
        from nsdrake.experiment.scenario import load_scenario

        path = tmp_path_factory.mktemp("scene") / "scene.yaml"
        path.write_text(OBSTACLE_SCENE)
        scenario = load_scenario("fig3", config=path)
        builder = DiagramBuilder()
        self.station = add_scenario_station(builder, scenario, sensing=False)
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        plant, sg = self.station.plant, self.station.scene_graph
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        self.sg_context = sg.GetMyContextFromRoot(self.context)
        self.distances = ObstacleDistances(
            plant, self.station.link_geometries, self.station.obstacle_geometries, sg.model_inspector()
        )

    def pairs(self, q, within=10.0):
        self.station.plant.SetPositions(self.plant_context, q)
        query = self.station.scene_graph.get_query_output_port().Eval(self.sg_context)
        return self.distances.pairs(self.plant_context, within, query=query)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return ObstacleScene(tmp_path_factory)


def separated_configurations(scene, count, seed, near_singular=False, clearance=0.003):
    """Configurations whose links all stay at least ``clearance`` from every obstacle."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        if near_singular:
            q = np.concatenate([[rng.uniform(-np.pi, np.pi)], rng.choice([0.0, np.pi], 3)])
            q = q + near_singular_offset(rng, 4)
        else:
            q = rng.uniform(-np.pi, np.pi, 4)
        if min(p.distance for p in scene.pairs(q)) > clearance:
            out.append(q)
    return out


def test_distance_gradients_against_central_differences(scene):
    """∂d/∂q of every link–obstacle pair (capsule links against a box, a sphere, a
    cylinder and the plate) against central differences of Drake's distances."""
    configs = separated_configurations(scene, 100, seed=33) + separated_configurations(
        scene, 20, seed=34, near_singular=True
    )
    for q in configs:
        pairs = scene.pairs(q)
        analytic = np.array([p.d_distance_dq for p in pairs])
        fd = central_differences(lambda x: np.array([p.distance for p in scene.pairs(x)]), q).T
        assert relative_error(analytic, fd) < FD_TOL


def test_obstacle_potential_gradient(scene):
    influence = 0.3  # wide, so that several pairs contribute
    for q in separated_configurations(scene, 100, seed=35):
        p, Phi = obstacle_potential(scene.pairs(q, influence), influence, 4)
        fd = central_differences(lambda x: obstacle_potential(scene.pairs(x, influence), influence, 4)[0], q)
        if np.max(np.abs(fd)) > 0:
            assert relative_error(Phi, fd) < FD_TOL


def test_distance_gradients_against_autodiff(scene):
    """AutoDiff of Drake's exact point-to-shape distance φ_o(S(q)) − r at each pair's
    axis point S (fixed on the link, where the minimum over the axis is attained):
    by the envelope theorem this is ∂d/∂q. Drake's AutoDiffXd supports the point
    queries for boxes, capsules and spheres (not cylinders, not capsule–box pairs)."""
    ad_diagram = scene.diagram.ToAutoDiffXd()
    ad_context = ad_diagram.CreateDefaultContext()
    ad_plant = ad_diagram.GetSubsystemByName("plant")
    ad_sg = ad_diagram.GetSubsystemByName("scene_graph")
    ad_plant_context = ad_plant.GetMyMutableContextFromRoot(ad_context)
    inspector = scene.station.scene_graph.model_inspector()
    shapes = {
        inspector.GetName(g): (g, type(inspector.GetShape(g)).__name__)
        for g in scene.station.obstacle_geometries
    }
    checked = 0
    for q in separated_configurations(scene, 100, seed=36):
        ad_plant.SetPositions(ad_plant_context, InitializeAutoDiff(q))
        query = ad_sg.get_query_output_port().Eval(ad_sg.GetMyContextFromRoot(ad_context))
        for pair, (g_link, _, body_frame, X_BG, axis) in zip(
            scene.pairs(q),
            [link for link in scene.distances._links for _ in scene.distances._obstacles],
            strict=True,
        ):
            g_obs, kind = shapes[pair.obstacle]
            if kind not in ("Box", "Sphere") or pair.distance <= 0:
                continue
            # Recover the refined axis point S from the analytic pair, then differentiate φ(S(q)).
            radius, half = axis
            M = (
                scene.station.scene_graph.get_query_output_port()
                .Eval(scene.sg_context)
                .GetPoseInWorld(g_link)
                .GetAsMatrix34()
            )
            s = _axis_parameter(scene, pair, M, radius, half, g_obs)
            p_BS = X_BG[:, :3] @ np.array([0.0, 0.0, s]) + X_BG[:, 3]
            ad_body = ad_plant.GetFrameByName(body_frame.name(), body_frame.model_instance())
            p_WS = ad_plant.CalcPointsPositions(
                ad_plant_context, ad_body, p_BS.reshape(3, 1), ad_plant.world_frame()
            )[:, 0]
            results = [r for r in query.ComputeSignedDistanceToPoint(p_WS) if r.id_G == g_obs]
            grad_ad = results[0].distance.derivatives()
            assert relative_error(pair.d_distance_dq, grad_ad) < AD_TOL
            checked += 1
    assert checked >= 100


def _axis_parameter(scene, pair, M, radius, half, g_obs):
    """The axis parameter s of the refined closest point, recomputed the same way the
    criterion does."""
    query = scene.station.scene_graph.get_query_output_port().Eval(scene.sg_context)
    inspector = scene.station.scene_graph.model_inspector()
    g_link = next(g for g in scene.station.link_geometries if inspector.GetName(g) == pair.link)
    witness = query.ComputeSignedDistancePairClosestPoints(g_link, g_obs)
    return scene.distances._refine(
        query, g_obs, query.GetPoseInWorld(g_link), radius, half, witness.distance
    )[2][2]

"""urdf/panda.urdf against the numbers it was written from (urdf/README.md, section panda.urdf).

Each test checks a published or physical property, independently of the file: the
forward kinematics against a plain numpy product of Franka's modified-DH transforms,
the limits against Franka's datasheet, the masses against Gaz et al. (2019), the
dynamics against a second parser (Pinocchio). Tolerances: the file and the references
are the same numbers evaluated in a different order, so they agree to rounding
(~1e-15); 1e-9 leaves room for it. Masses and limits are compared to 1e-9 because the
file carries the published digits exactly.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pytest
from pydrake.geometry import Box, Capsule, Cylinder, ProximityProperties, Role, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import JacobianWrtVariable, RevoluteJoint
from pydrake.systems.framework import DiagramBuilder

from nsdrake.station.models import models_dir

PANDA = models_dir() / "panda.urdf"
EXACT = 1e-9

# Franka's modified-DH (Craig) parameters: (a_{i-1}, d_i, alpha_{i-1}) for joints 1..7, and the flange.
DH = [
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -np.pi / 2),
    (0.0, 0.316, np.pi / 2),
    (0.0825, 0.0, np.pi / 2),
    (-0.0825, 0.384, -np.pi / 2),
    (0.0, 0.0, np.pi / 2),
    (0.088, 0.0, np.pi / 2),
]
FLANGE_D = 0.107

# Franka's datasheet (Panda): joint position, velocity and torque limits.
Q_MIN = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
Q_MAX = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
V_MAX = np.array([2.1750] * 4 + [2.6100] * 3)
TAU_MAX = np.array([87.0] * 4 + [12.0] * 3)

# Gaz et al., IEEE RA-L 4(4) 2019, identified feasible parameters of links 1..7 (supplementary
# material, Tables VIII-IX): mass [kg], centre of mass in the DH link frame [m], inertia about the
# centre of mass in axes parallel to the DH frame, (xx, xy, xz, yy, yz, zz) [kg m²].
GAZ_MASSES = [4.970684, 0.646926, 3.228604, 3.587895, 1.225946, 1.666555, 0.735522]
GAZ_COMS = [
    (3.875e-03, 2.081e-03, 0.0),
    (-3.141e-03, -2.872e-02, 3.495e-03),
    (2.7518e-02, 3.9252e-02, -6.6502e-02),
    (-5.317e-02, 1.04419e-01, 2.7454e-02),
    (-1.1953e-02, 4.1065e-02, -3.8437e-02),
    (6.0149e-02, -1.4117e-02, -1.0517e-02),
    (1.0517e-02, -4.252e-03, 6.1597e-02),
]
GAZ_INERTIAS = [
    (7.0337e-01, -1.3900e-04, 6.7720e-03, 7.0661e-01, 1.9169e-02, 9.1170e-03),
    (7.9620e-03, -3.9250e-03, 1.0254e-02, 2.8110e-02, 7.0400e-04, 2.5995e-02),
    (3.7242e-02, -4.7610e-03, -1.1396e-02, 3.6155e-02, -1.2805e-02, 1.0830e-02),
    (2.5853e-02, 7.7960e-03, -1.3320e-03, 1.9552e-02, 8.6410e-03, 2.8323e-02),
    (3.5549e-02, -2.1170e-03, -4.0370e-03, 2.9474e-02, 2.2900e-04, 8.6270e-03),
    (1.9640e-03, 1.0900e-04, -1.1580e-03, 4.3540e-03, 3.4100e-04, 5.4330e-03),
    (1.2516e-02, -4.2800e-04, -1.1960e-03, 1.0027e-02, -7.4100e-04, 4.8150e-03),
]

# The tool: sphere centre 0.09 m beyond the flange along its z (0.08 m shaft, sphere r 0.015 m).
TOOL_OFFSET = 0.09

# A table-wiping start (README): tool 0.5 m in front of the base, 0.15 m high, pointing down.
# q6 = q2 - q4 points the tool straight down when q1 = q3 = q5 = 0.
TABLE_Q0 = np.array([0.0, 0.182, 0.0, -2.400, 0.0, 2.582, 0.785])


def build(time_step=0.0):
    """Plant and SceneGraph with the Panda, parsed strictly: a Drake parser warning is an error
    (without it Drake would replace an impossible inertia by a valid one with only a warning)."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step)
    parser = Parser(plant)
    parser.SetStrictParsing()
    parser.AddModels(str(PANDA))
    return builder, plant, scene_graph


@pytest.fixture(scope="module")
def panda():
    _, plant, _ = build()
    plant.Finalize()
    return plant


def joints(plant):
    return [plant.GetJointByName(f"panda_joint{i}") for i in range(1, 8)]


def q_vector(plant, q_by_joint):
    """Drake's position vector from joint-ordered values (Drake orders positions its own way)."""
    q = np.zeros(plant.num_positions())
    for joint, value in zip(joints(plant), q_by_joint, strict=True):
        q[joint.position_start()] = value
    return q


def random_configurations(count, seed):
    rng = np.random.default_rng(seed)
    return [rng.uniform(Q_MIN, Q_MAX) for _ in range(count)]


def dh_transform(a, d, alpha, theta):
    """Craig's modified DH: Rot_x(alpha) Trans_x(a) Rot_z(theta) Trans_z(d)."""
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    return np.array(
        [
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -d * sa],
            [st * sa, ct * sa, ca, d * ca],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def dh_frames(q):
    """World poses of the DH frames 1..7 and the flange (frame 8)."""
    X = np.eye(4)
    out = []
    for (a, d, alpha), theta in zip(DH, q, strict=True):
        X = X @ dh_transform(a, d, alpha, theta)
        out.append(X)
    out.append(X @ dh_transform(0.0, FLANGE_D, 0.0, 0.0))
    return out


def rotation_angle(R):
    """Angle of a rotation matrix [rad], accurate near zero (from its skew part)."""
    skew = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return float(np.arctan2(0.5 * np.linalg.norm(skew), 0.5 * (np.trace(R) - 1.0)))


def test_loads_with_seven_revolute_joints_and_their_motors():
    """A discrete plant with a SceneGraph parses the file into 7 revolute joints, each with its own
    actuator ``panda_jointN_motor``. Catches: a missing or misnamed transmission, a joint typed
    fixed/continuous, an actuator on the wrong joint."""
    _, plant, _ = build(time_step=0.002)
    plant.Finalize()
    assert plant.num_positions() == plant.num_velocities() == 7
    assert plant.num_actuators() == 7
    for i, joint in enumerate(joints(plant), start=1):
        assert isinstance(joint, RevoluteJoint)
        assert plant.GetJointActuatorByName(f"panda_joint{i}_motor").joint().name() == f"panda_joint{i}"


def test_joint_limits_equal_the_datasheet(panda):
    """Position, velocity and effort limits equal Franka's datasheet to 1e-9. Catches: a limit on the
    wrong joint (joints 4 and 6 are asymmetric), velocities of the wrist (2.61) and the shoulder
    (2.175) swapped, an effort limit dropped (Drake would read it as unlimited)."""
    js = joints(panda)
    np.testing.assert_allclose([j.position_lower_limits()[0] for j in js], Q_MIN, rtol=0, atol=EXACT)
    np.testing.assert_allclose([j.position_upper_limits()[0] for j in js], Q_MAX, rtol=0, atol=EXACT)
    np.testing.assert_allclose([j.velocity_upper_limits()[0] for j in js], V_MAX, rtol=0, atol=EXACT)
    np.testing.assert_allclose([j.velocity_lower_limits()[0] for j in js], -V_MAX, rtol=0, atol=EXACT)
    efforts = [panda.GetJointActuatorByName(f"panda_joint{i}_motor").effort_limit() for i in range(1, 8)]
    np.testing.assert_allclose(efforts, TAU_MAX, rtol=0, atol=EXACT)


@pytest.mark.parametrize("case", range(11))
def test_link_and_flange_poses_equal_the_modified_dh_product(panda, case):
    """Every link frame panda_link1..7 and the flange panda_link8 sit where the product of Craig's
    modified-DH transforms puts them, to 1e-9 m and 1e-9 rad, at q = 0 and at ten random
    configurations within the limits. Catches: a wrong DH → URDF conversion (the sign of
    −d sin α, rpy about the wrong axis, a and d swapped, standard DH used instead of modified),
    a joint axis other than z."""
    q = np.zeros(7) if case == 0 else random_configurations(10, seed=7)[case - 1]
    context = panda.CreateDefaultContext()
    panda.SetPositions(context, q_vector(panda, q))
    for i, X_ref in enumerate(dh_frames(q), start=1):
        X = panda.GetFrameByName(f"panda_link{i}").CalcPoseInWorld(context).GetAsMatrix4()
        assert np.max(np.abs(X[:3, 3] - X_ref[:3, 3])) <= EXACT, f"panda_link{i} position"
        assert rotation_angle(X[:3, :3].T @ X_ref[:3, :3]) <= EXACT, f"panda_link{i} orientation"


def file_inertials():
    """{link: (mass, centre of mass, rotational inertia about the centre of mass)} as written in the
    file, read with a plain XML parser (URDF's <inertia> is about the <inertial> origin)."""
    out = {}
    for link in ET.parse(PANDA).getroot().iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        origin = inertial.find("origin")
        assert origin is None or float(np.abs(np.array(origin.get("rpy", "0 0 0").split(), float)).max()) == 0
        c = np.array((origin.get("xyz") if origin is not None else "0 0 0").split(), float)
        e = {k: float(v) for k, v in inertial.find("inertia").attrib.items()}
        I = np.array(
            [
                [e["ixx"], e["ixy"], e["ixz"]],
                [e["ixy"], e["iyy"], e["iyz"]],
                [e["ixz"], e["iyz"], e["izz"]],
            ]
        )
        out[link.get("name")] = (float(inertial.find("mass").get("value")), c, I)
    return out


def test_every_link_is_physically_valid(panda):
    """Every body with mass (base, links 1–7, tool), as written in the file, has m > 0 and a
    rotational inertia about its centre of mass that is positive definite and satisfies the
    triangle inequality (λ_i + λ_j ≥ λ_k, to 1e-12 kg m²); Drake's parsed inertia equals the
    file's (to 1e-12), i.e. Drake did not repair it. Catches: a typo in a moment that makes the
    tensor impossible for any mass distribution, a chosen (base, tool) inertia too small for its
    shape. (Sign flips and misplaced entries that stay feasible are the Gaz comparison's job.)"""
    inertials = file_inertials()
    assert sorted(inertials) == sorted([f"panda_link{i}" for i in range(8)] + ["tool"])
    for name, (m, c, I_com) in inertials.items():
        assert m > 0, name
        lam = np.linalg.eigvalsh(I_com)
        assert lam[0] > 0, name
        for k in range(3):
            assert lam.sum() - 2 * lam[k] >= -1e-12, f"{name}: triangle inequality, {lam}"
        M = panda.GetBodyByName(name).default_spatial_inertia()
        assert M.get_mass() == pytest.approx(m, abs=1e-12)
        np.testing.assert_allclose(M.get_com(), c, rtol=0, atol=1e-12)
        I_Bo = M.CalcRotationalInertia().CopyToFullMatrix3()
        np.testing.assert_allclose(I_Bo - m * (c @ c * np.eye(3) - np.outer(c, c)), I_com, rtol=0, atol=1e-12)


def test_inertial_parameters_are_gaz_et_als():
    """Links 1–7 carry Gaz et al.'s identified mass, centre of mass and inertia (to 1e-12), in the
    DH link frames (that the link frames are the DH frames is the forward-kinematics test's job).
    Catches: a typo or a sign flip in a published number, two links' rows swapped, the inertia's
    (xx, xy, xz, yy, yz, zz) order misread. Some of these (link 1's c_z and moments other than
    I_zz) do not enter the fixed-base dynamics, so only this comparison sees them."""
    inertials = file_inertials()
    for i in range(7):
        m, c, I = inertials[f"panda_link{i + 1}"]
        xx, xy, xz, yy, yz, zz = GAZ_INERTIAS[i]
        assert m == pytest.approx(GAZ_MASSES[i], abs=1e-12), i + 1
        np.testing.assert_allclose(c, GAZ_COMS[i], rtol=0, atol=1e-12)
        np.testing.assert_allclose(I, [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]], rtol=0, atol=1e-12)


def test_the_arm_weighs_what_franka_says(panda):
    """The arm with its base weighs within Franka's published 17.8–18.0 kg (Drake's parsed masses;
    Gaz et al.'s links 1–7 sum to 16.062 kg). The base (panda_link0) is not identified: its
    1.84 kg is the remainder to 17.9 kg, a choice (README), so this checks the sum of the other
    masses, not the base. Catches: a mass off by a large amount, the tool (0.1 kg) or a gripper
    counted as arm."""
    masses = [panda.GetBodyByName(f"panda_link{i}").default_mass() for i in range(8)]
    assert sum(masses[1:]) == pytest.approx(sum(GAZ_MASSES), abs=1e-9)
    assert 17.8 <= sum(masses) <= 18.0, sum(masses)


@pytest.mark.parametrize("seed", [11, 12, 13, 14])
def test_pinocchio_mass_matrix_and_gravity_equal_drakes(panda, seed):
    """Pinocchio (urdfdom's parser, its own algorithms) and Drake compute the same mass matrix and
    gravity torques from the file, to 1e-9, at random configurations. Drake's gravity generalized
    force is −g(q), Pinocchio's computeGeneralizedGravity is +g(q). Catches: URDF that only one
    parser reads as intended (Drake extensions, a frame convention that differs), an
    inertia Drake repairs or Pinocchio drops, a tool not merged into link 7. urdfdom logs an error
    for each <capsule> and drops it (geometry only); the model itself must still build."""
    model = pin.buildModelFromUrdf(str(PANDA))
    data = model.createData()
    assert model.nq == 7
    model.gravity.linear = panda.gravity_field().gravity_vector()
    # Pinocchio's configuration index of each of Drake's joints
    pin_index = [model.joints[model.getJointId(j.name())].idx_q for j in joints(panda)]
    context = panda.CreateDefaultContext()
    for q in random_configurations(3, seed):
        q_drake = q_vector(panda, q)
        q_pin = np.zeros(7)
        q_pin[pin_index] = q
        panda.SetPositions(context, q_drake)
        order = [j.velocity_start() for j in joints(panda)]  # Drake's rows, joint-ordered
        H_drake = panda.CalcMassMatrix(context)[np.ix_(order, order)]
        g_drake = panda.CalcGravityGeneralizedForces(context)[order]
        H_pin = pin.crba(model, data, q_pin)
        H_pin = np.triu(H_pin) + np.triu(H_pin, 1).T  # crba fills the upper triangle
        g_pin = pin.computeGeneralizedGravity(model, data, q_pin)
        np.testing.assert_allclose(H_pin[np.ix_(pin_index, pin_index)], H_drake, rtol=0, atol=EXACT)
        np.testing.assert_allclose(-g_pin[pin_index], g_drake, rtol=0, atol=EXACT)


def test_tool_frame_is_the_sphere_centre_beyond_the_flange(panda):
    """The frame ``tool`` is the flange frame moved 0.09 m along the flange's z (0.107 + 0.09 =
    0.197 m from panda_link7's origin), with the flange's orientation, at every configuration
    (q = 0 and random ones, to 1e-9 m / 1e-9 rad); the tool's sphere is centred on it. Catches: the
    tool offset along the wrong axis, the tool welded to link 7 instead of the flange, a task
    point at the shaft's end instead of the sphere's centre."""
    context = panda.CreateDefaultContext()
    tool = panda.GetFrameByName("tool")
    for q in [np.zeros(7), *random_configurations(5, seed=21)]:
        panda.SetPositions(context, q_vector(panda, q))
        X_ref = dh_frames(q)[-1] @ RigidTransform([0.0, 0.0, TOOL_OFFSET]).GetAsMatrix4()
        X = tool.CalcPoseInWorld(context).GetAsMatrix4()
        assert np.max(np.abs(X[:3, 3] - X_ref[:3, 3])) <= EXACT
        assert rotation_angle(X[:3, :3].T @ X_ref[:3, :3]) <= EXACT
    X_7T = tool.CalcPose(context, panda.GetFrameByName("panda_link7"))
    np.testing.assert_allclose(X_7T.translation(), [0.0, 0.0, FLANGE_D + TOOL_OFFSET], rtol=0, atol=EXACT)


def _proximity(inspector, geometry):
    props = inspector.GetProximityProperties(geometry)
    return (
        props.GetProperty("material", "hunt_crossley_dissipation"),
        props.GetProperty("material", "point_contact_stiffness"),
        props.GetProperty("material", "coulomb_friction"),
    )


def test_tool_contact_properties_equal_arm4s_and_the_arm_ignores_itself():
    """The tool's sphere and shaft carry arm4's tool contact properties (stiffness, Hunt–Crossley
    dissipation, friction: read from arm4.urdf, compared exactly), and no pair of the arm's own
    geometries is a collision candidate. Catches: the two models drifting apart in contact
    behaviour, a tool geometry left with Drake's defaults, a link missing from the self-collision
    filter."""
    builder, plant, scene_graph = build()
    Parser(plant).AddModels(str(models_dir() / "arm4.urdf"))
    plant.Finalize()
    inspector = scene_graph.model_inspector()
    by_name = {inspector.GetName(g): g for g in inspector.GetAllGeometryIds(Role.kProximity)}
    arm4_tool = _proximity(inspector, by_name["arm4::tool_collision"])
    for name in ("panda::tool_collision", "panda::tool_shaft_collision"):
        dissipation, stiffness, friction = _proximity(inspector, by_name[name])
        assert (dissipation, stiffness) == arm4_tool[:2], name
        assert (friction.static_friction(), friction.dynamic_friction()) == (
            arm4_tool[2].static_friction(),
            arm4_tool[2].dynamic_friction(),
        )
    panda_ids = {g for n, g in by_name.items() if n.startswith("panda::")}
    assert len(panda_ids) == 13  # 11 link shapes and the tool's shaft and sphere
    for a, b in inspector.GetCollisionCandidates():
        assert not ({a, b} <= panda_ids), (inspector.GetName(a), inspector.GetName(b))


def test_moving_links_are_capsules_for_the_obstacle_criterion():
    """Every collision shape of links 1–7 and the tool's shaft is a capsule, the tool's contact shape a
    sphere of r 0.015 m, the welded base a cylinder. nsdrake's obstacle criterion refines the
    distance to capsules and spheres with Drake's exact point distance and falls back to the
    GJK witness (~1e-5 m) for other shapes. Catches: capsules swapped for cylinders to quieten
    Pinocchio's parser, which would silently coarsen the obstacle gradients."""
    builder, plant, scene_graph = build()
    plant.Finalize()
    inspector = scene_graph.model_inspector()
    shapes = {}
    for body in ["panda_link0", *(f"panda_link{i}" for i in range(1, 8)), "tool"]:
        for g in plant.GetCollisionGeometriesForBody(plant.GetBodyByName(body)):
            shapes[inspector.GetName(g)] = (body, inspector.GetShape(g))
    assert len(shapes) == 13
    for name, (body, shape) in shapes.items():
        if body == "panda_link0":
            assert isinstance(shape, Cylinder), name
        elif name == "panda::tool_collision":
            assert isinstance(shape, Sphere) and shape.radius() == 0.015
        else:
            assert isinstance(shape, Capsule), name


def test_table_start_configuration_reaches_the_table_in_front_pointing_down():
    """At the README's q0 the tool's centre is 0.5 m in front of the base and 0.15 m high (to 2 mm,
    q0 is rounded to 1e-3 rad), the tool points straight down (to 1e-9 rad), every joint is at
    least 0.5 rad inside its limits, the position Jacobian's smallest singular value is above
    0.2 m/rad, and with a table whose top touches the tool's sphere every arm link is at least
    5 cm above it. Catches: a q0 quoted for a different model (e.g. another tool length), a start
    next to a singularity or a limit, links resting on the table."""
    builder, plant, scene_graph = build()
    table_top = 0.15 - 0.015  # the sphere's lowest point
    plant.RegisterCollisionGeometry(
        plant.world_body(),
        RigidTransform([0.6, 0.0, table_top - 0.01]),
        Box(0.8, 1.0, 0.02),  # x from 0.2 m to 1.0 m in front of the base
        "table",
        ProximityProperties(),
    )
    plant.Finalize()
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    context = plant.GetMyMutableContextFromRoot(root)
    plant.SetPositions(context, q_vector(plant, TABLE_Q0))
    X = plant.GetFrameByName("tool").CalcPoseInWorld(context)
    np.testing.assert_allclose(X.translation(), [0.5, 0.0, 0.15], rtol=0, atol=2e-3)
    z_tool = X.rotation().matrix()[:, 2]
    down = np.array([0.0, 0.0, -1.0])
    assert np.arctan2(np.linalg.norm(np.cross(z_tool, down)), z_tool @ down) <= EXACT
    assert np.min(np.minimum(TABLE_Q0 - Q_MIN, Q_MAX - TABLE_Q0)) >= 0.5
    J = plant.CalcJacobianTranslationalVelocity(
        context,
        JacobianWrtVariable.kV,
        plant.GetFrameByName("tool"),
        np.zeros(3),
        plant.world_frame(),
        plant.world_frame(),
    )
    assert np.linalg.svd(J, compute_uv=False)[-1] >= 0.2
    query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(root))
    inspector = query.inspector()
    checked = 0
    for pair in query.ComputeSignedDistancePairwiseClosestPoints(max_distance=10.0):
        names = {inspector.GetName(pair.id_A), inspector.GetName(pair.id_B)}
        if "table" not in names or any(n.startswith("panda::tool") for n in names):
            continue
        assert pair.distance >= 0.05, names
        checked += 1
    assert checked == 10  # links 1–7's cylinders (the base is welded, so Drake filters it against the world)

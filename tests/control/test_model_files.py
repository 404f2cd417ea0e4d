"""Model files as vendors ship them (issue 36, item 1): a 7-joint arm with OBJ meshes, a
package.xml, package:// and relative URIs, as URDF, SDF and Drake model directives, each
loaded by ControllerModel.from_file, against the same arm's mesh-free URDF text; and a
payload on the tool (item 4), against an arm whose URDF carries the payload as a link.

The models are written here (tests/vendor_arm.py), never downloaded."""

from __future__ import annotations

import re

import numpy as np
import pytest
from pydrake.geometry import Sphere
from pydrake.math import RigidTransform
from scipy.spatial import ConvexHull

from nsdrake.control import ControllerConfig, ControllerConfigError, ControllerModel, ControllerStep, Obstacle
from nsdrake.control.model import PinocchioDynamics, pinocchio_urdf
from nsdrake.control.model_files import Payload
from tests.vendor_arm import Q0, fin_vertices, mesh_free_urdf, write_vendor_arm

POSE = ("x", "y", "z", "rx", "ry", "rz")
FAR = [Obstacle("far", Sphere(0.1), RigidTransform([5.0, 0.0, 0.0]))]  # makes the model read its geometry
TERMS = ("H", "g", "Cv", "C", "J_spatial")


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    return write_vendor_arm(tmp_path_factory.mktemp("vendor"))


@pytest.fixture(scope="module")
def reference():
    return ControllerModel.from_urdf(mesh_free_urdf(), tool_frame="tool", task_axes=POSE)


def states(count: int, seed: int):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield rng.uniform(-2.5, 2.5, 7), rng.uniform(-1.5, 1.5, 7)


def worst_difference(a: ControllerModel, b: ControllerModel, seed: int = 3) -> float:
    """The largest difference of H, g, C q̇, C and J between two models, relative to the
    term's size, at seeded random states."""
    sa, sb, worst = a.create_scratch(), b.create_scratch(), 0.0
    for q, v in states(4, seed):
        x, y = a.terms(sa, q, v, True), b.terms(sb, q, v, True)
        for name in TERMS:
            u, w = getattr(x, name), getattr(y, name)
            worst = max(worst, float(np.max(np.abs(u - w))) / max(1.0, float(np.max(np.abs(w)))))
    return worst


def torques(model: ControllerModel, seed: int = 5) -> np.ndarray:
    """τ of a pose-holding ControllerStep at seeded states near Q0 (one fresh tick each)."""
    step = ControllerStep(controller_model=model, config=ControllerConfig(period=0.001), task_axes=POSE)
    context = model.plant.CreateDefaultContext()
    model.plant.SetPositions(context, Q0)
    X = model.arm.tool_frame.CalcPoseInWorld(context)
    quaternion = X.rotation().ToQuaternion().wxyz()
    rng, zero, out = np.random.default_rng(seed), np.zeros(3), []
    for _ in range(3):
        step.reset()
        q, v = Q0 + 0.2 * rng.standard_normal(7), 0.5 * rng.standard_normal(7)
        result = step.step(0.0, q, v, None, X.translation(), zero, zero, None, quaternion, zero, zero)
        out.append(result.tau.copy())
    return np.array(out)


@pytest.mark.parametrize("kind", ["urdf", "sdf", "directives"])
def test_a_model_file_gives_the_mesh_free_arms_terms_and_torques(arm, reference, kind):
    """URDF (package:// and ../ meshes), SDF (the same URIs) and model directives (a
    package:// model welded by the directives) load through one constructor, on the fast
    path (Pinocchio), with the mesh-free text's H, g, C q̇, C, J and τ to 1e-9. A mesh URI
    resolved wrongly fails the load; a joint placed or an inertia moved wrongly in the SDF or
    in the Pinocchio tree built from the plant fails the comparison. Without obstacles the
    model reads no geometry; with one, the link meshes are its geometry."""
    model = ControllerModel.from_file(getattr(arm, kind), tool_frame="tool", task_axes=POSE)
    assert model.dynamics == "pinocchio"
    assert model.joint_names == reference.joint_names
    assert worst_difference(model, reference) < 1e-9
    tau, expected = torques(model), torques(reference)
    assert np.max(np.abs(tau - expected)) < 1e-9 * max(1.0, float(np.max(np.abs(expected))))
    assert model.scene_graph is None and model.link_geometries == []  # no obstacle: no geometry read
    model = ControllerModel.from_file(getattr(arm, kind), tool_frame="tool", task_axes=POSE, obstacles=FAR)
    names = {model.scene_graph.model_inspector().GetName(g).split("::")[-1] for g in model.link_geometries}
    assert names == {"upper", "fin", "wrist"}


def test_the_pinocchio_tree_from_drakes_plant_equals_pinocchios_own_urdf_reader(reference):
    """The fast terms come from a Pinocchio model built from Drake's plant; Pinocchio's own
    URDF parser, given the same text, must give the same H, g, C q̇, C and J (a reference
    nsdrake's builder did not write: a wrong centre-of-mass shift, a joint frame off by the
    child's pose or a reversed axis changes them)."""
    own = PinocchioDynamics(mesh_free_urdf(), reference.arm, reference.plant.gravity_field().gravity_vector())
    assert own._model.nq == 7 and pinocchio_urdf(mesh_free_urdf())
    for q, v in states(4, seed=11):
        a, b = reference.pinocchio.terms(q, v, True), own.terms(q, v, True)
        for name in TERMS:
            x, y = getattr(a, name), getattr(b, name)
            assert np.max(np.abs(x - y)) < 1e-9 * max(1.0, float(np.max(np.abs(y)))), name


GRIPPER_URDF = """<?xml version="1.0"?>
<robot name="gripper">
  <link name="palm">
    <inertial><origin xyz="0.01 0.02 0.04"/><mass value="0.7"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.0015"/></inertial>
  </link>
</robot>
"""
OFFSET_DIRECTIVES = """directives:
- add_model:
    name: arm7
    file: package://myarm/urdf/arm7_free.urdf
- add_weld:
    parent: world
    child: arm7::base
    X_PC:
      translation: [0.1, -0.2, 0.3]
      rotation: !Rpy { deg: [10.0, -20.0, 30.0] }
- add_model:
    name: gripper
    file: package://myarm/urdf/gripper.urdf
- add_weld:
    parent: arm7::link7
    child: gripper::palm
    X_PC:
      translation: [0.03, 0.0, 0.12]
      rotation: !Rpy { deg: [0.0, 90.0, 45.0] }
"""


def test_welds_with_an_offset_give_pinocchio_drakes_terms(arm):
    """Model directives that weld the arm's base to the world and a gripper to link 7, each
    with an offset (a translation and a rotation: the weld joint's own pose X_FM, which a
    URDF's fixed joint never has; Drake keeps a URDF's in the parent frame): the Pinocchio
    tree built from Drake's plant gives Drake's own H, g, C q̇, C and J (ControllerModel
    with dynamics "drake": the plant's calls) to 1e-9, and the offsets act (the terms differ
    from the identity welds' by far more). Catches a weld's own pose dropped in the
    Pinocchio tree (every other weld in the tests is the identity), issue 46's mistake 7."""
    (arm.package / "urdf" / "gripper.urdf").write_text(GRIPPER_URDF)
    path = arm.package / "offset_welds.dmd.yaml"
    path.write_text(OFFSET_DIRECTIVES)
    fast = ControllerModel.from_file(path, tool_frame="tool", task_axes=POSE, dynamics="pinocchio")
    plant_calls = ControllerModel.from_file(path, tool_frame="tool", task_axes=POSE, dynamics="drake")
    assert (fast.dynamics, plant_calls.dynamics) == ("pinocchio", "drake")
    assert worst_difference(fast, plant_calls) < 1e-9
    identity = path.with_name("identity_welds.dmd.yaml")
    identity.write_text(
        re.sub(r"    X_PC:\n(      .*\n)+", "", OFFSET_DIRECTIVES)
    )  # the same welds, no offset
    plain = ControllerModel.from_file(identity, tool_frame="tool", task_axes=POSE, dynamics="drake")
    assert worst_difference(plain, plant_calls) > 1e-2


def test_packages_resolve_from_package_xml_ros_package_path_and_the_argument(arm, tmp_path, monkeypatch):
    """Without its package.xml the URDF's package://myarm/... is unknown: one line naming the
    file, the package and where packages come from. Then it loads from ROS_PACKAGE_PATH and
    from packages={"myarm": folder}, each alone."""
    package = write_vendor_arm(tmp_path / "ws").package
    (package / "package.xml").unlink()
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    path = package / "urdf" / "arm7.urdf"
    with pytest.raises(ControllerConfigError) as e:
        ControllerModel.from_file(path, tool_frame="tool", task_axes=POSE, obstacles=FAR)
    message = str(e.value)
    assert "\n" not in message and message.startswith("model_file: arm7.urdf: Drake cannot parse it")
    assert "'myarm'" in message and "packages={name: folder}" in message
    model = ControllerModel.from_file(
        path, tool_frame="tool", task_axes=POSE, packages={"myarm": package}, obstacles=FAR
    )
    assert len(model.link_geometries) == 3
    # ROS_PACKAGE_PATH: a folder with the package.xml below it (the original package).
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(arm.package.parent))
    model = ControllerModel.from_file(path, tool_frame="tool", task_axes=POSE, obstacles=FAR)
    assert len(model.link_geometries) == 3


@pytest.mark.parametrize(
    "arguments, where",
    [
        ({"path": "arm7.txt"}, "model_file: 'arm7.txt' must be a .urdf, .sdf, .dmd.yaml file"),
        ({"path": "missing.urdf"}, "model_file: 'missing.urdf' is not a file"),
        ({"packages": {"myarm": "/no/such/folder"}}, "packages: myarm: '/no/such/folder' is not a folder"),
        ({"payload": Payload(mass=-0.6)}, "payload: mass must be a finite number > 0 [kg], got -0.6"),
        # issue 43, item 3: the one number rule (True was a 1 kg payload)
        ({"payload": Payload(mass=True)}, "payload: mass must be a finite number > 0 [kg] as real numbers "
         "(booleans refused), got True"),
        ({"payload": Payload(mass="0.6")}, "payload: mass must be a finite number > 0 [kg] as real numbers "
         "(text refused), got '0.6'"),
        ({"payload": Payload(mass=0.6 + 0j)}, "payload: mass must be a finite number > 0 [kg] as real "
         "numbers (complex values refused)"),
        ({"payload": Payload(mass=0.6, com=(0, 0, True))}, "payload: com must be three finite numbers within "
         "10 m of the tool frame [m] as real numbers (booleans refused)"),
        ({"payload": Payload(mass=0.6, com=("0", 0, 0))}, "payload: com must be three finite numbers"),
        ({"payload": Payload(0.6, inertia=(1e-3, 1e-3, 1e-3, False, 0, 0))}, "payload: inertia must be a "
         "symmetric (3, 3) matrix or (ixx, iyy, izz, ixy, ixz, iyz) [kg m²] as real numbers (booleans "
         "refused)"),
        ({"payload": Payload(mass=0.6, com=(0, 0))}, "payload: com must be three finite numbers"),
        ({"payload": Payload(0.6, inertia=(1.0, 0.1, 0.1, 0, 0, 0))}, "payload: inertia is not physical"),
    ],
)  # fmt: skip
def test_bad_model_file_arguments_are_refused_in_one_line(arm, arguments, where):
    path = arguments.pop("path", arm.urdf)
    with pytest.raises(ControllerConfigError) as e:
        ControllerModel.from_file(path, tool_frame="tool", task_axes=POSE, **arguments)
    assert "\n" not in str(e.value) and str(e.value).startswith(where)


# The physical rules a model file passes before Drake reads it, each broken once in the
# mesh-free arm: (what is changed, the line's words). Drake itself would take some of these
# (a triangle-inequality inertia, a negative-size box) or say something else.
URDF_RULES = {
    "mass": (('<mass value="3.0"/>', '<mass value="-3.0"/>'), "link 'link1': mass -3 kg must be > 0"),
    "inertia": (
        ('iyy="0.03" iyz="0" izz="0.008"', 'iyy="0.03" iyz="0" izz="0.07"'),
        "link 'link2': inertia breaks the triangle inequality",
    ),
    "geometry": (
        (
            '<link name="tool">\n',
            '<link name="tool">\n    <collision><geometry><box size="0.1 0 0.1"/></geometry></collision>\n',
        ),
        "link 'tool': collision box size 0 must be > 0",
    ),
    "tree": (
        (
            "</robot>",
            '  <joint name="loop" type="fixed"><parent link="link7"/><child link="link3"/></joint>\n</robot>',
        ),
        "link 'link3': child of two joints ('j3' and 'loop'): a kinematic loop",
    ),
}
URDF_SPELLINGS = (".urdf", ".URDF", ".Urdf")  # what model_file_problem accepts: any case


@pytest.mark.parametrize("rule", list(URDF_RULES))
@pytest.mark.parametrize("suffix", URDF_SPELLINGS)
def test_every_spelling_of_urdf_goes_through_every_urdf_rule(tmp_path, suffix, rule):
    """A URDF file that breaks one rule, named arm7 with each spelling the file check
    accepts (.urdf, .URDF, .Urdf): ControllerModel.from_file, from_urdf (a path) and the
    simulated station (a scenario's arm.urdf) each refuse it in the rule's one line, naming
    the file, before Drake reads it (issue 46, mistake 8). Catches the rules run only for a
    lower-case .urdf (an upper-case file accepted by the file check and then skipping them:
    Drake takes a triangle-inequality inertia, a zero-size box and a loop silently or
    fails with its own words)."""
    from nsdrake.experiment.scenario import ScenarioError

    (old, replacement), words = URDF_RULES[rule]
    text = mesh_free_urdf()
    assert old in text
    path = tmp_path / f"arm7{suffix}"
    path.write_text(text.replace(old, replacement, 1))
    # each API names its own argument: from_file's model file, from_urdf's controller model
    for load, argument in (
        (ControllerModel.from_file, "model_file"),
        (ControllerModel.from_urdf, "controller_model"),
    ):
        with pytest.raises(ControllerConfigError) as e:
            load(path, tool_frame="tool", task_axes=POSE)
        assert str(e.value).startswith(f"{argument}: arm7{suffix}: {words}"), str(e.value)
    with pytest.raises(ScenarioError) as e:
        station_with_arm(tmp_path, path.name)
    assert f"arm7{suffix}: {words}" in str(e.value) and "\n" not in str(e.value), str(e.value)


@pytest.mark.parametrize("suffix", (".sdf", ".SDF"))
def test_every_spelling_of_sdf_goes_through_the_sdf_rules(arm, tmp_path, suffix):
    """The vendor arm's SDF with link 1's mass negative, named with each spelling: refused
    by from_file and by the station in one line naming the file and the link (Drake's SDF
    parser only warns, and simulates a "repaired" 1 kg body). Catches the SDF rules run for
    a lower-case .sdf only."""
    from nsdrake.experiment.scenario import ScenarioError

    path = arm.sdf.with_name(f"bad{suffix}")
    path.write_text(arm.sdf.read_text().replace("<mass>3.0</mass>", "<mass>-3.0</mass>", 1))
    with pytest.raises(ControllerConfigError) as e:
        ControllerModel.from_file(path, tool_frame="tool", task_axes=POSE)
    assert str(e.value) == f"model_file: bad{suffix}: link 'link1': mass -3 kg must be > 0"
    with pytest.raises(ScenarioError) as e:
        station_with_arm(tmp_path, str(path))
    assert f"bad{suffix}: link 'link1': mass -3 kg must be > 0" in str(e.value), str(e.value)


def station_with_arm(folder, model: str):
    """The simulated station of a scenario whose arm is the file ``model`` (relative to
    ``folder``, where the scenario file is written)."""
    from pydrake.systems.framework import DiagramBuilder

    from nsdrake.experiment.scenario import load_scenario_file
    from nsdrake.experiment.scenario_station import add_scenario_station

    joints = ", ".join(f"j{k + 1}: {q}" for k, q in enumerate(Q0))
    scenario = folder / "scenario.yaml"
    scenario.write_text(
        f"arm: {{urdf: {model}, initial_positions: {{{joints}}}}}\nplate: {{position: [1.5, 1.5, -1.0]}}\n"
        "task: {axes: [x, y, z, rx, ry, rz]}\nreference: {approach_speed: 0.0}\n"
        "report: {compare_without_null_space_task: false, checks: []}\n"
    )
    return add_scenario_station(DiagramBuilder(), load_scenario_file(scenario))


def test_a_mesh_on_a_link_is_seen_by_the_obstacle_criterion_as_its_convex_hull(arm):
    """A ball in front of the mouth of link 5's U-shaped mesh: the criterion's d_min is the
    distance to the U's convex hull (SciPy's hull of the OBJ's vertices, the link's pose from
    Drake), 0.03 m, not to the U itself (0.042 m) and not to another link: the mesh reaches
    the criterion, as Drake treats it."""
    X_W5 = _link_pose(arm, "link5")
    centre_5 = np.array([0.26, 0.0, 0.08])  # 6 cm in front of the mouth (x = 0.20), radius 3 cm
    ball = Obstacle("ball", Sphere(0.03), RigidTransform(X_W5 @ centre_5))
    model = ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE, obstacles=[ball])
    config = ControllerConfig(period=0.001)
    config.desired_null_space.criteria.obstacle.gain = 1.0
    step = ControllerStep(controller_model=model, config=config, task_axes=POSE)
    context = model.plant.CreateDefaultContext()
    model.plant.SetPositions(context, Q0)
    X = model.arm.tool_frame.CalcPoseInWorld(context)
    zero = np.zeros(3)
    result = step.step(
        0.0,
        Q0,
        np.zeros(7),
        None,
        X.translation(),
        zero,
        zero,
        None,
        X.rotation().ToQuaternion().wxyz(),
        zero,
        zero,
    )
    d_min = result.criteria[0, 7 + 1]
    hull = ConvexHull(fin_vertices())
    d_hull = float(np.max(hull.equations[:, :3] @ centre_5 + hull.equations[:, 3])) - 0.03
    assert d_hull == pytest.approx(0.03, abs=1e-12)  # the geometry is what the docstring says
    # Drake's distance between a mesh's hull and a ball is iterative (GJK), good to ~2e-5 m
    # here (criteria/obstacle.py says so for capsules); the U itself is 12 mm farther.
    assert d_min == pytest.approx(d_hull, abs=5e-5)


def _link_pose(arm, link: str) -> RigidTransform:
    model = ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE, dynamics="drake")
    context = model.plant.CreateDefaultContext()
    model.plant.SetPositions(context, Q0)
    return model.plant.GetFrameByName(link).CalcPoseInWorld(context)


PAYLOAD = Payload(mass=0.6, com=(0.01, -0.02, 0.05), inertia=(3e-3, 3e-3, 2e-3, 1e-4, -2e-4, 3e-4))


def _urdf_with_payload_link(payload: Payload) -> str:
    """The mesh-free arm with the payload as a URDF link on a fixed joint at the tool."""
    xx, yy, zz, xy, xz, yz = payload.inertia
    link = (
        f'<link name="load"><inertial><origin xyz="{" ".join(map(str, payload.com))}"/>'
        f'<mass value="{payload.mass}"/><inertia ixx="{xx}" iyy="{yy}" izz="{zz}" ixy="{xy}" ixz="{xz}" '
        f'iyz="{yz}"/></inertial></link><joint name="load_joint" type="fixed"><parent link="tool"/>'
        '<child link="load"/></joint>'
    )
    return mesh_free_urdf().replace("</robot>", link + "</robot>")


@pytest.mark.parametrize("source", ["file", "text"])
def test_a_payload_is_the_arm_carrying_that_link(arm, source):
    """A payload given to the model (mass, centre of mass and inertia on the tool frame) gives
    the terms of a URDF that carries the same inertia as a link fixed to the tool: its centre
    of mass offset, its inertia's axes and its products all count (a com taken in the world,
    an inertia about the tool's origin, a dropped product of inertia each fail this). And
    it changes them: without it, g differs."""
    carried = ControllerModel.from_urdf(_urdf_with_payload_link(PAYLOAD), tool_frame="tool", task_axes=POSE)
    given = (
        ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE, payload=PAYLOAD)
        if source == "file"
        else ControllerModel.from_urdf(mesh_free_urdf(), tool_frame="tool", task_axes=POSE, payload=PAYLOAD)
    )
    assert given.dynamics == "pinocchio"
    assert worst_difference(given, carried) < 1e-9
    bare = ControllerModel.from_urdf(mesh_free_urdf(), tool_frame="tool", task_axes=POSE)
    assert worst_difference(bare, carried) > 1e-3


def test_from_urdf_keeps_reading_paths_and_text(arm, reference, tmp_path):
    """from_urdf still takes a path (a .urdf goes through from_file, meshes and packages
    resolved; a URDF under another name, e.g. .xml, is read as text, as before) and text."""
    by_path = ControllerModel.from_urdf(arm.urdf, tool_frame="tool", task_axes=POSE, obstacles=FAR)
    assert len(by_path.link_geometries) == 3
    other = tmp_path / "arm7.xml"
    other.write_text(mesh_free_urdf())
    by_other_name = ControllerModel.from_urdf(str(other), tool_frame="tool", task_axes=POSE)
    assert worst_difference(by_path, reference) < 1e-9 and worst_difference(by_other_name, reference) < 1e-9


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("<mass>1.2</mass>", "<mass>-1.2</mass>", "link 'link5': mass -1.2 kg must be > 0"),
        ("<ixx>0.008</ixx>", "<ixx>0.02</ixx>", "link 'link5': inertia breaks the triangle inequality"),
    ],
)
def test_an_sdf_link_that_is_not_physical_is_refused_in_one_line(tmp_path, old, new, message):
    """Drake's SDF parser only warns about a negative mass or an impossible inertia and
    simulates a "repaired" 1 kg body; the controller's model and the station refuse the file,
    naming it and the link."""
    arm = write_vendor_arm(tmp_path)
    text = arm.sdf.read_text()
    assert text.count(old) == 1
    arm.sdf.write_text(text.replace(old, new))
    with pytest.raises(ControllerConfigError) as e:
        ControllerModel.from_file(arm.sdf, tool_frame="tool", task_axes=POSE)
    assert str(e.value).startswith(f"model_file: arm7.sdf: {message}") and "\n" not in str(e.value)


def test_drakes_refusal_keeps_the_same_words_wherever_the_file_is_installed(tmp_path):
    """Drake's message repeats the file's path; the one line keeps 240 characters of Drake's
    words with the file's folder not counted, so the same file in a short and a deep folder
    is refused with the same line but for the folder (vendor_arms' table row of TALOS's arm
    changed with the install folder when the cut counted the path)."""
    inertial = '<mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/>'
    name = "j" * 150  # Drake's words about a fixed joint with a mimic run past 240 characters
    urdf = f"""<robot name="r">
  <link name="base"/>
  <link name="a"><inertial>{inertial}</inertial></link>
  <link name="b"><inertial>{inertial}</inertial></link>
  <joint name="{name}" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
  <joint name="fixed_{name}" type="fixed"><parent link="a"/><child link="b"/><mimic joint="{name}"/></joint>
</robot>"""
    lines = []
    for folder in (tmp_path / "s", tmp_path / ("deep" * 30) / "er"):
        folder.mkdir(parents=True)
        (folder / "arm.urdf").write_text(urdf)
        with pytest.raises(ControllerConfigError) as e:
            ControllerModel.from_file(folder / "arm.urdf", tool_frame="b", task_axes=["x"])
        lines.append(str(e.value).replace(str(folder) + "/", ""))
    assert "cannot mimic" in lines[0] and len(lines[0]) > 240
    assert lines[0] == lines[1]

"""Every file a model is made of, as vendors write them (issues 42 and 43): include cycles,
the physical checks on included files, frame links, a floating root, a floating joint,
<mimic> joints, joints= locking, <limit effort> without a transmission, joint damping, STL
collision meshes and Drake's parser warnings. The models are the tests' own
(tests/vendor_arm.py), edited here; the references are Drake's own plants of the same
files, SciPy's convex hull and the numbers written into the files."""

from __future__ import annotations

import logging
import subprocess
import sys

import numpy as np
import pytest
import trimesh
from pydrake.geometry import Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from scipy.spatial import ConvexHull

from nsdrake.control import (
    ControllerConfig,
    ControllerConfigError,
    ControllerModel,
    ControllerStep,
    Obstacle,
    model_files,
)
from nsdrake.control.controller import torque_limits
from nsdrake.control.dynamics import ArmModel
from nsdrake.control.model_files import MODEL_WARNINGS
from nsdrake.experiment.scenario import load_scenario_file
from nsdrake.reporting.run_folder import run_to_folder
from tests.vendor_arm import FIN_BOXES, Q0, fin_vertices, write_vendor_arm

POSE = ("x", "y", "z", "rx", "ry", "rz")
ARM = [f"j{k}" for k in range(1, 8)]


def refused(path, **options) -> str:
    with pytest.raises(ControllerConfigError) as e:
        ControllerModel.from_file(path, tool_frame="tool", task_axes=POSE, **options)
    assert "\n" not in str(e.value)
    return str(e.value)


def drake_plant(path, package=None, weld: str | None = None) -> MultibodyPlant:
    """Drake's own plant of the file (no nsdrake code), ``weld`` welded to the world."""
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    if package is not None:
        parser.package_map().Add("myarm", str(package))
    parser.AddModels(str(path))
    if weld:
        plant.WeldFrames(plant.world_frame(), plant.GetBodyByName(weld).body_frame())
    plant.Finalize()
    return plant


def test_a_directives_file_that_includes_itself_is_refused_in_one_line(tmp_path):
    """Drake's AddModels recurses on a self-including directives file until the process dies
    (SIGSEGV, nothing said): the cycle is refused first, naming the chain, directly and
    through a second file. Run in a child process, so a missing check cannot kill the suite."""
    arm = write_vendor_arm(tmp_path)
    (arm.package / "loop.dmd.yaml").write_text(
        "directives:\n- add_directives:\n    file: package://myarm/loop.dmd.yaml\n"
    )
    (arm.package / "a.dmd.yaml").write_text(
        "directives:\n- add_directives:\n    file: package://myarm/b.dmd.yaml\n"
    )
    (arm.package / "b.dmd.yaml").write_text(
        "directives:\n- add_model:\n    name: x\n    file: package://myarm/urdf/arm7.urdf\n"
        "- add_directives:\n    file: package://myarm/a.dmd.yaml\n"
    )
    code = (
        "import sys\nfrom nsdrake.control import ControllerModel, ControllerConfigError\n"
        "try:\n    ControllerModel.from_file(sys.argv[1], tool_frame='tool', task_axes=['x', 'y', 'z'])\n"
        "except ControllerConfigError as e:\n    print(e)\n"
    )
    for name, chain in (
        ("loop", "loop.dmd.yaml → loop.dmd.yaml"),
        ("a", "a.dmd.yaml → b.dmd.yaml → a.dmd.yaml"),
    ):
        run = subprocess.run(
            [sys.executable, "-c", code, str(arm.package / f"{name}.dmd.yaml")],
            capture_output=True,
            text=True,
        )
        assert run.returncode == 0, run.stderr[-500:]
        assert run.stdout.count("\n") == 1 and f"an include cycle ({chain})" in run.stdout


@pytest.mark.parametrize(
    "kind, old, new, message",
    [
        ("sdf", "<mass>1.2</mass>", "<mass>0</mass>", "arm7.sdf: link 'link5': mass 0 kg must be > 0"),
        (
            "urdf",
            'ixx="0.008"',
            'ixx="-0.008"',
            "arm7_free.urdf: link 'link5': inertia must be positive definite",
        ),
    ],
)
def test_a_file_that_directives_include_gets_the_physical_checks(tmp_path, kind, old, new, message):
    """Drake "repairs" a massless or impossible link inside a directives include with a
    warning and simulates it: the included file is checked as a top-level one is."""
    arm = write_vendor_arm(tmp_path)
    included = arm.sdf if kind == "sdf" else arm.urdf_free
    text = included.read_text()
    assert text.count(old) == 1
    included.write_text(text.replace(old, new))
    if kind == "sdf":
        arm.directives.write_text(
            "directives:\n- add_model:\n    name: arm7\n    file: package://myarm/sdf/arm7.sdf\n"
        )
    assert refused(arm.directives).startswith(f"model_file: {message}")


def test_frame_links_that_cannot_move_may_be_massless_and_moving_ones_may_not(tmp_path):
    """ROS's frame links (tool0, panda_link8) have no mass on a fixed joint: they load, with
    Drake's own gravity torques. A massless link on a revolute joint is still refused."""
    arm = write_vendor_arm(tmp_path)
    text = arm.urdf.read_text()
    frame = (
        '<link name="flange"/><joint name="flange_joint" type="fixed"><parent link="link7"/>'
        '<child link="flange"/></joint>'
    )
    massless_tool = text.replace('<mass value="0.2"/>', '<mass value="0"/>').replace(
        'ixx="0.0002" ixy="0" ixz="0" iyy="0.0002" iyz="0" izz="0.0001"',
        'ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"',
    )
    assert massless_tool != text
    arm.urdf.write_text(massless_tool.replace("</robot>", frame + "</robot>"))
    model = ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE)
    plant = drake_plant(arm.urdf, arm.package)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, Q0)
    g = model.terms(model.create_scratch(), Q0, np.zeros(7), False).g
    np.testing.assert_allclose(g, -plant.CalcGravityGeneralizedForces(context), rtol=1e-12, atol=1e-12)
    arm.urdf.write_text(text.replace('<mass value="1.2"/>', '<mass value="0"/>'))
    assert "link 'link5': mass 0 kg must be > 0" in refused(arm.urdf)


def test_a_floating_root_is_welded_to_the_world_in_one_line_and_placed_by_base_pose(tmp_path, caplog):
    """A URDF without a world link (the ROS convention) loads, its root body welded to the
    world, said once naming the body; base_pose places it (the tool 1 m higher). Without the
    weld the plant has nq = 14 ≠ nv = 13 and was refused."""
    arm = write_vendor_arm(tmp_path)
    with caplog.at_level(logging.WARNING, logger="nsdrake"):
        model = ControllerModel.from_file(arm.urdf_free, tool_frame="tool", task_axes=POSE)
    lines = [r.getMessage() for r in caplog.records if "floats" in r.getMessage()]
    assert len(lines) == 1 and "root body 'base' floats" in lines[0] and "welded to the world" in lines[0]
    assert model.n == 7
    raised = ControllerModel.from_file(
        arm.urdf_free, tool_frame="tool", task_axes=POSE, base_pose=RigidTransform([0.0, 0.0, 1.0])
    )
    p = [m.terms(m.create_scratch(), Q0, np.zeros(7), False).p_WT for m in (model, raised)]
    np.testing.assert_allclose(p[1] - p[0], [0.0, 0.0, 1.0], atol=1e-12)


def test_a_plant_with_a_floating_base_is_named_as_such(tmp_path):
    """A plant built by the user with the root left floating: the message says "floating
    base" and how to weld it, not only nq != nv."""
    arm = write_vendor_arm(tmp_path)
    plant = drake_plant(arm.urdf_free, arm.package)
    with pytest.raises(ValueError, match="the body 'base' has a floating base .*weld it"):
        ArmModel(plant, plant.GetFrameByName("tool"), POSE)


def test_a_floating_joint_inside_the_arm_is_named_not_blamed_on_a_transmission(tmp_path):
    """Drake drops a URDF floating joint and then says its transmission names a joint that
    does not exist; the joint is named as a floating joint inside the arm instead."""
    arm = write_vendor_arm(tmp_path)
    text = arm.urdf.read_text()
    arm.urdf.write_text(
        text.replace('<joint name="j4" type="revolute">', '<joint name="j4" type="floating">')
    )
    message = refused(arm.urdf)
    assert message.startswith("model_file: arm7.urdf: joint 'j4': a floating joint inside the arm")
    assert "transmission" not in message.lower()


INERTIAL = (
    '<inertial><mass value="0.05"/>'
    '<inertia ixx="1e-5" iyy="1e-5" izz="1e-5" ixy="0" ixz="0" iyz="0"/></inertial>'
)
LIMIT = '<limit lower="0" upper="0.04" effort="20" velocity="0.2"/>'
FINGERS = f"""
  <link name="finger_a">{INERTIAL}</link>
  <link name="finger_b">{INERTIAL}</link>
  <joint name="finger_a_joint" type="prismatic"><parent link="tool"/><child link="finger_a"/>
    <origin xyz="0 0.03 0.02"/><axis xyz="0 1 0"/>{LIMIT}</joint>
  <joint name="finger_b_joint" type="prismatic"><parent link="tool"/><child link="finger_b"/>
    <origin xyz="0 -0.03 0.02"/><axis xyz="0 -1 0"/>{LIMIT}<mimic joint="finger_a_joint"/></joint>
</robot>"""


def with_dynamics(text: str, attributes: dict[str, str]) -> str:
    """The URDF ``text`` with ``<dynamics ATTRIBUTES/>`` on each named revolute joint."""
    for name, attribute in attributes.items():
        text = text.replace(
            f'<joint name="{name}" type="revolute">',
            f'<joint name="{name}" type="revolute"><dynamics {attribute}/>',
        )
    return text


def test_a_mimic_joint_is_refused_in_one_line_unless_locked_with_its_leader(tmp_path):
    """Drake couples a <mimic> joint to its leader; the controller's joints are independent,
    so a model that keeps it is refused in one line naming both. With joints=[j1..j7] the
    fingers are locked (the follower at its leader's image) and their mass joins the tool:
    Drake's own plant, its fingers at 0.02 m each, gives the same gravity torques."""
    arm = write_vendor_arm(tmp_path)
    arm.urdf.write_text(arm.urdf.read_text().replace("</robot>", FINGERS))
    message = refused(arm.urdf)
    assert "finger_b_joint" in message and "mimics 'finger_a_joint'" in message
    model = ControllerModel.from_file(
        arm.urdf, tool_frame="tool", task_axes=POSE, joints=ARM, locked={"finger_a_joint": 0.02}
    )
    assert model.joint_names == tuple(ARM) and model.parsed.locked == {
        "finger_a_joint": 0.02,
        "finger_b_joint": 0.02,
    }
    plant = drake_plant(arm.urdf, arm.package)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, np.concatenate([Q0, [0.02, 0.02]]))
    g = model.terms(model.create_scratch(), Q0, np.zeros(7), False).g
    np.testing.assert_allclose(g, -plant.CalcGravityGeneralizedForces(context)[:7], rtol=1e-12, atol=1e-12)


def test_locked_joints_are_welded_at_their_stated_position(tmp_path):
    """j6 locked at 0.7 rad, the other six the arm's: H (their block) and g equal Drake's own
    plant of the whole file with j6 at 0.7; a weld at 0, about another axis or without the
    outboard mass changes them."""
    arm = write_vendor_arm(tmp_path)
    chosen = [j for j in ARM if j != "j6"]
    model = ControllerModel.from_file(
        arm.urdf, tool_frame="tool", task_axes=("x", "y", "z"), joints=chosen, locked={"j6": 0.7}
    )
    assert model.joint_names == tuple(chosen)
    plant = drake_plant(arm.urdf, arm.package)
    context = plant.CreateDefaultContext()
    q = Q0.copy()
    q[5] = 0.7
    plant.SetPositions(context, q)
    keep = [0, 1, 2, 3, 4, 6]
    terms = model.terms(model.create_scratch(), q[keep], np.zeros(6), False)
    H = plant.CalcMassMatrix(context)[np.ix_(keep, keep)]
    np.testing.assert_allclose(terms.H, H, rtol=1e-12, atol=1e-12)
    g = -plant.CalcGravityGeneralizedForces(context)[keep]
    np.testing.assert_allclose(terms.g, g, rtol=1e-12, atol=1e-12)
    assert "outside the joint's limits" in refused(arm.urdf, joints=chosen, locked={"j6": 3.5})
    assert "unknown joint" in refused(arm.urdf, joints=["j1", "nope"])


def test_an_effort_limit_without_a_transmission_is_the_torque_limit(tmp_path):
    """Drake makes an actuator only from a <transmission>: a file with <limit effort> alone
    had infinite torque limits. Its effort limits become the controller's."""
    arm = write_vendor_arm(tmp_path)
    text = arm.urdf.read_text()
    start = text.index("  <transmission")
    while "<transmission" in text:
        start = text.index("  <transmission")
        text = text[:start] + text[text.index("</transmission>\n") + len("</transmission>\n") :]
    arm.urdf.write_text(text.replace('effort="200"', 'effort="87"', 1))
    model = ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE)
    np.testing.assert_array_equal(torque_limits(ControllerConfig(period=0.001), model), [87.0] + [200.0] * 6)


@pytest.mark.parametrize("dynamics", ["drake", "pinocchio"])
def test_joint_damping_is_compensated_as_part_of_the_bias_term(tmp_path, dynamics):
    """<dynamics damping> becomes −D q̇ in Drake's plant: the controller's C q̇ carries + D q̇
    with the numbers written in the file, in both libraries and in the compiled stages
    (a ControllerStep's τ differs from the undamped file's by exactly D q̇)."""
    D = np.array([10.0, 10.0, 5.0, 5.0, 5.0, 2.0, 2.0])
    arm = write_vendor_arm(tmp_path)
    text = arm.urdf.read_text()
    damped = with_dynamics(text, {name: f'damping="{d}"' for name, d in zip(ARM, D, strict=True)})
    (arm.urdf.parent / "damped.urdf").write_text(damped)
    model = ControllerModel.from_file(
        arm.urdf.parent / "damped.urdf", tool_frame="tool", task_axes=POSE, dynamics=dynamics
    )
    bare = ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE, dynamics=dynamics)
    v = np.linspace(-1.0, 1.0, 7)
    plant = drake_plant(arm.urdf, arm.package)
    context = plant.CreateDefaultContext()
    plant.SetPositionsAndVelocities(context, np.concatenate([Q0, v]))
    Cv = model.terms(model.create_scratch(), Q0, v, False).Cv
    np.testing.assert_allclose(Cv, plant.CalcBiasTerm(context) + D * v, rtol=1e-12, atol=1e-12)
    tau = []
    for m in (model, bare):
        step = ControllerStep(controller_model=m, config=ControllerConfig(period=0.001), task_axes=POSE)
        c = m.plant.CreateDefaultContext()
        m.plant.SetPositions(c, Q0)
        X, z = m.arm.tool_frame.CalcPoseInWorld(c), np.zeros(3)
        r = step.step(0.0, Q0, v, None, X.translation(), z, z, None, X.rotation().ToQuaternion().wxyz(), z, z)
        tau.append(r.tau.copy())
    np.testing.assert_allclose(tau[0] - tau[1], D * v, rtol=1e-9, atol=1e-9)


def test_an_stl_collision_mesh_is_seen_by_the_obstacle_criterion_as_its_convex_hull(tmp_path):
    """Drake takes no convex hull of an STL ("MakeConvexHull only applies to .obj, .vtk and
    .gltf"): link 5's U-shaped mesh shipped as STL reaches the criterion as its hull (SciPy's
    hull of the U's vertices), 0.03 m from a ball in front of its mouth, as the OBJ does; the
    file itself is untouched. Without an obstacle the model reads no geometry at all."""
    arm = write_vendor_arm(tmp_path)
    mesh = trimesh.util.concatenate([trimesh.creation.box(bounds=[b[0::2], b[1::2]]) for b in FIN_BOXES])
    mesh.export(arm.package / "meshes" / "fin.stl")
    text = arm.urdf.read_text().replace("../meshes/fin.obj", "../meshes/fin.stl")
    arm.urdf.write_text(text)
    assert ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE).scene_graph is None
    plain = drake_plant(arm.urdf, arm.package)
    context = plain.CreateDefaultContext()
    plain.SetPositions(context, Q0)
    centre_5 = np.array([0.26, 0.0, 0.08])
    ball = Obstacle(
        "ball",
        Sphere(0.03),
        RigidTransform(plain.GetFrameByName("link5").CalcPoseInWorld(context) @ centre_5),
    )
    model = ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE, obstacles=[ball])
    assert arm.urdf.read_text() == text
    config = ControllerConfig(period=0.001)
    config.desired_null_space.criteria.obstacle.gain = 1.0
    step = ControllerStep(controller_model=model, config=config, task_axes=POSE)
    X, z = plain.GetFrameByName("tool").CalcPoseInWorld(context), np.zeros(3)
    result = step.step(
        0.0, Q0, np.zeros(7), None, X.translation(), z, z, None, X.rotation().ToQuaternion().wxyz(), z, z
    )
    hull = ConvexHull(fin_vertices())
    d_hull = float(np.max(hull.equations[:, :3] @ centre_5 + hull.equations[:, 3])) - 0.03
    assert result.criteria[0, 7 + 1] == pytest.approx(d_hull, abs=5e-5)


def test_drakes_parser_warnings_are_one_line_per_file(tmp_path, caplog):
    """A file with joint friction makes Drake warn once per joint: nsdrake says one line for
    the file (how many, the first), and keeps every warning's full text on the model."""
    arm = write_vendor_arm(tmp_path)
    text = arm.urdf.read_text()
    text = with_dynamics(text, {name: 'friction="0.5"' for name in ARM})
    arm.urdf.write_text(text)
    with caplog.at_level(logging.WARNING):
        model = ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE)
    drake = [r for r in caplog.records if r.name == "drake"]
    ours = [r.getMessage() for r in caplog.records if r.name == "nsdrake" and "warned" in r.getMessage()]
    assert drake == [] and len(ours) == 1 and "arm7.urdf: Drake's parser warned 7 time(s)" in ours[0]
    assert len(model.parsed.warnings["arm7.urdf"]) == 7 and all(
        "friction" in w for w in model.parsed.warnings["arm7.urdf"]
    )


def test_a_hull_cache_that_cannot_be_written_is_one_line(tmp_path, monkeypatch):
    """An STL collision mesh needs its hull kept on disk: with NSDRAKE_CACHE naming a file
    (no folder can be made there) the model is refused in one line that names the mesh,
    the folder and the variable to set, not a traceback. Catches the write left unguarded."""
    arm = write_vendor_arm(tmp_path)
    mesh = trimesh.util.concatenate([trimesh.creation.box(bounds=[b[0::2], b[1::2]]) for b in FIN_BOXES])
    mesh.export(arm.package / "meshes" / "fin.stl")
    arm.urdf.write_text(arm.urdf.read_text().replace("../meshes/fin.obj", "../meshes/fin.stl"))
    blocked = tmp_path / "not_a_folder"
    blocked.write_text("a file of the user's\n")
    monkeypatch.setenv("NSDRAKE_CACHE", str(blocked))
    ball = Obstacle("ball", Sphere(0.03), RigidTransform([0.3, 0.0, 0.1]))
    with pytest.raises(ControllerConfigError) as e:
        ControllerModel.from_file(arm.urdf, tool_frame="tool", task_axes=POSE, obstacles=[ball])
    message = str(e.value)
    assert "\n" not in message and "fin.stl" in message and "NSDRAKE_CACHE" in message, message
    assert blocked.read_text() == "a file of the user's\n"


def test_a_locked_joint_without_a_stated_position_is_said_in_one_line(tmp_path, caplog, monkeypatch):
    """j6 and j7 left out of joints= and j7 alone given in locked=: j6 is held at 0, the
    default, said once in one line naming j6 only (not j7, whose position is stated); a
    model whose locked joints all have a position says nothing. Locking at 0 without a word
    (before issue 42's leftovers) fails this."""
    monkeypatch.setattr(model_files, "_SAID", set())  # what this process said before
    arm = write_vendor_arm(tmp_path)
    chosen = [j for j in ARM if j not in ("j6", "j7")]
    with caplog.at_level(logging.WARNING, logger="nsdrake"):
        for _ in range(2):
            model = ControllerModel.from_file(
                arm.urdf, tool_frame="tool", task_axes=("x", "y", "z"), joints=chosen, locked={"j7": 0.3}
            )
        ControllerModel.from_file(
            arm.urdf,
            tool_frame="tool",
            task_axes=("x", "y", "z"),
            joints=chosen,
            locked={"j6": 0.0, "j7": 0.3},
        )
    lines = [r.getMessage() for r in caplog.records if r.getMessage().startswith("locked:")]
    assert model.parsed.locked == {"j6": 0.0, "j7": 0.3}
    assert lines == [
        "locked: j6 held at 0 [rad or m], the default: no position stated for them in locked "
        "(arm.locked in a scenario)"
    ]


RUN = """
duration: 0.01
arm:
  urdf: myarm/urdf/arm7.urdf
  initial_positions: {%s}
plate:
  position: [1.5, 1.5, -1.0]
task:
  axes: [x, y, z, rx, ry, rz]
reference:
  approach_speed: 0.0
report:
  compare_without_null_space_task: false
  checks: []
"""


def test_a_run_keeps_every_parser_warning_in_full_in_its_folder(tmp_path):
    """The log says one line per file; the run folder's model_warnings.txt keeps all seven
    warnings (one per joint with friction), each in Drake's full text, under the file's
    name. A run of a file without warnings writes no such file. Keeping only the first
    warning, or none, fails this."""
    arm = write_vendor_arm(tmp_path)
    text = arm.urdf.read_text()
    text = with_dynamics(text, {name: 'friction="0.5"' for name in ARM})
    joints = ", ".join(f"j{k + 1}: {q}" for k, q in enumerate(Q0))
    (tmp_path / "scenario.yaml").write_text(RUN % joints)
    (tmp_path / "clean").mkdir()
    (tmp_path / "run").mkdir()
    clean = run_to_folder(load_scenario_file(tmp_path / "scenario.yaml"), tmp_path / "clean", replay=False)
    assert clean.failure is None and not (tmp_path / "clean" / MODEL_WARNINGS).exists()
    arm.urdf.write_text(text)
    result = run_to_folder(load_scenario_file(tmp_path / "scenario.yaml"), tmp_path / "run", replay=False)
    assert result.failure is None
    lines = (tmp_path / "run" / MODEL_WARNINGS).read_text().splitlines()
    assert lines[0] == "# arm7.urdf: 7 warning(s) of Drake's parser"
    assert len(lines) == 8 and all("warning:" in line and "'friction'" in line for line in lines[1:])
    assert all(str(arm.urdf) in line for line in lines[1:])  # Drake's text: the file, its line

"""The simulated station reads the arm's model file as the controller does (issue 36):
an SDF or Drake model directives in ``arm.urdf``, ``package://`` from ``arm.packages`` (folders
relative to the scenario file) or the package.xml above the file; the station's plant and
the controller's model then have the same arm. Builds stations only (no simulation)."""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import DiagramBuilder

from nsdrake.experiment.diagram import controller_model
from nsdrake.experiment.scenario import ScenarioError, load_scenario_file
from nsdrake.experiment.scenario_station import add_scenario_station
from tests.vendor_arm import Q0, write_vendor_arm

SCENARIO = """
arm:
  urdf: %s
  initial_positions: {%s}
%s
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


def scenario(tmp_path, model: str, extra: str = ""):
    joints = ", ".join(f"j{k + 1}: {q}" for k, q in enumerate(Q0))
    path = tmp_path / "scenario.yaml"
    path.write_text(SCENARIO % (model, joints, extra))
    return load_scenario_file(path)


@pytest.mark.parametrize("model", ["myarm/urdf/arm7.urdf", "myarm/sdf/arm7.sdf", "myarm/arm7.dmd.yaml"])
def test_the_station_and_the_controller_read_the_same_arm_from_any_model_file(tmp_path, model):
    """The station's plant (Drake, meshes included) and the controller's model give the same
    gravity torques at Q0, and the station sees the meshes as link geometry. A station that
    parsed the file from text (relative meshes lost) or skipped its packages fails to build."""
    write_vendor_arm(tmp_path)
    s = scenario(tmp_path, model)
    station = add_scenario_station(DiagramBuilder(), s)
    model_of_controller = controller_model(s, station)
    context = station.plant.CreateDefaultContext()
    station.plant.SetPositions(context, station.arm, Q0)
    g_station = -station.plant.CalcGravityGeneralizedForces(context)
    terms = model_of_controller.terms(model_of_controller.create_scratch(), Q0, np.zeros(7), False)
    assert np.max(np.abs(g_station - terms.g)) < 1e-9 * np.max(np.abs(terms.g))
    names = {
        station.scene_graph.model_inspector().GetName(g).split("::")[-1] for g in station.link_geometries
    }
    assert {"upper", "fin"} <= names


def test_packages_in_the_scenario_are_folders_relative_to_it(tmp_path):
    """Without the package.xml, the arm loads only with arm.packages naming the folder;
    a folder that does not exist is refused in one line naming arm.packages."""
    package = write_vendor_arm(tmp_path).package
    (package / "package.xml").unlink()
    with pytest.raises(ScenarioError, match="unknown package"):
        add_scenario_station(DiagramBuilder(), scenario(tmp_path, "myarm/urdf/arm7.urdf"))
    s = scenario(tmp_path, "myarm/urdf/arm7.urdf", "  packages: {myarm: myarm}")
    station = add_scenario_station(DiagramBuilder(), s)
    assert station.packages == {"myarm": tmp_path / "myarm"}
    controller_model(s, station)  # the controller finds the package the same way
    bad = scenario(tmp_path, "myarm/urdf/arm7.urdf", "  packages: {myarm: nowhere}")
    with pytest.raises(ScenarioError) as e:
        add_scenario_station(DiagramBuilder(), bad)
    assert "arm.packages: myarm:" in str(e.value) and "is not a folder" in str(e.value)
    assert "\n" not in str(e.value)


def test_a_payload_is_welded_to_the_simulated_tool(tmp_path):
    """arm.payload adds its mass to the simulated arm: the station's gravity torques grow by
    the payload's weight's torques, Jᵀ m g at its centre of mass (Drake's Jacobian of that
    point): a payload that never reached the plant, or sat at the tool's origin, fails this."""
    write_vendor_arm(tmp_path)
    bare = add_scenario_station(DiagramBuilder(), scenario(tmp_path, "myarm/urdf/arm7.urdf"))
    loaded = add_scenario_station(
        DiagramBuilder(),
        scenario(tmp_path, "myarm/urdf/arm7.urdf", "  payload: {mass: 0.6, com: [0.0, 0.05, 0.1]}"),
    )
    g = []
    for station in (bare, loaded):
        context = station.plant.CreateDefaultContext()
        station.plant.SetPositions(context, station.arm, Q0)
        g.append(-station.plant.CalcGravityGeneralizedForces(context))
    plant = bare.plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, bare.arm, Q0)
    J = plant.CalcJacobianTranslationalVelocity(
        context, JacobianWrtVariable.kV, plant.GetFrameByName("tool"), [0.0, 0.05, 0.1],
        plant.world_frame(), plant.world_frame(),
    )  # fmt: skip
    expected = -J.T @ (0.6 * bare.gravity)
    np.testing.assert_allclose(g[1] - g[0], expected, atol=1e-9)


def test_arm_joints_in_the_scenario_lock_the_others_in_the_station_and_the_controller(tmp_path):
    """arm.joints chooses the arm's joints and arm.locked holds j6 at 0.7 rad in the simulated
    plant and in the controller's model alike: both give Drake's own gravity torques of the
    whole file with j6 at 0.7 (a station that ignored arm.joints would have 7 joints; one
    that welded j6 elsewhere, other torques)."""
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    arm = write_vendor_arm(tmp_path)
    keep = [0, 1, 2, 3, 4, 6]
    joints = ", ".join(f"j{k + 1}: {Q0[k]}" for k in keep)
    path = tmp_path / "scenario.yaml"
    text = SCENARIO % (
        "myarm/urdf/arm7.urdf",
        joints,
        "  joints: [j1, j2, j3, j4, j5, j7]\n  locked: {j6: 0.7}",
    )
    path.write_text(text.replace("[x, y, z, rx, ry, rz]", "[x, y, z]"))
    s = load_scenario_file(path)
    station = add_scenario_station(DiagramBuilder(), s)
    model = controller_model(s, station)
    assert station.arm_model.joint_names == model.joint_names == ("j1", "j2", "j3", "j4", "j5", "j7")
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    parser.package_map().Add("myarm", str(arm.package))
    parser.AddModels(str(arm.urdf))
    plant.Finalize()
    context = plant.CreateDefaultContext()
    q = Q0.copy()
    q[5] = 0.7
    plant.SetPositions(context, q)
    g = -plant.CalcGravityGeneralizedForces(context)[keep]
    station_context = station.plant.CreateDefaultContext()
    station.plant.SetPositions(station_context, station.arm, q[keep])
    np.testing.assert_allclose(-station.plant.CalcGravityGeneralizedForces(station_context), g, atol=1e-9)
    terms = model.terms(model.create_scratch(), q[keep], np.zeros(6), False)
    np.testing.assert_allclose(terms.g, g, atol=1e-9)

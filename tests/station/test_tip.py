"""arm.tip_radius (issue 42): a sphere on the tool frame to touch with, for a vendor's model
whose file has no tool of its own (its flange, its hand)."""

from __future__ import annotations

import pytest
from conftest import fig3_with
from pydrake.systems.framework import DiagramBuilder

from nsdrake.experiment.scenario import ScenarioError
from nsdrake.experiment.scenario_station import add_scenario_station

RADIUS = 0.02  # [m]


def test_the_tip_is_a_massless_sphere_on_the_tool_frame_the_contact_monitor_allows(tmp_path):
    """The tip's signed distance to the plate at the start pose is the tool point's distance
    to the plate's face along the push direction, less the radius (plain geometry, against
    Drake's query); it adds no mass; it is the tool's (the monitor allows its contacts, the
    obstacle distances leave it out). Catches a sphere placed at the body's origin instead
    of the tool frame's, a radius dropped, a tip on another body."""
    builder = DiagramBuilder()
    scenario = fig3_with(tmp_path, f"arm: {{tip_radius: {RADIUS}}}")
    station = add_scenario_station(builder, scenario, sensing=False)
    plain = add_scenario_station(DiagramBuilder(), fig3_with(tmp_path, ""), sensing=False)
    plant, inspector = station.plant, station.scene_graph.model_inspector()
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    tip = next(
        g
        for g in plant.GetCollisionGeometriesForBody(station.tool_body)
        if inspector.GetName(g).endswith("tip")
    )
    (plate,) = plant.GetCollisionGeometriesForBody(plant.get_body(plant.GetBodyIndices(station.plate)[0]))
    query = station.scene_graph.get_query_output_port().Eval(
        station.scene_graph.GetMyContextFromRoot(context)
    )
    distance = query.ComputeSignedDistancePairClosestPoints(tip, plate).distance
    plant_context = plant.GetMyContextFromRoot(context)
    p_WT = station.arm_model.tool_frame.CalcPoseInWorld(plant_context).translation()
    X_WP = station.X_WP
    push = X_WP.rotation().matrix()[:, 1]  # the plate's +y: into its face
    expected = (X_WP.translation() - p_WT) @ push - RADIUS
    assert distance == pytest.approx(expected, abs=1e-9)
    assert plant.CalcTotalMass(plant_context) == pytest.approx(
        plain.plant.CalcTotalMass(plain.plant.CreateDefaultContext()), abs=1e-12
    )
    assert tip not in station.link_geometries


@pytest.mark.parametrize(
    ("value", "message"), [("-0.01", "must be >= 0"), (".nan", "must be a finite number")]
)
def test_a_bad_tip_radius_is_one_line(tmp_path, value, message):
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, f"arm: {{tip_radius: {value}}}")
    assert f"arm.tip_radius: {message}" in str(info.value) and "\n" not in str(info.value)

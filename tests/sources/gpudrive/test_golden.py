"""Hand-written GPUDrive / Nocturne scenarios (fixtures.py) converted, every field that matters asserted."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from scenariomax.pipeline import ConvertSettings, convert
from scenariomax.scenario import Scenario
from scenariomax.sources.base import MANIFEST_NOTES, Failure
from scenariomax.sources.gpudrive import GpuDriveSource
from scenariomax.sources.registry import make_source
from scenariomax.validate import validate_shards
from tests.sources.gpudrive.fixtures import SDC_SPEED, scene_document, scene_lights, write_document
from vmax_cli.scenariomax_cli import main

LAYOUTS = ("nocturne", "gpudrive-3d", "gpudrive-metadata")


def convert_doc(tmp_path, doc, name="scene.json") -> list:
    path = write_document(tmp_path, doc, name)
    return list(GpuDriveSource(str(path)).read_unit(str(path)))


def only_scenario(tmp_path, doc) -> Scenario:
    items = convert_doc(tmp_path, doc)
    assert len(items) == 1 and isinstance(items[0], Scenario), items
    assert items[0].validate() == []
    return items[0]


def notes_of(scenario: Scenario) -> dict:
    return scenario.metadata[MANIFEST_NOTES]


def row_of(scenario: Scenario, object_id: int) -> int:
    return int(np.flatnonzero(scenario.object_id == object_id)[0])


# --- the SDC ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("layout", ["nocturne", "gpudrive-3d"])
def test_unmarked_layouts_take_the_last_track_as_sdc(tmp_path, layout):
    scenario = only_scenario(tmp_path, scene_document(layout))
    assert scenario.is_sdc[0] and scenario.object_id[0] == 3  # positional id of the last object
    assert notes_of(scenario)["sdc"] == {"object_index": 3, "object_id": 3, "rule": "last-track"}
    np.testing.assert_allclose(scenario.x[0, :3], [0.0, 1.0, 2.0], atol=1e-5)  # the east-bound car


def test_furthest_always_valid_vehicle_when_the_last_object_cannot_be_the_sdc(tmp_path):
    doc = scene_document("nocturne")
    doc["objects"][3]["valid"][0] = False  # the last object is no longer valid throughout
    scenario = only_scenario(tmp_path, doc)
    # Vehicles valid at every step: 1 (drives 45 m north) and 2 (parked): the one that travels furthest.
    assert notes_of(scenario)["sdc"] == {"object_index": 1, "object_id": 1, "rule": "furthest"}
    assert scenario.object_id[0] == 1 and scenario.is_sdc[0]


def test_named_sdc_wins(tmp_path):
    doc = scene_document("gpudrive-metadata")
    doc["metadata"]["sdc_track_index"] = 1
    scenario = only_scenario(tmp_path, doc)
    assert notes_of(scenario)["sdc"] == {"object_index": 1, "object_id": 12, "rule": "named"}
    assert scenario.object_id[0] == 12 and scenario.is_sdc.sum() == 1


def test_indices_past_the_objects_choose_the_sdc_by_rule_and_drop_the_labels(tmp_path):
    # GPUDrive since v0.4.0 leaves out never-valid vehicles but keeps WOMD's track indices in its metadata:
    # here two such tracks were left out before the SDC, so the file names tracks 5 and 3 among 4 objects.
    doc = scene_document("gpudrive-metadata")
    doc["metadata"]["sdc_track_index"] = 5
    doc["metadata"]["tracks_to_predict"] = [{"track_index": 3, "difficulty": 2}]
    scenario = only_scenario(tmp_path, doc)
    notes = notes_of(scenario)
    assert notes["sdc"] == {"object_index": 3, "object_id": 14, "rule": "last-track"}
    assert "metadata indexes track 5 but the file holds 4 objects" in notes["track_indices_ignored"]
    assert not scenario.tracks_to_predict.any() and not scenario.difficulty_level.any()
    assert scenario.objects_of_interest.tolist() == [i == row_of(scenario, 12) for i in range(4)]  # ids, kept


def test_parallel_coordinate_lists_read_as_points(tmp_path):
    # Nocturne's first writer (2022) stored position and velocity as {"x": [...], "y": [...]}.
    rows = scene_document("nocturne")
    columns = scene_document("nocturne")
    for obj in columns["objects"]:
        for key in ("position", "velocity"):
            obj[key] = {name: [point[name] for point in obj[key]] for name in ("x", "y")}
    expected, got = only_scenario(tmp_path, rows), only_scenario(tmp_path, columns)
    for field in ("x", "y", "z", "bbox_yaw", "velocity_x", "velocity_y", "valid", "roadgraph_xyz"):
        np.testing.assert_array_equal(getattr(got, field), getattr(expected, field), err_msg=field)


def test_metadata_labels_and_ids(tmp_path):
    scenario = only_scenario(tmp_path, scene_document("gpudrive-metadata"))
    assert scenario.scenario_id == "toy-gpudrive-metadata"
    assert sorted(scenario.object_id.tolist()) == [11, 12, 13, 14]
    north = row_of(scenario, 12)
    assert scenario.tracks_to_predict.tolist() == [i == north for i in range(4)]
    assert scenario.difficulty_level[north] == 1
    assert scenario.objects_of_interest.tolist() == [i == north for i in range(4)]


def test_repeated_ids_become_positions_but_labels_keep_the_file_ids(tmp_path):
    doc = scene_document("gpudrive-metadata")
    doc["objects"][0]["id"] = 12  # the pedestrian repeats the north-bound car's track id
    scenario = only_scenario(tmp_path, doc)
    assert sorted(scenario.object_id.tolist()) == [0, 1, 2, 3]
    assert "repeat" in notes_of(scenario)["object_ids"]
    flagged = sorted(scenario.object_id[scenario.objects_of_interest].tolist())
    assert flagged == [0, 1]  # both objects the file calls 12


# --- headings, boxes, velocities, z ----------------------------------------------------------------
@pytest.mark.parametrize("layout, unit", [("nocturne", "degrees"), ("gpudrive-3d", "degrees"),
                                          ("gpudrive-metadata", "radians")])
def test_heading_unit_and_conversion(tmp_path, layout, unit):
    scenario = only_scenario(tmp_path, scene_document(layout))
    assert notes_of(scenario)["heading_unit"] == unit
    north = row_of(scenario, 12 if layout == "gpudrive-metadata" else 1)
    np.testing.assert_allclose(scenario.bbox_yaw[north], math.pi / 2, atol=1e-6)  # 90 degrees -> pi / 2
    np.testing.assert_allclose(scenario.bbox_yaw[0], 0.0, atol=1e-6)


def test_headings_beyond_one_turn_are_wrapped(tmp_path):
    doc = scene_document("nocturne")
    doc["objects"][1]["heading"] = [450.0] * 91  # Nocturne writes unwrapped degrees (real files: up to 612)
    scenario = only_scenario(tmp_path, doc)
    np.testing.assert_allclose(scenario.bbox_yaw[row_of(scenario, 1)], math.pi / 2, atol=1e-6)


@pytest.mark.parametrize("layout, swapped_id", [("nocturne", 2), ("gpudrive-metadata", 13)])
def test_vehicle_wider_than_long_is_swapped_and_noted(tmp_path, layout, swapped_id):
    scenario = only_scenario(tmp_path, scene_document(layout))
    parked = row_of(scenario, swapped_id)
    assert scenario.length[parked, 10] == pytest.approx(4.6) and scenario.width[parked, 10] == pytest.approx(1.9)
    assert notes_of(scenario)["boxes_swapped"] == [swapped_id]
    pedestrian = row_of(scenario, 0 if layout == "nocturne" else 11)  # 0.7 wide, 0.6 long: not a vehicle
    assert scenario.width[pedestrian, 10] == pytest.approx(0.7)


def test_missing_sizes_get_type_defaults(tmp_path):
    doc = scene_document("nocturne")
    doc["objects"][0]["length"] = doc["objects"][0]["width"] = 0.0  # as in the real Nocturne example
    scenario = only_scenario(tmp_path, doc)
    pedestrian = row_of(scenario, 0)
    assert (scenario.length[pedestrian, 10], scenario.width[pedestrian, 10]) == pytest.approx((0.6, 0.6))
    assert notes_of(scenario)["box_sizes_defaulted"] == [0]
    assert notes_of(scenario)["heights"] == "type defaults (the file has no heights)"
    assert scenario.height[0, 10] == pytest.approx(1.6)


def test_velocity_derived_where_absent_or_inconsistent(tmp_path):
    doc = scene_document("nocturne")
    sdc = doc["objects"][3]
    for step in range(30, 40):
        sdc["velocity"][step] = {"x": 0.0, "y": 0.0}  # says parked while the positions move at 10 m/s
    sdc["velocity"][50] = {"x": float("nan"), "y": 0.0}
    scenario = only_scenario(tmp_path, doc)
    np.testing.assert_allclose(scenario.velocity_x[0], SDC_SPEED, atol=1e-3)
    np.testing.assert_allclose(scenario.speed[0], SDC_SPEED, atol=1e-3)
    assert notes_of(scenario)["velocity_derived_steps"] == 11


def test_flipped_box_is_turned_back(tmp_path):
    doc = scene_document("nocturne")
    for step in (40, 41):
        doc["objects"][1]["heading"][step] = -90.0  # the tracker turned the north-bound car round
    scenario = only_scenario(tmp_path, doc)
    np.testing.assert_allclose(scenario.bbox_yaw[row_of(scenario, 1)], math.pi / 2, atol=1e-6)
    assert notes_of(scenario)["yaw_flips_fixed"] == 2


def test_z_of_2d_files_and_z_spikes(tmp_path):
    flat = only_scenario(tmp_path, scene_document("nocturne"))
    np.testing.assert_allclose(flat.z[0], 0.8)  # half the default vehicle height above z = 0
    assert "flat map" in notes_of(flat)["z"]
    doc = scene_document("gpudrive-3d")
    doc["objects"][3]["position"][20]["z"] = 40.0  # a 39 m spike in a track that stays at 0.8 m
    spiky = only_scenario(tmp_path, doc)
    np.testing.assert_allclose(spiky.z[0], 0.8)
    assert notes_of(spiky)["z_replaced_steps"] == 1


# --- time --------------------------------------------------------------------------------------------
def test_timestamps_are_10hz_from_the_window_start(tmp_path):
    scenario = only_scenario(tmp_path, scene_document("gpudrive-metadata"))
    assert scenario.current_time_index == 10 and scenario.num_timesteps == 91
    np.testing.assert_array_equal(scenario.timestamp_micros[0], np.arange(91) * 100_000)


def test_eleven_step_test_split_is_padded(tmp_path):
    scenario = only_scenario(tmp_path, scene_document("gpudrive-metadata", num_steps=11))
    assert scenario.valid[:, :11].all() and not scenario.valid[:, 11:].any()
    assert notes_of(scenario)["steps_padded"] == 80 and notes_of(scenario)["log_steps"] == 11


def test_long_logs_give_windows_with_labels_in_the_first(tmp_path):
    items = convert_doc(tmp_path, scene_document("gpudrive-metadata", num_steps=199))
    assert [s.scenario_id for s in items] == ["toy-gpudrive-metadata_t000", "toy-gpudrive-metadata_t080"]
    first, second = items
    assert first.tracks_to_predict.any() and not second.tracks_to_predict.any()
    np.testing.assert_allclose(second.x[0, 0], 80.0, atol=1e-4)  # log step 80 at 10 m/s
    assert notes_of(second)["log_start_step"] == 80


def test_log_shorter_than_the_history_is_one_padded_scenario(tmp_path):
    """GPUDrive's own test scenes log a few steps: the current step is the log's last but one, as for ScenarioNet."""
    scenario = only_scenario(tmp_path, scene_document("gpudrive-metadata", num_steps=8))
    sdc = scenario.sdc_index
    # log steps 0-7 at window steps 4-11: the current step (10) is log step 6, one step follows it
    assert scenario.valid[sdc, 4:12].all() and not scenario.valid[sdc, :4].any() and not scenario.valid[sdc, 12:].any()
    np.testing.assert_allclose(scenario.x[sdc, 10], 6 * SDC_SPEED * 0.1, atol=1e-4)
    notes = notes_of(scenario)
    assert notes["history_padded"] == 4 and notes["steps_padded"] == 79 and notes["log_steps"] == 8
    assert notes["current_step_moved"] == {"log": 10, "window": 6}
    assert scenario.tracks_to_predict.any()  # the log's only window keeps its labels


def test_one_step_log_is_a_failure_naming_the_cause(tmp_path):
    items = convert_doc(tmp_path, scene_document("gpudrive-metadata", num_steps=1))
    assert len(items) == 1 and isinstance(items[0], Failure)
    assert "1 step: nothing follows the current step to simulate" in items[0].reason and "\n" not in items[0].reason


# --- map and lights --------------------------------------------------------------------------------
def feature_types(scenario: Scenario) -> dict[int, int]:
    return dict(zip(scenario.roadgraph_id.tolist(), scenario.roadgraph_type.tolist()))


def test_gpudrive_road_types_and_ids(tmp_path):
    scenario = only_scenario(tmp_path, scene_document("gpudrive-3d"))
    assert feature_types(scenario) == {101: 1, 102: 7, 103: 15, 104: 16, 105: 18, 106: 17, 107: 19, 108: 20}


def test_nocturne_road_types_fall_back_on_the_kind(tmp_path):
    doc = scene_document("nocturne")
    doc["roads"].append({"geometry": [{"x": 0.0, "y": 0.0}, {"x": 1.0, "y": 0.0}], "type": "unknown"})
    scenario = only_scenario(tmp_path, doc)
    assert feature_types(scenario) == {1: 2, 2: 0, 3: 15, 4: 15, 5: 18, 6: 17, 7: 19, 8: 20}
    assert notes_of(scenario)["roads_skipped"] == {"unknown": 1}


def test_polygons_closed_and_edges_keep_the_file_order(tmp_path):
    scenario = only_scenario(tmp_path, scene_document("gpudrive-metadata"))
    crosswalk = scenario.roadgraph_xyz[scenario.roadgraph_id == 105]
    np.testing.assert_allclose(crosswalk[0], crosswalk[-1])  # outline returns to its first corner
    assert len(scenario.roadgraph_xyz[scenario.roadgraph_id == 106]) == 1  # stop sign: one point
    for edge, direction in ((103, 1.0), (104, -1.0)):
        dirs = scenario.roadgraph_dir[scenario.roadgraph_id == edge][:-1]
        np.testing.assert_allclose(dirs[:, 0], direction, atol=1e-6)


def test_traffic_light_states(tmp_path):
    scenario = only_scenario(tmp_path, scene_document("gpudrive-3d", tl_states=scene_lights()))
    assert scenario.tl_state.shape == (1, 91)
    assert scenario.tl_valid[0, :60].all() and not scenario.tl_valid[0, 60:].any()
    assert scenario.tl_state[0, 0] == 6 and scenario.tl_state[0, 25] == 1 and scenario.tl_state[0, 45] == 0
    assert (scenario.tl_lane_id[0, :60] == 101).all()
    np.testing.assert_allclose(scenario.tl_x[0, :60], 98.0)
    assert notes_of(scenario)["light_states_unknown"] == 20  # "purple" is stored as unknown


# --- through the pipeline and the CLI ----------------------------------------------------------------
@pytest.fixture(scope="module")
def three_layouts(tmp_path_factory):
    folder = tmp_path_factory.mktemp("gpudrive")
    for index, layout in enumerate(LAYOUTS):
        write_document(folder, scene_document(layout), f"scene_{index}.json")
    (folder / "valid_files.json").write_text(json.dumps({"scene_0.json": []}))  # Nocturne's index: skipped
    return folder


def test_pipeline_writes_the_notes_to_the_manifest(three_layouts, tmp_path):
    source = make_source("gpudrive", src=str(three_layouts))
    assert len(source.list_units()) == 3
    result = convert(source, ConvertSettings(out=tmp_path / "out", workers=1, progress=False))
    assert result.ok and result.num_scenarios == 3
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    rules = {entry["scenario"]: entry["notes"]["sdc"]["rule"] for entry in manifest["notes"]}
    assert rules == {"tfrecord-00000-of-01000_1": "last-track", "toy-gpudrive-3d": "last-track",
                     "toy-gpudrive-metadata": "named"}
    assert validate_shards(tmp_path / "out").bad == ()


def test_cli_converts_with_enrichment(three_layouts, tmp_path):
    out = tmp_path / "cli"
    result = CliRunner().invoke(main, ["convert", "--dataset", "gpudrive", "--src", str(three_layouts),
                                       "--out", str(out), "--workers", "1"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    assert json.loads((out / "manifest.json").read_text())["counts"]["scenarios"] == 3

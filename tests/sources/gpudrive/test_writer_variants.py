"""Layouts other writers of the GPUDrive / Nocturne JSON format produced (ScenarioMax's GPUDrive exports,
CARLA and self-play map writers, a Nocturne branch), built here from the format: each converts, and what
reading had to leave out is a manifest note, never a failed file."""

from __future__ import annotations

import copy

import numpy as np

from scenariomax.scenario import Scenario
from scenariomax.sources.base import MANIFEST_NOTES
from scenariomax.sources.gpudrive import GpuDriveSource
from tests.sources.gpudrive.fixtures import NUM_STEPS, SDC_SPEED, scene_document, write_document


def convert(tmp_path, doc) -> Scenario:
    path = write_document(tmp_path, doc)
    items = list(GpuDriveSource(str(path)).read_unit(str(path)))
    assert len(items) == 1 and isinstance(items[0], Scenario), items
    return items[0]


def notes(scenario: Scenario) -> dict:
    return scenario.metadata[MANIFEST_NOTES]


def lane_light(**lists) -> dict:
    """Lane 101's light at every step (red), with the per-step lists given."""
    return {"101": {"state": ["stop"] * NUM_STEPS, "time_index": list(range(NUM_STEPS)), **lists}}


def test_a_stop_point_written_once_holds_at_every_step(tmp_path):
    """ScenarioMax's GPUDrive export (mid-2025) wrote a lane's stop point once, with `z` left empty: the light
    is read at every step it reports, at that point."""
    for lists in ({"x": [98.0], "y": [0.5], "z": []}, {"x": [98.0], "y": [0.5], "z": [0.2]},
                  {"x": [98.0] * NUM_STEPS, "y": [0.5] * NUM_STEPS, "z": []}):
        scenario = convert(tmp_path, scene_document("gpudrive-metadata", tl_states=lane_light(**lists)))
        row = int(np.flatnonzero((scenario.tl_lane_id == 101).any(axis=1))[0])
        assert scenario.tl_valid[row].all(), lists
        np.testing.assert_allclose(scenario.tl_x[row], 98.0)
        np.testing.assert_allclose(scenario.tl_y[row], 0.5)
        assert "lights_unread" not in notes(scenario)


def test_a_light_whose_lists_do_not_line_up_is_left_out_with_a_note(tmp_path):
    lights = {**lane_light(x=[98.0] * NUM_STEPS, y=[0.5] * NUM_STEPS),
              "102": {"state": ["go"] * 3, "x": [1.0, 2.0], "y": [1.0, 2.0, 3.0], "time_index": [0, 1, 2]}}
    scenario = convert(tmp_path, scene_document("gpudrive-metadata", tl_states=lights))
    assert set(scenario.tl_lane_id[scenario.tl_valid].tolist()) == {101}
    assert notes(scenario)["lights_unread"] == "102 (state 3 entries, x 2)"


def test_an_empty_list_of_lights_is_no_lights(tmp_path):
    scenario = convert(tmp_path, scene_document("gpudrive-metadata", tl_states=[]))
    assert not scenario.tl_valid.any()


def test_sdc_track_index_minus_one_means_no_sdc_named(tmp_path):
    """CARLA and self-play map writers write -1 (GPUDrive's and PufferDrive's readers: no SDC): the SDC is
    chosen by rule (the last object, a vehicle valid throughout)."""
    doc = scene_document("gpudrive-metadata")
    doc["metadata"]["sdc_track_index"] = -1
    scenario = convert(tmp_path, doc)
    assert scenario.object_id[scenario.sdc_index] == 14
    assert notes(scenario)["sdc"]["rule"] == "last-track"
    assert notes(scenario)["sdc_track_index_ignored"].startswith("-1 (no SDC named)")
    doc["metadata"]["sdc_track_index"] = "3"
    assert "expected an integer" in notes(convert(tmp_path, doc))["sdc_track_index_ignored"]


def test_scenarionet_metadata_copied_into_the_json_keeps_its_readable_labels(tmp_path):
    """ScenarioMax copies ScenarioNet's metadata unchanged for datasets other than WOMD and nuPlan:
    `tracks_to_predict` a dict keyed by track id, `objects_of_interest` track keys (strings)."""
    doc = scene_document("gpudrive-metadata")
    doc["metadata"]["tracks_to_predict"] = {"car-a": {"track_index": 1, "track_id": "car-a", "difficulty": 2,
                                                      "object_type": "VEHICLE"}}
    doc["metadata"]["objects_of_interest"] = ["car-a"]
    scenario = convert(tmp_path, doc)
    assert scenario.tracks_to_predict[scenario.object_id.tolist().index(12)]
    assert scenario.difficulty_level[scenario.object_id.tolist().index(12)] == 2
    assert not scenario.objects_of_interest.any()
    assert "objects_of_interest[0]: expected an integer" in notes(scenario)["labels_ignored"]
    doc["metadata"]["tracks_to_predict"] = [3]  # unreadable labels never fail the file
    assert "tracks_to_predict[0]" in notes(convert(tmp_path, doc))["labels_ignored"]


def test_a_flagged_object_is_the_sdc(tmp_path):
    """A Nocturne branch (Jan 2024) marks the SDC `is_av: 1`; ScenarioMax writes `is_sdc`. One flagged
    object is the SDC when the metadata names none; several flagged say nothing."""
    doc = scene_document("nocturne")
    doc["objects"][1]["is_av"] = 1
    scenario = convert(tmp_path, doc)
    assert scenario.object_id[scenario.sdc_index] == 1 and notes(scenario)["sdc"]["rule"] == "flagged"
    doc["objects"][2]["is_sdc"] = True
    scenario = convert(tmp_path, doc)
    assert scenario.object_id[scenario.sdc_index] == 3 and notes(scenario)["sdc"]["rule"] == "last-track"
    named = scene_document("gpudrive-metadata")
    named["objects"][1]["is_sdc"] = True
    assert notes(convert(tmp_path, named))["sdc"]["rule"] == "named"


def test_objects_without_velocity_get_it_from_their_positions(tmp_path):
    doc = scene_document("gpudrive-metadata")
    for obj in doc["objects"]:
        del obj["velocity"]
    scenario = convert(tmp_path, doc)
    sdc = scenario.sdc_index
    np.testing.assert_allclose(scenario.velocity_x[sdc, 10:20], SDC_SPEED, atol=1e-3)
    assert notes(scenario)["velocity_derived_steps"] > 0


def test_road_kinds_from_map_element_id_and_in_capitals(tmp_path):
    """A road without `type` takes its kind from Waymax's `map_element_id`; kinds in capitals read as the
    lower-case ones (closed crosswalk outlines included); a road with neither is skipped and counted."""
    reference = convert(tmp_path, scene_document("gpudrive-metadata"))
    untyped = scene_document("gpudrive-metadata")
    for road in untyped["roads"]:
        del road["type"]
    shouting = scene_document("gpudrive-metadata")
    for road in shouting["roads"]:
        road["type"] = road["type"].upper()
    for doc in (untyped, shouting):
        scenario = convert(tmp_path, doc)
        for field in ("roadgraph_xyz", "roadgraph_type", "roadgraph_id", "roadgraph_valid"):
            np.testing.assert_array_equal(getattr(scenario, field), getattr(reference, field), err_msg=field)
    unknown = copy.deepcopy(untyped)
    del unknown["roads"][4]["map_element_id"]  # the crosswalk
    assert notes(convert(tmp_path, unknown))["roads_skipped"] == {"untyped": 1}

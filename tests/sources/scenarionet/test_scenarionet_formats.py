"""Descriptions from older MetaDrive / ScenarioNet generations, and the caps on what one may build."""

from __future__ import annotations

import numpy as np
import pytest

from scenariomax import schema as sch
from scenariomax.scenario import Scenario
from scenariomax.sources.base import MANIFEST_NOTES, Failure
from scenariomax.sources.scenarionet import ScenarioNetSource, resample_indices
from scenariomax.sources.scenarionet import convert as sn_convert
from tests.sources.scenarionet.fixtures import build_description, early_metadrive_description, write_pickle


def convert(tmp_path, desc, name="sd_case.pkl") -> list:
    path = write_pickle(tmp_path / name, desc)
    return list(ScenarioNetSource(str(path)).read_unit(str(path)))


def only_scenario(items) -> Scenario:
    assert len(items) == 1 and isinstance(items[0], Scenario), items
    assert items[0].validate() == []
    return items[0]


@pytest.mark.parametrize("metadata", ["missing", "empty", "none"])
def test_missing_metadata_finds_the_ego_track(tmp_path, metadata):
    desc = build_description(num_steps=91, step_seconds=0.1)
    if metadata == "missing":
        del desc["metadata"]
    else:
        desc["metadata"] = {} if metadata == "empty" else None
    scenario = only_scenario(convert(tmp_path, desc))
    assert scenario.scenario_id == "toy-sn"  # the top-level id
    assert scenario.is_sdc[0] and scenario.object_type[0] == sch.OBJECT_TYPE_VEHICLE
    np.testing.assert_allclose(scenario.x[0, 10], 2.0, atol=1e-6)  # 'ego' at 2 m/s, 1 s in
    assert not scenario.tracks_to_predict.any()


def test_missing_id_uses_the_file_name(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1)
    del desc["metadata"], desc["id"]
    assert only_scenario(convert(tmp_path, desc, name="0.pkl")).scenario_id == "0"


def test_sdc_derived_from_the_tracks(tmp_path):
    """No name hint: the vehicle valid at every step that travels furthest ('9' is faster but late)."""
    scenario = only_scenario(convert(tmp_path, early_metadrive_description()))
    assert scenario.object_id[0] == 7 and scenario.is_sdc.tolist() == [True, False, False]
    assert scenario.metadata["sdc_derived"]


@pytest.mark.parametrize("sdc_index, expected", [("8", 8), (8, 8), (1, 8)])
def test_top_level_sdc_index(tmp_path, sdc_index, expected):
    """Early MetaDrive names the SDC at the top: a track key, else a position in the track dict."""
    scenario = only_scenario(convert(tmp_path, early_metadrive_description(sdc_index=sdc_index)))
    assert scenario.object_id[0] == expected and not scenario.metadata["sdc_derived"]


def test_no_sdc_candidate_is_a_clean_failure(tmp_path):
    desc = early_metadrive_description()
    for track in desc["tracks"].values():
        track["state"]["valid"][0] = 0.0
    (item,) = convert(tmp_path, desc)
    assert isinstance(item, Failure) and "no sdc_id" in item.reason and "\n" not in item.reason


def test_time_step_from_top_level_ts_or_default(tmp_path):
    four_hz = early_metadrive_description(num_steps=41, step_seconds=0.25)
    scenario = only_scenario(convert(tmp_path, four_hz))  # resampled from 4 Hz: 10 s -> 101 steps
    np.testing.assert_allclose(scenario.x[0, :3], [0.0, 0.3, 0.6], atol=1e-5)
    no_times = early_metadrive_description(with_ts=False)  # no ts, no timestep: MetaDrive's 0.1 s
    scenario = only_scenario(convert(tmp_path, no_times, name="sd_b.pkl"))
    np.testing.assert_allclose(scenario.x[0, 90], 27.0, atol=1e-5)


def test_timestamp_jitter_is_not_resampled(tmp_path):
    """WOMD logs wobble around 10 Hz (one real 20 s file has a 0.0894 s step): keep the steps as
    they are and carry the real times into timestamp_micros."""
    desc = build_description(num_steps=91, step_seconds=0.1, with_ts=True)
    desc["metadata"]["ts"] = desc["metadata"]["ts"] + np.where(np.arange(91) >= 40, -0.0106, 0.0)
    assert resample_indices(desc["metadata"]["ts"] - 100) is None
    scenario = only_scenario(convert(tmp_path, desc))
    np.testing.assert_allclose(scenario.x[0, 40], 8.0, atol=1e-6)  # step 40 is source step 40
    assert scenario.timestamp_micros[0, 39:41].tolist() == [3_900_000, 3_989_400]
    dropped = np.r_[np.arange(50), np.arange(51, 92)] * 0.1  # one frame missing: resampled
    assert resample_indices(dropped) is not None


def test_early_metadrive_lights_and_crosswalk(tmp_path):
    scenario = only_scenario(convert(tmp_path, early_metadrive_description()))
    valid = scenario.tl_valid[0]
    assert not valid[:20].any() and valid[20:].all()  # lane 0 + stop point (0, 0, 0) = not reported
    assert (scenario.tl_state[0, 20:30] == sch.TL_UNKNOWN).all() and (scenario.tl_state[0, 30:60] == sch.TL_STOP).all()
    assert (scenario.tl_state[0, 60:] == sch.TL_GO).all()
    assert (scenario.tl_lane_id[0, 20:] == 11).all() and (scenario.tl_x[0, 20:] == 40).all()
    assert (scenario.tl_lane_id[0, :20] == -1).all()
    assert set(scenario.roadgraph_type[scenario.roadgraph_id == 12].tolist()) == {sch.RG_CROSSWALK}


def test_light_with_string_states_and_one_stop_point(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["dynamic_map_states"]["tl-1"]["state"]["object_state"] = np.array(
        ["LANE_STATE_ARROW_GO"] * 50 + [None] * 41, dtype=object)
    scenario = only_scenario(convert(tmp_path, desc))
    assert (scenario.tl_state[0, :50] == sch.TL_ARROW_GO).all() and not scenario.tl_valid[0, 50:].any()


def test_tracks_to_predict_as_a_list(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["metadata"]["tracks_to_predict"] = ["ped-a"]
    scenario = only_scenario(convert(tmp_path, desc))
    assert scenario.tracks_to_predict.tolist() == [False, False, True]


def test_cells_cap(tmp_path, monkeypatch):
    monkeypatch.setattr(sn_convert, "MAX_CELLS", 200)
    (item,) = convert(tmp_path, build_description(num_steps=91, step_seconds=0.1))
    assert isinstance(item, Failure) and "cells allowed" in item.reason


def test_huge_time_step_is_refused_before_resampling(tmp_path):
    desc = build_description(num_steps=41)
    desc["metadata"]["timestep"] = 1e7  # 41 steps would make a 4e9-step grid at 10 Hz
    (item,) = convert(tmp_path, desc)
    assert isinstance(item, Failure) and "cells allowed" in item.reason


def test_far_apart_map_points_are_refused(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["map_features"]["lane-2"]["polyline"] = np.array([[0.0, 0.0], [1e9, 0.0]])  # 1e9 samples at 1 m
    (item,) = convert(tmp_path, desc)
    assert isinstance(item, Failure) and "roadgraph points" in item.reason


def test_non_finite_map_points_are_dropped(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["map_features"]["lane-2"]["polyline"] = np.array([[100.0, 0.0], [np.nan, 0.0], [150.0, 0.0]])
    scenario = only_scenario(convert(tmp_path, desc))
    assert np.isfinite(scenario.roadgraph_xyz).all()


def test_malformed_parts_are_ignored_or_fail_cleanly(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["dynamic_map_states"] = [[{}]]  # an early MetaDrive placeholder
    desc["map_features"]["junk"] = "not a feature"
    only_scenario(convert(tmp_path, desc))
    desc["tracks"]["cone"] = "not a track"  # dropped and noted; the scenario still converts
    scenario = only_scenario(convert(tmp_path, desc, name="sd_bad.pkl"))
    assert scenario.metadata[MANIFEST_NOTES]["tracks_dropped"] == {"cone": "no state with 'valid'"}
    desc["tracks"]["ego"] = "not a track"  # the SDC itself: nothing to simulate
    (item,) = convert(tmp_path, desc, name="sd_bad2.pkl")
    assert isinstance(item, Failure) and "the SDC's track ego: no state" in item.reason


def test_non_finite_track_values_make_the_step_invalid(tmp_path):
    desc = build_description(num_steps=91, step_seconds=0.1)
    desc["tracks"]["ped-a"]["state"]["position"][20] = np.nan
    desc["tracks"]["ped-a"]["state"]["velocity"][21] = 1e300  # overflows float32
    scenario = only_scenario(convert(tmp_path, desc))
    ped = scenario.object_id.tolist().index(2)
    assert scenario.valid[ped, 19] and not scenario.valid[ped, 20] and not scenario.valid[ped, 21]

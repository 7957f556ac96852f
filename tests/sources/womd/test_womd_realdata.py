"""Real WOMD samples (../shared/realdata/womd): conversion checked against an independent raw read."""

from __future__ import annotations

import collections
import json

import numpy as np
import pytest

from scenariomax import schema as sch
from scenariomax.codec import decode_scenario, encode_scenario
from scenariomax.io.example import decode_example
from scenariomax.io.tfrecord import iter_records
from scenariomax.scenario import Scenario
from scenariomax.sources.womd import ScenarioProto, WomdSource, lane_side_vote
from tests.conftest import realdata_file
from tests.sources.womd.fixtures import write_records

SCENARIO_FILE = "womd/motion_data_one_scenario.tfrecord"
EXAMPLE_FILE = "womd/motion_data_one_example.tfrecord"


def raw_message(path) -> ScenarioProto:
    records = list(iter_records(path))
    assert len(records) == 1
    message = ScenarioProto()
    message.ParseFromString(records[0])
    return message


def expected_type_counts(message) -> collections.Counter:
    """Map features per roadgraph type, from the raw proto (WOMD enums -> our enum, by hand)."""
    lane = {0: 2, 1: 1, 2: 2, 3: 3}
    edge = {0: 15, 1: 15, 2: 16}
    fixed = {"stop_sign": 17, "crosswalk": 18, "speed_bump": 19, "driveway": 20}
    counts = collections.Counter()
    for feature in message.map_features:
        kind = feature.WhichOneof("feature_data")
        if kind == "lane":
            counts[lane[feature.lane.type]] += 1
        elif kind == "road_line":
            counts[feature.road_line.type + 5 if feature.road_line.type else 0] += 1
        elif kind == "road_edge":
            counts[edge[feature.road_edge.type]] += 1
        elif kind in fixed:
            counts[fixed[kind]] += 1
    return counts


def converted_type_counts(scenario: Scenario) -> collections.Counter:
    valid = scenario.roadgraph_valid
    pairs = set(zip(scenario.roadgraph_type[valid].tolist(), scenario.roadgraph_id[valid].tolist()))
    return collections.Counter(rg_type for rg_type, _ in pairs)


@pytest.fixture(scope="module")
def scenario_path():
    return realdata_file(SCENARIO_FILE)


@pytest.fixture(scope="module")
def converted(scenario_path) -> Scenario:
    items = list(WomdSource(str(scenario_path)).read_unit(str(scenario_path)))
    assert len(items) == 1 and isinstance(items[0], Scenario), items
    return items[0]


def test_real_scenario_is_valid_and_roundtrips(converted):
    assert converted.validate() == []
    decoded = decode_scenario(encode_scenario(converted))
    assert decoded.validate() == []
    assert decoded.scenario_id == converted.scenario_id


def test_real_scenario_matches_raw_proto(converted, scenario_path):
    message = raw_message(scenario_path)
    assert converted.num_objects == len(message.tracks) == 83
    assert converted.scenario_id == message.scenario_id
    sdc_track = message.tracks[message.sdc_track_index]
    assert converted.is_sdc[0] and converted.object_id[0] == sdc_track.id
    raw_valid = np.array([s.valid for s in sdc_track.states])
    raw_xy = np.array([(s.center_x, s.center_y) for s in sdc_track.states])
    np.testing.assert_array_equal(converted.valid[0], raw_valid)
    np.testing.assert_allclose(converted.x[0][raw_valid], raw_xy[raw_valid, 0], atol=1e-3, rtol=0)
    np.testing.assert_allclose(converted.y[0][raw_valid], raw_xy[raw_valid, 1], atol=1e-3, rtol=0)
    assert converted_type_counts(converted) == expected_type_counts(message)
    assert sum(expected_type_counts(message).values()) == len(message.map_features) == 301
    assert converted.tracks_to_predict.sum() == len(message.tracks_to_predict) == 3
    predicted_ids = {message.tracks[r.track_index].id for r in message.tracks_to_predict}
    assert set(converted.object_id[converted.tracks_to_predict].tolist()) == predicted_ids


def test_real_traffic_lights_match_raw(converted, scenario_path):
    message = raw_message(scenario_path)
    step = 10
    raw = {int(s.lane): int(s.state) for s in message.dynamic_map_states[step].lane_states}
    assert raw, "the sample has traffic-light states"
    got = {int(lane): int(state)
           for lane, state, ok in zip(converted.tl_lane_id[:, step], converted.tl_state[:, step],
                                      converted.tl_valid[:, step]) if ok}
    assert got == raw
    lane_ids = set(converted.lane_id.tolist())
    assert set(raw) <= lane_ids  # lights point at lanes of the lane graph


def test_real_road_edges_have_the_road_on_their_left(converted, scenario_path):
    lanes = np.isin(converted.roadgraph_type, sch.LANE_TYPES)
    lane_xy = converted.roadgraph_xyz[lanes, :2].astype(np.float64)
    edge_ids = np.unique(converted.roadgraph_id[np.isin(converted.roadgraph_type, sch.ROAD_EDGE_TYPES)])
    assert len(edge_ids) == 28
    for fid in edge_ids:
        edge = converted.roadgraph_xyz[converted.roadgraph_id == fid, :2].astype(np.float64)
        length = np.linalg.norm(np.diff(edge, axis=0), axis=1).sum()
        vote = lane_side_vote(edge, lane_xy)
        # Medians between opposite flows have lanes on both sides: only clear votes must agree.
        assert vote >= 0 or abs(vote) < 0.1 * length, (fid, vote, length)
    raw_first = {f.id: (f.road_edge.polyline[0].x, f.road_edge.polyline[0].y)
                 for f in raw_message(scenario_path).map_features if f.WhichOneof("feature_data") == "road_edge"}
    flipped = [fid for fid in edge_ids
               if not np.allclose(converted.roadgraph_xyz[converted.roadgraph_id == fid][0, :2], raw_first[fid],
                                  atol=1e-3)]
    assert flipped == []  # this sample already draws every edge with the road on its left: nothing to flip


def test_unknown_field_appended_to_real_message(tmp_path, scenario_path, converted):
    record = next(iter_records(scenario_path))
    extra = bytes([0xBA, 0x06, 4]) + b"\x08\x01\x10\x02"  # field 103, a nested message nobody knows
    path = write_records(tmp_path / "extra.tfrecord", [record + extra])
    items = list(WomdSource(str(path)).read_unit(str(path)))
    assert len(items) == 1 and items[0].equals(converted)


def test_real_tf_example(tmp_path):
    path = realdata_file(EXAMPLE_FILE)
    items = list(WomdSource(str(path)).read_unit(str(path)))
    assert len(items) == 1 and isinstance(items[0], Scenario), items
    scenario = items[0]
    assert scenario.validate() == [] and decode_scenario(encode_scenario(scenario)).validate() == []
    assert scenario.is_sdc[0] and scenario.source_dataset == "womd"
    assert np.all(np.abs(scenario.bbox_yaw[scenario.valid]) <= np.pi + 1e-6)
    raw = decode_example(next(iter_records(path)))
    sdc = int(np.flatnonzero(raw["state/is_sdc"] > 0)[0])

    def raw_steps(name):
        return np.concatenate([raw[f"state/{t}/{name}"].reshape(128, -1)[sdc] for t in ("past", "current", "future")])

    raw_valid = raw_steps("valid") > 0
    np.testing.assert_array_equal(scenario.valid[0], raw_valid)
    np.testing.assert_allclose(scenario.x[0][raw_valid], raw_steps("x")[raw_valid], atol=1e-3, rtol=0)
    np.testing.assert_allclose(scenario.y[0][raw_valid], raw_steps("y")[raw_valid], atol=1e-3, rtol=0)
    assert (raw["state/id"] != -1).sum() == scenario.num_objects or scenario.num_objects == 128
    forced = list(WomdSource(str(path), womd_format="tf_example").read_unit(str(path)))
    assert forced[0].equals(scenario)


def test_a_tf_example_with_a_full_roadgraph_is_noted_in_the_manifest(tmp_path, scenario_path):
    """The real tf.Example holds 20,000 of 20,000 roadgraph points: WOMD cut its map (junction connectors the
    SDC drove on are gone), so the conversion says so in the summary and the manifest; the proto does not."""
    from click.testing import CliRunner

    from vmax_cli.scenariomax_cli import main

    result = CliRunner().invoke(main, ["convert", "--dataset", "womd", "--src", str(realdata_file(EXAMPLE_FILE)),
                                       "--out", str(tmp_path / "example")])
    assert result.exit_code == 0, result.output
    assert "notes              1 scenario (tf_example_roadgraph_full_points 1" in result.output
    manifest = json.loads((tmp_path / "example" / "manifest.json").read_text())
    assert [n["notes"].get("tf_example_roadgraph_full_points") for n in manifest["notes"]] == [20000]
    proto = list(WomdSource(str(scenario_path)).read_unit(str(scenario_path)))[0]
    assert "tf_example_roadgraph_full_points" not in proto.metadata.get("manifest_notes", {})

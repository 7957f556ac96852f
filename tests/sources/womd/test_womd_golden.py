"""Golden tests: tiny WOMD Scenario protos written by the tests, converted, checked by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenariomax import schema as sch
from scenariomax.codec import decode_scenario, encode_scenario
from scenariomax.errors import InputError
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.base import Failure
from scenariomax.sources.womd import WomdSource, lane_side_vote, window_starts
from tests.sources.womd.fixtures import (
    CROSSWALK_ID,
    EDGE_ID,
    LANE_ID,
    LINE_ID,
    NEXT_LANE_ID,
    OTHER_TRACK_ID,
    SDC_TRACK_ID,
    STOP_ID,
    build_scenario,
    write_records,
)


def convert(path, **kwargs) -> list:
    source = WomdSource(str(path), **kwargs)
    return [item for unit in source.list_units() for item in source.read_unit(unit)]


@pytest.fixture
def converted(tmp_path) -> Scenario:
    items = convert(write_records(tmp_path / "toy.tfrecord", [build_scenario()]))
    assert len(items) == 1 and isinstance(items[0], Scenario), items
    return items[0]


def test_objects_sdc_first_with_labels(converted):
    assert converted.scenario_id == "toy-womd" and converted.source_dataset == "womd"
    assert converted.object_id.tolist() == [SDC_TRACK_ID, OTHER_TRACK_ID]
    assert converted.is_sdc.tolist() == [True, False]
    assert converted.object_type.tolist() == [sch.OBJECT_TYPE_VEHICLE, sch.OBJECT_TYPE_PEDESTRIAN]
    assert converted.tracks_to_predict.tolist() == [False, True]
    assert converted.difficulty_level.tolist() == [0, 2]
    assert converted.objects_of_interest.tolist() == [False, True]
    assert converted.validate() == []


def test_states_invalid_steps_and_wrapped_heading(converted):
    assert converted.num_timesteps == 91 and converted.current_time_index == 10
    np.testing.assert_allclose(converted.x[0, :3], [0.0, 1.0, 2.0])
    np.testing.assert_allclose(converted.bbox_yaw[0, 0], 3.5 - 2 * math.pi, atol=1e-6)  # wrapped
    np.testing.assert_allclose(converted.speed[0, 5], 10.0)
    # The pedestrian is valid at even steps only; odd steps are -1 placeholders.
    assert converted.valid[1, :4].tolist() == [True, False, True, False]
    assert converted.x[1, 1] == -1 and converted.y[1, 1] == -1 and converted.timestamp_micros[1, 1] == -1
    np.testing.assert_allclose(converted.y[1, 2], 3.2, atol=1e-5)
    # Timestamps come from timestamps_seconds (5.0 + 0.1 k), relative to the window's first step.
    assert converted.timestamp_micros[0, :3].tolist() == [0, 100_000, 200_000]
    assert converted.tl_timestamp_micros[90] == 9_000_000


def test_map_types_ids_speed_limit_and_links(converted):
    def feature_type(fid):
        return set(converted.roadgraph_type[converted.roadgraph_id == fid].tolist())

    assert feature_type(LANE_ID) == {sch.RG_LANE_SURFACE_STREET}
    assert feature_type(NEXT_LANE_ID) == {sch.RG_LANE_FREEWAY}
    assert feature_type(EDGE_ID) == {sch.RG_ROAD_EDGE_BOUNDARY}
    assert feature_type(LINE_ID) == {sch.RG_SOLID_DOUBLE_YELLOW}
    assert feature_type(CROSSWALK_ID) == {sch.RG_CROSSWALK}
    assert feature_type(STOP_ID) == {sch.RG_STOP_SIGN}
    lane = converted.roadgraph_id == LANE_ID
    assert lane.sum() == 41  # 40 m at 1 m spacing, both ends kept
    np.testing.assert_allclose(converted.roadgraph_speed_limit[lane], 25 * 0.44704, rtol=1e-6)
    np.testing.assert_allclose(converted.roadgraph_dir[lane][0], [1, 0, 0])
    crosswalk = converted.roadgraph_xyz[converted.roadgraph_id == CROSSWALK_ID]
    np.testing.assert_allclose(crosswalk[0], crosswalk[-1])  # closed polygon: 8 m perimeter -> 9 points
    assert len(crosswalk) == 9
    np.testing.assert_allclose(converted.roadgraph_xyz[converted.roadgraph_id == STOP_ID], [[38, -1.5, 0]])
    assert converted.lane_id.tolist() == [LANE_ID, NEXT_LANE_ID]
    assert converted.lane_successors[0, 0] == NEXT_LANE_ID and converted.lane_predecessors[1, 0] == LANE_ID
    assert converted.lane_right_neighbors[0, 0] == 999


def test_road_edge_flipped_so_road_is_on_the_left(converted):
    edge = converted.roadgraph_xyz[converted.roadgraph_id == EDGE_ID]
    assert edge[0, 0] == 0 and edge[-1, 0] == 60  # raw file draws it from x = 60 to x = 0
    np.testing.assert_allclose(converted.roadgraph_dir[converted.roadgraph_id == EDGE_ID][0], [1, 0, 0])


def test_lane_side_vote_sign():
    lane = np.array([[x, 0.0] for x in range(10)])
    assert lane_side_vote(np.array([[0, -2], [10, -2]], float), lane) > 0  # lane on the left
    assert lane_side_vote(np.array([[10, -2], [0, -2]], float), lane) < 0
    assert lane_side_vote(np.array([[0, -200], [10, -200]], float), lane) == 0  # too far: abstain


def test_traffic_lights(converted):
    assert converted.tl_state.shape == (1, 91)
    assert converted.tl_state[0, 49] == sch.TL_STOP and converted.tl_state[0, 50] == sch.TL_GO
    assert converted.tl_valid.all() and (converted.tl_lane_id == LANE_ID).all()
    assert (converted.tl_x == 30).all() and (converted.tl_z == 1).all()


def test_codec_roundtrip(converted):
    decoded = decode_scenario(encode_scenario(converted))
    assert decoded.validate() == []
    np.testing.assert_allclose(decoded.x[0, :91], converted.x[0])


def test_unknown_fields_are_ignored(tmp_path):
    # Field 99 (length-delimited) and field 98 (varint) are not in scenario.proto.
    extra = bytes([0x9A, 0x06, 3]) + b"abc" + bytes([0x90, 0x06, 0x2A])
    items = convert(write_records(tmp_path / "x.tfrecord", [build_scenario() + extra]))
    assert len(items) == 1 and isinstance(items[0], Scenario)
    assert items[0].object_id.tolist() == [SDC_TRACK_ID, OTHER_TRACK_ID]


def test_20s_file_cut_into_two_windows(tmp_path):
    items = convert(write_records(tmp_path / "long.tfrecord", [build_scenario(num_steps=199, scenario_id="long")]))
    assert [s.scenario_id for s in items] == ["long_t000", "long_t080"]
    second = items[1]
    np.testing.assert_allclose(second.x[0, 10], 90.0)  # its current step is log step 90
    assert second.timestamp_micros[0, 0] == 0
    assert second.tl_state[0, 0] == sch.TL_GO  # log step 80 >= 50
    assert not second.tracks_to_predict.any()  # labels belong to the log's own current step
    assert items[0].tracks_to_predict.any()
    assert window_starts(199, 10) == [0, 80] and window_starts(91, 10) == [0] and window_starts(90, 10) == []
    assert [s.scenario_id for s in convert(tmp_path / "long.tfrecord", window_stride=40)] == [
        "long_t000", "long_t040", "long_t080"]


def test_short_scenario_is_a_failure_and_the_file_goes_on(tmp_path):
    path = write_records(tmp_path / "mix.tfrecord", [build_scenario(num_steps=50, scenario_id="short"),
                                                      build_scenario(scenario_id="ok")])
    items = convert(path)
    assert isinstance(items[0], Failure) and items[0].scenario == "short" and "\n" not in items[0].reason
    assert isinstance(items[1], Scenario) and items[1].scenario_id == "ok"


def test_budget_keeps_sdc_first(tmp_path):
    items = convert(write_records(tmp_path / "toy.tfrecord", [build_scenario()]), sizes=Sizes(num_objects=1))
    assert items[0].object_id.tolist() == [SDC_TRACK_ID]


def test_directory_and_glob_units(tmp_path):
    (tmp_path / "a").mkdir()
    write_records(tmp_path / "a" / "training.tfrecord-00001-of-00002", [build_scenario()])
    write_records(tmp_path / "b.tfrecord", [build_scenario()])
    (tmp_path / "notes.txt").write_text("not data")
    units = WomdSource(str(tmp_path)).list_units()
    assert units == sorted([str(tmp_path / "a" / "training.tfrecord-00001-of-00002"), str(tmp_path / "b.tfrecord")])
    assert WomdSource(str(tmp_path / "*.tfrecord")).list_units() == [str(tmp_path / "b.tfrecord")]
    with pytest.raises(InputError, match="no such file"):
        WomdSource(str(tmp_path / "missing*.tfrecord")).list_units()


def test_source_is_picklable_and_reports_settings():
    import pickle

    source = WomdSource("x.tfrecord", womd_format="scenario")
    assert pickle.loads(pickle.dumps(source)) == source
    assert source.settings()["womd_format"] == "scenario" and source.name == "womd"
    with pytest.raises(ValueError, match="womd_format"):
        WomdSource("x", womd_format="nope")

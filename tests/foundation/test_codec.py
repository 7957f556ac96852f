import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scenariomax import BudgetError, Sizes, decode_scenario, encode_scenario, load_schema, read_shards
from scenariomax.codec import SchemaError, infer_sizes
from scenariomax.io import decode_example, iter_records
from tests.conftest import realdata_file, straight_road_scenario

REAL_EXAMPLE = "womd/motion_data_one_example.tfrecord"


def test_round_trip_preserves_every_field(toy_scenario):
    sizes = Sizes(num_objects=8, num_roadgraph=2000, num_lights=4, num_paths=2, num_points_per_path=20,
                  num_lanes=4, num_lane_links=2, num_agent_paths=2)
    decoded = decode_scenario(encode_scenario(toy_scenario, sizes))
    assert decoded.scenario_id == "toy-0" and decoded.source_dataset == "test"
    assert decoded.x.shape == (8, 91)
    n, r = toy_scenario.num_objects, toy_scenario.roadgraph_xyz.shape[0]
    np.testing.assert_array_equal(decoded.x[:n], toy_scenario.x)
    np.testing.assert_array_equal(decoded.valid[n:], False)
    np.testing.assert_array_equal(decoded.roadgraph_xyz[:r], toy_scenario.roadgraph_xyz)
    np.testing.assert_array_equal(decoded.roadgraph_speed_limit[:r], toy_scenario.roadgraph_speed_limit)
    np.testing.assert_array_equal(decoded.tl_state[:1], toy_scenario.tl_state)
    np.testing.assert_array_equal(decoded.timestamp_micros[0, :3], [0, 100_000, 200_000])
    assert decoded.validate() == []
    # Encoding the decoded (padded) scenario again is byte-identical.
    assert encode_scenario(decoded, sizes) == encode_scenario(toy_scenario, sizes)


def test_over_budget_is_refused(toy_scenario):
    with pytest.raises(BudgetError, match="state/id"):
        encode_scenario(toy_scenario, Sizes(num_objects=2))


def test_missing_key_is_a_schema_error(toy_scenario):
    from scenariomax.io import encode_example

    features = decode_example(encode_scenario(toy_scenario))
    del features["state/past/x"]
    with pytest.raises(SchemaError, match="missing feature state/past/x"):
        decode_scenario(encode_example(features))


def test_validate_reports_problems():
    bad = straight_road_scenario()
    bad.x[1, 5] = np.nan
    bad.is_sdc[1] = True
    problems = " | ".join(bad.validate())
    assert "x has NaN" in problems and "exactly one SDC, found 2" in problems


def test_validate_reports_timestamps_and_roadgraph_types():
    # Timestamps must rise within each row (checked for all rows at once): a drop across two rows is no problem.
    scenario = straight_road_scenario()
    assert scenario.validate() == []
    stamps = scenario.timestamp_micros
    assert scenario.valid[0].any() and scenario.valid[1].any()
    bad = straight_road_scenario()
    row = np.flatnonzero(bad.valid[1])
    bad.timestamp_micros[1, row[-1]] = bad.timestamp_micros[1, row[-2]]
    assert "timestamps do not increase along a trajectory" in bad.validate()
    later = straight_road_scenario()
    later.timestamp_micros[0] = np.where(later.valid[0], stamps[0] + 10 ** 9, -1)  # row 0 far later than row 1
    assert later.validate() == []
    odd = straight_road_scenario()
    odd.roadgraph_type[-1] = 99
    odd.roadgraph_type[0] = 98
    assert "unknown roadgraph types [98, 99]" in odd.validate()


def test_real_womd_example_round_trips_exactly():
    data = next(iter_records(realdata_file(REAL_EXAMPLE)))
    original = decode_example(data)
    scenario = decode_scenario(data)
    assert scenario.validate() == []
    ours = decode_example(encode_scenario(scenario, infer_sizes(original)))
    # Every key of the real record is written back with the same dtype and values...
    for key, value in original.items():
        if isinstance(value, list):
            assert ours[key] == value, key
        else:
            assert ours[key].dtype == value.dtype and np.array_equal(ours[key], value), key
    # ...and the only extra keys are the documented path samples and V-Max extras.
    extra = set(ours) - set(original)
    assert extra and all(k.startswith(("path_samples/", "vmax/")) for k in extra)


def test_our_records_match_real_layout_at_same_roadgraph_size(toy_scenario):
    original = decode_example(next(iter_records(realdata_file(REAL_EXAMPLE))))
    ours = decode_example(encode_scenario(toy_scenario, Sizes(num_roadgraph=20000)))
    for key, value in original.items():
        assert key in ours, key
        assert type(ours[key]) is type(value) and len(ours[key]) == len(value), key
        if not isinstance(value, list):
            assert ours[key].dtype == value.dtype, key


def test_schema_keys_cover_the_design_contract():
    keys = set(load_schema().keys)
    for group in ("past", "current", "future"):
        for name in ("x", "y", "z", "bbox_yaw", "length", "width", "height", "speed", "vel_yaw",
                     "velocity_x", "velocity_y", "timestamp_micros", "valid"):
            assert f"state/{group}/{name}" in keys
        for name in ("state", "valid", "id", "x", "y", "z", "timestamp_micros"):
            assert f"traffic_light_state/{group}/{name}" in keys
    for name in ("xyz", "valid", "id", "arc_length", "on_route"):
        assert f"path_samples/{name}" in keys


def test_read_shards_accepts_dir_file_and_glob(tmp_path, toy_scenario):
    from scenariomax import write_shards

    scenarios = [straight_road_scenario(f"toy-{i}") for i in range(5)]
    files = write_shards(scenarios, tmp_path, Sizes(num_roadgraph=2000), shard_size=2)
    assert [f.name for f in files] == [f"train-0000{i}-of-00003.tfrecord" for i in range(3)]
    for path in (tmp_path, files[0], str(tmp_path / "train-*")):
        ids = [s.scenario_id for s in read_shards(path)]
        assert ids == ([f"toy-{i}" for i in range(5)] if path != files[0] else ["toy-0", "toy-1"])


@settings(max_examples=30, deadline=None)
@given(data=st.data())
def test_corrupted_record_payload_gives_clean_error(tmp_path_factory, data):
    from scenariomax.io.tfrecord import frame_record
    from scenariomax.shards import ShardReadError

    payload = bytearray(encode_scenario(straight_road_scenario(), Sizes(num_roadgraph=2000)))
    for _ in range(data.draw(st.integers(1, 8))):
        position = data.draw(st.integers(0, len(payload) - 1))
        payload[position] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(0, len(payload)))
    path = tmp_path_factory.mktemp("c") / "bad.tfrecord"
    path.write_bytes(frame_record(bytes(payload[:cut])))  # valid framing, damaged message
    try:
        list(read_shards(path))
    except ShardReadError as error:
        assert str(error).startswith(f"{path}: record 0:") and "\n" not in str(error)

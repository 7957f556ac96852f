"""`inspect_shards` counts equal hand-computed values; `format_report` shows the key numbers."""

from __future__ import annotations

import json

import pytest

from scenariomax import write_shards
from scenariomax.errors import InputError
from scenariomax.inspect import format_report, inspect_shards, load_scenario
from scenariomax.io.tfrecord import TFRecordWriter
from tests.conftest import realdata_file
from tests.inspect import scenes
from tests.inspect.scenes import SIZES, make_scenario


@pytest.fixture(scope="module")
def shard_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("shards")
    bare = make_scenario("scene-b", with_lights=False, with_paths=False, with_controllable=False)
    write_shards([make_scenario("scene-a"), bare], out, sizes=SIZES, shard_size=1)
    return out


@pytest.fixture(scope="module")
def stats(shard_dir):
    return inspect_shards(shard_dir, scenario_id="scene-a")


def test_stats_are_json_serialisable(stats):
    assert json.loads(json.dumps(stats))["num_records"] == 2


def test_record_and_size_counts(stats):
    assert (stats["num_files"], stats["num_records"], stats["num_scenarios"]) == (2, 2, 2)
    assert stats["sizes"] == [{"sizes": SIZES.as_dict(), "num_records": 2}]
    assert stats["source_datasets"] == {"synthetic": 2}
    assert stats["validation"] == {"num_bad_records": 0, "first_problems": []}


def test_object_counts(stats):
    objects = stats["objects"]
    assert objects["by_type"] == {"vehicle": 6, "pedestrian": 2}
    assert (objects["mean_per_scenario"], objects["max_per_scenario"]) == (4.0, 4)
    assert objects["valid_step_fraction"] == pytest.approx(2 * scenes.NUM_VALID_OBJECT_STEPS / (2 * 4 * 91), abs=1e-4)


def test_sdc_speed_and_distance(stats):
    sdc = stats["sdc"]
    assert sdc["speed_mean"] == pytest.approx(scenes.SDC_SPEED_MEAN, abs=1e-3)
    assert sdc["speed_max"] == pytest.approx(12.0)
    assert sdc["current_speed_mean"] == pytest.approx(10.0)
    assert sdc["distance_mean_m"] == pytest.approx(scenes.SDC_DISTANCE_M, abs=1e-3)


def test_roadgraph_counts(stats):
    rg = stats["roadgraph"]
    assert rg["mean_valid_points"] == scenes.NUM_ROADGRAPH_POINTS == 561
    assert rg["points_by_type"] == {
        "lane_surface_street": 2 * scenes.NUM_LANE_POINTS, "road_edge_boundary": 2 * scenes.NUM_EDGE_POINTS,
        "road_line_broken_single_white": 2 * scenes.NUM_WHITE_POINTS, "crosswalk": 2 * scenes.NUM_CROSSWALK_POINTS,
        "stop_sign": 2 * scenes.NUM_STOP_SIGN_POINTS,
    }


def test_lights_paths_controllable(stats):
    assert stats["traffic_lights"] == {"scenarios_with_lights": 1, "mean_lights_per_scenario": 0.5,
                                       "state_counts": {"go": scenes.LIGHT_GO_STEPS, "stop": scenes.LIGHT_STOP_STEPS}}
    assert stats["paths"] == {"scenarios_with_paths": 1, "scenarios_with_on_route_path": 1, "mean_valid_paths": 1.0}
    assert stats["controllable"] == {"scenarios_with_controllable": 1, "mean_per_scenario": 0.5}


def test_scenario_block(stats, shard_dir):
    block = stats["scenario"]
    assert block["found"] and block["record_index"] == 0
    assert block["file"] == str(shard_dir / "train-00000-of-00002.tfrecord")
    assert block["objects_by_type"] == {"vehicle": 3, "pedestrian": 1}
    assert block["sdc"]["index"] == 0 and block["sdc"]["current_speed"] == pytest.approx(10.0)
    assert block["light_states_now"] == {"stop": 1}
    assert (block["num_paths"], block["num_on_route_paths"], block["num_controllable"]) == (2, 1, 1)
    assert block["problems"] == []


def test_unknown_scenario_id_fails_before_any_statistics(shard_dir):
    with pytest.raises(InputError) as error:
        inspect_shards(shard_dir, scenario_id="nope")
    assert str(error.value) == f"no scenario 'nope' in {shard_dir}; ids look like: scene-a, scene-b"


def test_max_records_stops_early(shard_dir):
    limited = inspect_shards(shard_dir, max_records=1)
    assert (limited["num_records"], limited["objects"]["by_type"]) == (1, {"vehicle": 3, "pedestrian": 1})


def test_format_report_shows_key_numbers(stats):
    text = format_report(stats)
    for expected in ("records            2", "synthetic 2", "schema validation  OK", "vehicle", "6", "68.1%",
                     "10.88 / 12.00 m/s", "98.00 / 98.00 m", "561.00 / 561", "1 of 2", "stop", "Scenario scene-a"):
        assert expected in text, expected
    # Aligned: every value in the summary block starts in the same column.
    summary = [line for line in text.splitlines()[1:6]]
    assert len({line.index(line.split("  ", 2)[-1].strip()) for line in summary if line.strip()}) == 1


def test_bad_records_are_counted_and_listed(tmp_path):
    good = (tmp_path / "good")
    (path,) = write_shards([make_scenario("ok")], good, sizes=SIZES)
    damaged = tmp_path / "damaged.tfrecord"
    damaged.write_bytes(path.read_bytes()[:-10])
    with TFRecordWriter(tmp_path / "garbage.tfrecord") as writer:
        writer.write(b"not an example")
    stats = inspect_shards(tmp_path / "*.tfrecord")
    assert stats["validation"]["num_bad_records"] == 2
    assert any("truncated record at byte 0" in p for p in stats["validation"]["first_problems"])
    assert "2 bad record(s)" in format_report(stats)


def test_load_scenario_by_id(shard_dir):
    assert load_scenario(shard_dir, "scene-b").scenario_id == "scene-b"
    with pytest.raises(InputError, match="no scenario 'zzz' found"):
        load_scenario(shard_dir, "zzz")


def test_real_womd_example_stats():
    stats = inspect_shards(realdata_file("womd/motion_data_one_example.tfrecord"))
    assert (stats["num_records"], stats["validation"]["num_bad_records"]) == (1, 0)
    assert stats["sizes"][0]["sizes"]["num_roadgraph"] == 20000
    assert stats["objects"]["by_type"] == {"vehicle": 119, "pedestrian": 8, "cyclist": 1}
    assert stats["traffic_lights"]["scenarios_with_lights"] == 1
    assert stats["paths"]["scenarios_with_paths"] == 0

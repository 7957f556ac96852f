"""Golden tests: tiny ScenarioNet descriptions pickled by the tests, converted, checked by hand."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from scenariomax import schema as sch
from scenariomax.codec import decode_scenario, encode_scenario
from scenariomax.errors import InputError
from scenariomax.scenario import Scenario
from scenariomax.sources.base import Failure
from scenariomax.sources.scenarionet import ScenarioNetSource, resample_indices, stable_int_ids
from tests.sources.scenarionet.fixtures import MAP_IDS, OBJECT_IDS, build_description, write_pickle


def convert(path, **kwargs) -> list:
    source = ScenarioNetSource(str(path), **kwargs)
    return [item for unit in source.list_units() for item in source.read_unit(unit)]


@pytest.fixture
def converted(tmp_path) -> Scenario:
    items = convert(write_pickle(tmp_path / "sd_toy.pkl", build_description()))
    assert len(items) == 1 and isinstance(items[0], Scenario), items
    return items[0]


def test_objects_types_ids_and_labels(converted):
    assert converted.scenario_id == "toy-sn" and converted.source_dataset == "scenarionet"
    assert converted.validate() == []
    assert converted.object_id.tolist() == [OBJECT_IDS["ego"], OBJECT_IDS["cone"], OBJECT_IDS["ped-a"]]
    assert converted.object_type.tolist() == [sch.OBJECT_TYPE_VEHICLE, sch.OBJECT_TYPE_OTHER,
                                              sch.OBJECT_TYPE_PEDESTRIAN]
    assert converted.tracks_to_predict.tolist() == [False, False, True]
    assert converted.difficulty_level.tolist() == [0, 0, 1]
    assert converted.objects_of_interest.tolist() == [False, False, True]


def test_resampled_from_4hz_to_10hz(converted):
    # x = 2 t: at 10 Hz step k the SDC is at 0.2 k, interpolated between 4 Hz samples.
    np.testing.assert_allclose(converted.x[0, :6], [0.0, 0.2, 0.4, 0.6, 0.8, 1.0], atol=1e-6)
    np.testing.assert_allclose(converted.x[0, 90], 18.0, atol=1e-5)
    assert converted.timestamp_micros[0, :3].tolist() == [0, 100_000, 200_000]
    # The pedestrian is invalid at source step 3 (t = 0.75 s): 10 Hz steps 6..9 touch it.
    assert converted.valid[2, 4:11].tolist() == [True, True, False, False, False, False, True]
    assert converted.x[2, 6] == -1
    np.testing.assert_allclose(converted.y[2, 1], 3.1, atol=1e-6)
    # Sizes stored as (T, 1) and (T,); 2-D positions get z = 0; headings stay wrapped.
    assert converted.length[0, 0] == pytest.approx(4.5) and converted.length[2, 0] == pytest.approx(0.5)
    assert converted.z[1, 0] == 0 and converted.z[0, 0] == pytest.approx(0.5)
    np.testing.assert_allclose(converted.bbox_yaw[2, 0], np.pi / 2, atol=1e-6)


def test_map_ids_types_speed_limits_and_links(converted):
    def types_of(key):
        return set(converted.roadgraph_type[converted.roadgraph_id == MAP_IDS[key]].tolist())

    assert types_of("lane-1") == {sch.RG_LANE_SURFACE_STREET} and types_of("lane-2") == {sch.RG_LANE_FREEWAY}
    assert types_of("edge-1") == {sch.RG_ROAD_EDGE_BOUNDARY} and types_of("crosswalk-1") == {sch.RG_CROSSWALK}
    assert types_of("drivable-1") == set()  # not a roadgraph type: skipped
    lane1 = converted.roadgraph_id == MAP_IDS["lane-1"]
    np.testing.assert_allclose(converted.roadgraph_speed_limit[lane1], 10.0, rtol=1e-6)  # 36 km/h
    np.testing.assert_allclose(converted.roadgraph_speed_limit[converted.roadgraph_id == MAP_IDS["lane-2"]],
                               30 * 0.44704, rtol=1e-6)
    edge = converted.roadgraph_xyz[converted.roadgraph_id == MAP_IDS["edge-1"]]
    assert edge[0, 0] == 0 and edge[-1, 0] == 150  # flipped: the lanes (y = 0) are now on its left
    assert converted.lane_id.tolist() == [MAP_IDS["lane-1"], MAP_IDS["lane-2"]]
    assert converted.lane_successors[0, 0] == MAP_IDS["lane-2"]
    assert converted.lane_predecessors[1, 0] == MAP_IDS["lane-1"]


@pytest.mark.parametrize("dataset, version", [("nuscenes", "nuscenesv1.0-mini"), ("av2", "v2"),
                                              ("", "nuscenesv1.0-trainval")])
def test_placeholder_speed_limits_are_unknown(tmp_path, dataset, version):
    # ScenarioNet's nuScenes and AV2 writers put one constant (100 km/h, 85 mph) on every lane: those maps have no
    # limits: unknown here (the enrichment gives them its lane-type default), and the manifest says why.
    description = build_description()
    description["metadata"]["dataset"], description["version"] = dataset, version
    for key in ("lane-1", "lane-2"):
        description["map_features"][key]["speed_limit_kmh"] = 100
    items = convert(write_pickle(tmp_path / "sd_nusc.pkl", description))
    lanes = np.isin(items[0].roadgraph_type, sch.LANE_TYPES) & items[0].roadgraph_valid
    assert lanes.any() and (items[0].roadgraph_speed_limit[lanes] == -1).all()
    assert "speed_limits_ignored" in items[0].metadata["manifest_notes"]


def test_drivable_area_outline_is_a_road_edge(tmp_path):
    # ScenarioNet's nuScenes / nuPlan / AV2 writers outline the drivable area as solid white lines "boundary_<n>"
    description = build_description()
    outline = np.array([[0.0, 3.0], [150.0, 3.0]])
    description["map_features"]["boundary_0"] = {"type": "ROAD_LINE_SOLID_SINGLE_WHITE", "polyline": outline}
    description["map_features"]["line-9"] = {"type": "ROAD_LINE_SOLID_SINGLE_WHITE", "polyline": outline - [0, 1]}
    scenario = convert(write_pickle(tmp_path / "sd_outline.pkl", description))[0]
    ids = stable_int_ids(description["map_features"])

    def types_of(key):
        return set(scenario.roadgraph_type[scenario.roadgraph_id == ids[key]].tolist())

    assert types_of("boundary_0") == {sch.RG_ROAD_EDGE_BOUNDARY}
    assert types_of("line-9") == {sch.RG_SOLID_SINGLE_WHITE}  # a painted line keyed otherwise stays one


def test_nuplan_speed_limits_in_metres_per_second(tmp_path):
    description = build_description()
    description["metadata"]["dataset"] = "nuplan"
    lane1 = description["map_features"]["lane-1"]
    del lane1["speed_limit_kmh"]
    lane1["speed_limit_mps"] = 11.2
    description["map_features"]["lane-2"]["speed_limit_mps"] = None  # nuPlan lanes without a limit
    del description["map_features"]["lane-2"]["speed_limit_mph"]
    items = convert(write_pickle(tmp_path / "sd_nuplan.pkl", description))
    limits = items[0].roadgraph_speed_limit
    np.testing.assert_allclose(limits[items[0].roadgraph_id == MAP_IDS["lane-1"]], 11.2, rtol=1e-6)
    assert (limits[items[0].roadgraph_id == MAP_IDS["lane-2"]] == -1).all()


def test_traffic_light_resampled(converted):
    assert converted.tl_state.shape == (1, 91)
    assert converted.tl_state[0, 49] == sch.TL_STOP and converted.tl_state[0, 50] == sch.TL_GO
    assert (converted.tl_lane_id == MAP_IDS["lane-1"]).all() and (converted.tl_x == 50).all()


def test_codec_roundtrip(converted):
    assert decode_scenario(encode_scenario(converted)).validate() == []


def test_20s_at_10hz_gives_two_windows(tmp_path):
    desc = build_description(num_steps=201, step_seconds=0.1, scenario_id="long", with_ts=True)
    items = convert(write_pickle(tmp_path / "sd_long.pkl", desc))
    assert [s.scenario_id for s in items] == ["long_t000", "long_t080"]
    np.testing.assert_allclose(items[1].x[0, 10], 2 * 9.0, atol=1e-5)  # current = log step 90 (9 s)
    assert not items[1].tracks_to_predict.any() and items[0].tracks_to_predict.any()


def test_windows_need_the_sdc_valid_at_their_current_step(tmp_path):
    desc = build_description(num_steps=201, step_seconds=0.1, scenario_id="gap")
    desc["tracks"]["ego"]["state"]["valid"][10] = 0.0  # the first window's current step only
    desc["tracks"]["ego"]["state"]["valid"][120] = 0.0  # inside the second window: kept, that step invalid
    items = convert(write_pickle(tmp_path / "sd_gap.pkl", desc))
    assert [s.scenario_id for s in items] == ["gap_t080"]
    assert not items[0].valid[0, 40] and items[0].valid[0].sum() == 90


def test_bad_description_fails_cleanly(tmp_path):
    desc = build_description()
    desc["metadata"]["sdc_id"] = "nobody"
    items = convert(write_pickle(tmp_path / "sd_bad.pkl", desc))
    assert isinstance(items[0], Failure) and "sdc_id" in items[0].reason
    desc = build_description()
    desc["tracks"]["ego"]["state"]["position"] = np.zeros((3, 3))  # wrong length
    items = convert(write_pickle(tmp_path / "sd_bad2.pkl", desc))
    assert isinstance(items[0], Failure) and "\n" not in items[0].reason
    path = write_pickle(tmp_path / "sd_list.pkl", [1, 2, 3])
    with pytest.raises(InputError, match="not a ScenarioNet scenario description"):
        list(ScenarioNetSource(str(path)).read_unit(str(path)))


def test_database_directory_with_mapping(tmp_path):
    write_pickle(tmp_path / "db" / "part_0" / "sd_a.pkl", build_description(scenario_id="a"))
    write_pickle(tmp_path / "elsewhere" / "sd_b.pkl", build_description(scenario_id="b"))
    write_pickle(tmp_path / "db" / "dataset_mapping.pkl", {"sd_a.pkl": "part_0", "sd_b.pkl": "../elsewhere"})
    write_pickle(tmp_path / "db" / "dataset_summary.pkl", {"sd_a.pkl": {}, "sd_b.pkl": {}})
    units = ScenarioNetSource(str(tmp_path / "db")).list_units()
    assert [u.rsplit("/", 1)[-1] for u in units] == ["sd_a.pkl", "sd_b.pkl"]
    assert ScenarioNetSource(str(tmp_path / "db" / "part_0" / "*.pkl")).list_units()[0].endswith("sd_a.pkl")
    source = ScenarioNetSource(str(tmp_path / "db"))
    assert pickle.loads(pickle.dumps(source)) == source and source.name == "scenarionet"


def test_stable_ids_and_resample_plan():
    assert stable_int_ids(["b", "a", "c"]) == {"a": 0, "b": 1, "c": 2}
    assert stable_int_ids(["12", "3"]) == {"12": 12, "3": 3}
    assert resample_indices(np.arange(5) * 0.1) is None
    lower, upper, weight = resample_indices(np.array([0.0, 0.25, 0.5]))
    assert lower.tolist() == [0, 0, 0, 1, 1, 2] and upper.tolist() == [0, 1, 1, 2, 2, 2]
    np.testing.assert_allclose(weight, [0, 0.4, 0.8, 0.2, 0.6, 0], atol=1e-9)

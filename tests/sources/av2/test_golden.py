"""Golden tests: a tiny AV2 scenario written by the test, converted, checked against hand-worked values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scenariomax import schema as sch
from scenariomax.codec import decode_scenario, encode_scenario
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.av2 import Av2Source
from tests.sources.av2.fixtures import SCENARIO_ID, write_scenario_dir

ROAD_LINE = 10**12


@pytest.fixture(scope="module")
def scenario(tmp_path_factory) -> Scenario:
    root = tmp_path_factory.mktemp("av2")
    write_scenario_dir(root)
    source = Av2Source(str(root))
    (item,) = [item for unit in source.list_units() for item in source.read_unit(unit)]
    assert isinstance(item, Scenario), item
    return item


def _row(scenario: Scenario, object_id: int) -> int:
    return int(np.flatnonzero(scenario.object_id == object_id)[0])


def test_scenario_is_sound_and_tagged(scenario):
    assert scenario.validate() == []
    assert scenario.scenario_id == SCENARIO_ID
    assert scenario.source_dataset == "av2"
    assert scenario.num_timesteps == 91 and scenario.current_time_index == 10


def test_window_keeps_the_av_valid_throughout_with_current_nearest_step_49(scenario):
    # 110 raw steps: starts 0..19 all keep the AV valid; 19 puts "current" (start + 10) nearest 49.
    assert scenario.metadata["window_start"] == 19
    assert scenario.is_sdc[0] and scenario.valid[0].all()
    np.testing.assert_allclose(scenario.x[0], 19.0 + np.arange(91))
    np.testing.assert_allclose(scenario.y[0], 0.0)
    np.testing.assert_array_equal(scenario.timestamp_micros[0], np.arange(91) * 100_000)


def test_objects_types_ids_and_drop_of_tracks_outside_the_window(scenario):
    # Bus "300" only exists at raw steps 0..5, before the window: dropped.
    assert sorted(scenario.object_id.tolist()) == [100, 200, 400, 401]  # AV follows the largest id
    types = dict(zip(scenario.object_id.tolist(), scenario.object_type.tolist()))
    assert types[100] == sch.OBJECT_TYPE_VEHICLE
    assert types[200] == sch.OBJECT_TYPE_PEDESTRIAN
    assert types[400] == sch.OBJECT_TYPE_OTHER
    # Relevance order: construction passes 1.9 m from the AV, pedestrian 4 m, the car 10.6 m.
    assert scenario.object_id[1:].tolist() == [400, 200, 100]


def test_ragged_track_is_valid_only_where_rows_exist(scenario):
    ped = _row(scenario, 200)
    np.testing.assert_array_equal(np.flatnonzero(scenario.valid[ped]), np.arange(21, 32))  # raw 40..50
    assert np.all(scenario.x[ped, ~scenario.valid[ped]] == -1)
    np.testing.assert_allclose(scenario.y[ped, 21], -5.0)
    np.testing.assert_allclose(scenario.speed[ped, 21], 1.0)
    np.testing.assert_allclose(scenario.vel_yaw[ped, 21], math.pi / 2, atol=1e-6)


def test_heading_wrapped_speed_and_default_sizes(scenario):
    car, cone = _row(scenario, 100), _row(scenario, 400)
    np.testing.assert_allclose(scenario.bbox_yaw[car], 0.1, atol=1e-6)  # 2*pi + 0.1 wrapped
    np.testing.assert_allclose(scenario.bbox_yaw[cone], -3.0, atol=1e-6)
    np.testing.assert_allclose(scenario.speed[0], 10.0)
    assert (scenario.length[0, 0], scenario.width[0, 0], scenario.height[0, 0]) == pytest.approx((4.5, 2.0, 1.6))
    assert (scenario.length[cone, 0], scenario.width[cone, 0]) == pytest.approx((0.5, 0.5))
    # z = ground (map z = 5) + half the box height.
    np.testing.assert_allclose(scenario.z[0], 5.8, atol=1e-5)
    np.testing.assert_allclose(scenario.z[cone], 5.5, atol=1e-5)


def test_prediction_labels(scenario):
    car = _row(scenario, 100)
    assert scenario.objects_of_interest.tolist() == [i == car for i in range(scenario.num_objects)]
    assert scenario.tracks_to_predict.tolist() == [i == car for i in range(scenario.num_objects)]


def _feature(scenario, feature_id):
    mask = scenario.roadgraph_id == feature_id
    return scenario.roadgraph_xyz[mask], scenario.roadgraph_dir[mask], set(scenario.roadgraph_type[mask].tolist())


def test_lane_centrelines_average_the_boundaries_in_driving_direction(scenario):
    xyz, dirs, types = _feature(scenario, 1)
    assert types == {sch.RG_LANE_SURFACE_STREET} and len(xyz) == 141  # 140 m at 1 m
    np.testing.assert_allclose(xyz[:, 1], 0.0, atol=1e-5)
    np.testing.assert_allclose(xyz[:, 2], 5.0, atol=1e-5)
    np.testing.assert_allclose(dirs[:-1], [[1.0, 0.0, 0.0]] * 140, atol=1e-6)
    xyz2, _, types2 = _feature(scenario, 2)
    assert types2 == {sch.RG_LANE_SURFACE_STREET}  # BUS lanes are vehicle lanes
    np.testing.assert_allclose(xyz2[:, 1], 3.5, atol=1e-5)
    assert _feature(scenario, 3)[2] == {sch.RG_LANE_BIKE}


def test_road_lines_from_marks_shared_boundary_once(scenario):
    lines = {int(i): int(t) for i, t in zip(scenario.roadgraph_id, scenario.roadgraph_type)
             if t in sch.ROAD_LINE_TYPES}
    assert lines == {ROAD_LINE + 2: sch.RG_BROKEN_SINGLE_WHITE, ROAD_LINE + 3: sch.RG_SOLID_SINGLE_WHITE,
                     ROAD_LINE + 4: sch.RG_SOLID_DOUBLE_YELLOW}


def test_road_edge_has_the_drivable_area_on_its_left(scenario):
    xyz, dirs, types = _feature(scenario, 60)
    assert types == {sch.RG_ROAD_EDGE_BOUNDARY}
    # (the ring's closing point repeats its first and has a zero direction)
    bottom = (np.abs(xyz[:, 1] + 2.0) < 1e-4) & (xyz[:, 0] < 139.5) & (np.linalg.norm(dirs, axis=1) > 0)
    assert bottom.sum() > 100
    np.testing.assert_allclose(dirs[bottom], [[1.0, 0.0, 0.0]] * int(bottom.sum()), atol=1e-6)


def test_crosswalk_is_a_closed_polygon(scenario):
    xyz, _, types = _feature(scenario, 50)
    assert types == {sch.RG_CROSSWALK}
    assert len(xyz) == 23  # perimeter 22 m at 1 m, first point repeated at the end
    np.testing.assert_allclose(xyz[0], xyz[-1])
    np.testing.assert_allclose([xyz[:, 0].min(), xyz[:, 0].max()], [60.0, 63.0], atol=1e-5)
    np.testing.assert_allclose([xyz[:, 1].min(), xyz[:, 1].max()], [-2.0, 6.0], atol=1e-5)


def test_lane_graph_keeps_links_to_known_lanes(scenario):
    row = {int(lane): k for k, lane in enumerate(scenario.lane_id)}
    assert scenario.lane_successors[row[1]].tolist()[:2] == [3, -1]  # 999 is not in the map
    assert scenario.lane_left_neighbors[row[1]].tolist()[:2] == [2, -1]
    assert scenario.lane_right_neighbors[row[2]].tolist()[:2] == [1, -1]
    assert scenario.lane_predecessors[row[3]].tolist()[:2] == [1, -1]
    assert np.all(scenario.roadgraph_speed_limit == -1.0)


def test_speed_limit_setting_fills_lanes_only(tmp_path):
    write_scenario_dir(tmp_path)
    (item,) = list(Av2Source(str(tmp_path), lane_speed_limit=11.2).read_unit(str(tmp_path / SCENARIO_ID)))
    is_lane = np.isin(item.roadgraph_type, sch.LANE_TYPES)
    np.testing.assert_allclose(item.roadgraph_speed_limit[is_lane], 11.2)
    np.testing.assert_allclose(item.roadgraph_speed_limit[~is_lane], -1.0)


def test_codec_round_trip(scenario):
    decoded = decode_scenario(encode_scenario(scenario, Sizes(num_roadgraph=2000)))
    assert decoded.validate() == []
    np.testing.assert_allclose(decoded.x[0, :91], scenario.x[0])
    assert decoded.scenario_id == SCENARIO_ID


def test_budget_keeps_the_focal_track_first(tmp_path):
    # the focal car (100) is AV2's track to predict: it keeps its slot over the nearer cone (400)
    write_scenario_dir(tmp_path)
    (item,) = list(Av2Source(str(tmp_path), sizes=Sizes(num_objects=2)).read_unit(str(tmp_path / SCENARIO_ID)))
    assert item.object_id[1:].tolist() == [100]


def test_source_is_picklable_and_lists_units(tmp_path):
    import pickle

    folder = write_scenario_dir(tmp_path / "train")
    source = Av2Source(str(tmp_path))
    assert pickle.loads(pickle.dumps(source)) == source
    assert source.list_units() == [str(folder)]
    assert Av2Source(str(tmp_path / "*" / "*" / "scenario_*.parquet")).list_units() == \
        [str(next(folder.glob("scenario_*.parquet")))]
    assert Av2Source(str(folder)).list_units() == [str(folder)]
    assert source.settings()["lane_speed_limit"] == -1.0


def test_object_ids_fit_float32_and_are_stable():
    from scenariomax.sources.av2.tracks import object_ids_of

    assert object_ids_of(("12", "AV", "7", "zz")).tolist() == [12, 13, 7, 14]
    # Numeric ids beyond float32's exact range (2**24) are renumbered like strings...
    assert object_ids_of(("16777300", "AV", "5")).tolist() == [6, 7, 5]
    # ...and when the free ids would overflow it, every track gets its rank in the sorted table.
    assert object_ids_of(("16777215", "AV", "5")).tolist() == [0, 2, 1]

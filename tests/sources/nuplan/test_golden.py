"""Golden checks of the nuPlan converter on a hand-built log + map (real on-disk layout)."""

from __future__ import annotations

import pickle
import sqlite3

import numpy as np
import pytest

from scenariomax import Scenario, decode_scenario, encode_scenario
from scenariomax import schema as sch
from scenariomax.errors import InputError
from scenariomax.sources.nuplan import NuplanSource
from scenariomax.sources.nuplan.map_features import (
    BOUNDARY_ID_OFFSET,
    CONNECTOR_ID_OFFSET,
    ROAD_EDGE_ID_OFFSET,
)
from tests.sources.nuplan import builders as b

X_TOL = 2e-3  # positions are stored relative to a whole-metre world_origin, so float32 keeps mm precision


def _by_id(scenario: Scenario, object_id: int) -> int:
    return int(np.flatnonzero(scenario.object_id == object_id)[0])


def _window(anchor: int) -> np.ndarray:
    return anchor + 2 * (np.arange(91) - 10)


def test_one_scenario_per_tagged_lidar_pc(nuplan_scenarios):
    assert [type(s) for s in nuplan_scenarios] == [Scenario, Scenario]
    first, second = nuplan_scenarios
    assert first.scenario_id == f"{b.LOG_NAME}_{b.token(5, 40).hex()}"
    assert second.scenario_id == f"{b.LOG_NAME}_{b.token(5, 60).hex()}"
    # two tags on lidar_pc 60 give one scenario carrying both
    assert second.metadata["scenario_tags"] == ["following_lane_with_lead", "near_multiple_vehicles"]
    for scenario in nuplan_scenarios:
        assert scenario.validate() == []
        assert scenario.source_dataset == "nuplan"
        assert scenario.num_timesteps == 91 and scenario.current_time_index == 10


def test_ego_is_sdc_resampled_to_10hz_at_box_centre(nuplan_scenarios):
    scenario = nuplan_scenarios[0]
    assert scenario.sdc_index == 0 and scenario.object_id[0] == 0 and scenario.object_type[0] == 1
    lidar = _window(40)
    times = np.array([b.lidar_time(i) for i in lidar])
    pose_times = b.T0 + np.round((times - b.T0) / 10_000) * 10_000  # nearest 100 Hz ego_pose
    expected_x = b.EGO_START_X + b.EGO_SPEED * (pose_times - b.T0) / 1e6 + 1.461  # rear axle -> centre
    assert scenario.valid[0].all()
    ox, oy, _ = scenario.world_origin
    assert ox == np.round(expected_x[10]) and oy == np.round(b.N0)  # the ego's current position, rounded
    np.testing.assert_allclose(scenario.x[0] + ox, expected_x, atol=X_TOL)
    np.testing.assert_allclose(scenario.y[0] + oy, b.N0, atol=X_TOL)
    np.testing.assert_array_equal(scenario.timestamp_micros[0], times - times[0])
    np.testing.assert_allclose(scenario.velocity_x[0], 10.0, atol=1e-5)
    np.testing.assert_allclose(scenario.speed[0], 10.0, atol=1e-5)
    np.testing.assert_allclose([scenario.length[0, 0], scenario.width[0, 0], scenario.height[0, 0]],
                               [5.176, 2.297, 1.777], atol=1e-5)


def test_agents_types_and_validity(nuplan_scenarios):
    scenario = nuplan_scenarios[0]
    assert scenario.num_objects == 1 + b.NUM_AGENTS
    types = {int(i): int(t) for i, t in zip(scenario.object_id, scenario.object_type)}
    assert types == {0: 1, 1: 1, 2: 1, 3: 2, 4: 3, 5: 4}  # ids: 1 + rank of the track token
    lidar = _window(40)
    pedestrian, bicycle = _by_id(scenario, 3), _by_id(scenario, 4)
    np.testing.assert_array_equal(scenario.valid[pedestrian], lidar < 120)
    np.testing.assert_array_equal(scenario.valid[bicycle], lidar >= 100)
    assert np.all(scenario.x[pedestrian, ~scenario.valid[pedestrian]] == -1)
    np.testing.assert_allclose(scenario.bbox_yaw[bicycle, scenario.valid[bicycle]], 0.1, atol=1e-6)  # 2pi + 0.1
    np.testing.assert_allclose(scenario.velocity_y[pedestrian, scenario.valid[pedestrian]], 0.5)
    lead = _by_id(scenario, 1)
    t = (np.array([b.lidar_time(i) for i in lidar]) - b.T0) / 1e6
    np.testing.assert_allclose(scenario.x[lead] + scenario.world_origin[0], b.E0 + 20 + 10 * t, atol=X_TOL)
    assert scenario.objects_of_interest[lead] and scenario.objects_of_interest.sum() == 1
    # SDC first, then by closest approach: the cone 30 m ahead of the origin beats the pedestrian
    assert list(scenario.object_id[:2]) == [0, 5]


def test_traffic_light_states_and_stop_points(nuplan_scenarios):
    scenario = nuplan_scenarios[0]
    assert scenario.tl_state.shape == (2, 91)  # connector 999 is not in the map -> dropped
    lidar = _window(40)
    expected = np.where(lidar < 100, sch.TL_STOP, np.where(lidar < 180, sch.TL_GO, sch.TL_CAUTION))
    row = int(np.flatnonzero(scenario.tl_lane_id[:, 10] == CONNECTOR_ID_OFFSET + 201)[0])
    np.testing.assert_array_equal(scenario.tl_state[row], expected)
    assert scenario.tl_valid.all()
    ox, oy, _ = scenario.world_origin
    np.testing.assert_allclose(scenario.tl_x[row] + ox, b.E0 + 100, atol=X_TOL)  # start of the connector
    np.testing.assert_allclose(scenario.tl_y[row] + oy, b.N0, atol=X_TOL)
    other = 1 - row
    assert scenario.tl_lane_id[other, 0] == CONNECTOR_ID_OFFSET + 202
    np.testing.assert_array_equal(scenario.tl_state[other], sch.TL_UNKNOWN)
    # the light's lane id is the connector's centreline id in the roadgraph
    assert np.any(scenario.roadgraph_id == CONNECTOR_ID_OFFSET + 201)


def test_lane_graph_links(nuplan_scenarios):
    scenario = nuplan_scenarios[0]
    c201, c202 = CONNECTOR_ID_OFFSET + 201, CONNECTOR_ID_OFFSET + 202

    def links(table, lane):
        row = int(np.flatnonzero(scenario.lane_id == lane)[0])
        return sorted(v for v in getattr(scenario, table)[row] if v != -1)

    assert sorted(scenario.lane_id.tolist()) == [101, 102, 103, c201, c202]
    assert links("lane_successors", 101) == [c202] and links("lane_successors", 102) == [c201]
    assert links("lane_predecessors", 103) == [c201, c202]
    assert links("lane_successors", c201) == [103] and links("lane_predecessors", c201) == [102]
    assert links("lane_left_neighbors", 102) == [101] and links("lane_right_neighbors", 101) == [102]
    assert links("lane_left_neighbors", 101) == [] and links("lane_right_neighbors", 102) == []


def test_speed_limits_and_roadgraph_feature_counts(nuplan_scenarios):
    scenario = nuplan_scenarios[0]
    limits = {int(i): float(v) for i, v in zip(scenario.roadgraph_id, scenario.roadgraph_speed_limit)}
    assert limits[101] == pytest.approx(13.4) and limits[CONNECTOR_ID_OFFSET + 201] == pytest.approx(11.0)
    assert limits[103] == -1.0 and limits[CONNECTOR_ID_OFFSET + 202] == -1.0  # NULL speed_limit_mps
    features = {}
    for rg_type, rg_id in set(zip(scenario.roadgraph_type.tolist(), scenario.roadgraph_id.tolist())):
        features.setdefault(rg_type, set()).add(rg_id)
    assert len(features[sch.RG_LANE_SURFACE_STREET]) == 5  # 3 lanes + 2 connectors
    assert features[sch.RG_SOLID_SINGLE_WHITE] == {BOUNDARY_ID_OFFSET + 401, BOUNDARY_ID_OFFSET + 403}
    assert features[sch.RG_BROKEN_SINGLE_WHITE] == {BOUNDARY_ID_OFFSET + 402}
    assert len(features[sch.RG_CROSSWALK]) == 1
    assert len(features[sch.RG_STOP_SIGN]) == 1  # only the STOP_SIGN stop polygon, not the light's stop line
    assert len(features[sch.RG_ROAD_EDGE_BOUNDARY]) >= 1
    np.testing.assert_allclose(np.linalg.norm(scenario.roadgraph_dir[:, :2], axis=1)[
        scenario.roadgraph_type == 2].max(), 1.0, atol=1e-5)


def _inside_drivable(x: float, y: float) -> bool:
    e, n = x - b.E0, y - b.N0
    return (-200 < e <= 120 and -1.75 < n < 5.25) or (120 <= e < 400 and -1.75 < n < 1.75)


def test_road_edges_have_the_road_on_their_left(nuplan_scenarios):
    scenario = nuplan_scenarios[0]
    edge = (scenario.roadgraph_type == sch.RG_ROAD_EDGE_BOUNDARY) & (np.linalg.norm(scenario.roadgraph_dir, axis=1) > 0)
    assert edge.sum() > 100
    assert np.all(scenario.roadgraph_id[edge] >= ROAD_EDGE_ID_OFFSET)
    xyz = scenario.roadgraph_xyz[edge].astype(np.float64) + scenario.world_origin
    direction = scenario.roadgraph_dir[edge].astype(np.float64)
    left = xyz[:, :2] + 0.5 * np.stack([-direction[:, 1], direction[:, 0]], axis=1)
    right = xyz[:, :2] - 0.5 * np.stack([-direction[:, 1], direction[:, 0]], axis=1)
    assert all(_inside_drivable(*p) for p in left)
    assert not any(_inside_drivable(*p) for p in right)


def test_lonlat_map_gives_the_same_roadgraph(nuplan_scenarios, nuplan_lonlat_files):
    source = NuplanSource(str(nuplan_lonlat_files.db_path), str(nuplan_lonlat_files.maps_root))
    lonlat = next(iter(source.read_unit(str(nuplan_lonlat_files.db_path))))
    utm = nuplan_scenarios[0]
    for feature in (101, 103, CONNECTOR_ID_OFFSET + 202, BOUNDARY_ID_OFFSET + 403):
        a = utm.roadgraph_xyz[utm.roadgraph_id == feature]
        c = lonlat.roadgraph_xyz[lonlat.roadgraph_id == feature]
        np.testing.assert_allclose(c[0], a[0], atol=X_TOL)
        np.testing.assert_allclose(c[-1], a[-1], atol=X_TOL)
    np.testing.assert_array_equal(lonlat.tl_state, utm.tl_state)


def test_codec_round_trip(nuplan_scenarios):
    for scenario in nuplan_scenarios:
        decoded = decode_scenario(encode_scenario(scenario))
        assert decoded.validate() == []
        n = scenario.num_objects
        np.testing.assert_array_equal(decoded.x[:n], scenario.x)
        np.testing.assert_array_equal(decoded.valid[:n], scenario.valid)
        np.testing.assert_array_equal(decoded.object_type[:n], scenario.object_type)
        r = scenario.roadgraph_xyz.shape[0]
        np.testing.assert_array_equal(decoded.roadgraph_type[:r], scenario.roadgraph_type)


def test_stride_option_and_default_without_tags(nuplan_files, tmp_path):
    source = NuplanSource(str(nuplan_files.db_path), str(nuplan_files.maps_root), stride_steps=20)
    anchors = [s.metadata["anchor_lidar_pc_token"] for s in source.read_unit(str(nuplan_files.db_path))]
    # tags at 40 and 60 plus full windows anchored at 20, 60 (shared) with 40 lidar_pcs between them
    assert anchors == [b.token(5, i).hex() for i in (20, 40, 60)]
    untagged = tmp_path / "untagged.db"
    untagged.write_bytes(nuplan_files.db_path.read_bytes())
    with sqlite3.connect(untagged) as conn:
        conn.execute("DELETE FROM scenario_tag")
    items = list(NuplanSource(str(untagged), str(nuplan_files.maps_root)).read_unit(str(untagged)))
    assert [s.metadata["anchor_lidar_pc_token"] for s in items] == [b.token(5, 20).hex()]  # stride 80: 20, 180>79


def test_list_units_and_pickling(nuplan_files, tmp_path):
    folder = nuplan_files.db_path.parent
    assert NuplanSource(str(folder), "m").list_units() == [str(nuplan_files.db_path)]
    assert NuplanSource(str(folder / "*.db"), "m").list_units() == [str(nuplan_files.db_path)]
    assert NuplanSource(str(nuplan_files.db_path), "m").list_units() == [str(nuplan_files.db_path)]
    with pytest.raises(InputError, match="no nuPlan log databases"):
        NuplanSource(str(tmp_path / "nothing*.db"), "m").list_units()
    source = NuplanSource(str(folder), str(nuplan_files.maps_root), stride_steps=40)
    assert pickle.loads(pickle.dumps(source)) == source
    assert source.name == "nuplan" and source.settings()["stride_steps"] == 40


def test_pipeline_writes_shards_from_a_nuplan_folder(nuplan_files, tmp_path):
    from scenariomax import read_shards
    from scenariomax.pipeline import ConvertSettings, convert

    source = NuplanSource(str(nuplan_files.db_path.parent), str(nuplan_files.maps_root))
    result = convert(source, ConvertSettings(out=tmp_path / "shards", workers=1, progress=False))
    assert result.ok and result.num_scenarios == 2
    read_back = list(read_shards(tmp_path / "shards"))
    assert sorted(s.scenario_id for s in read_back) == sorted(
        f"{b.LOG_NAME}_{b.token(5, i).hex()}" for i in b.TAGGED_LIDAR_PCS)
    assert all(s.validate() == [] for s in read_back)


def test_tag_near_the_end_of_the_log_keeps_91_steps(nuplan_files, tmp_path):
    db = tmp_path / "late_tag.db"
    db.write_bytes(nuplan_files.db_path.read_bytes())
    with sqlite3.connect(db) as conn:
        conn.execute("DELETE FROM scenario_tag")
        conn.execute("INSERT INTO scenario_tag VALUES (?,?,?,?)", (b.token(9, 9), b.token(5, 230), "stationary", None))
    (scenario,) = NuplanSource(str(db), str(nuplan_files.maps_root)).read_unit(str(db))
    assert scenario.validate() == []
    inside = _window(230) < b.NUM_LIDAR_PCS  # sweeps 210..238 exist: steps 0..14
    np.testing.assert_array_equal(scenario.valid[0], inside)
    assert np.all(scenario.timestamp_micros[0, ~inside] == -1) and np.all(scenario.x[0, ~inside] == -1)
    assert np.all(np.diff(scenario.tl_timestamp_micros) > 0)

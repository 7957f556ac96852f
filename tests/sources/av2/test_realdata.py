"""The real AV2 sample (../shared/realdata/av2): converted, validated, and checked against an
independent read of the raw parquet and map JSON."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pyarrow.parquet as pq
import pytest
import shapely

from scenariomax import schema as sch
from scenariomax.codec import decode_scenario, encode_scenario
from scenariomax.scenario import Scenario
from scenariomax.sources.av2 import Av2Source
from tests.conftest import realdata_file

SCENARIO = "0a1e6f0a-1817-4a98-b02e-db8c9327d151"


@pytest.fixture(scope="module")
def raw():
    folder = realdata_file(f"av2/{SCENARIO}")
    table = pq.read_table(folder / f"scenario_{SCENARIO}.parquet").to_pydict()
    archive = json.loads((folder / f"log_map_archive_{SCENARIO}.json").read_text())
    return folder, table, archive


@pytest.fixture(scope="module")
def scenario(raw) -> Scenario:
    folder = raw[0]
    source = Av2Source(str(folder.parent))
    assert source.list_units() == [str(folder)]
    (item,) = list(source.read_unit(str(folder)))
    assert isinstance(item, Scenario), item
    return item


def test_valid_and_survives_the_codec(scenario):
    assert scenario.validate() == []
    decoded = decode_scenario(encode_scenario(scenario))
    assert decoded.validate() == []
    assert decoded.scenario_id == SCENARIO and decoded.source_dataset == "av2"
    n = scenario.num_objects
    np.testing.assert_array_equal(decoded.object_id[:n], scenario.object_id)
    np.testing.assert_array_equal(decoded.x[:n], scenario.x)
    np.testing.assert_array_equal(decoded.valid[:n], scenario.valid)


def test_window_and_object_count_match_the_raw_table(raw, scenario):
    _, table, _ = raw
    av_steps = sorted(t for t, tid in zip(table["timestep"], table["track_id"]) if tid == "AV")
    assert av_steps == list(range(110))  # the AV is seen at every step...
    start = 19  # ...so the window is the last 91 steps (current = raw step 29, nearest AV2's 49)
    assert scenario.metadata["window_start"] == start
    in_window = {tid for t, tid in zip(table["timestep"], table["track_id"]) if start <= t < start + 91}
    assert scenario.num_objects == len(in_window)
    assert int(scenario.valid.sum()) == sum(start <= t < start + 91 for t in table["timestep"])


def test_sdc_trajectory_matches_the_raw_rows(raw, scenario):
    _, table, _ = raw
    rows = {t: (x, y) for t, tid, x, y in zip(table["timestep"], table["track_id"], table["position_x"],
                                              table["position_y"]) if tid == "AV"}
    assert scenario.is_sdc[0] and scenario.valid[0].all()
    expected = np.array([rows[19 + i] for i in range(91)])
    np.testing.assert_allclose(scenario.x[0], expected[:, 0], atol=1e-3, rtol=0)
    np.testing.assert_allclose(scenario.y[0], expected[:, 1], atol=1e-3, rtol=0)


def _features_per_type(scenario) -> Counter:
    pairs = set(zip(scenario.roadgraph_type.tolist(), scenario.roadgraph_id.tolist()))
    return Counter(t for t, _ in pairs)


def test_roadgraph_feature_counts_match_the_map(raw, scenario):
    _, _, archive = raw
    lanes = archive["lane_segments"].values()
    painted = set()
    for lane in lanes:
        for side in ("left", "right"):
            if lane[f"{side}_lane_mark_type"] not in ("NONE", "UNKNOWN", "SOLID_BLUE"):
                xy = tuple((round(p["x"], 2), round(p["y"], 2)) for p in lane[f"{side}_lane_boundary"])
                painted.add(min(xy, xy[::-1]))
    counts = _features_per_type(scenario)
    assert counts[sch.RG_LANE_SURFACE_STREET] == sum(lane["lane_type"] != "BIKE" for lane in lanes) == 34
    assert counts[sch.RG_LANE_BIKE] == sum(lane["lane_type"] == "BIKE" for lane in lanes) == 37
    assert counts[sch.RG_CROSSWALK] == len(archive["pedestrian_crossings"]) == 6
    # The 2 drivable areas touch: their union (seams removed) is 1 outline (and its holes are medians).
    areas = [shapely.Polygon([(p["x"], p["y"]) for p in area["area_boundary"]])
             for area in archive["drivable_areas"].values()]
    union_parts = shapely.get_parts(shapely.union_all(areas).buffer(0.02).buffer(-0.02))
    assert len(archive["drivable_areas"]) == 2
    assert counts[sch.RG_ROAD_EDGE_BOUNDARY] == len(union_parts) == 1
    assert counts.get(sch.RG_ROAD_EDGE_MEDIAN, 0) == sum(len(part.interiors) for part in union_parts)
    assert sum(counts[t] for t in sch.ROAD_LINE_TYPES) == len(painted)
    assert scenario.lane_id.size == len(archive["lane_segments"])


def test_centrelines_agree_with_the_archive_centrelines(raw, scenario):
    # The archive also stores AV2's own centrelines (z = 0 there); ours come from the boundaries.
    _, _, archive = raw
    for lane in archive["lane_segments"].values():
        ours = scenario.roadgraph_xyz[scenario.roadgraph_id == lane["id"], :2]
        theirs = np.array([[p["x"], p["y"]] for p in lane["centerline"]])
        np.testing.assert_allclose(ours[[0, -1]], theirs[[0, -1]], atol=0.1)


def test_road_edges_run_counter_clockwise(scenario):
    for feature in np.unique(scenario.roadgraph_id[scenario.roadgraph_type == sch.RG_ROAD_EDGE_BOUNDARY]):
        xy = scenario.roadgraph_xyz[scenario.roadgraph_id == feature, :2].astype(np.float64)
        area = 0.5 * np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])
        assert area > 0

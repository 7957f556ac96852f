"""Directions, road-edge orientation, speed limits and deterministic ids."""

from __future__ import annotations

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich import (
    edges_to_reverse,
    extract_lanes,
    fill_speed_limits,
    roadgraph_directions,
    stable_id,
    with_edges_oriented,
    with_missing_ids_assigned,
    with_recomputed_directions,
)
from scenariomax.enrich.roadgraph import MapPolyline
from tests.enrich.scenes import line, make_scenario, straight_xy, track


def test_directions_unit_within_polyline_and_zero_at_its_end():
    xyz = np.array([[0, 0, 0], [3, 4, 0], [3, 4, 0], [6, 8, 0], [10, 0, 0], [10, 1, 0]], np.float32)
    ids = np.array([1, 1, 1, 1, 2, 2])
    dirs = roadgraph_directions(xyz, ids, np.ones(6, bool))
    np.testing.assert_allclose(dirs[0], [0.6, 0.8, 0.0], atol=1e-6)
    np.testing.assert_allclose(dirs[1], [0.6, 0.8, 0.0], atol=1e-6)  # repeated point borrows the next step
    np.testing.assert_allclose(dirs[3], 0.0)  # last point of polyline 1
    np.testing.assert_allclose(dirs[4], [0.0, 1.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(dirs[5], 0.0)


def test_directions_stop_at_invalid_points():
    xyz = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], np.float32)
    dirs = roadgraph_directions(xyz, np.array([1, 1, 1]), np.array([True, False, True]))
    np.testing.assert_allclose(dirs, 0.0)


def _road(edge_wrong: bool):
    lane = MapPolyline(1, sch.RG_LANE_SURFACE_STREET, line((0, 0), (100, 0)))
    # Correct: right edge (y=-2) runs +x, left edge (y=+2) runs -x (road on the left of both).
    right = line((0, -2), (100, -2))
    left = line((100, 2), (0, 2))
    if edge_wrong:
        right, left = right[::-1], left[::-1]
    edges = [MapPolyline(2, sch.RG_ROAD_EDGE_BOUNDARY, right), MapPolyline(3, sch.RG_ROAD_EDGE_BOUNDARY, left)]
    return make_scenario([lane] + edges, [track(straight_xy(0, 5))])


def test_wrongly_oriented_edges_are_reversed():
    scenario = _road(edge_wrong=True)
    lanes = extract_lanes(scenario)
    assert len(edges_to_reverse(scenario, lanes)) == 2
    fixed = with_recomputed_directions(with_edges_oriented(scenario, lanes))
    right = fixed.roadgraph_id == 2
    left = fixed.roadgraph_id == 3
    assert fixed.roadgraph_dir[right][0, 0] > 0.99 and fixed.roadgraph_dir[left][0, 0] < -0.99
    assert len(edges_to_reverse(fixed, extract_lanes(fixed))) == 0


def test_correct_edges_are_left_alone():
    scenario = _road(edge_wrong=False)
    assert len(edges_to_reverse(scenario, extract_lanes(scenario))) == 0


def test_speed_limits_keep_known_values_and_default_by_lane_type():
    types = np.array([1, 2, 3, 2, 15])
    limits = fill_speed_limits(types, np.ones(5, bool), np.array([-1, -1, -1, 20.0, 5.0]))
    np.testing.assert_allclose(limits, [29.0, 13.4, 6.7, 20.0, -1.0], atol=1e-6)


def test_ids_are_deterministic_and_missing_ids_get_fresh_ones():
    assert stable_id("lane-7") == stable_id("lane-7") != stable_id("lane-8")
    assert 0 < stable_id("x") < 2 ** 62
    scenario = _road(edge_wrong=False)
    ids = scenario.roadgraph_id.copy()
    ids[ids == 3] = -1
    fixed = with_missing_ids_assigned(scenario.replace(roadgraph_id=ids))
    assert set(np.unique(fixed.roadgraph_id)) == {1, 2, 3}  # max id + 1

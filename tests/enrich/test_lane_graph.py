"""Lane graph: explicit links are used, otherwise links are rebuilt from geometry."""

from __future__ import annotations

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich import (
    LaneGraphSettings,
    extract_lanes,
    lane_graph_to_arrays,
    rebuild_lane_graph,
    scenario_lane_graph,
)
from scenariomax.enrich.roadgraph import LaneLinks, MapPolyline, lane_graph_arrays
from tests.enrich.scenes import line, make_scenario, straight_xy, track

LANE = sch.RG_LANE_SURFACE_STREET


def _ids(lanes, indices):
    return sorted(int(lanes.ids[k]) for k in indices)


def test_fork_gets_both_successors_and_opposite_lane_none():
    arc = np.array([[20 + 20 * np.sin(a), 20 - 20 * np.cos(a), 0.0] for a in np.linspace(0, np.pi / 2, 40)])
    polylines = [
        MapPolyline(10, LANE, line((0, 0), (20, 0))),
        MapPolyline(11, LANE, line((20, 0), (60, 0))),  # straight on
        MapPolyline(12, LANE, arc),  # curve to the left, tangent at the fork
        MapPolyline(13, LANE, line((20.5, 0.5), (0, 0.5))),  # opposite direction, starts at the fork
        MapPolyline(14, LANE, line((21, 0), (21, 30))),  # perpendicular: not a successor
    ]
    scenario = make_scenario(polylines, [track(straight_xy(0, 5))])
    lanes = extract_lanes(scenario)
    graph = rebuild_lane_graph(lanes)
    first = lanes.index_of[10]
    assert _ids(lanes, graph.successors[first]) == [11, 12]
    assert _ids(lanes, graph.predecessors[lanes.index_of[12]]) == [10]
    assert _ids(lanes, graph.successors[lanes.index_of[13]]) == []


def test_parallel_lanes_are_left_and_right_neighbours_unless_an_edge_separates_them():
    polylines = [MapPolyline(1, LANE, line((0, 0), (100, 0))), MapPolyline(2, LANE, line((0, 3.5), (100, 3.5))),
                 MapPolyline(3, LANE, line((0, 10), (100, 10))),  # 6.5 m away: too far
                 MapPolyline(4, LANE, line((0, -3.5), (100, -3.5))),
                 MapPolyline(9, sch.RG_ROAD_EDGE_MEDIAN, line((0, -1.75), (100, -1.75)))]
    scenario = make_scenario(polylines, [track(straight_xy(0, 5))])
    lanes = extract_lanes(scenario)
    graph, rebuilt = scenario_lane_graph(scenario, lanes)
    assert rebuilt
    one = lanes.index_of[1]
    assert _ids(lanes, graph.left[one]) == [2]
    assert _ids(lanes, graph.right[one]) == []  # lane 4 lies beyond the median edge
    assert _ids(lanes, graph.right[lanes.index_of[2]]) == [1]
    arrays = lane_graph_to_arrays(lanes, graph, num_lane_links=4)
    row = list(arrays["lane_id"]).index(1)
    assert list(arrays["lane_left_neighbors"][row]) == [2, -1, -1, -1]


def test_short_parallel_lanes_inside_a_dense_junction_are_still_neighbours():
    # Two 6 m lanes 3.5 m apart under 25 crossing lanes (a crosswalk-dense junction): each of their samples has
    # more than 32 samples of other lanes nearer than its neighbour; every one within reach is still considered.
    crossing = [MapPolyline(100 + k, LANE, line((0.25 * k, -4.0), (0.25 * k, 8.0))) for k in range(25)]
    polylines = [MapPolyline(1, LANE, line((0, 0), (6, 0))), MapPolyline(2, LANE, line((0, 3.5), (6, 3.5))),
                 *crossing]
    scenario = make_scenario(polylines, [track(straight_xy(0, 5))])
    lanes = extract_lanes(scenario)
    graph = rebuild_lane_graph(lanes)
    assert _ids(lanes, graph.left[lanes.index_of[1]]) == [2]
    assert _ids(lanes, graph.right[lanes.index_of[2]]) == [1]
    assert _ids(lanes, graph.left[lanes.index_of[100]]) == []  # crossing lanes 0.25 m apart: too near


def test_an_edge_exactly_at_the_clearance_from_the_lanes_midline_still_separates_them():
    def neighbours(edge_y):  # lanes at y = 0 and 3.5 (midline 1.75), a road edge along y = edge_y, same x points
        polylines = [MapPolyline(1, LANE, line((0, 0), (98, 0))), MapPolyline(2, LANE, line((0, 3.5), (98, 3.5))),
                     MapPolyline(9, sch.RG_ROAD_EDGE_BOUNDARY, line((0, edge_y), (98, edge_y)))]
        scenario = make_scenario(polylines, [track(straight_xy(0, 5))])
        lanes = extract_lanes(scenario)
        graph, _ = scenario_lane_graph(scenario, lanes)
        return _ids(lanes, graph.left[lanes.index_of[1]])

    clearance = LaneGraphSettings().edge_clearance_m
    assert neighbours(1.75 + clearance) == []  # exactly at the clearance: not clear of the edge
    assert neighbours(1.75 + clearance + 0.05) == [2]


def test_explicit_links_win_over_geometry():
    polylines = [MapPolyline(1, LANE, line((0, 0), (50, 0))), MapPolyline(2, LANE, line((50, 0), (100, 0)))]
    links = lane_graph_arrays([LaneLinks(1, successors=()), LaneLinks(2, predecessors=(1,))])
    scenario = make_scenario(polylines, [track(straight_xy(0, 5))], **links)
    lanes = extract_lanes(scenario)
    graph, rebuilt = scenario_lane_graph(scenario, lanes)
    assert not rebuilt
    assert graph.successors[lanes.index_of[1]] == ()  # the source says so, geometry would link them
    assert _ids(lanes, graph.predecessors[lanes.index_of[2]]) == [1]


def test_explicit_links_skip_padding_invalid_rows_and_absent_lanes():
    from scenariomax.enrich.lane_graph import graph_from_scenario_links

    polylines = [MapPolyline(k, LANE, line((0, 4.0 * k), (30, 4.0 * k))) for k in (1, 2, 3, 4)]
    links = lane_graph_arrays([LaneLinks(1, successors=(2, 99, 3), left_neighbors=(4,)), LaneLinks(2, successors=(3,)),
                               LaneLinks(3, predecessors=(1, 2, 2)), LaneLinks(77, successors=(1,)),
                               LaneLinks(4, right_neighbors=(1,))], num_lane_links=4)
    links["lane_successors"][1] = [-1, 3, -1, 1]  # padding between links
    links["lane_valid"][4] = False  # lane 4's row is not read
    scenario = make_scenario(polylines, [track(straight_xy(0, 5))], **links)
    lanes = extract_lanes(scenario)
    graph = graph_from_scenario_links(scenario, lanes)
    index = {int(lane_id): k for k, lane_id in enumerate(lanes.ids)}
    named = {name: {int(lanes.ids[a]): [int(lanes.ids[b]) for b in row] for a, row in enumerate(getattr(graph, name))}
             for name in ("successors", "predecessors", "left", "right")}
    assert named["successors"] == {1: [2, 3], 2: [3, 1], 3: [], 4: []}
    assert named["predecessors"] == {1: [], 2: [], 3: [1, 2], 4: []}  # a link given twice counts once
    assert named["left"] == {1: [4], 2: [], 3: [], 4: []}
    assert named["right"] == {1: [], 2: [], 3: [], 4: []}  # lane 4's row is invalid
    assert set(index) == {1, 2, 3, 4}

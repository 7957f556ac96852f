"""Road-edge orientation: every road-edge polyline runs with the drivable road on its LEFT.

Per edge polyline, each point looks up its nearest lane-centre point (within `search_radius_m`);
if most of those lane points lie to the right of the edge, the polyline's points are reversed.
Edges with no lane nearby are left as they are. Directions must be re-derived afterwards.
"""

from __future__ import annotations

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich.geometry import polyline_runs, run_index, tangents
from scenariomax.enrich.lanes import Lanes, nearest_lane_points
from scenariomax.scenario import Scenario

EDGE_SEARCH_RADIUS_M = 10.0


def edges_to_reverse(scenario: Scenario, lanes: Lanes, search_radius_m: float = EDGE_SEARCH_RADIUS_M) -> np.ndarray:
    """(start, stop) runs of road-edge polylines whose drivable side is on the right. -> (k, 2)"""
    is_edge = np.isin(scenario.roadgraph_type, sch.ROAD_EDGE_TYPES) & scenario.roadgraph_valid
    runs = polyline_runs(scenario.roadgraph_id, is_edge)
    runs = runs[runs[:, 1] - runs[:, 0] >= 2]
    if len(runs) == 0 or lanes.num_lanes == 0:
        return np.zeros((0, 2), np.int64)
    xyz = scenario.roadgraph_xyz.astype(np.float64)
    members = run_index(runs, len(xyz))
    point_ids = np.flatnonzero(members >= 0)
    edge_xy = xyz[point_ids, :2]
    tangent = np.vstack([tangents(xyz[a:b]) for a, b in runs])  # same order as point_ids
    _, nearest = nearest_lane_points(lanes, edge_xy, search_radius_m)
    found = nearest >= 0
    offset = lanes.points[np.where(found, nearest, 0), :2] - edge_xy
    cross = tangent[:, 0] * offset[:, 1] - tangent[:, 1] * offset[:, 0]  # > 0: lane is on the left
    votes = np.zeros(len(runs))
    np.add.at(votes, members[point_ids][found], np.sign(cross[found]))
    return runs[votes < 0]


def with_edges_oriented(scenario: Scenario, lanes: Lanes, search_radius_m: float = EDGE_SEARCH_RADIUS_M) -> Scenario:
    """The scenario with wrongly oriented road-edge polylines reversed (directions not yet updated)."""
    runs = edges_to_reverse(scenario, lanes, search_radius_m)
    if len(runs) == 0:
        return scenario
    xyz = scenario.roadgraph_xyz.copy()
    for start, stop in runs:
        xyz[start:stop] = xyz[start:stop][::-1]
    return scenario.replace(roadgraph_xyz=xyz)

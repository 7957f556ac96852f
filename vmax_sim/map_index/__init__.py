"""Per-scenario map acceleration structure: built once on the host, queried per step in JAX.

The peers check every box corner against every roadgraph point each step, so their step cost
grows with the map. Here the host (numpy, once per scenario) turns the roadgraph into

- a capped list of segments (consecutive points of one polyline, straight runs merged up to one
  cell long), with type, id and speed limit;
- two uniform grids centred on `center_xy` (normally the SDC at the current step) whose cells list
  up to `slots_per_cell` int16 segment indices (-1 pads): one for road edges, one for lane centres;
  segment endpoints, ids and speed limits live once in the segment table, and a query gathers the
  rows its window lists (no per-cell copies);
- a per-cell fallback signed distance to the nearest road edge (for cells with no edge nearby);
- a coarse grid of thinned sample points (edges, lanes, lines) for the observation, quantised to int16
  (positions within 0.2 mm).

About 0.45 MB per scene at the default sizes (it was ~3 MB with dense float32 copies per cell).

Every array's shape depends only on `MapIndexConfig`, never on the roadgraph size R, so per-step
queries touch a fixed, small window of cells whatever the map size.

The package follows that split: `build` (host, numpy, when shards are loaded) and `query` (device,
JAX, inside the step); `structure` holds the `MapIndex` pytree and `MapIndexConfig` they share.
"""

from vmax_sim.map_index.build import build_map_index, path_arc_length
from vmax_sim.map_index.query import (
    OBS_POINT_FEATURES,
    LaneCandidates,
    ObservationPoints,
    PathProjection,
    edge_block,
    lane_candidates,
    nearest_lane,
    observation_points,
    project_on_paths,
    query_segments,
    route_reference_arcs,
    signed_edge_distance,
    vertex_aware_side,
)
from vmax_sim.map_index.structure import MapIndex, MapIndexConfig

__all__ = [
    "OBS_POINT_FEATURES",
    "LaneCandidates",
    "MapIndex",
    "MapIndexConfig",
    "ObservationPoints",
    "PathProjection",
    "build_map_index",
    "edge_block",
    "lane_candidates",
    "nearest_lane",
    "observation_points",
    "path_arc_length",
    "project_on_paths",
    "query_segments",
    "route_reference_arcs",
    "signed_edge_distance",
    "vertex_aware_side",
]

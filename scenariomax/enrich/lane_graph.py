"""The lane graph (successors, predecessors, left/right neighbours) of a scenario.

Explicit links from the source are used when the scenario has them (`lane_id` with any link).
Otherwise (raw WOMD tf.Example: points only) the graph is rebuilt from the lane polylines:
- successor: a lane's last point lies within `successor_gap_m` (1.5 m) of another lane's first
  point and the headings there differ by less than `max_heading_deg` (45 deg);
- neighbour: sample points every ~2 m along a lane; another lane is a neighbour when at least
  `min_neighbor_samples` samples (or all, for short lanes) see it `neighbor_min_m`..`neighbor_max_m`
  (2-5 m) away laterally with headings within `neighbor_heading_deg` (30 deg), and no road edge
  passes within 0.5 m of the midpoint between them. Left/right is the majority side.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from scenariomax import schema as sch
from scenariomax.enrich.lanes import Lanes, edge_tree
from scenariomax.enrich.roadgraph import LaneLinks, lane_graph_arrays
from scenariomax.scenario import Scenario


@dataclasses.dataclass(frozen=True)
class LaneGraphSettings:
    successor_gap_m: float = 1.5
    max_heading_deg: float = 45.0
    neighbor_min_m: float = 2.0
    neighbor_max_m: float = 5.0
    neighbor_heading_deg: float = 30.0
    neighbor_sample_spacing_m: float = 2.0
    min_neighbor_samples: int = 3
    edge_clearance_m: float = 0.5


@dataclasses.dataclass(frozen=True)
class LaneGraph:
    """Links between lane *indices* of a `Lanes` object (each a tuple of indices per lane)."""

    successors: tuple[tuple[int, ...], ...]
    predecessors: tuple[tuple[int, ...], ...]
    left: tuple[tuple[int, ...], ...]
    right: tuple[tuple[int, ...], ...]


def _as_tuples(pairs: np.ndarray, num_lanes: int) -> tuple[tuple[int, ...], ...]:
    table: list[list[int]] = [[] for _ in range(num_lanes)]
    for a, b in np.asarray(pairs).tolist():  # Python ints: iterating numpy scalars is slow
        if b not in table[a]:
            table[a].append(b)
    return tuple(tuple(row) for row in table)


def has_explicit_links(scenario: Scenario) -> bool:
    links = (scenario.lane_successors, scenario.lane_predecessors, scenario.lane_left_neighbors,
             scenario.lane_right_neighbors)
    return bool(scenario.lane_valid.any() and any(table.size and (table >= 0).any() for table in links))


def graph_from_scenario_links(scenario: Scenario, lanes: Lanes) -> LaneGraph:
    """The source's explicit lane links, mapped onto lane indices (links to absent lanes dropped)."""
    index_of = lanes.index_of
    lane_ids, lane_valid = scenario.lane_id.tolist(), scenario.lane_valid.tolist()  # Python values: fast loops
    tables = {}
    for name in ("lane_successors", "lane_predecessors", "lane_left_neighbors", "lane_right_neighbors"):
        pairs = []
        table = getattr(scenario, name)  # (L, K), padded with -1
        rows, columns = np.nonzero(table >= 0)  # the links only, row by row in order (most slots are padding)
        for row, other in zip(rows.tolist(), table[rows, columns].tolist()):
            if lane_valid[row] and lane_ids[row] in index_of and other in index_of:
                pairs.append((index_of[lane_ids[row]], index_of[other]))
        tables[name] = _as_tuples(np.array(pairs, np.int64).reshape(-1, 2), lanes.num_lanes)
    return LaneGraph(tables["lane_successors"], tables["lane_predecessors"],
                     tables["lane_left_neighbors"], tables["lane_right_neighbors"])


def _successor_pairs(lanes: Lanes, settings: LaneGraphSettings) -> np.ndarray:
    first = lanes.offsets[:-1]
    last = lanes.offsets[1:] - 1
    starts, ends = lanes.points[first, :2], lanes.points[last, :2]
    start_dir, end_dir = lanes.point_tangent[first], lanes.point_tangent[last]
    hits = cKDTree(starts).query_ball_point(ends, r=settings.successor_gap_m)
    pairs = np.array([(a, b) for a, row in enumerate(hits) for b in row if a != b], np.int64).reshape(-1, 2)
    if len(pairs) == 0:
        return pairs
    aligned = (end_dir[pairs[:, 0]] * start_dir[pairs[:, 1]]).sum(-1) > np.cos(np.radians(settings.max_heading_deg))
    return pairs[aligned]


def _lane_samples(lanes: Lanes, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """One sample every `spacing` metres along each lane: the first of its points at or past each mark (the
    last point past its end), each point once. All lanes at once. -> point indices (s,), samples per lane (K,)"""
    cum = np.concatenate(lanes.cumulative) if lanes.num_lanes else np.zeros(0)  # (P,) arc along its lane
    total = cum[lanes.offsets[1:] - 1]  # (K,) lane lengths (every lane has >= 2 points)
    num_marks = np.ceil((total + 1e-9) / spacing).astype(np.int64)  # len(np.arange(0, total + 1e-9, spacing))
    mark_lane = np.repeat(np.arange(lanes.num_lanes), num_marks)
    marks = (np.arange(num_marks.sum()) - np.repeat(np.cumsum(num_marks) - num_marks, num_marks)) * spacing
    # np.searchsorted(cum_k, marks) per lane, as one search over (lane, arc) pairs (complex: lexicographic).
    at = np.searchsorted(lanes.point_lane + 1j * cum, mark_lane + 1j * marks, side="left")
    at = np.minimum(at, (lanes.offsets[1:] - 1)[mark_lane])  # past a lane's end: its last point
    fresh = np.ones(len(at), bool)
    fresh[1:] = at[1:] != at[:-1]  # marks are ascending per lane: duplicates are neighbours
    samples = at[fresh]
    return samples, np.bincount(lanes.point_lane[samples], minlength=lanes.num_lanes)


def _neighbor_pairs(lanes: Lanes, edge_xy: np.ndarray, settings: LaneGraphSettings) -> tuple[np.ndarray, np.ndarray]:
    """(left pairs, right pairs) as (lane, neighbour) index rows."""
    samples, samples_per_lane = _lane_samples(lanes, settings.neighbor_sample_spacing_m)
    sample_lane = lanes.point_lane[samples]
    sample_xy = lanes.points[samples, :2]
    sample_dir = lanes.point_tangent[samples]
    # Every pair of samples (every 2 m) within reach, each once (i < j): only the pairs that exist, where a fixed
    # k nearest per sample mostly returned padding (and, in dense junctions, cut real neighbours off).
    near = cKDTree(sample_xy).query_pairs(settings.neighbor_max_m + 1.0, output_type="ndarray")  # (p, 2)
    x, y = sample_xy[:, 0].copy(), sample_xy[:, 1].copy()  # (s,) each: 1-D gathers cost less than (s, 2) rows
    dir_x, dir_y = sample_dir[:, 0].copy(), sample_dir[:, 1].copy()
    a, b = near[:, 0], near[:, 1]
    # The tests that read both samples alike, on each unordered pair once: another lane, headings close.
    alike = ((sample_lane[a] != sample_lane[b])
             & (dir_x[a] * dir_x[b] + dir_y[a] * dir_y[b] > np.cos(np.radians(settings.neighbor_heading_deg))))
    a, b = a[alike], b[alike]
    rows, other = np.concatenate([a, b]), np.concatenate([b, a])  # both ways round
    # Exact lateral distance to the other lane: project onto the other sample's tangent line.
    offset_x, offset_y = x[other] - x[rows], y[other] - y[rows]
    other_x, other_y = dir_x[other], dir_y[other]
    lateral = np.abs(offset_x * other_y - offset_y * other_x)
    along = np.abs(offset_x * other_x + offset_y * other_y)
    ok = ((lateral >= settings.neighbor_min_m) & (lateral <= settings.neighbor_max_m)
          & (along <= settings.neighbor_sample_spacing_m))
    rows, other, offset = rows[ok], other[ok], np.stack([offset_x[ok], offset_y[ok]], 1)  # offset (q, 2)
    # Per sample, nearest first: the nearest sample of each neighbour lane casts that sample's vote below.
    order = np.lexsort((np.hypot(offset[:, 0], offset[:, 1]), rows))
    rows, other, offset = rows[order], other[order], offset[order]
    if len(edge_xy) and len(rows):
        midpoints = sample_xy[rows] + 0.5 * offset
        # Clear: no edge point within edge_clearance_m. The search stops at the clearance (an edge point at exactly
        # that distance is found: the bound is the next float up), not at each midpoint's nearest edge point.
        bound = np.nextafter(settings.edge_clearance_m, np.inf)
        clearance, _ = edge_tree(lanes, edge_xy).query(midpoints, k=1, distance_upper_bound=bound)
        clear = np.isinf(clearance)
        rows, other, offset = rows[clear], other[clear], offset[clear]
    side = np.sign(sample_dir[rows, 0] * offset[:, 1] - sample_dir[rows, 1] * offset[:, 0])  # + left
    lane_a, lane_b = sample_lane[rows], sample_lane[other]
    # One vote per (sample, neighbour lane): a sample may see several points of the same lane.
    # Pairs of non-negative ints as one int64 key (a * K + b sorts as the rows (a, b) do): np.unique on 1-D keys,
    # several times cheaper than np.unique(axis=0), with the same order and first occurrences.
    num = lanes.num_lanes
    key = np.unique(rows * num + lane_b, return_index=True)[1]
    lane_a, lane_b, side, rows = lane_a[key], lane_b[key], side[key], rows[key]
    pairs, inverse, counts = np.unique(lane_a * num + lane_b, return_inverse=True, return_counts=True)
    pair_keys = np.stack([pairs // num, pairs % num], 1)
    inverse = inverse.reshape(-1)
    side_votes = np.zeros(len(pair_keys))
    np.add.at(side_votes, inverse, side)
    needed = np.minimum(settings.min_neighbor_samples, samples_per_lane[pair_keys[:, 0]]) if len(pair_keys) else []
    enough = counts >= needed
    left = pair_keys[enough & (side_votes > 0)]
    right = pair_keys[enough & (side_votes < 0)]
    return left.reshape(-1, 2), right.reshape(-1, 2)


def rebuild_lane_graph(lanes: Lanes, edge_xy: np.ndarray | None = None,
                       settings: LaneGraphSettings = LaneGraphSettings()) -> LaneGraph:
    """Lane graph inferred from lane geometry alone (see the module docstring for the rules)."""
    num = lanes.num_lanes
    if num == 0:
        return LaneGraph((), (), (), ())
    succ = _successor_pairs(lanes, settings)
    edge_xy = np.zeros((0, 2)) if edge_xy is None else np.asarray(edge_xy, np.float64)[:, :2]
    left, right = _neighbor_pairs(lanes, edge_xy, settings) if num > 1 else (np.zeros((0, 2), np.int64),) * 2
    return LaneGraph(_as_tuples(succ, num), _as_tuples(succ[:, ::-1], num), _as_tuples(left, num),
                     _as_tuples(right, num))


def road_edge_points(scenario: Scenario) -> np.ndarray:
    mask = np.isin(scenario.roadgraph_type, sch.ROAD_EDGE_TYPES) & scenario.roadgraph_valid
    return scenario.roadgraph_xyz[mask, :2].astype(np.float64)


def scenario_lane_graph(scenario: Scenario, lanes: Lanes,
                        settings: LaneGraphSettings = LaneGraphSettings()) -> tuple[LaneGraph, bool]:
    """(graph, rebuilt): the source's links when present, else a graph rebuilt from geometry."""
    if has_explicit_links(scenario):
        return graph_from_scenario_links(scenario, lanes), False
    return rebuild_lane_graph(lanes, road_edge_points(scenario), settings), True


def lane_graph_to_arrays(lanes: Lanes, graph: LaneGraph, num_lane_links: int = 8) -> dict:
    """Scenario lane_* arrays (ids, not indices), as `enrich.roadgraph.lane_graph_arrays` returns."""
    ids = lanes.ids
    links = [LaneLinks(lane_id=int(ids[k]),
                       successors=[int(ids[j]) for j in graph.successors[k]],
                       predecessors=[int(ids[j]) for j in graph.predecessors[k]],
                       left_neighbors=[int(ids[j]) for j in graph.left[k]],
                       right_neighbors=[int(ids[j]) for j in graph.right[k]])
             for k in range(lanes.num_lanes)]
    return lane_graph_arrays(links, num_lane_links)

"""Paths along the lane graph from an agent's start pose (the SDC's `path_samples/*`).

Search: the lanes near the start position (within `start_radius_m`, heading within
`start_heading_deg`) are the roots; the path starts at the projection of the start position onto
the root lane. A depth-first search follows successors and (at most `max_lane_changes` times)
left/right neighbours, until a path reaches the point budget or a dead end. Branches that the
logged trajectory drives over are explored first, and the search is capped (`max_candidates`,
`max_expansions`), so its cost stays bounded in dense intersections.

Lane changes: only into a neighbour running the same way (a source may name the oncoming lane a neighbour, as
AV2 does). When the logged trajectory moves from lane A to its neighbour B, the path blends
from A to B exactly where the log does (the blend weight follows the logged lateral position
between the two centrelines), so the on-route path keeps hugging the logged trajectory. Without
such evidence, a lane change starts `default_change_delay_m` ahead and blends over
`default_change_length_m` (smoothstep).

Ranking and on-route: the logged positions from the current step onward (the part a policy
drives; the past lies behind the path start) are compared to each path. The path that follows the
log ranks first (below), the others by mean distance; a path is on route when at least
`on_route_fraction` (95%) of those positions lie within `on_route_tolerance_m` (1.0 m) of it. Paths
are resampled every `spacing_m` (1 m) and padded to `points_per_path` (valid False).

Following the log (`follow_log`): a lane path covers the log when every logged position lies within
the tolerance of it, in order (each foot on the path at or past the previous one, not further on than
the log has driven: a path that loops back past the log does not count). The covering path with the
smallest mean distance follows the log. When none covers it (the log changes lanes without a
neighbour link, drives between lanes, or leaves the lane graph), the candidate that covers the log
longest is spliced: it is kept up to the last position it covers (its last `splice_blend_m` pulled
smoothly onto the log; dropped when shorter), then the path runs through the logged positions until
the log rejoins a lane (within `log_rejoin_radius_m`, heading aligned, and within the tolerance for
the next `log_rejoin_length_m`), where a new search continues along the lane graph (its start pulled
onto the log likewise; at most `max_log_splices` times). A log that never rejoins is followed to its
end, then the path blends into the nearest heading-aligned lane there, or runs straight on along the
last heading. The spliced path is added to the candidates. Points on the log carry the id of the
nearest heading-aligned lane within `max_change_offset_m` (-1 when none, as on a straight run-on).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from scenariomax._compiled import kernels
from scenariomax.enrich.geometry import (
    arc_lengths,
    point_at_arc,
    polyline_segments,
    project_to_polyline,
    project_to_polylines,
    row_norm,
    slice_polyline,
)
from scenariomax.enrich.lane_graph import LaneGraph
from scenariomax.enrich.lanes import Lanes

# Scenario.metadata key naming who made the SDC paths when a source ships its own (e.g. "waymo": WOMD 1.3.1
# Scenario protos); enrichment keeps such paths instead of reconstructing them.
PATHS_SOURCE = "paths_source"
PATHS_RECONSTRUCTED = "reconstructed"


@dataclasses.dataclass(frozen=True)
class PathSettings:
    num_paths: int = 10
    points_per_path: int = 300
    spacing_m: float = 1.0
    start_radius_m: float = 3.0
    fallback_start_radius_m: float = 6.0  # tried when no lane lies within start_radius_m
    start_heading_deg: float = 45.0
    max_start_lanes: int = 6
    max_candidates: int = 40
    max_expansions: int = 400
    max_lane_changes: int = 1
    unlogged_lane_changes: bool = True  # also offer lane changes the log does not show
    default_change_delay_m: float = 10.0
    default_change_length_m: float = 30.0
    min_change_length_m: float = 8.0
    max_change_offset_m: float = 6.0
    track_hit_radius_m: float = 1.5
    bridge_gaps: bool = True  # connect lane-graph gaps the log drives through (missing connectors)
    max_bridge_start_gap_m: float = 6.0
    rejoin_radius_m: float = 1.0
    rejoin_heading_deg: float = 30.0
    on_route_tolerance_m: float = 1.0
    on_route_fraction: float = 0.95
    follow_log: bool = True  # splice the logged positions in where no lane path covers the log
    splice_blend_m: float = 10.0  # lane path ends and starts pulled onto the log over this length
    log_rejoin_radius_m: float = 0.5
    log_rejoin_length_m: float = 5.0
    max_log_splices: int = 8
    splice_search_candidates: int = 8  # search caps after a splice: the log guides the search
    splice_search_expansions: int = 80


@dataclasses.dataclass(frozen=True, eq=False)
class Path:
    """One resampled path."""

    xyz: np.ndarray  # (q, 3) float64, q <= points_per_path
    lane_id: np.ndarray  # (q,) int64
    arc_length: np.ndarray  # (q,) float64
    mean_distance: float  # mean distance of the logged positions to the path, metres
    on_route: bool


@dataclasses.dataclass(frozen=True)
class _Piece:
    xyz: np.ndarray  # (n, 3)
    lane: np.ndarray  # (n,) lane index


def _mean(values: np.ndarray) -> float:
    """np.mean of a non-empty float64 array, the same bits (numpy's pairwise sum over the count) at a third of its
    call cost: the search ranks every candidate by it."""
    return float(np.add.reduce(values)) / len(values)


def _piece_length(piece: _Piece) -> float:
    return float(arc_lengths(piece.xyz)[-1]) if len(piece.xyz) > 1 else 0.0


def _segments(lanes: Lanes, lane: int) -> tuple[np.ndarray, ...]:
    """`polyline_segments` of a lane, built once per scenario: every search projects onto the same lanes."""
    key = ("segments", lane)
    if key not in lanes.memo:
        lanes.memo[key] = polyline_segments(lanes.polyline(lane))
    return lanes.memo[key]


def start_lanes(lanes: Lanes, position: np.ndarray, yaw: float, settings: PathSettings) -> list[tuple[int, float]]:
    """(lane index, arc length of the projected start) of the lanes the path may start on, nearest first."""
    if lanes.num_lanes == 0:
        return []
    heading = np.array([np.cos(yaw), np.sin(yaw)])
    min_cos = np.cos(np.radians(settings.start_heading_deg))
    for radius in (settings.start_radius_m, settings.fallback_start_radius_m):
        near = np.asarray(lanes.tree.query_ball_point(position[:2], r=radius), np.int64)
        if near.size == 0:
            continue
        aligned = near[lanes.point_tangent[near] @ heading > min_cos]
        found = []
        for lane in np.unique(lanes.point_lane[aligned]):
            dist, arc, _ = project_to_polyline(position[None, :2], lanes.polyline(lane), _segments(lanes, lane),
                                               with_foot=False)
            found.append((float(dist[0]), int(lane), float(arc[0])))
        if found:
            found.sort()
            return [(lane, arc) for _, lane, arc in found[: settings.max_start_lanes]]
    return []


def _lane_hits(lanes: Lanes, track: np.ndarray, radius: float) -> np.ndarray:
    """How many logged positions lie near each lane. -> (K,)"""
    hits = np.zeros(lanes.num_lanes)
    if len(track) == 0:
        return hits
    near = lanes.tree.query_ball_point(track, r=radius)  # (m,) lists of lane point indices
    sizes = np.fromiter(map(len, near), np.int64, count=len(near))
    if sizes.sum() == 0:
        return hits
    position = np.repeat(np.arange(len(near)), sizes)  # (k,) the logged position of each nearby lane point
    lane = lanes.point_lane[np.concatenate([row for row in near if row])]
    pairs = np.unique(position * lanes.num_lanes + lane)  # each (position, lane) once
    hits += np.bincount(pairs % lanes.num_lanes, minlength=lanes.num_lanes)
    return hits


class _TrackNearLanes:
    """The logged positions (m, 2) projected onto lanes, each lane once (the search asks for the same lane
    again with every lane change from or into it), and only the positions that may lie within `radius` of
    it: `of(lane)` -> (distance (m,), foot arc (m,)), exact where the distance is < `radius`, inf / nan
    for the positions outside the lane's bounding box grown by `radius` (+1 m against rounding)."""

    def __init__(self, lanes: Lanes, track: np.ndarray, radius: float):
        self.lanes, self.track, self.radius = lanes, track, radius
        self._done: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._beside: dict[int, bool] = {}
        self._inside: np.ndarray | None = None  # (K, m) positions in each lane's grown box, on the first projection
        self._far: tuple[np.ndarray, np.ndarray] | None = None
        # x and y apart: comparing (m, 2) and reducing over the 2-wide axis costs more than the test itself.
        self._x, self._y = track[:, 0], track[:, 1]

    def of(self, lane: int) -> tuple[np.ndarray, np.ndarray]:
        if lane not in self._done:
            self._done[lane] = self._project(lane)
        return self._done[lane]

    def beside(self, lane: int) -> bool:
        """Whether at least two positions lie within `radius` of the lane (asked again with every lane change
        from or into it)."""
        if lane not in self._beside:
            self._beside[lane] = np.count_nonzero(self.of(lane)[0] < self.radius) >= 2
        return self._beside[lane]

    def _far_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(inf, nan) for every position: a lane whose grown box holds none (one pair, shared, read only)."""
        if self._far is None:
            self._far = (np.full(len(self.track), np.inf), np.full(len(self.track), np.nan))
        return self._far

    def _project(self, lane: int) -> tuple[np.ndarray, np.ndarray]:
        compiled = kernels()
        if compiled is not None and self.lanes.counts[lane] >= 2:  # box test and projection in one pass, same values
            line, _, _, sx, sy, seg_len2, cum = _segments(self.lanes, lane)
            dist, arc, inside = compiled.track_on_lane(self.track, self.lanes.boxes[lane], self.radius, line, sx, sy,
                                                       seg_len2, cum)
            return (dist, arc) if inside else self._far_arrays()
        if self._inside is None:  # the box test of every lane at once: most lanes asked for lie away from the log
            boxes = self.lanes.boxes
            low, high = boxes[:, :2] - self.radius - 1.0, boxes[:, 2:] + self.radius + 1.0  # (K, 2)
            self._inside = ((self._x >= low[:, 0:1]) & (self._x <= high[:, 0:1]) & (self._y >= low[:, 1:2])
                            & (self._y <= high[:, 1:2]))  # (K, m)
        near = np.flatnonzero(self._inside[lane])  # (k,)
        if not near.size:
            return self._far_arrays()
        dist, arc = np.full(len(self.track), np.inf), np.full(len(self.track), np.nan)
        # Each position's projection is computed on its own: a subset gives the same values.
        dist[near], arc[near], _ = project_to_polyline(self.track[near], self.lanes.polyline(lane),
                                                       _segments(self.lanes, lane), with_foot=False)
        return dist, arc


def _logged_change(on_lanes: _TrackNearLanes, lane_a: int, cum_a: np.ndarray, lane_b: int,
                   arc_from: float, settings: PathSettings) -> tuple[np.ndarray, np.ndarray] | None:
    """Where the log moves from lane A to lane B: (arcs along A, blend weights 0..1) or None."""
    if len(on_lanes.track) < 3:
        return None
    # `on_lanes` was built with radius max_change_offset_m: fewer than two positions that near A or B leave fewer
    # than two `between` them.
    if not on_lanes.beside(lane_a) or not on_lanes.beside(lane_b):
        return None
    dist_a, arc_a = on_lanes.of(lane_a)
    dist_b, _ = on_lanes.of(lane_b)
    between = ((dist_a < settings.max_change_offset_m) & (dist_b < settings.max_change_offset_m)
               & (arc_a >= arc_from - 1.0) & (arc_a < cum_a[-1] - 1e-3))
    idx = np.flatnonzero(between)
    if idx.size < 2:
        return None
    frac = dist_a[idx] / np.maximum(dist_a[idx] + dist_b[idx], 1e-6)  # 0 on A, 1 on B
    if frac[0] >= 0.5 or not (frac > 0.5).any():
        return None
    cross = int(np.argmax(frac > 0.5))
    low = np.flatnonzero(frac[:cross] <= 0.05)
    lo = int(low[-1]) if low.size else 0
    high = np.flatnonzero(frac[cross:] >= 0.95)
    hi = cross + int(high[0]) if high.size else len(frac) - 1
    arcs, weights = arc_a[idx[lo:hi + 1]], np.clip(frac[lo:hi + 1], 0.0, 1.0)
    keep = np.concatenate([[True], arcs[1:] > np.maximum.accumulate(arcs)[:-1] + 1e-3])
    arcs, weights = arcs[keep], np.maximum.accumulate(weights[keep])
    if arcs.size < 2:
        return None
    # The blend weight is the logged lateral fraction itself; short ramps take it to exactly 0 and 1.
    ramp = settings.default_change_length_m / 3.0
    arcs = np.concatenate([[arcs[0] - weights[0] * ramp], arcs, [arcs[-1] + (1.0 - weights[-1]) * ramp]])
    weights = np.concatenate([[0.0], weights, [1.0]])
    arcs[0] = max(arcs[0], arc_from)
    arcs[-1] = min(arcs[-1], cum_a[-1])
    if arcs[-1] - arcs[0] < 1.0:
        return None
    arcs = np.maximum.accumulate(arcs)
    # Densify so the blend is sampled at least every metre.
    dense = np.linspace(arcs[0], arcs[-1], max(int(np.ceil(arcs[-1] - arcs[0])) + 1, 2))
    return dense, np.interp(dense, arcs, weights)


def _direction_at(line: np.ndarray, cum: np.ndarray, arc: float) -> np.ndarray:
    """Unit direction (2,) of a polyline (n >= 2, 3) at arc length `arc`: its segment there."""
    segment = min(max(int(cum.searchsorted(arc, side="right")) - 1, 0), len(line) - 2)  # np.clip on plain ints
    step = line[segment + 1, :2] - line[segment, :2]
    return step / max(float(np.hypot(*step)), 1e-9)


def _lane_change(lanes: Lanes, lane_a: int, arc_from: float, lane_b: int, on_lanes: _TrackNearLanes,
                 settings: PathSettings) -> tuple[_Piece, float] | None:
    """The piece from `arc_from` on A through the blend onto B, and the arc on B where it lands."""
    cum_a = lanes.cumulative[lane_a]
    logged = _logged_change(on_lanes, lane_a, cum_a, lane_b, arc_from, settings)
    if logged is not None:
        arcs, weights = logged
    elif settings.unlogged_lane_changes:
        start = arc_from + settings.default_change_delay_m
        stop = min(start + settings.default_change_length_m, cum_a[-1])
        if stop - start < settings.min_change_length_m:
            return None
        arcs = np.linspace(start, stop, int(np.ceil(stop - start)) + 1)
        u = (arcs - start) / (stop - start)
        weights = u * u * (3.0 - 2.0 * u)
    else:
        return None  # most offers end here (agents' searches): the polylines are only looked up past it
    line_a, line_b, cum_b = lanes.polyline(lane_a), lanes.polyline(lane_b), lanes.cumulative[lane_b]
    # Most changes end here (on WOMD ~9 in 10 of those offered): B no longer runs beside A where the change
    # would end. The end point alone tells, and a point's projection does not depend on the others projected
    # with it, so the whole blend is only projected for a change that passes (the same values either way).
    segments_b = _segments(lanes, lane_b)
    end_offset, end_arc, _ = project_to_polyline(point_at_arc(line_a, cum_a, arcs[-1:]), line_b, segments_b,
                                                 with_foot=False)
    if end_offset[0] > settings.max_change_offset_m or end_arc[0] >= cum_b[-1] - 1e-3:
        return None  # B does not run alongside A where the change ends
    on_a = point_at_arc(line_a, cum_a, arcs)
    offset, arc_b, _ = project_to_polyline(on_a, line_b, segments_b, with_foot=False)
    if _direction_at(line_a, cum_a, arcs[-1]) @ _direction_at(line_b, cum_b, arc_b[-1]) <= 0.0:
        # B runs the other way (AV2 names the oncoming lane a neighbour): "changing" into it turns the path back
        # along itself, a loop past the log's end and outside the road edges
        return None
    on_b = point_at_arc(line_b, cum_b, arc_b)
    blended = (1.0 - weights)[:, None] * on_a + weights[:, None] * on_b
    before = slice_polyline(line_a, cum_a, arc_from, arcs[0])[:-1]
    xyz = np.vstack([before, blended])
    lane = np.concatenate([np.full(len(before), lane_a), np.where(weights < 0.5, lane_a, lane_b)])
    return _Piece(xyz, lane), float(arc_b[-1])


def _rest_of_lane(lanes: Lanes, lane: int, arc: float) -> tuple[_Piece, float]:
    """The piece of a lane from arc length `arc` to its end, and its length. A whole lane (entered from a
    predecessor, arc 0) is cut once per scenario: every search of every agent walks the same lanes."""
    whole = arc == 0.0
    if whole and lane in lanes.memo:
        return lanes.memo[lane]
    line, cum = lanes.polyline(lane), lanes.cumulative[lane]
    rest = slice_polyline(line, cum, arc, cum[-1])
    piece = _Piece(rest, np.full(len(rest), lane))
    out = piece, _piece_length(piece)
    if whole:
        lanes.memo[lane] = out
    return out


def _rejoin_candidates(lanes: Lanes, track: np.ndarray, track_yaw: np.ndarray,
                       settings: PathSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every logged position, its 8 nearest lane points within `rejoin_radius_m`: found, their lane (-1
    when not found) and whether it runs within `rejoin_heading_deg` of the logged heading. (m, 8) each"""
    dist, idx = lanes.tree.query(track, k=8, distance_upper_bound=settings.rejoin_radius_m)
    hit = np.isfinite(dist)
    lane_of = np.where(hit, lanes.point_lane[np.where(hit, idx, 0)], -1)
    heading = np.stack([np.cos(track_yaw), np.sin(track_yaw)], 1)
    tangent = lanes.point_tangent[np.where(hit, idx, 0)]
    aligned = (tangent * heading[:, None, :]).sum(-1) > np.cos(np.radians(settings.rejoin_heading_deg))
    return hit, lane_of, aligned


def _bridge(lanes: Lanes, end: np.ndarray, track: np.ndarray, rejoins: tuple[np.ndarray, ...], visited: tuple,
            settings: PathSettings) -> tuple[_Piece, int, float] | None:
    """Where the lane graph stops but the log drives on (e.g. an intersection connector missing from
    a cropped map): follow the logged positions from the lane's end to the first lane the log
    rejoins (within `rejoin_radius_m`, heading aligned). Bridge points carry the joined lane's id.
    Returns (piece, joined lane, arc on it) or None. `rejoins`: `_rejoin_candidates` of the track (the same
    for every bridge of a search: computed once)."""
    if len(track) < 2:
        return None
    gap = row_norm(track - end[:2])  # np.linalg.norm(..., axis=1), the same bits
    first = int(gap.argmin())
    if gap[first] > settings.max_bridge_start_gap_m or first + 1 >= len(track):
        return None
    later = track[first + 1:]
    hit, lane_of, aligned = (values[first + 1:] for values in rejoins)  # the positions after the lane's end
    fresh = ~np.isin(lane_of, np.asarray(visited))
    ok = hit & aligned & fresh
    rows = np.flatnonzero(ok.any(axis=1))
    if rows.size == 0:
        return None
    row = int(rows[0])
    lane = int(lane_of[row, int(np.argmax(ok[row]))])
    _, arc, _ = project_to_polyline(later[row:row + 1], lanes.polyline(lane), _segments(lanes, lane),
                                    with_foot=False)
    foot = point_at_arc(lanes.polyline(lane), lanes.cumulative[lane], arc)[0]
    inner = later[:row]
    z = np.linspace(end[2], foot[2], len(inner) + 2)[1:-1]
    xyz = np.vstack([end[None], np.column_stack([inner, z]), foot[None]])
    return _Piece(xyz, np.full(len(xyz), lane)), lane, float(arc[0])


def _may_bridge(end: np.ndarray, track_box: tuple[float, float, float, float] | None, max_gap: float) -> bool:
    """False when `_bridge` from lane end `end` finds no logged position within `max_gap` for sure: its distance
    to the log's box (min x, min y, max x, max y) is no more than that to any position, in floats too (each
    step rounds monotonically). None: fewer than two positions, where `_bridge` finds none either."""
    if track_box is None:
        return False
    x, y = float(end[0]), float(end[1])
    dx = max(track_box[0] - x, x - track_box[2], 0.0)
    dy = max(track_box[1] - y, y - track_box[3], 0.0)
    return not math.sqrt(dx * dx + dy * dy) > max_gap


def _enumerate(lanes: Lanes, graph: LaneGraph, starts: list[tuple[int, float]], track: np.ndarray,
               track_yaw: np.ndarray, settings: PathSettings) -> list[tuple[_Piece, ...]]:
    """Candidate paths as piece sequences (depth-first, log-consistent branches first)."""
    target = (settings.points_per_path - 1) * settings.spacing_m
    hits = _lane_hits(lanes, track, settings.track_hit_radius_m)
    on_lanes = _TrackNearLanes(lanes, track, settings.max_change_offset_m)
    rejoins = None  # _rejoin_candidates, on the first bridge
    # The log's bounding box: most lane ends lie further from it than a bridge may start (plain floats).
    track_box = (*track.min(axis=0).tolist(), *track.max(axis=0).tolist()) if len(track) >= 2 else None
    # Lane changes seen by this search: branches meet again at the same lane (entered at arc 0 from different
    # predecessors) and would rebuild the same change (~1 in 6 on WOMD); the result depends on nothing else.
    known_changes: dict[tuple[int, float, int], tuple[_Piece, float] | None] = {}
    # State: (pieces so far, length so far, lane, entry arc, lane changes used, lanes visited)
    stack = [((), 0.0, lane, arc, 0, (lane,)) for lane, arc in reversed(starts)]
    results: list[tuple[_Piece, ...]] = []
    expansions = 0
    while stack and len(results) < settings.max_candidates and expansions < settings.max_expansions:
        pieces, length, lane, arc, changes, visited = stack.pop()
        expansions += 1
        children = []
        if changes < settings.max_lane_changes:
            for other in graph.left[lane] + graph.right[lane]:
                if other in visited:
                    continue
                key = (lane, arc, other)
                if key not in known_changes:
                    known_changes[key] = _lane_change(lanes, lane, arc, other, on_lanes, settings)
                change = known_changes[key]
                if change is not None:
                    piece, landing = change
                    children.append((hits[other], (pieces + (piece,), length + _piece_length(piece), other,
                                                   landing, changes + 1, visited + (other,))))
        piece, piece_length = _rest_of_lane(lanes, lane, arc)
        rest = piece.xyz
        total = length + piece_length
        successors = [s for s in graph.successors[lane] if s not in visited]
        bridge = None
        if total < target and settings.bridge_gaps and not any(hits[s] > 0 for s in successors):
            if _may_bridge(rest[-1], track_box, settings.max_bridge_start_gap_m):
                if rejoins is None:
                    rejoins = _rejoin_candidates(lanes, track, track_yaw, settings)
                bridge = _bridge(lanes, rest[-1], track, rejoins, visited, settings)
        if total >= target or not (successors or bridge):
            results.append(pieces + (piece,))
        else:
            for nxt in successors:
                children.append((hits[nxt], (pieces + (piece,), total, nxt, 0.0, changes, visited + (nxt,))))
            if bridge is not None:
                link, joined, landing = bridge
                # A bridge exists only because the log drives it: explore it first.
                children.append((np.inf, (pieces + (piece, link), total + _piece_length(link), joined, landing,
                                          changes, visited + (joined,))))
        children.sort(key=lambda item: item[0])  # stable: best pushed last, popped first
        stack.extend(state for _, state in children)
    return results


def _resample(pieces: tuple[_Piece, ...], settings: PathSettings) -> _Piece:
    """The pieces joined and resampled every `spacing_m`, cut to the point budget (lane index -1: none)."""
    xyz = np.concatenate([p.xyz for p in pieces])  # (n, 3) pieces are 2-D: np.vstack's value, fewer calls
    lane = np.concatenate([p.lane for p in pieces])
    compiled = kernels()
    if compiled is not None and len(xyz) and xyz.dtype == np.float64:  # the same values in one pass
        points, point_lane, ok = compiled.resample_path(xyz, lane, float(settings.spacing_m),
                                                        settings.points_per_path)
        if ok:
            return _Piece(points, point_lane)
    cum = arc_lengths(xyz)
    keep = np.empty(len(cum), bool)  # the first point, then every point past the previous one
    keep[0] = True
    np.greater(cum[1:] - cum[:-1], 1e-6, out=keep[1:])
    xyz, lane, cum = xyz[keep], lane[keep], cum[keep]
    total = min(cum[-1], (settings.points_per_path - 1) * settings.spacing_m)
    targets = np.arange(0.0, total + 1e-6, settings.spacing_m)[: settings.points_per_path]
    points = point_at_arc(xyz, cum, targets) if len(xyz) > 1 else xyz[:1]
    # The segment of each target (searchsorted returns <= len: only the lower bound needs np.clip's test).
    segment = np.maximum(np.searchsorted(cum, targets, side="right") - 1, 0)
    return _Piece(points, lane[segment][: len(points)])


def _candidates(lanes: Lanes, graph: LaneGraph, starts: list[tuple[int, float]], track: np.ndarray,
                track_yaw: np.ndarray, settings: PathSettings) -> list[_Piece]:
    """Distinct resampled lane paths from the start lanes, in search order."""
    out: list[_Piece] = []
    seen: set = set()
    for pieces in _enumerate(lanes, graph, starts, track, track_yaw, settings):
        path = _resample(pieces, settings)
        lane = path.lane
        changes = np.concatenate(([True], lane[1:] != lane[:-1]))  # np.r_ without its index-trick overhead
        key = (tuple(lane[changes]), len(path.xyz), tuple(np.round(path.xyz[-1, :2], 1)))
        if key not in seen:
            seen.add(key)
            out.append(path)
    return out


def _aligned_lane_distance(lanes: Lanes, xy: np.ndarray, yaw: np.ndarray, radius: float,
                           heading_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Distance from each position to the nearest lane segment running within `heading_deg` of its
    heading, and that lane's index (inf / -1 beyond `radius`). (m, 2), (m,) -> (m,), (m,)"""
    dist_out, lane_out = np.full(len(xy), np.inf), np.full(len(xy), -1, np.int64)
    if len(xy) == 0 or len(lanes.points) == 0:
        return dist_out, lane_out
    k = min(16, len(lanes.points))
    # Lane points lie <= ~1 m apart: a segment within `radius` has an end point within radius + 1 m.
    dist, idx = lanes.tree.query(xy, k=k, distance_upper_bound=radius + 1.0)
    dist, idx = dist.reshape(len(xy), k), idx.reshape(len(xy), k)
    hit = np.isfinite(dist)
    idx = np.where(hit, idx, 0)  # (m, k)
    heading = np.stack([np.cos(yaw), np.sin(yaw)], 1)
    ok = hit & ((lanes.point_tangent[idx] * heading[:, None, :]).sum(-1) > np.cos(np.radians(heading_deg)))
    best = np.full(dist.shape, np.inf)
    last = len(lanes.points) - 1
    for other in (np.maximum(idx - 1, 0), np.minimum(idx + 1, last)):  # the segments on either side
        same = lanes.point_lane[other] == lanes.point_lane[idx]
        a, b = lanes.points[idx, :2], np.where(same[..., None], lanes.points[other, :2], lanes.points[idx, :2])
        seg = b - a
        frac = np.clip(((xy[:, None, :] - a) * seg).sum(-1) / np.maximum((seg ** 2).sum(-1), 1e-12), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(xy[:, None, :] - (a + frac[..., None] * seg), axis=-1))
    best = np.where(ok, best, np.inf)
    column = best.argmin(axis=1)
    rows = np.arange(len(xy))
    nearest = best[rows, column]
    found = nearest <= radius
    dist_out[found] = nearest[found]
    lane_out[found] = lanes.point_lane[idx[rows, column]][found]
    return dist_out, lane_out


def _covered_prefix(track: np.ndarray, travel: np.ndarray, path: np.ndarray, dist: np.ndarray, arc: np.ndarray,
                    tolerance: float) -> tuple[int, np.ndarray]:
    """How many leading logged positions a path covers in order, and the arc of each one's foot: each
    within `tolerance`, its foot neither behind the previous foot nor further ahead than the log has
    travelled. `dist`, `arc` (m,) are the nearest feet on the whole path; where that foot is out of
    order (the path passes the same place twice) the foot is looked for near the previous one.
    track (m, 2), travel (m,), path (q, 3) -> (count, (count,) arcs)"""
    m = len(track)
    feet = np.zeros(m)
    # The leading positions whose nearest foot is in order, in one pass (most paths cover most of the log): the
    # loop's bounds from the running maximum of those feet, the same float arithmetic. The loop takes over at
    # the first position that is not.
    reach = np.maximum.accumulate(np.concatenate([[0.0], arc]))[:m]  # (m,) prev_arc: max(0, earlier feet)
    before = np.concatenate([[0.0], travel[:-1]])  # (m,) prev_travel
    ok = (dist <= tolerance) & (reach - 2.0 <= arc) & (arc <= reach + 1.5 * (travel - before) + 2.0)
    start = m if ok.all() else int(ok.argmin())
    if start == m:
        return m, arc.copy()
    feet[:start] = arc[:start]
    prev_arc, prev_travel = float(reach[start]), float(before[start])
    cum = None  # arc_lengths(path), when a foot is looked for near the previous one
    # Plain floats in the loop (numpy scalars cost ~10x more per operation; the arithmetic is the same).
    for j, (moved, near, foot) in enumerate(zip(travel[start:].tolist(), dist[start:].tolist(),
                                                arc[start:].tolist()), start):
        low, high = prev_arc - 2.0, prev_arc + 1.5 * (moved - prev_travel) + 2.0
        if near <= tolerance and not low <= foot <= high:
            cum = arc_lengths(path) if cum is None else cum
            lo = max(int(np.searchsorted(cum, low)) - 1, 0)
            hi = min(int(np.searchsorted(cum, high)) + 1, len(cum))
            part = project_to_polyline(track[j:j + 1], path[lo:hi])
            near, foot = float(part[0][0]), float(part[1][0]) + float(cum[lo])
        if near > tolerance or not low <= foot <= high:
            return j, feet[:j]
        feet[j] = foot
        prev_arc, prev_travel = max(prev_arc, foot), moved
    return len(track), feet


def _rejoin_index(lanes: Lanes, track: np.ndarray, track_yaw: np.ndarray, first: int,
                  settings: PathSettings) -> int | None:
    """The first logged position from `first` on where the log is back on a lane: within
    `log_rejoin_radius_m` of a heading-aligned lane and within the tolerance of one for the next
    `log_rejoin_length_m` it drives (or to its end). None when it never rejoins."""
    dist, _ = _aligned_lane_distance(lanes, track[first:], track_yaw[first:], settings.on_route_tolerance_m,
                                     settings.rejoin_heading_deg)
    travel = arc_lengths(track[first:])
    within = dist <= settings.on_route_tolerance_m
    # Number of consecutive positions within the tolerance from each index on.
    run = np.zeros(len(dist) + 1, np.int64)
    for j in range(len(dist) - 1, -1, -1):
        run[j] = run[j + 1] + 1 if within[j] else 0
    for j in np.flatnonzero(dist <= settings.log_rejoin_radius_m):
        horizon = int(np.searchsorted(travel, travel[j] + settings.log_rejoin_length_m, side="right"))
        if run[j] >= horizon - j:
            return first + int(j)
    return None


def _thin(xy: np.ndarray, min_step: float) -> np.ndarray:
    """Indices of the positions kept so that consecutive ones lie >= `min_step` apart (a standing or
    jittering log would otherwise zig-zag the path). (m, 2) -> (k,)"""
    keep, last = [], None
    for j, point in enumerate(xy):
        if last is None or np.hypot(*(point - last)) >= min_step:
            keep.append(j)
            last = point
    if keep[-1] != len(xy) - 1:
        keep.append(len(xy) - 1)  # the path must reach the last position
    return np.asarray(keep, np.int64)


def _log_piece(lanes: Lanes, xy: np.ndarray, yaw: np.ndarray, settings: PathSettings) -> _Piece:
    """Logged positions as path points: z of the nearest lane point, lane index of the nearest
    heading-aligned lane (-1 when none within `max_change_offset_m`)."""
    if len(xy) == 0:
        return _Piece(np.zeros((0, 3)), np.zeros(0, np.int64))
    keep = _thin(xy, 0.5 * settings.spacing_m)
    xy, yaw = xy[keep], yaw[keep]
    _, nearest = lanes.tree.query(xy, k=1)
    _, lane = _aligned_lane_distance(lanes, xy, yaw, settings.max_change_offset_m, settings.rejoin_heading_deg)
    return _Piece(np.column_stack([xy, lanes.points[nearest, 2]]), lane)


def _continuation(lanes: Lanes, graph: LaneGraph, end: np.ndarray, yaw: float, settings: PathSettings) -> _Piece:
    """Past the end of a log that left the lanes: along the nearest heading-aligned lane, blended in from
    the end point (smoothstep, over 4x the lateral offset, `min_change_length_m`..`default_change_length_m`),
    else straight on along the last heading. Starts exactly at `end` (3,)."""
    heading = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    quick = dataclasses.replace(settings, max_candidates=1, max_lane_changes=0, bridge_gaps=False)
    starts = start_lanes(lanes, end, yaw, quick)
    found = _enumerate(lanes, graph, starts, np.zeros((0, 2)), np.zeros(0), quick) if starts else []
    if not found:
        length = (settings.points_per_path - 1) * settings.spacing_m
        steps = np.arange(0.0, length + 1e-6, settings.spacing_m)
        return _Piece(end + steps[:, None] * heading, np.full(len(steps), -1, np.int64))
    lane_path = _resample(found[0], settings)
    cum = arc_lengths(lane_path.xyz)
    offset = float(np.linalg.norm(lane_path.xyz[0, :2] - end[:2]))
    ramp = min(float(np.clip(4.0 * offset, settings.min_change_length_m, settings.default_change_length_m)), cum[-1])
    steps = np.arange(0.0, ramp, settings.spacing_m)
    on_lane = point_at_arc(lane_path.xyz, cum, steps)
    u = steps / max(ramp, 1e-6)
    weight = (u * u * (3.0 - 2.0 * u))[:, None]
    blended = (1.0 - weight) * (end + steps[:, None] * heading) + weight * on_lane
    rest = cum >= ramp
    lane = lane_path.lane[np.clip(np.searchsorted(cum, steps, side="right") - 1, 0, len(cum) - 1)]
    return _Piece(np.vstack([blended, lane_path.xyz[rest]]), np.concatenate([lane, lane_path.lane[rest]]))


def _head(path: _Piece, arc: float) -> _Piece:
    """The part of a resampled path up to arc length `arc` (its end interpolated)."""
    cum = arc_lengths(path.xyz)
    inner = cum < arc
    end = point_at_arc(path.xyz, cum, [arc])
    segment = int(np.clip(np.searchsorted(cum, arc, side="right") - 1, 0, len(cum) - 1))
    return _Piece(np.vstack([path.xyz[inner], end]), np.concatenate([path.lane[inner], [path.lane[segment]]]))


def _fits(track: np.ndarray, candidates: list[_Piece]) -> list[tuple[np.ndarray, np.ndarray]]:
    """(distance, foot arc) of every logged position on each candidate. -> [((m,), (m,))]"""
    return project_to_polylines(track, [path.xyz for path in candidates])


def _pull_to_log(path: _Piece, log: np.ndarray, length: float, at_end: bool) -> _Piece:
    """The path with its last (`at_end`) or first `length` metres moved sideways onto the logged positions
    `log` (k, 2) beside them: fully at its end (start) point, fading out smoothly (smoothstep), so that a
    lane path meets a stretch that follows the log without a jump."""
    if len(path.xyz) < 2 or len(log) == 0:
        return path
    cum = arc_lengths(path.xyz)
    _, arc, foot = project_to_polyline(log, path.xyz)
    order = np.argsort(arc, kind="stable")
    arc, shift = arc[order], (log - foot)[order]  # (k,), (k, 2): from the path to the log
    length = max(min(length, cum[-1]), 1e-6)
    u = np.clip((cum - (cum[-1] - length)) / length if at_end else (length - cum) / length, 0.0, 1.0)
    weight = u * u * (3.0 - 2.0 * u)  # (q,)
    xyz = path.xyz.copy()
    for k in range(2):
        xyz[:, k] += weight * np.interp(cum, arc, shift[:, k])
    return _Piece(xyz, path.lane)


def _follow_log(lanes: Lanes, graph: LaneGraph, candidates: list[_Piece], fits: list[tuple[np.ndarray, np.ndarray]],
                track: np.ndarray, track_yaw: np.ndarray, settings: PathSettings, depth: int = 0) -> _Piece:
    """A path through every logged position (see the module docstring): the candidate that covers the
    whole log, else the one covering it longest, spliced with the log. `track` (m >= 1, 2); `fits`
    from `_fits(track, candidates)`."""
    travel = arc_lengths(track)
    best, best_key, best_fit = None, None, None
    for path, (dist, arc) in zip(candidates, fits):
        covered, feet = _covered_prefix(track, travel, path.xyz, dist, arc, settings.on_route_tolerance_m)
        # Whole log covered first, then the longest covered stretch, then the smallest mean distance.
        key = (covered == len(track), travel[covered - 1] if covered else -1.0, -_mean(dist))
        if best_key is None or key > best_key:
            best, best_key, best_fit = path, key, (dist, feet, covered)
    if best_key is not None and best_key[0]:
        return best
    head = _Piece(np.zeros((0, 3)), np.zeros(0, np.int64))
    covered = best_fit[2] if best is not None else 0
    # A lane path that covers less than the blend length is dropped: it would start beside the log and
    # swerve onto it.
    kept = covered if covered and travel[covered - 1] >= settings.splice_blend_m else 0
    if kept:
        # Keep the lane path up to the last covered position, its end pulled onto the log (no sideways jump).
        feet = best_fit[1]
        near = travel[:covered] >= travel[covered - 1] - 2.0 * settings.splice_blend_m
        head = _pull_to_log(_head(best, float(feet[covered - 1])), track[:covered][near], settings.splice_blend_m,
                            at_end=True)
    # The log rejoins a lane only past where the kept lane path stops covering it, and at least one
    # position on: a new search from where this one started would find the same paths again.
    diverge = max(covered, 1)
    rejoin = (_rejoin_index(lanes, track, track_yaw, diverge, settings)
              if depth < settings.max_log_splices and diverge < len(track) else None)
    stop = len(track) if rejoin is None else rejoin
    bridge = _log_piece(lanes, track[kept:stop], track_yaw[kept:stop], settings)
    if rejoin is None:
        tail = _continuation(lanes, graph, bridge.xyz[-1], float(track_yaw[-1]), settings)
    else:
        narrow = dataclasses.replace(settings, max_candidates=min(settings.max_candidates,
                                                                  settings.splice_search_candidates),
                                     max_expansions=min(settings.max_expansions, settings.splice_search_expansions))
        rest, rest_yaw = track[rejoin:], track_yaw[rejoin:]
        starts = start_lanes(lanes, np.array([*rest[0], 0.0]), float(rest_yaw[0]), narrow)
        found = _candidates(lanes, graph, starts, rest, rest_yaw, narrow) if starts else []
        tail = _follow_log(lanes, graph, found, _fits(rest, found), rest, rest_yaw, narrow, depth + 1)
        # The lane path found there starts beside the log: pull its start onto it.
        near = arc_lengths(rest) <= 2.0 * settings.splice_blend_m
        tail = _pull_to_log(tail, rest[near], settings.splice_blend_m, at_end=False)
    return _Piece(np.vstack([head.xyz, bridge.xyz, tail.xyz]), np.concatenate([head.lane, bridge.lane, tail.lane]))


def search_paths(lanes: Lanes, graph: LaneGraph, position: np.ndarray, yaw: float, track: np.ndarray,
                 track_yaw: np.ndarray | None = None, settings: PathSettings = PathSettings()) -> list[Path]:
    """Ranked paths (best first, at most `num_paths`) from a start pose; `track` (m, 2) holds the
    logged positions from the start step onward and `track_yaw` (m,) their headings, used to guide,
    rank and mark on-route paths, and followed where no lane path covers them (`follow_log`).
    Returns [] when no lane lies near the start pose."""
    position = np.asarray(position, np.float64)
    track = np.asarray(track, np.float64).reshape(-1, 2)
    track_yaw = np.full(len(track), yaw) if track_yaw is None else np.asarray(track_yaw, np.float64)
    starts = start_lanes(lanes, position, yaw, settings)
    if not starts:
        return []
    candidates = _candidates(lanes, graph, starts, track, track_yaw, settings)
    fits = _fits(track, candidates)
    followed = None
    if settings.follow_log and len(track):
        followed = _follow_log(lanes, graph, candidates, fits, track, track_yaw, settings)
        if not any(followed is c for c in candidates):
            followed = _resample((followed,), settings)
            candidates, fits = [followed] + candidates, _fits(track, [followed]) + fits
    paths: list[Path] = []
    first = None  # the path that follows the log ranks first, the rest by mean distance
    for candidate, (dist, _) in zip(candidates, fits):
        xyz = candidate.xyz
        lane_id = np.where(candidate.lane >= 0, lanes.ids[np.maximum(candidate.lane, 0)], -1)
        arc = np.arange(len(xyz)) * settings.spacing_m
        if len(track) and len(xyz) > 1:
            mean = _mean(dist)
            on_route = np.count_nonzero(dist <= settings.on_route_tolerance_m) / len(dist) >= settings.on_route_fraction
        else:
            mean, on_route = 0.0, len(track) == 0
        paths.append(Path(xyz, lane_id, arc, mean, on_route))
        first = paths[-1] if candidate is followed else first
    paths.sort(key=lambda p: (p is not first, p.mean_distance))
    return paths[: settings.num_paths]


def paths_to_arrays(paths: list[Path], num_paths: int, points_per_path: int) -> dict:
    """Fixed-size Scenario path arrays (path_xyz, path_valid, path_lane_id, path_arc_length, path_on_route)."""
    xyz = np.zeros((num_paths, points_per_path, 3), np.float32)
    valid = np.zeros((num_paths, points_per_path), bool)
    lane_id = np.full((num_paths, points_per_path), -1, np.int64)
    arc = np.zeros((num_paths, points_per_path), np.float32)
    on_route = np.zeros(num_paths, bool)
    for row, path in enumerate(paths[:num_paths]):
        n = len(path.xyz)
        xyz[row, :n], valid[row, :n], lane_id[row, :n], arc[row, :n] = path.xyz, True, path.lane_id, path.arc_length
        on_route[row] = path.on_route
    return dict(path_xyz=xyz, path_valid=valid, path_lane_id=lane_id, path_arc_length=arc, path_on_route=on_route)


def logged_track(x: np.ndarray, y: np.ndarray, yaw: np.ndarray, valid: np.ndarray,
                 start: int) -> tuple[np.ndarray, np.ndarray]:
    """Valid positions (m, 2) and headings (m,) of one object from step `start` onward; inputs (T,)."""
    mask = np.asarray(valid, bool).copy()
    mask[:start] = False
    return np.stack([x[mask], y[mask]], axis=1).astype(np.float64), np.asarray(yaw, np.float64)[mask]

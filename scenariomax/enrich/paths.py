"""Paths along the lane graph from an agent's start pose (the SDC's `path_samples/*`).

Search: the lanes near the start position (within `start_radius_m`, heading within
`start_heading_deg`) are the roots; the path starts at the projection of the start position onto
the root lane. A depth-first search follows successors and (at most `max_lane_changes` times)
left/right neighbours, until a path reaches the point budget or a dead end. Branches that the
logged trajectory drives over are explored first, and the search is capped (`max_candidates`,
`max_expansions`), so its cost stays bounded in dense intersections.

Lane changes: when the logged trajectory moves from lane A to its neighbour B, the path blends
from A to B exactly where the log does (the blend weight follows the logged lateral position
between the two centrelines), so the on-route path keeps hugging the logged trajectory. Without
such evidence, a lane change starts `default_change_delay_m` ahead and blends over
`default_change_length_m` (smoothstep).

Ranking and on-route: the logged positions from the current step onward (the part a policy
drives; the past lies behind the path start) are compared to each path. Paths are ranked by mean
distance; a path is on route when at least `on_route_fraction` (95%) of those positions lie
within `on_route_tolerance_m` (1.0 m) of it. Paths are resampled every `spacing_m` (1 m) and
padded to `points_per_path` (valid False).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scenariomax.enrich.geometry import (
    arc_lengths,
    point_at_arc,
    project_to_polyline,
    slice_polyline,
)
from scenariomax.enrich.lane_graph import LaneGraph
from scenariomax.enrich.lanes import Lanes


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


def _piece_length(piece: _Piece) -> float:
    return float(arc_lengths(piece.xyz)[-1]) if len(piece.xyz) > 1 else 0.0


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
            dist, arc, _ = project_to_polyline(position[None, :2], lanes.polyline(lane))
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
    for row in lanes.tree.query_ball_point(track, r=radius):
        if row:
            hits[np.unique(lanes.point_lane[row])] += 1
    return hits


def _logged_change(track: np.ndarray, line_a: np.ndarray, cum_a: np.ndarray, line_b: np.ndarray,
                   arc_from: float, settings: PathSettings) -> tuple[np.ndarray, np.ndarray] | None:
    """Where the log moves from lane A to lane B: (arcs along A, blend weights 0..1) or None."""
    if len(track) < 3:
        return None
    dist_a, arc_a, _ = project_to_polyline(track, line_a)
    dist_b, _, _ = project_to_polyline(track, line_b)
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


def _lane_change(lanes: Lanes, lane_a: int, arc_from: float, lane_b: int, track: np.ndarray,
                 settings: PathSettings) -> tuple[_Piece, float] | None:
    """The piece from `arc_from` on A through the blend onto B, and the arc on B where it lands."""
    line_a, cum_a = lanes.polyline(lane_a), lanes.cumulative[lane_a]
    line_b, cum_b = lanes.polyline(lane_b), lanes.cumulative[lane_b]
    logged = _logged_change(track, line_a, cum_a, line_b, arc_from, settings)
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
        return None
    on_a = point_at_arc(line_a, cum_a, arcs)
    offset, arc_b, _ = project_to_polyline(on_a, line_b)
    if offset[-1] > settings.max_change_offset_m or arc_b[-1] >= cum_b[-1] - 1e-3:
        return None  # B does not run alongside A where the change ends
    on_b = point_at_arc(line_b, cum_b, arc_b)
    blended = (1.0 - weights)[:, None] * on_a + weights[:, None] * on_b
    before = slice_polyline(line_a, cum_a, arc_from, arcs[0])[:-1]
    xyz = np.vstack([before, blended])
    lane = np.concatenate([np.full(len(before), lane_a), np.where(weights < 0.5, lane_a, lane_b)])
    return _Piece(xyz, lane), float(arc_b[-1])


def _bridge(lanes: Lanes, end: np.ndarray, track: np.ndarray, track_yaw: np.ndarray, visited: tuple,
            settings: PathSettings) -> tuple[_Piece, int, float] | None:
    """Where the lane graph stops but the log drives on (e.g. an intersection connector missing from
    a cropped map): follow the logged positions from the lane's end to the first lane the log
    rejoins (within `rejoin_radius_m`, heading aligned). Bridge points carry the joined lane's id.
    Returns (piece, joined lane, arc on it) or None."""
    if len(track) < 2:
        return None
    gap = np.linalg.norm(track - end[:2], axis=1)
    first = int(gap.argmin())
    if gap[first] > settings.max_bridge_start_gap_m or first + 1 >= len(track):
        return None
    later = track[first + 1:]
    dist, idx = lanes.tree.query(later, k=8, distance_upper_bound=settings.rejoin_radius_m)
    hit = np.isfinite(dist)
    lane_of = np.where(hit, lanes.point_lane[np.where(hit, idx, 0)], -1)
    heading = np.stack([np.cos(track_yaw[first + 1:]), np.sin(track_yaw[first + 1:])], 1)
    tangent = lanes.point_tangent[np.where(hit, idx, 0)]
    aligned = (tangent * heading[:, None, :]).sum(-1) > np.cos(np.radians(settings.rejoin_heading_deg))
    fresh = ~np.isin(lane_of, np.asarray(visited))
    ok = hit & aligned & fresh
    rows = np.flatnonzero(ok.any(axis=1))
    if rows.size == 0:
        return None
    row = int(rows[0])
    lane = int(lane_of[row, int(np.argmax(ok[row]))])
    _, arc, _ = project_to_polyline(later[row:row + 1], lanes.polyline(lane))
    foot = point_at_arc(lanes.polyline(lane), lanes.cumulative[lane], arc)[0]
    inner = later[:row]
    z = np.linspace(end[2], foot[2], len(inner) + 2)[1:-1]
    xyz = np.vstack([end[None], np.column_stack([inner, z]), foot[None]])
    return _Piece(xyz, np.full(len(xyz), lane)), lane, float(arc[0])


def _enumerate(lanes: Lanes, graph: LaneGraph, starts: list[tuple[int, float]], track: np.ndarray,
               track_yaw: np.ndarray, settings: PathSettings) -> list[tuple[_Piece, ...]]:
    """Candidate paths as piece sequences (depth-first, log-consistent branches first)."""
    target = (settings.points_per_path - 1) * settings.spacing_m
    hits = _lane_hits(lanes, track, settings.track_hit_radius_m)
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
                change = _lane_change(lanes, lane, arc, other, track, settings)
                if change is not None:
                    piece, landing = change
                    children.append((hits[other], (pieces + (piece,), length + _piece_length(piece), other,
                                                   landing, changes + 1, visited + (other,))))
        line, cum = lanes.polyline(lane), lanes.cumulative[lane]
        rest = slice_polyline(line, cum, arc, cum[-1])
        piece = _Piece(rest, np.full(len(rest), lane))
        total = length + _piece_length(piece)
        successors = [s for s in graph.successors[lane] if s not in visited]
        bridge = None
        if total < target and settings.bridge_gaps and not any(hits[s] > 0 for s in successors):
            bridge = _bridge(lanes, rest[-1], track, track_yaw, visited, settings)
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


def _resample(pieces: tuple[_Piece, ...], lanes: Lanes, settings: PathSettings) -> tuple[np.ndarray, ...]:
    xyz = np.vstack([p.xyz for p in pieces])
    lane = np.concatenate([p.lane for p in pieces])
    cum = arc_lengths(xyz)
    keep = np.concatenate([[True], np.diff(cum) > 1e-6])
    xyz, lane, cum = xyz[keep], lane[keep], cum[keep]
    total = min(cum[-1], (settings.points_per_path - 1) * settings.spacing_m)
    targets = np.arange(0.0, total + 1e-6, settings.spacing_m)[: settings.points_per_path]
    points = point_at_arc(xyz, cum, targets) if len(xyz) > 1 else xyz[:1]
    segment = np.clip(np.searchsorted(cum, targets, side="right") - 1, 0, len(lane) - 1)
    return points, lanes.ids[lane[segment]], targets[: len(points)]


def search_paths(lanes: Lanes, graph: LaneGraph, position: np.ndarray, yaw: float, track: np.ndarray,
                 track_yaw: np.ndarray | None = None, settings: PathSettings = PathSettings()) -> list[Path]:
    """Ranked paths (best first, at most `num_paths`) from a start pose; `track` (m, 2) holds the
    logged positions from the start step onward and `track_yaw` (m,) their headings, used to guide,
    rank and mark on-route paths. Returns [] when no lane lies near the start pose."""
    position = np.asarray(position, np.float64)
    track = np.asarray(track, np.float64).reshape(-1, 2)
    track_yaw = np.full(len(track), yaw) if track_yaw is None else np.asarray(track_yaw, np.float64)
    starts = start_lanes(lanes, position, yaw, settings)
    if not starts:
        return []
    paths: list[Path] = []
    seen: set = set()
    for pieces in _enumerate(lanes, graph, starts, track, track_yaw, settings):
        xyz, lane_id, arc = _resample(pieces, lanes, settings)
        key = (tuple(lane_id[np.r_[True, lane_id[1:] != lane_id[:-1]]]), len(xyz), tuple(np.round(xyz[-1, :2], 1)))
        if key in seen:
            continue
        seen.add(key)
        if len(track) and len(xyz) > 1:
            dist = project_to_polyline(track, xyz)[0]
            mean, on_route = (float(dist.mean()),
                              bool(np.mean(dist <= settings.on_route_tolerance_m) >= settings.on_route_fraction))
        else:
            mean, on_route = 0.0, len(track) == 0
        paths.append(Path(xyz, lane_id, arc, mean, on_route))
    paths.sort(key=lambda p: p.mean_distance)
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

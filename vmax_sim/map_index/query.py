"""Device side of the map index: pure, jittable JAX queries run inside the simulator step (see
`vmax_sim.map_index`). Each touches a fixed window of cells around the query point, whatever the map size."""

from __future__ import annotations

import flax.struct
import jax
import jax.numpy as jnp
import numpy as np

from vmax_sim.geometry.reductions import argmin_packed
from vmax_sim.map_index.structure import OBS_DIR_STEPS, OBS_SPEED_STEP, OBS_XY_STEPS, MapIndex


def query_segments(map_index: MapIndex, xy: jnp.ndarray, kind: str = "edge",
                   window: int | None = None) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Candidate segments near xy (2,): indices (K,) int32 into MapIndex.seg_* and valid (K,),
    K = window^2 * slots. Covers at least (window // 2) * cell_size metres around xy.
    kind: "edge" or "lane".
    """
    window = window or map_index.query_window
    return _window_segments(map_index, xy, kind, window)


def _cell_value(grid: jnp.ndarray, origin: jnp.ndarray, cell_size: float, xy: jnp.ndarray) -> jnp.ndarray:
    """Value of the (clamped) grid cell holding each point. grid (G, G), xy (..., 2) -> (...,)."""
    g = grid.shape[0]
    cell = jnp.clip(jnp.floor((xy - origin) / cell_size).astype(jnp.int32), 0, g - 1)
    return grid[cell[..., 0], cell[..., 1]]


def _window_start(origin: jnp.ndarray, cell_size: float, xy: jnp.ndarray, window: int, grid_size: int) -> jnp.ndarray:
    """(2,) int32 first cell of the window x window block around xy, clamped into the grid."""
    # odd windows centre on the query's cell, even ones on its nearest cell corner
    start = jnp.floor((xy - origin) / cell_size + 0.5 - 0.5 * window).astype(jnp.int32)
    return jnp.clip(start, 0, grid_size - window)


def _window_segments(map_index: MapIndex, xy: jnp.ndarray, kind: str, window: int) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Segment indices listed by the window x window cells around xy (one contiguous block slice of
    the cell table), and their validity. -> (K,) int32 (0 where not valid), (K,) bool."""
    cells = map_index.edge_cells if kind == "edge" else map_index.lane_cells
    g = cells.shape[0]
    start = _window_start(map_index.origin_xy, map_index.cell_size, xy, window, g)
    index = jax.lax.dynamic_slice(cells, (start[0], start[1], 0), (window, window, cells.shape[2]))
    index = index.reshape(-1).astype(jnp.int32)
    ok = (index >= 0) & _inside_grid(map_index, xy, g, window)
    return jnp.maximum(index, 0), ok


def _inside_grid(map_index: MapIndex, xy: jnp.ndarray, grid_size: int, window: int) -> jnp.ndarray:
    """False when the query cell is so far outside the grid that the clamped window is unrelated."""
    cell = jnp.floor((xy - map_index.origin_xy) / map_index.cell_size).astype(jnp.int32)
    return jnp.all((cell >= -(window // 2)) & (cell < grid_size + window // 2))


def edge_block(map_index: MapIndex, xy: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Road-edge segments of the query window around xy (2,). -> (4, K) [sx, sy, ex, ey], valid (K,)."""
    index, ok = _window_segments(map_index, xy, "edge", map_index.query_window)
    return _segment_rows(map_index, index, ok), ok


def _segment_rows(map_index: MapIndex, index: jnp.ndarray, ok: jnp.ndarray) -> jnp.ndarray:
    """Endpoints of the listed segments (one gather of 16-byte rows), zero where not ok. -> (4, K)."""
    rows = jnp.take(map_index.seg_points, index, axis=0, mode="clip")
    return jnp.where(ok[:, None], rows, 0.0).T


# Two candidate segments count as equally near (a vertex they share) when their squared distances
# differ by less than TIE_RELATIVE * distance^2 + TIE_ABSOLUTE (m^2): float32 rounding of the same
# shared vertex reached from either segment is ~1e-7 relative; the band is 0.04 mm at 7 m and 1 mm
# at 0 m, so a different edge a few millimetres farther never takes part.
TIE_RELATIVE = 1e-5
TIE_ABSOLUTE = 1e-6


def signed_edge_distance(map_index: MapIndex, points: jnp.ndarray, center_xy: jnp.ndarray) -> jnp.ndarray:
    """Signed distance of points to the nearest road edge: > 0 off the road, < 0 on it.

    Road edges are oriented with the road on their left. One window of cells around `center_xy`
    (e.g. the SDC centre) serves all points (e.g. its 4 corners). Where no edge is in reach the
    host-computed distance of the centre's cell is used. points (P, 2), center_xy (2,) -> (P,).

    The side comes from the nearest segments; when several are equally near (the closest point is
    a vertex they share, in one cell or across cells) the one whose supporting line is farthest from
    the point decides (`vertex_aware_side`), which is the side of the vertex's angle-weighted
    pseudo-normal: past a convex corner of the road the point is off the road if it is outside either
    segment, past a reflex one only if it is outside both.
    """
    seg, ok = edge_block(map_index, center_xy)
    # (P, K) layout, reduced over the segments (the minor axis): under vmap at batch >= 32 it vectorises over
    # the K segments and runs 2x faster than (K, P) (which was 2x faster at batch 1; batches matter more)
    sx, sy, ex, ey = seg[0][None], seg[1][None], seg[2][None], seg[3][None]  # (1, K)
    px, py = points[:, 0:1], points[:, 1:2]  # (P, 1)
    dx, dy = ex - sx, ey - sy
    inv_len_sq = 1.0 / jnp.maximum(dx * dx + dy * dy, 1e-12)
    rx, ry = px - sx, py - sy  # (P, K)
    t = jnp.clip((rx * dx + ry * dy) * inv_len_sq, 0.0, 1.0)
    ox, oy = rx - t * dx, ry - t * dy
    dist_sq = jnp.where(ok[None], ox * ox + oy * oy, jnp.inf)  # invalid slots are never among the nearest
    best_sq = jnp.min(dist_sq, axis=1)  # (P,)
    cross = dx * ry - dy * rx  # > 0: point left of the segment (road side)
    off_road = vertex_aware_side(dist_sq, best_sq, cross * jnp.abs(cross) * inv_len_sq, axis=1) < 0.0
    best = jnp.sqrt(jnp.where(jnp.isfinite(best_sq), best_sq, 0.0))
    signed = jnp.where(off_road, best, -best)
    # no edge in the window: every point takes the host-computed distance of the centre's cell
    fallback = _cell_value(map_index.cell_edge_distance, map_index.origin_xy, map_index.cell_size, center_xy)
    return jnp.where(jnp.isfinite(best_sq), signed, fallback).astype(jnp.float32)


def vertex_aware_side(dist_sq, best_sq, line_sq, axis: int = -1):
    """Side of a point from its (equally) nearest segments: > 0 left (road side), < 0 right (off road).

    dist_sq squared point-segment distances with the segments along `axis` (inf for invalid slots),
    best_sq their minimum over that axis, line_sq (as dist_sq) signed squared distances to the
    segments' supporting lines (cross * |cross| / length^2, > 0 left). -> the signed line_sq of largest
    magnitude among the segments within the tie tolerance of the nearest (0 when all are 0; the road
    side wins an exact tie), shaped like best_sq.

    Why: when the closest point is a vertex V shared by segments A and B, the point u = P - V is on
    the road iff u . (n_A + n_B) > 0 (n the unit left normals: the angle-weighted pseudo-normal,
    both angles being pi in 2-D), and the sign of a sum of two terms is the sign of the larger one:
    the segment whose line is farther from P. A segment whose interior is nearest has |line| =
    distance, the largest possible, so it always decides alone. Segments listed in several cells
    repeat the same values, so ties across cells change nothing. Works with numpy and jax arrays.
    """
    xp = jnp if isinstance(dist_sq, jax.Array) else np
    near = dist_sq <= xp.expand_dims(best_sq, axis) * (1.0 + TIE_RELATIVE) + TIE_ABSOLUTE
    left = xp.max(xp.where(near, line_sq, 0.0), axis=axis)
    right = xp.min(xp.where(near, line_sq, 0.0), axis=axis)
    return xp.where(left >= -right, left, right)


@flax.struct.dataclass
class LaneCandidates:
    """Lane-centre segments near a query point, projected (fixed K from the window of cells)."""

    lane_id: jnp.ndarray  # (K,) int32, -1 when invalid
    distance: jnp.ndarray  # (K,) float32, point-to-segment distance (inf when invalid)
    lateral: jnp.ndarray  # (K,) float32, signed offset of the point from the centreline (+ left)
    dir_x: jnp.ndarray  # (K,) float32, unit lane direction x
    dir_y: jnp.ndarray  # (K,) float32, unit lane direction y
    speed_limit: jnp.ndarray  # (K,) float32, m/s, -1 unknown
    closest_x: jnp.ndarray  # (K,) float32, projection of the point on the segment
    closest_y: jnp.ndarray  # (K,) float32
    valid: jnp.ndarray  # (K,) bool

    @property
    def direction(self) -> jnp.ndarray:
        """(K, 2) unit lane directions."""
        return jnp.stack([self.dir_x, self.dir_y], -1)


def lane_candidates(map_index: MapIndex, xy: jnp.ndarray) -> LaneCandidates:
    """Lane-centre segments of the query window around xy (2,), projected. -> LaneCandidates (K)."""
    index, ok = _window_segments(map_index, xy, "lane", map_index.query_window)
    seg = _segment_rows(map_index, index, ok)
    ids = jnp.take(map_index.seg_id, index, mode="clip")
    limit = jnp.take(map_index.seg_speed_limit, index, mode="clip")
    sx, sy, ex, ey = seg[0], seg[1], seg[2], seg[3]
    dx, dy = ex - sx, ey - sy
    length = jnp.sqrt(jnp.maximum(dx * dx + dy * dy, 1e-12))
    ux, uy = dx / length, dy / length
    rx, ry = xy[0] - sx, xy[1] - sy
    along = jnp.clip(rx * ux + ry * uy, 0.0, length)
    cx, cy = sx + along * ux, sy + along * uy
    dist = jnp.sqrt((xy[0] - cx) ** 2 + (xy[1] - cy) ** 2)
    return LaneCandidates(
        lane_id=jnp.where(ok, ids, -1), distance=jnp.where(ok, dist, jnp.inf), lateral=ux * ry - uy * rx,
        dir_x=ux, dir_y=uy, speed_limit=jnp.where(ok, limit, -1.0), closest_x=cx, closest_y=cy, valid=ok)


def nearest_lane(candidates: LaneCandidates, yaw: jnp.ndarray, heading_weight: float = 3.0) -> jnp.ndarray:
    """Index into the candidates of the lane the agent drives on: near and aligned with `yaw`.

    Score = distance + heading_weight * (1 - cos(heading error)), so overlapping lanes at
    junctions resolve to the one the agent follows. -> () int32.
    """
    misalign = 1.0 - (candidates.dir_x * jnp.cos(yaw) + candidates.dir_y * jnp.sin(yaw))
    return argmin_packed(candidates.distance + heading_weight * misalign)


OBS_POINT_FEATURES = 8  # x, y, dir x, dir y, speed limit, is edge, is lane, is line


@flax.struct.dataclass
class ObservationPoints:
    """Observation sample points in the window of observation cells around a centre point."""

    features: jnp.ndarray  # (M, 8) float32, world frame: [x, y, dir x, dir y, speed limit (0 unknown),
    # is edge, is lane, is line]
    types: jnp.ndarray  # (M,) int32
    valid: jnp.ndarray  # (M,) bool

    @property
    def xy(self) -> jnp.ndarray:
        """(M, 2) points."""
        return self.features[:, :2]


def observation_points(map_index: MapIndex, center_xy: jnp.ndarray, window: int = 5) -> ObservationPoints:
    """All thinned points of the window x window observation cells around center_xy (2,).

    M = window^2 * obs_slots_per_cell; covers at least (window - 1) / 2 * obs_cell_size metres.
    No sort: points come in cell order with a validity mask. One block slice of the int16
    MapIndex.obs_points, decoded by one multiply-add (positions within 0.2 mm of the roadgraph's).
    """
    grid, cs = map_index.obs_points, map_index.obs_cell_size
    g, c, f = grid.shape[0], grid.shape[2], grid.shape[3]
    cell = _window_start(map_index.origin_xy, cs, center_xy, window, g)
    block = jax.lax.dynamic_slice(grid, (cell[0], cell[1], 0, 0), (window, window, c, f))
    types = jax.lax.dynamic_slice(map_index.obs_type, (cell[0], cell[1], 0), (window, window, c))
    scale = np.array([cs / OBS_XY_STEPS] * 2 + [1.0 / OBS_DIR_STEPS] * 2 + [OBS_SPEED_STEP, 1.0, 1.0, 1.0],
                     np.float32)
    # x, y are offsets from each cell's centre: the window's lower-left corner (traced) plus a constant
    centre = np.zeros((window, window, 1, f), np.float32)
    centre[..., 0] = ((np.arange(window) + 0.5) * cs)[:, None, None]
    centre[..., 1] = ((np.arange(window) + 0.5) * cs)[None, :, None]
    corner = jnp.concatenate([map_index.origin_xy + cell.astype(jnp.float32) * cs, jnp.zeros(f - 2, jnp.float32)])
    valid = types >= 0
    features = jnp.where(valid[..., None], block.astype(jnp.float32) * scale + (centre + corner), 0.0)
    return ObservationPoints(features=features.reshape(-1, f), valid=valid.reshape(-1),
                             types=jnp.maximum(types, 0).astype(jnp.int32).reshape(-1))


@flax.struct.dataclass
class PathProjection:
    """The projection of a point on each SDC path."""

    distance: jnp.ndarray  # (P,) float32, distance to the path (inf for invalid paths)
    arc: jnp.ndarray  # (P,) float32, arc length of the projection along the path
    direction: jnp.ndarray  # (P, 2) float32, unit path direction at the projection


def project_on_paths(path_xy: jnp.ndarray, path_valid: jnp.ndarray, path_arc: jnp.ndarray,
                     xy: jnp.ndarray, stride: int = 10) -> PathProjection:
    """Project xy (2,) on every path, coarse to fine: nearest knot every `stride` points, then the
    exact segments around it. path_xy (P, N, 2), path_valid (P, N), path_arc (P, N) -> PathProjection.

    Cost is O(P * (N / stride + 2 * stride)) instead of O(P * N).
    """
    num_points = path_xy.shape[1]
    px, py = path_xy[..., 0], path_xy[..., 1]
    kx, ky = px[:, ::stride] - xy[0], py[:, ::stride] - xy[1]
    knot_dist = jnp.where(path_valid[:, ::stride], kx * kx + ky * ky, jnp.inf)
    best_knot = argmin_packed(knot_dist, axis=1) * stride  # (P,)
    width = min(2 * stride + 1, num_points)
    lo = jnp.clip(best_knot - stride, 0, num_points - width)
    # one contiguous (4, width) window per path: a few block copies instead of per-element gathers
    packed = jnp.stack([px, py, path_arc, path_valid.astype(path_xy.dtype)])  # (4, P, N)
    window = jax.vmap(lambda rows, start: jax.lax.dynamic_slice(rows, (0, start), (4, width)),
                      in_axes=(1, 0), out_axes=1)(packed, lo)  # (4, P, width)
    wx, wy, w_arc, w_valid = window[0], window[1], window[2], window[3] > 0.5
    ax, ay, dx, dy = wx[:, :-1], wy[:, :-1], wx[:, 1:] - wx[:, :-1], wy[:, 1:] - wy[:, :-1]
    ok = w_valid[:, :-1] & w_valid[:, 1:]
    rx, ry = xy[0] - ax, xy[1] - ay
    len_sq = jnp.maximum(dx * dx + dy * dy, 1e-12)
    t = jnp.clip((rx * dx + ry * dy) / len_sq, 0.0, 1.0)
    ox, oy = rx - t * dx, ry - t * dy
    dist_sq = jnp.where(ok, ox * ox + oy * oy, jnp.inf)
    k = argmin_packed(dist_sq, axis=1)[:, None]  # (P, 1) nearest segment of each window

    def at_k(values):  # (P, width - 1) -> (P,)
        return jnp.take_along_axis(values, k, axis=1)[:, 0]

    best_sq = at_k(dist_sq)
    t_k = at_k(t)
    arc_k = at_k(w_arc[:, :-1])
    arc = arc_k + t_k * (at_k(w_arc[:, 1:]) - arc_k)
    seg_len = jnp.sqrt(at_k(len_sq))
    direction = jnp.stack([at_k(dx), at_k(dy)], -1) / jnp.maximum(seg_len, 1e-6)[:, None]
    # a path with a single valid point still has a distance
    single = jnp.min(jnp.where(w_valid, (wx - xy[0]) ** 2 + (wy - xy[1]) ** 2, jnp.inf), axis=1)
    dist = jnp.sqrt(jnp.where(jnp.isfinite(best_sq), best_sq, single))
    return PathProjection(distance=dist.astype(jnp.float32), arc=arc.astype(jnp.float32),
                          direction=direction.astype(jnp.float32))


def route_reference_arcs(path_xy: jnp.ndarray, path_valid: jnp.ndarray, path_arc: jnp.ndarray,
                         log_start_xy: jnp.ndarray, log_end_xy: jnp.ndarray) -> jnp.ndarray:
    """Arc length of the logged SDC start and end positions along every path, computed once per
    episode (at reset) for the progress metrics. -> (P, 2) float32 [start arc, end arc]."""
    start = project_on_paths(path_xy, path_valid, path_arc, log_start_xy).arc
    end = project_on_paths(path_xy, path_valid, path_arc, log_end_xy).arc
    return jnp.stack([start, end], -1)

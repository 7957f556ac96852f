"""Per-scenario map acceleration structure: built once on the host, queried per step in JAX.

The peers check every box corner against every roadgraph point each step, so their step cost
grows with the map. Here the host (numpy, once per scenario) turns the roadgraph into

- a capped list of segments (consecutive points of one polyline, straight runs merged up to one
  cell long), with type, id and speed limit;
- two uniform grids centred on `center_xy` (normally the SDC at the current step) whose cells list
  up to `slots_per_cell` segment indices (-1 pads): one for road edges, one for lane centres;
- a per-cell fallback signed distance to the nearest road edge (for cells with no edge nearby);
- a coarse grid of thinned sample points (edges, lanes, lines) for the observation.

Every array's shape depends only on `MapIndexConfig`, never on the roadgraph size R, so per-step
queries touch a fixed, small window of cells whatever the map size.
"""

from __future__ import annotations

import dataclasses

import flax.struct
import jax
import jax.numpy as jnp
import numpy as np

from scenariomax.schema import LANE_TYPES, ROAD_EDGE_TYPES, ROAD_LINE_TYPES
from scenariomax.sources.base import InputError

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

FAR_DISTANCE = 1e4  # metres, stands for "no feature in reach"


@dataclasses.dataclass(frozen=True)
class MapIndexConfig:
    """Sizes of the map index. Region covered = cell_size * grid_size metres per side."""

    cell_size: float = 8.0  # metres per segment-grid cell; also the longest merged segment
    grid_size: int = 64  # cells per side (64 x 8 m = 512 m)
    slots_per_cell: int = 16  # lane segments per cell; overflow keeps those nearest the cell centre
    edge_slots_per_cell: int = 8  # road-edge segments per cell (edges are sparser than lanes)
    max_segments: int = 4096  # S: segments kept, nearest the grid centre first
    query_window: int = 3  # cells per side looked at around a query point (odd: 3 -> 3x3)
    simplify_tolerance: float = 0.1  # metres a merged segment may stray from the points it skips
    edge_types: tuple[int, ...] = ROAD_EDGE_TYPES  # offroad queries
    lane_types: tuple[int, ...] = LANE_TYPES  # lane / route queries
    obs_types: tuple[int, ...] = ROAD_EDGE_TYPES + LANE_TYPES + ROAD_LINE_TYPES  # observation points
    obs_cell_size: float = 16.0  # metres per observation-grid cell
    obs_grid_size: int = 32  # cells per side (32 x 16 m = 512 m)
    obs_slots_per_cell: int = 8  # thinned points per observation cell
    obs_spacing: float = 2.0  # metres between observation points along a polyline
    max_link_gap: float = 5.0  # consecutive points further apart are not joined into a segment

    def __post_init__(self):
        if self.query_window % 2 != 1:
            raise ValueError(f"MapIndexConfig.query_window must be odd, got {self.query_window}")


@flax.struct.dataclass
class MapIndex:
    """Fixed-shape map acceleration structure of one scenario (batch it with leading dims)."""

    seg_start: jnp.ndarray  # (S, 2) float32, segment start points
    seg_end: jnp.ndarray  # (S, 2) float32, segment end points
    seg_type: jnp.ndarray  # (S,) int32, roadgraph type
    seg_id: jnp.ndarray  # (S,) int32, polyline (lane) id
    seg_speed_limit: jnp.ndarray  # (S,) float32, m/s, -1 unknown
    seg_valid: jnp.ndarray  # (S,) bool
    origin_xy: jnp.ndarray  # (2,) float32, lower-left corner of both grids
    edge_cells: jnp.ndarray  # (G, G, Ce) int32, road-edge segment indices, -1 pads
    lane_cells: jnp.ndarray  # (G, G, C) int32, lane-centre segment indices, -1 pads
    # dense per-cell copies (structure of arrays) so a query is one contiguous block slice and the
    # maths runs on unit-stride float vectors instead of gathers and size-2 minor axes
    edge_seg: jnp.ndarray  # (4, G, G, Ce) float32, [start x, start y, end x, end y] per slot
    lane_seg: jnp.ndarray  # (4, G, G, C) float32, same for lane centres
    lane_seg_id: jnp.ndarray  # (G, G, C) int32, lane id per slot (-1 empty)
    lane_seg_speed_limit: jnp.ndarray  # (G, G, C) float32, m/s, -1 unknown
    cell_edge_distance: jnp.ndarray  # (G, G) float32, signed distance of cell centres to the nearest
    # edge, only for cells whose query window holds no edge (0 elsewhere: never read)
    # observation points stored ready to use (array of structures): the per-step transform is one
    # small matmul, and no per-step transpose into the (points, features) layout is needed
    # (Go, Go, Co, 8) float32, [x, y, dir x, dir y, speed limit (0 unknown), is edge, is lane, is line]
    obs_features: jnp.ndarray
    obs_type: jnp.ndarray  # (Go, Go, Co) int32
    obs_speed_limit: jnp.ndarray  # (Go, Go, Co) float32, m/s, -1 unknown
    obs_valid: jnp.ndarray  # (Go, Go, Co) bool
    num_dropped: jnp.ndarray  # () int32, segments lost to the S cap or full cells (diagnostics)
    cell_size: float = flax.struct.field(pytree_node=False, default=8.0)  # static, metres
    obs_cell_size: float = flax.struct.field(pytree_node=False, default=16.0)  # static, metres
    query_window: int = flax.struct.field(pytree_node=False, default=3)  # static, cells per side


# ----------------------------------------------------------------------------- host-side build


def _segments(xyz, types, ids, valid, speed_limit, keep_types, config):
    """Simplified segments of the polylines whose type is in keep_types.

    Consecutive points of one polyline are greedily merged while the merged chord stays within
    `simplify_tolerance` of the points it skips (bound: accumulated turn x length / 8) and no
    longer than one cell. numpy -> (start (n, 2), end (n, 2), type, id, speed limit).
    """
    r = len(xyz)
    empty = (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
    if r < 2:
        return empty
    selected = valid & np.isin(types, keep_types)
    xy = xyz[:, :2].astype(np.float64)
    nxt = np.minimum(np.arange(1, r + 1), r - 1)
    gap = np.linalg.norm(xy[nxt] - xy, axis=1)
    linked = (selected & selected[nxt] & (ids == ids[nxt]) & (types == types[nxt])
              & (np.arange(r) < r - 1) & (gap > 1e-6) & (gap <= config.max_link_gap))
    prev_linked = np.concatenate([[False], linked[:-1]])
    heading = np.arctan2(xy[nxt, 1] - xy[:, 1], xy[nxt, 0] - xy[:, 0])
    turn = np.abs((heading - np.concatenate([heading[:1], heading[:-1]]) + np.pi) % (2 * np.pi) - np.pi)
    turn = np.where(prev_linked & linked, turn, 0.0)
    cum_turn = np.cumsum(turn)
    arc = np.concatenate([[0.0], np.cumsum(np.where(linked, gap, 0.0)[:-1])])
    max_len = config.cell_size - 1.0
    run_starts = np.flatnonzero(linked & ~prev_linked)
    run_ends = np.flatnonzero(~linked & prev_linked)  # last point of each run
    starts, ends = [], []
    for first, last in zip(run_starts, run_ends):
        a = first
        while a < last:
            hi = min(last, a + 64)
            j = np.arange(a + 1, hi + 1)
            length = arc[j] - arc[a]
            bent = cum_turn[j - 1] - cum_turn[a]
            ok = (length <= max_len) & (bent * length / 8.0 <= config.simplify_tolerance)
            ok[0] = True  # always advance by at least one point
            b = int(j[len(ok) - 1 - np.argmax(ok[::-1])]) if ok.all() else int(j[np.argmin(ok) - 1])
            starts.append(a)
            ends.append(b)
            a = b
    if not starts:
        return empty
    a, b = np.asarray(starts), np.asarray(ends)
    return xy[a], xy[b], types[a], ids[a], speed_limit[a]


def _fill_cells(cells_of_item, priority, num_cells, slots):
    """Scatter item indices into (num_cells, slots) keeping the lowest priority first. -> (cells, dropped)."""
    item, cell = cells_of_item
    table = np.full((num_cells, slots), -1, np.int32)
    if len(item) == 0:
        return table, 0
    order = np.lexsort((priority, cell))
    item, cell = item[order], cell[order]
    first = np.searchsorted(cell, cell, side="left")
    rank = np.arange(len(cell)) - first
    keep = rank < slots
    table[cell[keep], rank[keep]] = item[keep]
    return table, int(np.count_nonzero(~keep))


def _segment_cells(start, end, origin, config):
    """(segment, flat cell) pairs for every grid cell a segment's bounding box touches."""
    g, cs = config.grid_size, config.cell_size
    lo = np.floor((np.minimum(start, end) - origin) / cs).astype(np.int64)
    hi = np.floor((np.maximum(start, end) - origin) / cs).astype(np.int64)
    items, cells = [], []
    for dx in range(3):  # segments are at most ~1.5 cells long: their box spans <= 3x3 cells
        for dy in range(3):
            cx, cy = lo[:, 0] + dx, lo[:, 1] + dy
            ok = (cx <= hi[:, 0]) & (cy <= hi[:, 1]) & (cx >= 0) & (cy >= 0) & (cx < g) & (cy < g)
            items.append(np.flatnonzero(ok))
            cells.append(cx[ok] * g + cy[ok])
    return np.concatenate(items), np.concatenate(cells)


def _edge_distance_field(start, end, origin, edge_table, config):
    """Signed distance of cell centres to their nearest road edge (+ = off road). -> (G, G).

    Only cells whose query window holds no edge ever read it, so only those are computed (the
    rest keep 0).
    """
    g, cs, w = config.grid_size, config.cell_size, config.query_window
    field = np.zeros((g, g), np.float32)
    if len(start) == 0:
        return np.full((g, g), -FAR_DISTANCE, np.float32)
    has_edge = np.pad((edge_table >= 0).any(-1), w // 2)
    window_has_edge = np.zeros((g, g), bool)
    for dx in range(w):
        for dy in range(w):
            window_has_edge |= has_edge[dx:dx + g, dy:dy + g]
    cells = np.argwhere(~window_has_edge)
    if len(cells) == 0:
        return field
    pts = origin + (cells + 0.5) * cs  # (C, 2) cell centres
    # Nearest segment via a KD-tree over points every <= 1 m along each segment, then the exact
    # distance and side to that segment: these cells are >= a window away from any edge, so a
    # nearly-nearest segment changes the distance by < 0.5 m (brute force over all segments cost
    # ~45 ms per scenario, this ~3 ms).
    from scipy.spatial import cKDTree

    seg = (end - start).astype(np.float64)
    length = np.linalg.norm(seg, axis=1)
    per_segment = np.maximum(np.ceil(length).astype(np.int64), 1) + 1
    owner = np.repeat(np.arange(len(start)), per_segment)
    first = np.cumsum(per_segment) - per_segment
    frac = (np.arange(len(owner)) - np.repeat(first, per_segment)) / np.repeat(per_segment - 1, per_segment)
    samples = start[owner] + frac[:, None] * seg[owner]
    # The 4 nearest samples hold both ends meeting at a vertex (they coincide), so the side at a
    # vertex follows the same rule as the per-step query (`vertex_aware_side`).
    num_near = min(4, len(samples))
    _, nearest = cKDTree(samples).query(pts, k=num_near)
    k = owner[nearest.reshape(len(pts), num_near)]  # (C, 4) candidate segments
    rel = pts[:, None] - start[k]  # (C, 4, 2)
    inv_len_sq = 1.0 / np.maximum(length[k] ** 2, 1e-12)
    t = np.clip(np.sum(rel * seg[k], -1) * inv_len_sq, 0.0, 1.0)
    dist_sq = np.sum((rel - t[..., None] * seg[k]) ** 2, -1)
    best_sq = dist_sq.min(1)
    cross = seg[k, 0] * rel[..., 1] - seg[k, 1] * rel[..., 0]
    side = vertex_aware_side(dist_sq, best_sq, cross * np.abs(cross) * inv_len_sq)
    dist = np.sqrt(best_sq)
    field[cells[:, 0], cells[:, 1]] = np.where(side < 0, dist, -dist).astype(np.float32)
    return field


def _obs_points(xyz, dirs, types, ids, valid, speed_limit, origin, config):
    """Thinned observation points scattered into the observation grid."""
    go, co = config.obs_grid_size, config.obs_slots_per_cell
    selected = valid & np.isin(types, config.obs_types)
    idx = np.flatnonzero(selected)
    xy = xyz[idx, :2].astype(np.float64)
    # arc length along each polyline, restarting where the id changes; keep one point per spacing
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1) if len(xy) else np.zeros(0)
    same = ids[idx][1:] == ids[idx][:-1] if len(xy) else np.zeros(0, bool)
    step = np.where(same, np.minimum(step, config.max_link_gap), 0.0)
    arc = np.concatenate([[0.0], np.cumsum(step)]) if len(xy) else np.zeros(0)
    bucket = np.floor(arc / config.obs_spacing).astype(np.int64)
    first_in_bucket = np.concatenate([[True], (bucket[1:] != bucket[:-1]) | ~same]) if len(xy) else bucket.astype(bool)
    idx, xy = idx[first_in_bucket], xy[first_in_bucket]
    cell = np.floor((xy - origin) / config.obs_cell_size).astype(np.int64)
    inside = np.all((cell >= 0) & (cell < go), axis=1)
    idx, cell = idx[inside], cell[inside]
    flat = cell[:, 0] * go + cell[:, 1]
    order = np.argsort(flat, kind="stable")  # keep polyline order within a cell so thinning is even
    idx, flat = idx[order], flat[order]
    first = np.searchsorted(flat, flat, side="left")
    count = np.searchsorted(flat, flat, side="right") - first
    rank = np.arange(len(flat)) - first
    slot = np.where(count > co, (rank * co) // np.maximum(count, 1), rank)
    prev_slot = np.where(count > co, ((rank - 1) * co) // np.maximum(count, 1), rank - 1)
    keep = (rank == 0) | (slot != prev_slot)
    idx, flat, slot = idx[keep], flat[keep], slot[keep]
    out_xy = np.zeros((go * go, co, 2), np.float32)
    out_dir = np.zeros((go * go, co, 2), np.float32)
    out_type = np.zeros((go * go, co), np.int32)
    out_limit = np.full((go * go, co), -1.0, np.float32)
    out_valid = np.zeros((go * go, co), bool)
    out_xy[flat, slot] = xyz[idx, :2]
    out_dir[flat, slot] = dirs[idx, :2]
    out_type[flat, slot] = types[idx]
    out_limit[flat, slot] = speed_limit[idx]
    out_valid[flat, slot] = True
    shape = (go, go, co)
    return (out_xy.reshape(shape + (2,)), out_dir.reshape(shape + (2,)), out_type.reshape(shape),
            out_limit.reshape(shape), out_valid.reshape(shape))


def build_map_index(xyz: np.ndarray, dir: np.ndarray, types: np.ndarray, ids: np.ndarray,
                    valid: np.ndarray, config: MapIndexConfig | None = None,
                    center_xy: np.ndarray | None = None, *,
                    speed_limit: np.ndarray | None = None) -> MapIndex:
    """Build the map index of one scenario on the host (numpy, once per scenario).

    xyz (R, 3), dir (R, 3), types (R,), ids (R,), valid (R,) are the roadgraph arrays of a shard;
    speed_limit (R,) m/s (-1 unknown) is optional. Both grids are centred on `center_xy` (2,)
    (default: mean of the valid points; pass the SDC position at the current step).
    """
    config = config or MapIndexConfig()
    xyz = np.asarray(xyz, np.float32)
    if xyz.ndim != 2 or xyz.shape[1] not in (2, 3):
        raise InputError(f"build_map_index: roadgraph xyz must be (R, 3), got shape {xyz.shape}")
    r = len(xyz)
    arrays = {"dir": (dir, (r, 3)), "types": (types, (r,)), "ids": (ids, (r,)), "valid": (valid, (r,))}
    if speed_limit is not None:
        arrays["speed_limit"] = (speed_limit, (r,))
    for name, (value, shape) in arrays.items():
        if np.shape(value) != shape and np.size(value) != int(np.prod(shape)):
            raise InputError(f"build_map_index: roadgraph {name} has shape {np.shape(value)}, expected {shape}")
    xyz = np.pad(xyz, ((0, 0), (0, 3 - xyz.shape[1])))
    dir = np.asarray(dir, np.float32).reshape(r, 3)
    types = np.asarray(types).reshape(r).astype(np.int64)
    ids = np.asarray(ids).reshape(r).astype(np.int64)
    valid = np.asarray(valid).reshape(r).astype(bool) & np.all(np.isfinite(xyz), axis=1)
    speed_limit = (np.full(r, -1.0, np.float32) if speed_limit is None
                   else np.asarray(speed_limit, np.float32).reshape(r))
    if center_xy is None:
        center_xy = xyz[valid, :2].mean(0) if valid.any() else np.zeros(2)
    center_xy = np.asarray(center_xy, np.float64).reshape(2)
    g, s_cap = config.grid_size, config.max_segments
    origin = center_xy - 0.5 * g * config.cell_size

    start, end, seg_type, seg_id, seg_limit = _segments(
        xyz, types, ids, valid, speed_limit, tuple(config.edge_types) + tuple(config.lane_types), config)
    # cap S: keep the segments nearest the grid centre
    mid_dist = np.linalg.norm(0.5 * (start + end) - center_xy, axis=1)
    order = np.argsort(mid_dist, kind="stable")
    dropped = max(len(order) - s_cap, 0)
    order = order[:s_cap]
    start, end, seg_type, seg_id, seg_limit, mid_dist = (
        start[order], end[order], seg_type[order], seg_id[order], seg_limit[order], mid_dist[order])
    n = len(start)

    pairs_item, pairs_cell = _segment_cells(start, end, origin, config)
    cell_centre = origin + (np.stack([pairs_cell // g, pairs_cell % g], 1) + 0.5) * config.cell_size
    priority = np.linalg.norm(0.5 * (start[pairs_item] + end[pairs_item]) - cell_centre, axis=1)
    is_edge = np.isin(seg_type, config.edge_types)
    tables = []
    for wanted, slots in ((is_edge, config.edge_slots_per_cell), (~is_edge, config.slots_per_cell)):
        keep = wanted[pairs_item]
        table, lost = _fill_cells((pairs_item[keep], pairs_cell[keep]), priority[keep], g * g, slots)
        tables.append(table.reshape(g, g, slots))
        dropped += lost
    field = _edge_distance_field(start[is_edge], end[is_edge], origin, tables[0], config)
    obs = _obs_points(xyz, dir, types, ids, valid, speed_limit, origin, config)

    def pad(values, fill, dtype, shape_tail=()):
        out = np.full((s_cap,) + shape_tail, fill, dtype)
        out[:n] = values
        return out

    ends = np.concatenate([start, end], 1).T.astype(np.float32) if n else np.zeros((4, 0), np.float32)

    def dense(table, values, fill):
        if n == 0:
            return np.full(values.shape[:-1] + table.shape, fill, values.dtype)
        return np.where(table >= 0, values[..., np.maximum(table, 0)], fill).astype(values.dtype)

    return MapIndex(
        edge_seg=jnp.asarray(dense(tables[0], ends, 0.0)),
        lane_seg=jnp.asarray(dense(tables[1], ends, 0.0)),
        lane_seg_id=jnp.asarray(dense(tables[1], seg_id.astype(np.int32), -1)),
        lane_seg_speed_limit=jnp.asarray(dense(tables[1], seg_limit.astype(np.float32), -1.0)),
        seg_start=jnp.asarray(pad(start, 0.0, np.float32, (2,))),
        seg_end=jnp.asarray(pad(end, 0.0, np.float32, (2,))),
        seg_type=jnp.asarray(pad(seg_type, 0, np.int32)),
        seg_id=jnp.asarray(pad(seg_id, -1, np.int32)),
        seg_speed_limit=jnp.asarray(pad(seg_limit, -1.0, np.float32)),
        seg_valid=jnp.asarray(pad(np.ones(n, bool), False, bool)),
        origin_xy=jnp.asarray(origin, jnp.float32),
        edge_cells=jnp.asarray(tables[0]),
        lane_cells=jnp.asarray(tables[1]),
        cell_edge_distance=jnp.asarray(field),
        obs_features=jnp.asarray(np.concatenate([
            obs[0], obs[1], np.maximum(obs[3], 0.0)[..., None],
            np.stack([np.isin(obs[2], config.edge_types), np.isin(obs[2], config.lane_types),
                      np.isin(obs[2], ROAD_LINE_TYPES)], -1)], -1).astype(np.float32)),
        obs_type=jnp.asarray(obs[2]),
        obs_speed_limit=jnp.asarray(obs[3]), obs_valid=jnp.asarray(obs[4]),
        num_dropped=jnp.asarray(dropped, jnp.int32),
        cell_size=float(config.cell_size), obs_cell_size=float(config.obs_cell_size),
        query_window=int(config.query_window),
    )


# ----------------------------------------------------------------------------- JAX queries


def query_segments(map_index: MapIndex, xy: jnp.ndarray, kind: str = "edge",
                   window: int | None = None) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Candidate segments near xy (2,): indices (K,) int32 into MapIndex.seg_* and valid (K,),
    K = window^2 * slots. Covers at least (window // 2) * cell_size metres around xy.
    kind: "edge" or "lane". (The metrics use the dense per-cell copies instead: same cells.)
    """
    cells = map_index.edge_cells if kind == "edge" else map_index.lane_cells
    window = window or map_index.query_window
    slots = _block(cells, map_index.origin_xy, map_index.cell_size, xy, window)
    ok = (slots >= 0) & _inside_grid(map_index, xy, cells.shape[0], window)
    return jnp.maximum(slots, 0), ok


def _cell_value(grid: jnp.ndarray, origin: jnp.ndarray, cell_size: float, xy: jnp.ndarray) -> jnp.ndarray:
    """Value of the (clamped) grid cell holding each point. grid (G, G), xy (..., 2) -> (...,)."""
    g = grid.shape[0]
    cell = jnp.clip(jnp.floor((xy - origin) / cell_size).astype(jnp.int32), 0, g - 1)
    return grid[cell[..., 0], cell[..., 1]]


def _block(grid: jnp.ndarray, origin: jnp.ndarray, cell_size: float, xy: jnp.ndarray, window: int,
           lead: int = 0) -> jnp.ndarray:
    """Contiguous window x window block of a per-cell grid around the cell holding xy, flattened.

    grid (*lead_dims, G, G, C) -> (*lead_dims, window * window * C).
    """
    g, c = grid.shape[lead], grid.shape[lead + 2]
    # odd windows centre on the query's cell, even ones on its nearest cell corner
    start = jnp.floor((xy - origin) / cell_size + 0.5 - 0.5 * window).astype(jnp.int32)
    start = jnp.clip(start, 0, g - window)
    starts = (0,) * lead + (start[0], start[1], 0)
    sizes = grid.shape[:lead] + (window, window, c)
    return jax.lax.dynamic_slice(grid, starts, sizes).reshape(grid.shape[:lead] + (-1,))


def _inside_grid(map_index: MapIndex, xy: jnp.ndarray, grid_size: int, window: int) -> jnp.ndarray:
    """False when the query cell is so far outside the grid that the clamped window is unrelated."""
    cell = jnp.floor((xy - map_index.origin_xy) / map_index.cell_size).astype(jnp.int32)
    return jnp.all((cell >= -(window // 2)) & (cell < grid_size + window // 2))


def edge_block(map_index: MapIndex, xy: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Road-edge segments of the query window around xy (2,). -> (4, K) [sx, sy, ex, ey], valid (K,)."""
    w = map_index.query_window
    seg = _block(map_index.edge_seg, map_index.origin_xy, map_index.cell_size, xy, w, lead=1)
    slots = _block(map_index.edge_cells, map_index.origin_xy, map_index.cell_size, xy, w)
    ok = (slots >= 0) & _inside_grid(map_index, xy, map_index.edge_cells.shape[0], w)
    return seg, ok


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
    # (K, P) layout, reduced over the segments (axis 0): measured faster than (P, K) on CPU at batch 1
    sx, sy, ex, ey = seg[0][:, None], seg[1][:, None], seg[2][:, None], seg[3][:, None]  # (K, 1)
    px, py = points[None, :, 0], points[None, :, 1]  # (1, P)
    dx, dy = ex - sx, ey - sy
    inv_len_sq = 1.0 / jnp.maximum(dx * dx + dy * dy, 1e-12)
    rx, ry = px - sx, py - sy  # (K, P)
    t = jnp.clip((rx * dx + ry * dy) * inv_len_sq, 0.0, 1.0)
    ox, oy = rx - t * dx, ry - t * dy
    dist_sq = jnp.where(ok[:, None], ox * ox + oy * oy, jnp.inf)  # invalid slots are never among the nearest
    best_sq = jnp.min(dist_sq, axis=0)  # (P,)
    cross = dx * ry - dy * rx  # > 0: point left of the segment (road side)
    off_road = vertex_aware_side(dist_sq, best_sq, cross * jnp.abs(cross) * inv_len_sq, axis=0) < 0.0
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
    w = map_index.query_window
    seg = _block(map_index.lane_seg, map_index.origin_xy, map_index.cell_size, xy, w, lead=1)
    ids = _block(map_index.lane_seg_id, map_index.origin_xy, map_index.cell_size, xy, w)
    limit = _block(map_index.lane_seg_speed_limit, map_index.origin_xy, map_index.cell_size, xy, w)
    ok = (ids >= 0) & _inside_grid(map_index, xy, map_index.lane_cells.shape[0], w)
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
    return jnp.argmin(candidates.distance + heading_weight * misalign).astype(jnp.int32)


OBS_POINT_FEATURES = 8  # x, y, dir x, dir y, speed limit, is edge, is lane, is line


@flax.struct.dataclass
class ObservationPoints:
    """Observation sample points in the window of observation cells around a centre point."""

    features: jnp.ndarray  # (M, 8) float32, world frame: see MapIndex.obs_features
    types: jnp.ndarray  # (M,) int32
    valid: jnp.ndarray  # (M,) bool

    @property
    def xy(self) -> jnp.ndarray:
        """(M, 2) points."""
        return self.features[:, :2]


def observation_points(map_index: MapIndex, center_xy: jnp.ndarray, window: int = 5) -> ObservationPoints:
    """All thinned points of the window x window observation cells around center_xy (2,).

    M = window^2 * obs_slots_per_cell; covers at least (window - 1) / 2 * obs_cell_size metres.
    No sort: points come in cell order with a validity mask.
    """
    def block(grid):
        return _block(grid, map_index.origin_xy, map_index.obs_cell_size, center_xy, window)

    feats = _block_rows(map_index, center_xy, window)
    return ObservationPoints(features=feats, types=block(map_index.obs_type), valid=block(map_index.obs_valid))


def _block_rows(map_index: MapIndex, center_xy: jnp.ndarray, window: int) -> jnp.ndarray:
    """(window^2 * Co, 8) rows of obs_features around center_xy, one contiguous block slice."""
    grid = map_index.obs_features
    g, c, f = grid.shape[0], grid.shape[2], grid.shape[3]
    start = jnp.floor((center_xy - map_index.origin_xy) / map_index.obs_cell_size + 0.5 - 0.5 * window)
    start = jnp.clip(start.astype(jnp.int32), 0, g - window)
    out = jax.lax.dynamic_slice(grid, (start[0], start[1], 0, 0), (window, window, c, f))
    return out.reshape(-1, f)


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
    best_knot = jnp.argmin(knot_dist, axis=1) * stride  # (P,)
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
    is_k = jnp.arange(width - 1)[None] == jnp.argmin(dist_sq, axis=1)[:, None]  # (P, width - 1) one-hot

    def at_k(values):  # select by mask and sum: elementwise, no gather
        return jnp.sum(jnp.where(is_k, values, 0.0), axis=1)

    best_sq = jnp.min(dist_sq, axis=1)
    t_k = at_k(t)
    arc = at_k(w_arc[:, :-1]) + t_k * (at_k(w_arc[:, 1:]) - at_k(w_arc[:, :-1]))
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


def path_arc_length(path_xy: np.ndarray, path_valid: np.ndarray) -> np.ndarray:
    """Cumulative arc length along each path (host helper when a shard lacks it). (P, N, 2) -> (P, N)."""
    step = np.linalg.norm(np.diff(np.asarray(path_xy, np.float64), axis=1), axis=-1)
    step = np.where(np.asarray(path_valid)[:, 1:], step, 0.0)
    return np.concatenate([np.zeros((step.shape[0], 1)), np.cumsum(step, 1)], 1).astype(np.float32)

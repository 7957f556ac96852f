"""Host side of the map index: numpy, once per scenario when shards are loaded (see `vmax_sim.map_index`)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from scenariomax.errors import InputError
from scenariomax.schema import ROAD_LINE_TYPES
from vmax_sim.map_index.query import vertex_aware_side
from vmax_sim.map_index.structure import (
    FAR_DISTANCE,
    OBS_DIR_STEPS,
    OBS_SPEED_STEP,
    OBS_XY_STEPS,
    MapIndex,
    MapIndexConfig,
    index_dtype,
)


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
    """Thinned observation points scattered into the observation grid: per cell, lanes, lines, then edges."""
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
    # Within a cell: lanes, then road lines, then road edges, each in polyline order (so thinning is even). The
    # points a crowded cell keeps must not depend on the order the source lists its polylines in (the generator
    # lists lanes first, the real converters edges first); and the flat `none` encoder reads slots by position (the
    # MLP encoder pools over them).
    group = np.where(np.isin(types[idx], config.lane_types), 0, np.where(np.isin(types[idx], config.edge_types), 2, 1))
    order = np.lexsort((group, flat))  # stable: by cell, then group, then polyline order
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

    cell_dtype = index_dtype(config.max_segments - 1)
    obs_points, obs_type = _quantise_obs(*obs, origin, config)
    return MapIndex(
        seg_points=jnp.asarray(pad(np.concatenate([start, end], 1), 0.0, np.float32, (4,))),
        seg_type=jnp.asarray(pad(seg_type, -1, np.int8)),
        seg_id=jnp.asarray(pad(seg_id, -1, np.int32)),
        seg_speed_limit=jnp.asarray(pad(seg_limit, -1.0, np.float32)),
        origin_xy=jnp.asarray(origin, jnp.float32),
        edge_cells=jnp.asarray(tables[0].astype(cell_dtype)),
        lane_cells=jnp.asarray(tables[1].astype(cell_dtype)),
        cell_edge_distance=jnp.asarray(field),
        obs_points=jnp.asarray(obs_points), obs_type=jnp.asarray(obs_type),
        num_dropped=jnp.asarray(dropped, jnp.int32),
        cell_size=float(config.cell_size), obs_cell_size=float(config.obs_cell_size),
        query_window=int(config.query_window),
    )


def _quantise_obs(xy, dirs, types, limit, valid, origin, config):
    """Observation points (Go, Go, Co, ...) -> MapIndex.obs_points (int16 columns) and obs_type (int8)."""
    go, cs = config.obs_grid_size, config.obs_cell_size
    origin = np.asarray(origin, np.float32).astype(np.float64)  # the queries see the float32 origin
    centre = origin + (np.stack(np.meshgrid(np.arange(go), np.arange(go), indexing="ij"), -1) + 0.5) * cs
    offset = (xy - centre[:, :, None]) * (OBS_XY_STEPS / cs)
    columns = [offset[..., 0], offset[..., 1], dirs[..., 0] * OBS_DIR_STEPS, dirs[..., 1] * OBS_DIR_STEPS,
               np.maximum(limit, 0.0) / OBS_SPEED_STEP, np.isin(types, config.edge_types),
               np.isin(types, config.lane_types), np.isin(types, ROAD_LINE_TYPES)]
    most = np.iinfo(np.int16).max
    points = np.stack([np.clip(np.rint(c), -most, most) for c in columns], -1)
    return (np.where(valid[..., None], points, 0).astype(np.int16),
            np.where(valid, types, -1).astype(np.int8))


def path_arc_length(path_xy: np.ndarray, path_valid: np.ndarray) -> np.ndarray:
    """Cumulative arc length along each path (host helper when a shard lacks it). (P, N, 2) -> (P, N)."""
    step = np.linalg.norm(np.diff(np.asarray(path_xy, np.float64), axis=1), axis=-1)
    step = np.where(np.asarray(path_valid)[:, 1:], step, 0.0)
    return np.concatenate([np.zeros((step.shape[0], 1)), np.cumsum(step, 1)], 1).astype(np.float32)

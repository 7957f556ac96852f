"""Small polyline helpers shared by the enrichment steps (2-D maths on numpy arrays)."""

from __future__ import annotations

import math

import numpy as np

from scenariomax._compiled import kernels


def wrap_angle(angle) -> np.ndarray:
    """Radians wrapped to [-pi, pi). Any shape; keeps float32 input float32."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def polyline_runs(ids: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(start, stop) index pairs of the consecutive runs of equal id among valid points. -> (k, 2)"""
    ids = np.asarray(ids)
    valid = np.asarray(valid, dtype=bool)
    if ids.size == 0:
        return np.zeros((0, 2), np.int64)
    # A run breaks wherever the id or the validity changes.
    breaks = np.flatnonzero((ids[1:] != ids[:-1]) | (valid[1:] != valid[:-1])) + 1
    starts = np.concatenate([[0], breaks])
    stops = np.concatenate([breaks, [ids.size]])
    keep = valid[starts]
    return np.stack([starts[keep], stops[keep]], axis=1).astype(np.int64)


def run_index(runs: np.ndarray, size: int) -> np.ndarray:
    """Run number of every point (-1 outside every run). (k, 2) -> (size,) int64"""
    out = np.full(size, -1, np.int64)
    for number, (start, stop) in enumerate(runs):
        out[start:stop] = number
    return out


def arc_lengths(xy: np.ndarray) -> np.ndarray:
    """Cumulative 2-D distance along a polyline, 0 at the first point. (n, 2+) -> (n,)"""
    xy = np.asarray(xy, np.float64)
    compiled = kernels()
    if compiled is not None and xy.ndim == 2 and xy.shape[1] >= 2:  # the same bits, one call
        return compiled.arc_lengths(xy)
    out = np.zeros(len(xy))
    if len(xy) > 1:
        dx, dy = xy[1:, 0] - xy[:-1, 0], xy[1:, 1] - xy[:-1, 1]  # (n-1,)
        np.cumsum(np.sqrt(dx * dx + dy * dy), out=out[1:])  # the bits of norm(diff(xy[:, :2]), axis=1)
    return out


def row_norm(vectors: np.ndarray) -> np.ndarray:
    """np.linalg.norm(vectors, axis=-1) for a short last axis (2 or 3), the same bits (squares summed in order)
    without numpy's slow reduction over a tiny axis. (..., d) -> (...)"""
    vectors = np.asarray(vectors)
    total = vectors[..., 0] * vectors[..., 0]
    for k in range(1, vectors.shape[-1]):
        total = total + vectors[..., k] * vectors[..., k]
    return np.sqrt(total)


def unit(vectors: np.ndarray) -> np.ndarray:
    """Rows scaled to unit norm (zero rows stay zero). (n, d) -> (n, d)"""
    norm = row_norm(vectors)[..., None]
    return np.where(norm > 1e-9, vectors / np.maximum(norm, 1e-9), 0.0)


def tangents(xy: np.ndarray) -> np.ndarray:
    """Unit 2-D direction at every vertex (the last vertex reuses the last segment). (n, 2+) -> (n, 2)"""
    xy = np.asarray(xy, np.float64)[:, :2]
    if len(xy) < 2:
        return np.zeros((len(xy), 2))
    seg = unit(np.diff(xy, axis=0))
    return np.vstack([seg, seg[-1:]])


_CHUNK = 8  # segments per bounding box in the pruned nearest-segment search
_PRUNE_ABOVE = 15_000  # (points x segments) from which pruning pays for its bookkeeping


def _feet(px: np.ndarray, py: np.ndarray, ax: np.ndarray, ay: np.ndarray, sx: np.ndarray, sy: np.ndarray,
          seg_len2: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Foot of each point on each segment and the squared distance to it, in broadcast shapes (points along
    axis 0): frac, foot x, foot y, squared distance. Separate x and y planes updated in place: a (..., 2)
    array summed over its last axis costs ~4x more (tiny-axis reductions are slow in numpy)."""
    frac = (px - ax) * sx
    frac += (py - ay) * sy
    frac /= seg_len2
    np.clip(frac, 0.0, 1.0, out=frac)  # foot position along each segment
    foot_x, foot_y = frac * sx, frac * sy
    foot_x += ax
    foot_y += ay
    dist2 = px - foot_x
    dist2 *= dist2
    dy = py - foot_y
    dy *= dy
    dist2 += dy
    return frac, foot_x, foot_y, dist2


def _nearest_all(pts, ax, ay, sx, sy, seg_len2, with_foot: bool = True) -> tuple[np.ndarray, ...]:
    """Nearest segment of each point over all segments: index, frac, foot x, foot y (None unless `with_foot`),
    squared distance (m,) each."""
    frac, foot_x, foot_y, dist2 = _feet(pts[:, 0:1], pts[:, 1:2], ax, ay, sx, sy, seg_len2)  # (m, k) each
    best = dist2.argmin(axis=1)  # first of equal minima
    rows = np.arange(len(pts))
    if not with_foot:
        return best, frac[rows, best], None, None, dist2[rows, best]
    return best, frac[rows, best], foot_x[rows, best], foot_y[rows, best], dist2[rows, best]


def _nearest_pruned(pts, line, ax, ay, sx, sy, seg_len2) -> tuple[np.ndarray, ...]:
    """`_nearest_all` computed only on the chunks of `_CHUNK` segments that may hold each point's nearest one
    (the distance to a chunk's bounding box is at most that to some vertex): the same values, ties included,
    since every kept segment is computed exactly as in `_nearest_all` and in index order."""
    m, k = len(pts), len(ax)
    num_chunks = -(-k // _CHUNK)
    first = np.arange(num_chunks) * _CHUNK  # (C,) first segment (and vertex) of each chunk
    # Chunk boxes over its vertices first .. first + _CHUNK (inclusive: the last segment's end).
    low = np.minimum.reduceat(line, first, axis=0)  # (C, 2)
    high = np.maximum.reduceat(line, first, axis=0)
    ends = line[np.minimum(first + _CHUNK, len(line) - 1)]  # (C, 2)
    low, high = np.minimum(low, ends), np.maximum(high, ends)
    px, py = pts[:, 0:1], pts[:, 1:2]  # (m, 1)
    gap_x = np.maximum(np.maximum(low[:, 0] - px, px - high[:, 0]), 0.0)  # (m, C)
    gap_y = np.maximum(np.maximum(low[:, 1] - py, py - high[:, 1]), 0.0)
    lower2 = gap_x * gap_x + gap_y * gap_y  # (m, C) squared distance to the box: no segment inside is nearer
    to_x, to_y = px - line[first, 0], py - line[first, 1]
    upper2 = (to_x * to_x + to_y * to_y).min(axis=1, keepdims=True)  # (m, 1) some segment is at least this near
    point, chunk = np.nonzero(lower2 <= upper2 * (1.0 + 1e-9) + 1e-9)  # margin: rounding never prunes the nearest
    seg = chunk[:, None] * _CHUNK + np.arange(_CHUNK)  # (p, B) ascending per point: argmin's first-of-ties order
    real = seg < k
    seg = np.minimum(seg, k - 1)
    frac, foot_x, foot_y, dist2 = _feet(pts[point, 0:1], pts[point, 1:2], ax[seg], ay[seg], sx[seg], sy[seg],
                                        seg_len2[seg])  # (p, B) each
    dist2[~real] = np.inf
    counts = np.bincount(point, minlength=m) * _CHUNK  # (m,) candidates per point (>= 1 chunk each)
    starts = np.cumsum(counts) - counts
    flat = dist2.ravel()
    nearest = np.minimum.reduceat(flat, starts)  # (m,)
    hit = np.flatnonzero(flat == np.repeat(nearest, counts))  # ascending
    owner = np.repeat(np.arange(m), counts)[hit]
    pick = hit[np.concatenate([[True], owner[1:] != owner[:-1]])]  # (m,) the first minimum of each point
    return (seg.ravel()[pick], frac.ravel()[pick], foot_x.ravel()[pick], foot_y.ravel()[pick], flat[pick])


def polyline_segments(polyline: np.ndarray) -> tuple[np.ndarray, ...]:
    """What `project_to_polyline` derives from a polyline (n >= 2, 2+) before it looks at the points: the 2-D
    line (n, 2), segment starts ax, ay, vectors sx, sy, squared lengths (clamped to 1e-12) (n-1,) each, and the
    arc length at each vertex (n,). Kept by callers that project onto the same polyline again and again."""
    line = np.ascontiguousarray(np.asarray(polyline, np.float64)[:, :2])  # contiguous: one kernel signature
    ax, ay = line[:-1, 0], line[:-1, 1]  # (n-1,) segment starts
    compiled = kernels()
    if compiled is not None and len(line) >= 2:  # the same bits, one pass
        return (line, ax, ay, *compiled.segment_vectors(line))
    sx, sy = line[1:, 0] - ax, line[1:, 1] - ay  # (n-1,) segment vectors
    raw_len2 = sx * sx + sy * sy  # (n-1,)
    cum = np.zeros(len(line))  # arc_lengths(line), from the segment lengths at hand
    np.cumsum(np.sqrt(raw_len2), out=cum[1:])
    return line, ax, ay, sx, sy, np.maximum(raw_len2, 1e-12), cum


def project_to_polyline(points: np.ndarray, polyline: np.ndarray, segments: tuple[np.ndarray, ...] | None = None,
                        with_foot: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Nearest point on a polyline for each query point.

    points (m, 2+), polyline (n, 2+) -> distance (m,), arc length of the foot (m,), foot (m, 2) (None unless
    `with_foot`: the path search asks hundreds of times for distances and arcs alone).
    `segments`: `polyline_segments(polyline)` when the caller keeps it (n >= 2).
    """
    pts = np.asarray(points, np.float64)[:, :2]
    if segments is None:
        line = np.asarray(polyline, np.float64)[:, :2]
        if len(line) == 1:
            dist = np.linalg.norm(pts - line[0], axis=1)
            return dist, np.zeros(len(pts)), np.broadcast_to(line[0], pts.shape).copy()
        segments = polyline_segments(line)
    line, ax, ay, sx, sy, seg_len2, cum = segments
    compiled = kernels()
    if compiled is not None and len(sx):  # the same bits as below, ~5x faster on the short inputs of the path search
        dist, arc, foot = compiled.nearest_on_polyline(np.ascontiguousarray(pts), line, sx, sy, seg_len2, cum,
                                                       with_foot)
        return dist, arc, (foot if with_foot else None)
    return _project_numpy(pts, segments, with_foot)


def _project_numpy(pts: np.ndarray, segments: tuple[np.ndarray, ...],
                   with_foot: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """`project_to_polyline` in numpy (where numba is missing; the reference the kernel is tested against)."""
    line, ax, ay, sx, sy, seg_len2, cum = segments
    if len(pts) * len(ax) >= _PRUNE_ABOVE and np.isfinite(pts).all() and np.isfinite(line).all():
        best, frac, foot_x, foot_y, dist2 = _nearest_pruned(pts, line, ax, ay, sx, sy, seg_len2)
    else:
        best, frac, foot_x, foot_y, dist2 = _nearest_all(pts, ax, ay, sx, sy, seg_len2, with_foot)
    arc = cum[best] + frac * np.sqrt(seg_len2[best])
    if not with_foot:
        return np.sqrt(dist2), arc, None
    foot = np.empty((len(pts), 2))  # np.stack costs more than the rest on the short inputs of the path search
    foot[:, 0], foot[:, 1] = foot_x, foot_y
    return np.sqrt(dist2), arc, foot


def _box_gap2(p: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """max(max(low - p, p - high), 0) ** 2 along one axis: the squared gap from points p (m, 1) to the
    intervals low..high (C,), computed in place. -> (m, C)"""
    gap = low - p
    np.maximum(gap, p - high, out=gap)
    np.maximum(gap, 0.0, out=gap)
    gap *= gap
    return gap


def project_to_polylines(points: np.ndarray, polylines: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
    """(distance (m,), foot arc (m,)) of the points on each polyline, as `project_to_polyline` gives them (the
    same values, ties included), for many polylines at once: the pruned search of `_nearest_pruned` with
    chunks that never straddle two polylines, and one reduction per (point, polyline).
    points (m, 2+), polylines [(n_i >= 1, 2+)]"""
    pts = np.asarray(points, np.float64)[:, :2]
    lines = [np.asarray(line, np.float64)[:, :2] for line in polylines]
    batch = [k for k, line in enumerate(lines) if len(line) >= 2]
    out: list = [None] * len(lines)
    for k in set(range(len(lines))) - set(batch):
        out[k] = project_to_polyline(pts, lines[k])[:2]
    vertex = np.concatenate([lines[k] for k in batch]) if batch else np.zeros((0, 2))  # (V, 2)
    if not batch or len(pts) == 0 or not np.isfinite(pts).all() or not np.isfinite(vertex).all():
        for k in batch:
            out[k] = project_to_polyline(pts, lines[k])[:2]
        return out
    compiled = kernels()
    if compiled is not None:  # the same bits as below
        dist, arc = compiled.nearest_on_polylines(np.ascontiguousarray(pts), vertex,
                                                  np.array([len(lines[k]) for k in batch], np.int64))
        for row, k in enumerate(batch):
            out[k] = (dist[row], arc[row])
        return out
    return _project_many_numpy(pts, lines, batch, vertex, out)


def _project_many_numpy(pts: np.ndarray, lines: list[np.ndarray], batch: list[int], vertex: np.ndarray,
                        out: list) -> list[tuple[np.ndarray, np.ndarray]]:
    """`project_to_polylines` in numpy for the polylines `batch` (>= 2 vertices each, stored back to back in
    `vertex`), finite inputs (the reference the kernel is tested against)."""
    num_seg = np.array([len(lines[k]) - 1 for k in batch])  # (L,) segments per polyline
    v_start = run_starts(num_seg + 1)  # (L,) first vertex of each polyline
    s_start = run_starts(num_seg)  # (L,) first segment
    # Segments as project_to_polyline builds them, back to back (a polyline's last vertex starts none).
    starts_segment = np.ones(len(vertex), bool)
    starts_segment[v_start + num_seg] = False
    starts = np.flatnonzero(starts_segment)  # (S,) start vertex of each segment
    ax, ay = vertex[starts, 0], vertex[starts, 1]
    sx, sy = vertex[starts + 1, 0] - ax, vertex[starts + 1, 1] - ay
    raw_len2 = sx * sx + sy * sy
    seg_len2 = np.maximum(raw_len2, 1e-12)  # (S,)
    step = np.zeros(len(vertex))
    step[starts + 1] = np.sqrt(raw_len2)
    cum = run_cumsum(step, num_seg + 1)  # (V,) arc length at each vertex along its polyline
    # Chunks of _CHUNK segments within each polyline.
    num_chunks = -(-num_seg // _CHUNK)  # (L,)
    chunk_line = np.repeat(np.arange(len(batch)), num_chunks)  # (C,)
    chunk_rank = np.arange(num_chunks.sum()) - np.repeat(run_starts(num_chunks), num_chunks)
    first_seg = chunk_rank * _CHUNK  # (C,) within its polyline
    first_vertex = v_start[chunk_line] + first_seg  # (C,)
    last_vertex = v_start[chunk_line] + np.minimum(first_seg + _CHUNK, num_seg[chunk_line])  # inclusive
    low = np.minimum(np.minimum.reduceat(vertex, first_vertex, axis=0), vertex[last_vertex])  # (C, 2)
    high = np.maximum(np.maximum.reduceat(vertex, first_vertex, axis=0), vertex[last_vertex])
    # reduceat runs to the next chunk's first vertex: for a polyline's last chunk that is its own last vertex.
    px, py = pts[:, 0:1], pts[:, 1:2]  # (m, 1)
    # The (m, C) bounds below are the largest arrays of the search: updated in place (the same arithmetic as
    # max(max(low - p, p - high), 0) squared and summed, without a temporary per operation).
    lower2 = _box_gap2(px, low[:, 0], high[:, 0])  # (m, C)
    lower2 += _box_gap2(py, low[:, 1], high[:, 1])
    to_x, to_y = px - vertex[first_vertex, 0], py - vertex[first_vertex, 1]
    to_x *= to_x
    to_y *= to_y
    to_x += to_y
    upper2 = np.minimum.reduceat(to_x, run_starts(num_chunks), axis=1)  # (m, L)
    upper2 *= 1.0 + 1e-9  # margin: rounding never prunes the nearest
    upper2 += 1e-9
    point, chunk = np.nonzero(lower2 <= upper2[:, chunk_line])
    line_of = chunk_line[chunk]  # (p,)
    # Each chunk's segments (C, B), the last ones of a polyline's last chunk repeated (masked below), then one row
    # per (point, chunk) pair: whole rows are gathered faster than the same values one by one.
    local = first_seg[:, None] + np.arange(_CHUNK)  # (C, B) segment index within its polyline
    last = num_seg[chunk_line][:, None]  # (C, 1)
    chunk_seg = s_start[chunk_line][:, None] + np.minimum(local, last - 1)  # (C, B) global
    seg = chunk_seg[chunk]  # (p, B)
    frac, _, _, dist2 = _feet(pts[point, 0:1], pts[point, 1:2], ax[chunk_seg][chunk], ay[chunk_seg][chunk],
                              sx[chunk_seg][chunk], sy[chunk_seg][chunk], seg_len2[chunk_seg][chunk])
    dist2[(local >= last)[chunk]] = np.inf
    # One group per (point, polyline), in (point, polyline, segment) order: the first minimum is argmin's.
    group = point * len(batch) + line_of  # (p,) ascending
    counts = np.bincount(group, minlength=len(pts) * len(batch)) * _CHUNK  # every group has >= 1 chunk
    flat = dist2.ravel()
    nearest = np.minimum.reduceat(flat, run_starts(counts))  # (m * L,)
    hit = np.flatnonzero(flat == np.repeat(nearest, counts))
    owner = np.repeat(np.arange(len(counts)), counts)[hit]
    pick = hit[np.concatenate([[True], owner[1:] != owner[:-1]])]  # (m * L,)
    best = seg.ravel()[pick]
    arc = cum[starts[best]] + frac.ravel()[pick] * np.sqrt(seg_len2[best])
    dist = np.sqrt(flat[pick])
    for column, k in enumerate(batch):
        out[k] = (dist[column::len(batch)], arc[column::len(batch)])
    return out


def point_at_arc(polyline: np.ndarray, cum: np.ndarray, arcs: np.ndarray) -> np.ndarray:
    """Points at the given arc lengths (linear interpolation per coordinate). -> (m, d)"""
    arcs = np.asarray(arcs, np.float64)
    compiled = kernels()
    # np.interp's bits, all columns in one pass
    if compiled is not None and len(cum) and polyline.ndim == 2 and len(polyline) == len(cum):
        out, ok = compiled.interp_columns(arcs.ravel(), np.asarray(cum, np.float64),
                                          np.asarray(polyline, np.float64))
        if ok:
            return out.reshape(arcs.shape + polyline.shape[1:])
    # Columns written into one array: np.stack costs more than the interpolation on the short inputs of the
    # path search (hundreds of calls per scenario); the values are np.interp's either way.
    out = np.empty(arcs.shape + polyline.shape[1:])
    for k in range(polyline.shape[1]):
        out[..., k] = np.interp(arcs, cum, polyline[:, k])
    return out


def slice_polyline(polyline: np.ndarray, cum: np.ndarray, start: float, stop: float) -> np.ndarray:
    """The part of a polyline between two arc lengths, with interpolated end points. -> (k, d)"""
    start, stop = max(float(start), 0.0), min(float(stop), float(cum[-1]))
    if stop <= start:
        return point_at_arc(polyline, cum, [start])
    compiled = kernels()
    if compiled is not None and polyline.ndim == 2 and len(polyline) == len(cum) and polyline.dtype == np.float64:
        out, ok = compiled.slice_polyline(polyline, np.asarray(cum, np.float64), start, stop)  # the same values
        if ok:
            return out
    inner = (cum > start) & (cum < stop)
    ends = point_at_arc(polyline, cum, [start, stop])  # both ends in one call (np.interp is per element)
    return np.concatenate([ends[:1], polyline[inner], ends[1:]])


def segment_distances(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance from each point (m, 2+) to a polyline (n, 2+). -> (m,)"""
    return project_to_polyline(points, polyline)[0]


# --- many polylines at once ----------------------------------------------------------------------
# Sources' maps hold hundreds of short polylines; numpy calls per polyline cost more than the maths. These
# helpers work on polylines stored back to back ("runs": run r owns rows starts[r]:starts[r] + counts[r]) and
# give every run the same bits as the one-polyline numpy call (np.cumsum, np.interp, np.linalg.norm).


def run_starts(counts: np.ndarray) -> np.ndarray:
    """First row of each run. (R,) -> (R,) int64"""
    counts = np.asarray(counts, np.int64)
    return np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64) if len(counts) else counts


_FEW_RUNS = 16  # up to this many runs, run_cumsum loops over them (e.g. the path candidates of one search)


def run_cumsum(values: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """np.cumsum within each run, bit for bit (a run's sum never carries the previous run's rounding).
    values (n,) back to back, counts (R,) summing to n -> (n,)"""
    values = np.asarray(values, np.float64)
    counts = np.asarray(counts, np.int64)
    compiled = kernels()
    if compiled is not None and counts.sum() == len(values) and (counts >= 0).all():  # the same bits, one pass
        return compiled.run_cumsum(values, counts)
    out = np.empty_like(values)
    if len(values) == 0:
        return out
    if len(counts) <= _FEW_RUNS:  # one np.cumsum per run costs less than building the tables below
        begin = 0
        for count in counts.tolist():
            np.cumsum(values[begin:begin + count], out=out[begin:begin + count])
            begin += count
        return out
    place = np.arange(len(values)) - np.repeat(run_starts(counts), counts)  # (n,) position in its run
    run = np.repeat(np.arange(len(counts)), counts)  # (n,)
    # Runs of similar length (within a factor 2) share a table, one column per run, padded with zeros:
    # cumsum down the columns is the same sequential sum as per run, for all runs of the table at once.
    size_class = np.ceil(np.log2(np.maximum(counts, 1))).astype(np.int64)  # (R,)
    # The runs sorted by class once (and so their values): each class is then a slice of both.
    order = np.argsort(size_class, kind="stable")  # (R,)
    per_class = np.bincount(size_class, minlength=int(size_class.max()) + 1)  # (classes,) runs of each
    column = np.empty(len(counts), np.int64)  # (R,) a run's column in its class's table
    column[order] = np.arange(len(counts)) - np.repeat(run_starts(per_class), per_class)
    rows_by_class = np.argsort(size_class[run], kind="stable")  # (n,) values grouped by class, in order
    values_per_class = np.bincount(size_class, weights=counts, minlength=len(per_class)).astype(np.int64)
    run_begin, row_begin = 0, 0
    for num_runs, num_values in zip(per_class.tolist(), values_per_class.tolist()):
        members = order[run_begin:run_begin + num_runs]  # (r,)
        rows = rows_by_class[row_begin:row_begin + num_values]  # the values of these runs
        run_begin, row_begin = run_begin + num_runs, row_begin + num_values
        if num_values == 0:
            continue
        table = np.zeros((int(counts[members].max()), num_runs))  # (longest run of the class, r)
        at = place[rows], column[run[rows]]
        table[at] = values[rows]
        out[rows] = np.cumsum(table, axis=0)[at]
    return out


def _last_at_or_below(x: np.ndarray, x_run: np.ndarray, xp: np.ndarray, xp_run: np.ndarray,
                      starts: np.ndarray) -> np.ndarray:
    """Index of the last xp <= x[k] within run x_run[k] (the run's start - 1 when none): one searchsorted for all
    runs. xp (n,) increasing within each run, runs back to back (xp_run (n,) ascending). -> (m,)"""
    scale = max(float(np.abs(xp).max(initial=0.0)), float(np.abs(x).max(initial=0.0)), 1.0)
    if math.isfinite(scale):
        # Each run's values shifted by its own multiple of a power of two over 4x every |value|: the runs stay
        # apart and in order, and rounding keeps the order within a run except that a query may round onto a
        # key just above it. Those few are searched again below, exactly.
        span = 2.0 ** (math.ceil(math.log2(scale)) + 2)
        j = np.searchsorted(xp + xp_run * span, x + x_run * span, side="right") - 1  # (m,)
        again = np.flatnonzero((j >= starts[x_run]) & (xp[np.maximum(j, 0)] > x))
        if not again.size:
            return j
    else:  # not finite: every query searched exactly
        j, again = np.zeros(len(x), np.int64), np.arange(len(x))
    # (run, value) pairs as complex numbers sort lexicographically: an exact searchsorted for all runs.
    keys = xp_run + 1j * xp  # (n,)
    j[again] = np.searchsorted(keys, x_run[again] + 1j * x[again], side="right") - 1
    return j


def run_interp(x: np.ndarray, x_run: np.ndarray, xp: np.ndarray, fp: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """np.interp(x[k], xp_r, fp_r) for every query k against its run r = x_run[k], bit for bit (numpy's
    formula: fp[j] where x hits xp[j] or lies outside, else slope * (x - xp[j]) + fp[j]).
    x (m,), x_run (m,) int, xp (n,) increasing within each run, fp (n,) or (n, d), counts (R,) >= 1 each
    -> (m,) or (m, d)"""
    x = np.asarray(x, np.float64)
    xp, fp = np.asarray(xp, np.float64), np.asarray(fp, np.float64)
    compiled = kernels()
    runs, sizes = np.asarray(x_run, np.int64), np.asarray(counts, np.int64)
    # The kernel reads without bounds checks: only runs that tile xp, and queries of those runs.
    if (compiled is not None and len(sizes) and sizes.sum() == len(xp) == len(fp) and (sizes >= 1).all()
            and (not len(runs) or (runs.min() >= 0 and runs.max() < len(sizes)))):
        out, ok = compiled.run_interp(x, runs, xp, np.ascontiguousarray(fp.reshape(len(fp), -1)), sizes)
        if ok:  # the same bits, each query searched in its own run
            return out if fp.ndim == 2 else out[:, 0]
    starts = run_starts(counts)
    last = starts + np.asarray(counts, np.int64) - 1  # (R,)
    j = _last_at_or_below(x, x_run, xp, np.repeat(np.arange(len(starts)), counts), starts)
    j = np.clip(j, starts[x_run], last[x_run])  # left of the run: its first point (numpy's default)
    nxt = np.minimum(j + 1, last[x_run])
    if fp.ndim == 2:
        x, xj, xn = x[:, None], xp[j][:, None], xp[nxt][:, None]
    else:
        xj, xn = xp[j], xp[nxt]
    fj, fn = fp[j], fp[nxt]
    on_point = (xj == x) | (xj == xn) | (x < xj)  # hits xp[j], the run's last point, or lies left of the run
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = (fn - fj) / (xn - xj)
        out = slope * (x - xj) + fj
        # numpy retries from the right end, then takes fp[j] on a flat stretch (only off the points: those take
        # fp[j] below, e.g. every query at a run's last point, where the slope is 0 / 0)
        retry = np.isnan(out) & ~on_point
        if retry.any():
            out = np.where(retry, slope * (x - xn) + fn, out)
            out = np.where(np.isnan(out) & (fj == fn), fj, out)
    return np.where(on_point, fj, out)

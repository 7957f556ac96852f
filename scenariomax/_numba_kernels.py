"""Compiled loops (numba) for the hot spots of conversion: the nearest-segment search of the path search and the
varints of the record encoder. Imported only through `scenariomax._compiled.kernels()` (numba takes ~0.5 s to
import): never import this module directly.

Each kernel gives the same bits as the numpy code it stands in for (`enrich.geometry`, `io.example`): the same
IEEE operations in the same order on float64 scalars (numba contracts nothing into fused multiply-adds without
fastmath), the first of equal minima as `argmin`, NaN where numpy's `maximum`, `clip` and `argmin` give it.
Tests compare every kernel with the numpy code on random and real inputs.
"""

from __future__ import annotations

import numba
import numpy as np

_CHUNK = 8  # segments per bounding box of the pruned scan
_PRUNE_FROM = 32  # segments from which a polyline is scanned chunk by chunk


@numba.njit(cache=True, nogil=True)
def _box_gap2(px: float, py: float, low_x: float, low_y: float, high_x: float, high_y: float) -> float:
    """Squared distance from a point to a box (0 inside)."""
    gx = max(max(low_x - px, px - high_x), 0.0)
    gy = max(max(low_y - py, py - high_y), 0.0)
    return gx * gx + gy * gy


@numba.njit(cache=True, nogil=True)
def _scan(px, py, line, sx, sy, seg_len2, prune, low, high):
    """Nearest segment of one point: (index, frac, foot x, foot y, squared distance), as `geometry._feet` and
    `argmin` give them (segment j: from line[j] along (sx[j], sy[j])). `prune`: skip the chunks of `_CHUNK` segments
    (boxes `low`/`high` (C, 2) from `_chunk_boxes`) whose box lies further than the best so far."""
    best, best_frac, best_x, best_y, best_d2 = -1, 0.0, 0.0, 0.0, 0.0
    j, stop = 0, sx.shape[0]
    while j < stop:
        if prune and j % _CHUNK == 0 and best >= 0:
            # The margin covers rounding: a skipped chunk holds no segment at or below the best (ties keep the
            # earlier index anyway, as argmin does).
            c = j // _CHUNK
            if _box_gap2(px, py, low[c, 0], low[c, 1], high[c, 0], high[c, 1]) > best_d2 * (1.0 + 1e-9) + 1e-9:
                j += _CHUNK
                continue
        ax, ay = line[j, 0], line[j, 1]
        frac = (px - ax) * sx[j]
        frac += (py - ay) * sy[j]
        frac /= seg_len2[j]
        if frac < 0.0:  # np.clip: NaN stays NaN
            frac = 0.0
        elif frac > 1.0:
            frac = 1.0
        foot_x = frac * sx[j] + ax
        foot_y = frac * sy[j] + ay
        dx = px - foot_x
        dy = py - foot_y
        d2 = dx * dx + dy * dy
        if best < 0 or d2 < best_d2 or (d2 != d2 and best_d2 == best_d2):  # argmin: the first NaN wins
            best, best_frac, best_x, best_y, best_d2 = j, frac, foot_x, foot_y, d2
            if d2 != d2:
                break
        j += 1
    return best, best_frac, best_x, best_y, best_d2


@numba.njit(cache=True, nogil=True)
def _chunk_boxes(line, num_segments):
    """Bounding boxes of the chunks of `_CHUNK` segments of `line` (chunk c: vertices c * _CHUNK .. its last
    segment's end). -> (C, 2) low, (C, 2) high"""
    num = (num_segments + _CHUNK - 1) // _CHUNK
    low = np.empty((num, 2))
    high = np.empty((num, 2))
    for c in range(num):
        begin = c * _CHUNK
        end = min(begin + _CHUNK, num_segments)
        for d in range(2):
            lo = line[begin, d]
            hi = lo
            for v in range(begin + 1, end + 1):
                lo = min(lo, line[v, d])
                hi = max(hi, line[v, d])
            low[c, d] = lo
            high[c, d] = hi
    return low, high


@numba.njit(cache=True, nogil=True)
def _all_finite(values) -> bool:
    for v in values.ravel():
        if not np.isfinite(v):
            return False
    return True


@numba.njit(cache=True, nogil=True)
def _pruning(line, num_segments, finite_points):
    """Whether the scan of `line` may skip chunks (long, every coordinate finite) and its chunk boxes (empty
    otherwise)."""
    prune = num_segments >= _PRUNE_FROM and finite_points and _all_finite(line)
    if prune:
        low, high = _chunk_boxes(line, num_segments)
        return True, low, high
    return False, np.empty((0, 2)), np.empty((0, 2))


@numba.njit(cache=True, nogil=True)
def nearest_on_polyline(pts, line, sx, sy, seg_len2, cum, with_foot):
    """`geometry.project_to_polyline` after `polyline_segments`: distance (m,), foot arc (m,), foot (m, 2) (zeros
    unless `with_foot`). pts (m, 2), line (n >= 2, 2)."""
    m = pts.shape[0]
    dist = np.empty(m)
    arc = np.empty(m)
    foot = np.zeros((m, 2) if with_foot else (0, 2))
    prune, low, high = _pruning(line, sx.shape[0], _all_finite(pts))
    for i in range(m):
        best, frac, foot_x, foot_y, d2 = _scan(pts[i, 0], pts[i, 1], line, sx, sy, seg_len2, prune, low, high)
        arc[i] = cum[best] + frac * np.sqrt(seg_len2[best])
        dist[i] = np.sqrt(d2)
        if with_foot:
            foot[i, 0] = foot_x
            foot[i, 1] = foot_y
    return dist, arc, foot


@numba.njit(cache=True, nogil=True)
def nearest_on_polylines(pts, vertex, counts):
    """`geometry.project_to_polylines` for polylines of >= 2 vertices stored back to back (`vertex` (V, 2), vertices
    per polyline `counts` (L,)): distance (L, m), foot arc (L, m), each polyline as `nearest_on_polyline` after
    `segment_vectors`."""
    dist = np.empty((counts.shape[0], pts.shape[0]))
    arc = np.empty((counts.shape[0], pts.shape[0]))
    start = 0
    for row in range(counts.shape[0]):
        line = vertex[start:start + counts[row]]
        start += counts[row]
        sx, sy, seg_len2, cum = segment_vectors(line)
        dist[row], arc[row], _ = nearest_on_polyline(pts, line, sx, sy, seg_len2, cum, False)
    return dist, arc


@numba.njit(cache=True, nogil=True)
def trailing_run(values) -> int:
    """Where the run of values equal to the last one starts (shard arrays end in padding). (n >= 1,) -> index"""
    start = values.shape[0] - 1
    while start > 0 and values[start - 1] == values[start]:
        start -= 1
    return start


@numba.njit(cache=True, nogil=True)
def varint_bytes(values):
    """Packed protobuf varints of uint64 values (the bit patterns of int64s). (n,) -> (bytes,) uint8"""
    low7, more, shift = np.uint64(0x7F), np.uint64(0x80), np.uint64(7)  # uint64 throughout (no float promotion)
    size = 0
    for i in range(values.shape[0]):
        v = values[i]
        size += 1
        while v > low7:
            v = v >> shift
            size += 1
    out = np.empty(size, np.uint8)
    at = 0
    for i in range(values.shape[0]):
        v = values[i]
        while v > low7:
            out[at] = np.uint8((v & low7) | more)
            v = v >> shift
            at += 1
        out[at] = np.uint8(v)
        at += 1
    return out


@numba.njit(cache=True, nogil=True)
def track_on_lane(track, box, radius, line, sx, sy, seg_len2, cum):
    """`paths._TrackNearLanes._project`: distance (m,) and foot arc (m,) of the logged positions `track` (m, 2) on
    one lane, computed for the positions inside the lane's bounding box `box` (min x, min y, max x, max y) grown
    by `radius` + 1 m (inf / nan elsewhere), and how many lie inside."""
    m = track.shape[0]
    dist = np.full(m, np.inf)
    arc = np.full(m, np.nan)
    low_x, low_y = box[0] - radius - 1.0, box[1] - radius - 1.0
    high_x, high_y = box[2] + radius + 1.0, box[3] + radius + 1.0
    prune, low, high = _pruning(line, sx.shape[0], True)  # a position inside the (finite) box is finite
    inside = 0
    for i in range(m):
        px, py = track[i, 0], track[i, 1]
        if not (px >= low_x and px <= high_x and py >= low_y and py <= high_y):  # NaN: outside
            continue
        inside += 1
        best, frac, _, _, d2 = _scan(px, py, line, sx, sy, seg_len2, prune, low, high)
        arc[i] = cum[best] + frac * np.sqrt(seg_len2[best])
        dist[i] = np.sqrt(d2)
    return dist, arc, inside


@numba.njit(cache=True, nogil=True)
def arc_lengths(xy):
    """`geometry.arc_lengths` of a float64 polyline (n, 2+): 0, then the running sum of the 2-D steps. -> (n,)"""
    n = xy.shape[0]
    out = np.zeros(n)
    total = 0.0
    for i in range(1, n):
        dx = xy[i, 0] - xy[i - 1, 0]
        dy = xy[i, 1] - xy[i - 1, 1]
        step = np.sqrt(dx * dx + dy * dy)
        total = step if i == 1 else total + step  # np.cumsum starts from the first value itself
        out[i] = total
    return out


@numba.njit(cache=True, nogil=True)
def run_cumsum(values, counts):
    """`geometry.run_cumsum`: np.cumsum within each run of `values` (n,) (runs of `counts` (R,), back to back)."""
    out = np.empty_like(values)
    at = 0
    for r in range(counts.shape[0]):
        total = 0.0
        for i in range(counts[r]):
            total = values[at] if i == 0 else total + values[at]
            out[at] = total
            at += 1
    return out


@numba.njit(cache=True, nogil=True)
def _last_at_or_below(xp, value, first, stop) -> int:
    """The last index j in [first, stop) with xp[j] <= value, first - 1 when none (np.searchsorted(..., "right")
    - 1 by bisection). xp non-decreasing there."""
    lo, hi = first, stop
    while lo < hi:
        mid = lo + ((hi - lo) >> 1)
        if value >= xp[mid]:
            lo = mid + 1
        else:
            hi = mid
    return lo - 1


@numba.njit(cache=True, nogil=True)
def _interp_into(out, i, value, xp, fp, first, n):
    """out[i, :] = np.interp(value, xp[first:first + n], fp[first:first + n, k]) for every column k, bit for bit, by
    numpy's rule (compiled_base.c) with j the last index with xp[j] <= value: a one-point xp gives fp[0]; NaN stays
    NaN; left of xp: fp[0]; right of it, at its last point or on xp[j] itself: fp[j]; else slope * (value - xp[j])
    + fp[j], and where that is NaN (an infinite slope) the same from xp[j + 1], else fp[j] when fp[j] == fp[j + 1].
    xp non-decreasing there (numpy's search may land on another j elsewhere)."""
    d = fp.shape[1]
    last = first + n - 1
    if n == 1:  # numpy's own case: fp[0] whatever the value is (NaN included)
        j = first
    elif value != value:
        for k in range(d):
            out[i, k] = value
        return
    elif value < xp[first]:
        j = first
    elif value >= xp[last]:
        j = last
    else:
        j = _last_at_or_below(xp, value, first, last + 1)
    if j == last or xp[j] == value or value < xp[j]:
        for k in range(d):
            out[i, k] = fp[j, k]
        return
    for k in range(d):
        slope = (fp[j + 1, k] - fp[j, k]) / (xp[j + 1] - xp[j])
        result = slope * (value - xp[j]) + fp[j, k]
        if result != result:
            result = slope * (value - xp[j + 1]) + fp[j + 1, k]
            if result != result and fp[j, k] == fp[j + 1, k]:
                result = fp[j, k]
        out[i, k] = result


@numba.njit(cache=True, nogil=True)
def _ordered(xp, first, n) -> bool:
    """Whether xp[first:first + n] is non-decreasing (no NaN)."""
    for j in range(first, first + n - 1):
        if not xp[j] <= xp[j + 1]:
            return False
    return True


@numba.njit(cache=True, nogil=True)
def interp_columns(x, xp, fp):
    """np.interp(x, xp, fp[:, k]) for every column k, bit for bit (`_interp_into`). x (m,), xp (n >= 1,), fp (n, d)
    -> (m, d), and whether it was computed: not where xp is not non-decreasing (NaN included)."""
    out = np.empty((x.shape[0], fp.shape[1]))
    if not _ordered(xp, 0, xp.shape[0]):
        return out, False
    for i in range(x.shape[0]):
        _interp_into(out, i, x[i], xp, fp, 0, xp.shape[0])
    return out, True


@numba.njit(cache=True, nogil=True)
def run_interp(x, x_run, xp, fp, counts):
    """`geometry.run_interp`: np.interp(x[i], xp_r, fp_r[:, k]) against the run r = x_run[i] of xp (n,) and fp (n, d)
    (runs of `counts` (R,) >= 1, back to back). -> (m, d), and whether it was computed (every run ordered)."""
    out = np.empty((x.shape[0], fp.shape[1]))
    starts = np.empty(counts.shape[0], np.int64)
    at = 0
    for r in range(counts.shape[0]):
        starts[r] = at
        if not _ordered(xp, at, counts[r]):
            return out, False
        at += counts[r]
    for i in range(x.shape[0]):
        r = x_run[i]
        _interp_into(out, i, x[i], xp, fp, starts[r], counts[r])
    return out, True


@numba.njit(cache=True, nogil=True)
def slice_polyline(polyline, cum, start, stop):
    """`geometry.slice_polyline` for start < stop (already clamped to the polyline): the interpolated start, the
    vertices strictly between, the interpolated stop. polyline (n >= 1, d), cum (n,) -> (k, d), and whether it
    was computed (not where cum is not non-decreasing: the vertices between would not be one run)."""
    n, d = polyline.shape
    if not _ordered(cum, 0, n):
        return np.empty((0, d)), False
    first = 0
    while first < n and not cum[first] > start:
        first += 1
    inner = 0
    while first + inner < n and cum[first + inner] < stop:
        inner += 1
    out = np.empty((inner + 2, d))
    _interp_into(out, 0, start, cum, polyline, 0, n)
    for i in range(inner):
        for k in range(d):
            out[1 + i, k] = polyline[first + i, k]
    _interp_into(out, inner + 1, stop, cum, polyline, 0, n)
    return out, True


@numba.njit(cache=True, nogil=True)
def resample_path(xyz, lane, spacing, max_points):
    """`paths._resample` after the pieces are joined: the points (n, 3) with lane indices (n,) resampled every
    `spacing` along their 2-D arc length, at most `max_points`, repeated points (a step <= 1e-6 m) dropped first.
    xyz (n >= 1, 3) float64 -> points (q, 3), lane index of each (q,), and whether they were computed (not where the
    length is not finite: np.arange refuses it)."""
    n = xyz.shape[0]
    cum = arc_lengths(xyz)
    keep = np.empty(n, np.bool_)
    keep[0] = True
    for i in range(1, n):
        keep[i] = cum[i] - cum[i - 1] > 1e-6
    kept = np.flatnonzero(keep)
    points, lanes, arcs = xyz[kept], lane[kept], cum[kept]
    if points.shape[0] <= 1:
        return points[:1].copy(), lanes[:1].copy(), True
    total = min(arcs[-1], (max_points - 1) * spacing)
    if not np.isfinite(total):
        return points[:0].copy(), lanes[:0].copy(), False
    count = min(int(np.ceil((total + 1e-6) / spacing)), max_points)  # np.arange(0, total + 1e-6, spacing)[:max]
    out = np.empty((count, points.shape[1]))
    out_lane = np.empty(count, lane.dtype)
    for i in range(count):
        target = i * spacing  # np.arange's values from 0: i * step
        _interp_into(out, i, target, arcs, points, 0, arcs.shape[0])
        out_lane[i] = lanes[max(_last_at_or_below(arcs, target, 0, arcs.shape[0]), 0)]
    return out, out_lane, True


@numba.njit(cache=True, nogil=True)
def segment_vectors(line):
    """`geometry.polyline_segments` after the 2-D line (n >= 2, 2): segment vectors sx, sy (n-1,), squared lengths
    clamped to 1e-12 (n-1,), arc length at each vertex (n,)."""
    k = line.shape[0] - 1
    sx = np.empty(k)
    sy = np.empty(k)
    seg_len2 = np.empty(k)
    cum = np.empty(k + 1)
    cum[0] = 0.0
    for j in range(k):
        sx[j] = line[j + 1, 0] - line[j, 0]
        sy[j] = line[j + 1, 1] - line[j, 1]
        raw = sx[j] * sx[j] + sy[j] * sy[j]
        step = np.sqrt(raw)
        cum[j + 1] = step if j == 0 else cum[j] + step  # np.cumsum starts from the first value itself
        seg_len2[j] = 1e-12 if raw < 1e-12 else raw  # np.maximum: NaN stays NaN
    return sx, sy, seg_len2, cum

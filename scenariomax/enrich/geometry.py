"""Small polyline helpers shared by the enrichment steps (2-D maths on numpy arrays)."""

from __future__ import annotations

import numpy as np


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
    if len(xy) == 0:
        return np.zeros(0)
    steps = np.linalg.norm(np.diff(np.asarray(xy, np.float64)[:, :2], axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def unit(vectors: np.ndarray) -> np.ndarray:
    """Rows scaled to unit norm (zero rows stay zero). (n, d) -> (n, d)"""
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.where(norm > 1e-9, vectors / np.maximum(norm, 1e-9), 0.0)


def tangents(xy: np.ndarray) -> np.ndarray:
    """Unit 2-D direction at every vertex (the last vertex reuses the last segment). (n, 2+) -> (n, 2)"""
    xy = np.asarray(xy, np.float64)[:, :2]
    if len(xy) < 2:
        return np.zeros((len(xy), 2))
    seg = unit(np.diff(xy, axis=0))
    return np.vstack([seg, seg[-1:]])


def project_to_polyline(points: np.ndarray, polyline: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest point on a polyline for each query point.

    points (m, 2+), polyline (n, 2+) -> distance (m,), arc length of the foot (m,), foot (m, 2).
    """
    pts = np.asarray(points, np.float64)[:, :2]
    line = np.asarray(polyline, np.float64)[:, :2]
    if len(line) == 1:
        dist = np.linalg.norm(pts - line[0], axis=1)
        return dist, np.zeros(len(pts)), np.broadcast_to(line[0], pts.shape).copy()
    # x and y as separate (m, n-1) planes, updated in place: a (m, n-1, 2) array summed over its last axis
    # costs ~4x more (tiny-axis reductions are slow in numpy); the arithmetic, and so every bit, is the same.
    px, py = pts[:, 0:1], pts[:, 1:2]  # (m, 1)
    ax, ay = line[:-1, 0], line[:-1, 1]  # (n-1,) segment starts
    sx, sy = line[1:, 0] - ax, line[1:, 1] - ay  # (n-1,) segment vectors
    seg_len2 = np.maximum(sx * sx + sy * sy, 1e-12)  # (n-1,)
    frac = (px - ax) * sx
    frac += (py - ay) * sy
    frac /= seg_len2
    np.clip(frac, 0.0, 1.0, out=frac)  # (m, n-1) foot position along each segment
    foot_x, foot_y = frac * sx, frac * sy
    foot_x += ax
    foot_y += ay  # (m, n-1) feet
    dist2 = px - foot_x
    dist2 *= dist2
    dy = py - foot_y
    dy *= dy
    dist2 += dy  # (m, n-1) squared distance to each segment
    best = dist2.argmin(axis=1)
    rows = np.arange(len(pts))
    cum = arc_lengths(line)
    arc = cum[best] + frac[rows, best] * np.sqrt(seg_len2[best])
    return np.sqrt(dist2[rows, best]), arc, np.stack([foot_x[rows, best], foot_y[rows, best]], axis=1)


def point_at_arc(polyline: np.ndarray, cum: np.ndarray, arcs: np.ndarray) -> np.ndarray:
    """Points at the given arc lengths (linear interpolation per coordinate). -> (m, d)"""
    arcs = np.asarray(arcs, np.float64)
    return np.stack([np.interp(arcs, cum, polyline[:, k]) for k in range(polyline.shape[1])], axis=1)


def slice_polyline(polyline: np.ndarray, cum: np.ndarray, start: float, stop: float) -> np.ndarray:
    """The part of a polyline between two arc lengths, with interpolated end points. -> (k, d)"""
    start, stop = max(float(start), 0.0), min(float(stop), float(cum[-1]))
    if stop <= start:
        return point_at_arc(polyline, cum, [start])
    inner = (cum > start) & (cum < stop)
    return np.vstack([point_at_arc(polyline, cum, [start]), polyline[inner], point_at_arc(polyline, cum, [stop])])


def segment_distances(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance from each point (m, 2+) to a polyline (n, 2+). -> (m,)"""
    return project_to_polyline(points, polyline)[0]

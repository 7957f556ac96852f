"""Map polylines -> roadgraph sample points, and the lane graph arrays of a Scenario.

Sources describe their maps as `MapPolyline`s (one per lane centreline, road line, road edge,
crosswalk outline, stop sign...) and lanes' links as `LaneLinks`; these helpers resample them at
a fixed spacing and compute unit direction vectors, so every dataset shares one convention.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence

import numpy as np

from scenariomax.enrich.geometry import run_cumsum, run_interp, run_starts

DEFAULT_SPACING_M = 1.0


@dataclasses.dataclass(frozen=True)
class MapPolyline:
    feature_id: int  # stable id (lane ids must match traffic-light lane ids)
    feature_type: int  # enum roadgraph_type
    xyz: np.ndarray  # (n, 3) float, ordered along the feature (lanes: driving direction)
    speed_limit: float = -1.0  # m/s, lanes only; -1 unknown
    closed: bool = False  # polygons (crosswalks, speed bumps): the last point joins the first


@dataclasses.dataclass(frozen=True)
class LaneLinks:
    lane_id: int
    successors: Sequence[int] = ()
    predecessors: Sequence[int] = ()
    left_neighbors: Sequence[int] = ()
    right_neighbors: Sequence[int] = ()


def resample_polyline(xyz: np.ndarray, spacing: float = DEFAULT_SPACING_M, closed: bool = False,
                      origin: np.ndarray | None = None) -> np.ndarray:
    """Points every `spacing` metres along the polyline, keeping both ends. (n, 3) -> (m, 3).

    `origin` (3,) is subtracted in float64 before the float32 cast, so large map coordinates
    (e.g. UTM) keep centimetre precision."""
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if origin is not None:
        xyz = xyz - np.asarray(origin, np.float64)
    if closed and len(xyz) > 2 and not np.allclose(xyz[0], xyz[-1]):
        xyz = np.vstack([xyz, xyz[:1]])
    if len(xyz) < 2:
        return xyz.astype(np.float32)
    seg = np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-6])  # drop repeated points
    xyz = xyz[keep]
    if len(xyz) < 2:
        return xyz[:1].astype(np.float32)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xyz[:, :2], axis=0), axis=1))])
    num = max(int(np.ceil(arc[-1] / spacing)), 1) + 1
    targets = np.linspace(0.0, arc[-1], num)
    return np.stack([np.interp(targets, arc, xyz[:, k]) for k in range(3)], axis=1).astype(np.float32)


def direction_vectors(xyz: np.ndarray) -> np.ndarray:
    """Unit vector from each point to the next one; the last point gets zeros. (m, 3) -> (m, 3)."""
    dirs = np.zeros_like(xyz, dtype=np.float32)
    if len(xyz) < 2:
        return dirs
    diff = np.diff(xyz.astype(np.float64), axis=0)
    norm = np.linalg.norm(diff, axis=1, keepdims=True)
    dirs[:-1] = np.where(norm > 1e-9, diff / np.maximum(norm, 1e-9), 0.0)
    return dirs


def _prepared(line: MapPolyline, origin: np.ndarray | None) -> np.ndarray:
    """One polyline's points as `resample_polyline` starts from them: float64, `origin` subtracted, a
    polygon closed. -> (n, 3)"""
    xyz = np.asarray(line.xyz, dtype=np.float64).reshape(-1, 3)
    if origin is not None:
        xyz = xyz - np.asarray(origin, np.float64)
    if line.closed and len(xyz) > 2 and not _allclose(xyz[0].tolist(), xyz[-1].tolist()):
        xyz = np.vstack([xyz, xyz[:1]])
    return xyz


def _allclose(a: list[float], b: list[float]) -> bool:
    """np.allclose(a, b) of two short vectors in plain floats (the call costs ~15 us; the arithmetic is the
    same: |a - b| <= 1e-8 + 1e-5 |b| where both are finite, else equality)."""
    return all(abs(x - y) <= 1e-8 + 1e-5 * abs(y) if math.isfinite(x) and math.isfinite(y) else x == y
               for x, y in zip(a, b))


def _norm2d(diff: np.ndarray) -> np.ndarray:
    """np.linalg.norm(diff[:, :2], axis=1) with the same bits. (n, 2+) -> (n,)"""
    return np.sqrt(diff[:, 0] * diff[:, 0] + diff[:, 1] * diff[:, 1])


def resample_polylines(polylines: Sequence[np.ndarray], spacing: float = DEFAULT_SPACING_M) -> tuple[np.ndarray,
                                                                                                    np.ndarray]:
    """`resample_polyline` of many prepared polylines (see `_prepared`) at once, the same bits per polyline.
    -> points (m, 3) float32 back to back, points per polyline (P,)"""
    counts = np.array([len(xyz) for xyz in polylines], np.int64)  # (P,)
    if counts.sum() == 0:
        return np.zeros((0, 3), np.float32), counts
    xyz = np.concatenate(polylines)  # (n, 3)
    first = np.zeros(len(xyz), bool)
    first[run_starts(counts)[counts > 0]] = True
    # Drop repeated points (a step <= 1 micrometre from the previous raw point of the same polyline).
    keep = first | np.concatenate([[True], _norm2d(np.diff(xyz, axis=0)) > 1e-6])
    owner = np.repeat(np.arange(len(counts)), counts)[keep]
    xyz = xyz[keep]  # (k, 3)
    kept = np.bincount(owner, minlength=len(counts))  # (P,)
    # Arc length along each polyline at each kept point: 0, then the running sum of its steps.
    step = np.concatenate([[0.0], _norm2d(np.diff(xyz, axis=0))])
    step[first[keep]] = 0.0
    arc = run_cumsum(step, kept)  # (k,)
    total = arc[np.minimum(run_starts(kept) + np.maximum(kept, 1) - 1, len(arc) - 1)]  # (P,) (unused where kept == 0)
    # np.linspace(0, total, num): index * (total / (num - 1)), the last target exactly `total`.
    num = np.where(kept >= 2, np.maximum(np.ceil(total / spacing).astype(np.int64), 1) + 1, kept)  # (P,)
    target_owner = np.repeat(np.arange(len(counts)), num)  # (m,)
    index = (np.arange(num.sum()) - np.repeat(run_starts(num), num)).astype(np.float64)  # (m,)
    with np.errstate(divide="ignore", invalid="ignore"):
        targets = index * (total / np.maximum(num - 1, 1))[target_owner]
    ends = run_starts(num) + num - 1
    targets[ends[num > 0]] = total[num > 0]
    has = kept > 0
    points = run_interp(targets, np.searchsorted(np.flatnonzero(has), target_owner), arc, xyz, kept[has])
    return points.astype(np.float32), num


def _directions(points: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """`direction_vectors` of polylines stored back to back, the same bits. (m, 3), (P,) -> (m, 3) float32"""
    dirs = np.zeros(points.shape, np.float32)
    if len(points) < 2:
        return dirs
    diff = np.diff(points.astype(np.float64), axis=0)  # (m-1, 3)
    norm = np.sqrt(diff[:, 0] * diff[:, 0] + diff[:, 1] * diff[:, 1] + diff[:, 2] * diff[:, 2])[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        dirs[:-1] = np.where(norm > 1e-9, diff / np.maximum(norm, 1e-9), 0.0)
    dirs[(run_starts(counts) + counts - 1)[counts > 0]] = 0.0  # each polyline's last point
    return dirs


def polylines_to_roadgraph(polylines: Sequence[MapPolyline], spacing: float = DEFAULT_SPACING_M,
                           origin: np.ndarray | None = None) -> dict:
    """Concatenated roadgraph arrays (unpadded): keys roadgraph_xyz, _dir, _type, _id, _valid,
    _speed_limit, ready to pass to `Scenario(**...)`. Every polyline is resampled as `resample_polyline`
    and given `direction_vectors`, all in one pass."""
    points, counts = resample_polylines([_prepared(line, origin) for line in polylines], spacing)

    def per_point(values, dtype) -> np.ndarray:
        return np.repeat(np.asarray(values, dtype), counts)

    return dict(
        roadgraph_xyz=points,
        roadgraph_dir=_directions(points, counts),
        roadgraph_type=per_point([line.feature_type for line in polylines], np.int64),
        roadgraph_id=per_point([line.feature_id for line in polylines], np.int64),
        roadgraph_valid=np.ones(len(points), bool),
        roadgraph_speed_limit=per_point([line.speed_limit for line in polylines], np.float32),
    )


def lane_graph_arrays(links: Sequence[LaneLinks], num_lane_links: int = 8) -> dict:
    """Lane graph arrays (unpadded in lanes, padded with -1 to `num_lane_links` per row)."""

    def table(attr: str) -> np.ndarray:
        out = np.full((len(links), num_lane_links), -1, np.int64)
        rows = [list(getattr(link, attr))[:num_lane_links] for link in links]
        counts = np.fromiter(map(len, rows), np.int64, count=len(rows))  # (K,)
        # All rows in one assignment (a loop of row assignments costs more than the table): row r's values fill
        # its first counts[r] columns.
        row = np.repeat(np.arange(len(rows)), counts)
        column = np.arange(len(row)) - np.repeat(np.cumsum(counts) - counts, counts)
        out[row, column] = np.fromiter(itertools.chain.from_iterable(rows), np.int64, count=len(row))
        return out

    return dict(
        lane_id=np.array([link.lane_id for link in links], np.int64),
        lane_valid=np.ones(len(links), bool),
        lane_successors=table("successors"),
        lane_predecessors=table("predecessors"),
        lane_left_neighbors=table("left_neighbors"),
        lane_right_neighbors=table("right_neighbors"),
    )

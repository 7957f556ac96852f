"""Map polylines -> roadgraph sample points, and the lane graph arrays of a Scenario.

Sources describe their maps as `MapPolyline`s (one per lane centreline, road line, road edge,
crosswalk outline, stop sign...) and lanes' links as `LaneLinks`; these helpers resample them at
a fixed spacing and compute unit direction vectors, so every dataset shares one convention.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

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


def polylines_to_roadgraph(polylines: Sequence[MapPolyline], spacing: float = DEFAULT_SPACING_M,
                           origin: np.ndarray | None = None) -> dict:
    """Concatenated roadgraph arrays (unpadded): keys roadgraph_xyz, _dir, _type, _id, _valid,
    _speed_limit, ready to pass to `Scenario(**...)`."""
    xyz, dirs, types, ids, limits = [], [], [], [], []
    for line in polylines:
        points = resample_polyline(line.xyz, spacing, line.closed, origin)
        if len(points) == 0:
            continue
        xyz.append(points)
        dirs.append(direction_vectors(points))
        types.append(np.full(len(points), line.feature_type, np.int64))
        ids.append(np.full(len(points), line.feature_id, np.int64))
        limits.append(np.full(len(points), line.speed_limit, np.float32))
    if not xyz:
        empty = np.zeros((0,), np.int64)
        return dict(roadgraph_xyz=np.zeros((0, 3), np.float32), roadgraph_dir=np.zeros((0, 3), np.float32),
                    roadgraph_type=empty, roadgraph_id=empty, roadgraph_valid=np.zeros(0, bool),
                    roadgraph_speed_limit=np.zeros(0, np.float32))
    xyz_all = np.concatenate(xyz)
    return dict(
        roadgraph_xyz=xyz_all,
        roadgraph_dir=np.concatenate(dirs),
        roadgraph_type=np.concatenate(types),
        roadgraph_id=np.concatenate(ids),
        roadgraph_valid=np.ones(len(xyz_all), bool),
        roadgraph_speed_limit=np.concatenate(limits),
    )


def lane_graph_arrays(links: Sequence[LaneLinks], num_lane_links: int = 8) -> dict:
    """Lane graph arrays (unpadded in lanes, padded with -1 to `num_lane_links` per row)."""

    def table(attr: str) -> np.ndarray:
        out = np.full((len(links), num_lane_links), -1, np.int64)
        for row, link in enumerate(links):
            values = list(getattr(link, attr))[:num_lane_links]
            out[row, : len(values)] = values
        return out

    return dict(
        lane_id=np.array([link.lane_id for link in links], np.int64),
        lane_valid=np.ones(len(links), bool),
        lane_successors=table("successors"),
        lane_predecessors=table("predecessors"),
        lane_left_neighbors=table("left_neighbors"),
        lane_right_neighbors=table("right_neighbors"),
    )

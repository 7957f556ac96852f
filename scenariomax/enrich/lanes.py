"""Lane centrelines pulled out of a scenario's roadgraph, with a spatial index over their points."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
from scipy.spatial import cKDTree

from scenariomax import schema as sch
from scenariomax.enrich.geometry import polyline_runs, run_cumsum, unit
from scenariomax.scenario import Scenario


@dataclasses.dataclass(frozen=True, eq=False)
class Lanes:
    """K lane centrelines stored back to back; lane k owns points[offsets[k]:offsets[k + 1]]."""

    ids: np.ndarray  # (K,) int64, roadgraph ids
    types: np.ndarray  # (K,) int64, enum roadgraph_type
    offsets: np.ndarray  # (K + 1,) int64
    points: np.ndarray  # (P, 3) float64

    @property
    def num_lanes(self) -> int:
        return int(self.ids.shape[0])

    def polyline(self, lane: int) -> np.ndarray:
        """Points of lane index `lane`. -> (n, 3)"""
        return self.points[self.offsets[lane]:self.offsets[lane + 1]]

    @functools.cached_property
    def counts(self) -> np.ndarray:  # (K,) int64 points per lane
        return np.diff(self.offsets)

    @functools.cached_property
    def cumulative(self) -> tuple[np.ndarray, ...]:
        """Arc length along each lane at each of its points (the bits of `arc_lengths` per lane, all lanes in
        one pass)."""
        if len(self.points) == 0:
            return tuple(np.zeros(0) for _ in range(self.num_lanes))
        step = np.concatenate([[0.0], _norm2d(np.diff(self.points, axis=0))])  # (P,) from the previous point
        step[self.offsets[:-1][self.counts > 0]] = 0.0  # each lane starts at 0
        return tuple(np.split(run_cumsum(step, self.counts), self.offsets[1:-1]))

    @functools.cached_property
    def lengths(self) -> np.ndarray:  # (K,) float64
        return np.array([c[-1] if c.size else 0.0 for c in self.cumulative])

    @functools.cached_property
    def point_lane(self) -> np.ndarray:  # (P,) int64, lane index of each point
        return np.repeat(np.arange(self.num_lanes), np.diff(self.offsets))

    @functools.cached_property
    def point_tangent(self) -> np.ndarray:  # (P, 2) unit direction of travel at each point
        if self.num_lanes == 0:
            return np.zeros((0, 2))
        # The bits of `tangents` per lane, all lanes in one pass: each point the direction of its segment to
        # the next point, a lane's last point that of the segment before it (a one-point lane: zeros).
        seg = unit(np.diff(self.points[:, :2], axis=0))  # (P-1, 2); rows between two lanes unused
        row = np.arange(len(self.points))
        row[self.offsets[1:][self.counts > 0] - 1] -= 1
        out = seg[np.clip(row, 0, max(len(seg) - 1, 0))] if len(seg) else np.zeros((len(self.points), 2))
        out[np.repeat(self.counts < 2, self.counts)] = 0.0
        return out

    @functools.cached_property
    def boxes(self) -> np.ndarray:  # (K, 4) float64 bounding box of each lane: min x, min y, max x, max y
        if self.num_lanes == 0:
            return np.zeros((0, 4))
        starts = self.offsets[:-1]  # every lane has >= 1 point (extract_lanes keeps >= 2)
        xy = self.points[:, :2]
        return np.hstack([np.minimum.reduceat(xy, starts, axis=0), np.maximum.reduceat(xy, starts, axis=0)])

    @functools.cached_property
    def tree(self) -> cKDTree:
        return cKDTree(self.points[:, :2] if len(self.points) else np.zeros((0, 2)))

    @functools.cached_property
    def memo(self) -> dict:
        """Scratch space for results derived from these lanes alone (e.g. the path search's whole-lane pieces),
        shared by every search of one scenario; never part of the lanes' value."""
        return {}

    @functools.cached_property
    def index_of(self) -> dict[int, int]:
        return {lane_id: k for k, lane_id in enumerate(self.ids.tolist())}


def edge_tree(lanes: Lanes, edge_xy: np.ndarray) -> cKDTree:
    """A cKDTree over road-edge points (k, 2) of the lanes' scenario, built once: the lane graph and the
    controllable labels query the same points (kept in `lanes.memo`, rebuilt when other points are asked)."""
    cached = lanes.memo.get("edge_tree")
    if cached is not None and cached[0].shape == edge_xy.shape and np.array_equal(cached[0], edge_xy):
        return cached[1]
    tree = cKDTree(edge_xy)
    lanes.memo["edge_tree"] = (edge_xy.copy(), tree)
    return tree


def _norm2d(diff: np.ndarray) -> np.ndarray:
    """np.linalg.norm(diff[:, :2], axis=1) with the same bits. (n, 2+) -> (n,)"""
    return np.sqrt(diff[:, 0] * diff[:, 0] + diff[:, 1] * diff[:, 1])


def extract_lanes(scenario: Scenario) -> Lanes:
    """Lane polylines (types freeway, surface street, bike) from the roadgraph. When a lane id has
    several runs (e.g. after a budget crop) the longest one is kept; single-point lanes are dropped."""
    is_lane = np.isin(scenario.roadgraph_type, sch.LANE_TYPES) & scenario.roadgraph_valid
    runs = polyline_runs(scenario.roadgraph_id, is_lane)
    best: dict[int, tuple[int, int]] = {}
    # Plain ints in the loop (a map has hundreds of lanes; numpy scalars cost ~10x more per operation).
    for (start, stop), lane_id in zip(runs.tolist(), scenario.roadgraph_id[runs[:, 0]].tolist()):
        if stop - start >= 2 and (lane_id not in best or stop - start > best[lane_id][1] - best[lane_id][0]):
            best[lane_id] = (start, stop)
    chosen = sorted(best.values())  # roadgraph order: deterministic
    xyz = scenario.roadgraph_xyz.astype(np.float64)
    points = [xyz[a:b] for a, b in chosen]
    sizes = [b - a for a, b in chosen]
    first = np.array([a for a, _ in chosen], np.int64)  # (K,)
    return Lanes(
        ids=scenario.roadgraph_id[first].astype(np.int64),
        types=scenario.roadgraph_type[first].astype(np.int64),
        offsets=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        points=np.concatenate(points) if points else np.zeros((0, 3)),
    )


def nearest_lane_points(lanes: Lanes, xy: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Distance to and index of the nearest lane point within `radius` (inf / -1 when none). -> (m,), (m,)"""
    if len(lanes.points) == 0 or len(xy) == 0:
        return np.full(len(xy), np.inf), np.full(len(xy), -1, np.int64)
    dist, index = lanes.tree.query(np.asarray(xy, np.float64)[:, :2], k=1, distance_upper_bound=radius)
    index = np.where(np.isfinite(dist), index, -1)
    return dist, index.astype(np.int64)

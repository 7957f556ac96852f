"""Route geometry shared by every mover on the same lane sequence: samples, headings, where each
lane starts, the gates (reserved lanes) on the way, and a desired-speed profile that slows down
for bends ahead."""

from __future__ import annotations

import dataclasses

import numpy as np

from scenariomax.sources.synthetic import geometry as geo
from scenariomax.sources.synthetic.network import RoadNetwork

ROUTE_DS_M = 0.5  # route resampling: position lookups become index arithmetic
MAX_ROUTE_POINTS = 2400  # 1.2 km
LATERAL_ACCEL = 2.5  # m/s^2 drivers accept in bends
ANTICIPATION_DECEL = 1.2  # m/s^2 used to slow down ahead of a bend
MIN_DESIRED_SPEED = 2.0  # m/s


@dataclasses.dataclass(frozen=True)
class Gate:
    lane_id: int
    start_s: float  # route arc length of the stop point
    end_s: float  # route arc length where the gated lane ends
    signal_group: int
    has_stop_sign: bool
    conflicts: tuple[int, ...]
    yields_to: tuple[int, ...]


@dataclasses.dataclass(frozen=True)
class RouteShape:
    """What every mover on one route shares (cached per route)."""

    xy: np.ndarray  # (n, 2) route samples ROUTE_DS_M apart
    yaw: np.ndarray  # (n,) heading at each sample
    starts: np.ndarray  # (num_lanes + 1,) arc length where each route lane starts (and the end)
    speed_limit: np.ndarray  # (n,) the lane's limit at each sample
    bend_speed: np.ndarray  # (n,) speed keeping lateral acceleration comfortable
    gates: tuple[Gate, ...]
    siblings: tuple[tuple[int, float], ...]  # (lane branching beside the route, arc length of the fork)
    crosswalks: tuple  # (index, |along| (n,), |across| (n,), half length, half width) per nearby crosswalk


def route_shape(network: RoadNetwork, route: tuple[int, ...]) -> RouteShape:
    lanes = [network.lane(lane_id) for lane_id in route]
    starts = np.concatenate([[0.0], np.cumsum([lane.length for lane in lanes])])
    xy = geo.resample(geo.join(*[lane.xy for lane in lanes]), ROUTE_DS_M)[:MAX_ROUTE_POINTS]
    heading = geo.tangents(xy) if len(xy) > 1 else np.array([[1.0, 0.0]])
    yaw = np.arctan2(heading[:, 1], heading[:, 0])
    arc = np.arange(len(xy)) * ROUTE_DS_M
    lane_index = np.clip(np.searchsorted(starts, arc, side="right") - 1, 0, len(lanes) - 1)
    limit = np.array([lane.speed_limit for lane in lanes])[lane_index]
    curvature = np.abs(np.gradient(np.unwrap(yaw), ROUTE_DS_M)) if len(xy) > 2 else np.zeros(len(xy))
    curvature = np.convolve(curvature, np.ones(9) / 9, mode="same")  # over ~4 m
    bend = np.sqrt(LATERAL_ACCEL / np.maximum(curvature, 1e-6))
    gates = tuple(
        Gate(lane.lane_id, float(starts[k]), float(starts[k + 1]), lanes[k - 1].signal_group,
              lanes[k - 1].has_stop_sign, lane.conflicts, lane.yields_to)
        for k, lane in enumerate(lanes) if k > 0 and lane.is_gated)
    siblings = tuple((other, float(starts[k])) for k in range(1, len(lanes))
                     for other in lanes[k - 1].successors if other != route[k])
    walks = []
    for index, walk in enumerate(network.crosswalks):
        along = (walk.end - walk.start) / np.linalg.norm(walk.end - walk.start)
        rel = xy - walk.polygon.mean(axis=0)
        half_len = np.linalg.norm(walk.polygon[1] - walk.polygon[0]) / 2
        half_wid = np.linalg.norm(walk.polygon[3] - walk.polygon[0]) / 2
        along_abs, across_abs = np.abs(rel @ along), np.abs(rel @ geo.left_normal(along))
        if np.any((along_abs < half_len + 1.0) & (across_abs < half_wid + 6.0)):
            walks.append((index, along_abs, across_abs, half_len, half_wid))
    return RouteShape(xy, yaw, starts, limit, bend, gates, siblings, tuple(walks))


def anticipate(desired: np.ndarray) -> np.ndarray:
    """Lowers desired speeds ahead of slow stretches so drivers brake before them, not in them:
    v(s) <= sqrt(v(s')^2 + 2 b (s' - s)) for every s' ahead. (n,) -> (n,)"""
    desired = np.maximum(desired, MIN_DESIRED_SPEED)
    arc = np.arange(len(desired)) * ROUTE_DS_M
    reach = np.minimum.accumulate((desired ** 2 + 2 * ANTICIPATION_DECEL * arc)[::-1])[::-1]
    return np.sqrt(np.maximum(reach - 2 * ANTICIPATION_DECEL * arc, MIN_DESIRED_SPEED ** 2))

"""Which logged agents a policy may drive in reactive evaluation, and a lane path for each.

An agent is controllable when it is
- a vehicle, valid at every step of the scenario (a partial track cannot be replayed or scored);
- on the road at every step: within `lane_radius_m` (2 m) of some lane centre point, and never more
  than `edge_margin_m` (0.5 m) on the wrong (right-hand) side of its nearest road edge within 3 m;
- not parked: it moves more than `min_travel_m` (2 m) from its first position, or covers more
  than `min_speed_mps` (0.5 m/s) x 1 s within some 1 s window (positions, not the noisy velocity).
The SDC is always labelled controllable (a policy drives it); the statistics count other agents.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich.geometry import row_norm
from scenariomax.enrich.lane_graph import LaneGraph
from scenariomax.enrich.lanes import Lanes, nearest_lane_points
from scenariomax.enrich.lanes import edge_tree as shared_edge_tree
from scenariomax.enrich.paths import Path, PathSettings, logged_track, search_paths
from scenariomax.scenario import Scenario

STEPS_PER_SECOND = 10


@dataclasses.dataclass(frozen=True)
class ControllableSettings:
    lane_radius_m: float = 2.0
    edge_search_m: float = 3.0
    edge_margin_m: float = 0.5
    min_travel_m: float = 2.0
    min_speed_mps: float = 0.5


@dataclasses.dataclass(frozen=True)
class ControllableStats:
    num_scenarios: int
    num_with_controllable: int  # scenarios with >= 1 controllable agent besides the SDC
    mean_per_scenario: float  # controllable agents besides the SDC


def is_moving(x: np.ndarray, y: np.ndarray, settings: ControllableSettings = ControllableSettings()) -> bool:
    """True unless the (fully valid) track looks parked. (T,), (T,) -> bool"""
    return bool(_moving_rows(np.asarray(x)[None], np.asarray(y)[None], settings)[0])


def _on_road(scenario: Scenario, lanes: Lanes, xy: np.ndarray, edge_tree, edge_xy, edge_dir,
             settings: ControllableSettings) -> np.ndarray:
    """(m, 2) -> (m,) bool: near a lane centre and not beyond a road edge."""
    near_lane = np.isfinite(nearest_lane_points(lanes, xy, settings.lane_radius_m)[0])
    if edge_tree is None:
        return near_lane
    dist, idx = edge_tree.query(xy, k=1, distance_upper_bound=settings.edge_search_m)
    found = np.isfinite(dist)
    safe = np.where(found, idx, 0)
    rel = xy - edge_xy[safe]
    signed = edge_dir[safe, 0] * rel[:, 1] - edge_dir[safe, 1] * rel[:, 0]  # > 0: left = road side
    return near_lane & ~(found & (signed < -settings.edge_margin_m))


def controllable_mask(scenario: Scenario, lanes: Lanes,
                      settings: ControllableSettings = ControllableSettings()) -> np.ndarray:
    """(N,) bool controllable labels (edges must already be oriented road-on-the-left)."""
    edges = np.isin(scenario.roadgraph_type, sch.ROAD_EDGE_TYPES) & scenario.roadgraph_valid
    edge_xy = scenario.roadgraph_xyz[edges, :2].astype(np.float64)
    edge_dir = scenario.roadgraph_dir[edges, :2].astype(np.float64)
    edge_tree = shared_edge_tree(lanes, edge_xy) if len(edge_xy) else None
    mask = np.zeros(scenario.num_objects, bool)
    full = np.flatnonzero(scenario.valid.all(axis=1) & (scenario.object_type == sch.OBJECT_TYPE_VEHICLE))
    moving = full[_moving_rows(scenario.x[full], scenario.y[full], settings)]  # (k,)
    if len(moving):
        # Every moving vehicle's positions in one query (each point's answer is its own), then per vehicle.
        xy = np.stack([scenario.x[moving], scenario.y[moving]], -1).astype(np.float64)  # (k, T, 2)
        on_road = _on_road(scenario, lanes, xy.reshape(-1, 2), edge_tree, edge_xy, edge_dir, settings)
        mask[moving] = on_road.reshape(len(moving), -1).all(axis=1)
    mask[scenario.sdc_index] = True
    return mask


def _moving_rows(x: np.ndarray, y: np.ndarray, settings: ControllableSettings) -> np.ndarray:
    """Whether each track moves: it gets further than `min_travel_m` from its start, or faster than
    `min_speed_mps` over some one-second window; every row at once. (k, T), (k, T) -> (k,) bool"""
    xy = np.stack([x, y], -1).astype(np.float64)  # (k, T, 2)
    if len(xy) == 0:
        return np.zeros(0, bool)
    travel = row_norm(xy - xy[:, :1]).max(axis=1, initial=0.0)  # (k,)
    window = STEPS_PER_SECOND
    if xy.shape[1] > window:
        speed = row_norm(xy[:, window:] - xy[:, :-window]).max(axis=1) * STEPS_PER_SECOND / window
    else:
        speed = np.zeros(len(xy))
    return (travel > settings.min_travel_m) | (speed > settings.min_speed_mps)


def nearest_first(scenario: Scenario, agents: np.ndarray) -> np.ndarray:
    """Indices of the `agents` (mask (N,)) valid at the current step, the SDC left out, by distance to the SDC
    there (ties: object order)."""
    start, sdc = scenario.current_time_index, scenario.sdc_index
    candidates = np.flatnonzero(agents & scenario.valid[:, start])
    candidates = candidates[candidates != sdc]
    distance = np.hypot(scenario.x[candidates, start] - scenario.x[sdc, start],
                        scenario.y[candidates, start] - scenario.y[sdc, start])
    return candidates[np.argsort(distance, kind="stable")]


def agent_paths(scenario: Scenario, lanes: Lanes, graph: LaneGraph, controllable: np.ndarray,
                num_agent_paths: int, settings: PathSettings) -> dict:
    """The best path of each controllable agent but the SDC, nearest the SDC first (up to the budget: in dense
    scenes the agents that interact with the SDC get the slots): the lane path that follows its log from the
    current step on, spliced with the logged positions where no lane path does (`search_paths`, `follow_log`)."""
    agent_settings = dataclasses.replace(settings, num_paths=1, max_candidates=8, max_expansions=80,
                                         unlogged_lane_changes=False)
    start = scenario.current_time_index
    chosen: list[tuple[int, Path]] = []
    for index in nearest_first(scenario, controllable):
        if len(chosen) >= num_agent_paths:
            break
        track, track_yaw = logged_track(scenario.x[index], scenario.y[index], scenario.bbox_yaw[index],
                                        scenario.valid[index], start)
        position = np.array([scenario.x[index, start], scenario.y[index, start], scenario.z[index, start]])
        found = search_paths(lanes, graph, position, float(scenario.bbox_yaw[index, start]), track, track_yaw,
                             agent_settings)
        if found:
            chosen.append((int(index), found[0]))
    q = settings.points_per_path
    xyz = np.zeros((len(chosen), q, 3), np.float32)
    valid = np.zeros((len(chosen), q), bool)
    arc = np.zeros((len(chosen), q), np.float32)
    for row, (_, path) in enumerate(chosen):
        n = len(path.xyz)
        xyz[row, :n], valid[row, :n], arc[row, :n] = path.xyz, True, path.arc_length
    return dict(agent_path_object_index=np.array([i for i, _ in chosen], np.int64),
                agent_path_xyz=xyz, agent_path_valid=valid, agent_path_arc_length=arc)


def controllable_stats(scenarios: Iterable[Scenario]) -> ControllableStats:
    """How many scenarios have >= 1 controllable agent besides the SDC, and the mean count."""
    num, with_any, total = 0, 0, 0
    for scenario in scenarios:
        count = int(scenario.is_controllable.sum()) - int(scenario.is_controllable[scenario.sdc_index])
        num += 1
        with_any += count > 0
        total += count
    return ControllableStats(num, with_any, total / num if num else 0.0)

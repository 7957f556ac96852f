"""Fitting a scenario into the shard budget without losing what matters.

Objects: the SDC goes to slot 0, the rest are ordered by relevance (closest approach to the SDC
over the episode). When there are more objects than slots, the kept ones are chosen by priority:
the SDC, then WOMD's `tracks_to_predict`, then `objects_of_interest`, then relevance; the kept ones
stay in relevance order (so a scenario within budget is never reordered by its labels, and fitting
twice changes nothing). Roadgraph: when there are too many points,
keep those nearest the SDC trajectory (in their original order, so polylines stay contiguous).
Lights and lanes: nearest the SDC trajectory first.
"""

from __future__ import annotations

import numpy as np

from scenariomax.crop import distance_to_points, sdc_positions
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes

_PER_OBJECT = ("object_id", "object_type", "is_sdc", "tracks_to_predict", "objects_of_interest",
               "difficulty_level", "is_controllable")
_PER_OBJECT_STEP = ("x", "y", "z", "bbox_yaw", "length", "width", "height", "speed", "vel_yaw",
                    "velocity_x", "velocity_y", "timestamp_micros", "valid")
_PER_POINT = ("roadgraph_xyz", "roadgraph_dir", "roadgraph_type", "roadgraph_id", "roadgraph_valid",
              "roadgraph_speed_limit")
_PER_LIGHT = ("tl_state", "tl_valid", "tl_lane_id", "tl_x", "tl_y", "tl_z", "tl_inferred")
_PER_LANE = ("lane_id", "lane_valid", "lane_successors", "lane_predecessors", "lane_left_neighbors",
             "lane_right_neighbors")


def object_relevance_order(scenario: Scenario) -> np.ndarray:
    """Object indices, SDC first, then by closest approach to the SDC (never-present objects last)."""
    sdc = scenario.sdc_index
    both = scenario.valid & scenario.valid[sdc][None, :]
    dist = np.hypot(scenario.x - scenario.x[sdc], scenario.y - scenario.y[sdc])
    closest = np.where(both, dist, np.inf).min(axis=1)
    # Objects never valid together with the SDC: rank by distance to any SDC position, after the rest.
    anchors = sdc_positions(scenario)
    for index in np.flatnonzero(~np.isfinite(closest)):
        mask = scenario.valid[index]
        if mask.any():
            pts = np.stack([scenario.x[index, mask], scenario.y[index, mask]], axis=1)
            closest[index] = 1e6 + distance_to_points(pts, anchors).min()
        else:
            closest[index] = 1e12
    closest[sdc] = -1.0
    return np.argsort(closest, kind="stable")


def objects_to_keep(scenario: Scenario, num_slots: int) -> np.ndarray:
    """Indices of the objects that fill `num_slots`, in relevance order (SDC first). When they do not
    all fit, the SDC, `tracks_to_predict` and `objects_of_interest` are kept before the rest."""
    order = object_relevance_order(scenario)
    if len(order) <= num_slots:
        return order
    # lexsort: the last key is the primary one; False sorts first, so negate the flags.
    priority = np.lexsort((np.arange(len(order)), ~scenario.objects_of_interest[order],
                           ~scenario.tracks_to_predict[order], ~scenario.is_sdc[order]))
    kept = np.zeros(len(order), bool)
    kept[priority[:num_slots]] = True
    return order[kept]


def _mean_light_positions(scenario: Scenario) -> np.ndarray:
    """Mean valid stop point of each light; 1e9 for a light never valid (sorts last). -> (L, 2)"""
    count = scenario.tl_valid.sum(axis=1)
    xy = np.stack([np.where(scenario.tl_valid, scenario.tl_x, 0.0).sum(axis=1),
                   np.where(scenario.tl_valid, scenario.tl_y, 0.0).sum(axis=1)], -1).astype(np.float64)
    return np.where(count[:, None] > 0, xy / np.maximum(count, 1)[:, None], 1e9)


def _take(scenario: Scenario, names, index: np.ndarray, axis: int = 0) -> dict:
    return {name: np.take(getattr(scenario, name), index, axis=axis) for name in names}


def fit_to_budget(scenario: Scenario, sizes: Sizes) -> Scenario:
    """SDC in slot 0, objects by relevance (labelled ones kept first when over budget), every part cropped
    to the budget."""
    changes: dict = {}
    order = objects_to_keep(scenario, sizes.num_objects)
    if not np.array_equal(order, np.arange(scenario.num_objects)):
        changes.update(_take(scenario, _PER_OBJECT + _PER_OBJECT_STEP, order))
        if scenario.agent_path_object_index.size:
            remap = {int(old): new for new, old in enumerate(order)}
            kept = [i for i, obj in enumerate(scenario.agent_path_object_index) if int(obj) in remap]
            changes["agent_path_object_index"] = np.array(
                [remap[int(scenario.agent_path_object_index[i])] for i in kept], np.int64)
            for name in ("agent_path_xyz", "agent_path_valid", "agent_path_arc_length"):
                changes[name] = getattr(scenario, name)[kept]
    anchors = sdc_positions(scenario)[::5]
    num_points = scenario.roadgraph_xyz.shape[0]
    if num_points > sizes.num_roadgraph:
        dist = distance_to_points(scenario.roadgraph_xyz[:, :2].astype(np.float64), anchors)
        dist = np.where(scenario.roadgraph_valid, dist, np.inf)
        keep = np.sort(np.argpartition(dist, sizes.num_roadgraph - 1)[: sizes.num_roadgraph])
        changes.update(_take(scenario, _PER_POINT, keep))
    num_lights = scenario.tl_state.shape[0]
    if num_lights > sizes.num_lights:
        mean = _mean_light_positions(scenario)
        keep = np.sort(np.argsort(distance_to_points(mean, anchors), kind="stable")[: sizes.num_lights])
        changes.update(_take(scenario, _PER_LIGHT, keep))
    num_lanes = scenario.lane_id.shape[0]
    if num_lanes > sizes.num_lanes:
        rg_ids = changes.get("roadgraph_id", scenario.roadgraph_id)
        rg_xy = changes.get("roadgraph_xyz", scenario.roadgraph_xyz)[:, :2].astype(np.float64)
        lane_dist = np.full(num_lanes, np.inf)
        point_dist = distance_to_points(rg_xy, anchors)
        for row, lane in enumerate(scenario.lane_id):
            mask = rg_ids == lane
            if mask.any():
                lane_dist[row] = point_dist[mask].min()
        keep = np.sort(np.argsort(lane_dist, kind="stable")[: sizes.num_lanes])
        changes.update(_take(scenario, _PER_LANE, keep))
    if scenario.lane_successors.shape[1:] and scenario.lane_successors.shape[1] > sizes.num_lane_links:
        for name in _PER_LANE[2:]:
            changes[name] = changes.get(name, getattr(scenario, name))[:, : sizes.num_lane_links]
    return scenario.replace(**changes) if changes else scenario

"""Geometric checks of a scenario: road-edge signed distance, box overlaps, red-light crossings,
distance to the lane graph. Used by the generator to pick a clean SDC and by the tests."""

from __future__ import annotations

import numpy as np

from scenariomax.scenario import Scenario
from scenariomax.schema import OBJECT_TYPE_VEHICLE, ROAD_EDGE_TYPES, TL_STOP


def polyline_segments(xyz: np.ndarray, ids: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segments joining consecutive roadgraph points of the same feature. -> starts (m, 2), ends (m, 2)"""
    xy, ids = xyz[mask, :2].astype(np.float64), ids[mask]
    same = ids[1:] == ids[:-1]
    return xy[:-1][same], xy[1:][same]


def _nearest_segment(points: np.ndarray, starts: np.ndarray, ends: np.ndarray, chunk: int = 512):
    """Distance to, and index of, the nearest segment for each point. -> (n,), (n,)"""
    dist = np.empty(len(points))
    index = np.empty(len(points), np.int64)
    seg = ends - starts
    seg_len2 = np.maximum((seg ** 2).sum(-1), 1e-12)
    for lo in range(0, len(points), chunk):
        rel = points[lo:lo + chunk, None, :] - starts[None]  # (c, m, 2)
        t = np.clip((rel * seg[None]).sum(-1) / seg_len2[None], 0.0, 1.0)
        d = np.linalg.norm(rel - t[..., None] * seg[None], axis=-1)
        best = d.min(axis=1)
        # Ties (the nearest point is a vertex two segments share): the segment whose supporting
        # line is farthest from the point decides the side, which is right at convex and reflex corners.
        line = np.abs(seg[None, :, 0] * rel[..., 1] - seg[None, :, 1] * rel[..., 0]) / np.sqrt(seg_len2)[None]
        index[lo:lo + chunk] = np.where(d <= best[:, None] + 1e-9, line, -1.0).argmax(axis=1)
        dist[lo:lo + chunk] = best
    return dist, index


def road_edge_signed_distance(scenario: Scenario, points: np.ndarray) -> np.ndarray:
    """Signed distance of (n, 2) points to the road edges: negative on the road (edges have the
    drivable area on their left), positive off it. -> (n,)"""
    mask = scenario.roadgraph_valid & np.isin(scenario.roadgraph_type, ROAD_EDGE_TYPES)
    starts, ends = polyline_segments(scenario.roadgraph_xyz, scenario.roadgraph_id, mask)
    if len(starts) == 0:
        return np.full(len(points), -np.inf)
    dist, index = _nearest_segment(np.asarray(points, np.float64), starts, ends)
    seg, rel = ends[index] - starts[index], points - starts[index]
    cross = seg[:, 0] * rel[:, 1] - seg[:, 1] * rel[:, 0]
    return np.where(cross > 0, -dist, dist)


def box_corners(x, y, yaw, length, width) -> np.ndarray:
    """Corners of oriented boxes. (...,) -> (..., 4, 2)"""
    c, s = np.cos(yaw), np.sin(yaw)
    half_l, half_w = np.asarray(length) / 2, np.asarray(width) / 2
    local = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]], np.float64)
    dx = local[:, 0] * half_l[..., None]
    dy = local[:, 1] * half_w[..., None]
    return np.stack([x[..., None] + c[..., None] * dx - s[..., None] * dy,
                     y[..., None] + s[..., None] * dx + c[..., None] * dy], axis=-1)


def boxes_overlap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Separating-axis test for pairs of convex quadrilaterals. (k, 4, 2) x2 -> (k,) bool"""
    overlap = np.ones(len(a), bool)
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=1) - poly
        axes = np.stack([-edges[..., 1], edges[..., 0]], axis=-1)  # (k, 4, 2)
        proj_a = np.einsum("kad,kcd->kac", axes, a)
        proj_b = np.einsum("kad,kcd->kac", axes, b)
        separated = (proj_a.max(-1) < proj_b.min(-1)) | (proj_b.max(-1) < proj_a.min(-1))
        overlap &= ~separated.any(axis=1)
    return overlap


def overlaps_others(scenario: Scenario, obj: int, length: np.ndarray, width: np.ndarray) -> bool:
    """Whether object `obj` with the box `length`, `width` (T,) would overlap any other valid object's box at a step
    where both are valid."""
    valid = scenario.valid[obj]  # (T,)
    others, steps = np.nonzero(scenario.valid & valid[None])  # every (object, step) beside a valid `obj`
    keep = others != obj
    others, steps = others[keep], steps[keep]
    x, y, yaw = (np.asarray(a, np.float64) for a in (scenario.x, scenario.y, scenario.bbox_yaw))
    reach = (np.hypot(length[steps], width[steps]) + np.hypot(scenario.length[others, steps],
                                                              scenario.width[others, steps])) / 2
    near = np.hypot(x[others, steps] - x[obj, steps], y[others, steps] - y[obj, steps]) < reach
    others, steps = others[near], steps[near]
    mine = box_corners(x[obj, steps], y[obj, steps], yaw[obj, steps], length[steps], width[steps])  # (k, 4, 2)
    theirs = box_corners(x[others, steps], y[others, steps], yaw[others, steps], scenario.length[others, steps],
                         scenario.width[others, steps])
    return bool(boxes_overlap(mine, theirs).any())


def overlapping_vehicle_pairs(scenario: Scenario, types: tuple[int, ...] = (OBJECT_TYPE_VEHICLE,)
                              ) -> list[tuple[int, int, int]]:
    """(object a, object b, step) for every pair of valid objects of `types` whose boxes overlap."""
    found = []
    vehicles = np.flatnonzero(np.isin(scenario.object_type, types))
    for step in range(scenario.num_timesteps):
        idx = vehicles[scenario.valid[vehicles, step]]
        if len(idx) < 2:
            continue
        a, b = np.triu_indices(len(idx), 1)
        a, b = idx[a], idx[b]
        x, y = scenario.x[:, step].astype(np.float64), scenario.y[:, step].astype(np.float64)
        radius = np.hypot(scenario.length[:, step], scenario.width[:, step]) / 2
        close = np.hypot(x[a] - x[b], y[a] - y[b]) < radius[a] + radius[b]
        a, b = a[close], b[close]
        if len(a) == 0:
            continue
        corners = box_corners(x, y, scenario.bbox_yaw[:, step].astype(np.float64),
                              scenario.length[:, step].astype(np.float64), scenario.width[:, step].astype(np.float64))
        hit = boxes_overlap(corners[a], corners[b])
        found += [(int(i), int(j), step) for i, j in zip(a[hit], b[hit])]
    return found


def red_light_crossings(scenario: Scenario, obj: int, lane_half_width: float = 2.0) -> list[tuple[int, int]]:
    """(light, step) where the object's centre passes a stop point while that light is red (4)."""
    found = []
    lane_dir = {}
    lanes = scenario.roadgraph_id
    for light in range(scenario.tl_state.shape[0]):
        if not scenario.tl_valid[light].any():
            continue
        lane_id = int(scenario.tl_lane_id[light][scenario.tl_valid[light]][0])
        if lane_id not in lane_dir:
            points = scenario.roadgraph_xyz[lanes == lane_id, :2].astype(np.float64)
            if len(points) < 2:
                continue
            d = points[-1] - points[-2]
            lane_dir[lane_id] = d / np.linalg.norm(d)
        heading = lane_dir[lane_id]
        step_valid = scenario.valid[obj] & scenario.tl_valid[light]
        stop = np.stack([scenario.tl_x[light], scenario.tl_y[light]], -1).astype(np.float64)
        rel = np.stack([scenario.x[obj], scenario.y[obj]], -1).astype(np.float64) - stop
        along = rel @ heading
        lateral = np.abs(rel @ np.array([-heading[1], heading[0]]))
        for step in range(1, scenario.num_timesteps):
            if step_valid[step] and step_valid[step - 1] and along[step - 1] < 0 <= along[step] \
                    and lateral[step] < lane_half_width and TL_STOP in (scenario.tl_state[light, step],
                                                                         scenario.tl_state[light, step - 1]):
                found.append((light, step))
    return found


def lane_graph_distance(scenario: Scenario, obj: int) -> np.ndarray:
    """Distance of each valid position of `obj` to the lanes reachable (along successor links)
    from the lane nearest its first valid position. -> (k,)"""
    lane_mask = np.isin(scenario.roadgraph_id, scenario.lane_id[scenario.lane_valid]) & scenario.roadgraph_valid
    positions = np.stack([scenario.x[obj], scenario.y[obj]], -1)[scenario.valid[obj]].astype(np.float64)
    starts, ends = polyline_segments(scenario.roadgraph_xyz, scenario.roadgraph_id, lane_mask)
    seg_ids = scenario.roadgraph_id[lane_mask][:-1][
        scenario.roadgraph_id[lane_mask][1:] == scenario.roadgraph_id[lane_mask][:-1]]
    _, index = _nearest_segment(positions[:1], starts, ends)
    first_lane = int(seg_ids[index[0]])
    successors = {int(lane): [int(s) for s in row if s >= 0]
                  for lane, row in zip(scenario.lane_id, scenario.lane_successors)}
    reachable, todo = {first_lane}, [first_lane]
    while todo:
        for nxt in successors.get(todo.pop(), []):
            if nxt not in reachable:
                reachable.add(nxt)
                todo.append(nxt)
    keep = np.isin(seg_ids, list(reachable))
    dist, _ = _nearest_segment(positions, starts[keep], ends[keep])
    return dist

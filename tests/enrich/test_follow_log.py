"""Paths follow the log where the lane graph does not: lane changes without a link, driving between
lanes, leaving the lanes (SDC paths and per-agent paths)."""

from __future__ import annotations

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich import EnrichSettings, PathSettings, enrich_scenario, extract_lanes, search_paths
from scenariomax.enrich.geometry import arc_lengths, project_to_polyline
from scenariomax.enrich.lane_graph import LaneGraph
from scenariomax.enrich.paths import _covered_prefix
from scenariomax.enrich.roadgraph import LaneLinks, MapPolyline, lane_graph_arrays
from tests.enrich.scenes import CURRENT, NUM_STEPS, line, make_scenario, straight_xy, track

LANE = sch.RG_LANE_SURFACE_STREET
FAST = EnrichSettings(label_controllable=False, infer_lights=False)


def _smooth_shift(xy: np.ndarray, start: int, stop: int, dy: float) -> np.ndarray:
    """Shift y by `dy` between two steps (smoothstep), keeping the rest. (T, 2) -> (T, 2)"""
    u = np.clip((np.arange(len(xy)) - start) / (stop - start), 0.0, 1.0)
    out = xy.copy()
    out[:, 1] += dy * u * u * (3.0 - 2.0 * u)
    return out


def _unlinked_lanes() -> tuple[list[MapPolyline], dict]:
    """Lane 1 (y = 0, then lane 3 after x = 200) and lane 2 (y = 3.5) with explicit links that have no
    neighbours: the lane graph offers no lane change."""
    polylines = [MapPolyline(1, LANE, line((0, 0), (200, 0), 200)), MapPolyline(3, LANE, line((200, 0), (400, 0), 200)),
                 MapPolyline(2, LANE, line((0, 3.5), (400, 3.5), 400))]
    links = lane_graph_arrays([LaneLinks(1, successors=(3,)), LaneLinks(3, predecessors=(1,)), LaneLinks(2)])
    return polylines, links


def _coverage(path: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Distance of each logged position from the current step on to the path. -> (m,)"""
    return project_to_polyline(xy[CURRENT:], path)[0]


def _best(out) -> tuple[np.ndarray, np.ndarray]:
    valid = out.path_valid[0]
    return out.path_xyz[0][valid].astype(np.float64), out.path_lane_id[0][valid]


def test_lane_change_without_a_link_is_followed():
    polylines, links = _unlinked_lanes()
    xy = _smooth_shift(straight_xy(10, 10.0), 30, 60, 3.5)
    out = enrich_scenario(make_scenario(polylines, [track(xy)], **links), FAST)
    path, ids = _best(out)
    dist = _coverage(path, xy)
    assert out.path_on_route[0] and np.mean(dist <= 1.0) >= 0.95 and dist.max() < 0.6
    assert ids[0] == 1 and ids[-1] == 2  # starts on lane 1, carries on along lane 2 past the log
    assert out.path_valid[0].sum() == 300
    # The lane paths that stay on lane 1 remain, off route.
    assert not out.path_on_route[1:].any() and out.path_valid[1].any()


def test_driving_between_two_lanes_is_followed():
    polylines, links = _unlinked_lanes()
    xy = straight_xy(10, 10.0, y=1.75)  # astride the lane line, 1.75 m from both centres
    out = enrich_scenario(make_scenario(polylines, [track(xy)], **links), FAST)
    path, _ = _best(out)
    dist = _coverage(path, xy)
    assert out.path_on_route[0] and dist.max() < 0.1
    # Past the log's end the path blends into a lane and runs on along it.
    tail = path[-50:]
    assert np.allclose(np.abs(tail[:, 1] - 1.75), 1.75, atol=0.05)


def test_leaving_the_lanes_is_followed_then_continued_straight_on():
    # Along lane 1 to x = 40, then into a car park north of it (no lanes) where the log ends.
    xy = straight_xy(10, 8.0)
    xy = _smooth_shift(xy, 20, 50, 12.0)
    polylines = [MapPolyline(1, LANE, line((0, 0), (300, 0), 300))]
    out = enrich_scenario(make_scenario(polylines, [track(xy)]), FAST)
    path, ids = _best(out)
    dist = _coverage(path, xy)
    assert out.path_on_route[0] and np.mean(dist <= 1.0) >= 0.95 and dist.max() < 0.6
    assert ids[0] == 1
    # Past the log's end, 12 m from the lane: straight on along the last heading (east), no lane id.
    beyond = path[:, 0] > xy[-1, 0] + 5.0
    assert beyond.any() and np.allclose(path[beyond, 1], 12.0, atol=0.05) and (ids[beyond] == -1).all()


def test_swerve_off_the_lane_and_back_rejoins_the_lane_graph():
    xy = straight_xy(10, 10.0)
    xy = _smooth_shift(xy, 25, 35, 3.0)
    xy = _smooth_shift(xy, 45, 55, -3.0)  # around a parked car, back on lane 1 by step 55
    polylines = [MapPolyline(1, LANE, line((0, 0), (150, 0), 150)), MapPolyline(4, LANE, line((150, 0), (400, 0), 250))]
    out = enrich_scenario(make_scenario(polylines, [track(xy)]), FAST)
    path, ids = _best(out)
    dist = _coverage(path, xy)
    assert out.path_on_route[0] and dist.max() < 0.6
    assert list(dict.fromkeys(ids.tolist())) == [1, 4] and out.path_valid[0].sum() == 300
    np.testing.assert_allclose(path[path[:, 0] > 100, 1], 0.0, atol=1e-6)  # back on the lane centre


def test_lane_path_that_covers_the_log_is_left_unchanged():
    xy = straight_xy(10, 10.0, y=0.4)
    polylines = [MapPolyline(1, LANE, line((0, 0), (200, 0), 200))]
    scenario = make_scenario(polylines, [track(xy)])
    followed = enrich_scenario(scenario, FAST)
    plain = enrich_scenario(scenario, EnrichSettings(label_controllable=False, infer_lights=False,
                                                     paths=PathSettings(follow_log=False)))
    np.testing.assert_array_equal(followed.path_xyz, plain.path_xyz)
    np.testing.assert_array_equal(followed.path_on_route, plain.path_on_route)


def test_agent_path_follows_a_lane_change_without_a_link():
    polylines, links = _unlinked_lanes()
    agent_xy = _smooth_shift(straight_xy(40, 8.0), 30, 55, 3.5)
    objects = [track(straight_xy(10, 10.0)), track(agent_xy)]
    out = enrich_scenario(make_scenario(polylines, objects, **links), EnrichSettings(infer_lights=False))
    assert out.is_controllable.tolist() == [True, True] and out.agent_path_object_index.tolist() == [1]
    path = out.agent_path_xyz[0][out.agent_path_valid[0]].astype(np.float64)
    dist = _coverage(path, agent_xy)
    assert np.mean(dist <= 1.0) >= 0.95 and dist.max() < 0.6
    assert abs(path[-1, 1] - 3.5) < 0.05  # carries on along lane 2


def test_agent_path_follows_a_log_between_lanes():
    polylines, links = _unlinked_lanes()
    agent_xy = straight_xy(40, 8.0, y=1.6)
    objects = [track(straight_xy(10, 10.0)), track(agent_xy)]
    out = enrich_scenario(make_scenario(polylines, objects, **links), EnrichSettings(infer_lights=False))
    assert out.agent_path_object_index.tolist() == [1]
    path = out.agent_path_xyz[0][out.agent_path_valid[0]].astype(np.float64)
    assert _coverage(path, agent_xy).max() < 0.1


def test_stationary_sdc_off_the_lane_gets_a_path_from_its_position():
    xy = np.tile([[30.0, 1.5]], (NUM_STEPS, 1))  # parked 1.5 m beside the lane centre
    polylines = [MapPolyline(1, LANE, line((0, 0), (300, 0), 300))]
    out = enrich_scenario(make_scenario(polylines, [track(xy)]), FAST)
    path, ids = _best(out)
    assert out.path_on_route[0]
    np.testing.assert_allclose(path[0, :2], [30.0, 1.5], atol=1e-6)
    assert abs(path[-1, 1]) < 1e-6 and ids[-1] == 1  # blended into the lane ahead


def test_no_start_lane_still_means_no_path():
    lanes = extract_lanes(make_scenario([MapPolyline(1, LANE, line((0, 50), (100, 50)))],
                                        [track(straight_xy(10, 10.0))]))
    graph = LaneGraph(((),), ((),), ((),), ((),))
    assert search_paths(lanes, graph, np.array([10.0, 0.0, 0.0]), 0.0, straight_xy(10, 10.0)) == []


def test_covered_prefix_looks_near_the_last_foot_where_the_path_passes_twice():
    # The path runs east 20 m, loops back west 1 m north of itself, and east again 5 cm north of its start;
    # the log (4 cm north of the first leg) is nearest the third leg.
    path = np.vstack([line((0, 0), (20, 0), 21), line((20, 1), (0, 1), 21), line((0, 0.05), (40, 0.05), 41)])
    log = np.column_stack([np.linspace(0, 15, 16), np.full(16, 0.04)])
    dist, arc, _ = project_to_polyline(log, path)
    assert arc[0] > 40  # the nearest foot lies on the third leg
    covered, feet = _covered_prefix(log, arc_lengths(log), path, dist, arc, 1.0)
    assert covered == 16
    np.testing.assert_allclose(feet, log[:, 0], atol=1e-6)  # the first leg, in order


def _covered_prefix_one_by_one(track, travel, path, dist, arc, tolerance):
    """_covered_prefix as a plain loop over the positions (the reference its vectorised start must match)."""
    cum = arc_lengths(path)
    feet = np.zeros(len(track))
    prev_arc, prev_travel = 0.0, 0.0
    for j in range(len(track)):
        moved, near, foot = float(travel[j]), float(dist[j]), float(arc[j])
        low, high = prev_arc - 2.0, prev_arc + 1.5 * (moved - prev_travel) + 2.0
        if near <= tolerance and not low <= foot <= high:
            lo = max(int(np.searchsorted(cum, low)) - 1, 0)
            hi = min(int(np.searchsorted(cum, high)) + 1, len(cum))
            part = project_to_polyline(track[j:j + 1], path[lo:hi])
            near, foot = float(part[0][0]), float(part[1][0]) + float(cum[lo])
        if near > tolerance or not low <= foot <= high:
            return j, feet[:j]
        feet[j] = foot
        prev_arc, prev_travel = max(prev_arc, foot), moved
    return len(track), feet


def test_covered_prefix_is_the_loop_over_positions():
    rng = np.random.default_rng(3)
    loop = np.column_stack([30 * np.cos(np.linspace(0, 4 * np.pi, 400)), 30 * np.sin(np.linspace(0, 4 * np.pi, 400)),
                            np.zeros(400)])  # a path around the same circle twice
    paths = [line((0, 0), (80, 0), 81), loop, np.vstack([line((0, 0), (40, 0), 41), line((40, 0.5), (0, 0.5), 41)])]
    stops = []
    for path in paths:
        for _ in range(40):
            m = int(rng.integers(1, 60))
            along = np.cumsum(rng.uniform(0.0, 1.5, m)) + rng.uniform(0, 5)
            along += rng.choice([0.0, 1.0]) * rng.uniform(-2.6, 0.4, m)  # feet a little behind the last
            along = np.maximum(along, 0.0)
            track_xy = project_to_polyline(np.zeros((1, 2)), path)[2]  # a start on the path
            track_xy = np.vstack([track_xy, path[np.minimum(along.astype(int), len(path) - 1), :2]])[1:]
            track_xy = track_xy + rng.normal(0, rng.choice([0.1, 0.6, 2.0]), track_xy.shape)
            if rng.random() < 0.2:
                track_xy = track_xy[::-1].copy()  # backwards: feet out of order
            travel = arc_lengths(track_xy)
            dist, arc, _ = project_to_polyline(track_xy, path)
            want = _covered_prefix_one_by_one(track_xy, travel, path, dist, arc, 1.0)
            got = _covered_prefix(track_xy, travel, path, dist, arc, 1.0)
            assert got[0] == want[0]
            np.testing.assert_array_equal(got[1], want[1])
            stops.append(want[0] / m)
    assert min(stops) < 0.5 and max(stops) == 1.0  # both partly and wholly covered logs were tried

"""Controllable labels, agent paths and traffic-light inference on hand-built scenes."""

from __future__ import annotations

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich import EnrichSettings, controllable_stats, enrich_scenario
from scenariomax.enrich.roadgraph import MapPolyline
from tests.enrich.scenes import NUM_STEPS, line, make_scenario, straight_xy, track

LANE = sch.RG_LANE_SURFACE_STREET


def _road():
    return [MapPolyline(1, LANE, line((0, 0), (400, 0), 400)),
            MapPolyline(5, sch.RG_ROAD_EDGE_BOUNDARY, line((0, -2), (400, -2), 200)),
            MapPolyline(6, sch.RG_ROAD_EDGE_BOUNDARY, line((400, 5.5), (0, 5.5), 200))]


def test_controllable_labels_and_agent_paths():
    partial = np.ones(NUM_STEPS, bool)
    partial[60:] = False
    objects = [
        track(straight_xy(10, 10.0)),  # SDC
        track(straight_xy(40, 8.0)),  # moving on the lane: controllable
        track(np.tile([[60.0, 0.0]], (NUM_STEPS, 1))),  # parked on the lane
        track(straight_xy(30, 8.0), valid=partial),  # partial track
        track(straight_xy(20, 1.5, y=0.5), object_type=sch.OBJECT_TYPE_PEDESTRIAN),
        track(straight_xy(20, 8.0, y=-6.0)),  # beyond the road edge, 6 m from the lane
    ]
    out = enrich_scenario(make_scenario(_road(), objects), EnrichSettings(infer_lights=False))
    assert out.is_controllable.tolist() == [True, True, False, False, False, False]
    assert out.agent_path_object_index.tolist() == [1]
    assert out.agent_path_valid[0].sum() > 100 and np.allclose(out.agent_path_xyz[0, 0, :2], [48.0, 0.0], atol=1e-3)
    stats = controllable_stats([out, out.replace(is_controllable=out.is_controllable & False | out.is_sdc)])
    assert (stats.num_scenarios, stats.num_with_controllable, stats.mean_per_scenario) == (2, 1, 0.5)


def test_agent_path_slots_go_to_the_agents_nearest_the_sdc():
    sdc = track(straight_xy(150, 8.0))
    # far agents first in object order: a budget filled in object order would skip the SDC's neighbours
    starts = [290, 270, 250, 230, 160, 175, 130]
    objects = [sdc] + [track(straight_xy(x0, 8.0)) for x0 in starts]
    out = enrich_scenario(make_scenario(_road(), objects), EnrichSettings(infer_lights=False, num_agent_paths=3))
    assert out.is_controllable[1:].all()
    assert out.agent_path_object_index.tolist() == [5, 7, 6]  # 10 m, 20 m, 25 m from the SDC


def _light_scene(logged_state: int):
    """Lane 1 runs east to a stop point at x=50. Car 1 waits at x=45 until step 40, then drives
    through; car 2 crosses north-bound at x=60 during steps 0-40 (cross traffic)."""
    waiting = np.tile([[45.0, 0.0]], (NUM_STEPS, 1))
    waiting[41:, 0] = 45.0 + 0.5 * 0.5 * (np.arange(50) * 0.1 * 10) ** 2 / 10  # accelerating east
    cross = np.column_stack([np.full(NUM_STEPS, 60.0), -20 + 10.0 * 0.1 * np.arange(NUM_STEPS)])
    objects = [track(straight_xy(-60, 0.0)) , track(waiting), track(cross)]
    objects[0]["yaw"][:] = 0.0
    num_steps = NUM_STEPS
    lights = dict(tl_state=np.zeros((1, num_steps), np.int64), tl_valid=np.zeros((1, num_steps), bool),
                  tl_lane_id=np.full((1, num_steps), 1), tl_x=np.full((1, num_steps), 50.0),
                  tl_y=np.zeros((1, num_steps)), tl_z=np.zeros((1, num_steps)))
    lights["tl_state"][0, 0], lights["tl_valid"][0, 0] = logged_state, True
    polylines = [MapPolyline(1, LANE, line((-100, 0), (50, 0), 300)),
                 MapPolyline(2, LANE, line((50, 0), (200, 0), 300)),
                 MapPolyline(3, LANE, line((60, -60), (60, 60), 240))]
    return make_scenario(polylines, objects, **lights)


def test_light_inferred_red_while_queued_and_green_when_crossing():
    scenario = _light_scene(logged_state=sch.TL_CAUTION)
    out = enrich_scenario(scenario, EnrichSettings(label_controllable=False))
    state, inferred = out.tl_state[0], out.tl_inferred[0]
    assert state[0] == sch.TL_CAUTION and not inferred[0]  # logged state kept
    assert (state[1:30] == sch.TL_STOP).all() and inferred[1:30].all()
    crossing = int(np.argmax(out.x[1] >= 50.0))
    assert 41 < crossing < 70
    assert state[crossing] == sch.TL_GO and inferred[crossing]
    assert out.tl_valid[0, crossing] and out.tl_lane_id[0, crossing] == 1
    assert not inferred[crossing + 30:].any() and (state[crossing + 30:] == 0).all()  # no evidence: unknown


def test_light_without_lane_or_evidence_stays_unknown():
    scenario = _light_scene(logged_state=sch.TL_GO)
    scenario = scenario.replace(tl_lane_id=np.full_like(scenario.tl_lane_id, -1))
    out = enrich_scenario(scenario, EnrichSettings(label_controllable=False))
    assert not out.tl_inferred.any() and out.tl_valid[0].sum() == 1


def _one_light_evidence(scenario, stop, direction, settings, motion):
    """The evidence of one light, written step by step as before the lights were batched (the reference)."""
    from scenariomax.enrich.traffic_lights import _fill_gaps

    rel_x, rel_y = motion.x - stop[0], motion.y - stop[1]
    along = rel_x * direction[0] + rel_y * direction[1]
    lateral = np.abs(rel_x * direction[1] - rel_y * direction[0])
    heading_cos = motion.cos_yaw * direction[0] + motion.sin_yaw * direction[1]
    on_lane = motion.valid & (lateral <= settings.lane_halfwidth_m) & (heading_cos > np.cos(np.pi / 4))
    crossed = on_lane[:, 1:] & on_lane[:, :-1] & (along[:, :-1] < 0) & (along[:, 1:] >= 0)
    green = np.zeros(scenario.num_timesteps, bool)
    for step in np.flatnonzero(crossed.any(axis=0)) + 1:
        green[max(step - settings.green_window, 0):step + settings.green_window + 1] = True
    queued = (on_lane & (along < 0) & (along >= -settings.queue_distance_m)
              & (motion.speed < settings.stopped_speed_mps)).any(0)
    crossing = (motion.valid & (np.hypot(rel_x, rel_y) <= settings.cross_radius_m)
                & (motion.speed > settings.cross_speed_mps) & (np.abs(heading_cos) < 0.5))
    red = queued & crossing.any(axis=0)
    green, red = _fill_gaps(green, settings.max_gap_steps), _fill_gaps(red, settings.max_gap_steps)
    return green & ~(green & red), red & ~(green & red)


def _one_track_moves(x, y, settings):
    """Whether one track moves, written as before the tracks were batched (the reference)."""
    from scenariomax.enrich.controllable import STEPS_PER_SECOND

    xy = np.stack([x, y], 1).astype(np.float64)
    travel = np.linalg.norm(xy - xy[0], axis=1).max(initial=0.0)
    window = STEPS_PER_SECOND
    speed = 0.0
    if len(xy) > window:
        speed = np.linalg.norm(xy[window:] - xy[:-window], axis=1).max() * STEPS_PER_SECOND / window
    return bool(travel > settings.min_travel_m or speed > settings.min_speed_mps)


def test_light_evidence_reads_only_rows_that_can_count():
    """vehicle_motion keeps the vehicles valid at some step; the evidence is the one read from every object."""
    from scenariomax.enrich.traffic_lights import Motion, light_evidence, vehicle_motion

    scenario = _light_scene(logged_state=sch.TL_UNKNOWN)
    kinds = scenario.object_type.copy()
    kinds[::2] = sch.OBJECT_TYPE_PEDESTRIAN  # rows that never count, between rows that do
    scenario = scenario.replace(object_type=kinds)
    vehicles = scenario.object_type == sch.OBJECT_TYPE_VEHICLE
    every_row = Motion(scenario.valid & vehicles[:, None], np.cos(scenario.bbox_yaw), np.sin(scenario.bbox_yaw),
                       np.hypot(scenario.velocity_x, scenario.velocity_y), scenario.x, scenario.y)
    assert len(vehicle_motion(scenario).x) < scenario.num_objects
    for stop, direction in (((50.0, 0.0), (1.0, 0.0)), ((60.0, -5.0), (0.0, 1.0))):
        got = light_evidence(scenario, np.array([*stop, 0.0]), np.array(direction))
        want = light_evidence(scenario, np.array([*stop, 0.0]), np.array(direction), motion=every_row)
        for g, w in zip(got, want):
            np.testing.assert_array_equal(g, w)


def test_evidence_of_many_lights_is_each_lights_own():
    """with_inferred_lights reads the evidence of all its lights in one pass: the same as one light at a time."""
    from scenariomax.enrich.traffic_lights import LightSettings, _evidence_of_lights, vehicle_motion

    scenario = _light_scene(logged_state=sch.TL_UNKNOWN)
    stops = np.array([[50.0, 0.0, 0.0], [60.0, -5.0, 1.0], [50.3, 0.2, 0.0], [-500.0, 0.0, 0.0]])
    directions = np.array([[1.0, 0.0], [0.0, 1.0], [np.cos(0.1), np.sin(0.1)], [1.0, 0.0]])
    settings = LightSettings(max_gap_steps=4)
    greens, reds = _evidence_of_lights(scenario.num_timesteps, stops, directions, settings, vehicle_motion(scenario))
    for stop, direction, green, red in zip(stops, directions, greens, reds):
        want_green, want_red = _one_light_evidence(scenario, stop, direction, settings, vehicle_motion(scenario))
        np.testing.assert_array_equal(green, want_green)
        np.testing.assert_array_equal(red, want_red)
    assert greens[0].any() and reds[0].any() and greens[1].any() and not (greens[3].any() or reds[3].any())
    empty = _evidence_of_lights(scenario.num_timesteps, np.zeros((0, 3)), np.zeros((0, 2)), settings,
                                vehicle_motion(scenario))
    assert [array.shape for array in empty] == [(0, scenario.num_timesteps)] * 2


def test_controllable_mask_of_all_vehicles_at_once_is_one_by_one():
    """controllable_mask tests every moving vehicle in one pass: the labels of the per-vehicle loop."""
    from scipy.spatial import cKDTree

    from scenariomax.enrich.controllable import (
        ControllableSettings,
        _moving_rows,
        _on_road,
        controllable_mask,
    )
    from scenariomax.enrich.lanes import extract_lanes
    from scenariomax.enrich.orientation import with_edges_oriented

    rng = np.random.default_rng(4)
    objects = [track(straight_xy(10, 10.0))]
    for _ in range(14):  # on the lane, beside it, beyond an edge, parked, crawling
        objects.append(track(straight_xy(rng.uniform(0, 300), rng.choice([0.0, 0.02, 0.3, 8.0]),
                                         y=rng.choice([0.0, 1.0, -4.0, 6.5]))))
    scenario = make_scenario(_road(), objects)
    lanes = extract_lanes(scenario)
    scenario = with_edges_oriented(scenario, lanes)
    settings = ControllableSettings()
    got = controllable_mask(scenario, lanes, settings)
    np.testing.assert_array_equal(_moving_rows(scenario.x, scenario.y, settings),
                                  [_one_track_moves(x, y, settings) for x, y in zip(scenario.x, scenario.y)])
    edges = np.isin(scenario.roadgraph_type, sch.ROAD_EDGE_TYPES) & scenario.roadgraph_valid
    edge_xy = scenario.roadgraph_xyz[edges, :2].astype(np.float64)
    edge_dir = scenario.roadgraph_dir[edges, :2].astype(np.float64)
    want = np.zeros(scenario.num_objects, bool)
    for index in range(scenario.num_objects):
        if _one_track_moves(scenario.x[index], scenario.y[index], settings):
            xy = np.stack([scenario.x[index], scenario.y[index]], 1).astype(np.float64)
            want[index] = _on_road(scenario, lanes, xy, cKDTree(edge_xy), edge_xy, edge_dir, settings).all()
    want[scenario.sdc_index] = True
    np.testing.assert_array_equal(got, want)
    assert 1 < got.sum() < scenario.num_objects  # both labels occur

"""Difficulty signals on hand-built scenes, the documented score and levels, and the per-bucket report."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import scenariomax
from scenariomax.enrich.roadgraph import LaneLinks, MapPolyline, lane_graph_arrays, polylines_to_roadgraph
from scenariomax.schema import (
    OBJECT_TYPE_CYCLIST,
    OBJECT_TYPE_PEDESTRIAN,
    RG_LANE_SURFACE_STREET,
    RG_ROAD_EDGE_BOUNDARY,
)
from tests.integration_sim.conftest import DT, NUM_STEPS, cruising_scenario, road_scenario
from tests.policies.scenes import CURVE_RADIUS, curve_scenario, empty_road_scenario, red_light_scenario
from vmax_sim.evaluation.difficulty import (
    DifficultySignals,
    bucket_rows,
    difficulty_score,
    distance_to_polyline,
    format_difficulty_markdown,
    max_curvature,
    scenario_difficulty,
    signal_buckets,
)


def _with_object(scenario: scenariomax.Scenario, object_type: int, x: float, y: float) -> scenariomax.Scenario:
    """`scenario` plus one object standing still at (x, y) for the whole log."""
    ones = np.ones((1, scenario.num_timesteps), np.float32)

    def add(name, row):
        return np.concatenate([getattr(scenario, name), row.astype(getattr(scenario, name).dtype)])

    return dataclasses.replace(
        scenario, object_id=add("object_id", np.array([999])), object_type=add("object_type", np.array([object_type])),
        is_sdc=add("is_sdc", np.array([False])), x=add("x", x * ones), y=add("y", y * ones), z=add("z", 0 * ones),
        bbox_yaw=add("bbox_yaw", 0 * ones), length=add("length", 0.6 * ones), width=add("width", 0.6 * ones),
        height=add("height", 1.7 * ones), velocity_x=add("velocity_x", 0 * ones),
        velocity_y=add("velocity_y", 0 * ones),
        valid=add("valid", ones.astype(bool)), speed=None, vel_yaw=None, timestamp_micros=None,
        tracks_to_predict=None, objects_of_interest=None, difficulty_level=None, is_controllable=None)


def test_a_straight_empty_road_is_easy():
    signals = scenario_difficulty(empty_road_scenario())
    assert signals.num_interacting == 0 and signals.num_vru_near_path == 0
    assert not signals.is_intersection and not signals.has_traffic_light
    assert signals.max_curvature == pytest.approx(0.0, abs=1e-6)
    assert signals.sdc_speed == pytest.approx(5.0, abs=1e-3) and signals.num_lane_changes == 0
    assert signals.score == 0 and signals.level == "easy"


def test_a_pedestrian_near_the_path_is_a_vru_signal_and_not_easy():
    # 2.5 m beside the lane the SDC drives along, 40 m ahead (the SDC covers 5 m/s x 8 s = 40 m, +10 m margin)
    signals = scenario_difficulty(_with_object(empty_road_scenario(), OBJECT_TYPE_PEDESTRIAN, 40.0, 2.5))
    assert signals.num_vru_near_path == 1 and signals.num_interacting == 1
    assert signals.score == 1 + 2 and signals.level == "medium"
    # the same pedestrian 30 m off the road, or behind the SDC's start, does not count
    far = scenario_difficulty(_with_object(empty_road_scenario(), OBJECT_TYPE_PEDESTRIAN, 40.0, 30.0))
    behind = scenario_difficulty(_with_object(empty_road_scenario(), OBJECT_TYPE_CYCLIST, -30.0, 0.0))
    assert far.level == "easy" and behind.num_vru_near_path == 0 and behind.num_interacting == 0


def test_cars_on_the_path_interact_and_a_red_light_is_an_intersection():
    cruise = scenario_difficulty(cruising_scenario())  # two cars ahead in the SDC's lane, 10 m/s
    assert cruise.num_interacting == 2 and cruise.sdc_speed == pytest.approx(10.0, abs=1e-3)
    assert cruise.score == 1 + 1 and cruise.level == "easy"  # 1-3 interacting objects, fast
    light = scenario_difficulty(red_light_scenario())  # stop point at x = 50 m on the SDC's lane
    assert light.has_traffic_light and light.is_intersection


def test_curvature_of_the_bend():
    signals = scenario_difficulty(curve_scenario())
    assert signals.max_curvature == pytest.approx(1 / CURVE_RADIUS, rel=0.05)
    assert dict(signal_buckets(signals))["path curvature"] == "curved"
    assert max_curvature(np.stack([20 * np.cos(t := np.linspace(0, 3, 200)), 20 * np.sin(t)], 1)) == pytest.approx(
        0.05, rel=0.02)
    assert max_curvature(np.array([[0.0, 0.0], [100.0, 0.0]])) == 0.0


def _two_lane_scenario(change: bool) -> scenariomax.Scenario:
    """Two east-bound lanes (y = 0, y = 3.5); the SDC changes to the left one between 3 s and 5 s when `change`."""
    road = polylines_to_roadgraph([
        MapPolyline(1, RG_LANE_SURFACE_STREET, np.array([[-50, 0, 0], [400, 0, 0]], float), speed_limit=13.4),
        MapPolyline(4, RG_LANE_SURFACE_STREET, np.array([[-50, 3.5, 0], [400, 3.5, 0]], float), speed_limit=13.4),
        MapPolyline(2, RG_ROAD_EDGE_BOUNDARY, np.array([[-50, -2, 0], [400, -2, 0]], float)),
        MapPolyline(3, RG_ROAD_EDGE_BOUNDARY, np.array([[400, 5.5, 0], [-50, 5.5, 0]], float)),
    ])
    time = np.arange(NUM_STEPS) * DT
    xs = (8.0 * time)[None]
    scenario = road_scenario("lanes", xs, np.full_like(xs, 8.0))
    y = np.where(change, 3.5 * np.clip((time - 3.0) / 2.0, 0.0, 1.0), 0.0)[None]
    yaw = np.arctan2(np.gradient(y[0], DT), 8.0)[None]
    return dataclasses.replace(scenario, y=y.astype(np.float32), bbox_yaw=yaw.astype(np.float32),
                               **road, **lane_graph_arrays([LaneLinks(1), LaneLinks(4)]))


def test_lane_changes_are_counted_and_successor_lanes_are_not():
    assert scenario_difficulty(_two_lane_scenario(change=True)).num_lane_changes == 1
    assert scenario_difficulty(_two_lane_scenario(change=False)).num_lane_changes == 0
    # one lane cut in two (lane 5 succeeds lane 1 at x = 30 m): the SDC stays in its lane
    road = polylines_to_roadgraph([
        MapPolyline(1, RG_LANE_SURFACE_STREET, np.array([[-50, 0, 0], [30, 0, 0]], float)),
        MapPolyline(5, RG_LANE_SURFACE_STREET, np.array([[30, 0, 0], [400, 0, 0]], float)),
    ])
    split = dataclasses.replace(empty_road_scenario(), **road, **lane_graph_arrays([LaneLinks(1, (5,)), LaneLinks(5)]))
    assert scenario_difficulty(split).num_lane_changes == 0


def test_score_levels_and_geometry_by_hand():
    assert difficulty_score(0, False, 0.0, 0.0, 0, 0) == 0
    assert difficulty_score(5, True, 0.03, 12.0, 3, 1) == 2 + 1 + 1 + 1 + 2 + 2
    assert difficulty_score(9, True, 0.2, 20.0, 2, 4) == 11  # the maximum
    assert distance_to_polyline(np.array([[5.0, 2.0], [-3.0, 4.0], [12.0, 0.0]]),
                                np.array([[0.0, 0.0], [10.0, 0.0]])) == pytest.approx([2.0, 5.0, 2.0])


def _signals(level: str, vru: int = 0) -> DifficultySignals:
    return DifficultySignals(num_interacting=0, num_vru_near_path=vru, has_traffic_light=False, is_intersection=False,
                             max_curvature=0.0, sdc_speed=3.0, num_lane_changes=0, score=0, level=level)


def test_accuracy_and_vmax_per_bucket():
    signals = [_signals("easy"), _signals("easy"), _signals("hard", vru=1)]
    episodes = {"accurate": np.array([1.0, 1.0, 0.0]), "vmax_score": np.array([0.9, 0.7, 0.0])}
    other = {"accurate": np.array([1.0, 0.0, 1.0]), "vmax_score": np.array([1.0, 0.0, 0.5])}
    rows = {(r.group, r.bucket): r.cells for r in bucket_rows([episodes, other], [signals, signals])}
    assert rows[("difficulty", "easy")][0] == (2, 1.0, pytest.approx(0.8))
    assert rows[("difficulty", "easy")][1] == (2, 0.5, 0.5)
    assert rows[("difficulty", "hard")][0] == (1, 0.0, 0.0)
    assert rows[("VRU near path", "1+")][1] == (1, 1.0, 0.5)
    count, accuracy, vmax = rows[("difficulty", "medium")][0]
    assert count == 0 and math.isnan(accuracy) and math.isnan(vmax)
    lines = format_difficulty_markdown(["a", "b"], bucket_rows([episodes, other], [signals, signals])).splitlines()
    assert lines[0] == "| Group | Bucket | Episodes | a accuracy (%) | a V-Max (%) | b accuracy (%) | b V-Max (%) |"
    assert "| difficulty | easy | 2 | 100.00 | 80.00 | 50.00 | 50.00 |" in lines
    assert "| difficulty | medium | 0 | n/a | n/a | n/a | n/a |" in lines
    with pytest.raises(ValueError, match="3 scenarios tagged but 2 episodes"):
        bucket_rows([{"accurate": np.ones(2), "vmax_score": np.ones(2)}], [signals])


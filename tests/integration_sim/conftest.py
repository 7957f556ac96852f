"""Tiny hand-made scenarios for the integration tests, written as real shards."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import scenariomax
from scenariomax.enrich.roadgraph import LaneLinks, MapPolyline, lane_graph_arrays, polylines_to_roadgraph
from scenariomax.schema import OBJECT_TYPE_VEHICLE, RG_LANE_SURFACE_STREET, RG_ROAD_EDGE_BOUNDARY, TL_GO, Sizes
from vmax_sim.data import DataConfig

NUM_STEPS = 91
DT = 0.1
SMALL_SIZES = Sizes(num_objects=8, num_roadgraph=2000, num_lights=4, num_paths=2, num_points_per_path=300,
                    num_lanes=8, num_lane_links=2, num_agent_paths=2)
REALDATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata"

# braking scenario: hand-worked numbers used by the tests
CAR_AHEAD_X = 40.0  # stopped car's centre; its rear bumper is at 40 - 2.25 = 37.75 m
BRAKE_START_STEP = 10  # the SDC drives 10 m/s until t = 1 s (x = 10 m), then brakes at 2.5 m/s^2 to x = 30 m


def _straight_road(length: float = 300.0) -> dict:
    """One east-bound lane along y = 0 (13.4 m/s limit) with road edges at y = -2 and y = +5.5."""
    return polylines_to_roadgraph([
        MapPolyline(1, RG_LANE_SURFACE_STREET, np.array([[-50, 0, 0], [length, 0, 0]], float), speed_limit=13.4),
        MapPolyline(2, RG_ROAD_EDGE_BOUNDARY, np.array([[-50, -2, 0], [length, -2, 0]], float)),
        MapPolyline(3, RG_ROAD_EDGE_BOUNDARY, np.array([[length, 5.5, 0], [-50, 5.5, 0]], float)),
    ])


def road_scenario(scenario_id: str, xs: np.ndarray, speeds: np.ndarray) -> scenariomax.Scenario:
    """Vehicles 4.5 x 2 m on the lane at y = 0, heading east. xs, speeds (N, T); the SDC is slot 0."""
    n, t = xs.shape
    ones = np.ones((n, t), np.float32)
    path_x = np.arange(-40.0, 260.0, 1.0)
    path_xyz = np.stack([path_x, 0 * path_x, 0 * path_x], axis=1)[None]
    return scenariomax.Scenario(
        scenario_id=scenario_id, object_id=np.arange(n) + 100, object_type=np.full(n, OBJECT_TYPE_VEHICLE),
        is_sdc=np.arange(n) == 0, x=xs, y=0 * ones, z=0 * ones, bbox_yaw=0 * ones,
        length=4.5 * ones, width=2.0 * ones, height=1.6 * ones, velocity_x=speeds, velocity_y=0 * ones,
        valid=ones.astype(bool),
        tl_state=np.full((1, t), TL_GO), tl_valid=np.ones((1, t), bool), tl_lane_id=np.ones((1, t)),
        tl_x=np.full((1, t), 200.0), tl_y=np.zeros((1, t)), tl_z=np.zeros((1, t)),
        path_xyz=path_xyz, path_valid=np.ones((1, len(path_x)), bool), path_lane_id=np.ones((1, len(path_x))),
        path_arc_length=(path_x - path_x[0])[None], path_on_route=np.array([True]),
        source_dataset="test", **_straight_road(), **lane_graph_arrays([LaneLinks(1)]),
    )


def cruising_scenario(scenario_id: str = "cruise", speed: float = 10.0) -> scenariomax.Scenario:
    """The SDC and two cars 20 m apart, all at a constant `speed`."""
    time = np.arange(NUM_STEPS) * DT
    xs = np.stack([20.0 * i + speed * time for i in range(3)])
    return road_scenario(scenario_id, xs, np.full_like(xs, speed))


def braking_scenario(scenario_id: str = "brake") -> scenariomax.Scenario:
    """The logged SDC brakes (10 m/s, -2.5 m/s^2 from t = 1 s) and stops at x = 30 m behind a car
    stopped at x = 40 m; a driver keeping 10 m/s hits it."""
    time = np.arange(NUM_STEPS) * DT
    after = np.clip(time - BRAKE_START_STEP * DT, 0.0, 4.0)  # braking lasts 4 s
    sdc_x = 10.0 * np.minimum(time, 1.0) + 10.0 * after - 1.25 * after**2
    sdc_v = np.where(time < 1.0, 10.0, 10.0 - 2.5 * after)
    xs = np.stack([sdc_x, np.full(NUM_STEPS, CAR_AHEAD_X)])
    return road_scenario(scenario_id, xs, np.stack([sdc_v, np.zeros(NUM_STEPS)]))


def small_data_config(path, **changes) -> DataConfig:
    values = {"path": str(path), "batch_size": 2, "num_objects": 8, "num_roadgraph_points": 1000, "num_paths": 2,
              "num_points_per_path": 300, "max_num_lights": 4, "prefetch": 0}
    values.update(changes)
    return DataConfig(**values)


@pytest.fixture(scope="session")
def road_shards(tmp_path_factory) -> Path:
    """Shards holding: cruise, brake, cruise at 8 m/s (in this order)."""
    out = tmp_path_factory.mktemp("road_shards")
    scenarios = [cruising_scenario("cruise"), braking_scenario("brake"), cruising_scenario("cruise-slow", 8.0)]
    scenariomax.write_shards(scenarios, out, sizes=SMALL_SIZES)
    return out

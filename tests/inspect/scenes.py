"""Hand-made scenarios with hand-computable statistics, shared by the inspect/validate/render tests.

The scene: a straight two-lane east-bound road from x=0 to x=110 (points every metre), a broken
white line between the lanes, two road edges, a crosswalk, a stop sign; three vehicles (the SDC in
slot 0) and a pedestrian; one traffic light; two SDC paths (one on route).
"""

from __future__ import annotations

import numpy as np

from scenariomax import Scenario, Sizes
from scenariomax import schema as sch

SIZES = Sizes(num_objects=8, num_roadgraph=600, num_lights=4, num_paths=3, num_points_per_path=50,
              num_lanes=4, num_lane_links=2, num_agent_paths=2)
T = 91
ROAD_X = np.arange(0.0, 111.0)  # 111 points per straight feature

# Hand-computed facts about `make_scenario(...)` -------------------------------------------------
NUM_LANE_POINTS = 2 * 111
NUM_WHITE_POINTS = 111
NUM_EDGE_POINTS = 2 * 111
NUM_CROSSWALK_POINTS = 5
NUM_STOP_SIGN_POINTS = 1
NUM_ROADGRAPH_POINTS = 222 + 111 + 222 + 5 + 1  # 561
# SDC speed: 10 m/s for steps 0..50, 12 m/s for steps 51..90.
SDC_SPEED_MEAN = (51 * 10.0 + 40 * 12.0) / 91  # 10.879...
SDC_SPEED_MAX = 12.0
SDC_DISTANCE_M = 0.1 * (50 * 10.0 + 40 * 12.0)  # 98 m: x[t] = x[t-1] + 0.1 * v[t]
NUM_VALID_OBJECT_STEPS = 91 + 91 + 46 + 20  # SDC, vehicle 2, parked vehicle (0..45), pedestrian (0..19)
LIGHT_STOP_STEPS, LIGHT_GO_STEPS = 30, 61


def _line(x: np.ndarray, y: float) -> np.ndarray:
    return np.stack([x, np.full_like(x, y), np.zeros_like(x)], axis=-1)


def _roadgraph() -> dict:
    crosswalk = np.array([[80, -1.75, 0], [84, -1.75, 0], [84, 5.25, 0], [80, 5.25, 0], [80, -1.75, 0]], float)
    parts = [  # (xyz, type, id)
        (_line(ROAD_X, 0.0), sch.RG_LANE_SURFACE_STREET, 1),
        (_line(ROAD_X, 3.5), sch.RG_LANE_SURFACE_STREET, 2),
        (_line(ROAD_X, 1.75), sch.RG_BROKEN_SINGLE_WHITE, 10),
        (_line(ROAD_X, -1.75), sch.RG_ROAD_EDGE_BOUNDARY, 20),
        (_line(ROAD_X[::-1], 5.25), sch.RG_ROAD_EDGE_BOUNDARY, 21),
        (crosswalk, sch.RG_CROSSWALK, 30),
        (np.array([[98.0, -1.0, 0.0]]), sch.RG_STOP_SIGN, 40),
    ]
    xyz = np.concatenate([p[0] for p in parts]).astype(np.float32)
    dirs = np.concatenate([_directions(p[0]) for p in parts]).astype(np.float32)
    return {
        "roadgraph_xyz": xyz, "roadgraph_dir": dirs,
        "roadgraph_type": np.concatenate([np.full(len(p[0]), p[1]) for p in parts]),
        "roadgraph_id": np.concatenate([np.full(len(p[0]), p[2]) for p in parts]),
        "roadgraph_valid": np.ones(len(xyz), bool),
    }


def _directions(xyz: np.ndarray) -> np.ndarray:
    out = np.zeros_like(xyz)
    diff = np.diff(xyz, axis=0)
    out[:-1] = diff / np.linalg.norm(diff, axis=1, keepdims=True)
    return out


def _objects() -> dict:
    n = 4
    t = np.arange(T)
    sdc_speed = np.where(t <= 50, 10.0, 12.0)
    sdc_x = 5.0 + np.concatenate([[0.0], np.cumsum(0.1 * sdc_speed[1:])])
    x = np.stack([sdc_x, 2.0 + 0.5 * t, np.full(T, 40.0), np.full(T, 90.0)])  # vehicle 2 at 5 m/s
    y = np.stack([np.zeros(T), np.full(T, 3.5), np.full(T, -1.0), 2.0 + 0.14 * t])  # pedestrian crossing north
    velocity_x = np.stack([sdc_speed, np.full(T, 5.0), np.zeros(T), np.zeros(T)])
    velocity_y = np.stack([np.zeros(T), np.zeros(T), np.zeros(T), np.full(T, 1.4)])
    valid = np.stack([t >= 0, t >= 0, t <= 45, t < 20])
    yaw = np.stack([np.zeros(T), np.zeros(T), np.zeros(T), np.full(T, np.pi / 2)])
    size = np.array([[4.8, 2.0], [4.5, 1.9], [4.2, 1.8], [0.6, 0.6]])
    return {
        "object_id": np.array([7, 11, 12, 13]),
        "object_type": np.array([sch.OBJECT_TYPE_VEHICLE] * 3 + [sch.OBJECT_TYPE_PEDESTRIAN]),
        "is_sdc": np.array([True, False, False, False]),
        "x": np.where(valid, x, -1), "y": np.where(valid, y, -1), "z": np.zeros((n, T)),
        "bbox_yaw": np.where(valid, yaw, -1),
        "length": np.where(valid, size[:, :1], -1), "width": np.where(valid, size[:, 1:], -1),
        "height": np.where(valid, 1.5, -1),
        "velocity_x": np.where(valid, velocity_x, -1), "velocity_y": np.where(valid, velocity_y, -1),
        "valid": valid,
    }


def _light() -> dict:
    t = np.arange(T)
    return {
        "tl_state": np.where(t < LIGHT_STOP_STEPS, sch.TL_STOP, sch.TL_GO)[None, :],
        "tl_valid": np.ones((1, T), bool),
        "tl_lane_id": np.ones((1, T)),
        "tl_x": np.full((1, T), 100.0), "tl_y": np.zeros((1, T)), "tl_z": np.zeros((1, T)),
    }


def _paths() -> dict:
    xs = np.linspace(5.0, 104.0, 50)
    path_xyz = np.stack([_line(xs, 0.0), _line(xs, 3.5)]).astype(np.float32)  # (2, 50, 3)
    return {
        "path_xyz": path_xyz, "path_valid": np.ones((2, 50), bool),
        "path_lane_id": np.stack([np.full(50, 1), np.full(50, 2)]),
        "path_arc_length": np.stack([xs - 5.0, xs - 5.0]),
        "path_on_route": np.array([True, False]),
    }


def make_scenario(scenario_id: str = "scene-a", *, with_lights: bool = True, with_paths: bool = True,
                  with_controllable: bool = True) -> Scenario:
    extras = {}
    if with_lights:
        extras.update(_light())
    if with_paths:
        extras.update(_paths())
    if with_controllable:
        extras["is_controllable"] = np.array([False, True, False, False])
    return Scenario(scenario_id=scenario_id, source_dataset="synthetic", **_objects(), **_roadgraph(), **extras)

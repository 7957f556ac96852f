"""Hand-made scenarios (a straight two-lane road, a few road users) written as real shards."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import scenariomax
from scenariomax.schema import (
    OBJECT_TYPE_PEDESTRIAN,
    OBJECT_TYPE_VEHICLE,
    RG_LANE_SURFACE_STREET,
    RG_ROAD_EDGE_BOUNDARY,
    TL_GO,
    Sizes,
)
from vmax_sim.data import DataConfig

NUM_STEPS = 91
DT = 0.1
SMALL_SIZES = Sizes(num_objects=8, num_roadgraph=2000, num_lights=4, num_paths=2, num_points_per_path=400,
                    num_lanes=8, num_lane_links=2, num_agent_paths=2)
REALDATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata"


def smooth_bicycle_track(seed: int, num_steps: int = NUM_STEPS, substeps: int = 100):
    """A physically consistent track: speed and curvature vary smoothly, integrated finely.

    Returns x, y, yaw, vel_x, vel_y sampled at 10 Hz, each (num_steps,) float64.
    """
    rng = np.random.default_rng(seed)
    h = DT / substeps
    time = np.arange(num_steps * substeps) * h
    accel = 0.8 * np.sin(0.4 * time + rng.uniform(0, 6))
    curvature = 0.02 * np.sin(0.3 * time + rng.uniform(0, 6))
    speed = 8.0 + rng.uniform(0, 4) + np.cumsum(accel) * h
    yaw = rng.uniform(-0.3, 0.3) + np.cumsum(curvature * speed) * h
    x = np.cumsum(speed * np.cos(yaw)) * h
    y = np.cumsum(speed * np.sin(yaw)) * h
    pick = np.arange(num_steps) * substeps
    return x[pick], y[pick], yaw[pick], (speed * np.cos(yaw))[pick], (speed * np.sin(yaw))[pick]


def _polyline(x0, x1, y, spacing=1.0):
    xs = np.arange(x0, x1, spacing)
    xyz = np.stack([xs, np.full_like(xs, y), np.zeros_like(xs)], axis=1)
    direction = np.tile([1.0, 0.0, 0.0], (len(xs), 1))
    return xyz, direction


def make_scenario(seed: int = 0, scenario_id: str | None = None, num_objects: int = 5) -> scenariomax.Scenario:
    """SDC (slot 0) on a smooth track; a car ahead at constant speed; a parked car; a pedestrian
    crossing; and a car that appears at step 30. Two lanes along +x with road edges."""
    rng = np.random.default_rng(seed + 1000)
    n, t = num_objects, NUM_STEPS
    steps = np.arange(t) * DT
    x = np.zeros((n, t))
    y = np.zeros((n, t))
    yaw = np.zeros((n, t))
    vx = np.zeros((n, t))
    vy = np.zeros((n, t))
    valid = np.ones((n, t), bool)
    x[0], y[0], yaw[0], vx[0], vy[0] = smooth_bicycle_track(seed)
    speed_ahead = 10.0 + rng.uniform(0, 2)
    x[1], y[1], vx[1] = 30.0 + speed_ahead * steps, 3.5, speed_ahead  # constant speed, other lane
    x[2], y[2] = 60.0, -3.0  # parked
    x[3], y[3], yaw[3], vy[3] = 80.0, -6.0 + 1.2 * steps, np.pi / 2, 1.2  # pedestrian crossing
    x[4], y[4], vx[4] = -20.0 + 12.0 * steps, 3.5, 12.0
    valid[4, :30] = False
    length = np.tile([[4.5], [4.8], [4.2], [0.6], [4.6]][:n], (1, t))
    width = np.tile([[2.0], [2.0], [1.9], [0.6], [2.0]][:n], (1, t))
    object_type = np.array([OBJECT_TYPE_VEHICLE] * 3 + [OBJECT_TYPE_PEDESTRIAN] + [OBJECT_TYPE_VEHICLE])[:n]
    lanes = [_polyline(-60, 300, 0.0), _polyline(-60, 300, 3.5)]
    edges = [_polyline(-60, 300, -1.75), _polyline(-60, 300, 5.25)]
    xyz = np.concatenate([p[0] for p in lanes + edges])
    direction = np.concatenate([p[1] for p in lanes + edges])
    counts = [len(p[0]) for p in lanes + edges]
    types = np.repeat([RG_LANE_SURFACE_STREET, RG_LANE_SURFACE_STREET, RG_ROAD_EDGE_BOUNDARY,
                       RG_ROAD_EDGE_BOUNDARY], counts)
    ids = np.repeat([100, 101, 200, 201], counts)
    path_x = np.arange(0, 400, 1.0)
    path_xyz = np.stack([path_x, np.zeros_like(path_x), np.zeros_like(path_x)], axis=1)[None]
    return scenariomax.Scenario(
        scenario_id=scenario_id or f"straight-{seed}",
        object_id=np.arange(n) + 10, object_type=object_type, is_sdc=np.arange(n) == 0,
        x=np.where(valid, x, -1), y=np.where(valid, y, -1), z=np.zeros((n, t)), bbox_yaw=yaw,
        length=length, width=width, height=np.full((n, t), 1.6), velocity_x=vx, velocity_y=vy, valid=valid,
        is_controllable=np.isin(np.arange(n), [1, 4]), objects_of_interest=np.arange(n) == 1,
        roadgraph_xyz=xyz, roadgraph_dir=direction, roadgraph_type=types, roadgraph_id=ids,
        roadgraph_speed_limit=np.full(len(xyz), 13.4),
        tl_state=np.full((1, t), TL_GO), tl_valid=np.ones((1, t), bool), tl_lane_id=np.full((1, t), 100),
        tl_x=np.full((1, t), 150.0), tl_y=np.zeros((1, t)), tl_z=np.zeros((1, t)),
        path_xyz=path_xyz, path_valid=np.ones((1, len(path_x)), bool), path_lane_id=np.full((1, len(path_x)), 100),
        path_arc_length=path_x[None], path_on_route=np.array([True]),
        source_dataset="synthetic",
    )


@pytest.fixture(scope="session")
def shard_dir(tmp_path_factory) -> Path:
    """Six scenarios in two shard files."""
    out = tmp_path_factory.mktemp("shards")
    scenariomax.write_shards([make_scenario(seed) for seed in range(6)], out, sizes=SMALL_SIZES, shard_size=3)
    return out


def small_config(path="", **changes) -> DataConfig:
    values = {"path": str(path), "batch_size": 3, "num_objects": 8, "num_roadgraph_points": 1000, "num_paths": 2,
              "num_points_per_path": 300, "max_num_lights": 4, "include_map_index": False, "prefetch": 0}
    values.update(changes)
    return DataConfig(**values)

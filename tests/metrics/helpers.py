"""Hand-made scenes for the simulator-core tests: a straight two-lane road along +x."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from scenariomax.schema import RG_LANE_SURFACE_STREET, RG_ROAD_EDGE_BOUNDARY, RG_SOLID_SINGLE_WHITE
from vmax_sim.map_index import MapIndexConfig, build_map_index, path_arc_length, route_reference_arcs
from vmax_sim.metrics import StepInputs

LANE_WIDTH = 3.7
RIGHT_EDGE_Y = -0.5 * LANE_WIDTH  # road on the left of an edge running +x
LEFT_EDGE_Y = 1.5 * LANE_WIDTH  # runs -x so the road is on its left too


def straight_road(length: float = 200.0):
    """Roadgraph arrays: lane 1 at y=0, lane 2 at y=3.7 (both +x, 10 m/s), a line between, 2 edges."""
    x = np.arange(-0.5 * length, 0.5 * length + 1e-6, 1.0)
    polylines = [(x, 0.0, RG_LANE_SURFACE_STREET, 1), (x, LANE_WIDTH, RG_LANE_SURFACE_STREET, 2),
                 (x, 0.5 * LANE_WIDTH, RG_SOLID_SINGLE_WHITE, 3), (x, RIGHT_EDGE_Y, RG_ROAD_EDGE_BOUNDARY, 4),
                 (x[::-1], LEFT_EDGE_Y, RG_ROAD_EDGE_BOUNDARY, 5)]
    xyz = np.concatenate([np.stack([px, np.full_like(px, y), np.zeros_like(px)], 1) for px, y, _, _ in polylines])
    dirs = np.concatenate([np.tile([[np.sign(px[1] - px[0]), 0.0, 0.0]], (len(px), 1)) for px, _, _, _ in polylines])
    types = np.concatenate([np.full(len(px), t) for px, _, t, _ in polylines])
    ids = np.concatenate([np.full(len(px), i) for px, _, _, i in polylines])
    limit = np.where(types == RG_LANE_SURFACE_STREET, 10.0, -1.0)
    return {"xyz": xyz.astype(np.float32), "dir": dirs.astype(np.float32), "types": types, "ids": ids,
                "valid": np.ones(len(xyz), bool), "speed_limit": limit.astype(np.float32)}


def road_index(config: MapIndexConfig | None = None, center=(0.0, 0.0), **road):
    r = straight_road(**road)
    return build_map_index(r["xyz"], r["dir"], r["types"], r["ids"], r["valid"], config,
                           np.asarray(center), speed_limit=r["speed_limit"])


def route_paths(num_paths: int = 2, num_points: int = 300):
    """Path 0 along lane 1 (on route), path 1 along lane 2 (off route); points 1 m apart from x=-50."""
    px = -50.0 + np.arange(num_points, dtype=np.float32)
    xy = np.stack([np.stack([px, np.full_like(px, k * LANE_WIDTH)], -1) for k in range(num_paths)]).astype(np.float32)
    valid = np.ones(xy.shape[:2], bool)
    return xy, valid, path_arc_length(xy, valid), np.arange(num_paths) == 0


_ROUTE_ARCS = jax.jit(route_reference_arcs)


def step_inputs(sdc_xy=((-1.0, 0.0), (0.0, 0.0), (1.0, 0.0)), sdc_yaw=0.0, sdc_size=(4.0, 2.0),
                objects=(), object_vel=None, lights=(), log_start=(0.0, 0.0), log_end=(80.0, 0.0),
                sdc_log_xy=None, num_objects: int = 8) -> StepInputs:
    """StepInputs with the SDC history (oldest first) and objects given as [x, y, length, width, yaw]."""
    sdc_xy = jnp.asarray(sdc_xy, jnp.float32)
    h = sdc_xy.shape[0]
    yaw = jnp.broadcast_to(jnp.asarray(sdc_yaw, jnp.float32), (h,))
    boxes = np.zeros((num_objects, 5), np.float32)
    valid = np.zeros(num_objects, bool)
    vel = np.zeros((num_objects, 2), np.float32)
    for i, box in enumerate(objects):
        boxes[i], valid[i] = box, True
    if object_vel is not None:
        vel[:len(object_vel)] = object_vel
    num_lights = 4
    light_xy = np.zeros((num_lights, 2), np.float32)
    light_lane = np.full(num_lights, -1, np.int32)
    light_state = np.zeros(num_lights, np.int32)
    light_valid = np.zeros(num_lights, bool)
    for i, (x, y, lane, state) in enumerate(lights):
        light_xy[i], light_lane[i], light_state[i], light_valid[i] = (x, y), lane, state, True
    path_xy, path_valid, path_arc, on_route = route_paths()
    log_arc = _ROUTE_ARCS(jnp.asarray(path_xy), jnp.asarray(path_valid), jnp.asarray(path_arc),
                                   jnp.asarray(log_start, jnp.float32), jnp.asarray(log_end, jnp.float32))
    return StepInputs(
        sdc_xy=sdc_xy, sdc_yaw=yaw, sdc_size=jnp.asarray(sdc_size, jnp.float32),
        sdc_log_xy=sdc_xy[-1] if sdc_log_xy is None else jnp.asarray(sdc_log_xy, jnp.float32),
        object_boxes=jnp.asarray(boxes), object_vel=jnp.asarray(vel), object_valid=jnp.asarray(valid),
        light_xy=jnp.asarray(light_xy), light_lane_id=jnp.asarray(light_lane), light_state=jnp.asarray(light_state),
        light_valid=jnp.asarray(light_valid), path_xy=jnp.asarray(path_xy), path_valid=jnp.asarray(path_valid),
        path_arc=jnp.asarray(path_arc), path_on_route=jnp.asarray(on_route), path_log_arc=log_arc)

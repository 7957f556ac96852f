"""One nuPlan scenario window (anchor lidar_pc of an open log) -> a `Scenario`."""

from __future__ import annotations

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich.budget import fit_to_budget
from scenariomax.enrich.roadgraph import lane_graph_arrays, polylines_to_roadgraph
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.nuplan import ego
from scenariomax.sources.nuplan.log_db import (
    EGO_OBJECT_ID,
    MAX_ABS_VALUE,
    MAX_EGO_GAP_MICROS,
    EgoPoses,
    LogIndex,
    LogSlice,
    _float_table,
    light_state,
    nearest_pose_index,
)
from scenariomax.sources.nuplan.map_features import CONNECTOR_ID_OFFSET, map_id, scenario_map
from scenariomax.sources.nuplan.map_reader import CityMap
from scenariomax.sources.nuplan.windows import window_indices

STEP_MICROS = 100_000
SOURCE_DATASET = "nuplan"


def token_text(token) -> str:
    return bytes(token).hex() if isinstance(token, (bytes, bytearray, memoryview)) else str(token)


def scenario_id(log: LogIndex, anchor: int) -> str:
    return f"{log.log_name}_{token_text(log.lidar_token[anchor])}"


def step_times(log: LogIndex, steps: np.ndarray, current_index: int) -> tuple[np.ndarray, np.ndarray]:
    """(sweep time per step, -1 outside the log) and the same relative to step 0 (T,), (T,) int64.

    Times are the real lidar_pc timestamps; when step 0 lies before the log, it is placed
    `current_index` steps of 100 ms before the anchor.
    """
    in_log = steps >= 0
    absolute = np.where(in_log, log.lidar_time[np.maximum(steps, 0)], -1)
    anchor_time = int(absolute[current_index])
    start = int(absolute[0]) if in_log[0] else anchor_time - current_index * STEP_MICROS
    grid = (np.arange(len(steps)) - current_index) * STEP_MICROS + (anchor_time - start)
    relative = np.where(in_log, absolute - start, grid)
    return absolute, relative


def _empty_tracks(num_objects: int, num_steps: int) -> dict:
    fill = {name: np.full((num_objects, num_steps), -1.0) for name in
            ("x", "y", "z", "bbox_yaw", "length", "width", "height", "velocity_x", "velocity_y")}
    fill["valid"] = np.zeros((num_objects, num_steps), bool)
    return fill


def _ego_row(poses: EgoPoses, absolute: np.ndarray, tracks: dict) -> None:
    """Fills object row 0 with the ego's box-centre states (in place)."""
    in_log = np.flatnonzero(absolute >= 0)
    pick = nearest_pose_index(poses.time, absolute[in_log])
    steps, pick = in_log[pick >= 0], pick[pick >= 0]
    yaw = poses.yaw[pick]
    cx, cy = ego.rear_axle_to_center(poses.x[pick], poses.y[pick], yaw)
    vx, vy = ego.center_velocity_global(poses.vx[pick], poses.vy[pick], poses.yaw_rate[pick], yaw)
    for name, values in (("x", cx), ("y", cy), ("z", poses.z[pick]), ("bbox_yaw", ego.wrap_angle(yaw)),
                         ("length", ego.EGO_LENGTH_M), ("width", ego.EGO_WIDTH_M), ("height", ego.EGO_HEIGHT_M),
                         ("velocity_x", vx), ("velocity_y", vy)):
        tracks[name][0, steps] = values
    tracks["valid"][0, steps] = True


def _agent_rows(boxes: list[tuple], step_of_sweep: dict, log: LogIndex
                ) -> tuple[list, np.ndarray, np.ndarray, np.ndarray]:
    """Track tokens in object order (by id), and per kept box its object row (from 1), step and
    values (x y z length width height yaw vx vy). The first box of a track at a step wins."""
    values = _float_table([row[2:] for row in boxes], 9)
    usable = (np.isfinite(values).all(axis=1) & (np.abs(values) < MAX_ABS_VALUE).all(axis=1)
              & (values[:, 3:6] > 0).all(axis=1))
    keep = [i for i, row in enumerate(boxes)
            if usable[i] and row[1] in log.track_id and row[0] in step_of_sweep]
    order = sorted({boxes[i][1] for i in keep}, key=lambda token: log.track_id[token])
    row_of = {token: row for row, token in enumerate(order, start=1)}
    rows = np.array([row_of[boxes[i][1]] for i in keep], np.int64)
    steps = np.array([step_of_sweep[boxes[i][0]] for i in keep], np.int64)
    _, first = np.unique(rows * 1_000_000 + steps, return_index=True)
    return order, rows[first], steps[first], values[np.array(keep, np.int64)[first]]


def build_scenario(log: LogIndex, data: LogSlice, anchor: int, city: CityMap, sizes: Sizes,
                   map_margin_m: float) -> Scenario:
    """`data` must cover the anchor's window (see `window_time_span`)."""
    num_steps, current = sizes.num_timesteps, sizes.current_time_index
    steps = window_indices(anchor, len(log.lidar_time), num_steps, current)
    absolute, relative = step_times(log, steps, current)
    sweeps = [log.lidar_token[i] for i in steps if i >= 0]
    step_of_sweep = {log.lidar_token[i]: k for k, i in enumerate(steps) if i >= 0}

    boxes = [row for sweep in sweeps for row in data.boxes.get(sweep, ())]
    order, rows, box_steps, values = _agent_rows(boxes, step_of_sweep, log)
    tracks = _empty_tracks(1 + len(order), num_steps)
    _ego_row(data.ego, absolute, tracks)
    if not tracks["valid"][0, current]:
        raise ValueError(f"no ego_pose within {MAX_EGO_GAP_MICROS // 1000} ms of the current sweep")
    values[:, 6] = ego.wrap_angle(values[:, 6])
    for column, name in enumerate(("x", "y", "z", "length", "width", "height", "bbox_yaw", "velocity_x",
                                   "velocity_y")):
        tracks[name][rows, box_steps] = values[:, column]
    tracks["valid"][rows, box_steps] = True
    valid = tracks["valid"]
    object_id = np.array([EGO_OBJECT_ID] + [log.track_id[t] for t in order], np.int64)
    object_type = np.array([sch.OBJECT_TYPE_VEHICLE] + [log.track_type[t] for t in order], np.int64)
    is_sdc = np.arange(len(object_id)) == 0
    interacting = set(log.tag_agents.get(anchor, ()))
    objects_of_interest = np.array([False] + [t in interacting for t in order], bool)

    crop = _crop_box(tracks["x"][0, valid[0]], tracks["y"][0, valid[0]], map_margin_m)
    smap = scenario_map(city, crop)
    # UTM coordinates (~1e6 m) lose up to 0.25 m in float32: store positions relative to a
    # whole-metre origin at the ego's current position (kept in `world_origin`).
    origin = np.array([np.round(tracks["x"][0, current]), np.round(tracks["y"][0, current]), 0.0])
    tracks["x"] = np.where(valid, tracks["x"] - origin[0], -1.0)
    tracks["y"] = np.where(valid, tracks["y"] - origin[1], -1.0)
    roadgraph = polylines_to_roadgraph(smap.polylines, origin=origin)
    lanes = lane_graph_arrays(smap.lane_links, sizes.num_lane_links)
    statuses = [row for sweep in sweeps for row in data.lights.get(sweep, ())]
    lights = _light_arrays(statuses, step_of_sweep, smap.stop_points, num_steps)
    lights["tl_x"] = np.where(lights["tl_valid"], lights["tl_x"] - origin[0], -1.0)
    lights["tl_y"] = np.where(lights["tl_valid"], lights["tl_y"] - origin[1], -1.0)

    scenario = Scenario(
        scenario_id=scenario_id(log, anchor),
        object_id=object_id, object_type=object_type, is_sdc=is_sdc,
        objects_of_interest=objects_of_interest,
        timestamp_micros=np.where(valid, relative[None, :], -1),
        **tracks,
        **roadgraph, **lanes, **lights,
        tl_timestamp_micros=relative,
        world_origin=origin,
        source_dataset=SOURCE_DATASET,
        current_time_index=current,
        metadata={"log_name": log.log_name, "map_version": log.map_version,
                  "anchor_lidar_pc_token": token_text(log.lidar_token[anchor]),
                  "anchor_timestamp_micros": int(log.lidar_time[anchor]),
                  "scenario_tags": list(log.tags.get(anchor, ()))},
    )
    return fit_to_budget(scenario, sizes)


def window_time_span(log: LogIndex, anchors: list[int], sizes: Sizes) -> tuple[int, int]:
    """First and last sweep timestamps the windows of these anchors touch."""
    first = window_indices(min(anchors), len(log.lidar_time), sizes.num_timesteps, sizes.current_time_index)
    last = window_indices(max(anchors), len(log.lidar_time), sizes.num_timesteps, sizes.current_time_index)
    return int(log.lidar_time[first[first >= 0].min()]), int(log.lidar_time[last[last >= 0].max()])


def _crop_box(x: np.ndarray, y: np.ndarray, margin: float) -> tuple[float, float, float, float]:
    return (float(x.min()) - margin, float(y.min()) - margin, float(x.max()) + margin, float(y.max()) + margin)


def _light_arrays(statuses: list[tuple], step_of_sweep: dict, stop_points: dict, num_steps: int) -> dict:
    """(L, T) light arrays for lane connectors with a status and a stop point in the cropped map."""
    per_connector: dict[int, dict[int, int]] = {}
    for sweep, connector, status in statuses:
        if sweep not in step_of_sweep or not isinstance(connector, int) or connector not in stop_points:
            continue
        per_connector.setdefault(connector, {}).setdefault(step_of_sweep[sweep], light_state(status))
    connectors = sorted(per_connector)
    num = len(connectors)
    state = np.zeros((num, num_steps), np.int64)
    valid = np.zeros((num, num_steps), bool)
    for row, connector in enumerate(connectors):
        for k, value in per_connector[connector].items():
            state[row, k], valid[row, k] = value, True
    lane_id = np.array([map_id(CONNECTOR_ID_OFFSET, c) for c in connectors], np.int64).reshape(num, 1)
    stop_x = np.array([stop_points[c][0] for c in connectors]).reshape(num, 1)
    stop_y = np.array([stop_points[c][1] for c in connectors]).reshape(num, 1)
    return {
        "tl_state": np.where(valid, state, -1), "tl_valid": valid,
        "tl_lane_id": np.where(valid, lane_id, -1),
        "tl_x": np.where(valid, stop_x, -1.0), "tl_y": np.where(valid, stop_y, -1.0),
        "tl_z": np.where(valid, 0.0, -1.0),
    }

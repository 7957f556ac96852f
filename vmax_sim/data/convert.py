"""One `scenariomax.Scenario` -> one unbatched `SimulatorState` (numpy on the host, then device).

All padding and cropping happens here so every state from one `DataConfig` has the same shapes.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable, Sequence

import jax
import numpy as np

from scenariomax import Scenario
from scenariomax.crop import distance_to_points, sdc_positions
from scenariomax.errors import InputError
from vmax_sim.data.config import DataConfig
from vmax_sim.datatypes import (
    ObjectMetadata,
    Paths,
    RoadgraphPoints,
    SimulatorState,
    TrafficLights,
    Trajectory,
)


def _pad_first_axis(array: np.ndarray, size: int, fill) -> np.ndarray:
    """Crops or pads axis 0 to `size`."""
    array = array[:size]
    if array.shape[0] == size:
        return array
    pad = np.full((size - array.shape[0],) + array.shape[1:], fill, dtype=array.dtype)
    return np.concatenate([array, pad], axis=0)


def _pad_axes(array: np.ndarray, shape: tuple[int, ...], fill) -> np.ndarray:
    """Crops or pads every axis to `shape`."""
    out = np.full(shape, fill, dtype=array.dtype)
    cropped = array[tuple(slice(0, n) for n in shape)]
    out[tuple(slice(0, n) for n in cropped.shape)] = cropped
    return out


def object_slots(scenario: Scenario, num_objects: int) -> np.ndarray:
    """The first `num_objects` slots, with the SDC moved to slot 0 if it lies beyond them. (k,) int"""
    sdc = scenario.sdc_index
    slots = np.arange(min(num_objects, scenario.num_objects))
    if sdc >= num_objects:
        slots = np.concatenate([[sdc], slots[:-1]])
    return slots


def _trajectory(scenario: Scenario, slots: np.ndarray, num_objects: int) -> Trajectory:
    valid = scenario.valid[slots]

    def take(values: np.ndarray, dtype, fill) -> np.ndarray:
        kept = np.where(valid, values[slots], fill).astype(dtype)
        return _pad_first_axis(kept, num_objects, fill)

    return Trajectory(
        x=take(scenario.x, np.float32, 0), y=take(scenario.y, np.float32, 0), z=take(scenario.z, np.float32, 0),
        vel_x=take(scenario.velocity_x, np.float32, 0), vel_y=take(scenario.velocity_y, np.float32, 0),
        yaw=take(scenario.bbox_yaw, np.float32, 0), length=take(scenario.length, np.float32, 0),
        width=take(scenario.width, np.float32, 0), height=take(scenario.height, np.float32, 0),
        valid=_pad_first_axis(valid, num_objects, False),
        timestamp_micros=take(scenario.timestamp_micros, np.int32, -1),
    )


def _metadata(scenario: Scenario, slots: np.ndarray, num_objects: int) -> ObjectMetadata:
    def take(values: np.ndarray, dtype, fill) -> np.ndarray:
        return _pad_first_axis(values[slots].astype(dtype), num_objects, fill)

    is_sdc = take(scenario.is_sdc, bool, False)
    return ObjectMetadata(
        ids=take(scenario.object_id, np.int32, -1), object_types=take(scenario.object_type, np.int32, 0),
        is_sdc=is_sdc, is_controlled=is_sdc.copy(), is_controllable=take(scenario.is_controllable, bool, False),
        is_valid=take(scenario.valid.any(axis=1), bool, False),
        objects_of_interest=take(scenario.objects_of_interest, bool, False),
    )


def roadgraph_selection(scenario: Scenario, num_points: int) -> np.ndarray:
    """Indices of the valid roadgraph points kept (nearest the SDC trajectory), in map order. (k,) int"""
    kept = np.flatnonzero(scenario.roadgraph_valid)
    if kept.size <= num_points:
        return kept
    anchors = sdc_positions(scenario)[::5]
    dist = distance_to_points(scenario.roadgraph_xyz[kept, :2].astype(np.float64), anchors)
    return np.sort(kept[np.argpartition(dist, num_points - 1)[:num_points]])


def _roadgraph(scenario: Scenario, num_points: int) -> RoadgraphPoints:
    keep = roadgraph_selection(scenario, num_points)

    def take(values: np.ndarray, dtype, fill) -> np.ndarray:
        return _pad_first_axis(values[keep].astype(dtype), num_points, fill)

    xyz, direction = scenario.roadgraph_xyz, scenario.roadgraph_dir
    return RoadgraphPoints(
        x=take(xyz[:, 0], np.float32, 0), y=take(xyz[:, 1], np.float32, 0), z=take(xyz[:, 2], np.float32, 0),
        dir_x=take(direction[:, 0], np.float32, 0), dir_y=take(direction[:, 1], np.float32, 0),
        dir_z=take(direction[:, 2], np.float32, 0), types=take(scenario.roadgraph_type, np.int32, 0),
        ids=take(scenario.roadgraph_id, np.int32, -1), valid=take(scenario.roadgraph_valid, bool, False),
        speed_limit=take(scenario.roadgraph_speed_limit, np.float32, -1),
    )


def lights_hidden(scenario_id: str, share: float) -> bool:
    """Whether `DataConfig.hide_lights` hides this scenario's lights: a fixed draw per scenario id (crc32, the same
    in every process and run), so a scenario is lit or unlit every time it is read, as a recording is."""
    return share > 0 and zlib.crc32(scenario_id.encode()) / 2**32 < share


def _traffic_lights(scenario: Scenario, num_lights: int, hidden: bool = False) -> TrafficLights:
    """The first `num_lights` lights seen at least once; none (all slots invalid) when `hidden`."""
    keep = np.flatnonzero(scenario.tl_valid.any(axis=1))[:0 if hidden else num_lights]
    valid = scenario.tl_valid[keep]

    def take(values: np.ndarray, dtype, fill) -> np.ndarray:
        return _pad_first_axis(np.where(valid, values[keep], fill).astype(dtype), num_lights, fill)

    return TrafficLights(
        x=take(scenario.tl_x, np.float32, 0), y=take(scenario.tl_y, np.float32, 0),
        z=take(scenario.tl_z, np.float32, 0), state=take(scenario.tl_state, np.int32, 0),
        lane_ids=take(scenario.tl_lane_id, np.int32, -1), valid=_pad_first_axis(valid, num_lights, False),
    )


def _paths(scenario: Scenario, num_paths: int, num_points: int) -> Paths:
    shape = (num_paths, num_points)
    valid = _pad_axes(scenario.path_valid, shape, False)

    def take(values: np.ndarray, dtype, fill) -> np.ndarray:
        return np.where(valid, _pad_axes(values.astype(dtype), shape, fill), fill).astype(dtype)

    xyz = scenario.path_xyz
    return Paths(
        x=take(xyz[..., 0], np.float32, 0), y=take(xyz[..., 1], np.float32, 0), z=take(xyz[..., 2], np.float32, 0),
        ids=take(scenario.path_lane_id, np.int32, -1), valid=valid,
        arc_length=take(scenario.path_arc_length, np.float32, 0),
        on_route=_pad_first_axis(scenario.path_on_route.astype(bool), num_paths, False),
    )


AGENT_PATH_SPACING_M = 1.0  # spacing of the paths built from an agent's logged positions (as the shards')


def logged_path(x: np.ndarray, y: np.ndarray, valid: np.ndarray, num_points: int,
                spacing: float = AGENT_PATH_SPACING_M) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A path through an object's valid logged positions, resampled every `spacing` metres from its
    first one (the whole log: it starts behind the object's position at the current step).

    x, y, valid (T,) -> xy (num_points, 2), valid (num_points,), arc length (num_points,) float32.
    A track shorter than `spacing` gives its single first point (users extend it along the heading).
    """
    xy = np.stack([x[valid], y[valid]], axis=1).astype(np.float64)
    out_xy = np.zeros((num_points, 2), np.float32)
    out_valid = np.zeros(num_points, bool)
    out_arc = np.zeros(num_points, np.float32)
    if len(xy) == 0:
        return out_xy, out_valid, out_arc
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    keep = np.concatenate([[True], np.diff(cum) > 1e-6])
    xy, cum = xy[keep], cum[keep]
    targets = np.arange(0.0, cum[-1] + 1e-6, spacing)[:num_points]
    points = np.stack([np.interp(targets, cum, xy[:, 0]), np.interp(targets, cum, xy[:, 1])], 1)
    n = len(points)
    out_xy[:n], out_valid[:n], out_arc[:n] = points, True, targets
    return out_xy, out_valid, out_arc


def _agent_paths(scenario: Scenario, slots: np.ndarray, num_objects: int, num_points: int) -> Paths:
    """Per object slot: the shard's lane path of a controllable agent (on_route True) or, when it has
    none, a path through its logged positions (on_route False); invalid for the SDC and every other
    object. -> Paths (num_objects, num_points)."""
    shape = (num_objects, num_points)
    x, y = np.zeros(shape, np.float32), np.zeros(shape, np.float32)
    valid, arc = np.zeros(shape, bool), np.zeros(shape, np.float32)
    from_shards = np.zeros(num_objects, bool)
    rows = {int(index): row for row, index in enumerate(scenario.agent_path_object_index)}
    controllable = np.asarray(scenario.is_controllable, bool)
    for slot, index in enumerate(slots):
        if index == scenario.sdc_index or not controllable[index]:
            continue
        row = rows.get(int(index))
        if row is not None and scenario.agent_path_valid[row].any():
            kept = scenario.agent_path_valid[row][:num_points]
            n = len(kept)
            x[slot, :n] = np.where(kept, scenario.agent_path_xyz[row, :num_points, 0], 0.0)
            y[slot, :n] = np.where(kept, scenario.agent_path_xyz[row, :num_points, 1], 0.0)
            arc[slot, :n] = np.where(kept, scenario.agent_path_arc_length[row, :num_points], 0.0)
            valid[slot, :n] = kept
            from_shards[slot] = True
        else:
            xy, valid[slot], arc[slot] = logged_path(scenario.x[index], scenario.y[index], scenario.valid[index],
                                                     num_points)
            x[slot], y[slot] = xy[:, 0], xy[:, 1]
    return Paths(x=x, y=y, z=np.zeros(shape, np.float32), ids=np.full(shape, -1, np.int32), valid=valid,
                 arc_length=arc, on_route=from_shards)


def build_map_index_for(roadgraph: RoadgraphPoints, center_xy: np.ndarray, config: DataConfig):
    """The map index of one roadgraph, centred on `center_xy` (2,) (numpy, host).

    The data path's one call into the host side of the map index (`vmax_sim.map_index.build`).
    """
    from vmax_sim.map_index.build import build_map_index

    xyz = np.stack([roadgraph.x, roadgraph.y, roadgraph.z], axis=-1)
    direction = np.stack([roadgraph.dir_x, roadgraph.dir_y, roadgraph.dir_z], axis=-1)
    return build_map_index(xyz, direction, roadgraph.types, roadgraph.ids, roadgraph.valid,
                           config.map_index_config, center_xy=center_xy, speed_limit=roadgraph.speed_limit)


def scenario_to_numpy_state(scenario: Scenario, config: DataConfig) -> SimulatorState:
    """Host-side conversion: a SimulatorState of numpy arrays, timestep at the scenario's current step."""
    try:
        sdc = scenario.sdc_index
    except ValueError as error:
        raise InputError(f"scenario {scenario.scenario_id}: {error}") from None
    if not scenario.valid[sdc, scenario.current_time_index]:
        raise InputError(f"scenario {scenario.scenario_id}: the SDC is not valid at the current step")
    slots = object_slots(scenario, config.num_objects)
    log = _trajectory(scenario, slots, config.num_objects)
    roadgraph = _roadgraph(scenario, config.num_roadgraph_points)
    now = scenario.current_time_index
    sdc_xy = np.array([scenario.x[sdc, now], scenario.y[sdc, now]], np.float64)
    hidden = lights_hidden(scenario.scenario_id, config.hide_lights)
    from_student_only = config.hide_lights > 0 and config.hide_lights_from == "student"
    return SimulatorState(
        log_trajectory=log,
        sim_trajectory=log,
        object_metadata=_metadata(scenario, slots, config.num_objects),
        roadgraph_points=roadgraph,
        log_traffic_light=_traffic_lights(scenario, config.max_num_lights, hidden and not from_student_only),
        sdc_paths=_paths(scenario, config.num_paths, config.num_points_per_path),
        map_index=build_map_index_for(roadgraph, sdc_xy, config) if config.include_map_index else None,
        timestep=np.asarray(scenario.current_time_index, np.int32),
        agent_paths=(_agent_paths(scenario, slots, config.num_objects, config.num_points_per_agent_path)
                     if config.include_agent_paths else None),
        lights_hidden=np.asarray(hidden) if from_student_only else None,
    )


def scenario_to_state(scenario: Scenario, config: DataConfig) -> SimulatorState:
    """One scenario as an unbatched SimulatorState on the default device."""
    return jax.device_put(scenario_to_numpy_state(scenario, config))


def stack_states(states: Sequence[SimulatorState]) -> SimulatorState:
    """Stacks unbatched states (numpy or jax) on a new leading batch axis (numpy result)."""
    if not states:
        raise ValueError("cannot stack an empty list of states")
    return jax.tree.map(lambda *leaves: np.stack([np.asarray(leaf) for leaf in leaves]), *states)


def scenarios_to_batch(scenarios: Iterable[Scenario], config: DataConfig) -> SimulatorState:
    """A fixed list of scenarios as one batch (leading axis = number of scenarios), on device."""
    return jax.device_put(stack_states([scenario_to_numpy_state(s, config) for s in scenarios]))

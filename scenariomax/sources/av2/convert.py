"""One AV2 scenario (RawTracks + Av2Map) -> a V-Max `Scenario` of 91 steps."""

from __future__ import annotations

import numpy as np

from scenariomax.enrich.budget import fit_to_budget
from scenariomax.enrich.geometry import wrap_angle  # noqa: F401 (shared; re-exported)
from scenariomax.enrich.roadgraph import lane_graph_arrays, polylines_to_roadgraph
from scenariomax.scenario import Scenario
from scenariomax.schema import OBJECT_TYPE_OTHER, Sizes
from scenariomax.sources.av2.errors import Av2ScenarioError
from scenariomax.sources.av2.map import Av2Map
from scenariomax.sources.av2.tracks import (
    AV_TRACK_ID,
    DEFAULT_BOX_SIZES,
    OBJECT_TYPES,
    SCORED_CATEGORY,
    RawTracks,
    choose_window_start,
    object_ids_of,
    window,
)

SOURCE_DATASET = "av2"
_CHUNK = 2048


def _unique_rows(xy: np.ndarray, cell_m: float) -> tuple[np.ndarray, np.ndarray]:
    """One representative per `cell_m` grid cell, and each row's representative index."""
    _, first, inverse = np.unique(np.floor(xy / cell_m).astype(np.int64), axis=0, return_index=True,
                                  return_inverse=True)
    return first, inverse.reshape(-1)


def ground_heights(xy: np.ndarray, ground_xyz: np.ndarray) -> np.ndarray:
    """z of the nearest map vertex (in xy) for each query point; 0 without a map. (m, 2) -> (m,)

    Queries are snapped to 0.5 m cells and map vertices thinned to one per 1 m cell: heights vary
    slowly, and this keeps the brute-force search small.
    """
    if len(ground_xyz) == 0 or len(xy) == 0:
        return np.zeros(len(xy))
    ground = ground_xyz[_unique_rows(ground_xyz[:, :2], 1.0)[0]]
    query_rows, query_of = _unique_rows(xy, 0.5)
    queries = xy[query_rows]
    heights = np.empty(len(queries))
    for start in range(0, len(queries), _CHUNK):
        block = queries[start:start + _CHUNK, None, :] - ground[None, :, :2]
        heights[start:start + _CHUNK] = ground[np.argmin(np.einsum("qgk,qgk->qg", block, block), axis=1), 2]
    return heights[query_of]


def build_scenario(tracks: RawTracks, av2_map: Av2Map, sizes: Sizes) -> Scenario:
    """Window, object arrays, roadgraph and lane graph, fitted to the budget."""
    sdc = tracks.index_of(AV_TRACK_ID)
    num_window_steps = sizes.num_timesteps
    start = choose_window_start(tracks.valid[sdc], num_window_steps, sizes.current_time_index)

    def cut(values: np.ndarray, fill) -> np.ndarray:
        return window(values, start, num_window_steps, fill)

    valid = cut(tracks.valid, False)
    present = valid.any(axis=1)
    present[sdc] = True
    keep = np.flatnonzero(present)  # tracks with no row inside the window are dropped
    valid = valid[keep]
    if not valid[np.flatnonzero(keep == sdc)[0], sizes.current_time_index]:
        raise Av2ScenarioError("the AV track is not valid at the current step")

    type_names = [tracks.object_types[i] for i in keep]
    boxes = np.array([DEFAULT_BOX_SIZES.get(name, DEFAULT_BOX_SIZES["unknown"]) for name in type_names])
    x, y = cut(tracks.x, np.nan)[keep], cut(tracks.y, np.nan)[keep]
    z = np.full(x.shape, -1.0)
    ground = ground_heights(np.stack([x[valid], y[valid]], axis=1), av2_map.ground_xyz)
    # Box centre height: ground under the object plus half its (default) height.
    z[valid] = ground + np.broadcast_to(boxes[:, None, 2], valid.shape)[valid] / 2

    def per_step(values: np.ndarray) -> np.ndarray:
        return np.where(valid, values, -1.0)

    def box_dim(column: int) -> np.ndarray:
        return per_step(np.broadcast_to(boxes[:, None, column], valid.shape))

    velocity_x = per_step(cut(tracks.velocity_x, np.nan)[keep])
    velocity_y = per_step(cut(tracks.velocity_y, np.nan)[keep])
    category = tracks.category[keep]
    is_sdc = keep == sdc
    current_valid = valid[:, sizes.current_time_index]
    focal = np.array([tracks.track_ids[i] == tracks.focal_track_id for i in keep])

    roadgraph = polylines_to_roadgraph(av2_map.polylines)
    lanes = lane_graph_arrays(av2_map.lane_links, sizes.num_lane_links)
    scenario = Scenario(
        scenario_id=tracks.scenario_id,
        object_id=object_ids_of(tracks.track_ids)[keep],
        object_type=np.array([OBJECT_TYPES.get(name, OBJECT_TYPE_OTHER) for name in type_names], np.int64),
        is_sdc=is_sdc,
        x=per_step(x), y=per_step(y), z=z,
        bbox_yaw=per_step(wrap_angle(np.nan_to_num(cut(tracks.heading, 0.0)[keep]))),
        length=box_dim(0), width=box_dim(1), height=box_dim(2),
        velocity_x=velocity_x, velocity_y=velocity_y, valid=valid,
        # speed, vel_yaw and timestamps (step k -> k * 100 ms from the window start) are derived.
        tracks_to_predict=(category >= SCORED_CATEGORY) & current_valid & ~is_sdc,
        objects_of_interest=focal & current_valid,
        **roadgraph, **lanes,
        source_dataset=SOURCE_DATASET,
        current_time_index=sizes.current_time_index,
        metadata={"city": tracks.city, "focal_track_id": tracks.focal_track_id, "window_start": start,
                      "num_raw_steps": tracks.num_steps},
    )
    return fit_to_budget(scenario, sizes)

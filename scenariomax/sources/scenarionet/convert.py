"""ScenarioNet / MetaDrive scenario description (a dict) -> `Scenario`s, one per 91-step window.

Tracks are resampled to 10 Hz when the description's sample rate differs, then cut into windows
(see `scenariomax.sources.womd.windows`); only windows where the SDC is valid at every step are
kept. String ids are mapped to ints with a stable table (see `stable_int_ids`).
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich.budget import fit_to_budget
from scenariomax.enrich.roadgraph import LaneLinks, MapPolyline, lane_graph_arrays, polylines_to_roadgraph
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.womd.convert import ScenarioBuildError
from scenariomax.sources.womd.edges import orient_road_edges
from scenariomax.sources.womd.windows import DEFAULT_WINDOW_STRIDE, window_starts, wrap_angle

SOURCE_NAME = "scenarionet"
STEP_SECONDS = 0.1
MPH_TO_MPS, KMH_TO_MPS = 0.44704, 1.0 / 3.6

OBJECT_TYPES = {"VEHICLE": sch.OBJECT_TYPE_VEHICLE, "PEDESTRIAN": sch.OBJECT_TYPE_PEDESTRIAN,
                "CYCLIST": sch.OBJECT_TYPE_CYCLIST}  # anything else (barriers, cones, OTHER...) -> other
MAP_TYPES = {
    "LANE_FREEWAY": sch.RG_LANE_FREEWAY, "LANE_SURFACE_STREET": sch.RG_LANE_SURFACE_STREET,
    "LANE_BIKE_LANE": sch.RG_LANE_BIKE, "LANE_UNKNOWN": sch.RG_LANE_SURFACE_STREET,
    "ROAD_LINE_UNKNOWN": 0,
    "ROAD_LINE_BROKEN_SINGLE_WHITE": sch.RG_BROKEN_SINGLE_WHITE,
    "ROAD_LINE_SOLID_SINGLE_WHITE": sch.RG_SOLID_SINGLE_WHITE,
    "ROAD_LINE_SOLID_DOUBLE_WHITE": sch.RG_SOLID_DOUBLE_WHITE,
    "ROAD_LINE_BROKEN_SINGLE_YELLOW": sch.RG_BROKEN_SINGLE_YELLOW,
    "ROAD_LINE_BROKEN_DOUBLE_YELLOW": sch.RG_BROKEN_DOUBLE_YELLOW,
    "ROAD_LINE_SOLID_SINGLE_YELLOW": sch.RG_SOLID_SINGLE_YELLOW,
    "ROAD_LINE_SOLID_DOUBLE_YELLOW": sch.RG_SOLID_DOUBLE_YELLOW,
    "ROAD_LINE_PASSING_DOUBLE_YELLOW": sch.RG_PASSING_DOUBLE_YELLOW,
    "ROAD_EDGE_UNKNOWN": sch.RG_ROAD_EDGE_BOUNDARY, "ROAD_EDGE_BOUNDARY": sch.RG_ROAD_EDGE_BOUNDARY,
    "ROAD_EDGE_MEDIAN": sch.RG_ROAD_EDGE_MEDIAN, "ROAD_EDGE_SIDEWALK": sch.RG_ROAD_EDGE_BOUNDARY,
    "STOP_SIGN": sch.RG_STOP_SIGN, "CROSSWALK": sch.RG_CROSSWALK, "SPEED_BUMP": sch.RG_SPEED_BUMP,
    "DRIVEWAY": sch.RG_DRIVEWAY,
}
_CLOSED_TYPES = (sch.RG_CROSSWALK, sch.RG_SPEED_BUMP, sch.RG_DRIVEWAY)
# MetaDrive light strings and WOMD lane-state strings -> WOMD light enum.
LIGHT_STATES = {
    "TRAFFIC_LIGHT_RED": sch.TL_STOP, "TRAFFIC_LIGHT_YELLOW": sch.TL_CAUTION, "TRAFFIC_LIGHT_GREEN": sch.TL_GO,
    "TRAFFIC_LIGHT_UNKNOWN": sch.TL_UNKNOWN,
    "LANE_STATE_UNKNOWN": sch.TL_UNKNOWN, "LANE_STATE_ARROW_STOP": sch.TL_ARROW_STOP,
    "LANE_STATE_ARROW_CAUTION": sch.TL_ARROW_CAUTION, "LANE_STATE_ARROW_GO": sch.TL_ARROW_GO,
    "LANE_STATE_STOP": sch.TL_STOP, "LANE_STATE_CAUTION": sch.TL_CAUTION, "LANE_STATE_GO": sch.TL_GO,
    "LANE_STATE_FLASHING_STOP": sch.TL_FLASHING_STOP, "LANE_STATE_FLASHING_CAUTION": sch.TL_FLASHING_CAUTION,
}


def stable_int_ids(keys) -> dict[Any, int]:
    """Deterministic int ids: the keys themselves when all are integers (or decimal strings), else
    their rank in the list sorted by str(key)."""
    keys = list(keys)
    if all(isinstance(k, (int, np.integer)) or (isinstance(k, str) and k.isdigit()) for k in keys):
        return {k: int(k) for k in keys}
    return {k: rank for rank, k in enumerate(sorted(keys, key=str))}


# --- times and resampling --------------------------------------------------------------------------
def source_times(desc: Mapping, num_steps: int) -> np.ndarray:
    """Seconds of each source step: metadata `ts` when it fits, else a fixed `timestep`/`sample_rate`."""
    meta = desc.get("metadata", {}) or {}
    ts = meta.get("ts")
    if ts is not None and np.size(ts) == num_steps:
        times = np.asarray(ts, np.float64).ravel()
        if num_steps < 2 or np.all(np.diff(times) > 0):
            return times - times[0]
    step = float(meta.get("timestep") or meta.get("sample_rate") or STEP_SECONDS)
    if not step > 0:
        raise ScenarioBuildError(f"bad time step {step}")
    return np.arange(num_steps) * step


def resample_indices(times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """For a 10 Hz grid over `times`: (lower index, upper index, weight of upper) per target step,
    or None when the source is already at 10 Hz."""
    if len(times) < 2 or np.allclose(np.diff(times), STEP_SECONDS, atol=1e-3):
        return None
    target = np.arange(int(np.floor(times[-1] / STEP_SECONDS + 1e-6)) + 1) * STEP_SECONDS
    upper = np.clip(np.searchsorted(times, target - 1e-9), 0, len(times) - 1)
    lower = np.clip(upper - 1, 0, len(times) - 1)
    exact = np.isclose(times[upper], target, atol=1e-6)
    lower = np.where(exact, upper, lower)
    span = times[upper] - times[lower]
    weight = np.where(span > 0, (target - times[lower]) / np.where(span > 0, span, 1.0), 0.0)
    return lower, upper, weight


def _interp(values: np.ndarray, plan) -> np.ndarray:
    lower, upper, weight = plan
    w = weight.reshape((1, -1) + (1,) * (values.ndim - 2))
    return values[:, lower] * (1 - w) + values[:, upper] * w


# --- tracks ----------------------------------------------------------------------------------------
def _per_step(state: Mapping, key: str, num_steps: int, width: int | None = None) -> np.ndarray:
    value = np.asarray(state[key], np.float64)
    if width is None:
        value = value.reshape(num_steps, -1)[:, 0] if value.size else np.zeros(num_steps)
        return value
    value = value.reshape(num_steps, -1)
    if value.shape[1] < width:  # 2-D positions: z = 0
        value = np.concatenate([value, np.zeros((num_steps, width - value.shape[1]))], axis=1)
    return value[:, :width]


def track_arrays(tracks: Mapping, num_steps: int) -> dict[str, np.ndarray]:
    """Source-rate arrays: position (N, T, 3), heading/length/width/height (N, T), velocity (N, T, 2), valid."""
    rows = {name: [] for name in ("position", "heading", "velocity", "length", "width", "height", "valid")}
    for key, track in tracks.items():
        state = track["state"]
        try:
            rows["position"].append(_per_step(state, "position", num_steps, 3))
            rows["velocity"].append(_per_step(state, "velocity", num_steps, 2))
            for name in ("heading", "length", "width", "height", "valid"):
                rows[name].append(_per_step(state, name, num_steps))
        except (KeyError, ValueError) as error:
            raise ScenarioBuildError(f"track {key}: bad state ({type(error).__name__}: {error})") from None
    out = {name: np.stack(values) if values else np.zeros((0, num_steps)) for name, values in rows.items()}
    out["valid"] = out["valid"] > 0.5
    return out


def resample_tracks(arrays: dict, plan) -> dict:
    if plan is None:
        return arrays
    lower, upper, _ = plan
    out = {name: _interp(arrays[name], plan) for name in ("position", "velocity", "length", "width", "height")}
    out["heading"] = np.arctan2(_interp(np.sin(arrays["heading"]), plan), _interp(np.cos(arrays["heading"]), plan))
    out["valid"] = arrays["valid"][:, lower] & arrays["valid"][:, upper]
    return out


# --- map -------------------------------------------------------------------------------------------
def _xyz(points) -> np.ndarray:
    array = np.asarray(points, np.float64)
    if array.ndim == 1:
        array = array.reshape(1, -1)
    if array.size == 0:
        return np.zeros((0, 3))
    if array.shape[1] == 2:
        array = np.concatenate([array, np.zeros((len(array), 1))], axis=1)
    return array[:, :3]


def _link_ids(values, ids: Mapping) -> list[int]:
    out = []
    for value in values if isinstance(values, (list, tuple, np.ndarray)) else []:
        key = value.get("feature_id", value.get("id")) if isinstance(value, Mapping) else value
        for candidate in (key, str(key)):
            if candidate in ids:
                out.append(ids[candidate])
                break
    return out


def _speed_limit(feature: Mapping) -> float:
    for key, scale in (("speed_limit_mph", MPH_TO_MPS), ("speed_limit_kmh", KMH_TO_MPS)):
        value = feature.get(key)
        if value is not None and np.isfinite(float(value)) and float(value) > 0:
            return float(value) * scale
    return -1.0


def map_polylines(features: Mapping, ids: Mapping) -> tuple[list[MapPolyline], list[LaneLinks]]:
    polylines, links = [], []
    for key, feature in features.items():
        rg_type = MAP_TYPES.get(str(feature.get("type", "")))
        if rg_type is None:
            continue  # unknown feature kinds (e.g. drivable-area polygons) are not part of the roadgraph
        fid = ids[key]
        if rg_type == sch.RG_STOP_SIGN:
            points = _xyz(feature.get("position", feature.get("polyline", [])))
        elif rg_type in _CLOSED_TYPES:
            points = _xyz(feature.get("polygon", feature.get("polyline", [])))
        else:
            points = _xyz(feature.get("polyline", []))
        if len(points) == 0:
            continue
        is_lane = rg_type in sch.LANE_TYPES
        polylines.append(MapPolyline(fid, rg_type, points, speed_limit=_speed_limit(feature) if is_lane else -1.0,
                                     closed=rg_type in _CLOSED_TYPES))
        if is_lane:
            links.append(LaneLinks(fid, successors=_link_ids(feature.get("exit_lanes", []), ids),
                                   predecessors=_link_ids(feature.get("entry_lanes", []), ids),
                                   left_neighbors=_link_ids(feature.get("left_neighbor", []), ids),
                                   right_neighbors=_link_ids(feature.get("right_neighbor", []), ids)))
    return orient_road_edges(polylines, sch.ROAD_EDGE_TYPES, sch.LANE_TYPES), links


# --- traffic lights --------------------------------------------------------------------------------
def light_arrays(lights: Mapping, ids: Mapping, num_steps: int, plan) -> dict[str, np.ndarray]:
    """(L, T10) arrays at 10 Hz (nearest earlier source step when resampling)."""
    rows = []
    for key in sorted(lights, key=str):
        light = lights[key]
        states = list((light.get("state") or {}).get("object_state", []))[:num_steps]
        states += [None] * (num_steps - len(states))
        lane = light.get("lane")
        lane_id = _link_ids([lane], ids)
        point = _xyz(light.get("stop_point", [np.nan, np.nan, np.nan]))[0] if light.get("stop_point") is not None \
            else np.full(3, np.nan)
        codes = np.array([LIGHT_STATES.get(str(s), sch.TL_UNKNOWN) for s in states], np.int64)
        known = np.array([s is not None for s in states], bool) & bool(lane_id) & np.all(np.isfinite(point))
        rows.append((codes, known, lane_id[0] if lane_id else -1, point))
    if plan is not None:
        lower = plan[0]
        rows = [(codes[lower], known[lower], lane, point) for codes, known, lane, point in rows]
    steps = len(plan[0]) if plan is not None else num_steps
    shape = (len(rows), steps)
    out = dict(tl_state=np.zeros(shape, np.int64), tl_valid=np.zeros(shape, bool),
               tl_lane_id=np.full(shape, -1, np.int64), tl_x=np.full(shape, -1.0, np.float32),
               tl_y=np.full(shape, -1.0, np.float32), tl_z=np.full(shape, -1.0, np.float32))
    for row, (codes, known, lane, point) in enumerate(rows):
        out["tl_valid"][row] = known
        out["tl_state"][row] = np.where(known, codes, 0)
        out["tl_lane_id"][row] = np.where(known, lane, -1)
        for axis, name in enumerate(("tl_x", "tl_y", "tl_z")):
            out[name][row] = np.where(known, point[axis], -1.0)
    return out


# --- scenarios -------------------------------------------------------------------------------------
def _window_field(values: np.ndarray, cut: slice, valid: np.ndarray) -> np.ndarray:
    """One window of a per-step array, -1 where invalid. (N, T10) -> (N, 91) float32"""
    return np.where(valid, values[:, cut], -1.0).astype(np.float32)


def _object_labels(meta: Mapping, keys: list, object_ids: np.ndarray, key_ids: Mapping) -> dict:
    to_predict = np.zeros(len(keys), bool)
    difficulty = np.zeros(len(keys), np.int64)
    row_of = {key: row for row, key in enumerate(keys)}
    predictions = meta.get("tracks_to_predict") or {}
    for track_key, info in (predictions.items() if isinstance(predictions, Mapping) else []):
        track_key = info.get("track_id", track_key) if isinstance(info, Mapping) else track_key
        for candidate in (track_key, str(track_key)):
            if candidate in row_of:
                to_predict[row_of[candidate]] = True
                if isinstance(info, Mapping) and info.get("difficulty") is not None:
                    difficulty[row_of[candidate]] = int(info["difficulty"])
                break
    interest = {str(k) for k in (meta.get("objects_of_interest") or [])}
    of_interest = np.array([str(key) in interest for key in keys], bool)
    return dict(tracks_to_predict=to_predict, difficulty_level=difficulty, objects_of_interest=of_interest)


def description_windows(desc: Mapping, sizes: Sizes, stride: int = DEFAULT_WINDOW_STRIDE
                        ) -> Iterator[Scenario | ScenarioBuildError]:
    """Every 91-step window (SDC valid throughout) of one scenario description, fitted to the budget."""
    if not isinstance(desc, Mapping) or "tracks" not in desc:
        yield ScenarioBuildError("not a ScenarioNet scenario description (no 'tracks')")
        return
    meta = desc.get("metadata", {}) or {}
    scenario_id = str(meta.get("scenario_id", desc.get("id", "unnamed")))
    tracks = desc["tracks"]
    keys = list(tracks)
    sdc_key = meta.get("sdc_id")
    if sdc_key not in tracks:
        yield ScenarioBuildError(f"scenario {scenario_id}: sdc_id {sdc_key!r} is not a track")
        return
    num_steps = int(np.size(tracks[sdc_key]["state"]["valid"]))
    times = source_times(desc, num_steps)
    plan = resample_indices(times)
    arrays = resample_tracks(track_arrays(tracks, num_steps), plan)
    num_steps_10hz = arrays["valid"].shape[1]
    current = int(meta.get("current_time_index", sizes.num_past)) if plan is None else sizes.num_past
    all_starts = window_starts(num_steps_10hz, current, sizes.num_past, sizes.num_timesteps, stride)
    sdc = keys.index(sdc_key)
    starts = [s for s in all_starts if arrays["valid"][sdc, s:s + sizes.num_timesteps].all()]
    if not starts:
        yield ScenarioBuildError(f"scenario {scenario_id}: no {sizes.num_timesteps}-step window at 10 Hz with the "
                                 f"SDC valid throughout ({num_steps_10hz} steps)")
        return
    key_ids = stable_int_ids(keys)
    object_ids = np.array([key_ids[k] for k in keys], np.int64)
    object_types = np.array([OBJECT_TYPES.get(str(tracks[k].get("type", "")), sch.OBJECT_TYPE_OTHER) for k in keys])
    is_sdc = np.arange(len(keys)) == sdc
    labels = _object_labels(meta, keys, object_ids, key_ids)
    features = desc.get("map_features", {}) or {}
    map_ids = stable_int_ids(features)
    polylines, links = map_polylines(features, map_ids)
    roadgraph = polylines_to_roadgraph(polylines)
    lane_graph = lane_graph_arrays(links, sizes.num_lane_links)
    lights = light_arrays(desc.get("dynamic_map_states", {}) or {}, map_ids, num_steps, plan)
    for start in starts:
        cut = slice(start, start + sizes.num_timesteps)
        valid = arrays["valid"][:, cut]
        field = functools.partial(_window_field, cut=cut, valid=valid)
        position, velocity = arrays["position"], arrays["velocity"]
        window_labels = labels if start + sizes.num_past == current else {
            name: np.zeros_like(value) for name, value in labels.items()}
        scenario = Scenario(
            scenario_id=scenario_id if len(all_starts) == 1 else f"{scenario_id}_t{start:03d}",
            object_id=object_ids, object_type=object_types, is_sdc=is_sdc, valid=valid,
            x=field(position[..., 0]), y=field(position[..., 1]), z=field(position[..., 2]),
            bbox_yaw=field(wrap_angle(arrays["heading"])), length=field(arrays["length"]),
            width=field(arrays["width"]), height=field(arrays["height"]),
            velocity_x=field(velocity[..., 0]), velocity_y=field(velocity[..., 1]),
            **window_labels, **roadgraph, **lane_graph,
            **{name: value[:, cut] for name, value in lights.items()},
            source_dataset=SOURCE_NAME, current_time_index=sizes.num_past,
            metadata={"dataset": str(meta.get("dataset", "")), "log_start_step": start},
        )
        yield fit_to_budget(scenario, sizes)

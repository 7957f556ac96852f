"""WOMD `Scenario` proto -> `Scenario`s (one per 91-step window).

Coordinates stay global (as the dataset gives them). Invalid states are filled with -1.
Map features become `MapPolyline`s (lane centrelines in driving direction, road edges oriented
with the road on their left) and `LaneLinks`; traffic-light lane states become (L, T) arrays.
"""

from __future__ import annotations

import operator
from collections.abc import Iterator

import numpy as np
from google.protobuf.message import DecodeError

from scenariomax import schema as sch
from scenariomax.enrich.budget import fit_to_budget
from scenariomax.enrich.orientation import orient_road_edges
from scenariomax.enrich.roadgraph import LaneLinks, MapPolyline, lane_graph_arrays, polylines_to_roadgraph
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.base import MANIFEST_NOTES
from scenariomax.sources.womd import bulk, proto
from scenariomax.sources.womd.sdc_paths import (
    PATHS_FROM_WAYMO,
    PATHS_SOURCE,
    SDC_PATHS_AUTO,
    SDC_PATHS_MODES,
    SDC_PATHS_RECONSTRUCT,
    SDC_PATHS_WAYMO,
    SdcPathError,
    decode_sdc_paths,
    waymo_path_arrays,
)
from scenariomax.sources.womd.windows import DEFAULT_WINDOW_STRIDE, window_starts, wrap_angle

MPH_TO_MPS = 0.44704
SOURCE_NAME = "womd"

# WOMD LaneCenter.type -> roadgraph type. Undefined lanes are still drivable lanes: surface street.
LANE_TYPES = {proto.LANE_TYPE_UNDEFINED: sch.RG_LANE_SURFACE_STREET, proto.LANE_TYPE_FREEWAY: sch.RG_LANE_FREEWAY,
              proto.LANE_TYPE_SURFACE_STREET: sch.RG_LANE_SURFACE_STREET, proto.LANE_TYPE_BIKE: sch.RG_LANE_BIKE}
# WOMD RoadLine.type 1..8 -> roadgraph types 6..13 (same order); unknown (0) stays unknown (0).
ROAD_LINE_TYPES = {0: 0, **{k: k + 5 for k in range(1, 9)}}
# WOMD RoadEdge.type -> roadgraph type; an unknown edge is treated as a boundary.
ROAD_EDGE_TYPES = {proto.ROAD_EDGE_UNKNOWN: sch.RG_ROAD_EDGE_BOUNDARY,
                   proto.ROAD_EDGE_BOUNDARY: sch.RG_ROAD_EDGE_BOUNDARY,
                   proto.ROAD_EDGE_MEDIAN: sch.RG_ROAD_EDGE_MEDIAN}
KNOWN_OBJECT_TYPES = (sch.OBJECT_TYPE_VEHICLE, sch.OBJECT_TYPE_PEDESTRIAN, sch.OBJECT_TYPE_CYCLIST,
                      sch.OBJECT_TYPE_OTHER)
_STATE_FIELDS = bulk.STATE_FIELDS
_STATE_GETTER = operator.attrgetter(*_STATE_FIELDS, "valid")
_POINT_GETTER = operator.attrgetter("x", "y", "z")
_FEATURE_ID = operator.attrgetter("feature_id")


class ScenarioBuildError(ValueError):
    """One scenario (or window) cannot be built; the message is one line."""


def parse_scenario(data: bytes, bulk: bool = False) -> proto.ScenarioProto:
    """The Scenario message; `bulk`: the variant that keeps track states and map points as bytes (read in one
    numpy pass by `track_arrays` and `map_polylines`: the same arrays, several times faster)."""
    message = proto.ScenarioBulkProto() if bulk else proto.ScenarioProto()
    try:
        message.ParseFromString(data)
    except (DecodeError, RuntimeError, ValueError) as error:
        raise ScenarioBuildError(f"not a WOMD Scenario message ({error})") from None
    return message


def parse_raw_scenario(data: bytes):
    """The Scenario's tracks and map features as their serialised bytes (`proto.ScenarioRawProto`; for
    `track_arrays` and `map_polylines`), or None when it does not parse."""
    try:
        return proto.ScenarioRawProto.FromString(data)
    except (DecodeError, RuntimeError, ValueError):
        return None


# --- tracks --------------------------------------------------------------------------------------
def track_arrays(message, raw_tracks: list[bytes] | None = None) -> dict[str, np.ndarray]:
    """Per-track state arrays over the whole log: (N, T) float64 for each state field, (N, T) bool valid.
    `raw_tracks`: the message's tracks serialised (`parse_raw_scenario`), which lets a bulk message's states be
    decoded a track at a time."""
    num_steps = len(message.timestamps_seconds) or max((len(t.states) for t in message.tracks), default=0)
    num_tracks = len(message.tracks)
    for track in message.tracks:
        if len(track.states) != num_steps:
            raise ScenarioBuildError(f"track {track.id} has {len(track.states)} states, expected {num_steps}")
    table = None
    if proto.is_bulk(message) and raw_tracks is not None and len(raw_tracks) == num_tracks:
        table = bulk.track_state_table(raw_tracks, num_steps)  # None: some track is laid out otherwise
    if table is None and proto.is_bulk(message):  # serialised states, decoded with numpy
        try:
            table = bulk.state_table([state for track in message.tracks for state in track.states])
        except ValueError as error:
            raise ScenarioBuildError(str(error)) from None
    elif table is None:  # every state read in one C-level pass (attrgetter: the fields, then valid); one conversion
        table = np.array([state for track in message.tracks for state in map(_STATE_GETTER, track.states)],
                         np.float64)
    table = table.reshape(num_tracks, num_steps, len(_STATE_FIELDS) + 1)  # (N, T, F + 1)
    valid = table[:, :, -1] != 0  # (N, T)
    values = np.where(valid[:, :, None], table[:, :, :-1], -1.0).transpose(2, 0, 1)  # (F, N, T)
    out = dict(zip(_STATE_FIELDS, values))
    out["valid"] = valid
    return out


# --- map -----------------------------------------------------------------------------------------
def _point_arrays(containers: list, serialised: bool = False, features: list[bytes] | None = None) -> list[np.ndarray]:
    """The points of every map feature (MapPoint messages, or their bytes when `serialised`), converted in one
    pass: (n_i, 3) float64 each. `features`: the serialised MapFeature of each container (bulk only), whose
    points are decoded a whole polyline at a time where Waymo's layout allows (`bulk.feature_points`)."""
    counts = [len(points) for points in containers]
    out: list = [None] * len(containers)
    if serialised and features is not None:
        out = bulk.feature_points(features, counts)
    rest = [row for row, xyz in enumerate(out) if xyz is None]  # every container when not decoded by feature
    if not rest:
        return out
    if serialised:
        try:
            table = bulk.point_table([point for row in rest for point in containers[row]])
        except ValueError as error:
            raise ScenarioBuildError(str(error)) from None
    else:
        rows = [xyz for row in rest for xyz in map(_POINT_GETTER, containers[row])]
        table = np.array(rows, np.float64).reshape(-1, 3)  # (sum n_i, 3)
    stops = np.cumsum([counts[row] for row in rest]).tolist()
    for row, stop in zip(rest, stops):
        out[row] = table[stop - counts[row]:stop]
    return out


def map_polylines(message, orient_edges: bool = True,
                  raw_features: list[bytes] | None = None) -> tuple[list[MapPolyline], list[LaneLinks]]:
    """Map features -> polylines (road edges oriented, road on the left, unless `orient_edges` is False) and lane
    links. `raw_features`: the message's map features serialised (`parse_raw_scenario`), which lets a bulk
    message's points be decoded a polyline at a time."""
    features: list[tuple] = []  # (id, roadgraph type, points container, speed limit, closed)
    links: list[LaneLinks] = []
    kept: list[int] = []  # index in map_features of each entry of `features`
    for index, feature in enumerate(message.map_features):
        kind = feature.WhichOneof("feature_data")
        fid = int(feature.id)
        if kind == "lane":
            lane = feature.lane
            limit = lane.speed_limit_mph * MPH_TO_MPS if lane.speed_limit_mph > 0 else -1.0
            features.append((fid, LANE_TYPES.get(lane.type, sch.RG_LANE_SURFACE_STREET), lane.polyline,
                             float(limit), False))
            # Positional (successors, predecessors, left, right neighbours): keywords cost more per lane.
            links.append(LaneLinks(fid, list(lane.exit_lanes), list(lane.entry_lanes),
                                   list(map(_FEATURE_ID, lane.left_neighbors)),
                                   list(map(_FEATURE_ID, lane.right_neighbors))))
        elif kind == "road_line":
            features.append((fid, ROAD_LINE_TYPES.get(feature.road_line.type, 0), feature.road_line.polyline,
                             -1.0, False))
        elif kind == "road_edge":
            features.append((fid, ROAD_EDGE_TYPES.get(feature.road_edge.type, sch.RG_ROAD_EDGE_BOUNDARY),
                             feature.road_edge.polyline, -1.0, False))
        elif kind == "stop_sign":
            features.append((fid, sch.RG_STOP_SIGN, [feature.stop_sign.position], -1.0, False))
        elif kind in ("crosswalk", "speed_bump", "driveway"):
            rg_type = {"crosswalk": sch.RG_CROSSWALK, "speed_bump": sch.RG_SPEED_BUMP,
                       "driveway": sch.RG_DRIVEWAY}[kind]
            features.append((fid, rg_type, getattr(feature, kind).polygon, -1.0, True))
        if len(features) > len(kept):
            kept.append(index)
    serialised = proto.is_bulk(message)
    raw = ([raw_features[index] for index in kept]
           if serialised and raw_features is not None and len(raw_features) == len(message.map_features) else None)
    points = _point_arrays([container for _, _, container, _, _ in features], serialised, raw)
    polylines = [MapPolyline(fid, rg_type, xyz, speed_limit=limit, closed=closed)
                 for (fid, rg_type, _, limit, closed), xyz in zip(features, points) if len(xyz)]
    return (orient_road_edges(polylines) if orient_edges else polylines), links


# --- traffic lights ------------------------------------------------------------------------------
_LANE_STATE_GETTER = operator.attrgetter("lane", "state", "stop_point.x", "stop_point.y", "stop_point.z")


def traffic_light_arrays(message, start: int, num_timesteps: int) -> dict[str, np.ndarray]:
    """(L, T) light arrays for one window, one row per controlled lane (sorted by lane id)."""
    steps = message.dynamic_map_states[start:start + num_timesteps]
    step = np.repeat(np.arange(len(steps)), [len(dynamic.lane_states) for dynamic in steps])  # (k,)
    if proto.is_bulk(message):  # serialised lane states, decoded with numpy
        try:
            lane, code, point = bulk.lane_state_table([report for dynamic in steps for report in dynamic.lane_states])
        except ValueError as error:
            raise ScenarioBuildError(str(error)) from None
    else:  # every lane state read in one pass (attrgetter), then placed with numpy
        read = [values for dynamic in steps for values in map(_LANE_STATE_GETTER, dynamic.lane_states)]
        lane = np.array([values[0] for values in read], np.int64).reshape(-1)  # (k,)
        code = np.array([values[1] for values in read], np.int64).reshape(-1)
        point = np.array([values[2:] for values in read], np.float64).reshape(-1, 3)  # (k, 3)
    lanes = np.unique(lane)  # (L,) sorted
    shape = (len(lanes), num_timesteps)
    state, lane_id = np.zeros(shape, np.int64), np.full(shape, -1, np.int64)
    valid = np.zeros(shape, bool)
    xyz = np.full((3,) + shape, -1.0, np.float32)
    if len(lane):
        row = np.searchsorted(lanes, lane)
        # A lane reported twice in one step: its last report counts (as when written one by one).
        last = len(lane) - 1 - np.unique((row * num_timesteps + step)[::-1], return_index=True)[1]
        row, step, lane, code, point = row[last], step[last], lane[last], code[last], point[last]
        known = np.isin(code, list(sch.load_schema().enums["traffic_light_state"]))
        valid[row, step] = True
        state[row, step] = np.where(known, code, sch.TL_UNKNOWN)
        lane_id[row, step] = lane
        xyz[:, row, step] = point.T
    return dict(tl_state=state, tl_valid=valid, tl_lane_id=lane_id, tl_x=xyz[0], tl_y=xyz[1], tl_z=xyz[2])


# --- scenarios -----------------------------------------------------------------------------------
def _object_fields(message) -> dict[str, np.ndarray]:
    num_tracks = len(message.tracks)
    types = np.array([t.object_type for t in message.tracks], np.int64)
    is_sdc = np.zeros(num_tracks, bool)
    if not 0 <= message.sdc_track_index < num_tracks:
        raise ScenarioBuildError(f"sdc_track_index {message.sdc_track_index} is outside the {num_tracks} tracks")
    is_sdc[message.sdc_track_index] = True
    ids = np.array([t.id for t in message.tracks], np.int64)
    difficulty = np.zeros(num_tracks, np.int64)
    to_predict = np.zeros(num_tracks, bool)
    for required in message.tracks_to_predict:
        if 0 <= required.track_index < num_tracks:
            to_predict[required.track_index] = True
            difficulty[required.track_index] = required.difficulty
    interest_ids = set(message.objects_of_interest)
    return dict(
        object_id=ids,
        object_type=np.where(np.isin(types, KNOWN_OBJECT_TYPES), types, sch.OBJECT_TYPE_OTHER),
        is_sdc=is_sdc,
        tracks_to_predict=to_predict,
        difficulty_level=difficulty,
        objects_of_interest=np.array([int(i) in interest_ids for i in ids], bool),
    )


def _window(tracks: dict, start: int, num_timesteps: int, seconds: np.ndarray) -> dict[str, np.ndarray]:
    cut = slice(start, start + num_timesteps)
    valid = tracks["valid"][:, cut]

    def field(name: str) -> np.ndarray:
        return np.where(valid, tracks[name][:, cut], -1.0).astype(np.float32)

    yaw = np.where(valid, wrap_angle(tracks["heading"][:, cut]), -1.0)
    if len(seconds) >= start + num_timesteps:
        micros = np.round((seconds[cut] - seconds[start]) * 1e6).astype(np.int64)
    else:
        micros = np.arange(num_timesteps, dtype=np.int64) * 100_000
    return dict(
        x=field("center_x"), y=field("center_y"), z=field("center_z"), bbox_yaw=yaw.astype(np.float32),
        length=field("length"), width=field("width"), height=field("height"),
        velocity_x=field("velocity_x"), velocity_y=field("velocity_y"), valid=valid,
        timestamp_micros=np.where(valid, micros[None, :], -1), tl_timestamp_micros=micros,
    )


def _waymo_paths(message, sdc_paths: str, sizes: Sizes) -> dict | None:
    """Waymo's paths as our path arrays, or None when reconstruction is asked for (or, in "auto", when the
    proto has none). Raises ScenarioBuildError when "waymo" is asked for and they are missing or unreadable."""
    if sdc_paths not in SDC_PATHS_MODES:
        raise ValueError(f"sdc_paths must be one of {SDC_PATHS_MODES}, got {sdc_paths!r}")
    if sdc_paths == SDC_PATHS_RECONSTRUCT or (sdc_paths == SDC_PATHS_AUTO and not message.sdc_paths):
        return None
    try:
        paths = decode_sdc_paths(message)
    except SdcPathError as error:
        raise ScenarioBuildError(f"scenario {message.scenario_id or 'unnamed'}: {error}") from None
    if not paths:
        if sdc_paths == SDC_PATHS_AUTO:
            return None  # all of them empty: as if absent
        raise ScenarioBuildError(f"scenario {message.scenario_id or 'unnamed'}: no Waymo SDC paths in the proto "
                                 "(WOMD before 1.3.1?); use --sdc-paths auto or reconstruct")
    return waymo_path_arrays(paths, sizes.num_paths, sizes.num_points_per_path)


def scenario_windows(message, sizes: Sizes, stride: int = DEFAULT_WINDOW_STRIDE, sdc_paths: str = SDC_PATHS_AUTO,
                     orient_edges: bool = True,
                     raw=None) -> Iterator[Scenario | ScenarioBuildError]:
    """Every 91-step window of one WOMD Scenario message, fitted to the budget. Windows that cannot be
    built are yielded as ScenarioBuildError (the caller records them as Failures). `sdc_paths` chooses
    who makes the SDC paths (see sdc_paths.py): Waymo's paths start at the log's own current step, so
    they go to that window only; the others are left to the reconstruction. `orient_edges`: see `WomdSource`.
    `raw`: the record's `parse_raw_scenario` (faster decoding of the same values), or None."""
    scenario_id = message.scenario_id or "unnamed"
    num_steps = len(message.timestamps_seconds)
    current = message.current_time_index if message.HasField("current_time_index") else sizes.num_past
    starts = window_starts(num_steps, current, sizes.num_past, sizes.num_timesteps, stride)
    if not starts:
        yield ScenarioBuildError(f"scenario {scenario_id}: {num_steps} steps with current index {current} "
                                 f"cannot hold a {sizes.num_timesteps}-step window")
        return
    try:
        waymo_paths = _waymo_paths(message, sdc_paths, sizes)
    except ScenarioBuildError as error:
        yield error
        return
    tracks = track_arrays(message, None if raw is None else raw.tracks)
    objects = _object_fields(message)
    polylines, links = map_polylines(message, orient_edges, None if raw is None else raw.map_features)
    roadgraph = polylines_to_roadgraph(polylines)
    lane_graph = lane_graph_arrays(links, sizes.num_lane_links)
    seconds = np.asarray(message.timestamps_seconds, np.float64)
    sdc = int(np.flatnonzero(objects["is_sdc"])[0])
    for start in starts:
        window_id = scenario_id if len(starts) == 1 else f"{scenario_id}_t{start:03d}"
        window = _window(tracks, start, sizes.num_timesteps, seconds)
        if not window["valid"][sdc, sizes.num_past]:
            yield ScenarioBuildError(f"scenario {window_id}: the SDC is not valid at the current step")
            continue
        per_object = dict(objects)
        at_log_current = start + sizes.num_past == current
        if not at_log_current:  # prediction labels belong to the log's own current step
            for name in ("tracks_to_predict", "objects_of_interest"):
                per_object[name] = np.zeros_like(objects[name])
            per_object["difficulty_level"] = np.zeros_like(objects["difficulty_level"])
        paths, metadata = {}, {"log_start_step": start, "log_num_steps": num_steps}
        if waymo_paths is not None and at_log_current:
            paths = waymo_paths
            metadata.update({PATHS_SOURCE: PATHS_FROM_WAYMO, MANIFEST_NOTES: {PATHS_SOURCE: PATHS_FROM_WAYMO}})
        elif waymo_paths is not None and sdc_paths == SDC_PATHS_WAYMO:
            yield ScenarioBuildError(f"scenario {window_id}: Waymo's SDC paths start at the log's current step "
                                     f"{current}, not this window's ({start + sizes.num_past})")
            continue
        scenario = Scenario(
            scenario_id=window_id, source_dataset=SOURCE_NAME, current_time_index=sizes.num_past,
            **per_object, **window, **roadgraph, **lane_graph, **paths,
            **traffic_light_arrays(message, start, sizes.num_timesteps),
            metadata=metadata,
        )
        yield fit_to_budget(scenario, sizes)

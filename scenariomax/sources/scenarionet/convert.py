"""ScenarioNet / MetaDrive scenario description (a dict) -> `Scenario`s, one per 91-step window.

Tracks are resampled to 10 Hz when the description's sample rate differs, then cut into windows
(see `scenariomax.sources.womd.windows.log_window_starts`); windows where the SDC is valid at the
current step are kept. A log shorter than a window gives one window whose steps past the log's end
are invalid (noted in the manifest). String ids are mapped to ints with a stable table (see
`stable_int_ids`).

Descriptions from every MetaDrive / ScenarioNet generation are accepted (docs/datasets.md lists the
layouts): `metadata` may be empty, partial or missing (the SDC and the time step are then derived,
see `named_sdc`, `derived_sdc` and `source_times`); a track's state may be a dict under "state", its
fields on the track itself, or one (T, 10) array; box sizes may be one (T, 3) `size`; traffic lights
may store their lane and stop point once or per step. Tracks that cannot be read are dropped and
noted, not fatal (unless one is the SDC).
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import math
import re
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich.budget import fit_to_budget
from scenariomax.enrich.orientation import orient_road_edges
from scenariomax.enrich.roadgraph import (
    DEFAULT_SPACING_M,
    LaneLinks,
    MapPolyline,
    lane_graph_arrays,
    polylines_to_roadgraph,
)
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.base import MANIFEST_NOTES
from scenariomax.sources.sanity import STEP_SECONDS, is_nominal_10hz, swap_rows, wider_than_long
from scenariomax.sources.scenarionet.unpickle import EnumValue
from scenariomax.sources.womd.convert import ROAD_EDGE_TYPES, ROAD_LINE_TYPES, ScenarioBuildError
from scenariomax.sources.womd.windows import (
    DEFAULT_WINDOW_STRIDE,
    log_window_starts,
    window_notes,
    window_steps,
    wrap_angle,
)

SOURCE_NAME = "scenarionet"
MPH_TO_MPS, KMH_TO_MPS = 0.44704, 1.0 / 3.6

# What one description may make us build (the unpickler already caps the file and its expansion;
# these cap what the conversion itself allocates, whatever the file's own numbers claim).
MAX_TRACKS = 10_000
MAX_CELLS = 4_000_000  # tracks x steps (source rate and 10 Hz), and lights x steps
MAX_MAP_POINTS = 2_000_000  # roadgraph samples at DEFAULT_SPACING_M before the budget crop
SDC_NAMES = ("ego", "sdc", "av", "default_agent")  # track keys that name the SDC when metadata does not

OBJECT_TYPES = {"VEHICLE": sch.OBJECT_TYPE_VEHICLE, "PEDESTRIAN": sch.OBJECT_TYPE_PEDESTRIAN,
                "CYCLIST": sch.OBJECT_TYPE_CYCLIST}  # anything else (barriers, cones, OTHER...) -> other
MAP_TYPES = {
    "LANE_FREEWAY": sch.RG_LANE_FREEWAY, "LANE_SURFACE_STREET": sch.RG_LANE_SURFACE_STREET,
    "LANE_BIKE_LANE": sch.RG_LANE_BIKE, "LANE_UNKNOWN": sch.RG_LANE_SURFACE_STREET,
    "LANE_SURFACE_UNSTRUCTURE": sch.RG_LANE_SURFACE_STREET,
    "ROAD_LINE_UNKNOWN": 0, "UNKNOWN_LINE": 0,
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
    "STOP_SIGN": sch.RG_STOP_SIGN, "CROSSWALK": sch.RG_CROSSWALK, "CROSS_WALK": sch.RG_CROSSWALK,
    "SPEED_BUMP": sch.RG_SPEED_BUMP, "DRIVEWAY": sch.RG_DRIVEWAY,
    # MetaDrive's own names before the March 2023 Scenario Description (its "old format" files)
    "center_lane": sch.RG_LANE_SURFACE_STREET, "stop_sign": sch.RG_STOP_SIGN, "cross_walk": sch.RG_CROSSWALK,
    # MetaDrive, March 2023 ("Mar23"): WOMD's solid double white line, and "UNKNOWN" for type 0 of a lane, a
    # road line or a road edge alike (a lane is told by its links, see `feature_type`; the others stay 0)
    "ROAD_LINE_DOUBLE_WHITE": sch.RG_SOLID_DOUBLE_WHITE, "UNKNOWN": 0,
}
_LANE_KEYS = ("entry_lanes", "exit_lanes", "entry", "exit", "left_boundaries", "right_boundaries")
# MetaDrive 2021-2022 pickled enum members (see unpickle.WRITER_ENUMS) whose values are the WOMD protos':
# Track.ObjectType for tracks, RoadLine.RoadLineType / RoadEdge.RoadEdgeType for map features.
ENUM_OBJECT_TYPES = {1: sch.OBJECT_TYPE_VEHICLE, 2: sch.OBJECT_TYPE_PEDESTRIAN, 3: sch.OBJECT_TYPE_CYCLIST}
ENUM_MAP_TYPES = {"RoadLineType": ROAD_LINE_TYPES, "RoadEdgeType": ROAD_EDGE_TYPES}
_CLOSED_TYPES = (sch.RG_CROSSWALK, sch.RG_SPEED_BUMP, sch.RG_DRIVEWAY)
# MetaDrive light strings and WOMD lane-state strings -> WOMD light enum. Early MetaDrive stored the
# WOMD enum itself (ints 0..8), which is our enum too.
LIGHT_STATES = {
    "TRAFFIC_LIGHT_RED": sch.TL_STOP, "TRAFFIC_LIGHT_YELLOW": sch.TL_CAUTION, "TRAFFIC_LIGHT_GREEN": sch.TL_GO,
    "TRAFFIC_LIGHT_UNKNOWN": sch.TL_UNKNOWN,
    "LANE_STATE_UNKNOWN": sch.TL_UNKNOWN, "LANE_STATE_ARROW_STOP": sch.TL_ARROW_STOP,
    "LANE_STATE_ARROW_CAUTION": sch.TL_ARROW_CAUTION, "LANE_STATE_ARROW_GO": sch.TL_ARROW_GO,
    "LANE_STATE_STOP": sch.TL_STOP, "LANE_STATE_CAUTION": sch.TL_CAUTION, "LANE_STATE_GO": sch.TL_GO,
    "LANE_STATE_FLASHING_STOP": sch.TL_FLASHING_STOP, "LANE_STATE_FLASHING_CAUTION": sch.TL_FLASHING_CAUTION,
}
_MAX_LIGHT_ENUM = sch.TL_FLASHING_CAUTION


def stable_int_ids(keys) -> dict[Any, int]:
    """Deterministic int ids: the keys themselves when all are integers (or decimal strings), else
    their rank in the list sorted by str(key)."""
    keys = list(keys)
    if all(isinstance(k, (int, np.integer)) or (isinstance(k, str) and k.isdigit()) for k in keys):
        return {k: int(k) for k in keys}
    return {k: rank for rank, k in enumerate(sorted(keys, key=str))}


# --- header: ids, SDC, times -----------------------------------------------------------------------
def as_mapping(value) -> Mapping:
    """`value` when it is a dict, else {} (early MetaDrive files leave parts out or use lists)."""
    return value if isinstance(value, Mapping) else {}


def _given(value) -> bool:
    return value is not None and not (isinstance(value, str) and not value)


def scenario_name(desc: Mapping, default: str = "unnamed") -> str:
    meta = as_mapping(desc.get("metadata"))
    for value in (meta.get("scenario_id"), meta.get("id"), desc.get("id")):
        if _given(value) and isinstance(value, (str, int, np.integer, np.str_)):
            return str(value)
    return default


def _track_key(tracks: Mapping, value):
    """The key of `tracks` that `value` names (as stored, or spelt as str or int), else None."""
    candidates = [value, str(value)]
    if isinstance(value, str) and value.isdigit():
        candidates.append(int(value))
    for candidate in candidates:
        try:
            if candidate in tracks:
                return candidate
        except TypeError:  # unhashable value
            continue
    return None


def named_sdc(desc: Mapping, keys: list) -> Any | None:
    """The SDC track key the description names: metadata `sdc_id`, or the top-level `sdc_id` /
    `sdc_track_index` / `sdc_index` of early MetaDrive files (a key, else a position). None when
    nothing names it; ScenarioBuildError when the name matches no track."""
    meta = as_mapping(desc.get("metadata"))
    tracks = dict.fromkeys(keys)
    for source, field in ((meta, "sdc_id"), (desc, "sdc_id"), (meta, "sdc_track_index"),
                          (desc, "sdc_track_index"), (desc, "sdc_index")):
        value = source.get(field)
        if not _given(value):
            continue
        key = _track_key(tracks, value)
        if key is not None:
            return key
        if field != "sdc_id" and isinstance(value, (int, np.integer)) and 0 <= value < len(keys):
            return keys[int(value)]
        raise ScenarioBuildError(f"{field} {value!r} is not a track")
    return None


def derived_sdc(keys: list, types: np.ndarray, valid: np.ndarray, position: np.ndarray) -> int:
    """Row of the SDC when nothing names it: a track keyed "ego"/"sdc"/"av"/"default_agent", else the
    vehicle valid at every step that travels furthest (the logging car is recorded throughout)."""
    for row, key in enumerate(keys):
        if str(key).lower() in SDC_NAMES:
            return row
    always = valid.all(axis=1) & (types == sch.OBJECT_TYPE_VEHICLE)
    if not always.any():
        raise ScenarioBuildError("no sdc_id, and no vehicle track is valid at every step to stand in for it")
    travel = np.linalg.norm(np.diff(position[..., :2], axis=1), axis=-1).sum(axis=1)
    return int(np.argmax(np.where(always, np.nan_to_num(travel, nan=-1.0), -2.0)))


def _increasing_times(ts, num_steps: int) -> np.ndarray | None:
    if ts is None or np.size(ts) != num_steps:
        return None
    try:
        times = np.asarray(ts, np.float64).ravel()
    except (TypeError, ValueError):
        return None
    if not np.all(np.isfinite(times)) or (num_steps > 1 and not np.all(np.diff(times) > 0)):
        return None
    return times - times[0]


def source_times(desc: Mapping, num_steps: int) -> np.ndarray:
    """Seconds of each source step: timestamps (`metadata.ts`, or the top-level `ts` of early
    MetaDrive files) when one per step and increasing, else a fixed `timestep` / `sample_rate`,
    else MetaDrive's 0.1 s."""
    meta = as_mapping(desc.get("metadata"))
    for ts in (meta.get("ts"), desc.get("ts")):
        times = _increasing_times(ts, num_steps)
        if times is not None:
            return times
    step = float(meta.get("timestep") or meta.get("sample_rate") or desc.get("timestep") or STEP_SECONDS)
    if not (np.isfinite(step) and step > 0):
        raise ScenarioBuildError(f"bad time step {step}")
    return np.arange(num_steps) * step


def grid_steps(times: np.ndarray) -> int:
    """Number of 10 Hz steps covering `times` (from 0)."""
    return int(np.floor(times[-1] / STEP_SECONDS + 1e-6)) + 1 if len(times) else 0


def resample_indices(times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """For a 10 Hz grid over `times`: (lower index, upper index, weight of upper) per target step,
    or None when the source is already at 10 Hz."""
    if is_nominal_10hz(times):
        return None
    target = np.arange(grid_steps(times)) * STEP_SECONDS
    upper = np.clip(np.searchsorted(times, target - 1e-9), 0, len(times) - 1)
    lower = np.clip(upper - 1, 0, len(times) - 1)
    exact = np.isclose(times[upper], target, atol=1e-6)
    lower = np.where(exact, upper, lower)
    span = times[upper] - times[lower]
    weight = np.where(span > 0, (target - times[lower]) / np.where(span > 0, span, 1.0), 0.0)
    return lower, upper, weight


def check_cells(rows: int, steps: int, what: str) -> None:
    """Refuses arrays of rows x steps beyond `MAX_CELLS` before they are allocated."""
    if rows * steps > MAX_CELLS:
        raise ScenarioBuildError(f"{rows} {what} x {steps} steps is more than the {MAX_CELLS} cells allowed")


def _interp(values: np.ndarray, plan) -> np.ndarray:
    lower, upper, weight = plan
    w = weight.reshape((1, -1) + (1,) * (values.ndim - 2))
    return values[:, lower] * (1 - w) + values[:, upper] * w


# --- tracks ----------------------------------------------------------------------------------------
# Columns of the single (T, 10) state array MetaDrive wrote in 2021-2022.
STATE_COLUMNS = {"position": slice(0, 3), "length": 3, "width": 4, "height": 5, "heading": 6,
                 "velocity": slice(7, 9), "valid": 9}
HEADING_NAMES = ("heading", "heading_theta", "yaw")  # MetaDrive's object states call it heading_theta
SIZE_NAMES = ("length", "width", "height")
# MetaDrive's exports (`convert_recorded_scenario_exported`, since April 2023) write a box size only for objects
# that report one; its traffic cones, warning triangles (typed TRAFFIC_OBJECT) and barriers never do, and
# ScenarioNet's PG converter places them. Their sizes from MetaDrive's own classes, (length along the heading,
# width, height) m: a cone is a cylinder of radius 0.2, a triangle of radius 0.5, a barrier 0.3 deep and 2 across.
# Its pedestrians and cyclists reported none either until MetaDrive 8fffccd9 (2024-12-02) gave them `get_state`:
# MetaDrive's pedestrian is a cylinder of radius 0.35 and height 1.75, its cyclist 1.75 long, 0.4 wide, 1.75 high.
STATIC_OBJECT_SIZES = {"TRAFFIC_CONE": (0.4, 0.4, 2.0), "TRAFFIC_OBJECT": (1.0, 1.0, 1.2),
                       "TRAFFIC_BARRIER": (0.3, 2.0, 2.0), "PEDESTRIAN": (0.7, 0.7, 1.75),
                       "CYCLIST": (1.75, 0.4, 1.75)}


def _raw_state(track) -> Mapping | np.ndarray | None:
    """The state as written: `track["state"]` (a dict, or the 2021-2022 array), or the track itself when
    its fields sit on it (MetaDrive's March 2023 "old format": type, position, size... side by side)."""
    if not isinstance(track, Mapping):
        return None
    state = track.get("state")
    if isinstance(state, (Mapping, np.ndarray)):
        return state
    return track if "valid" in track else None


def _split_size(size) -> dict[str, np.ndarray]:
    """length / width / height from one `size`: (T, 3) per step, or (3,) for the whole track."""
    size = np.asarray(size, np.float64)
    if size.ndim == 1 and size.size == 3:
        return {name: np.full(1, size[i]) for i, name in enumerate(SIZE_NAMES)}  # repeated by `_per_step`
    size = size.reshape(len(size), -1)
    if size.shape[1] < 3:
        raise ValueError(f"size of shape {size.shape} (expected (T, 3))")
    return {name: size[:, i] for i, name in enumerate(SIZE_NAMES)}


def track_state(key, track) -> Mapping:
    """One track's per-step fields under our names, whatever the writer's generation (see `_raw_state`):
    position, heading, velocity, length, width, height, valid. ScenarioBuildError without `valid`."""
    state = _raw_state(track)
    if isinstance(state, np.ndarray):
        if state.ndim != 2 or state.shape[1] < 10:
            raise ScenarioBuildError(f"track {key}: state array of shape {state.shape} (expected (T, 10))")
        return {name: state[:, column] for name, column in STATE_COLUMNS.items()}
    if not isinstance(state, Mapping) or "valid" not in state:
        raise ScenarioBuildError(f"track {key}: no state with 'valid'")
    if "heading" in state and all(name in state for name in SIZE_NAMES):
        return state  # ScenarioNet's own layout: nothing to rename
    out = dict(state)
    heading = next((name for name in HEADING_NAMES if name in state), None)
    if heading is not None:
        out["heading"] = state[heading]
    if not all(name in state for name in SIZE_NAMES) and "size" in state:
        try:
            out.update(_split_size(state["size"]))
        except (ValueError, TypeError) as error:
            raise ScenarioBuildError(f"track {key}: bad size ({error})") from None
    out.update(class_size(track, state) or {})
    return out


def class_size(track, state) -> dict[str, np.ndarray] | None:
    """length / width / height of a static object written without any size (STATIC_OBJECT_SIZES), else None."""
    if not isinstance(state, Mapping) or "size" in state or any(name in state for name in SIZE_NAMES):
        return None
    kind = as_mapping(track).get("type")
    size = STATIC_OBJECT_SIZES.get(kind) if isinstance(kind, str) else None
    return None if size is None else {name: np.full(1, value) for name, value in zip(SIZE_NAMES, size)}


def common_length(tracks: Mapping) -> int:
    """Steps per track: the most common length of `valid` among readable tracks (ScenarioNet tracks share one)."""
    lengths = collections.Counter()
    for key, track in tracks.items():
        try:
            lengths[int(np.size(track_state(key, track)["valid"]))] += 1
        except ScenarioBuildError:
            continue  # dropped later, with the reason noted
    return lengths.most_common(1)[0][0] if lengths else 0


def sdc_length(key, track) -> int:
    """Steps of the named SDC's track: the log's length."""
    try:
        return int(np.size(track_state(key, track)["valid"]))
    except ScenarioBuildError as error:
        raise ScenarioBuildError(f"the SDC's {error}") from None


def _per_step(state: Mapping, key: str, num_steps: int, width: int | None = None) -> np.ndarray:
    if key not in state:
        missing = "heading (nor heading_theta)" if key == "heading" else \
            f"{key} (nor size)" if key in SIZE_NAMES else key
        raise KeyError(f"no {missing}")
    value = np.asarray(state[key], np.float64)
    if value.size == 1 and num_steps != 1:  # one value for the whole track
        value = np.full(num_steps * (width or 1), float(value.ravel()[0]))
    if width is None:
        value = value.reshape(num_steps, -1)[:, 0] if value.size else np.zeros(num_steps)
        return value
    value = value.reshape(num_steps, -1)
    if value.shape[1] < width:  # 2-D positions: z = 0
        value = np.concatenate([value, np.zeros((num_steps, width - value.shape[1]))], axis=1)
    return value[:, :width]


def track_row(key, track, num_steps: int) -> dict[str, np.ndarray]:
    """One track's source-rate fields; ScenarioBuildError naming the track and the cause."""
    state = track_state(key, track)
    try:
        row = {"position": _per_step(state, "position", num_steps, 3),
               "velocity": _per_step(state, "velocity", num_steps, 2) if "velocity" in state
               else np.zeros((num_steps, 2))}  # absent in some exports: the sanity pass derives it
        for name in ("heading", "length", "width", "height", "valid"):
            row[name] = _per_step(state, name, num_steps)
    except KeyError as error:
        raise ScenarioBuildError(f"track {key}: {error.args[0] if error.args else error}") from None
    except (ValueError, TypeError) as error:
        raise ScenarioBuildError(f"track {key}: bad state ({type(error).__name__}: {error})") from None
    return row


def track_arrays(tracks: Mapping, num_steps: int, keep=None) -> tuple[dict[str, np.ndarray], list, dict[str, str]]:
    """Source-rate arrays of the readable tracks: position (N, T, 3), heading/length/width/height (N, T),
    velocity (N, T, 2), valid; their keys; and {key: why} for the tracks dropped. A track that cannot be
    read (another length, a missing field) is dropped, unless it is `keep` (the SDC): then it fails."""
    rows = {name: [] for name in ("position", "heading", "velocity", "length", "width", "height", "valid")}
    keys, dropped = [], {}
    for key, track in tracks.items():
        try:
            row = track_row(key, track, num_steps)
        except ScenarioBuildError as error:
            if keep is not None and key == keep:
                raise ScenarioBuildError(f"the SDC's {error}") from None
            dropped[str(key)] = str(error).removeprefix(f"track {key}: ")
            continue
        keys.append(key)
        for name, value in row.items():
            rows[name].append(value)
    out = {name: np.stack(values) if values else np.zeros((0, num_steps)) for name, values in rows.items()}
    if not keys:
        out["position"], out["velocity"] = np.zeros((0, num_steps, 3)), np.zeros((0, num_steps, 2))
    out["valid"] = (out["valid"] > 0.5) & _finite_steps(out)
    return out, keys, dropped


def finite32(values: np.ndarray) -> np.ndarray:
    """Where values survive the float32 shards (NaN, inf and 1e300 do not)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.isfinite(np.asarray(values).astype(np.float32))


def _finite_steps(arrays: dict) -> np.ndarray:
    """Steps with every value usable; a NaN position is not a valid step."""
    finite = [finite32(arrays[name]) for name in ("position", "velocity", "heading", "length", "width", "height")]
    return np.all([f.all(axis=-1) if f.ndim == 3 else f for f in finite], axis=0)


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
    if array.size == 0 or array.ndim != 2:
        return np.zeros((0, 3))
    if array.shape[1] == 2:
        array = np.concatenate([array, np.zeros((len(array), 1))], axis=1)
    return array[:, :3]


def _link_ids(values, ids: Mapping) -> list[int]:
    out = []
    for value in values if isinstance(values, (list, tuple, np.ndarray)) else []:
        key = value.get("feature_id", value.get("id")) if isinstance(value, Mapping) else value
        for candidate in (key, str(key)):
            try:
                if candidate in ids:
                    out.append(ids[candidate])
                    break
            except TypeError:  # unhashable
                continue
    return out


# ScenarioNet's nuScenes, nuPlan and Argoverse 2 converters write the outline of the drivable area (its polygons'
# union) as solid white lines keyed "boundary_<n>": those maps have no road-edge layer, and this outline is the
# kerb. Read as a painted line, the map had no road edge at all (no off-road, nothing for the observation's edges)
DRIVABLE_OUTLINE_PREFIX = "boundary_"

# ScenarioNet's nuScenes and Argoverse 2 converters write one constant on every lane (100 km/h; 85 mph): those
# maps carry no speed limits, so the value is the writer's placeholder, not the road's (-1: unknown, and the
# enrichment's lane-type default applies, as for our own AV2 converter)
DATASETS_WITHOUT_SPEED_LIMITS = ("nuscenes", "av2", "argoverse")


def map_has_speed_limits(desc: Mapping, meta: Mapping) -> bool:
    """False for databases whose writer put a placeholder in every lane's speed limit (metadata `dataset`, or the
    `version` prefix that older writers set alone, e.g. "nuscenesv1.0-mini"). MetaDrive's re-exports of a
    scene (`dataset` "metadrive", the source's metadata under `history_metadata`) write 100 km/h on every lane
    that had no km/h or mph value: every nuScenes, AV2 and nuPlan lane (whose m/s values it does not read)."""
    source = str(as_mapping(meta.get("history_metadata")).get("dataset", "")).lower()
    return not (written_by(desc, meta, DATASETS_WITHOUT_SPEED_LIMITS)
                or source.startswith(DATASETS_WITHOUT_SPEED_LIMITS + ("nuplan",)))


def written_by(desc: Mapping, meta: Mapping, datasets: tuple[str, ...]) -> bool:
    """Whether the description names one of `datasets` as its source: metadata `dataset`, or the `version` prefix
    older writers set alone (e.g. "nuscenesv1.0-mini")."""
    return any(name.lower().startswith(datasets) for name in (str(meta.get("dataset", "")),
                                                               str(desc.get("version", ""))))


# ScenarioNet's nuScenes converter from 2024-01-18 to 2024-02-24 (1f61a4b to 69a3d7a) wrote the map centred on the
# ego's first position and then moved it back by shifting each feature's `polygon`, or its `polyline` when it had no
# polygon: lanes have both, so their centre lines stayed ego-centred, hundreds of metres from their own outlines.
# Told apart per map: when its centre lines lie a median of more than RECENTRE_FAR_M from their own polygons and the
# ego's first position brings them to a median within RECENTRE_NEAR_M (a true lane's centroids differ by ~2 m, up
# to ~40 m on long curved lanes), every centre line written beside a polygon is moved back.
RECENTRE_FAR_M = 100.0
RECENTRE_NEAR_M = 10.0


def recentred_lane_lines(features: Mapping, origin_xy: np.ndarray) -> tuple[Mapping, int]:
    """`features` with such centre lines moved by `origin_xy` (2,), and how many were."""
    lines: dict = {}  # key -> (points (n, >=2), centroid gap to the polygon (2,))
    for key, feature in features.items():
        if not isinstance(feature, Mapping) or feature.get("polygon") is None or feature.get("polyline") is None:
            continue
        try:
            line, outline = _xyz(feature["polyline"]), _xyz(feature["polygon"])
        except (TypeError, ValueError):
            continue
        if len(line) and len(outline):
            lines[key] = (line, line[:, :2].mean(axis=0) - outline[:, :2].mean(axis=0))
    if not lines:
        return features, 0
    gaps = np.array([gap for _, gap in lines.values()])  # (k, 2)
    if not (np.median(np.hypot(*gaps.T)) > RECENTRE_FAR_M
            and np.median(np.hypot(*(gaps + origin_xy).T)) < RECENTRE_NEAR_M):
        return features, 0
    out = dict(features)
    for key, (line, _) in lines.items():
        moved = line.copy()
        moved[:, :2] += origin_xy
        out[key] = {**features[key], "polyline": moved}
    return out, len(lines)


def _speed_limit(feature: Mapping) -> float:
    """A lane's speed limit in m/s (nuPlan's writer: `speed_limit_mps`; WOMD's: mph and km/h), -1 when unknown."""
    for key, scale in (("speed_limit_mps", 1.0), ("speed_limit_mph", MPH_TO_MPS), ("speed_limit_kmh", KMH_TO_MPS)):
        value = feature.get(key)
        try:
            value = float(value) if value is not None else math.nan
        except (TypeError, ValueError):
            continue
        if np.isfinite(value) and value > 0:
            return value * scale
    return -1.0


def map_features(desc: Mapping) -> Mapping:
    """`map_features`, or `map` in the earliest MetaDrive files."""
    features = desc.get("map_features")
    return as_mapping(features if features is not None else desc.get("map"))


def roadgraph_samples(polyline: MapPolyline, spacing: float = DEFAULT_SPACING_M) -> int:
    """Upper bound of the points `resample_polyline` makes from this polyline (its length / spacing)."""
    xy = polyline.xyz[:, :2]
    if polyline.closed and len(xy) > 2:
        xy = np.vstack([xy, xy[:1]])
    if len(xy) < 2:
        return len(xy)
    length = float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum())
    return math.ceil(min(length, 1e15) / spacing) + 1


def feature_type(feature: Mapping) -> int | None:
    """Roadgraph type of one map feature, None when not part of the roadgraph. Besides the type names,
    MetaDrive's converters before April 2023 wrote a crosswalk with no type but `sign: "cross_walk"`, and
    a speed bump whose `type` is the bump itself (a reference cycle)."""
    kind = feature.get("type")
    if kind == "UNKNOWN" and any(key in feature for key in _LANE_KEYS):
        return sch.RG_LANE_SURFACE_STREET  # a lane of undefined type is still a drivable lane (as for WOMD)
    if isinstance(kind, str):
        return MAP_TYPES.get(kind)
    if isinstance(kind, EnumValue):  # MetaDrive 2021-2022: a RoadLineType / RoadEdgeType member
        return ENUM_MAP_TYPES.get(kind.enum, {}).get(kind.value)
    if kind is feature and "polygon" in feature:
        return sch.RG_SPEED_BUMP
    if kind is None and feature.get("sign") == "cross_walk":
        return sch.RG_CROSSWALK
    return None


def _feature_points(feature: Mapping, rg_type: int) -> np.ndarray:
    if rg_type == sch.RG_STOP_SIGN:
        points = feature.get("position", feature.get("pos", feature.get("polyline", [])))
    elif rg_type in _CLOSED_TYPES or _is_sidewalk_outline(feature, rg_type):
        points = feature.get("polygon", feature.get("polyline", []))
    else:
        points = feature.get("polyline", [])
    points = _xyz(points)
    return points[np.all(finite32(points), axis=1)]  # a NaN point would poison the resampling


def _is_sidewalk_outline(feature: Mapping, rg_type: int) -> bool:
    """A road edge written as a polygon alone: MetaDrive's PG maps (since September 2023) and ScenarioNet's
    nuScenes and nuPlan walkways write ROAD_EDGE_SIDEWALK so."""
    return rg_type in sch.ROAD_EDGE_TYPES and feature.get("polyline") is None and feature.get("polygon") is not None


# ScenarioNet's nuScenes converter (every version) writes lane centre lines as the devkit's (x, y, yaw) poses: the
# third column is the lane's heading in radians, not a height (nuScenes maps are flat; every other feature is 2-D).
# Told apart by the values: a height that follows the lane's heading is not one.
HEADING_AS_Z_TOLERANCE_RAD = 0.1  # a pose's yaw against its chord's direction (samples ~0.5 m apart)
HEADING_AS_Z_SHARE = 0.9  # of the lane points
HEADING_AS_Z_MIN_POINTS = 10


def lane_z_is_heading(polylines: list[MapPolyline]) -> bool:
    """Whether the lanes' z column holds their heading (see above) rather than a height."""
    lanes = [line.xyz for line in polylines if line.feature_type in sch.LANE_TYPES and len(line.xyz) >= 2]
    if sum(map(len, lanes)) < HEADING_AS_Z_MIN_POINTS:
        return False
    xyz = np.concatenate(lanes)  # (n, 3), every lane's points one after the other
    if not np.any(np.abs(xyz[:, 2]) > HEADING_AS_Z_TOLERANCE_RAD):
        return False  # flat already (an east-bound lane at z = 0 would look like its own heading)
    step = np.diff(xyz[:, :2], axis=0)
    heading = np.append(np.arctan2(step[:, 1], step[:, 0]), 0.0)  # (n,) towards the next point
    last = np.cumsum([len(lane) for lane in lanes]) - 1
    heading[last] = heading[last - 1]  # a lane's last point: the direction it came from
    gaps = np.abs(wrap_angle(xyz[:, 2] - heading))
    return float((gaps < HEADING_AS_Z_TOLERANCE_RAD).mean()) >= HEADING_AS_Z_SHARE


def flat_lanes(polylines: list[MapPolyline]) -> list[MapPolyline]:
    """The lanes at z = 0 (their z column was their heading: `lane_z_is_heading`)."""
    return [dataclasses.replace(line, xyz=np.concatenate([line.xyz[:, :2], np.zeros((len(line.xyz), 1))], axis=1))
            if line.feature_type in sch.LANE_TYPES else line for line in polylines]


def map_polylines(features: Mapping, ids: Mapping, speed_limits: bool = True, orient_edges: bool = True
                  ) -> tuple[list[MapPolyline], list[LaneLinks], dict[str, Any]]:
    """The roadgraph polylines and lane links of a map, and notes on what was read otherwise than written;
    `speed_limits` False: the lanes' values are placeholders; `orient_edges` False: road edges as written (see
    `ScenarioNetSource`)."""
    polylines, links, sidewalks, notes = [], [], [], {}
    for key, feature in features.items():
        if not isinstance(feature, Mapping):
            continue
        rg_type = feature_type(feature)
        if rg_type is None:
            continue  # unknown feature kinds (e.g. drivable-area polygons) are not part of the roadgraph
        if rg_type == sch.RG_SOLID_SINGLE_WHITE and str(key).startswith(DRIVABLE_OUTLINE_PREFIX):
            rg_type = sch.RG_ROAD_EDGE_BOUNDARY
        try:
            points = _feature_points(feature, rg_type)
        except (TypeError, ValueError):  # e.g. ragged point lists: this feature cannot be read, the map still can
            notes["map_features_unread"] = notes.get("map_features_unread", 0) + 1
            continue
        if len(points) == 0:
            continue
        if _is_sidewalk_outline(feature, rg_type):
            sidewalks.append(MapPolyline(ids[key], rg_type, points, closed=True))
            continue
        is_lane = rg_type in sch.LANE_TYPES
        fid = ids[key]
        limit = _speed_limit(feature) if is_lane and speed_limits else -1.0
        polylines.append(MapPolyline(fid, rg_type, points, speed_limit=limit, closed=rg_type in _CLOSED_TYPES))
        if is_lane:
            links.append(LaneLinks(fid, successors=_link_ids(feature.get("exit_lanes", feature.get("exit")), ids),
                                   predecessors=_link_ids(feature.get("entry_lanes", feature.get("entry")), ids),
                                   left_neighbors=_link_ids(feature.get("left_neighbor", []), ids),
                                   right_neighbors=_link_ids(feature.get("right_neighbor", []), ids)))
    if sidewalks and not any(line.feature_type in sch.ROAD_EDGE_TYPES for line in polylines):
        # PG maps write their kerb as a painted line: the sidewalks' outlines are their only road edges (in nuScenes
        # and nuPlan the drivable-area outline is, and the walkways would only double it)
        polylines += sidewalks
        notes["road_edges_from_sidewalks"] = len(sidewalks)
    if lane_z_is_heading(polylines):
        polylines = flat_lanes(polylines)
        notes["lane_z_was_heading"] = "lane points' third column is their heading (nuScenes poses): read as z = 0"
    total = sum(roadgraph_samples(line) for line in polylines)
    if total > MAX_MAP_POINTS:
        raise ScenarioBuildError(f"map of {total} roadgraph points at {DEFAULT_SPACING_M:g} m is more than the "
                                 f"{MAX_MAP_POINTS} allowed")
    return (orient_road_edges(polylines) if orient_edges else polylines), links, notes


# --- traffic lights --------------------------------------------------------------------------------
def light_code(state) -> int | None:
    """WOMD light enum of one step's state: a MetaDrive / WOMD string or an early-MetaDrive int."""
    if state is None:
        return None
    if isinstance(state, (int, np.integer)) and not isinstance(state, (bool, np.bool_)):
        return int(state) if 0 <= state <= _MAX_LIGHT_ENUM else sch.TL_UNKNOWN
    return LIGHT_STATES.get(str(state), sch.TL_UNKNOWN)


def _steps(value, num_steps: int) -> list:
    """One entry per step: a single value repeated, or a sequence cut / padded with None (unknown)."""
    if isinstance(value, (list, tuple, np.ndarray)) and np.ndim(value) >= 1:
        values = list(value)
        if len(values) == 1:
            return values * num_steps
        return values[:num_steps] + [None] * (num_steps - len(values))
    return [value] * num_steps


def light_lanes(value, ids: Mapping, num_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """(lane id per step, -1 unknown; True where the source wrote lane 0, early MetaDrive's filler)."""
    raw = _steps(value, num_steps)
    cache: dict[str, int] = {}
    lanes = np.full(num_steps, -1, np.int64)
    zero = np.zeros(num_steps, bool)
    for step, lane in enumerate(raw):
        if lane is None or isinstance(lane, (list, dict, np.ndarray)):
            continue
        text = str(lane)
        if text not in cache:
            found = _link_ids([lane], ids)
            cache[text] = found[0] if found else -1
        lanes[step] = cache[text]
        zero[step] = text == "0"
    return lanes, zero


def light_points(value, num_steps: int) -> np.ndarray:
    """Stop point per step (T, 3), NaN where unknown; one point or one per step."""
    if value is None:
        return np.full((num_steps, 3), np.nan)
    try:
        points = _xyz(value)
    except (TypeError, ValueError):
        return np.full((num_steps, 3), np.nan)
    if len(points) == num_steps:
        return points
    if len(points) == 1:
        return np.repeat(points, num_steps, axis=0)
    return np.full((num_steps, 3), np.nan)


def light_row(light: Mapping, ids: Mapping, num_steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                                   bool]:
    """(codes, known, lane ids, stop points, unread) at the source rate for one light. Lane and stop point
    sit on the light (ScenarioNet) or per step in its state (early MetaDrive, which fills steps
    without data with lane 0 and stop point (0, 0, 0): those steps are unknown). `unread`: the light
    reports a state at some step but no step can be used (its lane is not in the map, no stop point...)."""
    state = as_mapping(light.get("state"))
    codes = [light_code(s) for s in _steps(state.get("object_state"), num_steps)]
    lane_value = light.get("lane") if light.get("lane") is not None else state.get("lane")
    point_value = light.get("stop_point") if light.get("stop_point") is not None else state.get("stop_point")
    lanes, zero_lane = light_lanes(lane_value, ids, num_steps)
    points = light_points(point_value, num_steps)
    filler = zero_lane & np.all(points == 0, axis=1)
    reported = np.array([c is not None for c in codes], bool) & ~filler
    known = reported & (lanes >= 0) & np.all(finite32(points), axis=1)
    return np.array([c or 0 for c in codes], np.int64), known, lanes, points, bool(reported.any() and not known.any())


def _lane_states(entry) -> tuple[list[tuple[Any, Any, Any]], int]:
    """One step of a per-step light list: [(lane, state, stop point)] and the count of items that cannot be
    read. The step is a dict keyed by lane of {state, stop_point} (MetaDrive 2021-2022) or a list of
    {lane, state, stop_point} (MetaDrive, March 2023); empty items (the "old format"'s [[{}]]) are nothing."""
    if isinstance(entry, Mapping):
        items = [(lane, as_mapping(value)) for lane, value in entry.items()]
    elif isinstance(entry, (list, tuple)):
        items = [(as_mapping(value).get("lane"), as_mapping(value)) for value in entry if not _empty(value)]
    else:
        return [], int(not _empty(entry))
    states = [(lane, value.get("state"), value.get("stop_point")) for lane, value in items
              if lane is not None and value.get("state") is not None]
    return states, len(items) - len(states)


def _empty(value) -> bool:
    return value is None or (isinstance(value, (Mapping, list, tuple)) and not value)


def stepped_lights(steps: list, num_steps: int) -> tuple[dict, int]:
    """Lights keyed by lane, in ScenarioNet's shape ({lane, stop_point (T, 3), state: {object_state (T,)}}),
    from a `dynamic_map_states` list with one entry per step, and the count of entries that cannot be read.
    A list of one entry is MetaDrive 2021-2022's: its converter appended only the last step's states."""
    if len(steps) not in (num_steps, 1):
        return {}, sum(not _empty(entry) for entry in steps)
    first = num_steps - len(steps)  # 0, or the last step for the one-entry list
    lights, unread = {}, 0
    for step, entry in enumerate(steps, start=first):
        states, bad = _lane_states(entry)
        unread += bad
        for lane, state, point in states:
            key = str(lane)
            if key not in lights:
                check_cells(len(lights) + 1, num_steps, "traffic lights")
                lights[key] = {"lane": lane, "stop_point": np.full((num_steps, 3), np.nan),
                               "state": {"object_state": [None] * num_steps}}
            lights[key]["state"]["object_state"][step] = state
            try:
                lights[key]["stop_point"][step] = _xyz(point)[0]
            except (TypeError, ValueError, IndexError):
                pass  # no usable stop point: the step stays unknown (and the light unread if no step is)
    return lights, unread


def light_table(value, num_steps: int) -> tuple[Mapping, int]:
    """`dynamic_map_states` as lights keyed by id, whatever the writer's generation, and the count of
    entries that cannot be read: a dict of lights (ScenarioNet), a list per step (MetaDrive before
    April 2023, see `stepped_lights`), or nothing."""
    if isinstance(value, Mapping):
        return value, sum(not isinstance(light, Mapping) and not _empty(light) for light in value.values())
    if isinstance(value, (list, tuple)):
        return stepped_lights(list(value), num_steps)
    return {}, int(not _empty(value))


def light_arrays(lights: Mapping, ids: Mapping, num_steps: int, plan) -> tuple[dict[str, np.ndarray], int]:
    """(L, T10) arrays at 10 Hz (nearest earlier source step when resampling), and the number of lights
    that report states none of which can be used."""
    check_cells(len(lights), num_steps, "traffic lights")
    rows = [light_row(as_mapping(lights[key]), ids, num_steps) for key in sorted(lights, key=str)]
    unread = sum(row[4] for row in rows)
    rows = [row[:4] for row in rows]
    if plan is not None:
        lower = plan[0]
        rows = [(codes[lower], known[lower], lanes[lower], points[lower]) for codes, known, lanes, points in rows]
    steps = len(plan[0]) if plan is not None else num_steps
    shape = (len(rows), steps)
    out = dict(tl_state=np.zeros(shape, np.int64), tl_valid=np.zeros(shape, bool),
               tl_lane_id=np.full(shape, -1, np.int64), tl_x=np.full(shape, -1.0, np.float32),
               tl_y=np.full(shape, -1.0, np.float32), tl_z=np.full(shape, -1.0, np.float32))
    for row, (codes, known, lanes, points) in enumerate(rows):
        out["tl_valid"][row] = known
        out["tl_state"][row] = np.where(known, codes, 0)
        out["tl_lane_id"][row] = np.where(known, lanes, -1)
        for axis, name in enumerate(("tl_x", "tl_y", "tl_z")):
            out[name][row] = np.where(known, points[:, axis], -1.0)
    return out, unread


# --- scenarios -------------------------------------------------------------------------------------
def _window_field(values: np.ndarray, start: int, length: int, valid: np.ndarray) -> np.ndarray:
    """One window of a per-step array, -1 where invalid or outside the log. (N, T10) -> (N, 91) float32"""
    return np.where(valid, window_steps(values, start, length, -1.0), -1.0).astype(np.float32)


def _object_labels(meta: Mapping, keys: list) -> dict:
    to_predict = np.zeros(len(keys), bool)
    difficulty = np.zeros(len(keys), np.int64)
    row_of = {str(key): row for row, key in enumerate(keys)}
    predictions = meta.get("tracks_to_predict") or {}
    if isinstance(predictions, Mapping):
        entries = list(predictions.items())
    else:  # a plain list of track keys
        entries = [(key, None) for key in predictions] if isinstance(predictions, (list, tuple)) else []
    for track_key, info in entries:
        track_key = info.get("track_id", track_key) if isinstance(info, Mapping) else track_key
        row = row_of.get(str(track_key))
        if row is None:
            continue
        to_predict[row] = True
        if isinstance(info, Mapping) and info.get("difficulty") is not None:
            difficulty[row] = int(info["difficulty"])
    interest = meta.get("objects_of_interest") or []
    interest = {str(k) for k in interest} if isinstance(interest, (list, tuple, set, np.ndarray)) else set()
    of_interest = np.array([str(key) in interest for key in keys], bool)
    return dict(tracks_to_predict=to_predict, difficulty_level=difficulty, objects_of_interest=of_interest)


def _window_times(times: np.ndarray | None, start: int, length: int, valid: np.ndarray) -> dict:
    """Timestamps from the data when the source steps are the 10 Hz steps, else the schema default.
    Steps outside the log are extrapolated at 10 Hz from its nearest end."""
    if times is None:
        return {}
    steps = np.arange(start, start + length)
    inside = np.clip(steps, 0, len(times) - 1)
    seconds = times[inside] + (steps - inside) * STEP_SECONDS
    micros = np.round((seconds - seconds[0]) * 1e6).astype(np.int64)
    return dict(timestamp_micros=np.where(valid, micros[None, :], -1), tl_timestamp_micros=micros)


# ScenarioNet's nuScenes converter in prediction mode (`prediction=True`, since 2023-12; the layout UniTraj reads)
# cuts one sample of the nuScenes prediction challenge: up to 2 s of keyframes before it and 6 s after (2 Hz,
# interpolated to 10 Hz), id "<scene>_<instance token>_<sample token>", and writes no current_time_index. The
# challenge's samples all have their 6 s future, so the current step is the 60th before the log's last.
PREDICTION_SAMPLE_ID = re.compile(r"_[0-9a-f]{32}_[0-9a-f]{32}$")
PREDICTION_FUTURE_STEPS = 60


def prediction_current_step(desc: Mapping, meta: Mapping, scenario_id: str, num_steps_10hz: int
                            ) -> tuple[int, dict] | None:
    """The current step of a nuScenes prediction sample written without current_time_index (see above), and its
    note; None for any other description."""
    if _given(meta.get("current_time_index")) or not PREDICTION_SAMPLE_ID.search(scenario_id):
        return None
    if not written_by(desc, meta, ("nuscenes",)):
        return None
    current = max(num_steps_10hz - 1 - PREDICTION_FUTURE_STEPS, 0)
    return current, {"current_time_index_derived": f"{current}: a nuScenes prediction sample, "
                                                   f"{PREDICTION_FUTURE_STEPS} steps (6 s) before the log's end"}


def log_current_step(meta: Mapping, times: np.ndarray, plan, num_steps_10hz: int, default: int) -> tuple[int, dict]:
    """The log's current step on the 10 Hz grid, and a note when the metadata's could not be used.
    `current_time_index` counts source steps: resampled, it is the 10 Hz step nearest its time."""
    given = meta.get("current_time_index")
    if not _given(given):
        return default, {}
    try:
        index = int(given)
    except (TypeError, ValueError):
        return default, {"current_time_index_ignored": f"{given!r} is not a step index"[:120]}
    if not 0 <= index < len(times):
        return default, {"current_time_index_ignored": f"{index} is outside the log's {len(times)} steps"}
    if plan is not None:
        index = min(int(round(times[index] / STEP_SECONDS)), num_steps_10hz - 1)
    return index, {}


def no_window_reason(sdc_key, sdc_valid: np.ndarray, starts: list[int], num_past: int) -> str:
    """Why none of the windows `starts` can be simulated: the SDC is not valid at any window's current step."""
    currents = [start + num_past for start in starts]
    shown = ", ".join(str(c) for c in currents[:5]) + (", ..." if len(currents) > 5 else "")
    valid_steps = np.flatnonzero(sdc_valid)
    where = f"steps {valid_steps[0]}-{valid_steps[-1]}" if len(valid_steps) else "no step"
    plural = "s" * (len(currents) > 1)
    return (f"the SDC (track {sdc_key}) is not valid at the current step of any window (log step{plural} "
            f"{shown}); it is valid on {len(valid_steps)} of {len(sdc_valid)} steps at 10 Hz ({where})")


def description_windows(desc: Mapping, sizes: Sizes, stride: int = DEFAULT_WINDOW_STRIDE,
                        default_id: str = "unnamed", orient_edges: bool = True
                        ) -> Iterator[Scenario | ScenarioBuildError]:
    """Every 91-step window (SDC valid at its current step) of one scenario description, fitted to the budget."""
    if not isinstance(desc, Mapping) or not isinstance(desc.get("tracks"), Mapping):
        yield ScenarioBuildError("not a ScenarioNet scenario description (no 'tracks' dict)")
        return
    scenario_id = scenario_name(desc, default_id)
    try:
        yield from _windows(desc, sizes, stride, scenario_id, orient_edges)
    except ScenarioBuildError as error:
        yield ScenarioBuildError(f"scenario {scenario_id}: {error}")


def _windows(desc: Mapping, sizes: Sizes, stride: int, scenario_id: str, orient_edges: bool = True
             ) -> Iterator[Scenario]:
    meta = as_mapping(desc.get("metadata"))
    tracks = desc["tracks"]
    if not tracks or len(tracks) > MAX_TRACKS:
        raise ScenarioBuildError(f"{len(tracks)} tracks (1 to {MAX_TRACKS} allowed)")
    sdc_key = named_sdc(desc, list(tracks))
    num_steps = sdc_length(sdc_key, tracks[sdc_key]) if sdc_key is not None else common_length(tracks)
    check_cells(len(tracks), num_steps, "tracks")
    times = source_times(desc, num_steps)
    if not is_nominal_10hz(times):
        check_cells(len(tracks), grid_steps(times), "tracks (at 10 Hz)")
    plan = resample_indices(times)
    source_arrays, keys, dropped = track_arrays(tracks, num_steps, keep=sdc_key)
    if not keys:
        raise ScenarioBuildError(f"no readable track ({len(dropped)} dropped, e.g. {next(iter(dropped.items()))})")
    object_types = np.array([object_type(as_mapping(tracks[k]).get("type")) for k in keys])
    sdc = keys.index(sdc_key) if sdc_key is not None else derived_sdc(
        keys, object_types, source_arrays["valid"], source_arrays["position"])
    arrays = resample_tracks(source_arrays, plan)
    swapped = wider_than_long(arrays["length"], arrays["width"], object_types, arrays["valid"])
    arrays["length"], arrays["width"] = swap_rows(arrays["length"], arrays["width"], swapped)
    num_steps_10hz = arrays["valid"].shape[1]
    if num_steps_10hz < 2:
        raise ScenarioBuildError(f"{num_steps_10hz} step{'s' * (num_steps_10hz != 1)} at 10 Hz: nothing follows "
                                 f"the current step to simulate")
    derived = prediction_current_step(desc, meta, scenario_id, num_steps_10hz)
    current, file_notes = derived or log_current_step(meta, times, plan, num_steps_10hz, sizes.num_past)
    current = min(current, num_steps_10hz - 2)  # a short log without metadata: one step follows it at least
    all_starts = log_window_starts(num_steps_10hz, current, sizes.num_past, sizes.num_timesteps, stride)
    starts = [s for s in all_starts if arrays["valid"][sdc, s + sizes.num_past]]
    if not starts:
        raise ScenarioBuildError(no_window_reason(keys[sdc], arrays["valid"][sdc], all_starts, sizes.num_past))
    if dropped:
        file_notes["tracks_dropped"] = dict(list(dropped.items())[:20])  # unreadable tracks (first 20)
    if swapped.any():
        file_notes["boxes_swapped"] = [str(keys[i]) for i in np.flatnonzero(swapped)]
    sized = [str(k) for k in keys if class_size(tracks[k], _raw_state(tracks[k]))]
    if sized:
        file_notes["sizes_from_class"] = sized[:20]  # static objects written without a size (first 20)
    key_ids = stable_int_ids(keys)
    object_ids = np.array([key_ids[k] for k in keys], np.int64)
    is_sdc = np.arange(len(keys)) == sdc
    labels = _object_labels(meta, keys)
    features = map_features(desc)
    if written_by(desc, meta, ("nuscenes",)):
        features, num_recentred = recentred_lane_lines(features, source_arrays["position"][sdc, 0, :2])
        if num_recentred:
            file_notes["lane_lines_recentred"] = num_recentred
    map_ids = stable_int_ids(features)
    speed_limits = map_has_speed_limits(desc, meta)
    if not speed_limits:
        file_notes["speed_limits_ignored"] = "the writer's constant placeholder on every lane (no limits in this map)"
    polylines, links, map_notes = map_polylines(features, map_ids, speed_limits=speed_limits,
                                                orient_edges=orient_edges)
    file_notes.update(map_notes)
    roadgraph = polylines_to_roadgraph(polylines)
    lane_graph = lane_graph_arrays(links, sizes.num_lane_links)
    light_states, unread_entries = light_table(desc.get("dynamic_map_states"), num_steps)
    lights, unread_lights = light_arrays(light_states, map_ids, num_steps, plan)
    if unread_entries or unread_lights:
        file_notes["lights_unread"] = unread_entries + unread_lights
    fills = dict(tl_state=0, tl_valid=False, tl_lane_id=-1, tl_x=-1.0, tl_y=-1.0, tl_z=-1.0)
    length = sizes.num_timesteps
    for start in starts:
        valid = window_steps(arrays["valid"], start, length, False)
        field = functools.partial(_window_field, start=start, length=length, valid=valid)
        position, velocity = arrays["position"], arrays["velocity"]
        window_labels = labels if start + sizes.num_past == current else {
            name: np.zeros_like(value) for name, value in labels.items()}
        notes = {**file_notes, **window_notes(start, num_steps_10hz, sizes.num_past, length, current)}
        scenario = Scenario(
            scenario_id=scenario_id if len(all_starts) == 1 else f"{scenario_id}_t{start:03d}",
            object_id=object_ids, object_type=object_types, is_sdc=is_sdc, valid=valid,
            x=field(position[..., 0]), y=field(position[..., 1]), z=field(position[..., 2]),
            bbox_yaw=field(wrap_angle(arrays["heading"])), length=field(arrays["length"]),
            width=field(arrays["width"]), height=field(arrays["height"]),
            velocity_x=field(velocity[..., 0]), velocity_y=field(velocity[..., 1]),
            **_window_times(times if plan is None else None, start, length, valid),
            **window_labels, **roadgraph, **lane_graph,
            **{name: window_steps(value, start, length, fills[name]) for name, value in lights.items()},
            source_dataset=SOURCE_NAME, current_time_index=sizes.num_past,
            metadata={"dataset": str(meta.get("dataset", "")), "log_start_step": start,
                      "sdc_derived": sdc_key is None, **({MANIFEST_NOTES: notes} if notes else {})},
        )
        yield fit_to_budget(scenario, sizes)


def object_type(value) -> int:
    """Our object type of a track's `type`: a type name, or MetaDrive 2021-2022's AgentType member (its
    WOMD value); anything else (another object, a nested dict) is other."""
    if isinstance(value, str):
        return OBJECT_TYPES.get(value, sch.OBJECT_TYPE_OTHER)
    if isinstance(value, EnumValue) and value.enum == "AgentType":
        return ENUM_OBJECT_TYPES.get(value.value, sch.OBJECT_TYPE_OTHER)
    return sch.OBJECT_TYPE_OTHER

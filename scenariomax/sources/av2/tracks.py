"""AV2 scenario parquet -> dense per-track arrays, and the choice of the 91-step window.

The parquet holds one row per (track, timestep) where the track was observed, so tracks are
ragged: a step is valid only where a row exists. Ids are strings ("AV" is the ego vehicle).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from scenariomax import schema as sch
from scenariomax.sources.av2.errors import Av2FormatError, Av2ScenarioError

AV_TRACK_ID = "AV"
REQUIRED_COLUMNS = ("track_id", "object_type", "timestep", "position_x", "position_y", "heading",
                    "velocity_x", "velocity_y")
OPTIONAL_COLUMNS = ("object_category", "scenario_id", "focal_track_id", "city", "num_timestamps")
MAX_RAW_STEPS = 1000  # AV2 scenarios have 110; anything far beyond is corrupt data
# Plausibility bounds of position_x, position_y, heading, velocity_x, velocity_y: rows beyond
# them (or NaN) come from corrupt files and are left invalid.
MAX_ABS_VALUE = np.array([1e6, 1e6, 1e3, 1e3, 1e3])
MAX_ROWS = 5_000_000  # bounds memory on a corrupt row count
AV2_CURRENT_STEP = 49  # the forecasting split's "current" step (50 observed + 60 future)
FOCAL_CATEGORY, SCORED_CATEGORY = 3, 2
MAX_EXACT_ID = 2**24  # ids are stored as float32 in shards: exact below this

OBJECT_TYPES = {
    "vehicle": sch.OBJECT_TYPE_VEHICLE, "bus": sch.OBJECT_TYPE_VEHICLE,
    "pedestrian": sch.OBJECT_TYPE_PEDESTRIAN,
    "cyclist": sch.OBJECT_TYPE_CYCLIST, "motorcyclist": sch.OBJECT_TYPE_CYCLIST,
    "static": sch.OBJECT_TYPE_OTHER, "background": sch.OBJECT_TYPE_OTHER,
    "construction": sch.OBJECT_TYPE_OTHER, "riderless_bicycle": sch.OBJECT_TYPE_OTHER,
    "unknown": sch.OBJECT_TYPE_OTHER,
}
# AV2 gives no box sizes: (length, width, height) in metres per AV2 object type.
DEFAULT_BOX_SIZES = {
    "vehicle": (4.5, 2.0, 1.6), "bus": (12.0, 2.6, 3.2), "pedestrian": (0.6, 0.6, 1.7),
    "cyclist": (1.8, 0.7, 1.7), "motorcyclist": (2.2, 0.9, 1.7), "riderless_bicycle": (1.8, 0.6, 1.1),
    "construction": (0.5, 0.5, 1.0), "static": (1.0, 1.0, 1.0), "background": (1.0, 1.0, 1.0),
    "unknown": (1.0, 1.0, 1.5),
}


@dataclasses.dataclass(frozen=True)
class RawTracks:
    """Every track of one AV2 scenario on the full raw time axis."""

    scenario_id: str
    track_ids: tuple[str, ...]  # (N,) sorted AV2 track id strings
    object_types: tuple[str, ...]  # (N,) AV2 object type strings
    category: np.ndarray  # (N,) int64, AV2 track category (0 fragment .. 3 focal), -1 unknown
    x: np.ndarray  # (N, S) float64, S raw steps
    y: np.ndarray  # (N, S) float64
    heading: np.ndarray  # (N, S) float64, radians
    velocity_x: np.ndarray  # (N, S) float64, m/s
    velocity_y: np.ndarray  # (N, S) float64
    valid: np.ndarray  # (N, S) bool, a row exists for (track, step)
    focal_track_id: str
    city: str

    @property
    def num_steps(self) -> int:
        return int(self.valid.shape[1])

    def index_of(self, track_id: str) -> int:
        try:
            return self.track_ids.index(track_id)
        except ValueError:
            raise Av2ScenarioError(f"no '{track_id}' track") from None


def object_ids_of(track_ids: tuple[str, ...]) -> np.ndarray:
    """Integer object ids for AV2 track id strings. -> (N,) int64

    Shards store `state/id` as float32 (WOMD layout), so ids must stay below 2**24. Numeric AV2 ids
    keep their value; the others ("AV") follow the largest numeric id, in sorted string order. If
    that does not fit, every track gets its rank in the sorted id table.
    """
    numeric = {t: int(t) for t in track_ids if t.isdigit() and len(t) < 10 and int(t) < MAX_EXACT_ID}
    others = sorted(t for t in track_ids if t not in numeric)
    first_free = max(numeric.values(), default=-1) + 1
    if first_free + len(others) > MAX_EXACT_ID:
        table = {t: rank for rank, t in enumerate(sorted(track_ids))}
    else:
        table = {**numeric, **{t: first_free + rank for rank, t in enumerate(others)}}
    return np.array([table[t] for t in track_ids], np.int64)


def _strings(column) -> list[str]:
    return ["" if value is None else str(value) for value in column.to_pylist()]


def _floats(column) -> np.ndarray:
    return np.asarray(column.to_numpy(zero_copy_only=False), dtype=np.float64)


def read_columns(table) -> dict:
    """The columns we use, as python lists / float64 arrays. Raises Av2FormatError."""
    missing = [name for name in REQUIRED_COLUMNS if name not in table.column_names]
    if missing:
        raise Av2FormatError(f"missing columns {missing}")
    if table.num_rows > MAX_ROWS:
        raise Av2FormatError(f"{table.num_rows} rows, more than the {MAX_ROWS} an AV2 scenario can hold")
    try:
        columns = {name: _strings(table.column(name)) for name in ("track_id", "object_type")}
        for name in ("timestep", "position_x", "position_y", "heading", "velocity_x", "velocity_y"):
            columns[name] = _floats(table.column(name))
        for name in OPTIONAL_COLUMNS:
            if name in table.column_names:
                is_text = name in ("scenario_id", "focal_track_id", "city")
                columns[name] = _strings(table.column(name)) if is_text else _floats(table.column(name))
    except (TypeError, ValueError) as err:  # e.g. a text column where numbers belong
        raise Av2FormatError(f"unexpected column types ({str(err).splitlines()[0]})") from None
    return columns


def _first(values, rows: np.ndarray, default):
    return values[int(rows[0])] if values is not None and rows.size else default


def build_tracks(columns: dict, rows: np.ndarray, scenario_id: str) -> RawTracks:
    """Dense arrays for the rows of one scenario. Rows with NaN or absurd values are left invalid."""
    steps = columns["timestep"][rows]
    numeric = np.stack([columns[name][rows] for name in
                        ("position_x", "position_y", "heading", "velocity_x", "velocity_y")])
    usable = np.isfinite(steps) & np.all(np.abs(numeric) < MAX_ABS_VALUE[:, None], axis=0)
    if not usable.any():
        raise Av2ScenarioError("no rows with finite values")
    steps_int = steps[usable]
    if np.any(steps_int < 0) or np.any(steps_int != np.round(steps_int)) or steps_int.max() >= MAX_RAW_STEPS:
        raise Av2ScenarioError(f"timesteps outside [0, {MAX_RAW_STEPS}) or not integers")
    steps_int = steps_int.astype(np.int64)
    num_steps = int(steps_int.max()) + 1
    declared = _first(columns.get("num_timestamps"), rows, np.nan)
    if np.isfinite(declared) and num_steps <= declared < MAX_RAW_STEPS:
        num_steps = int(declared)

    track_strings = np.array([columns["track_id"][r] for r in rows], dtype=object)
    track_ids, first_position, track_index = np.unique(track_strings, return_index=True, return_inverse=True)
    num_tracks = len(track_ids)
    used_tracks, used_steps = track_index[usable], steps_int

    def dense(values: np.ndarray) -> np.ndarray:
        out = np.full((num_tracks, num_steps), np.nan)
        out[used_tracks, used_steps] = values[usable]
        return out

    valid = np.zeros((num_tracks, num_steps), bool)
    valid[used_tracks, used_steps] = True
    first_row = rows[first_position]  # a track's type and category are read from its first row
    categories = columns.get("object_category")
    category = np.array([categories[r] if categories is not None and np.isfinite(categories[r]) else -1
                         for r in first_row], dtype=np.int64)
    return RawTracks(
        scenario_id=scenario_id,
        track_ids=tuple(str(t) for t in track_ids),
        object_types=tuple(columns["object_type"][r] for r in first_row),
        category=category,
        x=dense(numeric[0]), y=dense(numeric[1]), heading=dense(numeric[2]),
        velocity_x=dense(numeric[3]), velocity_y=dense(numeric[4]), valid=valid,
        focal_track_id=str(_first(columns.get("focal_track_id"), rows, "")),
        city=str(_first(columns.get("city"), rows, "")),
    )


def split_scenarios(columns: dict, fallback_id: str) -> list[tuple[str, np.ndarray]]:
    """(scenario_id, row indices) per scenario in the file, sorted by id (AV2 files hold one)."""
    num_rows = len(columns["track_id"])
    ids = columns.get("scenario_id")
    if ids is None:
        return [(fallback_id, np.arange(num_rows))]
    ids_array = np.array([i or fallback_id for i in ids], dtype=object)
    return [(str(sid), np.flatnonzero(ids_array == sid)) for sid in sorted(set(ids_array.tolist()))]


def choose_window_start(sdc_valid: np.ndarray, num_window_steps: int, current_offset: int) -> int:
    """First raw step of the window.

    Prefers windows where the SDC is valid at every step; among those, the one whose current step
    lies closest to AV2's forecasting "current" step (49), earlier on ties. Falls back to the
    window with the most SDC-valid steps that still has the SDC valid at the current step.
    """
    num_steps = len(sdc_valid)
    best_key, best_start = None, None
    for start in range(max(num_steps - num_window_steps, 0) + 1):
        current = start + current_offset
        if current >= num_steps or not sdc_valid[current]:
            continue
        coverage = int(sdc_valid[start:start + num_window_steps].sum())
        key = (-coverage, abs(current - AV2_CURRENT_STEP), start)
        if best_key is None or key < best_key:
            best_key, best_start = key, start
    if best_start is None:
        raise Av2ScenarioError("the AV track is never valid at a usable current step")
    return best_start


def window(values: np.ndarray, start: int, length: int, fill) -> np.ndarray:
    """values[:, start:start+length], padded with `fill` past the raw end. (N, S) -> (N, length)"""
    out = np.full((values.shape[0], length), fill, dtype=values.dtype)
    chunk = values[:, start:start + length]
    out[:, : chunk.shape[1]] = chunk
    return out

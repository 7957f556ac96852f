"""Reading one GPUDrive / Nocturne JSON file, and telling its layout apart from the others.

Every layout is one JSON object per WOMD scenario with `objects` (per-step `position`, `heading`,
`velocity`, `valid`, one box size), `roads` (typed polylines under `geometry`) and `tl_states`.
The writers changed over time (Nocturne's `waymo_scenario_construction.py`, then GPUDrive's
`data_utils/process_waymo_files.py`); what matters for reading:

| layout | written by | points | heading | ids | SDC marker |
|---|---|---|---|---|---|
| `nocturne` | Nocturne | x, y | degrees | none | none |
| `gpudrive-3d` | GPUDrive Oct - Dec 2024 | x, y, z (+ object `height`) | degrees | roads | none |
| `gpudrive-metadata` | GPUDrive from Dec 2024 | x, y, z | radians in [-pi, pi] | objects, roads | yes (*) |

(*) `metadata.sdc_track_index`. Invalid steps hold -10000 (0.0001 in `gpudrive-3d`); `valid` decides.
The heading unit is still decided per file from the values (`headings_in_degrees`), not the label.
Road `id`s are WOMD map feature ids, `map_element_id` Waymax's type code.

GPUDrive's writers keep WOMD's track order, one box size per object (its last valid state) and tl_states
keyed by lane id; the Nocturne files we hold look the same (the SDC's track last, as in WOMD). Since v0.4.0
(Feb 2025) GPUDrive leaves out vehicles and cyclists that are never valid, yet `metadata.sdc_track_index` and
`tracks_to_predict` still index WOMD's full list: an index past the end of `objects` makes the converter
choose the SDC by rule and drop those labels (`convert.stale_track_indices`). Nocturne's first writer (2022)
stored `position` and `velocity` as one object of parallel lists, `{"x": [...], "y": [...]}`.

`parse_document` turns the JSON into numpy arrays (`RawScenario`) and refuses a file whose fields
have the wrong shape or type with one `InputError` line naming the file and the field.
The layout is a label for the manifest and the heading-unit default; each field is still read
where present, whatever the label says (see `convert.py`).
"""

from __future__ import annotations

import dataclasses
import itertools
import operator
from collections.abc import Mapping
from pathlib import Path
from typing import NoReturn

import numpy as np

from scenariomax.errors import InputError
from scenariomax.sources.base import parse_json

LAYOUT_NOCTURNE = "nocturne"
LAYOUT_GPUDRIVE_3D = "gpudrive-3d"
LAYOUT_GPUDRIVE_METADATA = "gpudrive-metadata"
MAX_FILE_BYTES = 512 * 2**20  # real files are 1-4 MB; refuse absurd inputs before reading them
EXPECTED_SHAPE = "a JSON object with an 'objects' list and a 'roads' list (a GPUDrive / Nocturne scenario)"
# Files Nocturne keeps beside its scenarios in a dataset folder (lists of file names, not scenarios).
INDEX_FILES = ("valid_files.json", "invalid_files.json")
# A heading in radians never exceeds this (GPUDrive wraps to [-pi, pi]; unwrapped WOMD yaws stay within 2 pi).
MAX_RADIANS = 2 * np.pi + 1e-3
# per-object SDC markers: ScenarioMax's `is_sdc`, Nocturne's `ev/add_av_data` branch's `is_av` (0 / 1)
SDC_FLAGS = ("is_sdc", "is_av")
# Waymax's `map_element_id` codes -> the road kind, for roads written without a `type`
ELEMENT_KINDS = {**dict.fromkeys(range(0, 4), "lane"), **dict.fromkeys(range(5, 14), "road_line"),
                 **dict.fromkeys(range(14, 17), "road_edge"), 17: "stop_sign", 18: "crosswalk", 19: "speed_bump",
                 20: "driveway"}
UNTYPED_ROAD = "untyped"  # a road with neither `type` nor a known `map_element_id`: skipped, counted
MOVING_MPS = 1.0  # speed above which a box's heading and its velocity direction should agree
MIN_MOVING_STEPS = 5  # steps needed before the velocity vote on the heading unit is trusted


def read_json(path: str) -> object:
    """The parsed file. InputError (one line naming the file) when it is unreadable or not JSON."""
    try:
        size = Path(path).stat().st_size
        if size > MAX_FILE_BYTES:
            raise InputError(f"{path}: {size} bytes, more than the {MAX_FILE_BYTES} allowed for one scenario")
        data = Path(path).read_bytes()
    except OSError as error:
        raise InputError(f"{path}: cannot read ({error.strerror or error})") from None
    try:
        return parse_json(data)
    except ValueError as error:
        raise InputError(f"{path}: {error}") from None


def _what_it_is(doc: object) -> str:
    if isinstance(doc, Mapping):
        keys = sorted(str(key) for key in doc)
        return f"an object with keys {keys[:8]}{' ...' if len(keys) > 8 else ''}"
    return f"a JSON {type(doc).__name__}"


def check_document(doc: object, path: str) -> Mapping:
    """`doc` when it has the shape every layout shares, else InputError saying what was expected."""
    if not isinstance(doc, Mapping) or not isinstance(doc.get("objects"), list) \
            or not isinstance(doc.get("roads"), list):
        raise InputError(f"{path}: expected {EXPECTED_SHAPE}, found {_what_it_is(doc)}")
    for key in ("tl_states", "metadata"):
        if key == "tl_states" and doc.get(key) == []:
            continue  # no lights, as some CARLA / self-play map writers spell it
        if doc.get(key) is not None and not isinstance(doc.get(key), Mapping):
            raise InputError(f"{path}: expected '{key}' to be a JSON object, found a {type(doc[key]).__name__}")
    return doc


def _first(items: list) -> Mapping:
    return items[0] if items and isinstance(items[0], Mapping) else {}


def layout_of(doc: Mapping) -> str:
    """The layout label (see the module table): from the keys of the first object and road."""
    first_object, first_road = _first(doc["objects"]), _first(doc["roads"])
    if "id" in first_object or isinstance(doc.get("metadata"), Mapping):
        return LAYOUT_GPUDRIVE_METADATA
    if "map_element_id" in first_road or "id" in first_road or "height" in first_object:
        return LAYOUT_GPUDRIVE_3D
    return LAYOUT_NOCTURNE


def headings_in_degrees(heading: np.ndarray, velocity: np.ndarray, valid: np.ndarray, layout: str) -> bool:
    """Whether the file stores headings in degrees. (N, T), (N, T, 2), (N, T) -> bool

    Nocturne and GPUDrive before Nov 2024 wrote `math.degrees(heading)`, later GPUDrive radians.
    The values decide first (any |heading| beyond 2 pi is degrees), then moving boxes (their
    heading should point along their velocity; a few reversing cars do not outvote the rest),
    and only a file with neither (everything parked, small angles) falls back on the layout."""
    with np.errstate(invalid="ignore", over="ignore"):
        usable = valid & np.isfinite(heading)
        if np.any(np.abs(heading[usable]) > MAX_RADIANS):
            return True
        speed = np.hypot(velocity[..., 0], velocity[..., 1])
        moving = usable & np.isfinite(speed) & (speed > MOVING_MPS)
        if moving.sum() >= MIN_MOVING_STEPS:
            direction = np.arctan2(velocity[..., 1], velocity[..., 0])[moving]
            as_radians = np.cos(heading[moving] - direction).mean()
            as_degrees = np.cos(np.deg2rad(heading[moving]) - direction).mean()
            return bool(as_degrees > as_radians)
    return layout != LAYOUT_GPUDRIVE_METADATA


# --- fields -> arrays ------------------------------------------------------------------------------
NO_Z = float("nan")  # a point written without z (2-D layouts)
_XYZ, _XY = operator.itemgetter("x", "y", "z"), operator.itemgetter("x", "y")


@dataclasses.dataclass(frozen=True)
class RawRoad:
    """One entry of `roads`, as written."""

    kind: str  # "lane", "road_line", "road_edge", "stop_sign", "crosswalk", "speed_bump", "driveway", ...
    element_id: int | None  # `map_element_id` (GPUDrive's Waymax-style type code), None when absent
    road_id: int | None  # `id` (the WOMD map feature id), None when absent
    xyz: np.ndarray  # (n, 3) float64, z NaN where the point has none


@dataclasses.dataclass(frozen=True)
class RawLight:
    """One entry of `tl_states`: the states one lane reports at some steps."""

    lane_id: int
    state: tuple  # (k,) state names (str) or WOMD codes (int)
    xyz: np.ndarray  # (k, 3) float64 stop points, z NaN when absent
    time_index: np.ndarray  # (k,) int64 log steps


@dataclasses.dataclass(frozen=True)
class RawScenario:
    """One file's content as arrays (N objects, T log steps), before any repair."""

    scenario_id: str
    layout: str
    position: np.ndarray  # (N, T, 3) float64, z NaN where absent
    heading: np.ndarray  # (N, T) float64, in the file's unit
    velocity: np.ndarray  # (N, T, 2) float64
    valid: np.ndarray  # (N, T) bool
    length: np.ndarray  # (N,) float64
    width: np.ndarray  # (N,) float64
    height: np.ndarray  # (N,) float64, NaN when absent
    type_names: tuple[str, ...]  # (N,)
    object_ids: np.ndarray | None  # (N,) int64 `id`s, None when some object has none
    roads: tuple[RawRoad, ...]
    lights: tuple[RawLight, ...]
    sdc_track_index: int | None  # metadata.sdc_track_index
    tracks_to_predict: tuple[tuple[int, int], ...]  # (object index, difficulty) from metadata
    objects_of_interest: tuple[int, ...]  # object ids from metadata
    sdc_flagged: tuple[int, ...] = ()  # objects marked `is_sdc` / `is_av` (ScenarioMax, a Nocturne branch)
    notes: Mapping = dataclasses.field(default_factory=dict)  # what reading skipped, for the manifest

    @property
    def num_objects(self) -> int:
        return int(self.valid.shape[0])

    @property
    def num_steps(self) -> int:
        return int(self.valid.shape[1])


class _Fields:
    """Typed access to JSON values; every problem is one InputError line `<file>: <field>: <problem>`."""

    def __init__(self, path: str):
        self.path = path

    def fail(self, where: str, problem: str) -> NoReturn:
        raise InputError(f"{self.path}: {where}: {problem}")

    def without_path(self, error: InputError) -> str:
        """`<field>: <problem>` of an error `fail` raised (for a note: the manifest names the file already)."""
        text = str(error)
        return text[len(self.path) + 2:] if text.startswith(f"{self.path}: ") else text

    def mapping(self, value: object, where: str) -> Mapping:
        if not isinstance(value, Mapping):
            self.fail(where, f"expected a JSON object, found {_kind(value)}")
        return value

    def items(self, value: object, where: str) -> list:
        if not isinstance(value, list):
            self.fail(where, f"expected a list, found {_kind(value)}")
        return value

    def number(self, value: object, where: str) -> float:
        if type(value) not in (int, float):  # bool is an int subclass but no number here
            self.fail(where, f"expected a number, found {_kind(value)}")
        try:
            return float(value)
        except OverflowError:
            self.fail(where, "number out of range")

    def integer(self, value: object, where: str) -> int:
        if type(value) is not int and not (type(value) is float and float(value).is_integer()):
            self.fail(where, f"expected an integer, found {_kind(value)}")
        if abs(value) >= 2**62:
            self.fail(where, f"integer {value:.6g} out of range")
        return int(value)

    def numbers(self, value: object, where: str) -> np.ndarray:
        """A list of numbers. -> (k,) float64"""
        values = self.items(value, where)
        if not {type(item) for item in values} <= {int, float}:  # one pass; then find the culprit
            for index, item in enumerate(values):
                if type(item) not in (int, float):
                    self.fail(f"{where}[{index}]", f"expected a number, found {_kind(item)}")
        return self._array(values, where)

    def points(self, value: object, where: str, names: tuple[str, ...]) -> np.ndarray:
        """A list of {x, y[, z]} objects, or one object of parallel lists {"x": [...], "y": [...]} (Nocturne's
        first writer, 2022). -> (k, len(names)) float64; an absent 'z' is NaN."""
        if isinstance(value, Mapping):
            value = self._rows_of_columns(value, where)
        values = self.items(value, where)
        try:  # the common layouts spelled out, read by itemgetter (C) where every point has every name
            if names == ("x", "y", "z"):
                try:
                    rows = list(map(_XYZ, values))
                except KeyError:  # some point without z (2-D layouts)
                    rows = [(p["x"], p["y"], p.get("z", NO_Z)) for p in values]
            elif names == ("x", "y"):
                rows = list(map(_XY, values))
            else:
                rows = [tuple(p[name] if name != "z" else p.get("z", NO_Z) for name in names) for p in values]
        except (TypeError, KeyError, AttributeError):
            bad = next((i for i, p in enumerate(values)
                        if not isinstance(p, Mapping) or "x" not in p or "y" not in p), 0)
            self.fail(f"{where}[{bad}]", "expected an object with numeric 'x' and 'y'")
        flat = list(itertools.chain.from_iterable(rows))
        if not set(map(type, flat)) <= {int, float}:  # one pass; then find the culprit
            for index, row in enumerate(rows):
                if any(type(item) not in (int, float) for item in row):
                    self.fail(f"{where}[{index}]", "expected numeric coordinates")
        return self._array(flat, where).reshape(len(rows), len(names))

    def _rows_of_columns(self, columns: Mapping, where: str) -> list[dict]:
        """{"x": [...], "y": [...][, "z": [...]]} -> [{"x", "y"[, "z"]}, ...]; the lists must be equally long."""
        names = [name for name in ("x", "y", "z") if name != "z" or name in columns]
        lengths = {name: len(self.items(columns.get(name), f"{where}.{name}")) for name in names}
        if len(set(lengths.values())) != 1:
            self.fail(where, "coordinate lists differ in length (" +
                      ", ".join(f"{name} {n}" for name, n in lengths.items()) + ")")
        return [dict(zip(names, row)) for row in zip(*(columns[name] for name in names))]

    def flags(self, value: object, where: str) -> np.ndarray:
        """A list of booleans (0 / 1 accepted). -> (k,) bool"""
        values = self.items(value, where)
        if not ({type(item) for item in values} <= {bool, int} and set(values) <= {0, 1}):  # one pass, then
            for index, item in enumerate(values):  # find the culprit
                if item not in (True, False) or type(item) not in (bool, int):
                    self.fail(f"{where}[{index}]", f"expected true or false, found {_kind(item)}")
        return np.array(values, bool).reshape(len(values))

    def _array(self, rows: list, where: str) -> np.ndarray:
        """Numbers, or tuples of numbers, as a flat float64 array (fromiter: ~2x faster than np.array here)."""
        flat = itertools.chain.from_iterable(rows) if rows and type(rows[0]) is tuple else rows
        try:
            return np.fromiter(flat, np.float64)
        except OverflowError:  # an integer literal beyond float range
            self.fail(where, "number out of range")


def _kind(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    return {str: "a string", int: "an integer", float: "a number", list: "a list"}.get(
        type(value), "an object" if isinstance(value, Mapping) else type(value).__name__)


def _object_arrays(fields: _Fields, objects: list) -> dict:
    """Per-object fields of the `objects` list, stacked. (N, T, ...) arrays."""
    if not objects:
        fields.fail("objects", "the list is empty (no agent to convert)")
    out = {name: [] for name in ("position", "heading", "velocity", "valid", "length", "width", "height",
                                 "type", "id", "flagged")}
    num_steps = None
    for index, item in enumerate(objects):
        where = f"objects[{index}]"
        obj = fields.mapping(item, where)
        for key in ("position", "heading", "valid"):
            if key not in obj:
                fields.fail(where, f"missing '{key}'")
        series = {
            "position": fields.points(obj["position"], f"{where}.position", ("x", "y", "z")),
            "heading": fields.numbers(obj["heading"], f"{where}.heading"),
            "valid": fields.flags(obj["valid"], f"{where}.valid"),
        }
        # no velocity (GPUDrive's and PufferDrive's readers accept that): NaN, derived from the positions later
        series["velocity"] = (fields.points(obj["velocity"], f"{where}.velocity", ("x", "y"))
                              if obj.get("velocity") is not None else np.full((len(series["valid"]), 2), np.nan))
        lengths = {key: len(values) for key, values in series.items()}
        if len(set(lengths.values())) != 1:
            fields.fail(where, "per-step lists differ in length (" +
                        ", ".join(f"{key} {n}" for key, n in lengths.items()) + ")")
        steps = lengths["valid"]
        if num_steps is None:
            num_steps = steps
        elif steps != num_steps:
            fields.fail(where, f"{steps} steps, but objects[0] has {num_steps}")
        for key, values in series.items():
            out[key].append(values)
        for key in ("length", "width", "height"):  # absent (2-D layouts: height) -> NaN, filled later
            out[key].append(fields.number(obj[key], f"{where}.{key}") if obj.get(key) is not None else np.nan)
        kind = obj.get("type", "")
        if not isinstance(kind, str):
            fields.fail(f"{where}.type", f"expected a string, found {_kind(kind)}")
        out["type"].append(kind)
        out["id"].append(fields.integer(obj["id"], f"{where}.id") if obj.get("id") is not None else None)
        out["flagged"].append(any(obj.get(flag) in (True, 1) for flag in SDC_FLAGS))
    if num_steps == 0:
        fields.fail("objects[0]", "no steps")
    return out


def _roads(fields: _Fields, roads: list) -> tuple[RawRoad, ...]:
    out = []
    for index, item in enumerate(roads):
        where = f"roads[{index}]"
        road = fields.mapping(item, where)
        kind = road.get("type")
        if kind is not None and not isinstance(kind, str):
            fields.fail(f"{where}.type", f"expected a string, found {_kind(kind)}")
        if "geometry" not in road:
            fields.fail(where, "missing 'geometry'")
        element = road.get("map_element_id")
        element = None if element is None else fields.integer(element, f"{where}.map_element_id")
        road_id = road.get("id")
        out.append(RawRoad(
            kind=kind if kind is not None else ELEMENT_KINDS.get(element, UNTYPED_ROAD),
            element_id=element,
            road_id=None if road_id is None else fields.integer(road_id, f"{where}.id"),
            xyz=fields.points(road["geometry"], f"{where}.geometry", ("x", "y", "z")),
        ))
    return tuple(out)


def _light_series(fields: _Fields, light: Mapping, name: str, where: str, count: int) -> np.ndarray | None:
    """One per-step list of a light (x, y, z, time_index) spread over its `count` states: absent or empty -> NaN
    (time_index: 0..count-1, as Nocturne-era files list every step), one entry -> that value at every step
    (ScenarioMax's writers of mid-2025 wrote the stop point once per lane). None when it cannot be spread."""
    if light.get(name) is None or light.get(name) == []:
        return np.arange(count, dtype=np.float64) if name == "time_index" else np.full(count, np.nan)
    values = fields.numbers(light[name], f"{where}.{name}")
    if len(values) == 1 and name != "time_index":
        return np.repeat(values, count)
    return values if len(values) == count else None


def _lights(fields: _Fields, tl_states: Mapping | None) -> tuple[tuple[RawLight, ...], dict]:
    """The lights, and a note naming the ones whose per-step lists do not line up with their states (left out;
    a light never fails the file)."""
    out, unread = [], []
    for key, item in (tl_states or {}).items():
        where = f"tl_states[{key!r}]"
        try:
            lane_id = int(str(key).strip())
        except ValueError:
            fields.fail(where, "expected a lane id (an integer) as key")
        light = fields.mapping(item, where)
        states = fields.items(light.get("state"), f"{where}.state")
        for index, state in enumerate(states):
            if not isinstance(state, str) and type(state) is not int:
                fields.fail(f"{where}.state[{index}]", f"expected a state name, found {_kind(state)}")
        count = len(states)
        series = {name: _light_series(fields, light, name, where, count) for name in ("x", "y", "z", "time_index")}
        if any(values is None for values in series.values()):
            unread.append(f"{lane_id} (state {count} entries, " + ", ".join(
                f"{name} {len(light[name])}" for name, values in series.items() if values is None) + ")")
            continue
        steps = series["time_index"]
        if not np.all(np.isfinite(steps) & (steps == np.round(steps)) & (np.abs(steps) < 2**31)):
            fields.fail(f"{where}.time_index", "expected integer steps")
        coords = np.stack([series["x"], series["y"], series["z"]], axis=1)
        out.append(RawLight(lane_id, tuple(states), coords, steps.astype(np.int64)))
    notes = {"lights_unread": id_list_text(unread)} if unread else {}
    return tuple(sorted(out, key=lambda light: light.lane_id)), notes


def id_list_text(items: list[str], shown: int = 5) -> str:
    """The first `shown` items joined, and how many more."""
    more = f" and {len(items) - shown} more" if len(items) > shown else ""
    return "; ".join(items[:shown]) + more


def _sdc_index(fields: _Fields, metadata: Mapping) -> tuple[int | None, dict]:
    """metadata.sdc_track_index, or None with a note when it names no object: negative (GPUDrive's and
    PufferDrive's readers take -1 for "no SDC"; CARLA and self-play map writers write it) or not an integer."""
    value = metadata.get("sdc_track_index")
    if value is None:
        return None, {}
    try:
        index = fields.integer(value, "metadata.sdc_track_index")
    except InputError as error:
        return None, {"sdc_track_index_ignored": fields.without_path(error)}
    if index < 0:
        return None, {"sdc_track_index_ignored": f"{index} (no SDC named): SDC chosen by rule"}
    return index, {}


def _prediction_entries(fields: _Fields, value: object) -> list[tuple[int, int]]:
    """tracks_to_predict as (track index, difficulty): GPUDrive's list of {track_index, difficulty}, or the
    ScenarioNet metadata ScenarioMax copies unchanged ({track id: {track_index, difficulty, ...}})."""
    entries = value.values() if isinstance(value, Mapping) else fields.items(value, "metadata.tracks_to_predict")
    out = []
    for index, item in enumerate(entries):
        where = f"metadata.tracks_to_predict[{index}]"
        entry = fields.mapping(item, where)
        out.append((fields.integer(entry.get("track_index"), f"{where}.track_index"),
                    fields.integer(entry.get("difficulty", 0), f"{where}.difficulty")))
    return out


def _labels(fields: _Fields, metadata: Mapping | None) -> tuple[int | None, tuple, tuple, dict]:
    """(sdc_track_index, tracks_to_predict as (index, difficulty), objects_of_interest ids, notes) from metadata.
    Prediction labels never fail a file: ones that cannot be read are left out with a note."""
    metadata = metadata or {}
    sdc, notes = _sdc_index(fields, metadata)
    ignored = []
    try:
        predict = _prediction_entries(fields, metadata.get("tracks_to_predict", []))
    except InputError as error:
        predict = []
        ignored.append(fields.without_path(error))
    interest = []
    values = metadata.get("objects_of_interest", [])
    for index, value in enumerate(values if isinstance(values, list) else [values]):
        try:
            interest.append(fields.integer(value, f"metadata.objects_of_interest[{index}]"))
        except InputError as error:  # ScenarioNet's track keys (strings) name no object here
            ignored.append(fields.without_path(error))
    if ignored:
        notes["labels_ignored"] = id_list_text(ignored, shown=3)
    return sdc, tuple(predict), tuple(interest), notes


def scenario_name(doc: Mapping, path: str) -> str:
    """`scenario_id` when the file has one, else its `name` (a file name) or the file's own name, less `.json`."""
    for value in (doc.get("scenario_id"), doc.get("name")):
        if isinstance(value, str) and value.strip():
            name = value.strip()
            return name[:-5] if name.endswith(".json") else name
    return Path(path).stem


def parse_document(doc: object, path: str) -> RawScenario:
    """The file's scenario as arrays. InputError (one line: file, field, problem) when malformed."""
    doc = check_document(doc, path)
    fields = _Fields(path)
    arrays = _object_arrays(fields, doc["objects"])
    ids = arrays["id"]
    sdc, predict, interest, label_notes = _labels(fields, doc.get("metadata"))
    lights, light_notes = _lights(fields, doc.get("tl_states"))
    return RawScenario(
        scenario_id=scenario_name(doc, path),
        layout=layout_of(doc),
        position=np.stack(arrays["position"]),
        heading=np.stack(arrays["heading"]),
        velocity=np.stack(arrays["velocity"]),
        valid=np.stack(arrays["valid"]),
        length=np.array(arrays["length"], np.float64),
        width=np.array(arrays["width"], np.float64),
        height=np.array(arrays["height"], np.float64),
        type_names=tuple(arrays["type"]),
        object_ids=None if any(i is None for i in ids) else np.array(ids, np.int64),
        roads=_roads(fields, doc["roads"]),
        lights=lights,
        sdc_track_index=sdc,
        tracks_to_predict=predict,
        objects_of_interest=interest,
        sdc_flagged=tuple(int(i) for i in np.flatnonzero(arrays["flagged"])),
        notes={**label_notes, **light_notes},
    )

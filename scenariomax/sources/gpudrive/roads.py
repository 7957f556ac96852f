"""GPUDrive / Nocturne `roads` -> map polylines, and `tl_states` -> (L, T) traffic-light arrays.

Road kinds are WOMD's map feature kinds. GPUDrive files also carry `map_element_id`, Waymax's type
code (lanes 0-3, road lines 5-13, road edges 14-16, ...), which refines lanes, road lines and road
edges; Nocturne files have only the kind, so their road lines are "unknown" and their road edges
boundaries (as the WOMD source maps WOMD's own unknown subtypes).

Road edges keep the file's point order. Both writers copy WOMD polylines in order, and WOMD edges
already run with the road on their left (the real WOMD record, read without any re-orientation, keeps
its logged SDC on the road: `tests/metrics/test_sim_realdata.py`). The enrichment's orientation rule
(`scenariomax.enrich.orientation`) leaves every edge of the real GPUDrive / Nocturne files as drawn;
before its sight test it reversed 5 barrier edges of `tfrecord-00000-of-01000_402.json`
(`tests/sources/gpudrive/test_edge_orientation_402.py`).
"""

from __future__ import annotations

import dataclasses
from collections import Counter

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich.roadgraph import MapPolyline
from scenariomax.sources.gpudrive.layout import RawLight, RawRoad
from scenariomax.sources.gpudrive.tracks import MAX_ABS_COORD_M

RG_UNKNOWN = 0
# Type of a road by kind when `map_element_id` says nothing better.
KIND_TYPES = {"lane": sch.RG_LANE_SURFACE_STREET, "road_line": RG_UNKNOWN, "road_edge": sch.RG_ROAD_EDGE_BOUNDARY,
              "stop_sign": sch.RG_STOP_SIGN, "crosswalk": sch.RG_CROSSWALK, "speed_bump": sch.RG_SPEED_BUMP,
              "driveway": sch.RG_DRIVEWAY}
# `map_element_id` -> roadgraph type, for the kinds it refines. Undefined lanes (0) are still drivable lanes
# (surface street, as in the WOMD source); the unknown road line (5) and road edge (14) codes have no schema type.
ELEMENT_TYPES = {
    "lane": {0: sch.RG_LANE_SURFACE_STREET, 1: sch.RG_LANE_FREEWAY, 2: sch.RG_LANE_SURFACE_STREET,
             3: sch.RG_LANE_BIKE},
    "road_line": {5: RG_UNKNOWN, **{code: code for code in range(6, 14)}},
    "road_edge": {14: sch.RG_ROAD_EDGE_BOUNDARY, 15: sch.RG_ROAD_EDGE_BOUNDARY, 16: sch.RG_ROAD_EDGE_MEDIAN},
}
POLYGON_KINDS = ("crosswalk", "speed_bump", "driveway")  # closed outlines, as the WOMD source stores them
# Light state names GPUDrive writes are the schema's names ("arrow_stop", "go", ...); WOMD's enum spelling
# ("LANE_STATE_GO") is accepted too.
_STATE_PREFIX = "lane_state_"


@dataclasses.dataclass(frozen=True)
class MapResult:
    polylines: list[MapPolyline]
    notes: dict  # roads skipped by kind, points dropped, how ids were assigned


def road_type(road: RawRoad) -> int | None:
    """Schema roadgraph type of one road, None for a kind the schema has no type for."""
    kind = road.kind.strip().lower()
    if kind not in KIND_TYPES:
        return None
    return ELEMENT_TYPES.get(kind, {}).get(road.element_id, KIND_TYPES[kind])


def road_ids(roads: tuple[RawRoad, ...]) -> tuple[np.ndarray, bool]:
    """(ids (n,), whether they are the file's own): the roads' `id`s when every road has a distinct one
    (lights refer to lanes by them), else positions 1..n."""
    ids = [road.road_id for road in roads]
    if ids and None not in ids and len(set(ids)) == len(ids):
        return np.array(ids, np.int64), True
    return np.arange(1, len(roads) + 1, dtype=np.int64), False


def _kept_rows(xyz: np.ndarray) -> np.ndarray:
    """Rows with finite, sane x and y. (n, 3) -> (n,) bool"""
    with np.errstate(invalid="ignore"):
        return np.all(np.isfinite(xyz[:, :2]) & (np.abs(xyz[:, :2]) < MAX_ABS_COORD_M), axis=1)


def clean_points(xyz: np.ndarray) -> tuple[np.ndarray, int]:
    """Points with finite, sane x and y (z: 0 where absent). (n, 3) -> ((m, 3), n - m)"""
    keep = _kept_rows(xyz)
    with np.errstate(invalid="ignore"):
        z = np.where(np.isfinite(xyz[:, 2]) & (np.abs(xyz[:, 2]) < MAX_ABS_COORD_M), xyz[:, 2], 0.0)
    return np.column_stack([xyz[:, :2], z])[keep], int((~keep).sum())


def map_polylines(roads: tuple[RawRoad, ...]) -> MapResult:
    """Roads -> polylines (in the file's order, see the module docstring) and notes for the manifest."""
    ids, own_ids = road_ids(roads)
    skipped: Counter = Counter()
    dropped = 0
    polylines = []
    # Every road's points cleaned in one pass (clean_points on the concatenation: the same rows), then split.
    counts = np.array([len(road.xyz) for road in roads], np.int64)  # (R,)
    xyz = np.concatenate([road.xyz for road in roads]) if roads else np.zeros((0, 3))
    cleaned, _ = clean_points(xyz)  # (m, 3) the kept rows, road after road
    kept = np.bincount(np.repeat(np.arange(len(roads)), counts)[_kept_rows(xyz)], minlength=len(roads))
    for road, feature_id, points, num_points in zip(roads, ids, np.split(cleaned, np.cumsum(kept)[:-1]), counts):
        rg_type = road_type(road)
        dropped += int(num_points) - len(points)
        if rg_type is None or len(points) == 0:
            skipped[road.kind if rg_type is None else f"{road.kind} (no points)"] += 1
            continue
        polylines.append(MapPolyline(int(feature_id), rg_type, points,
                                     closed=road.kind.strip().lower() in POLYGON_KINDS))
    notes: dict = {}
    if skipped:
        notes["roads_skipped"] = dict(sorted(skipped.items()))
    if dropped:
        notes["road_points_dropped"] = dropped  # non-finite or absurd coordinates
    if roads and not own_ids:
        notes["road_ids"] = "positional (1..n): the file's roads have no distinct ids"
    return MapResult(polylines, notes)


def light_state_code(state: str | int) -> int | None:
    """Schema traffic-light state of one GPUDrive state name (or WOMD code); None when unknown."""
    names = sch.load_schema().enums["traffic_light_state"]
    if isinstance(state, int):
        return state if state in names else None
    name = state.strip().lower()
    name = name[len(_STATE_PREFIX):] if name.startswith(_STATE_PREFIX) else name
    return next((code for code, known in names.items() if known == name), None)


def light_arrays(lights: tuple[RawLight, ...], start: int, num_timesteps: int) -> tuple[dict, int]:
    """(L, T) light arrays of one window, a row per lane reporting inside it (sorted by lane id), and the
    number of state values that were not light states (stored as unknown)."""
    rows = [light for light in lights if np.any((light.time_index >= start) &
                                                (light.time_index < start + num_timesteps))]
    shape = (len(rows), num_timesteps)
    state, lane_id, valid = np.zeros(shape, np.int64), np.full(shape, -1, np.int64), np.zeros(shape, bool)
    xyz = np.full((3,) + shape, -1.0)
    unknown = 0
    for row, light in enumerate(rows):
        for value, point, step in zip(light.state, light.xyz, light.time_index - start):
            if not 0 <= step < num_timesteps:
                continue
            with np.errstate(invalid="ignore"):
                if not np.all(np.isfinite(point[:2]) & (np.abs(point[:2]) < MAX_ABS_COORD_M)):
                    continue  # no usable stop point: the step stays invalid
            code = light_state_code(value)
            unknown += code is None
            state[row, step] = sch.TL_UNKNOWN if code is None else code
            valid[row, step] = True
            lane_id[row, step] = light.lane_id
            z_ok = np.isfinite(point[2]) and abs(point[2]) < MAX_ABS_COORD_M
            xyz[:, row, step] = (point[0], point[1], point[2] if z_ok else 0.0)
    arrays = dict(tl_state=state, tl_valid=valid, tl_lane_id=lane_id, tl_x=xyz[0], tl_y=xyz[1], tl_z=xyz[2])
    return arrays, unknown

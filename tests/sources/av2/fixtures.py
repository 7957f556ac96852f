"""Writes tiny AV2 scenarios in the real on-disk format (parquet table + map archive JSON)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

SCENARIO_ID = "tiny-0000-av2"
NUM_STEPS = 110


def _track(track_id, object_type, category, steps, x_fn, y_fn, heading, velocity):
    return [{"track_id": track_id, "object_type": object_type, "object_category": category, "timestep": int(t),
                 "position_x": float(x_fn(t)), "position_y": float(y_fn(t)), "heading": float(heading),
                 "velocity_x": float(velocity[0]), "velocity_y": float(velocity[1]), "observed": bool(t < 50)}
            for t in steps]


def tiny_rows() -> list[dict]:
    """AV east-bound at 10 m/s on y=0; a focal car beside it; a short-lived pedestrian; a bus seen only
    before the window (dropped); a static construction object."""
    all_steps = range(NUM_STEPS)
    rows = (
        _track("AV", "vehicle", 1, all_steps, lambda t: t * 1.0, lambda t: 0.0, 0.0, (10.0, 0.0))
        + _track("100", "vehicle", 3, all_steps, lambda t: t + 10.0, lambda t: 3.5, 2 * math.pi + 0.1, (10.0, 0.0))
        + _track("200", "pedestrian", 0, range(40, 51), lambda t: 50.0, lambda t: -5.0 + 0.1 * (t - 40),
                 math.pi / 2, (0.0, 1.0))
        + _track("300", "bus", 2, range(6), lambda t: -5.0, lambda t: 3.5, 0.0, (0.0, 0.0))
        + _track("400", "construction", 0, all_steps, lambda t: 70.0, lambda t: -1.9, -3.0, (0.0, 0.0))
    )
    for row in rows:
        row.update(scenario_id=SCENARIO_ID, start_timestamp=3.0e17, end_timestamp=3.0e17 + 1.09e10,
                   num_timestamps=NUM_STEPS, focal_track_id="100", city="austin", map_id=1,
                   slice_id="slice")
    return rows


def write_parquet(path: Path, rows: list[dict]) -> None:
    columns = {key: [row[key] for row in rows] for key in rows[0]}
    pq.write_table(pa.table(columns), path)


def _points(*xyz) -> list[dict]:
    return [{"x": float(x), "y": float(y), "z": float(z)} for x, y, z in xyz]


def tiny_map() -> dict:
    """Lane 1 (y in [-1.75, 1.75]) and lane 2 (y in [1.75, 5.25]) from x=-10 to 130 at z=5, bike lane 3
    after lane 1, a crosswalk at x=60..63 and a clockwise drivable area around it all."""
    lane1 = {"id": 1, "is_intersection": False, "lane_type": "VEHICLE",
                 "left_lane_boundary": _points((-10, 1.75, 5), (130, 1.75, 5)),
                 "right_lane_boundary": _points((-10, -1.75, 5), (60, -1.75, 5), (130, -1.75, 5)),
                 "left_lane_mark_type": "DASHED_WHITE", "right_lane_mark_type": "SOLID_WHITE",
                 "left_neighbor_id": 2, "right_neighbor_id": None, "predecessors": [], "successors": [3, 999]}
    lane2 = {"id": 2, "is_intersection": False, "lane_type": "BUS",
                 "left_lane_boundary": _points((-10, 5.25, 5), (130, 5.25, 5)),
                 "right_lane_boundary": _points((-10, 1.75, 5), (130, 1.75, 5)),
                 "left_lane_mark_type": "DOUBLE_SOLID_YELLOW", "right_lane_mark_type": "DASHED_WHITE",
                 "left_neighbor_id": None, "right_neighbor_id": 1, "predecessors": [], "successors": []}
    lane3 = {"id": 3, "is_intersection": True, "lane_type": "BIKE",
                 "left_lane_boundary": _points((130, 1.75, 5), (140, 1.75, 5)),
                 "right_lane_boundary": _points((130, -1.75, 5), (140, -1.75, 5)),
                 "left_lane_mark_type": "NONE", "right_lane_mark_type": "UNKNOWN",
                 "left_neighbor_id": None, "right_neighbor_id": None, "predecessors": [1], "successors": []}
    crossing = {"id": 50, "edge1": _points((60, -2, 5), (60, 6, 5)), "edge2": _points((63, -2, 5), (63, 6, 5))}
    area = {"id": 60, "area_boundary": _points((-10, -2, 5), (-10, 6, 5), (140, 6, 5), (140, -2, 5))}
    return {"lane_segments": {str(lane["id"]): lane for lane in (lane1, lane2, lane3)},
                "pedestrian_crossings": {"50": crossing}, "drivable_areas": {"60": area}}


def write_scenario_dir(root: Path, rows: list[dict] | None = None, archive: dict | None = None,
                       scenario_id: str = SCENARIO_ID) -> Path:
    """root/<id>/scenario_<id>.parquet + log_map_archive_<id>.json; returns the folder."""
    folder = root / scenario_id
    folder.mkdir(parents=True, exist_ok=True)
    write_parquet(folder / f"scenario_{scenario_id}.parquet", rows if rows is not None else tiny_rows())
    (folder / f"log_map_archive_{scenario_id}.json").write_text(json.dumps(archive or tiny_map()))
    return folder


def parquet_of(folder: Path) -> Path:
    return next(folder.glob("scenario_*.parquet"))


def map_of(folder: Path) -> Path:
    return next(folder.glob("log_map_archive_*.json"))

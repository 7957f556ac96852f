"""The nuPlan log database (SQLite): schema checks and the queries the converter runs.

The whole-log index (lidar_pc clock, tags, tracks) is small; boxes, ego poses and light states
are queried per scenario window so memory does not grow with the log.
"""

from __future__ import annotations

import dataclasses
import sqlite3
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scenariomax import schema as sch
from scenariomax.errors import InputError
from scenariomax.sources.nuplan.ego import quaternion_yaw
from scenariomax.sources.nuplan.sqlite_access import fetch_all, require_columns, table_columns

REQUIRED_COLUMNS = {
    "log": ("map_version",),
    "lidar_pc": ("token", "timestamp"),
    "ego_pose": ("timestamp", "x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "angular_rate_z"),
    "lidar_box": ("lidar_pc_token", "track_token", "x", "y", "z", "width", "length", "height", "yaw", "vx", "vy"),
    "track": ("token", "category_token"),
    "category": ("token", "name"),
    "scenario_tag": ("lidar_pc_token", "type"),
    "traffic_light_status": ("lidar_pc_token", "lane_connector_id", "status"),
}
CATEGORY_TO_OBJECT_TYPE = {
    "vehicle": sch.OBJECT_TYPE_VEHICLE,
    "pedestrian": sch.OBJECT_TYPE_PEDESTRIAN,
    "bicycle": sch.OBJECT_TYPE_CYCLIST,
    "traffic_cone": sch.OBJECT_TYPE_OTHER,
    "barrier": sch.OBJECT_TYPE_OTHER,
    "czone_sign": sch.OBJECT_TYPE_OTHER,
    "generic_object": sch.OBJECT_TYPE_OTHER,
}
LIGHT_STATUS_TO_STATE = {"green": sch.TL_GO, "red": sch.TL_STOP, "yellow": sch.TL_CAUTION, "unknown": sch.TL_UNKNOWN}
EGO_OBJECT_ID = 0
MAX_EGO_GAP_MICROS = 250_000  # an ego_pose farther than this from a sweep leaves the SDC invalid there
MAX_ABS_VALUE = 1e8  # larger positions, sizes or speeds are corrupt (and would overflow float32)


@dataclasses.dataclass(frozen=True)
class LogIndex:
    path: str
    log_name: str
    map_version: str
    lidar_token: tuple  # (n,) bytes tokens of lidar_pc ordered by timestamp
    lidar_time: np.ndarray  # (n,) int64, Unix microseconds
    tags: dict  # lidar_pc index -> tuple of scenario_tag types
    tag_agents: dict  # lidar_pc index -> tuple of interacting agents' track tokens
    track_id: dict  # track token -> object id (1.. by sorted token; 0 is the ego)
    track_type: dict  # track token -> object type enum
    ego_extent: tuple  # (minx, miny, maxx, maxy) of all ego poses, UTM metres


@dataclasses.dataclass(frozen=True)
class EgoPoses:
    time: np.ndarray  # (E,) int64
    x: np.ndarray  # (E,) float64, rear axle
    y: np.ndarray  # (E,) float64
    z: np.ndarray  # (E,) float64
    yaw: np.ndarray  # (E,) float64
    vx: np.ndarray  # (E,) float64, body frame
    vy: np.ndarray  # (E,) float64
    yaw_rate: np.ndarray  # (E,) float64


def check_schema(conn: sqlite3.Connection, path: str) -> None:
    for table, columns in REQUIRED_COLUMNS.items():
        require_columns(conn, path, table, columns)


def read_log_index(conn: sqlite3.Connection, path: str) -> LogIndex:
    check_schema(conn, path)
    logs = fetch_all(conn, path, "SELECT map_version FROM log")
    if not logs or not isinstance(logs[0][0], str) or not logs[0][0].strip():
        raise InputError(f"{path}: table 'log' holds no map_version")
    rows = fetch_all(conn, path, "SELECT token, timestamp FROM lidar_pc")
    rows = sorted((r for r in rows if isinstance(r[1], int) and r[0] is not None), key=lambda r: (r[1], bytes(r[0])
                  if isinstance(r[0], (bytes, bytearray)) else str(r[0]).encode()))
    # Duplicate timestamps would make time run backwards; keep the first sweep of each.
    unique = [r for i, r in enumerate(rows) if i == 0 or r[1] != rows[i - 1][1]]
    if not unique:
        raise InputError(f"{path}: table 'lidar_pc' is empty")
    tokens = tuple(r[0] for r in unique)
    position = {token: i for i, token in enumerate(tokens)}
    tags: dict[int, tuple] = {}
    tag_agents: dict[int, tuple] = {}
    has_agents = "agent_track_token" in (table_columns(conn, path, "scenario_tag") or ())
    agent_column = "agent_track_token" if has_agents else "NULL"
    for token, kind, agent in fetch_all(conn, path, f"SELECT lidar_pc_token, type, {agent_column} FROM scenario_tag"):
        if token in position:
            tags[position[token]] = tags.get(position[token], ()) + (str(kind),)
            if agent is not None:
                tag_agents[position[token]] = tag_agents.get(position[token], ()) + (agent,)
    categories = {token: str(name) for token, name in fetch_all(conn, path, "SELECT token, name FROM category")}
    tracks = fetch_all(conn, path, "SELECT token, category_token FROM track")
    tracks = sorted((t for t in tracks if t[0] is not None), key=lambda t: _sort_key(t[0]))
    track_id = {token: rank + 1 for rank, (token, _) in enumerate(tracks)}
    track_type = {token: CATEGORY_TO_OBJECT_TYPE.get(categories.get(cat, ""), sch.OBJECT_TYPE_OTHER)
                  for token, cat in tracks}
    extent = fetch_all(conn, path, "SELECT min(x), min(y), max(x), max(y) FROM ego_pose")[0]
    if any(not isinstance(v, (int, float)) or not np.isfinite(v) for v in extent):
        raise InputError(f"{path}: table 'ego_pose' is empty or holds no finite positions")
    return LogIndex(path, Path(path).stem, logs[0][0].strip(), tokens,
                    np.array([r[1] for r in unique], np.int64), tags, tag_agents, track_id, track_type,
                    tuple(float(v) for v in extent))


def _sort_key(token) -> bytes:
    return bytes(token) if isinstance(token, (bytes, bytearray)) else str(token).encode()


def read_ego_poses(conn: sqlite3.Connection, path: str, start_micros: int, end_micros: int) -> EgoPoses:
    """Ego poses with timestamps in [start, end], ordered by time (non-finite rows dropped)."""
    rows = fetch_all(conn, path, "SELECT timestamp, x, y, z, qw, qx, qy, qz, vx, vy, angular_rate_z FROM ego_pose "
                     "WHERE timestamp BETWEEN ? AND ? ORDER BY timestamp", (int(start_micros), int(end_micros)))
    table = _float_table(rows, 11)
    table = table[np.isfinite(table).all(axis=1) & (np.abs(table[:, 1:]) < MAX_ABS_VALUE).all(axis=1)]
    time = table[:, 0].astype(np.int64)
    yaw = quaternion_yaw(table[:, 4], table[:, 5], table[:, 6], table[:, 7])
    return EgoPoses(time, table[:, 1], table[:, 2], table[:, 3], yaw, table[:, 8], table[:, 9], table[:, 10])


def _float_table(rows: Sequence[tuple], width: int) -> np.ndarray:
    """Rows of numbers -> (len, width) float64; NULL and non-numeric cells become NaN."""
    try:
        table = np.array([row[:width] for row in rows], dtype=np.float64).reshape(len(rows), width)
        if not any(isinstance(v, (str, bytes)) for row in rows[:1] for v in row[:width]):
            return table
    except (ValueError, TypeError, OverflowError):
        pass
    out = np.full((len(rows), width), np.nan)  # slow path: a corrupted cell somewhere
    for i, row in enumerate(rows):
        for j, value in enumerate(row[:width]):
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                out[i, j] = float(value) if abs(value) < 1e300 else np.nan
    return out


def nearest_pose_index(pose_time: np.ndarray, query_time: np.ndarray) -> np.ndarray:
    """Index of the pose nearest each query time, -1 when none lies within MAX_EGO_GAP_MICROS. (Q,) -> (Q,)"""
    if len(pose_time) == 0:
        return np.full(len(query_time), -1, np.int64)
    right = np.clip(np.searchsorted(pose_time, query_time), 0, len(pose_time) - 1)
    left = np.clip(right - 1, 0, len(pose_time) - 1)
    pick = np.where(np.abs(pose_time[left] - query_time) <= np.abs(pose_time[right] - query_time), left, right)
    return np.where(np.abs(pose_time[pick] - query_time) <= MAX_EGO_GAP_MICROS, pick, -1)


@dataclasses.dataclass(frozen=True)
class LogSlice:
    """Everything scenarios anchored in one stretch of the log need, read with one scan per table
    (real logs may lack indexes on lidar_pc_token, so per-scenario queries would rescan the table)."""

    boxes: dict  # lidar_pc token -> [(lidar_pc_token, track_token, x, y, z, length, width, height, yaw, vx, vy)]
    lights: dict  # lidar_pc token -> [(lidar_pc_token, lane_connector_id, status)]
    ego: EgoPoses  # ego poses over the stretch (+ MAX_EGO_GAP_MICROS on both ends)


def read_log_slice(conn: sqlite3.Connection, path: str, start_micros: int, end_micros: int) -> LogSlice:
    """Boxes, light states and ego poses of the sweeps with timestamps in [start, end]."""
    span = (int(start_micros), int(end_micros))
    boxes = fetch_all(conn, path, "SELECT b.lidar_pc_token, b.track_token, b.x, b.y, b.z, b.length, b.width, "
                      "b.height, b.yaw, b.vx, b.vy FROM lidar_box AS b "
                      "JOIN lidar_pc AS p ON p.token = b.lidar_pc_token "
                      "WHERE p.timestamp BETWEEN ? AND ?", span)
    lights = fetch_all(conn, path, "SELECT s.lidar_pc_token, s.lane_connector_id, s.status FROM traffic_light_status "
                       "AS s JOIN lidar_pc AS p ON p.token = s.lidar_pc_token WHERE p.timestamp BETWEEN ? AND ?", span)
    ego = read_ego_poses(conn, path, span[0] - MAX_EGO_GAP_MICROS, span[1] + MAX_EGO_GAP_MICROS)
    return LogSlice(_by_sweep(boxes), _by_sweep(lights), ego)


def _by_sweep(rows: list[tuple]) -> dict:
    out: dict = {}
    for row in rows:
        if row[0] is not None:
            out.setdefault(row[0], []).append(row)
    return out


def light_state(status) -> int:
    return LIGHT_STATUS_TO_STATE.get(str(status).strip().lower(), sch.TL_UNKNOWN)

"""`Scenario`: one driving scenario as numpy arrays, the in-memory form of one shard record.

Arrays may be smaller than the shard budget (converters fill only what they have); the shard
writer pads them. Scenarios read back from shards hold the padded arrays the record stores.
Shapes use: N objects, T timesteps (91), R roadgraph points, L traffic lights, P paths,
Q points per path, K lanes, M links per lane, A agent paths.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from scenariomax import schema as sch

_OBJECT_TRAJECTORY_FIELDS = (
    "x", "y", "z", "bbox_yaw", "length", "width", "height", "speed", "vel_yaw", "velocity_x", "velocity_y",
)
_LIGHT_FLOAT_FIELDS = ("tl_x", "tl_y", "tl_z")
MAX_ABS_YAW = 4 * np.pi
MAX_EXACT_OBJECT_ID = 2 ** 24  # integers above this are not exact in float32


@dataclasses.dataclass(frozen=True, eq=False)
class Scenario:
    scenario_id: str
    # --- objects --------------------------------------------------------------------------------
    object_id: np.ndarray  # (N,) int64, track id from the source
    object_type: np.ndarray  # (N,) int64, enum object_type
    is_sdc: np.ndarray  # (N,) bool, exactly one True
    x: np.ndarray  # (N, T) float32, metres
    y: np.ndarray  # (N, T) float32
    z: np.ndarray  # (N, T) float32
    bbox_yaw: np.ndarray  # (N, T) float32, radians in [-pi, pi]
    length: np.ndarray  # (N, T) float32, metres
    width: np.ndarray  # (N, T) float32
    height: np.ndarray  # (N, T) float32
    velocity_x: np.ndarray  # (N, T) float32, m/s
    velocity_y: np.ndarray  # (N, T) float32, m/s
    valid: np.ndarray  # (N, T) bool
    speed: np.ndarray | None = None  # (N, T) float32, m/s; derived from velocity when None
    vel_yaw: np.ndarray | None = None  # (N, T) float32, radians; derived from velocity when None
    timestamp_micros: np.ndarray | None = None  # (N, T) int64; 100 ms steps from 0 when None
    tracks_to_predict: np.ndarray | None = None  # (N,) bool
    objects_of_interest: np.ndarray | None = None  # (N,) bool
    difficulty_level: np.ndarray | None = None  # (N,) int64
    is_controllable: np.ndarray | None = None  # (N,) bool
    # --- roadgraph --------------------------------------------------------------------------------
    roadgraph_xyz: np.ndarray | None = None  # (R, 3) float32
    roadgraph_dir: np.ndarray | None = None  # (R, 3) float32, unit vector to the next point
    roadgraph_type: np.ndarray | None = None  # (R,) int64, enum roadgraph_type
    roadgraph_id: np.ndarray | None = None  # (R,) int64, map feature id
    roadgraph_valid: np.ndarray | None = None  # (R,) bool
    roadgraph_speed_limit: np.ndarray | None = None  # (R,) float32, m/s, -1 unknown
    # --- traffic lights (object-major, like trajectories) -------------------------------------------
    tl_state: np.ndarray | None = None  # (L, T) int64, enum traffic_light_state
    tl_valid: np.ndarray | None = None  # (L, T) bool
    tl_lane_id: np.ndarray | None = None  # (L, T) int64, controlled lane
    tl_x: np.ndarray | None = None  # (L, T) float32, stop point
    tl_y: np.ndarray | None = None  # (L, T) float32
    tl_z: np.ndarray | None = None  # (L, T) float32
    tl_inferred: np.ndarray | None = None  # (L, T) bool, state inferred from motion
    tl_timestamp_micros: np.ndarray | None = None  # (T,) int64
    # --- SDC paths -----------------------------------------------------------------------------------
    path_xyz: np.ndarray | None = None  # (P, Q, 3) float32
    path_valid: np.ndarray | None = None  # (P, Q) bool
    path_lane_id: np.ndarray | None = None  # (P, Q) int64
    path_arc_length: np.ndarray | None = None  # (P, Q) float32
    path_on_route: np.ndarray | None = None  # (P,) bool
    # --- lane graph -----------------------------------------------------------------------------------
    lane_id: np.ndarray | None = None  # (K,) int64
    lane_valid: np.ndarray | None = None  # (K,) bool
    lane_successors: np.ndarray | None = None  # (K, M) int64, -1 pads
    lane_predecessors: np.ndarray | None = None  # (K, M) int64
    lane_left_neighbors: np.ndarray | None = None  # (K, M) int64
    lane_right_neighbors: np.ndarray | None = None  # (K, M) int64
    # --- per-agent paths (controllable agents) -----------------------------------------------------
    agent_path_object_index: np.ndarray | None = None  # (A,) int64
    agent_path_xyz: np.ndarray | None = None  # (A, Q, 3) float32
    agent_path_valid: np.ndarray | None = None  # (A, Q) bool
    agent_path_arc_length: np.ndarray | None = None  # (A, Q) float32
    # --- metadata -------------------------------------------------------------------------------------
    world_origin: np.ndarray | None = None  # (3,) float64, whole metres; positions are relative to it
    source_dataset: str = ""
    current_time_index: int = 10
    metadata: dict[str, Any] = dataclasses.field(default_factory=dict)  # not serialised

    def __post_init__(self) -> None:
        _fill_defaults(self)

    # Convenience views ------------------------------------------------------------------------------
    @property
    def num_objects(self) -> int:
        return int(self.x.shape[0])

    @property
    def num_timesteps(self) -> int:
        return int(self.x.shape[1])

    @property
    def sdc_index(self) -> int:
        indices = np.flatnonzero(self.is_sdc)
        if indices.size != 1:
            raise ValueError(f"scenario {self.scenario_id}: expected one SDC, found {indices.size}")
        return int(indices[0])

    def replace(self, **changes) -> Scenario:
        return dataclasses.replace(self, **changes)

    def validate(self) -> list[str]:
        """Every inconsistency found, as human-readable lines (empty when the scenario is sound)."""
        return validate_scenario(self)

    def equals(self, other: Scenario) -> bool:
        """Field-by-field equality (NaN-aware), ignoring `metadata`."""
        for field in dataclasses.fields(self):
            if field.name == "metadata":
                continue
            a, b = getattr(self, field.name), getattr(other, field.name)
            if isinstance(a, np.ndarray):
                if a.shape != b.shape or not np.array_equal(a, b, equal_nan=a.dtype.kind == "f"):
                    return False
            elif a != b:
                return False
        return True


def array_fields() -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(Scenario) if f.name not in
                 ("scenario_id", "source_dataset", "current_time_index", "metadata"))


def _set(scenario: Scenario, name: str, value) -> None:
    object.__setattr__(scenario, name, value)


def _as(scenario: Scenario, name: str, dtype, default_shape, fill) -> None:
    value = getattr(scenario, name)
    if value is None:
        value = np.full(default_shape, fill, dtype=dtype)
    _set(scenario, name, np.asarray(value, dtype=dtype))


def _fill_defaults(s: Scenario) -> None:
    """Coerces dtypes and fills optional fields (derived values or empty arrays)."""
    for name in _OBJECT_TRAJECTORY_FIELDS:
        if getattr(s, name) is not None:
            _set(s, name, np.asarray(getattr(s, name), dtype=np.float32))
    _set(s, "valid", np.asarray(s.valid, dtype=bool))
    n, t = s.x.shape
    if s.speed is None:
        _set(s, "speed", np.where(s.valid, np.hypot(s.velocity_x, s.velocity_y), -1.0).astype(np.float32))
    if s.vel_yaw is None:
        _set(s, "vel_yaw", np.where(s.valid, np.arctan2(s.velocity_y, s.velocity_x), -1.0).astype(np.float32))
    if s.timestamp_micros is None:
        steps = np.broadcast_to(np.arange(t, dtype=np.int64) * 100_000, (n, t))
        _set(s, "timestamp_micros", np.where(s.valid, steps, -1))
    _as(s, "timestamp_micros", np.int64, (n, t), -1)
    _set(s, "object_id", np.asarray(s.object_id, dtype=np.int64))
    _set(s, "object_type", np.asarray(s.object_type, dtype=np.int64))
    _set(s, "is_sdc", np.asarray(s.is_sdc, dtype=bool))
    for name in ("tracks_to_predict", "objects_of_interest", "is_controllable"):
        _as(s, name, bool, (n,), False)
    _as(s, "difficulty_level", np.int64, (n,), 0)
    _as(s, "roadgraph_xyz", np.float32, (0, 3), 0.0)
    r = s.roadgraph_xyz.shape[0]
    _as(s, "roadgraph_dir", np.float32, (r, 3), 0.0)
    _as(s, "roadgraph_type", np.int64, (r,), 0)
    _as(s, "roadgraph_id", np.int64, (r,), -1)
    _as(s, "roadgraph_valid", bool, (r,), True)
    _as(s, "roadgraph_speed_limit", np.float32, (r,), -1.0)
    _as(s, "tl_state", np.int64, (0, t), 0)
    lights = s.tl_state.shape[0]
    _as(s, "tl_valid", bool, (lights, t), False)
    _as(s, "tl_lane_id", np.int64, (lights, t), -1)
    for name in _LIGHT_FLOAT_FIELDS:
        _as(s, name, np.float32, (lights, t), -1.0)
    _as(s, "tl_inferred", bool, (lights, t), False)
    if s.tl_timestamp_micros is None:
        _set(s, "tl_timestamp_micros", np.arange(t, dtype=np.int64) * 100_000)
    _as(s, "tl_timestamp_micros", np.int64, (t,), -1)
    _as(s, "path_xyz", np.float32, (0, 0, 3), 0.0)
    p, q = s.path_xyz.shape[:2]
    _as(s, "path_valid", bool, (p, q), False)
    _as(s, "path_lane_id", np.int64, (p, q), -1)
    _as(s, "path_arc_length", np.float32, (p, q), 0.0)
    _as(s, "path_on_route", bool, (p,), False)
    _as(s, "lane_id", np.int64, (0,), -1)
    k = s.lane_id.shape[0]
    _as(s, "lane_valid", bool, (k,), True)
    for name in ("lane_successors", "lane_predecessors", "lane_left_neighbors", "lane_right_neighbors"):
        _as(s, name, np.int64, (k, 0), -1)
    _as(s, "world_origin", np.float64, (3,), 0.0)
    _as(s, "agent_path_object_index", np.int64, (0,), -1)
    a = s.agent_path_object_index.shape[0]
    _as(s, "agent_path_xyz", np.float32, (a, q, 3), 0.0)
    q_agent = s.agent_path_xyz.shape[1]
    _as(s, "agent_path_valid", bool, (a, q_agent), False)
    _as(s, "agent_path_arc_length", np.float32, (a, q_agent), 0.0)


def validate_scenario(s: Scenario) -> list[str]:
    problems: list[str] = []
    n, t = s.x.shape
    for name in _OBJECT_TRAJECTORY_FIELDS + ("valid", "timestamp_micros"):
        if getattr(s, name).shape != (n, t):
            problems.append(f"{name} has shape {getattr(s, name).shape}, expected {(n, t)}")
    for name in ("object_id", "object_type", "is_sdc", "tracks_to_predict", "objects_of_interest",
                 "difficulty_level", "is_controllable"):
        if getattr(s, name).shape != (n,):
            problems.append(f"{name} has shape {getattr(s, name).shape}, expected {(n,)}")
    if problems:
        return problems  # the checks below index with these shapes
    valid = s.valid
    for name in _OBJECT_TRAJECTORY_FIELDS:
        values = getattr(s, name)[valid]
        if values.size and not np.all(np.isfinite(values)):
            problems.append(f"{name} has NaN or infinite values at valid steps")
    yaw = s.bbox_yaw[valid]
    # WOMD stores unwrapped headings (|yaw| up to ~7.5 rad in real records), so only absurd values fail.
    if yaw.size and np.any(np.abs(yaw[np.isfinite(yaw)]) > MAX_ABS_YAW):
        problems.append(f"bbox_yaw beyond +-{MAX_ABS_YAW:.1f} rad at valid steps")
    for name in ("length", "width", "height"):
        values = getattr(s, name)[valid]
        if values.size and np.any(values[np.isfinite(values)] <= 0):
            problems.append(f"{name} is not positive at some valid steps")
    speed = s.speed[valid]
    expected_speed = np.hypot(s.velocity_x, s.velocity_y)[valid]
    if speed.size and np.any(np.abs(speed - expected_speed) > 0.05 + 0.01 * expected_speed):
        problems.append("speed disagrees with the norm of (velocity_x, velocity_y)")
    num_sdc = int(s.is_sdc.sum())
    if num_sdc != 1:
        problems.append(f"expected exactly one SDC, found {num_sdc}")
    elif not (0 <= s.current_time_index < t) or not valid[s.sdc_index, s.current_time_index]:
        problems.append("the SDC is not valid at the current time step")
    present = valid.any(axis=1)
    known_types = set(sch.load_schema().enums["object_type"])
    bad_types = set(np.unique(s.object_type[present]).tolist()) - known_types
    if bad_types:
        problems.append(f"unknown object types {sorted(bad_types)}")
    ids = s.object_id[present]
    if ids.size != np.unique(ids).size:
        problems.append("duplicate object ids among present objects")
    if np.any(np.abs(ids) >= MAX_EXACT_OBJECT_ID):
        problems.append("object ids must be below 2^24 (state/id is stored as float32)")
    if np.any(s.world_origin != np.round(s.world_origin)) or np.any(np.abs(s.world_origin) >= MAX_EXACT_OBJECT_ID):
        problems.append("world_origin must be whole metres below 2^24 (stored exactly as float32)")
    # The valid stamps of all rows back to back: each must exceed the one before it in the same row.
    row_of, _ = np.nonzero(valid)  # (v,) row-major, as s.timestamp_micros[valid]
    step = np.diff(s.timestamp_micros[valid])  # (v-1,)
    if np.any((step <= 0) & (row_of[1:] == row_of[:-1])):
        problems.append("timestamps do not increase along a trajectory")
    problems += _validate_roadgraph(s)
    problems += _validate_lights(s, t)
    problems += _validate_paths(s)
    return problems


def _validate_roadgraph(s: Scenario) -> list[str]:
    problems = []
    r = s.roadgraph_xyz.shape[0]
    for name, shape in (("roadgraph_dir", (r, 3)), ("roadgraph_type", (r,)), ("roadgraph_id", (r,)),
                        ("roadgraph_valid", (r,)), ("roadgraph_speed_limit", (r,))):
        if getattr(s, name).shape != shape:
            problems.append(f"{name} has shape {getattr(s, name).shape}, expected {shape}")
    if problems:
        return problems
    valid = s.roadgraph_valid
    d = s.roadgraph_dir[valid]  # (v, 3): norm(d, axis=-1)'s bits below, without the slow 3-wide reduction
    if not np.all(np.isfinite(s.roadgraph_xyz[valid])) or not np.all(np.isfinite(d)):
        problems.append("roadgraph has NaN or infinite values at valid points")
    norms = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2])
    if norms.size and np.any((norms > 1.01) | ((norms < 0.99) & (norms > 1e-3))):
        problems.append("roadgraph_dir has vectors that are neither unit nor zero")
    known = set(sch.load_schema().enums["roadgraph_type"])
    types = s.roadgraph_type[valid]  # (v,) in runs of one polyline: its distinct values are those of the run starts
    run_start = np.ones(len(types), bool)
    run_start[1:] = types[1:] != types[:-1]
    bad = set(np.unique(types[run_start]).tolist()) - known
    if bad:
        problems.append(f"unknown roadgraph types {sorted(bad)}")
    return problems


def _validate_lights(s: Scenario, t: int) -> list[str]:
    lights = s.tl_state.shape[0]
    shape = (lights, t)
    problems = [f"{name} has shape {getattr(s, name).shape}, expected {shape}"
                for name in ("tl_valid", "tl_lane_id", "tl_x", "tl_y", "tl_z", "tl_inferred")
                if getattr(s, name).shape != shape]
    if s.tl_state.shape[1:] != (t,):
        problems.append(f"tl_state has shape {s.tl_state.shape}, expected (L, {t})")
    if problems:
        return problems
    known = set(sch.load_schema().enums["traffic_light_state"])
    bad = set(np.unique(s.tl_state[s.tl_valid]).tolist()) - known
    if bad:
        problems.append(f"unknown traffic light states {sorted(bad)}")
    return problems


def _validate_paths(s: Scenario) -> list[str]:
    p, q = s.path_xyz.shape[:2]
    problems = [f"{name} has shape {getattr(s, name).shape}, expected {(p, q)}"
                for name in ("path_valid", "path_lane_id", "path_arc_length")
                if getattr(s, name).shape != (p, q)]
    if s.path_on_route.shape != (p,):
        problems.append(f"path_on_route has shape {s.path_on_route.shape}, expected {(p,)}")
    if not problems and not np.all(np.isfinite(s.path_xyz[s.path_valid])):
        problems.append("path_xyz has NaN or infinite values at valid points")
    return problems

"""One scenario as the viewer's compact binary "scene": quantised arrays plus a small JSON header.

Layout of a packed scene (little-endian), the same bytes whether embedded in the HTML (base64) or
served by `scenariomax view --serve` (application/octet-stream):

    uint32 header_length | header (UTF-8 JSON) | zero padding to 8 bytes | array data

The header holds `meta` (ids, types, summary, problems, rollouts...) and `arrays`:
name -> [dtype, byte offset into the data, element count]; every array starts 8-byte aligned so the
page reads it with a typed-array view without copying. Positions are int16 multiples of `scale`
metres (1 cm when the scene spans at most +-327 m around `origin`, coarser only for larger maps),
headings int16 in 1e-4 rad, sizes and speeds uint16 centimetres (per second). A real WOMD scene
(128 objects x 91 steps, 20000 roadgraph points) packs to about 0.3 MB.
"""

from __future__ import annotations

import dataclasses
import json
import math
import struct
from collections.abc import Sequence

import numpy as np

from scenariomax import schema as sch
from scenariomax.scenario import Scenario

MAX_POINT_GAP_M = 5.0  # consecutive points of one line feature further apart than this are not joined
POLYGON_TYPES = (sch.RG_CROSSWALK, sch.RG_SPEED_BUMP, sch.RG_DRIVEWAY)
YAW_UNITS = 1e-4  # rad per int16 unit
SIZE_UNITS = 0.01  # m (and m/s) per uint16 unit
_DTYPES = {"i16": "<i2", "u16": "<u2", "u8": "u1", "i32": "<i4", "f32": "<f4"}
_KINDS = {np.dtype(v): k for k, v in _DTYPES.items()}
_INT16_MAX = 32767
_ALIGN = 8


@dataclasses.dataclass(frozen=True)
class SimTrack:
    """One policy's simulated SDC in a rollout, for drawing over the logged scene.

    Policy step k (0-based) lands at timestep `first_timestep + k + 1`; `metrics` are per policy step.
    """

    name: str
    x: np.ndarray  # (T,) float, metres (same frame as the scenario)
    y: np.ndarray  # (T,)
    yaw: np.ndarray  # (T,) radians
    valid: np.ndarray  # (T,) bool, the simulated SDC exists at that timestep (log history included)
    length: float  # metres
    width: float
    first_timestep: int  # the timestep reset() set
    metrics: dict  # name -> (S,) float per policy step
    step_valid: np.ndarray  # (S,) bool, the step belongs to the episode (not after termination)
    failures: tuple = ()  # ({"metric", "label", "step" (policy step or None)}, ...)
    episode: dict = dataclasses.field(default_factory=dict)  # episode metric -> float


def _finite(values: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(values), values, 0.0)


def _quantise(values: np.ndarray, origin: float, scale: float) -> np.ndarray:
    q = np.rint((_finite(np.asarray(values, np.float64)) - origin) / scale)
    return np.clip(q, -_INT16_MAX, _INT16_MAX).astype("<i2")


def _wrap_yaw(yaw: np.ndarray) -> np.ndarray:
    yaw = _finite(np.asarray(yaw, np.float64))
    return np.clip(np.rint((np.mod(yaw + np.pi, 2 * np.pi) - np.pi) / YAW_UNITS), -_INT16_MAX, _INT16_MAX
                   ).astype("<i2")


def _centimetres(values: np.ndarray) -> np.ndarray:
    values = _finite(np.asarray(values, np.float64))
    return np.clip(np.rint(values / SIZE_UNITS), 0, 65535).astype("<u2")


def roadgraph_polylines(xy: np.ndarray, types: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Splits valid roadgraph points into drawable runs: a new run starts where the feature id or type
    changes, or (for line features) at a gap above MAX_POINT_GAP_M.

    (R, 2), (R,), (R,) -> run starts (K + 1,) int (offsets into the points, the last = R), run types (K,).
    """
    if len(xy) == 0:
        return np.zeros(1, np.int64), np.zeros(0, np.int64)
    gap = np.linalg.norm(np.diff(xy, axis=0), axis=-1) > MAX_POINT_GAP_M
    is_polygon = np.isin(types[1:], POLYGON_TYPES)
    breaks = (ids[1:] != ids[:-1]) | (types[1:] != types[:-1]) | (gap & ~is_polygon)
    starts = np.concatenate([[0], np.flatnonzero(breaks) + 1, [len(xy)]]).astype(np.int64)
    return starts, types[starts[:-1]].astype(np.int64)


def _runs(points: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Concatenates (k, 2) polylines -> points (sum k, 2), starts (count + 1,)."""
    lengths = [len(p) for p in points]
    starts = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64) if points else np.zeros(1, np.int64)
    xy = np.concatenate(points, axis=0) if points else np.zeros((0, 2))
    return xy, starts


def _frame(coords: Sequence[np.ndarray]) -> tuple[np.ndarray, float]:
    """(origin (2,), scale m per unit) so every point fits int16 around the origin at the finest scale."""
    stacked = [c.reshape(-1, 2) for c in coords if c.size]
    stacked = [c[np.all(np.isfinite(c), axis=-1)] for c in stacked]
    points = np.concatenate(stacked) if stacked else np.zeros((0, 2))
    if len(points) == 0:
        return np.zeros(2), SIZE_UNITS
    lo, hi = points.min(axis=0), points.max(axis=0)
    origin = np.round(0.5 * (lo + hi), 2)
    extent = float(np.max(np.maximum(hi - origin, origin - lo))) + 1.0
    scale = SIZE_UNITS if extent <= _INT16_MAX * SIZE_UNITS else math.ceil(extent / _INT16_MAX * 1e4) / 1e4
    return origin, scale


def _json_ready(value):
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_ready(value.tolist())
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return round(float(value), 4) if math.isfinite(value) else None
    return value


def scene_from_scenario(scenario: Scenario, *, summary: dict | None = None, problems: Sequence[str] = (),
                        sims: Sequence[SimTrack] = (), extra_meta: dict | None = None) -> tuple[dict, dict]:
    """The viewer's scene of `scenario` -> (meta (JSON-serialisable), arrays name -> numpy array).

    Only objects observed at least once are kept. `summary` / `problems` are shown in the page's
    summary panel (see `scenariomax.inspect.summarize_scenario` and `scenariomax.validate`); `sims` are
    policies' simulated SDCs drawn over the log (`vmax-sim view`).
    """
    s = scenario
    present = np.flatnonzero(s.valid.any(axis=1))
    valid = s.valid[present] & np.isfinite(s.x[present]) & np.isfinite(s.y[present])  # (N, T)
    obj_xy = np.stack([s.x[present], s.y[present]], axis=-1)  # (N, T, 2)

    rg_ok = s.roadgraph_valid & np.all(np.isfinite(s.roadgraph_xyz[:, :2]), axis=-1)
    rg_xy = s.roadgraph_xyz[rg_ok, :2].astype(np.float64)
    rg_starts, rg_types = roadgraph_polylines(rg_xy, s.roadgraph_type[rg_ok], s.roadgraph_id[rg_ok])

    paths = [s.path_xyz[p, s.path_valid[p], :2] for p in range(s.path_xyz.shape[0]) if s.path_valid[p].sum() >= 2]
    on_route = [bool(s.path_on_route[p]) for p in range(s.path_xyz.shape[0]) if s.path_valid[p].sum() >= 2]
    slot_to_row = {int(slot): row for row, slot in enumerate(present)}
    agent_rows, agent_paths = [], []
    for a in range(s.agent_path_object_index.shape[0]):
        slot = int(s.agent_path_object_index[a])
        if slot in slot_to_row and s.agent_path_valid[a].sum() >= 2:
            agent_rows.append(slot_to_row[slot])
            agent_paths.append(s.agent_path_xyz[a, s.agent_path_valid[a], :2])

    lights = np.flatnonzero(s.tl_valid.any(axis=1)) if s.tl_state.shape[0] else np.zeros(0, np.int64)
    tl_valid = s.tl_valid[lights] & np.isfinite(s.tl_x[lights]) & np.isfinite(s.tl_y[lights])
    tl_xy = np.stack([s.tl_x[lights], s.tl_y[lights]], axis=-1)

    sim_xy = [np.stack([sim.x, sim.y], -1)[np.asarray(sim.valid, bool)] for sim in sims]
    origin, scale = _frame([obj_xy[valid], rg_xy, tl_xy[tl_valid]] + paths + agent_paths + sim_xy)
    path_xy, path_starts = _runs(paths)
    apath_xy, apath_starts = _runs(agent_paths)

    speed = np.where(s.speed[present] >= 0, s.speed[present],
                     np.hypot(s.velocity_x[present], s.velocity_y[present]))
    arrays = {
        "obj_x": _quantise(obj_xy[..., 0], origin[0], scale), "obj_y": _quantise(obj_xy[..., 1], origin[1], scale),
        "obj_yaw": _wrap_yaw(s.bbox_yaw[present]), "obj_len": _centimetres(s.length[present]),
        "obj_wid": _centimetres(s.width[present]), "obj_speed": _centimetres(speed),
        "obj_valid": valid.astype("u1"),
        "rg_x": _quantise(rg_xy[:, 0], origin[0], scale), "rg_y": _quantise(rg_xy[:, 1], origin[1], scale),
        "rg_start": rg_starts.astype("<i4"), "rg_type": rg_types.astype("u1"),
        "tl_x": _quantise(tl_xy[..., 0], origin[0], scale), "tl_y": _quantise(tl_xy[..., 1], origin[1], scale),
        "tl_state": s.tl_state[lights].astype("u1"), "tl_valid": tl_valid.astype("u1"),
        "path_x": _quantise(path_xy[:, 0], origin[0], scale), "path_y": _quantise(path_xy[:, 1], origin[1], scale),
        "path_start": path_starts.astype("<i4"),
        "apath_x": _quantise(apath_xy[:, 0], origin[0], scale), "apath_y": _quantise(apath_xy[:, 1], origin[1], scale),
        "apath_start": apath_starts.astype("<i4"),
    }
    sim_meta = []
    for k, sim in enumerate(sims):
        sim_valid = np.asarray(sim.valid, bool) & np.isfinite(sim.x) & np.isfinite(sim.y)
        arrays[f"sim{k}_x"] = _quantise(sim.x, origin[0], scale)
        arrays[f"sim{k}_y"] = _quantise(sim.y, origin[1], scale)
        arrays[f"sim{k}_yaw"] = _wrap_yaw(sim.yaw)
        arrays[f"sim{k}_valid"] = sim_valid.astype("u1")
        names = sorted(sim.metrics)
        for j, name in enumerate(names):
            arrays[f"sim{k}_m{j}"] = np.asarray(sim.metrics[name], "<f4")
        arrays[f"sim{k}_step_valid"] = np.asarray(sim.step_valid, bool).astype("u1")
        sim_meta.append({"name": sim.name, "length": float(sim.length), "width": float(sim.width),
                         "first_timestep": int(sim.first_timestep), "metrics": names,
                         "num_steps": int(len(sim.step_valid)), "failures": list(sim.failures),
                         "episode": dict(sim.episode)})
    sdc_rows = np.flatnonzero(s.is_sdc[present])
    meta = {
        "id": s.scenario_id, "dataset": s.source_dataset, "num_steps": s.num_timesteps,
        "current_step": s.current_time_index, "dt": 0.1, "origin": origin.tolist(), "scale": scale,
        "yaw_units": YAW_UNITS, "size_units": SIZE_UNITS,
        "num_objects": int(len(present)), "object_ids": s.object_id[present], "object_types": s.object_type[present],
        "object_slots": present, "sdc": int(sdc_rows[0]) if sdc_rows.size else -1,
        "controllable": np.flatnonzero(s.is_controllable[present]),
        "num_lights": int(len(lights)),
        "path_on_route": on_route, "agent_path_objects": agent_rows,
        "summary": summary or {}, "problems": list(problems), "sims": sim_meta,
    }
    meta.update(extra_meta or {})
    return _json_ready(meta), arrays


def pack_scene(meta: dict, arrays: dict) -> bytes:
    """(meta, arrays) -> the packed scene bytes (see the module docstring)."""
    layout, chunks, offset = {}, [], 0
    for name, array in arrays.items():
        kind = _KINDS.get(np.dtype(array.dtype))
        if kind is None:
            raise TypeError(f"scene array {name!r}: unsupported dtype {array.dtype}")
        data = np.ascontiguousarray(array, dtype=_DTYPES[kind]).tobytes()
        layout[name] = [kind, offset, int(array.size)]
        padding = (-len(data)) % _ALIGN
        chunks.append(data + b"\0" * padding)
        offset += len(data) + padding
    header = json.dumps({"meta": meta, "arrays": layout}, separators=(",", ":"), allow_nan=False).encode()
    head = struct.pack("<I", len(header)) + header
    head += b"\0" * ((-len(head)) % _ALIGN)
    return head + b"".join(chunks)


def unpack_scene(blob: bytes) -> tuple[dict, dict]:
    """Inverse of `pack_scene` (for tests and tools): -> (meta, arrays name -> numpy array)."""
    (length,) = struct.unpack_from("<I", blob, 0)
    header = json.loads(blob[4:4 + length].decode())
    start = 4 + length + ((-(4 + length)) % _ALIGN)
    arrays = {name: np.frombuffer(blob, dtype=_DTYPES[kind], count=count, offset=start + offset)
              for name, (kind, offset, count) in header["arrays"].items()}
    return header["meta"], arrays


def error_scene(message: str, scenario_id: str = "") -> bytes:
    """A scene without data that tells the page why (an unreadable record)."""
    return pack_scene({"id": scenario_id, "error": message, "num_steps": 1, "problems": [message]}, {})


__all__ = ["SimTrack", "error_scene", "pack_scene", "roadgraph_polylines", "scene_from_scenario", "unpack_scene"]

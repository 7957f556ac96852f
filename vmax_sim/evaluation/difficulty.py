"""Difficulty of a scenario from its log, and the evaluation scores per difficulty bucket.

Signals are computed on the host (numpy) from the same fixed-size state the simulator ran (so the
object and roadgraph crops match the evaluation), over the episode window (first policy step to the
last step of the episode), independent of the policy:

- `num_interacting`: other objects whose logged centre comes within `interaction_distance_m` of the
  SDC's path ahead (the on-route SDC path from the SDC's start to `path_margin_m` past its logged end,
  at least `min_path_ahead_m` long; the logged SDC trajectory when the scenario has no on-route path).
- `num_vru_near_path`: pedestrians and cyclists within `vru_distance_m` of the path ahead.
- `has_traffic_light`: a logged light's stop point within `light_distance_m` of the path ahead.
- `is_intersection`: that, or a stop sign within `light_distance_m`, or a lane centre crossing the path
  ahead (a lane point within `crossing_distance_m` whose direction is more than `crossing_angle_deg` off).
- `max_curvature`: largest heading change per metre of the path ahead over `curvature_window_m` (1/m).
- `sdc_speed`: mean logged SDC speed over the window (m/s).
- `num_lane_changes`: the logged SDC's nearest heading-aligned lane centre (within `lane_search_m`)
  changes to another lane that persists `lane_persist_steps` steps and lies more than
  `lane_change_offset_m` sideways of the first (a successor lane continues the first: no change).

The score (0..11, docs/evaluation-reports.md) adds: 1 / 2 / 3 for 1-3 / 4-7 / 8+ interacting objects, 1 for an
intersection, 1 for a curved / 2 for a sharp path, 1 for a fast SDC, 1 per lane change (at most 2),
2 for a vulnerable road user near the path. Levels: easy <= 2 < medium <= 4 < hard.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from scenariomax import schema as sch

LEVELS = ("easy", "medium", "hard")
LANE_TYPES = (sch.RG_LANE_FREEWAY, sch.RG_LANE_SURFACE_STREET)
VRU_TYPES = (sch.OBJECT_TYPE_PEDESTRIAN, sch.OBJECT_TYPE_CYCLIST)


@dataclasses.dataclass(frozen=True)
class DifficultyConfig:
    interaction_distance_m: float = 3.5  # object centre this close to the path ahead: interacting
    vru_distance_m: float = 5.0  # pedestrian / cyclist this close to the path ahead: VRU signal
    path_margin_m: float = 10.0  # the path ahead runs this far past the SDC's logged end
    min_path_ahead_m: float = 20.0  # and is at least this long
    light_distance_m: float = 5.0  # light stop point / stop sign this close to the path ahead
    crossing_distance_m: float = 1.5  # lane point this close to the path ahead ...
    crossing_angle_deg: float = 45.0  # ... heading this far off the path's: a crossing lane
    curvature_window_m: float = 5.0  # heading change measured over this arc
    lane_search_m: float = 3.0  # the SDC's lane: nearest aligned lane centre within this
    lane_align_deg: float = 30.0  # aligned: lane direction within this of the SDC's heading
    lane_change_offset_m: float = 2.0  # the new lane lies this far sideways of the old one
    lane_persist_steps: int = 5  # a lane counts once the SDC stays on it this many steps
    curved_curvature: float = 0.02  # 1/m (radius 50 m): "curved"
    sharp_curvature: float = 0.05  # 1/m (radius 20 m): "sharp"
    slow_speed_mps: float = 5.0  # speed buckets: < slow, slow..fast, >= fast (the score counts >= fast)
    fast_speed_mps: float = 10.0
    interacting_steps: tuple[int, int, int] = (1, 4, 8)  # 1, 2, 3 points from these many interacting objects
    easy_max_score: int = 2
    medium_max_score: int = 4


@dataclasses.dataclass(frozen=True)
class DifficultySignals:
    num_interacting: int
    num_vru_near_path: int
    has_traffic_light: bool
    is_intersection: bool
    max_curvature: float  # 1/m
    sdc_speed: float  # m/s, mean over the episode window
    num_lane_changes: int
    score: int  # difficulty_score of the above
    level: str  # one of LEVELS

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


# --- geometry (pure numpy) -------------------------------------------------------------------------

def distance_to_polyline(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance of each point to a polyline (its segments; a single vertex is a point). (M, 2), (K, 2) -> (M,)."""
    points = np.asarray(points, np.float64).reshape(-1, 2)
    polyline = np.asarray(polyline, np.float64).reshape(-1, 2)
    if len(points) == 0:
        return np.zeros(0)
    if len(polyline) == 0:
        return np.full(len(points), np.inf)
    if len(polyline) == 1:
        return np.linalg.norm(points - polyline[0], axis=-1)
    start, end = polyline[:-1], polyline[1:]  # (K-1, 2)
    seg = end - start
    length2 = np.maximum(np.sum(seg**2, axis=-1), 1e-12)
    best = np.full(len(points), np.inf)
    for lo in range(0, len(points), 2048):  # bounded memory for long inputs
        p = points[lo:lo + 2048, None, :]  # (m, 1, 2)
        along = np.clip(np.sum((p - start) * seg, axis=-1) / length2, 0.0, 1.0)  # (m, K-1)
        closest = start + along[..., None] * seg
        best[lo:lo + 2048] = np.min(np.linalg.norm(p - closest, axis=-1), axis=-1)
    return best


def _dedupe(points: np.ndarray, min_gap: float = 0.1) -> np.ndarray:
    """Drops points closer than `min_gap` to the previous kept one. (K, 2) -> (K', 2)"""
    if len(points) < 2:
        return points
    kept = [points[0]]
    for point in points[1:]:
        if np.linalg.norm(point - kept[-1]) >= min_gap:
            kept.append(point)
    return np.asarray(kept)


def max_curvature(polyline: np.ndarray, window_m: float = 5.0) -> float:
    """Largest |heading change| / arc over windows of at least `window_m` along a polyline (1/m). (K, 2) -> float.

    0 for a polyline shorter than the window.
    """
    points = _dedupe(np.asarray(polyline, np.float64).reshape(-1, 2))
    if len(points) < 3:
        return 0.0
    step = np.diff(points, axis=0)
    heading = np.unwrap(np.arctan2(step[:, 1], step[:, 0]))  # (K-1,) heading of each segment
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(step, axis=-1))])
    mid = 0.5 * (arc[:-1] + arc[1:])  # arc of each segment's middle
    ends = np.searchsorted(mid, mid + window_m)  # first segment at least a window further
    has = ends < len(mid)
    if not has.any():
        return 0.0
    i = np.flatnonzero(has)
    j = ends[has]
    return float(np.max(np.abs(heading[j] - heading[i]) / (mid[j] - mid[i])))


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


# --- signals of one scenario -----------------------------------------------------------------------

def _sdc_row(batch, i: int) -> int:
    return int(np.argmax(np.asarray(batch.object_metadata.is_sdc[i])))


def _path_ahead(batch, i: int, sdc_xy: np.ndarray, config: DifficultyConfig) -> np.ndarray:
    """The on-route path from the SDC's start to past its logged end, or the logged SDC trajectory. (K, 2)"""
    paths = batch.sdc_paths
    valid = np.asarray(paths.valid[i], bool)  # (P, Q)
    on_route = np.flatnonzero(np.asarray(paths.on_route[i], bool) & (valid.sum(-1) >= 2))
    if on_route.size == 0 or len(sdc_xy) == 0:
        return sdc_xy
    xy = np.stack([np.asarray(paths.x[i]), np.asarray(paths.y[i])], -1)  # (P, Q, 2)
    gaps = [np.min(np.linalg.norm(xy[p][valid[p]] - sdc_xy[-1], axis=-1)) for p in on_route]
    p = on_route[int(np.argmin(gaps))]
    points, arc = xy[p][valid[p]], np.asarray(paths.arc_length[i][p])[valid[p]]
    start = arc[np.argmin(np.linalg.norm(points - sdc_xy[0], axis=-1))]
    end = arc[np.argmin(np.linalg.norm(points - sdc_xy[-1], axis=-1))]
    end = max(end + config.path_margin_m, start + config.min_path_ahead_m)
    ahead = points[(arc >= start) & (arc <= end)]
    return ahead if len(ahead) >= 2 else sdc_xy


def _lane_changes(batch, i: int, sdc_xy: np.ndarray, sdc_yaw: np.ndarray, config: DifficultyConfig) -> int:
    rg = batch.roadgraph_points
    is_lane = np.isin(np.asarray(rg.types[i]), LANE_TYPES) & np.asarray(rg.valid[i], bool)
    if len(sdc_xy) < 2 or not is_lane.any():
        return 0
    lane_xy = np.stack([np.asarray(rg.x[i])[is_lane], np.asarray(rg.y[i])[is_lane]], -1)
    lane_dir = np.arctan2(np.asarray(rg.dir_y[i])[is_lane], np.asarray(rg.dir_x[i])[is_lane])
    lane_id = np.asarray(rg.ids[i])[is_lane]
    lo, hi = sdc_xy.min(0) - 10.0, sdc_xy.max(0) + 10.0
    near = np.all((lane_xy >= lo) & (lane_xy <= hi), axis=-1)
    lane_xy, lane_dir, lane_id = lane_xy[near], lane_dir[near], lane_id[near]
    if len(lane_xy) == 0:
        return 0
    dist = np.linalg.norm(sdc_xy[:, None] - lane_xy[None], axis=-1)  # (S, K)
    aligned = np.abs(_wrap(lane_dir[None] - sdc_yaw[:, None])) < math.radians(config.lane_align_deg)
    dist = np.where(aligned, dist, np.inf)
    nearest = np.argmin(dist, axis=-1)
    found = np.isfinite(dist[np.arange(len(dist)), nearest]) & (dist[np.arange(len(dist)), nearest]
                                                                 <= config.lane_search_m)
    ids = np.where(found, lane_id[nearest], -1)
    # stable lanes: runs of one id lasting lane_persist_steps
    changes, current = 0, None
    run_id, run_start = None, 0
    for step, lane in enumerate(list(ids) + [None]):
        if lane == run_id:
            continue
        if run_id is not None and run_id >= 0 and step - run_start >= config.lane_persist_steps and run_id != current:
            if current is not None and _lanes_apart(lane_xy, lane_id, current, run_id, sdc_xy[run_start],
                                                    sdc_yaw[run_start], config.lane_change_offset_m):
                changes += 1
            current = run_id
        run_id, run_start = lane, step
    return changes


def _lanes_apart(lane_xy, lane_id, old, new, xy, yaw, offset_m: float) -> bool:
    """The nearest points of lanes `old` and `new` to `xy` lie more than offset_m apart sideways of `yaw`."""
    normal = np.array([-np.sin(yaw), np.cos(yaw)])
    nearest = []
    for lane in (old, new):
        points = lane_xy[lane_id == lane]
        nearest.append(points[np.argmin(np.linalg.norm(points - xy, axis=-1))])
    return abs(float((nearest[1] - nearest[0]) @ normal)) > offset_m


def difficulty_score(num_interacting: int, is_intersection: bool, curvature: float, sdc_speed: float,
                     num_lane_changes: int, num_vru_near_path: int,
                     config: DifficultyConfig = DifficultyConfig()) -> int:
    """The documented 0..11 score (see the module docstring)."""
    curve = 2 if curvature >= config.sharp_curvature else 1 if curvature >= config.curved_curvature else 0
    interacting = sum(num_interacting >= step for step in config.interacting_steps)
    return (interacting + int(is_intersection) + curve + int(sdc_speed >= config.fast_speed_mps)
            + min(num_lane_changes, 2) + 2 * int(num_vru_near_path > 0))


def difficulty_level(score: int, config: DifficultyConfig = DifficultyConfig()) -> str:
    return "easy" if score <= config.easy_max_score else "medium" if score <= config.medium_max_score else "hard"


def state_difficulty(batch, index: int = 0, first_timestep: int = 10, last_timestep: int = 90,
                     config: DifficultyConfig = DifficultyConfig()) -> DifficultySignals:
    """Signals of episode `index` of a host (numpy) batched SimulatorState over the log window
    first_timestep..last_timestep (inclusive; clipped to the log)."""
    i = index
    log = batch.log_trajectory
    num_timesteps = np.asarray(log.x).shape[-1]
    t0 = int(np.clip(first_timestep, 0, num_timesteps - 1))
    t1 = int(np.clip(last_timestep, t0, num_timesteps - 1))
    window = slice(t0, t1 + 1)
    x, y = np.asarray(log.x[i])[:, window], np.asarray(log.y[i])[:, window]  # (N, S)
    valid = np.asarray(log.valid[i], bool)[:, window]
    sdc = _sdc_row(batch, i)
    sdc_valid = valid[sdc]
    sdc_xy = np.stack([x[sdc], y[sdc]], -1)[sdc_valid]
    sdc_yaw = np.asarray(log.yaw[i])[sdc, window][sdc_valid]
    speed = np.hypot(np.asarray(log.vel_x[i])[sdc, window], np.asarray(log.vel_y[i])[sdc, window])[sdc_valid]
    path = _path_ahead(batch, i, sdc_xy, config)

    others = np.ones(len(x), bool)
    others[sdc] = False
    near = np.full(x.shape, np.inf)
    where = valid & others[:, None]
    if where.any() and len(path):
        near[where] = distance_to_polyline(np.stack([x[where], y[where]], -1), path)
    closest = near.min(axis=-1)  # (N,) closest approach to the path ahead
    types = np.asarray(batch.object_metadata.object_types[i])
    num_interacting = int(np.sum(closest <= config.interaction_distance_m))
    num_vru = int(np.sum((closest <= config.vru_distance_m) & np.isin(types, VRU_TYPES)))

    lights = batch.log_traffic_light
    light_valid = np.asarray(lights.valid[i], bool)[:, window]
    light_xy = np.stack([np.asarray(lights.x[i])[:, window], np.asarray(lights.y[i])[:, window]], -1)[light_valid]
    has_light = bool(len(light_xy) and len(path)
                     and np.any(distance_to_polyline(light_xy, path) <= config.light_distance_m))

    rg = batch.roadgraph_points
    rg_valid = np.asarray(rg.valid[i], bool)
    rg_xy = np.stack([np.asarray(rg.x[i]), np.asarray(rg.y[i])], -1)
    rg_types = np.asarray(rg.types[i])
    is_intersection = has_light
    if len(path) >= 2:
        lo, hi = path.min(0) - config.light_distance_m, path.max(0) + config.light_distance_m
        box = rg_valid & np.all((rg_xy >= lo) & (rg_xy <= hi), axis=-1)
        stops = box & (rg_types == sch.RG_STOP_SIGN)
        if stops.any() and np.any(distance_to_polyline(rg_xy[stops], path) <= config.light_distance_m):
            is_intersection = True
        lanes = box & np.isin(rg_types, LANE_TYPES)
        if not is_intersection and lanes.any():
            is_intersection = _crosses(path, rg_xy[lanes], np.asarray(rg.dir_x[i])[lanes],
                                       np.asarray(rg.dir_y[i])[lanes], config)

    curvature = max_curvature(path, config.curvature_window_m)
    sdc_speed = float(np.mean(speed)) if len(speed) else 0.0
    lane_changes = _lane_changes(batch, i, sdc_xy, sdc_yaw, config)
    score = difficulty_score(num_interacting, is_intersection, curvature, sdc_speed, lane_changes, num_vru, config)
    return DifficultySignals(num_interacting=num_interacting, num_vru_near_path=num_vru, has_traffic_light=has_light,
                             is_intersection=bool(is_intersection), max_curvature=curvature, sdc_speed=sdc_speed,
                             num_lane_changes=lane_changes, score=score, level=difficulty_level(score, config))


def _crosses(path: np.ndarray, lane_xy: np.ndarray, dir_x: np.ndarray, dir_y: np.ndarray,
             config: DifficultyConfig) -> bool:
    """A lane point near the path ahead heads more than crossing_angle_deg off the path's nearest segment."""
    step = np.diff(path, axis=0)
    seg_heading = np.arctan2(step[:, 1], step[:, 0])  # (K-1,)
    mid = 0.5 * (path[:-1] + path[1:])
    dist = distance_to_polyline(lane_xy, path)
    close = dist <= config.crossing_distance_m
    if not close.any():
        return False
    nearest = np.argmin(np.linalg.norm(lane_xy[close][:, None] - mid[None], axis=-1), axis=-1)
    lane_heading = np.arctan2(dir_y[close], dir_x[close])
    off = np.abs(_wrap(lane_heading - seg_heading[nearest]))
    off = np.minimum(off, np.pi - off)  # a lane the other way along the path is not crossing it
    return bool(np.any(off > math.radians(config.crossing_angle_deg)))


def scenario_difficulty(scenario, config: DifficultyConfig = DifficultyConfig(), data_config=None,
                        first_timestep: int = 10, last_timestep: int = 90) -> DifficultySignals:
    """Signals of one `scenariomax.Scenario` (converted with `data_config`, default DataConfig())."""
    from vmax_sim.data import DataConfig, scenario_to_numpy_state, stack_states

    data_config = data_config or DataConfig(include_map_index=False)
    batch = stack_states([scenario_to_numpy_state(scenario, data_config)])
    return state_difficulty(batch, 0, first_timestep, last_timestep, config)


# --- buckets and the per-bucket report -------------------------------------------------------------

def signal_buckets(signals: DifficultySignals, config: DifficultyConfig = DifficultyConfig()) -> list[tuple[str, str]]:
    """(group, bucket) pairs an episode falls in: its level, then one bucket per signal."""
    n = signals.num_interacting
    curve = signals.max_curvature
    speed = signals.sdc_speed
    return [
        ("difficulty", signals.level),
        ("interacting objects", _count_bucket(n, config)),
        ("intersection", "yes" if signals.is_intersection else "no"),
        ("traffic light", "yes" if signals.has_traffic_light else "no"),
        ("path curvature", "sharp" if curve >= config.sharp_curvature else
         "curved" if curve >= config.curved_curvature else "straight"),
        ("SDC speed", f">= {config.fast_speed_mps:g} m/s" if speed >= config.fast_speed_mps else
         f"< {config.slow_speed_mps:g} m/s" if speed < config.slow_speed_mps else
         f"{config.slow_speed_mps:g}-{config.fast_speed_mps:g} m/s"),
        ("lane changes", "0" if signals.num_lane_changes == 0 else "1+"),
        ("VRU near path", "0" if signals.num_vru_near_path == 0 else "1+"),
    ]


def _count_buckets(config: DifficultyConfig) -> tuple[str, ...]:
    one, four, eight = config.interacting_steps
    return ("0" if one == 1 else f"< {one}", f"{one}-{four - 1}", f"{four}-{eight - 1}", f">= {eight}")


def _count_bucket(n: int, config: DifficultyConfig) -> str:
    return _count_buckets(config)[sum(n >= step for step in config.interacting_steps)]


def bucket_order(config: DifficultyConfig = DifficultyConfig()) -> list[tuple[str, str]]:
    """Every (group, bucket) in the order of the report (empty buckets included)."""
    slow, fast = config.slow_speed_mps, config.fast_speed_mps
    return ([("difficulty", level) for level in LEVELS]
            + [("interacting objects", b) for b in _count_buckets(config)]
            + [("intersection", b) for b in ("no", "yes")] + [("traffic light", b) for b in ("no", "yes")]
            + [("path curvature", b) for b in ("straight", "curved", "sharp")]
            + [("SDC speed", b) for b in (f"< {slow:g} m/s", f"{slow:g}-{fast:g} m/s", f">= {fast:g} m/s")]
            + [("lane changes", b) for b in ("0", "1+")] + [("VRU near path", b) for b in ("0", "1+")])


@dataclasses.dataclass(frozen=True)
class BucketRow:
    group: str
    bucket: str
    cells: tuple  # per policy: (episodes, accuracy in [0, 1] or nan, V-Max score in [0, 1] or nan)


def bucket_rows(episodes: Sequence[dict], signals: Sequence[Sequence[DifficultySignals]],
                config: DifficultyConfig = DifficultyConfig()) -> list[BucketRow]:
    """Accuracy and V-Max score per bucket. episodes[k]: policy k's episode metrics (name -> (E,));
    signals[k]: the (E,) signals of its episodes, in the same order."""
    per_policy = []
    for metrics, sigs in zip(episodes, signals):
        accurate = np.asarray(metrics["accurate"], np.float64)
        vmax = np.asarray(metrics["vmax_score"], np.float64)
        if len(sigs) != len(accurate):
            raise ValueError(f"difficulty: {len(sigs)} scenarios tagged but {len(accurate)} episodes evaluated")
        members: dict[tuple[str, str], list[int]] = {}
        for e, sig in enumerate(sigs):
            for key in signal_buckets(sig, config):
                members.setdefault(key, []).append(e)
        per_policy.append((accurate, vmax, members))
    rows = []
    for key in bucket_order(config):
        cells = []
        for accurate, vmax, members in per_policy:
            index = members.get(key, [])
            cells.append((len(index), float(np.mean(accurate[index])) if index else math.nan,
                          float(np.mean(vmax[index])) if index else math.nan))
        rows.append(BucketRow(key[0], key[1], tuple(cells)))
    return rows


def _pct(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{100 * value:.2f}"


def format_difficulty_markdown(names: Sequence[str], rows: Sequence[BucketRow]) -> str:
    """Markdown: group, bucket, episodes, then accuracy and V-Max score (in %) per policy."""
    header = ["Group", "Bucket", "Episodes"]
    for name in names:
        header += [f"{name} accuracy (%)", f"{name} V-Max (%)"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        counts = sorted({cell[0] for cell in row.cells})
        cells = [row.group, row.bucket, " / ".join(str(c[0]) for c in row.cells) if len(counts) > 1 else str(counts[0])]
        for _, accuracy, vmax in row.cells:
            cells += [_pct(accuracy), _pct(vmax)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def difficulty_csv(names: Sequence[str], rows: Sequence[BucketRow]) -> str:
    """Long CSV: group, bucket, policy, episodes, accuracy, vmax_score (fractions; empty when no episode)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["group", "bucket", "policy", "episodes", "accuracy", "vmax_score"])
    for row in rows:
        for name, (count, accuracy, vmax) in zip(names, row.cells):
            writer.writerow([row.group, row.bucket, name, count, "" if count == 0 else f"{accuracy:.6f}",
                             "" if count == 0 else f"{vmax:.6f}"])
    return buffer.getvalue()


def scenarios_csv(scenario_ids: Sequence[str], signals: Sequence[DifficultySignals]) -> str:
    """One row per scenario: id and every signal, score and level."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    fields = [f.name for f in dataclasses.fields(DifficultySignals)]
    writer.writerow(["scenario_id"] + fields)
    for scenario_id, sig in zip(scenario_ids, signals):
        values = sig.as_dict()
        writer.writerow([scenario_id] + [f"{values[f]:.4f}" if isinstance(values[f], float) else values[f]
                                         for f in fields])
    return buffer.getvalue()


class DifficultyCollector:
    """An evaluation `on_batch` hook (see `compare_policies`) that tags every evaluated scenario.

    Keeps a few numbers per episode. Policies that run the same host batch share one computation.
    """

    def __init__(self, config: DifficultyConfig = DifficultyConfig()):
        self.config = config
        self.signals: dict[int, list[DifficultySignals]] = {}
        self.scenario_ids: dict[int, list[str]] = {}
        self._last: tuple | None = None  # (host batch, its signals)

    def __call__(self, column: int, ids: Sequence[str], batch, rollout, real: int) -> None:
        if self._last is not None and self._last[0] is batch:
            signals = self._last[1]
        else:
            first = np.asarray(rollout.trajectory["first_timestep"]) if rollout.trajectory else np.full(real, 10)
            num_steps = int(np.asarray(rollout.step_valid).shape[-1])
            signals = [state_difficulty(batch, i, int(first[i]), int(first[i]) + num_steps, self.config)
                       for i in range(real)]
            self._last = (batch, signals)
        self.signals.setdefault(column, []).extend(signals[:real])
        self.scenario_ids.setdefault(column, []).extend(list(ids)[:real])

    def rows(self, runs) -> list[BucketRow]:
        """Per-bucket accuracy and V-Max score of `runs` (the PolicyRun columns of compare_policies)."""
        return bucket_rows([run.result.episodes for run in runs],
                           [self.signals.get(column, []) for column in range(len(runs))], self.config)

    def markdown(self, runs) -> str:
        return format_difficulty_markdown([run.name for run in runs], self.rows(runs))

    def write(self, out_dir: str | Path, runs) -> list[Path]:
        """difficulty.csv (per bucket and policy) and difficulty-scenarios.csv (signals of the first column)."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = [out / "difficulty.csv", out / "difficulty-scenarios.csv"]
        paths[0].write_text(difficulty_csv([run.name for run in runs], self.rows(runs)))
        paths[1].write_text(scenarios_csv(self.scenario_ids.get(0, []), self.signals.get(0, [])))
        return paths

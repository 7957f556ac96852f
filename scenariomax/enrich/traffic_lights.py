"""Traffic-light states inferred from vehicle motion where the log has none.

For each light slot with a controlled lane and a stop point, entries whose state is unknown (not
valid, or state 0) get evidence from vehicles travelling along that lane near its stop point
(lateral offset <= `lane_halfwidth_m`, heading within 45 deg of the lane):
- green (GO): a vehicle crosses the stop point at step t -> GO for steps t-`green_window`..t+`green_window`;
- red (STOP): a vehicle stands (speed < `stopped_speed_mps`) within `queue_distance_m` before the
  stop point while cross traffic flows (a vehicle within `cross_radius_m` of the stop point moving
  faster than `cross_speed_mps` roughly perpendicular to the lane).
Steps with both kinds of evidence stay unknown; gaps of at most `max_gap_steps` between equal
evidence are filled. Inferred entries are marked in `tl_inferred`; logged known states are never
changed and lights without evidence stay unknown.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich.geometry import project_to_polyline
from scenariomax.enrich.lanes import Lanes
from scenariomax.scenario import Scenario


@dataclasses.dataclass(frozen=True)
class LightSettings:
    lane_halfwidth_m: float = 2.0
    queue_distance_m: float = 10.0
    stopped_speed_mps: float = 0.5
    cross_radius_m: float = 30.0
    cross_speed_mps: float = 2.0
    green_window: int = 5
    max_gap_steps: int = 10


def _stop_pose(scenario: Scenario, light: int, lanes: Lanes) -> tuple[np.ndarray, np.ndarray, int] | None:
    """Stop point (3,), lane direction there (2,), controlled lane id; None when unknown."""
    has_lane = scenario.tl_lane_id[light] >= 0
    if not has_lane.any():
        return None
    step = int(np.argmax(has_lane & scenario.tl_valid[light])) if (has_lane & scenario.tl_valid[light]).any() \
        else int(np.argmax(has_lane))
    lane_id = int(scenario.tl_lane_id[light, step])
    stop = np.array([scenario.tl_x[light, step], scenario.tl_y[light, step], scenario.tl_z[light, step]], np.float64)
    lane = lanes.index_of.get(lane_id)
    if lane is None:
        return None
    line = lanes.polyline(lane)
    _, arc, _ = project_to_polyline(stop[None, :2], line)
    k = int(np.clip(np.searchsorted(lanes.cumulative[lane], arc[0]) - 1, 0, len(line) - 1))
    return stop, lanes.point_tangent[lanes.offsets[lane] + k], lane_id  # tangents(line)[k], computed once


def _fill_gaps(evidence: np.ndarray, max_gap: int) -> np.ndarray:
    """Fills runs of False of length <= max_gap that lie between two True entries, along the last axis.
    (..., T) -> (..., T)"""
    steps = np.arange(evidence.shape[-1])
    before = np.maximum.accumulate(np.where(evidence, steps, -1), axis=-1)  # the last True at or before each step
    after = np.flip(np.minimum.accumulate(np.flip(np.where(evidence, steps, evidence.shape[-1]), -1), axis=-1), -1)
    return evidence | ((before >= 0) & (after < evidence.shape[-1]) & (after - before <= max_gap + 1))


def _dilate(marks: np.ndarray, reach: int) -> np.ndarray:
    """True where a True of `marks` lies within `reach` steps either side, along the last axis. (..., T) -> (..., T)"""
    count = np.concatenate([np.zeros(marks.shape[:-1] + (1,), np.int64), np.cumsum(marks, axis=-1)], axis=-1)
    steps = np.arange(marks.shape[-1])
    high, low = np.minimum(steps + reach + 1, marks.shape[-1]), np.maximum(steps - reach, 0)
    return count[..., high] > count[..., low]


class Motion(NamedTuple):
    """What every light's evidence reads from the vehicles, computed once per scenario. (V, T) each: only the
    objects that are vehicles valid at some step (every piece of evidence needs a valid vehicle step, so the
    other rows never count; dropping them saves most of the work on scenes with many pedestrians or empty
    slots)."""

    valid: np.ndarray  # bool: valid vehicle steps
    cos_yaw: np.ndarray
    sin_yaw: np.ndarray
    speed: np.ndarray  # m/s
    x: np.ndarray
    y: np.ndarray


def vehicle_motion(scenario: Scenario) -> Motion:
    vehicles = scenario.object_type == sch.OBJECT_TYPE_VEHICLE
    valid = scenario.valid & vehicles[:, None]
    rows = np.flatnonzero(valid.any(axis=1))
    yaw = scenario.bbox_yaw[rows]
    return Motion(valid[rows], np.cos(yaw), np.sin(yaw), np.hypot(scenario.velocity_x[rows], scenario.velocity_y[rows]),
                  scenario.x[rows], scenario.y[rows])


def light_evidence(scenario: Scenario, stop: np.ndarray, direction: np.ndarray,
                   settings: LightSettings = LightSettings(), motion: Motion | None = None) -> tuple[np.ndarray,
                                                                                                    np.ndarray]:
    """(green (T,) bool, red (T,) bool) evidence for a stop point and lane direction. `motion`: the scenario's
    `vehicle_motion`, when the caller has it (it is the same for every light)."""
    motion = vehicle_motion(scenario) if motion is None else motion
    greens, reds = _evidence_of_lights(scenario.num_timesteps, np.asarray(stop, np.float64)[None, :2],
                                       np.asarray(direction, np.float64)[None, :2], settings, motion)
    return greens[0], reds[0]


def _near_pairs(stops: np.ndarray, motion: Motion, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """(light, vehicle) index pairs, sorted by light, of the vehicles whose valid positions' bounding box comes
    within `reach` of the light's stop point. -> (P,), (P,)"""
    valid = motion.valid
    low_x = np.where(valid, motion.x, np.inf).min(axis=1)  # (V,)
    high_x = np.where(valid, motion.x, -np.inf).max(axis=1)
    low_y = np.where(valid, motion.y, np.inf).min(axis=1)
    high_y = np.where(valid, motion.y, -np.inf).max(axis=1)
    gap_x = np.maximum(np.maximum(low_x - stops[:, 0:1], stops[:, 0:1] - high_x), 0.0)  # (L, V)
    gap_y = np.maximum(np.maximum(low_y - stops[:, 1:2], stops[:, 1:2] - high_y), 0.0)
    return np.nonzero(gap_x * gap_x + gap_y * gap_y <= reach * reach)


def _evidence_of_lights(num_steps: int, stops: np.ndarray, directions: np.ndarray, settings: LightSettings,
                        motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """The green and red evidence of many lights at once (float64 stop points (L, 2+) and lane directions (L, 2)),
    on (light, vehicle) pairs instead of one numpy call sequence per light. A light's green: some vehicle on its
    lane crossed the stop point within `green_window` steps; red: a vehicle stands queued before it while another
    crosses the junction; gaps filled, steps with both dropped. -> green, red (L, T) bool

    Only the vehicles that pass near a light can count for it: a crossing vehicle is within `cross_radius_m` of the
    stop point, a queued one within the queue's diagonal, and one that crosses the stop line on the lane does so
    between two of its positions within `lane_halfwidth_m` of the stop point, so their bounding box holds a point
    that near (a lane half-width is less than the queue's diagonal). The pairs are those within the larger of the
    cross radius and the queue's diagonal (+1 m against rounding): the same evidence."""
    greens = np.zeros((len(stops), num_steps), bool)
    reds = np.zeros((len(stops), num_steps), bool)
    reach = max(settings.cross_radius_m, np.hypot(settings.queue_distance_m, settings.lane_halfwidth_m)) + 1.0
    light, vehicle = _near_pairs(stops, motion, reach)  # (P,) each
    if not len(light):
        return greens, reds
    valid = motion.valid[vehicle]  # (P, T)
    d0, d1 = directions[light, 0, None], directions[light, 1, None]  # (P, 1)
    rel_x, rel_y = motion.x[vehicle] - stops[light, 0, None], motion.y[vehicle] - stops[light, 1, None]  # (P, T)
    along = rel_x * d0 + rel_y * d1  # > 0 past the stop point
    lateral = np.abs(rel_x * d1 - rel_y * d0)
    heading_cos = motion.cos_yaw[vehicle] * d0 + motion.sin_yaw[vehicle] * d1
    on_lane = valid & (lateral <= settings.lane_halfwidth_m) & (heading_cos > np.cos(np.pi / 4))
    crossed = on_lane[:, 1:] & on_lane[:, :-1] & (along[:, :-1] < 0) & (along[:, 1:] >= 0)  # (P, T - 1)
    speed = motion.speed[vehicle]
    queued = on_lane & (along < 0) & (along >= -settings.queue_distance_m) & (speed < settings.stopped_speed_mps)
    crossing = (valid & (np.hypot(rel_x, rel_y) <= settings.cross_radius_m) & (speed > settings.cross_speed_mps)
                & (np.abs(heading_cos) < 0.5))
    # Per light: any of its vehicles (pairs sorted by light; each run of one light's pairs reduced at once).
    lights, first = np.unique(light, return_index=True)  # (L',), (L',)
    reds[lights] = (np.logical_or.reduceat(queued, first, axis=0) & np.logical_or.reduceat(crossing, first, axis=0))
    crossed_at = np.zeros((len(lights), num_steps), bool)
    crossed_at[:, 1:] = np.logical_or.reduceat(crossed, first, axis=0)  # a vehicle crossed on arriving at the step
    green = _fill_gaps(_dilate(crossed_at, settings.green_window), settings.max_gap_steps)
    red = _fill_gaps(reds[lights], settings.max_gap_steps)
    conflict = green & red
    greens[lights], reds[lights] = green & ~conflict, red & ~conflict
    return greens, reds


def with_inferred_lights(scenario: Scenario, lanes: Lanes, settings: LightSettings = LightSettings()) -> Scenario:
    """The scenario with unknown light states filled from vehicle motion where there is evidence."""
    num_lights = scenario.tl_state.shape[0]
    if num_lights == 0:
        return scenario
    state, valid, inferred = scenario.tl_state.copy(), scenario.tl_valid.copy(), scenario.tl_inferred.copy()
    lane_id = scenario.tl_lane_id.copy()
    xs, ys, zs = scenario.tl_x.copy(), scenario.tl_y.copy(), scenario.tl_z.copy()
    poses = [(light, pose) for light in range(num_lights) if (pose := _stop_pose(scenario, light, lanes)) is not None]
    greens, reds = _evidence_of_lights(scenario.num_timesteps, np.array([pose[0] for _, pose in poses]).reshape(-1, 3),
                                       np.array([pose[1] for _, pose in poses]).reshape(-1, 2), settings,
                                       vehicle_motion(scenario))
    for (light, (stop, _, controlled)), green, red in zip(poses, greens, reds):
        unknown = ~(valid[light] & (state[light] != sch.TL_UNKNOWN))
        for evidence, value in ((green, sch.TL_GO), (red, sch.TL_STOP)):
            fill = evidence & unknown
            state[light, fill], valid[light, fill], inferred[light, fill] = value, True, True
            lane_id[light, fill] = controlled
            xs[light, fill], ys[light, fill], zs[light, fill] = stop
    return scenario.replace(tl_state=state, tl_valid=valid, tl_inferred=inferred, tl_lane_id=lane_id,
                            tl_x=xs, tl_y=ys, tl_z=zs)

"""Physical-sanity repairs shared by the sources (docs/datasets.md, "Sanity of physical quantities").

Small pure functions on per-step (N, T) arrays, and `sanitize_scenario`, which applies them to a converted
`Scenario` of any real source (the pipeline calls it for every source in SANITIZED_SOURCES) and writes what it
changed under `metadata[MANIFEST_NOTES]`: yaw flips of vehicles and cyclists turned back, velocities that
disagree with the positions derived from them, boxes clearly wider than long swapped, z spikes flattened, and
steps that are not 0.1 s apart reported (never resampled here: sources that can resample do it themselves).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich.geometry import row_norm, wrap_angle
from scenariomax.scenario import Scenario
from scenariomax.sources.base import MANIFEST_NOTES

# The raw-data sources whose scenarios the pipeline sanitizes. Not "synthetic" (exact by construction) nor
# "records" (shards already written, re-read by `scenariomax build-sdc-paths`).
SANITIZED_SOURCES = ("womd", "nuplan", "av2", "scenarionet", "gpudrive")
MAX_LISTED_IDS = 20  # object ids listed per note; longer lists become a count (as the GPUDrive source does)

# --- time ---------------------------------------------------------------------------------------------
STEP_SECONDS = 0.1  # every shard is 10 Hz
# A log is 10 Hz when its steps average 0.1 s within STEP_MEAN_TOL_S (no drift) and no step is off by more than
# STEP_JITTER_S (no dropped or doubled frame). Timestamps wobble and are kept as they are: WOMD has real steps of
# 0.0995 s and 0.0894 s; the mean, unlike a median, lets jitter cancel (nuPlan's 20 Hz sweeps taken two by two in
# the nuPlan test log give steps of 102, 99, 99 ms: median 99 ms, mean 100 ms).
STEP_MEAN_TOL_S = 1e-3
STEP_JITTER_S = 0.5 * STEP_SECONDS

# --- yaw ----------------------------------------------------------------------------------------------
# Yaw flips: a run of at most MAX_FLIP_STEPS steps whose heading is within FLIP_TOL_RAD of a half turn away
# from runs of at least MIN_REFERENCE_STEPS steps on each side it has is a box the tracker turned round, not a
# turn. A half turn give or take heading noise: a 2.7 rad one-step glitch of a parked WOMD truck is not a flip,
# and adding pi to it would leave it 0.44 rad wrong.
FLIP_TOL_RAD = 0.25
FLIP_RAD = np.pi - FLIP_TOL_RAD
MAX_FLIP_STEPS = 3
MIN_REFERENCE_STEPS = 5
FLIP_CHECKED_TYPES = (sch.OBJECT_TYPE_VEHICLE, sch.OBJECT_TYPE_CYCLIST)  # pedestrians do turn on the spot

# --- boxes --------------------------------------------------------------------------------------------
# A vehicle or cyclist more than SWAP_RATIO times wider than long has its length and width swapped (nuScenes
# egos through ScenarioNet arrive as 1.73 m long, 4.08 m wide; pedestrians and "other" may be wider).
SWAP_RATIO = 1.2
SWAP_CHECKED_TYPES = (sch.OBJECT_TYPE_VEHICLE, sch.OBJECT_TYPE_CYCLIST)

# --- velocity -----------------------------------------------------------------------------------------
MAX_SPEED_MPS = 150.0  # a logged velocity beyond this is garbage: derive it from the positions
# The logged velocity must match the position difference to one side of the step within
# VELOCITY_TOL_MPS + VELOCITY_TOL_FRACTION * |difference| (WOMD velocities are tracker outputs, a little noisy).
VELOCITY_TOL_MPS = 2.0
VELOCITY_TOL_FRACTION = 0.25
# A step whose previous step is not logged (a track's first step, or the first after a gap) can only be checked
# against the forward difference, i.e. the next step's motion: a causal tracker's velocity there reaches back to
# positions the log does not hold (WOMD logs velocity[k] = (p[k] - p[k-1]) / 0.1 s exactly). The two differ by
# the track's own step-to-step change of its position differences (~2 m/s for a jittery WOMD pedestrian), so
# that check adds NOISE_FACTOR times the track's median change.
NOISE_FACTOR = 2.0

# --- z ------------------------------------------------------------------------------------------------
# A box centre more than Z_OUTLIER_M from the median z of its own track within Z_WINDOW_STEPS steps either side
# is a glitch (a real track varies by < 3.2 m over 9 s; a local median keeps a car climbing a long ramp untouched).
Z_OUTLIER_M = 5.0
Z_WINDOW_STEPS = 5


# --- time ---------------------------------------------------------------------------------------------
def nominal_steps(steps: np.ndarray) -> bool:
    """Whether step durations (seconds) are 0.1 s up to timestamp jitter, no frame dropped. (S,) -> bool"""
    if len(steps) == 0:
        return True
    return abs(float(np.mean(steps)) - STEP_SECONDS) < STEP_MEAN_TOL_S and bool(
        np.all(np.abs(steps - STEP_SECONDS) < STEP_JITTER_S))


def is_nominal_10hz(times: np.ndarray) -> bool:
    """Seconds of consecutive steps (T,) -> whether they are 10 Hz (see `nominal_steps`)."""
    return nominal_steps(np.diff(times))


def step_seconds(timestamp_micros: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Seconds between consecutive valid steps of the same object. (N, T), (N, T) -> (pairs,)"""
    pair = valid[:, 1:] & valid[:, :-1]
    return np.diff(timestamp_micros.astype(np.int64), axis=1)[pair] * 1e-6


# --- yaw ----------------------------------------------------------------------------------------------
def flipped_steps(yaw: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Steps of one track whose box is turned round (see FLIP_RAD). (T,), (T,) -> (T,) bool"""
    steps = np.flatnonzero(usable)
    flipped = np.zeros(yaw.shape, bool)
    if len(steps) < MIN_REFERENCE_STEPS + 1:
        return flipped
    jumps = np.abs(wrap_angle(np.diff(np.asarray(yaw, np.float64)[steps]))) > FLIP_RAD
    run_of = np.concatenate([[0], np.cumsum(jumps)])  # consecutive usable steps split at every jump
    sizes = np.bincount(run_of)
    for run in np.flatnonzero(sizes <= MAX_FLIP_STEPS):
        sides = [side for side in (run - 1, run + 1) if 0 <= side < len(sizes)]
        if sides and all(sizes[side] >= MIN_REFERENCE_STEPS for side in sides):
            flipped[steps[run_of == run]] = True
    return flipped


def _has_jump(yaw: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Tracks with a heading jump of about FLIP_RAD between consecutive usable steps (a margin below it: a
    superset of the tracks `flipped_steps` can flip). (N, T), (N, T) -> (N,) bool"""
    steps = np.arange(yaw.shape[1])
    last = np.maximum.accumulate(np.where(usable, steps, -1), axis=1)  # (N, T) last usable step up to t
    previous = np.concatenate([np.full((len(yaw), 1), -1), last[:, :-1]], axis=1)  # before t
    has_previous = usable & (previous >= 0)
    rows = np.arange(len(yaw))[:, None]
    step = np.asarray(yaw, np.float64) - np.asarray(yaw, np.float64)[rows, np.maximum(previous, 0)]
    with np.errstate(invalid="ignore"):
        return (has_previous & ~(np.abs(wrap_angle(step)) <= FLIP_RAD - 1e-6)).any(axis=1)


def fix_yaw_flips(yaw: np.ndarray, usable: np.ndarray, types: np.ndarray) -> tuple[np.ndarray, int]:
    """Turns flipped boxes of vehicles and cyclists back. (N, T), (N, T), (N,) -> ((N, T), steps fixed)"""
    flipped = np.zeros(yaw.shape, bool)
    # A track without a jump between consecutive usable steps has nothing flipped: only the others are walked.
    for row in np.flatnonzero(np.isin(types, FLIP_CHECKED_TYPES) & _has_jump(yaw, usable)):
        flipped[row] = flipped_steps(yaw[row], usable[row])
    return np.where(flipped, wrap_angle(yaw + np.pi), yaw), int(flipped.sum())


# --- boxes --------------------------------------------------------------------------------------------
def wider_than_long(length: np.ndarray, width: np.ndarray, types: np.ndarray,
                    valid: np.ndarray | None = None) -> np.ndarray:
    """Objects whose box is clearly wider than long, judged on the median size over their valid steps.

    length, width: (N,) or (N, T) metres; types (N,); valid (N, T) or None. -> (N,) bool
    """
    length, width = np.asarray(length, np.float64), np.asarray(width, np.float64)
    if length.ndim == 2:
        mask = np.ones(length.shape, bool) if valid is None else np.asarray(valid, bool)
        length = nanmedian_last(np.where(mask, length, np.nan))  # an object never valid: NaN
        width = nanmedian_last(np.where(mask, width, np.nan))
    with np.errstate(invalid="ignore"):
        wide = np.isfinite(length) & np.isfinite(width) & (length > 0) & (width > SWAP_RATIO * length)
    return wide & np.isin(types, SWAP_CHECKED_TYPES)


def swap_rows(length: np.ndarray, width: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """length and width exchanged on the rows where `rows` (N,) is True. (N, ...) each -> (N, ...) each"""
    flag = np.reshape(rows, rows.shape + (1,) * (np.ndim(length) - 1))
    return np.where(flag, width, length), np.where(flag, length, width)


# --- velocity -----------------------------------------------------------------------------------------
def difference_noise(step: np.ndarray, pair: np.ndarray) -> np.ndarray:
    """Median change between consecutive position differences of each track, m/s. (N, T-1, 2), (N, T-1) -> (N,)"""
    both = pair[:, 1:] & pair[:, :-1]  # (N, T-2) three consecutive usable steps
    change = np.where(both, row_norm(np.diff(step, axis=1)), np.nan)
    # A track without three consecutive steps: NaN, then 0.
    noise = nanmedian_last(change) if change.shape[1] else np.full(len(change), np.nan)
    return np.nan_to_num(noise, nan=0.0)


def consistent_velocity(xy: np.ndarray, velocity: np.ndarray, usable: np.ndarray,
                        dt: float = STEP_SECONDS) -> tuple[np.ndarray, np.ndarray]:
    """Velocities that agree with the positions. (N, T, 2), (N, T, 2), (N, T) -> ((N, T, 2), derived (N, T))

    A usable step keeps its logged velocity when it is finite, sane and matches the position
    difference to the previous or the next usable step (the next alone: see NOISE_FACTOR); otherwise
    (absent, garbage, inconsistent) it gets the central difference (one-sided at track ends, zero for
    an isolated step)."""
    xy, velocity = np.asarray(xy, np.float64), np.asarray(velocity, np.float64)
    pair = usable[:, 1:] & usable[:, :-1]  # (N, T-1) both ends usable
    with np.errstate(invalid="ignore", over="ignore"):
        step = np.where(pair[..., None], np.diff(xy, axis=1) / dt, 0.0)  # (N, T-1, 2)
    zeros, no = np.zeros_like(step[:, :1]), np.zeros_like(pair[:, :1])
    backward, has_backward = np.concatenate([zeros, step], axis=1), np.concatenate([no, pair], axis=1)
    forward, has_forward = np.concatenate([step, zeros], axis=1), np.concatenate([pair, no], axis=1)
    slack = np.where(has_backward, 0.0, NOISE_FACTOR * difference_noise(step, pair)[:, None])  # (N, T)

    def agrees(reference: np.ndarray, present: np.ndarray, extra: np.ndarray | float = 0.0) -> np.ndarray:
        tolerance = VELOCITY_TOL_MPS + VELOCITY_TOL_FRACTION * row_norm(reference) + extra
        return present & (row_norm(velocity - reference) <= tolerance)

    with np.errstate(invalid="ignore", over="ignore"):
        sane = np.all(np.isfinite(velocity), axis=-1) & (row_norm(velocity) < MAX_SPEED_MPS)
        checkable = has_backward | has_forward
        matches = agrees(backward, has_backward) | agrees(forward, has_forward, slack)
    derived = usable & (~sane | (checkable & ~matches))
    count = (has_backward.astype(float) + has_forward.astype(float))[..., None]
    central = (backward + forward) / np.maximum(count, 1.0)
    return np.where(derived[..., None], central, np.where(usable[..., None], velocity, 0.0)), derived


# --- z ------------------------------------------------------------------------------------------------
def local_median(values: np.ndarray, present: np.ndarray, half_window: int = Z_WINDOW_STEPS) -> np.ndarray:
    """Median of each track's present values within `half_window` steps either side (NaN where none).
    (N, T), (N, T) -> (N, T)"""
    padded = np.pad(np.where(present, values, np.nan), ((0, 0), (half_window, half_window)),
                    constant_values=np.nan)
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half_window + 1, axis=1)  # (N, T, W)
    return nanmedian_last(windows)


def nanmedian_last(values: np.ndarray) -> np.ndarray:
    """np.nanmedian over the last axis, the same bits, without its masked-array path (slow on many small
    windows): sort (NaN last), then the mean of the two middle present values. (..., W) -> (...)"""
    ordered = np.sort(values, axis=-1)  # (..., W)
    count = (~np.isnan(values)).sum(axis=-1)  # (...,) present values
    high = count // 2
    low = np.where(count % 2 == 1, high, high - 1)  # odd: the middle value twice, so the mean is itself
    pick = np.stack([np.maximum(low, 0), high], axis=-1)  # (..., 2)
    middle = np.take_along_axis(ordered, np.minimum(pick, values.shape[-1] - 1), axis=-1)  # (..., 2)
    with np.errstate(invalid="ignore", over="ignore"):
        median = (middle[..., 0] + middle[..., 1]) / 2.0
    return np.where(count > 0, median, np.nan)


def z_outliers(z: np.ndarray, present: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Box-centre z with spikes flattened. (N, T), (N, T) -> ((N, T), replaced (N, T))

    A present step more than Z_OUTLIER_M from the local median of its track (see Z_WINDOW_STEPS)
    takes that median; other steps are unchanged."""
    z = np.asarray(z, np.float64)
    # A track whose present z are finite and span at most Z_OUTLIER_M has no spike (its medians lie within that
    # span): only the others get the sliding median.
    finite = present & np.isfinite(z)
    span = np.where(finite, z, -np.inf).max(axis=1) - np.where(finite, z, np.inf).min(axis=1)  # (N,) -inf: none
    check = np.flatnonzero((span > Z_OUTLIER_M - 1e-6) | (present & ~finite).any(axis=1))
    reference = np.full(z.shape, np.nan)
    reference[check] = local_median(z[check], present[check])
    with np.errstate(invalid="ignore"):
        replaced = present & np.isfinite(reference) & (np.abs(z - reference) > Z_OUTLIER_M)
    return np.where(replaced, reference, z), replaced


# --- one scenario -------------------------------------------------------------------------------------
def id_list(ids: np.ndarray, mask: np.ndarray) -> list[int] | int:
    """The ids where `mask` (N,) holds, or their count when there are more than MAX_LISTED_IDS."""
    chosen = [int(i) for i in ids[mask]]
    return chosen if len(chosen) <= MAX_LISTED_IDS else len(chosen)


def merge_notes(notes: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    """A source's notes plus the sanity notes: counts add up, id lists join (a count past MAX_LISTED_IDS),
    a list meeting a count adds its length; anything else from `new` wins."""
    out = dict(notes)
    for key, value in new.items():
        old = out.get(key)
        if isinstance(old, list) and isinstance(value, list):
            joined = old + [item for item in value if item not in old]
            out[key] = joined if len(joined) <= MAX_LISTED_IDS else len(joined)
        elif isinstance(old, (int, list)) and isinstance(value, (int, list)) and not isinstance(old, bool):
            out[key] = (len(old) if isinstance(old, list) else old) + (len(value) if isinstance(value, list) else value)
        else:
            out[key] = value
    return out


def sanity_repairs(scenario: Scenario) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """(changed fields, notes) of the repairs `scenario` needs; both empty when it is sound."""
    valid = scenario.valid
    types = scenario.object_type
    changes: dict[str, np.ndarray] = {}
    notes: dict[str, Any] = {}
    steps = step_seconds(scenario.timestamp_micros, valid)
    ten_hz = nominal_steps(steps)
    if not ten_hz:
        notes["timestamps_not_10hz"] = {"mean_step_s": round(float(np.mean(steps)), 4),
                                        "min_step_s": round(float(steps.min()), 4),
                                        "max_step_s": round(float(steps.max()), 4)}
    yaw, num_flips = fix_yaw_flips(scenario.bbox_yaw, valid, types)
    if num_flips:
        changes["bbox_yaw"] = yaw.astype(np.float32)
        notes["yaw_flips_fixed"] = num_flips
    swapped = wider_than_long(scenario.length, scenario.width, types, valid)
    if swapped.any():
        changes["length"], changes["width"] = swap_rows(scenario.length, scenario.width, swapped)
        notes["boxes_swapped"] = id_list(scenario.object_id, swapped)
    if ten_hz:  # the differences assume 0.1 s steps
        xy = np.stack([scenario.x, scenario.y], axis=-1)
        logged = np.stack([scenario.velocity_x, scenario.velocity_y], axis=-1).astype(np.float64)
        derived_velocity, derived = consistent_velocity(xy, logged, valid)
        # Only steps whose value moves count: a source that already derived them (GPUDrive) is not repaired twice.
        changed = derived & (row_norm(derived_velocity - logged) > 1e-3)
        if changed.any():
            vx = np.where(changed, derived_velocity[..., 0], scenario.velocity_x)
            vy = np.where(changed, derived_velocity[..., 1], scenario.velocity_y)
            changes.update(velocity_x=vx, velocity_y=vy, speed=np.where(changed, np.hypot(vx, vy), scenario.speed),
                           vel_yaw=np.where(changed, np.arctan2(vy, vx), scenario.vel_yaw))
            notes["velocity_derived_steps"] = int(changed.sum())
    z, replaced = z_outliers(scenario.z, valid)
    if replaced.any():
        changes["z"] = z.astype(np.float32)
        notes["z_replaced_steps"] = int(replaced.sum())
    return changes, notes


def sanitize_scenario(scenario: Scenario) -> Scenario:
    """`scenario` with the sanity repairs applied and noted under metadata[MANIFEST_NOTES] (merged with the
    source's own notes); the same object when nothing needs repairing."""
    changes, notes = sanity_repairs(scenario)
    if not changes and not notes:
        return scenario
    metadata = dict(scenario.metadata)
    metadata[MANIFEST_NOTES] = merge_notes(metadata.get(MANIFEST_NOTES) or {}, notes)
    return scenario.replace(**changes, metadata=metadata)

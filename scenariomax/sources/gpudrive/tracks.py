"""Per-object repairs of a GPUDrive / Nocturne scenario: small pure functions on (N, T) arrays.

The files are WOMD logs converted by third-party scripts, so each field is checked against the
others before it is trusted: headings are put in radians and kept continuous, box sizes are made
positive and length-wise, velocities are checked against the positions, z is filled or de-spiked,
and the SDC is chosen when the file does not name it. Each repair is counted for the manifest.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from scenariomax import schema as sch
from scenariomax.enrich.geometry import wrap_angle
from scenariomax.sources.gpudrive.layout import headings_in_degrees

STEP_SECONDS = 0.1  # WOMD logs, hence every GPUDrive / Nocturne file, are sampled at 10 Hz
MAX_ABS_COORD_M = 1e7  # WOMD map frames span < 1e5 m; beyond this a coordinate is garbage
MAX_SPEED_MPS = 150.0  # a logged velocity beyond this is garbage: derive it from the positions
# Velocity check: the logged velocity must match the position difference to one side of the step within
# VELOCITY_TOL_MPS + VELOCITY_TOL_FRACTION * |difference| (WOMD velocities are tracker outputs, a little noisy).
VELOCITY_TOL_MPS = 2.0
VELOCITY_TOL_FRACTION = 0.25
# Yaw flips: a run of at most MAX_FLIP_STEPS steps whose heading is more than FLIP_RAD (~pi) away from runs of
# at least MIN_REFERENCE_STEPS steps on each side it has is a box the tracker turned round, not a turn.
FLIP_RAD = 2.5
MAX_FLIP_STEPS = 3
MIN_REFERENCE_STEPS = 5
FLIP_CHECKED_TYPES = (sch.OBJECT_TYPE_VEHICLE, sch.OBJECT_TYPE_CYCLIST)  # pedestrians do turn on the spot
# Box sizes: a vehicle or cyclist more than SWAP_RATIO times wider than long has length and width swapped.
SWAP_RATIO = 1.2
SWAP_CHECKED_TYPES = (sch.OBJECT_TYPE_VEHICLE, sch.OBJECT_TYPE_CYCLIST)
# Default (length, width, height) in metres by object type, for sizes a file lacks (the AV2 source's values).
DEFAULT_BOX = {sch.OBJECT_TYPE_VEHICLE: (4.5, 2.0, 1.6), sch.OBJECT_TYPE_PEDESTRIAN: (0.6, 0.6, 1.7),
               sch.OBJECT_TYPE_CYCLIST: (1.8, 0.7, 1.7), sch.OBJECT_TYPE_OTHER: (1.0, 1.0, 1.5)}
Z_OUTLIER_M = 5.0  # a box centre this far from its track's median height is a glitch (real tracks vary < 1 m)
OBJECT_TYPES = {"vehicle": sch.OBJECT_TYPE_VEHICLE, "pedestrian": sch.OBJECT_TYPE_PEDESTRIAN,
                "cyclist": sch.OBJECT_TYPE_CYCLIST}  # "other", "unset" and anything else -> other

SDC_NAMED, SDC_LAST_TRACK, SDC_FURTHEST = "named", "last-track", "furthest"


class ScenarioError(ValueError):
    """The file's scenario cannot be built (one line); the run goes on."""


def object_types(names: tuple[str, ...]) -> np.ndarray:
    """GPUDrive type names -> schema object types. (N,) -> (N,) int64"""
    return np.array([OBJECT_TYPES.get(name.strip().lower(), sch.OBJECT_TYPE_OTHER) for name in names], np.int64)


def usable_steps(position: np.ndarray, heading: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Steps marked valid whose x, y and heading are finite and sane. (N, T, 3), (N, T), (N, T) -> (N, T)"""
    with np.errstate(invalid="ignore"):
        xy_ok = np.all(np.isfinite(position[..., :2]) & (np.abs(position[..., :2]) < MAX_ABS_COORD_M), axis=-1)
        return valid & xy_ok & np.isfinite(heading) & (np.abs(heading) < MAX_ABS_COORD_M)


def yaw_in_radians(heading: np.ndarray, velocity: np.ndarray, usable: np.ndarray,
                   layout: str) -> tuple[np.ndarray, bool]:
    """(yaw wrapped to [-pi, pi), 0 at unusable steps; whether the file's unit was degrees). (N, T) -> (N, T)"""
    degrees = headings_in_degrees(heading, velocity, usable, layout)
    yaw = np.deg2rad(heading) if degrees else heading
    return np.where(usable, wrap_angle(np.where(usable, yaw, 0.0)), 0.0), degrees


def flipped_steps(yaw: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Steps of one track whose box is turned round (see FLIP_RAD). (T,), (T,) -> (T,) bool"""
    steps = np.flatnonzero(usable)
    flipped = np.zeros(yaw.shape, bool)
    if len(steps) < MIN_REFERENCE_STEPS + 1:
        return flipped
    jumps = np.abs(wrap_angle(np.diff(yaw[steps]))) > FLIP_RAD
    run_of = np.concatenate([[0], np.cumsum(jumps)])  # consecutive usable steps split at every jump
    sizes = np.bincount(run_of)
    for run in np.flatnonzero(sizes <= MAX_FLIP_STEPS):
        sides = [side for side in (run - 1, run + 1) if 0 <= side < len(sizes)]
        if sides and all(sizes[side] >= MIN_REFERENCE_STEPS for side in sides):
            flipped[steps[run_of == run]] = True
    return flipped


def fix_yaw_flips(yaw: np.ndarray, usable: np.ndarray, types: np.ndarray) -> tuple[np.ndarray, int]:
    """Turns flipped boxes of vehicles and cyclists back. (N, T), (N, T), (N,) -> ((N, T), steps fixed)"""
    flipped = np.zeros(yaw.shape, bool)
    for row in np.flatnonzero(np.isin(types, FLIP_CHECKED_TYPES)):
        flipped[row] = flipped_steps(yaw[row], usable[row])
    return np.where(flipped, wrap_angle(yaw + np.pi), yaw), int(flipped.sum())


class Boxes(NamedTuple):
    length: np.ndarray  # (N,) metres, positive
    width: np.ndarray  # (N,)
    height: np.ndarray  # (N,)
    swapped: np.ndarray  # (N,) bool, length and width exchanged
    defaulted: np.ndarray  # (N,) bool, length and width from DEFAULT_BOX (missing or not positive)
    height_defaulted: np.ndarray  # (N,) bool


def box_dimensions(length: np.ndarray, width: np.ndarray, height: np.ndarray, types: np.ndarray) -> Boxes:
    """Positive, length-wise box sizes. (N,) each -> Boxes"""
    default = np.array([DEFAULT_BOX.get(int(t), DEFAULT_BOX[sch.OBJECT_TYPE_OTHER]) for t in types]).reshape(-1, 3)

    def bad(values: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            return ~(np.isfinite(values) & (values > 0) & (values < 100.0))  # nothing on a road is 100 m long

    defaulted = bad(length) | bad(width)
    length, width = np.where(defaulted, default[:, 0], length), np.where(defaulted, default[:, 1], width)
    swapped = ~defaulted & np.isin(types, SWAP_CHECKED_TYPES) & (width > SWAP_RATIO * length)
    length, width = np.where(swapped, width, length), np.where(swapped, length, width)
    height_defaulted = bad(height)
    height = np.where(height_defaulted, default[:, 2], height)
    return Boxes(length, width, height, swapped, defaulted, height_defaulted)


def consistent_velocity(xy: np.ndarray, velocity: np.ndarray, usable: np.ndarray,
                        dt: float = STEP_SECONDS) -> tuple[np.ndarray, np.ndarray]:
    """Velocities that agree with the positions. (N, T, 2), (N, T, 2), (N, T) -> ((N, T, 2), derived (N, T))

    A usable step keeps its logged velocity when it is finite, sane and matches the position
    difference to the previous or the next usable step; otherwise (absent, garbage, inconsistent)
    it gets the central difference (one-sided at track ends, zero for an isolated step)."""
    pair = usable[:, 1:] & usable[:, :-1]  # (N, T-1) both ends usable
    step = np.where(pair[..., None], np.diff(xy, axis=1) / dt, 0.0)  # (N, T-1, 2)
    zeros, no = np.zeros_like(step[:, :1]), np.zeros_like(pair[:, :1])
    backward, has_backward = np.concatenate([zeros, step], axis=1), np.concatenate([no, pair], axis=1)
    forward, has_forward = np.concatenate([step, zeros], axis=1), np.concatenate([pair, no], axis=1)

    def agrees(reference: np.ndarray, present: np.ndarray) -> np.ndarray:
        tolerance = VELOCITY_TOL_MPS + VELOCITY_TOL_FRACTION * np.linalg.norm(reference, axis=-1)
        return present & (np.linalg.norm(velocity - reference, axis=-1) <= tolerance)

    with np.errstate(invalid="ignore", over="ignore"):
        sane = np.all(np.isfinite(velocity), axis=-1) & (np.linalg.norm(velocity, axis=-1) < MAX_SPEED_MPS)
        checkable = has_backward | has_forward
        matches = agrees(backward, has_backward) | agrees(forward, has_forward)
    derived = usable & (~sane | (checkable & ~matches))
    count = (has_backward.astype(float) + has_forward.astype(float))[..., None]
    central = (backward + forward) / np.maximum(count, 1.0)
    return np.where(derived[..., None], central, np.where(usable[..., None], velocity, 0.0)), derived


def box_centre_heights(z: np.ndarray, usable: np.ndarray, height: np.ndarray) -> tuple[np.ndarray, int, bool]:
    """Box-centre z. (N, T), (N, T), (N,) -> ((N, T), steps replaced, whether the file had z at all)

    2-D files (no z anywhere): the box stands on a flat map at z = 0, centre at half its height.
    Otherwise a step without z, or one more than Z_OUTLIER_M from its track's median, takes that median
    (a track without any z takes the scene's median)."""
    present = usable & np.isfinite(z)
    if not present.any():
        return np.where(usable, 0.5 * height[:, None], 0.0), 0, False
    scene_median = float(np.median(z[present]))
    track_median = np.array([np.median(z[row, present[row]]) if present[row].any() else scene_median
                             for row in range(len(z))]).reshape(-1, 1)  # (N, 1)
    with np.errstate(invalid="ignore"):
        replace = usable & (~present | (np.abs(z - track_median) > Z_OUTLIER_M))
    out = np.where(replace, track_median, np.where(usable, z, 0.0))
    return out, int(replace.sum()), True


def travel_distance(xy: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Path length over consecutive usable steps. (N, T, 2), (N, T) -> (N,)"""
    pair = usable[:, 1:] & usable[:, :-1]
    return np.where(pair, np.linalg.norm(np.diff(xy, axis=1), axis=-1), 0.0).sum(axis=1)


def choose_sdc(named: int | None, types: np.ndarray, usable: np.ndarray, xy: np.ndarray) -> tuple[int, str]:
    """(object index of the SDC, the rule that chose it). (N,), (N, T), (N, T, 2)

    `named` (metadata.sdc_track_index) wins. Otherwise the recording car is a vehicle usable at every
    step: the LAST such object when it is the last object of the file (WOMD lists the SDC's track last,
    which all 14 WOMD samples we hold, in four formats, confirm and the converters keep), else the one
    that travels furthest."""
    num_objects = len(types)
    if named is not None:
        if not 0 <= named < num_objects:
            raise ScenarioError(f"metadata.sdc_track_index {named} is outside the {num_objects} objects")
        return named, SDC_NAMED
    candidates = (types == sch.OBJECT_TYPE_VEHICLE) & usable.all(axis=1)
    if not candidates.any():
        raise ScenarioError("no SDC named (metadata.sdc_track_index), and no vehicle is valid at every step "
                            "to stand in for it")
    if candidates[-1]:
        return num_objects - 1, SDC_LAST_TRACK
    travel = np.where(candidates, travel_distance(xy, usable), -1.0)
    return int(np.argmax(travel)), SDC_FURTHEST

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
from scenariomax.sources.sanity import (  # the generic repairs, shared with every source (re-exported)
    consistent_velocity,  # noqa: F401
    fix_yaw_flips,  # noqa: F401
    flipped_steps,  # noqa: F401
    nanmedian_last,
    swap_rows,
    wider_than_long,
    z_outliers,
)

MAX_ABS_COORD_M = 1e7  # WOMD map frames span < 1e5 m; beyond this a coordinate is garbage
# Default (length, width, height) in metres by object type, for sizes a file lacks (the AV2 source's values).
DEFAULT_BOX = {sch.OBJECT_TYPE_VEHICLE: (4.5, 2.0, 1.6), sch.OBJECT_TYPE_PEDESTRIAN: (0.6, 0.6, 1.7),
               sch.OBJECT_TYPE_CYCLIST: (1.8, 0.7, 1.7), sch.OBJECT_TYPE_OTHER: (1.0, 1.0, 1.5)}
OBJECT_TYPES = {"vehicle": sch.OBJECT_TYPE_VEHICLE, "pedestrian": sch.OBJECT_TYPE_PEDESTRIAN,
                "cyclist": sch.OBJECT_TYPE_CYCLIST}  # "other", "unset" and anything else -> other

SDC_NAMED, SDC_FLAGGED, SDC_LAST_TRACK, SDC_FURTHEST = "named", "flagged", "last-track", "furthest"


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
    swapped = ~defaulted & wider_than_long(length, width, types)  # scenariomax.sources.sanity.SWAP_RATIO
    length, width = swap_rows(length, width, swapped)
    height_defaulted = bad(height)
    height = np.where(height_defaulted, default[:, 2], height)
    return Boxes(length, width, height, swapped, defaulted, height_defaulted)


def box_centre_heights(z: np.ndarray, usable: np.ndarray, height: np.ndarray) -> tuple[np.ndarray, int, bool]:
    """Box-centre z. (N, T), (N, T), (N,) -> ((N, T), steps replaced, whether the file had z at all)

    2-D files (no z anywhere): the box stands on a flat map at z = 0, centre at half its height.
    Otherwise a step without z takes its track's median (a track without any z, the scene's median),
    and a spike (`scenariomax.sources.sanity.z_outliers`) the median of its track around it."""
    present = usable & np.isfinite(z)
    if not present.any():
        return np.where(usable, 0.5 * height[:, None], 0.0), 0, False
    scene_median = float(np.median(z[present]))
    # Each track's median of its present z (np.median's bits: the mean of the two middle values), all at once.
    track_median = np.where(present.any(axis=1), nanmedian_last(np.where(present, z, np.nan)),
                            scene_median)[:, None]  # (N, 1)
    despiked, spikes = z_outliers(np.where(present, z, track_median), present)
    replaced = (usable & ~present) | spikes
    return np.where(usable, despiked, 0.0), int(replaced.sum()), True


def travel_distance(xy: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Path length over consecutive usable steps. (N, T, 2), (N, T) -> (N,)"""
    pair = usable[:, 1:] & usable[:, :-1]
    return np.where(pair, np.linalg.norm(np.diff(xy, axis=1), axis=-1), 0.0).sum(axis=1)


def choose_sdc(named: int | None, types: np.ndarray, usable: np.ndarray, xy: np.ndarray,
               flagged: tuple[int, ...] = ()) -> tuple[int, str]:
    """(object index of the SDC, the rule that chose it). (N,), (N, T), (N, T, 2)

    `named` (metadata.sdc_track_index) wins; then the one object `flagged` `is_sdc` / `is_av` (several flagged
    say nothing). Otherwise the recording car is a vehicle usable at every step: the LAST such object when it
    is the last object of the file (WOMD lists the SDC's track last, which all 14 WOMD samples we hold, in four
    formats, confirm and the converters keep), else the one that travels furthest."""
    num_objects = len(types)
    if named is not None:
        if not 0 <= named < num_objects:
            raise ScenarioError(f"metadata.sdc_track_index {named} is outside the {num_objects} objects")
        return named, SDC_NAMED
    if len(flagged) == 1 and 0 <= flagged[0] < num_objects:
        return flagged[0], SDC_FLAGGED
    candidates = (types == sch.OBJECT_TYPE_VEHICLE) & usable.all(axis=1)
    if not candidates.any():
        raise ScenarioError("no SDC named (metadata.sdc_track_index), and no vehicle is valid at every step "
                            "to stand in for it")
    if candidates[-1]:
        return num_objects - 1, SDC_LAST_TRACK
    travel = np.where(candidates, travel_distance(xy, usable), -1.0)
    return int(np.argmax(travel)), SDC_FURTHEST

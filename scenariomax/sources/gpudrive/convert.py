"""One GPUDrive / Nocturne `RawScenario` -> `Scenario`s of 91 steps (one per window).

Objects are repaired field by field (`tracks.py`), the map is built from `roads` (`roads.py`), and
every decision or repair is written under `metadata[MANIFEST_NOTES]` so that the manifest says what
was changed and why: the layout, the heading unit, which object is the SDC and by which rule, boxes
swapped or defaulted, velocities derived, yaw flips turned back, z filled.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np

from scenariomax.enrich.budget import fit_to_budget
from scenariomax.enrich.roadgraph import polylines_to_roadgraph
from scenariomax.scenario import MAX_EXACT_OBJECT_ID, Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.base import MANIFEST_NOTES
from scenariomax.sources.gpudrive import tracks as trk
from scenariomax.sources.gpudrive.layout import RawScenario
from scenariomax.sources.gpudrive.roads import light_arrays, map_polylines
from scenariomax.sources.sanity import id_list  # lists of more than MAX_LISTED_IDS ids become a count
from scenariomax.sources.womd.windows import DEFAULT_WINDOW_STRIDE, window_steps
from scenariomax.sources.womd.windows import log_window_starts as shared_log_window_starts
from scenariomax.sources.womd.windows import window_notes as log_window_notes

SOURCE_NAME = "gpudrive"


@dataclasses.dataclass(frozen=True)
class CleanTracks:
    """Repaired per-object arrays over the whole log (N objects, T log steps)."""

    x: np.ndarray  # (N, T) float64, 0 at unusable steps
    y: np.ndarray  # (N, T)
    z: np.ndarray  # (N, T) box centre
    yaw: np.ndarray  # (N, T) radians in [-pi, pi)
    velocity: np.ndarray  # (N, T, 2) m/s
    valid: np.ndarray  # (N, T) bool, usable steps
    boxes: trk.Boxes  # (N,) sizes
    types: np.ndarray  # (N,) int64 schema object types
    ids: np.ndarray  # (N,) int64
    notes: dict


def object_ids(raw: RawScenario) -> tuple[np.ndarray, str | None]:
    """(ids (N,), note or None): the file's `id`s (WOMD track ids) when every object has a distinct one
    below 2^24 (shards store ids as float32), else positions 0..N-1."""
    ids = raw.object_ids
    if ids is None:
        return np.arange(raw.num_objects, dtype=np.int64), "positional (0..N-1): the file's objects have no ids"
    if len(np.unique(ids)) != len(ids) or np.any((ids < 0) | (ids >= MAX_EXACT_OBJECT_ID)):
        return (np.arange(raw.num_objects, dtype=np.int64),
                "positional (0..N-1): the file's ids repeat or are outside [0, 2^24)")
    return ids, None


def clean_tracks(raw: RawScenario) -> CleanTracks:
    """Every repair of `tracks.py`, in order, with its manifest notes."""
    types = trk.object_types(raw.type_names)
    ids, id_note = object_ids(raw)
    usable = trk.usable_steps(raw.position, raw.heading, raw.valid)
    yaw, in_degrees = trk.yaw_in_radians(raw.heading, raw.velocity, usable, raw.layout)
    yaw, num_flips = trk.fix_yaw_flips(yaw, usable, types)
    boxes = trk.box_dimensions(raw.length, raw.width, raw.height, types)
    xy = np.where(usable[..., None], raw.position[..., :2], 0.0)
    velocity, derived = trk.consistent_velocity(xy, raw.velocity, usable)
    z, num_z_replaced, has_z = trk.box_centre_heights(raw.position[..., 2], usable, boxes.height)
    seen = usable.any(axis=1)  # objects never usable are padding-like: their sizes are not worth a note
    notes: dict = {"layout": raw.layout, "heading_unit": "degrees" if in_degrees else "radians"}
    if id_note:
        notes["object_ids"] = id_note
    if (num_unusable := int((raw.valid & ~usable).sum())):
        notes["valid_steps_dropped"] = num_unusable  # marked valid, but NaN or absurd position / heading
    if num_flips:
        notes["yaw_flips_fixed"] = num_flips
    if (boxes.swapped & seen).any():
        notes["boxes_swapped"] = id_list(ids, boxes.swapped & seen)  # clearly wider than long: length <-> width
    if (boxes.defaulted & seen).any():
        notes["box_sizes_defaulted"] = id_list(ids, boxes.defaulted & seen)  # missing or not positive in the file
    if np.isnan(raw.height).all():
        notes["heights"] = "type defaults (the file has no heights)"
    elif (boxes.height_defaulted & seen).any():
        notes["heights_defaulted"] = id_list(ids, boxes.height_defaulted & seen)
    if derived.any():
        notes["velocity_derived_steps"] = int(derived.sum())  # absent or inconsistent with the positions
    if not has_z:
        notes["z"] = "not in the file: box centres at half height above a flat map (z = 0)"
    elif num_z_replaced:
        notes["z_replaced_steps"] = num_z_replaced  # missing, or more than Z_OUTLIER_M from the track's median
    return CleanTracks(x=xy[..., 0], y=xy[..., 1], z=z, yaw=yaw, velocity=velocity, valid=usable, boxes=boxes,
                       types=types, ids=ids, notes=notes)


def log_window_starts(num_steps: int, sizes: Sizes, stride: int) -> list[int]:
    """First log step of every window, cut as ScenarioNet logs are (`womd.windows.log_window_starts`) with the
    current step at log step 10 (where GPUDrive starts): a log of at least 91 steps gives WOMD's windows (then
    every `stride`); a shorter one one window padded with invalid future steps; one shorter than the history
    (GPUDrive's own few-step test scenes) one window whose current step is the log's last but one, the history
    before the log invalid (a negative start). A log of one step gives none."""
    if num_steps < 2:
        return []
    # log step 10 while it exists (WOMD's 11-step test split keeps it, though nothing follows it); in a shorter
    # log one step at least follows the current step
    current = sizes.num_past if num_steps > sizes.num_past else num_steps - 2
    return shared_log_window_starts(num_steps, current, sizes.num_past, sizes.num_timesteps, stride)


def stale_track_indices(raw: RawScenario) -> str | None:
    """Why the metadata's track indices cannot be trusted, or None when they can.

    GPUDrive's writer since v0.4.0 (Feb 2025) leaves out vehicles and cyclists that are never valid but keeps
    `sdc_track_index` and `tracks_to_predict` as positions in WOMD's full track list; the SDC is WOMD's last
    track, so an index past the end of `objects` shows the shift. How many tracks went missing before a given
    index is not written, so the indices cannot be mapped back."""
    indices = ([] if raw.sdc_track_index is None else [raw.sdc_track_index]) + [i for i, _ in raw.tracks_to_predict]
    beyond = [index for index in indices if index >= raw.num_objects]
    if not beyond:
        return None
    return (f"metadata indexes track {max(beyond)} but the file holds {raw.num_objects} objects (its writer left "
            f"out never-valid tracks): SDC chosen by rule, tracks_to_predict not read")


def prediction_labels(raw: RawScenario, indices_trusted: bool = True) -> dict[str, np.ndarray]:
    """tracks_to_predict / difficulty_level (by object index, when `indices_trusted`) and objects_of_interest
    (by the file's own track ids) from the file's metadata. (N,) each"""
    num = raw.num_objects
    to_predict, difficulty = np.zeros(num, bool), np.zeros(num, np.int64)
    for index, level in raw.tracks_to_predict if indices_trusted else ():
        if 0 <= index < num:
            to_predict[index], difficulty[index] = True, level if 0 <= level <= 2 else 0
    interest = np.zeros(num, bool) if raw.object_ids is None else \
        np.isin(raw.object_ids, np.array(raw.objects_of_interest, np.int64))
    return dict(tracks_to_predict=to_predict, difficulty_level=difficulty, objects_of_interest=interest)


def _window_objects(tracks: CleanTracks, start: int, num_timesteps: int) -> dict[str, np.ndarray]:
    valid = window_steps(tracks.valid, start, num_timesteps, False)

    def field(values: np.ndarray) -> np.ndarray:
        return np.where(valid, window_steps(values, start, num_timesteps, -1.0), -1.0).astype(np.float32)

    def size(values: np.ndarray) -> np.ndarray:
        return np.where(valid, values[:, None], -1.0).astype(np.float32)

    velocity = window_steps(tracks.velocity, start, num_timesteps, -1.0)
    return dict(x=field(tracks.x), y=field(tracks.y), z=field(tracks.z), bbox_yaw=field(tracks.yaw),
                velocity_x=np.where(valid, velocity[..., 0], -1.0), velocity_y=np.where(valid, velocity[..., 1], -1.0),
                length=size(tracks.boxes.length), width=size(tracks.boxes.width), height=size(tracks.boxes.height),
                valid=valid)


def scenario_windows(raw: RawScenario, sizes: Sizes,
                     stride: int = DEFAULT_WINDOW_STRIDE) -> Iterator[Scenario | trk.ScenarioError]:
    """Every 91-step window of one file's scenario, fitted to the budget; windows that cannot be built are
    yielded as ScenarioError (the caller records them as Failures)."""
    starts = log_window_starts(raw.num_steps, sizes, stride)
    if not starts:
        yield trk.ScenarioError(f"scenario {raw.scenario_id}: {raw.num_steps} step{'s' * (raw.num_steps != 1)}: "
                                f"nothing follows the current step to simulate")
        return
    tracks = clean_tracks(raw)
    stale = stale_track_indices(raw)
    try:
        sdc, rule = trk.choose_sdc(None if stale else raw.sdc_track_index, tracks.types, tracks.valid,
                                   np.stack([tracks.x, tracks.y], axis=-1), raw.sdc_flagged)
    except trk.ScenarioError as error:
        yield trk.ScenarioError(f"scenario {raw.scenario_id}: {error}")
        return
    map_result = map_polylines(raw.roads)
    roadgraph = polylines_to_roadgraph(map_result.polylines)
    labels = prediction_labels(raw, indices_trusted=stale is None)
    notes = {**tracks.notes, "sdc": {"object_index": sdc, "object_id": int(tracks.ids[sdc]), "rule": rule},
             "log_steps": raw.num_steps, **map_result.notes, **raw.notes}
    if stale:
        notes["track_indices_ignored"] = stale
    for start in starts:
        window_id = raw.scenario_id if len(starts) == 1 else f"{raw.scenario_id}_t{start:03d}"
        objects = _window_objects(tracks, start, sizes.num_timesteps)
        if not objects["valid"][sdc, sizes.num_past]:
            yield trk.ScenarioError(f"scenario {window_id}: the SDC (object {sdc}) is not valid at the current step")
            continue
        lights, unknown_states = light_arrays(raw.lights, start, sizes.num_timesteps)
        # padding outside the log, and a current step other than the log's step 10 (a log shorter than the history)
        window_notes = dict(notes, **log_window_notes(start, raw.num_steps, sizes.num_past, sizes.num_timesteps,
                                                      sizes.num_past))
        if len(starts) > 1:
            window_notes["log_start_step"] = start
        if unknown_states:
            window_notes["light_states_unknown"] = unknown_states  # not a light state name: stored as unknown
        # Prediction labels belong to the log's own current step (step 10, where GPUDrive starts).
        window_labels = labels if start <= 0 else {k: np.zeros_like(v) for k, v in labels.items()}
        scenario = Scenario(
            scenario_id=window_id, source_dataset=SOURCE_NAME, current_time_index=sizes.num_past,
            object_id=tracks.ids, object_type=tracks.types, is_sdc=np.arange(raw.num_objects) == sdc,
            **objects, **window_labels, **roadgraph, **lights,
            metadata={"layout": raw.layout, "log_start_step": start, "log_num_steps": raw.num_steps,
                      MANIFEST_NOTES: window_notes},
        )
        yield fit_to_budget(scenario, sizes)

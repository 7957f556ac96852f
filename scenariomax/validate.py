"""Schema validation of shard records: `validate_record` for one record, `validate_shards` for files.

A record is checked in two layers. First the raw tf.Example against the schema (keys present,
dtype kinds, element counts consistent with one set of budget sizes), then, when the structure is
sound, the decoded `Scenario` against its own invariants (`Scenario.validate`). With `deep=True`,
`plausibility_problems` adds physical bounds per field (`PLAUSIBLE_BOUNDS`, docs/validate.md).

`validate_shards` also checks the output as a whole: scenario ids unique across every file, and, where a
folder holds a `manifest.json`, that the folder is the complete output it lists (state, shards present,
no unlisted shard, record counts and sha256; see `scenariomax.manifest`). Every problem is one line of
text, so a user can grep a report or read it in a terminal.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from scenariomax.codec import SchemaError, features_to_scenario, infer_sizes
from scenariomax.errors import InputError
from scenariomax.io.example import ExampleError, decode_example
from scenariomax.io.record_kind import WOMD_SCENARIO_NOT_A_SHARD, looks_like_womd_scenario
from scenariomax.io.tfrecord import RecordError, iter_records_from_stream
from scenariomax.manifest import (
    COMPLETE,
    HashingReader,
    ShardDigest,
    content_problems,
    listing_problems,
    load_for_checking,
    manifest_path,
    no_manifest_message,
    scopes_of,
)
from scenariomax.scenario import MAX_ABS_YAW, Scenario
from scenariomax.schema import FeatureSpec, Sizes, load_schema
from scenariomax.shards import find_record_files, list_shard_files, named_folder

# Groups of keys that a record may leave out entirely (a raw WOMD tf.Example has neither),
# but never in part: half a group means a broken writer.
OPTIONAL_GROUP_PREFIXES = ("path_samples/", "vmax/")
# Keys older WOMD releases lack; the decoder fills them with their pad value.
OPTIONAL_KEYS = ("state/difficulty_level",)
# Features whose values are 0/1 flags; anything else means the writer mixed up two keys.
_FLAG_FIELDS = ("is_sdc", "valid", "tracks_to_predict", "objects_of_interest", "roadgraph_valid", "tl_valid",
                "path_valid", "path_on_route", "is_controllable", "tl_inferred", "lane_valid", "agent_path_valid")
# The keys `codec.infer_sizes` reads the budget sizes from: without one, counts cannot be compared.
_SIZE_KEYS = {"state/id": None, "state/past/x": None, "state/current/x": None, "state/future/x": None,
              "roadgraph_samples/valid": None, "traffic_light_state/current/state": None,
              "path_samples/on_route": "path_samples/", "path_samples/valid": "path_samples/",
              "vmax/lane/id": "vmax/", "vmax/lane/successors": "vmax/", "vmax/agent_paths/object_index": "vmax/"}
_KIND_OF_DTYPE = {"float": "float_list", "int64": "int64_list", "bytes": "bytes_list"}

MAX_REASONS_PER_RECORD = 8


class BadRecord(NamedTuple):
    """One record (or one damaged file) that failed validation."""

    file: str
    record_index: int  # for damaged framing: the index of the first record that could not be read
    scenario_id: str  # empty when unknown
    reason: str  # one line; several problems are joined with "; "


@dataclasses.dataclass(frozen=True)
class ValidationReport:
    num_records: int  # records read (framing intact), good or bad
    num_files: int
    bad: tuple[BadRecord, ...]  # (file, record_index, scenario_id, reason) per bad record or damaged file
    # (record_index -1: a problem of the whole file or of the output, e.g. from its manifest)
    warnings: tuple[str, ...] = ()  # e.g. a folder without manifest.json, whose completeness is unchecked

    @property
    def ok(self) -> bool:
        return not self.bad

    @property
    def num_bad(self) -> int:
        return len(self.bad)


@dataclasses.dataclass(frozen=True)
class RecordCheck:
    """What validating one record found, plus the decoded scenario when decoding succeeded."""

    scenario_id: str
    problems: tuple[str, ...]
    scenario: Scenario | None  # None when the record's structure is too broken to decode
    sizes: Sizes | None


# --- one record ------------------------------------------------------------------------------------

def _group_of(key: str) -> str | None:
    return next((prefix for prefix in OPTIONAL_GROUP_PREFIXES if key.startswith(prefix)), None)


def _value_kind(value) -> str:
    if isinstance(value, list):
        return "bytes_list"
    return "float_list" if np.asarray(value).dtype.kind == "f" else "int64_list"


def _key_problems(features: dict, specs: tuple[FeatureSpec, ...]) -> list[str]:
    """Missing required keys, partially present optional groups, unknown keys."""
    problems = []
    known = {spec.key for spec in specs}
    for prefix in OPTIONAL_GROUP_PREFIXES:
        group = [spec.key for spec in specs if spec.key.startswith(prefix)]
        present = [key for key in group if key in features]
        if present and len(present) < len(group):
            missing = [key for key in group if key not in features]
            problems.append(f"partial {prefix}* group: missing {_list_some(missing)} "
                            f"({len(present)} of {len(group)} keys present)")
    required_missing = [spec.key for spec in specs
                        if _group_of(spec.key) is None and spec.key not in OPTIONAL_KEYS and spec.key not in features]
    if required_missing:
        problems.append(f"missing required key {_list_some(required_missing)}")
    unknown = sorted(set(features) - known)
    if unknown:
        problems.append(f"unknown key {_list_some(unknown)}")
    return problems


def _list_some(keys: list[str], limit: int = 3) -> str:
    shown = ", ".join(keys[:limit])
    return shown + (f" (and {len(keys) - limit} more)" if len(keys) > limit else "")


def _dtype_problems(features: dict, specs: tuple[FeatureSpec, ...]) -> list[str]:
    problems = []
    for spec in specs:
        value = features.get(spec.key)
        if value is None:
            continue
        kind, expected = _value_kind(value), _KIND_OF_DTYPE[spec.dtype]
        # An empty list carries no kind on the wire; only a non-empty one can be the wrong kind.
        if kind != expected and len(value) > 0:
            problems.append(f"{spec.key} is stored as {kind}, the schema wants {expected}")
    return problems


def _count_problems(features: dict, specs: tuple[FeatureSpec, ...], sizes: Sizes) -> list[str]:
    dims = sizes.as_dict()
    problems = []
    for spec in specs:
        value = features.get(spec.key)
        if value is None:
            continue
        expected = spec.num_elements(dims)
        if len(value) != expected:
            shape = "x".join(str(n) for n in spec.resolved_shape(dims)) or "scalar"
            problems.append(f"{spec.key} has {len(value)} values, expected {expected} ({shape}) "
                            f"for the sizes the record implies")
    return problems


def _raw_flag_problems(features: dict, specs: tuple[FeatureSpec, ...]) -> list[str]:
    bad = [spec.key for spec in specs if spec.field in _FLAG_FIELDS and spec.key in features
           and np.asarray(features[spec.key]).size and not np.isin(features[spec.key], (0, 1)).all()]
    return [f"flag {_list_some(bad)} holds values other than 0 and 1"] if bad else []


def _scenario_id(features: dict) -> str:
    value = features.get("scenario/id")
    if isinstance(value, list) and value:
        return value[0].decode("utf-8", "replace")
    return ""


def check_features(features: dict) -> RecordCheck:
    """Validates decoded tf.Example features; returns the problems and, if possible, the Scenario."""
    specs = load_schema().features
    if not features:
        return RecordCheck("", ("record holds no tf.Example features (not a tf.Example?)",), None, None)
    scenario_id = _scenario_id(features)
    problems = _key_problems(features, specs) + _dtype_problems(features, specs)
    group_present = {prefix: any(key.startswith(prefix) for key in features) for prefix in OPTIONAL_GROUP_PREFIXES}
    if any(key not in features and (group is None or group_present[group]) for key, group in _SIZE_KEYS.items()):
        return RecordCheck(scenario_id, tuple(problems), None, None)  # sizes unknowable; the key problem says why
    try:
        sizes = infer_sizes(features)
    except SchemaError as error:
        return RecordCheck(scenario_id, tuple(problems + [str(error)]), None, None)
    problems += _count_problems(features, specs, sizes)
    if problems:
        return RecordCheck(scenario_id, tuple(problems), None, sizes)
    problems += _raw_flag_problems(features, specs)
    if not scenario_id:
        problems.append("scenario/id is empty")
    try:
        scenario = features_to_scenario(features, sizes)
    except (SchemaError, ValueError) as error:
        return RecordCheck(scenario_id, tuple(problems + [f"cannot decode: {error}"]), None, sizes)
    problems += scenario.validate()
    return RecordCheck(scenario_id, tuple(problems), scenario, sizes)


def check_record(data: bytes) -> RecordCheck:
    """Like `validate_record`, but also returns the scenario id and decoded Scenario."""
    try:
        features = decode_example(data)
    except ExampleError as error:
        features, decode_problem = {}, str(error)
    else:
        decode_problem = ""
    if not features and looks_like_womd_scenario(data):  # a raw WOMD file given as shards: name the format
        return RecordCheck("", (WOMD_SCENARIO_NOT_A_SHARD,), None, None)
    return RecordCheck("", (decode_problem,), None, None) if decode_problem else check_features(features)


def validate_record(data: bytes) -> list[str]:
    """Checks one raw record (tf.Example bytes) against the shard schema; one line per problem."""
    return list(check_record(data).problems)


# --- plausibility (validate --deep) ----------------------------------------------------------------
# Ranges no real driving log leaves, wide enough for every dataset we convert (docs/validate.md says why).
MAX_ABS_XY_M = 1e6  # positions are local to a city map (or to `world_origin`)
MAX_ABS_Z_M = 1e4  # above Everest, below the Dead Sea
BOX_SIZE_M = (0.05, 30.0)  # a post to a truck with trailer
MAX_SPEED_MPS = 100.0  # 360 km/h
MAX_SPEED_LIMIT_MPS = 70.0  # 252 km/h
MAX_TIMESTAMP_MICROS = 3_600_000_000  # one hour from the first step
STEP_MICROS = (10_000, 1_000_000)  # time per step between valid steps (10 Hz nominal: 100_000)
MAX_IMPLIED_SPEED_MPS = 150.0  # displacement between valid steps over their nominal time apart (0.1 s per step)
MAX_ARC_LENGTH_M = 1e5
NOMINAL_STEP_S = 0.1

_OBJECT_STEP = ("object", "step")


@dataclasses.dataclass(frozen=True)
class Bound:
    """A range every real entry of one quantity must lie in; NaN and infinity lie in none."""

    name: str
    low: float
    high: float
    unit: str
    values_fn: Callable[[Scenario], np.ndarray]
    mask_fn: Callable[[Scenario], np.ndarray]  # the real entries (same shape as the values)
    axes: tuple[str, ...]  # what each axis indexes, for the location in the message


def _xyz_bounds(name: str, xyz_fn: Callable[[Scenario], np.ndarray], mask_fn: Callable[[Scenario], np.ndarray],
                axes: tuple[str, ...]) -> tuple[Bound, ...]:
    limits = (MAX_ABS_XY_M, MAX_ABS_XY_M, MAX_ABS_Z_M)
    return tuple(Bound(f"{name} {axis}", -limit, limit, "m", lambda s, i=i: xyz_fn(s)[..., i], mask_fn, axes)
                 for i, (axis, limit) in enumerate(zip("xyz", limits)))


def _object_bound(field: str, low: float, high: float, unit: str) -> Bound:
    return Bound(field, low, high, unit, lambda s: getattr(s, field), lambda s: s.valid, _OBJECT_STEP)


PLAUSIBLE_BOUNDS: tuple[Bound, ...] = (
    *_xyz_bounds("position", lambda s: np.stack([s.x, s.y, s.z], axis=-1), lambda s: s.valid, _OBJECT_STEP),
    *(_object_bound(field, *BOX_SIZE_M, "m") for field in ("length", "width", "height")),
    _object_bound("speed", 0.0, MAX_SPEED_MPS, "m/s"),
    _object_bound("velocity_x", -MAX_SPEED_MPS, MAX_SPEED_MPS, "m/s"),
    _object_bound("velocity_y", -MAX_SPEED_MPS, MAX_SPEED_MPS, "m/s"),
    _object_bound("bbox_yaw", -MAX_ABS_YAW, MAX_ABS_YAW, "rad"),
    _object_bound("vel_yaw", -MAX_ABS_YAW, MAX_ABS_YAW, "rad"),
    _object_bound("timestamp_micros", 0, MAX_TIMESTAMP_MICROS, "us"),
    *_xyz_bounds("roadgraph", lambda s: s.roadgraph_xyz, lambda s: s.roadgraph_valid, ("point",)),
    Bound("roadgraph speed_limit", 0.0, MAX_SPEED_LIMIT_MPS, "m/s", lambda s: s.roadgraph_speed_limit,
          lambda s: s.roadgraph_valid & (s.roadgraph_speed_limit != -1), ("point",)),  # -1: unknown
    *_xyz_bounds("traffic light stop point", lambda s: np.stack([s.tl_x, s.tl_y, s.tl_z], axis=-1),
                 lambda s: s.tl_valid, ("light", "step")),
    *_xyz_bounds("SDC path", lambda s: s.path_xyz, lambda s: s.path_valid, ("path", "point")),
    Bound("SDC path arc_length", 0.0, MAX_ARC_LENGTH_M, "m", lambda s: s.path_arc_length, lambda s: s.path_valid,
          ("path", "point")),
    *_xyz_bounds("agent path", lambda s: s.agent_path_xyz, lambda s: s.agent_path_valid, ("agent path", "point")),
    Bound("agent path arc_length", 0.0, MAX_ARC_LENGTH_M, "m", lambda s: s.agent_path_arc_length,
          lambda s: s.agent_path_valid, ("agent path", "point")),
)


def _location(axes: tuple[str, ...], index: tuple[int, ...]) -> str:
    return ", ".join(f"{axis} {int(i)}" for axis, i in zip(axes, index))


def _entries(count: int) -> str:
    return f" ({count} entries)" if count > 1 else ""


def _bound_problem(scenario: Scenario, bound: Bound) -> str | None:
    values = np.asarray(bound.values_fn(scenario), dtype=np.float64)
    mask = np.asarray(bound.mask_fn(scenario), dtype=bool)
    if values.shape != mask.shape:
        return None  # a shape problem, which Scenario.validate reports
    with np.errstate(invalid="ignore"):
        outside = mask & ~((values >= bound.low) & (values <= bound.high))
    if not outside.any():
        return None
    first = tuple(np.argwhere(outside)[0])
    return (f"{bound.name} {values[first]:.4g} {bound.unit} at {_location(bound.axes, first)} is outside the "
            f"plausible range [{bound.low:g}, {bound.high:g}] {bound.unit}{_entries(int(outside.sum()))}")


def _consecutive_valid_steps(valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(object, earlier step, later step) of every pair of consecutive valid steps. (N, T) -> 3 x (K,)"""
    objects, steps = np.nonzero(valid)  # row-major: sorted by object, then step
    same_object = objects[1:] == objects[:-1]
    return objects[1:][same_object], steps[:-1][same_object], steps[1:][same_object]


def _motion_problems(s: Scenario) -> list[str]:
    """Time per step and implied speed between consecutive valid steps of each object."""
    if s.valid.shape != s.x.shape or s.timestamp_micros.shape != s.x.shape:
        return []
    objects, earlier, later = _consecutive_valid_steps(s.valid)
    if objects.size == 0:
        return []
    problems = []
    gap = (later - earlier).astype(np.float64)
    per_step = (s.timestamp_micros[objects, later] - s.timestamp_micros[objects, earlier]) / gap
    off = (per_step < STEP_MICROS[0]) | (per_step > STEP_MICROS[1])
    if off.any():
        k = int(np.argmax(off))
        problems.append(f"timestamps advance {per_step[k]:.4g} us per step at object {objects[k]}, step {later[k]}, "
                        f"outside the plausible [{STEP_MICROS[0]}, {STEP_MICROS[1]}] us{_entries(int(off.sum()))}")
    with np.errstate(invalid="ignore", over="ignore"):
        distance = np.hypot(s.x[objects, later].astype(np.float64) - s.x[objects, earlier],
                            s.y[objects, later].astype(np.float64) - s.y[objects, earlier])
        implied = distance / (gap * NOMINAL_STEP_S)
        jump = implied > MAX_IMPLIED_SPEED_MPS  # NaN positions are the bounds' business
    if jump.any():
        k = int(np.argmax(jump))
        problems.append(f"object {objects[k]} jumps {distance[k]:.4g} m between steps {earlier[k]} and {later[k]} "
                        f"({implied[k]:.4g} m/s, plausible up to {MAX_IMPLIED_SPEED_MPS:g}){_entries(int(jump.sum()))}")
    return problems


def plausibility_problems(scenario: Scenario) -> list[str]:
    """Values no real log holds (`PLAUSIBLE_BOUNDS`, time steps, jumps); one line per quantity."""
    problems = [problem for bound in PLAUSIBLE_BOUNDS if (problem := _bound_problem(scenario, bound))]
    return problems + _motion_problems(scenario)


# --- files -----------------------------------------------------------------------------------------

def join_reasons(problems: tuple[str, ...] | list[str]) -> str:
    shown = list(problems[:MAX_REASONS_PER_RECORD])
    if len(problems) > MAX_REASONS_PER_RECORD:
        shown.append(f"and {len(problems) - MAX_REASONS_PER_RECORD} more")
    return "; ".join(shown)


def resolve_files(path: str | os.PathLike) -> list[Path]:
    """The record files under `path` (directory, file or glob) for reading: InputError when there are none,
    ManifestError (an InputError) when a manifest says the output is incomplete or inconsistent."""
    try:
        return list_shard_files(path)
    except FileNotFoundError as error:
        raise InputError(str(error)) from None


def find_files_to_check(path: str | os.PathLike) -> list[Path]:
    """The record files under `path`, without the readers' manifest checks (validate and inspect report those
    instead of stopping at them). InputError when `path` holds neither records nor a manifest."""
    try:
        files = find_record_files(path)
    except FileNotFoundError as error:
        raise InputError(str(error)) from None
    folder = named_folder(path)
    if not files and (folder is None or not manifest_path(folder).exists()):
        raise InputError(f"{path}: no .tfrecord files found")
    return files


@dataclasses.dataclass(frozen=True)
class ScannedRecord:
    """One record met while scanning files: its check, or the framing error that ended the file."""

    file: Path
    record_index: int
    check: RecordCheck | None  # None for a framing error
    framing_error: str = ""


def scan_records(files: list[Path], max_records: int | None = None, digests: dict[Path, ShardDigest] | None = None,
                 hash_bytes: bool = False) -> Iterator[ScannedRecord]:
    """Validates records file by file, streaming. A damaged file yields one framing-error entry and
    the scan goes on with the next file.

    `digests`: filled with the record count (and with `hash_bytes` the sha256) of every file read to its end
    or to its damage, for comparison with a manifest in the same pass over the bytes."""
    num_seen = 0
    for file in files:
        index = 0
        try:
            with open(file, "rb") as raw:
                stream = HashingReader(raw) if hash_bytes else raw
                for data in iter_records_from_stream(stream, str(file)):
                    if max_records is not None and num_seen >= max_records:
                        return
                    yield ScannedRecord(file, index, check_record(data))
                    index += 1
                    num_seen += 1
            if digests is not None:
                digests[file] = ShardDigest(index, stream.digest.hexdigest() if hash_bytes else "")
        except RecordError as error:
            yield ScannedRecord(file, index, None, str(error))
            if digests is not None:
                digests[file] = ShardDigest(index, error=str(error))
        except OSError as error:
            yield ScannedRecord(file, index, None, f"{file}: cannot read ({error.strerror or error})")
            if digests is not None:
                digests[file] = ShardDigest(index, error=str(error))


@dataclasses.dataclass(frozen=True)
class ManifestFindings:
    """What the manifests of the folders under a path say about them."""

    problems: tuple[BadRecord, ...]  # record_index -1: about a file or the folder, not one record
    warnings: tuple[str, ...]  # folders without a manifest (completeness unchecked)
    num_checked: int  # folders whose manifest was read


def manifest_findings(path: str | os.PathLike, files: list[Path],
                      digests: dict[Path, ShardDigest] | None = None) -> ManifestFindings:
    """Checks each folder under `path` against its manifest.json: the listing always, record counts and
    sha256 for the files in `digests` (files read to their end)."""
    problems, warnings, num_checked = [], [], 0
    for scope in scopes_of(files, named_folder(path)):
        manifest, unreadable = load_for_checking(scope.folder)
        if manifest is None:
            if scope.whole and not unreadable:
                warnings.append(no_manifest_message(scope.folder))
            found = unreadable
        else:
            num_checked += 1
            found = listing_problems(scope.folder, manifest, None if scope.whole else scope.files)
            if manifest["state"] == COMPLETE and digests:
                by_name = {file.name: digests[file] for file in scope.files if file in digests}
                found += content_problems(scope.folder, manifest, by_name)
        problems += [BadRecord(problem.path, -1, "", problem.message) for problem in found]
    return ManifestFindings(tuple(problems), tuple(warnings), num_checked)


def duplicate_problem(first_seen: dict[str, tuple[str, int]], item: ScannedRecord) -> str | None:
    """Remembers where each scenario id was first met; a line naming that place for a repeat."""
    scenario_id = item.check.scenario_id if item.check is not None else ""
    if not scenario_id:
        return None
    first = first_seen.setdefault(scenario_id, (str(item.file), item.record_index))
    if first == (str(item.file), item.record_index):
        return None
    return f"duplicate scenario id, first seen in {first[0]}: record {first[1]}"


def validate_shards(path: str | os.PathLike, deep: bool = False) -> ValidationReport:
    """Validates every record under `path` (a directory, a file or a glob), streaming, and the output as a
    whole: unique scenario ids, and the folder against its manifest.json (sha256 included). `deep` adds
    `plausibility_problems` per record."""
    files = find_files_to_check(path)
    digests: dict[Path, ShardDigest] = {}
    first_seen: dict[str, tuple[str, int]] = {}
    num_records, bad = 0, []
    for item in scan_records(files, digests=digests, hash_bytes=True):
        if item.check is None:
            bad.append(BadRecord(str(item.file), item.record_index, "", item.framing_error))
            continue
        num_records += 1
        problems = list(item.check.problems)
        if deep and item.check.scenario is not None:
            problems += plausibility_problems(item.check.scenario)
        duplicate = duplicate_problem(first_seen, item)
        if duplicate:
            problems.append(duplicate)
        if problems:
            bad.append(BadRecord(str(item.file), item.record_index, item.check.scenario_id, join_reasons(problems)))
    findings = manifest_findings(path, files, digests)
    return ValidationReport(num_records=num_records, num_files=len(files), bad=findings.problems + tuple(bad),
                            warnings=findings.warnings)


def combine_reports(reports: Sequence[ValidationReport]) -> ValidationReport:
    """One report for several validated paths: records and files summed, problems and warnings in path order."""
    return ValidationReport(num_records=sum(r.num_records for r in reports),
                            num_files=sum(r.num_files for r in reports),
                            bad=tuple(entry for r in reports for entry in r.bad),
                            warnings=tuple(warning for r in reports for warning in r.warnings))


def format_bad(entry: BadRecord) -> str:
    """One line naming the file once: where (record and scenario id when known) and what."""
    prefix = f"{entry.file}: "
    reason = entry.reason[len(prefix):] if entry.reason.startswith(prefix) else entry.reason
    # a framing problem names the file and says where in it (a byte offset); a record's own problem needs its index
    has_index = reason == entry.reason and entry.record_index >= 0
    where = f"{entry.file}: record {entry.record_index}" if has_index else entry.file
    who = f" ({entry.scenario_id})" if entry.scenario_id else ""
    return f"{where}{who}: {reason}"


def format_validation(report: ValidationReport, max_lines: int = 50) -> str:
    """A short human-readable summary: one line per bad record, warnings, then a verdict."""
    lines = [format_bad(entry) for entry in report.bad[:max_lines]]
    if len(report.bad) > max_lines:
        lines.append(f"... and {len(report.bad) - max_lines} more")
    lines += [f"warning: {warning}" for warning in report.warnings]
    verdict = "OK" if report.ok else f"{report.num_bad} problem(s)"
    lines.append(f"{report.num_records} records in {report.num_files} file(s): {verdict}")
    return "\n".join(lines)


__all__ = [
    "PLAUSIBLE_BOUNDS",
    "BadRecord",
    "Bound",
    "ManifestFindings",
    "RecordCheck",
    "ValidationReport",
    "check_features",
    "check_record",
    "combine_reports",
    "duplicate_problem",
    "find_files_to_check",
    "format_bad",
    "format_validation",
    "manifest_findings",
    "plausibility_problems",
    "resolve_files",
    "scan_records",
    "validate_record",
    "validate_shards",
]

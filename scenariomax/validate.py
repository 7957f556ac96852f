"""Schema validation of shard records: `validate_record` for one record, `validate_shards` for files.

A record is checked in two layers. First the raw tf.Example against the schema (keys present,
dtype kinds, element counts consistent with one set of budget sizes), then, when the structure is
sound, the decoded `Scenario` against its own invariants (`Scenario.validate`). Every problem is one
line of text, so a user can grep a report or read it in a terminal.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np

from scenariomax.codec import SchemaError, features_to_scenario, infer_sizes
from scenariomax.io.example import ExampleError, decode_example
from scenariomax.io.tfrecord import RecordError, iter_records
from scenariomax.scenario import Scenario
from scenariomax.schema import FeatureSpec, Sizes, load_schema
from scenariomax.shards import list_shard_files
from scenariomax.sources.base import InputError

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
        return RecordCheck("", (str(error),), None, None)
    return check_features(features)


def validate_record(data: bytes) -> list[str]:
    """Checks one raw record (tf.Example bytes) against the shard schema; one line per problem."""
    return list(check_record(data).problems)


# --- files -----------------------------------------------------------------------------------------

def join_reasons(problems: tuple[str, ...] | list[str]) -> str:
    shown = list(problems[:MAX_REASONS_PER_RECORD])
    if len(problems) > MAX_REASONS_PER_RECORD:
        shown.append(f"and {len(problems) - MAX_REASONS_PER_RECORD} more")
    return "; ".join(shown)


def resolve_files(path: str | os.PathLike) -> list[Path]:
    """The record files under `path` (directory, file or glob); InputError when there are none."""
    try:
        return list_shard_files(path)
    except FileNotFoundError as error:
        raise InputError(str(error)) from None


@dataclasses.dataclass(frozen=True)
class ScannedRecord:
    """One record met while scanning files: its check, or the framing error that ended the file."""

    file: Path
    record_index: int
    check: RecordCheck | None  # None for a framing error
    framing_error: str = ""


def scan_records(files: list[Path], max_records: int | None = None) -> Iterator[ScannedRecord]:
    """Validates records file by file, streaming. A damaged file yields one framing-error entry and
    the scan goes on with the next file."""
    num_seen = 0
    for file in files:
        index = 0
        try:
            for data in iter_records(file):
                if max_records is not None and num_seen >= max_records:
                    return
                yield ScannedRecord(file, index, check_record(data))
                index += 1
                num_seen += 1
        except RecordError as error:
            yield ScannedRecord(file, index, None, str(error))
        except OSError as error:
            yield ScannedRecord(file, index, None, f"{file}: cannot read ({error.strerror or error})")


def validate_shards(path: str | os.PathLike) -> ValidationReport:
    """Validates every record under `path` (a directory, a file or a glob), streaming."""
    files = resolve_files(path)
    num_records, bad = 0, []
    for item in scan_records(files):
        if item.check is None:
            bad.append(BadRecord(str(item.file), item.record_index, "", item.framing_error))
            continue
        num_records += 1
        if item.check.problems:
            bad.append(BadRecord(str(item.file), item.record_index, item.check.scenario_id,
                                 join_reasons(item.check.problems)))
    return ValidationReport(num_records=num_records, num_files=len(files), bad=tuple(bad))


def format_validation(report: ValidationReport, max_lines: int = 50) -> str:
    """A short human-readable summary: one line per bad record, then a verdict."""
    lines = []
    for entry in report.bad[:max_lines]:
        who = f" ({entry.scenario_id})" if entry.scenario_id else ""
        lines.append(f"{entry.file}: record {entry.record_index}{who}: {entry.reason}")
    if len(report.bad) > max_lines:
        lines.append(f"... and {len(report.bad) - max_lines} more")
    verdict = "OK" if report.ok else f"{report.num_bad} problem(s)"
    lines.append(f"{report.num_records} records in {report.num_files} file(s): {verdict}")
    return "\n".join(lines)


__all__ = [
    "BadRecord",
    "RecordCheck",
    "ValidationReport",
    "check_features",
    "check_record",
    "format_validation",
    "resolve_files",
    "scan_records",
    "validate_record",
    "validate_shards",
]

"""`manifest.json`: reading it, and checking that a shard folder is the complete output it describes.

A conversion (`scenariomax.pipeline`) and `scenariomax.write_shards` leave `OUT/manifest.json` beside the
shards: `schema`, `source_dataset`, `settings`, `state` (running | finalizing | complete), `counts`, and one
entry per shard `{file, num_records, sha256}` (optionally `num_bytes`; while running or finalizing `file` may
be a hidden temp name and `temp_file` present). This module reads it and compares it with the folder:

- `listing_problems`: metadata only (state, every listed shard present with its listed size, no shard file
  the manifest does not list, counts that add up). Readers run it before they stream (`check_before_reading`).
- `content_problems`: sha256 and record count of every shard, from digests of one pass over its bytes
  (`digest_shard`, or those `scenariomax.validate` collects while it validates the records).
- `check_output`: both, one line per problem.

A folder without a manifest (shards written by hand, raw WOMD files) stays readable, with a one-line warning
that its completeness cannot be checked (`warn_no_manifest`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import BinaryIO, NamedTuple

from scenariomax.errors import InputError
from scenariomax.io.tfrecord import RecordError, iter_records_from_stream

MANIFEST = "manifest.json"
MANIFEST_TEMP = f".{MANIFEST}.tmp"
STATES = ("running", "finalizing", "complete")
COMPLETE = "complete"
WRITE_SHARDS = "write_shards"  # the `source_dataset` of outputs that `scenariomax.write_shards` wrote
SHARD_SUFFIXES = (".tfrecord", ".tfrecords")
_REQUIRED = {"schema": dict, "source_dataset": str, "settings": dict, "state": str, "counts": dict, "shards": list}
_OPTIONAL = {"units": dict, "failures": list, "notes": list}
_JSON_NAMES = {dict: "an object", list: "an array", str: "a string", int: "an integer", bool: "a boolean"}
_SHA256 = re.compile(r"[0-9a-f]{64}")
_DAMAGED = "the manifest is damaged: move the folder away and convert (or write) it again"
_MAX_LISTED = 3


class ManifestError(InputError):
    """manifest.json is unreadable or malformed, or the folder disagrees with it. One line, naming the file."""


class ManifestMissingError(ManifestError, FileNotFoundError):
    """The folder holds no manifest.json (also a FileNotFoundError, as `pipeline.read_manifest` raised)."""


class ManifestWarning(UserWarning):
    """A shard folder is read without a manifest.json: its completeness cannot be checked."""


class Problem(NamedTuple):
    """One thing wrong with an output: the file or folder concerned and a one-line message without it."""

    path: str
    message: str

    def __str__(self) -> str:
        return f"{self.path}: {self.message}"


@dataclasses.dataclass(frozen=True)
class ShardDigest:
    """What one pass over a shard file found."""

    num_records: int
    sha256: str = ""  # "" when not hashed
    error: str = ""  # framing damage or read error: the pass stopped there, and the counts cover the bytes before


@dataclasses.dataclass(frozen=True)
class Scope:
    """Record files selected in one folder, and whether the whole folder was asked for."""

    folder: Path
    files: tuple[Path, ...]
    whole: bool  # a folder path: its unlisted shard files count, and a missing manifest is warned about


# --- reading -----------------------------------------------------------------------------------------

def manifest_path(folder: str | os.PathLike) -> Path:
    return Path(folder) / MANIFEST


def _json_type(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, float):
        return "a number"
    return next((name for kind, name in _JSON_NAMES.items() if type(value) is kind), type(value).__name__)


def _json_reason(error: BaseException, text: bytes) -> str:
    if isinstance(error, RecursionError):
        return "nested too deeply"
    if not text.strip():
        return "the file is empty"
    if isinstance(error, json.JSONDecodeError):
        where = "ends early (truncated?)" if error.pos >= len(error.doc.rstrip()) else f"at line {error.lineno}"
        return f"{error.msg.lower()}, {where}"
    return str(error).splitlines()[0] if str(error) else type(error).__name__


def read_manifest(folder: str | os.PathLike) -> dict:
    """The manifest of an output folder, with its keys and their types checked.

    Raises ManifestMissingError when there is none, ManifestError (one line) when it is unreadable, not
    JSON, not an object, or misses or mistypes a key."""
    path = manifest_path(folder)
    try:
        text = path.read_bytes()
    except FileNotFoundError:
        raise ManifestMissingError(f"{path}: no manifest (not the output of `scenariomax convert` or write_shards)") \
            from None
    except OSError as error:
        raise ManifestError(f"{path}: cannot read ({error.strerror or error})") from None
    try:
        manifest = json.loads(text)
    except (ValueError, RecursionError) as error:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise ManifestError(f"{path}: not valid JSON ({_json_reason(error, text)}); {_DAMAGED}") from None
    problems = manifest_field_problems(manifest)
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise ManifestError(f"{path}: {problems[0]}{more}; {_DAMAGED}")
    return manifest


def find_manifest(folder: str | os.PathLike) -> dict | None:
    """Like `read_manifest`, but None when the folder has no manifest."""
    try:
        return read_manifest(folder)
    except ManifestMissingError:
        return None


def load_for_checking(folder: str | os.PathLike) -> tuple[dict | None, list[Problem]]:
    """(manifest, []) when readable; (None, []) when absent; (None, [the problem]) when unreadable."""
    try:
        return find_manifest(folder), []
    except ManifestError as error:
        path = manifest_path(folder)
        return None, [Problem(str(path), _without_path(str(error), path))]


def _is_count(value: object) -> bool:
    return type(value) is int and value >= 0


def _is_plain_name(value: object) -> bool:
    return isinstance(value, str) and value not in ("", ".", "..") and "/" not in value and "\\" not in value


def _shard_entry_problems(index: int, entry: object) -> list[str]:
    where = f"shards[{index}]"
    if not isinstance(entry, dict):
        return [f"{where} is {_json_type(entry)}, expected an object"]
    problems = []
    for key in ("file", "num_records", "sha256"):
        if key not in entry:
            problems.append(f"{where} has no '{key}'")
    if "file" in entry and not _is_plain_name(entry["file"]):
        problems.append(f"{where}.file {entry['file']!r} is not a file name")
    if "temp_file" in entry and not _is_plain_name(entry["temp_file"]):
        problems.append(f"{where}.temp_file {entry['temp_file']!r} is not a file name")
    for key in ("num_records", "num_bytes"):
        if key in entry and not _is_count(entry[key]):
            problems.append(f"{where}.{key} is {entry[key]!r}, expected a count (integer >= 0)")
    if "sha256" in entry and not (isinstance(entry["sha256"], str) and _SHA256.fullmatch(entry["sha256"])):
        problems.append(f"{where}.sha256 is not 64 lowercase hex digits")
    return problems


def manifest_field_problems(manifest: object) -> list[str]:
    """Missing or mistyped keys of a parsed manifest, one line each (empty when its layout is sound)."""
    if not isinstance(manifest, dict):
        return [f"holds {_json_type(manifest)}, not a JSON object"]
    missing = [key for key in _REQUIRED if key not in manifest]
    problems = [f"missing key {', '.join(missing)}"] if missing else []
    for key, kind in {**_REQUIRED, **_OPTIONAL}.items():
        if key in manifest and type(manifest[key]) is not kind:
            problems.append(f"'{key}' is {_json_type(manifest[key])}, expected {_JSON_NAMES[kind]}")
    if problems:
        return problems
    if manifest["state"] not in STATES:
        problems.append(f"'state' is {manifest['state']!r}, expected one of {', '.join(STATES)}")
    schema = manifest["schema"]
    if not isinstance(schema.get("name"), str) or not isinstance(schema.get("version"), str):
        problems.append("'schema' needs a string 'name' and 'version'")
    bad_counts = [key for key, value in manifest["counts"].items() if not _is_count(value)]
    if bad_counts:
        problems.append(f"counts.{bad_counts[0]} is {manifest['counts'][bad_counts[0]]!r}, expected a count")
    for index, entry in enumerate(manifest["shards"]):
        problems += _shard_entry_problems(index, entry)
    return problems


def write_manifest(folder: str | os.PathLike, manifest: dict) -> None:
    """Writes `folder/manifest.json` atomically (temp file, fsync, rename): readers see the old or the new one."""
    path = manifest_path(folder)
    temp = path.with_name(MANIFEST_TEMP)
    with open(temp, "w") as stream:
        json.dump(manifest, stream, indent=1)
        stream.flush()
        os.fsync(stream.fileno())
    os.replace(temp, path)


# --- the folder against its manifest -------------------------------------------------------------------

def is_record_name(name: str) -> bool:
    """Whether readers take a file of this name for records (hidden files are temp files: never)."""
    return not name.startswith(".") and (name.endswith(SHARD_SUFFIXES) or ".tfrecord-" in name)


def record_files_in(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if is_record_name(p.name) and p.is_file())


def _rerun_hint(manifest: dict) -> str:
    if manifest["source_dataset"] == WRITE_SHARDS:
        return "write_shards was interrupted: run it again into this folder"
    return "the conversion was interrupted: rerun the same `scenariomax convert ...` command with --resume"


def _listed(manifest: dict) -> dict[str, dict]:
    return {entry["file"]: entry for entry in manifest["shards"]}


def _count_problems(folder: Path, manifest: dict) -> list[Problem]:
    where, counts = str(manifest_path(folder)), manifest["counts"]
    problems = []
    num_listed = sum(entry["num_records"] for entry in manifest["shards"])
    if "scenarios" in counts and counts["scenarios"] != num_listed:
        problems.append(Problem(where, f"counts.scenarios is {counts['scenarios']} but its shards hold "
                                       f"{num_listed} records"))
    if "failures" in counts and "failures" in manifest and counts["failures"] != len(manifest["failures"]):
        problems.append(Problem(where, f"counts.failures is {counts['failures']} but it lists "
                                       f"{len(manifest['failures'])} failures"))
    units = manifest.get("units")
    if units is not None:
        num_done = sum(isinstance(unit, dict) and unit.get("done") is True for unit in units.values())
        if "units" in counts and counts["units"] != len(units):
            problems.append(Problem(where, f"counts.units is {counts['units']} but it lists {len(units)} inputs"))
        if num_done != len(units):
            problems.append(Problem(where, f"complete, yet only {num_done} of its {len(units)} inputs are done"))
    if len(manifest["shards"]) != len(_listed(manifest)):
        problems.append(Problem(where, "lists a shard file twice"))
    return problems


def _schema_problems(folder: Path, manifest: dict) -> list[Problem]:
    from scenariomax.schema import load_schema

    ours, theirs = load_schema(), manifest["schema"]
    # Minor versions only add optional keys: the major version decides whether this reader understands it.
    if theirs["name"] != ours.name or theirs["version"].split(".")[0] != ours.version.split(".")[0]:
        return [Problem(str(manifest_path(folder)), f"written with schema {theirs['name']} {theirs['version']}; "
                                                    f"this scenariomax reads {ours.name} {ours.version}")]
    return []


def _shard_listing_problems(folder: Path, name: str, entry: dict | None) -> list[Problem]:
    file = folder / name
    if entry is None:
        return [Problem(str(file), "not listed in manifest.json, so not part of this output (a leftover, or added "
                                   "by hand): move it out of the folder")]
    if not is_record_name(name):
        return [Problem(str(file), "listed in manifest.json but not named like a shard (*.tfrecord): readers "
                                   "would skip it")]
    try:
        size = file.stat().st_size if file.is_file() else None
    except OSError:
        size = None
    if size is None:
        records = f"{entry['num_records']} record{'' if entry['num_records'] == 1 else 's'}"
        return [Problem(str(file), f"listed in manifest.json ({records}) but missing: restore it, or convert again")]
    if "num_bytes" in entry and size != entry["num_bytes"]:
        return [Problem(str(file), f"{size} bytes, manifest.json lists {entry['num_bytes']}: the file was changed "
                                   "or cut short after it was written")]
    return []


def listing_problems(folder: str | os.PathLike, manifest: dict,
                     selected: Sequence[Path] | None = None) -> list[Problem]:
    """Metadata-only checks of `folder` against its manifest (no shard is read).

    `selected`: only these files were asked for (a glob or a file): each must be listed; None: the whole
    folder, so every listed shard must be present and every shard file listed."""
    folder = Path(folder)
    shards = manifest["shards"]
    if manifest["state"] != COMPLETE:
        in_place = sum(_is_plain_name(s.get("file")) and (folder / s["file"]).is_file() for s in shards)
        return [Problem(str(folder), f"incomplete output: manifest.json state is '{manifest['state']}' ({in_place} "
                                     f"of {len(shards)} listed shards in place); {_rerun_hint(manifest)}")]
    problems = _schema_problems(folder, manifest) + _count_problems(folder, manifest)
    listed = _listed(manifest)
    names = list(listed) if selected is None else [file.name for file in selected]
    for name in names:
        problems += _shard_listing_problems(folder, name, listed.get(name))
    if selected is None:
        problems += [problem for file in record_files_in(folder) if file.name not in listed
                     for problem in _shard_listing_problems(folder, file.name, None)]
    return problems


def content_problems(folder: str | os.PathLike, manifest: dict, digests: Mapping[str, ShardDigest]) -> list[Problem]:
    """Record counts and sha256 of the shards in `digests` (by file name) against the manifest.

    Shards without a digest (not read) or whose read failed (the failure is its own problem) are skipped."""
    problems = []
    for name, entry in _listed(manifest).items():
        digest = digests.get(name)
        if digest is None or digest.error:
            continue
        file = str(Path(folder) / name)
        if digest.num_records != entry["num_records"]:
            problems.append(Problem(file, f"holds {digest.num_records} records, manifest.json lists "
                                          f"{entry['num_records']}"))
        if digest.sha256 and digest.sha256 != entry["sha256"]:
            problems.append(Problem(file, "sha256 differs from manifest.json: the file was changed or damaged "
                                          "after it was written"))
    return problems


def file_sha256(path: str | os.PathLike) -> str:
    """The sha256 of a file's bytes, as manifests list it."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


class HashingReader:
    """A binary stream wrapper that sha256-hashes every byte read through it."""

    def __init__(self, stream: BinaryIO):
        self._stream = stream
        self.digest = hashlib.sha256()

    def read(self, size: int = -1) -> bytes:
        data = self._stream.read(size)
        self.digest.update(data)
        return data


def _without_path(message: str, path: Path) -> str:
    prefix = f"{path}: "
    return message[len(prefix):] if message.startswith(prefix) else message


def digest_shard(path: Path, hash_bytes: bool = True) -> ShardDigest:
    """Counts the records of a shard (framing only, no CRC: the sha256 covers the bytes) and hashes it."""
    count = 0
    try:
        with open(path, "rb") as raw:
            stream = HashingReader(raw) if hash_bytes else raw
            try:
                for _ in iter_records_from_stream(stream, str(path), check_crc=False):
                    count += 1
            except RecordError as error:
                return ShardDigest(count, error=_without_path(str(error), path))
            return ShardDigest(count, stream.digest.hexdigest() if hash_bytes else "")
    except OSError as error:
        return ShardDigest(count, error=f"cannot read ({error.strerror or error})")


def check_output(folder: str | os.PathLike, contents: bool = True) -> list[str]:
    """Every reason `folder` is not the complete, intact output its manifest describes; one line each.

    `contents`: also read every shard (sha256 and record count), which costs a pass over all the bytes.
    A folder without a manifest cannot prove anything and gives one problem saying so."""
    folder = Path(folder)
    try:
        manifest = read_manifest(folder)
    except ManifestError as error:
        return [str(error)]
    problems = listing_problems(folder, manifest)
    if contents and manifest["state"] == COMPLETE:
        digests = {}
        for name in _listed(manifest):
            if (folder / name).is_file():
                digests[name] = digest_shard(folder / name)
                if digests[name].error:
                    problems.append(Problem(str(folder / name), digests[name].error))
        problems += content_problems(folder, manifest, digests)
    return [str(problem) for problem in problems]


# --- readers -------------------------------------------------------------------------------------------

def scopes_of(files: Sequence[Path], whole_folder: Path | None) -> list[Scope]:
    """Groups selected record files by folder. `whole_folder`: the folder the user named, if they named one."""
    if whole_folder is not None:
        return [Scope(whole_folder, tuple(files), True)]
    by_folder: dict[Path, list[Path]] = {}
    for file in files:
        by_folder.setdefault(file.parent, []).append(file)
    return [Scope(folder, tuple(selected), False) for folder, selected in by_folder.items()]


def no_manifest_message(folder: Path) -> str:
    return (f"{folder}: no manifest.json, so completeness cannot be checked (a missing or extra shard would go "
            "unnoticed); outputs of `scenariomax convert` and write_shards carry one")


_WARNED: dict = {}  # warnings registry: each folder is warned about once per process


def warn_no_manifest(folder: Path) -> None:
    # warn_explicit without a source line: the warning prints as one line
    warnings.warn_explicit(no_manifest_message(folder), ManifestWarning, "scenariomax", 0, registry=_WARNED)


def _summary(problems: list[Problem]) -> str:
    more = f" (and {len(problems) - 1} more: `scenariomax validate` lists them)" if len(problems) > 1 else ""
    return f"{problems[0]}{more}"


def check_before_reading(scopes: Sequence[Scope]) -> dict[Path, int]:
    """The cheap checks readers run before streaming: raises ManifestError (one line) for an incomplete or
    inconsistent output, warns about a folder without a manifest. Returns the record count the manifests list
    for each selected file, for the reader to compare with what it streams."""
    expected: dict[Path, int] = {}
    for scope in scopes:
        manifest = find_manifest(scope.folder)
        if manifest is None:
            if scope.whole and scope.files:  # an empty folder gets its own error from the reader
                warn_no_manifest(scope.folder)
            continue
        problems = listing_problems(scope.folder, manifest, None if scope.whole else scope.files)
        if problems:
            raise ManifestError(_summary(problems))
        listed = _listed(manifest)
        expected.update({file: listed[file.name]["num_records"] for file in scope.files if file.name in listed})
    return expected


def record_count_message(file: Path, num_read: int, num_listed: int) -> str:
    return (f"{file}: holds {num_read} records, manifest.json lists {num_listed}: the output is damaged "
            "(`scenariomax validate` checks it)")


__all__ = [
    "MANIFEST", "STATES", "WRITE_SHARDS", "ManifestError", "ManifestMissingError", "ManifestWarning", "Problem",
    "Scope", "ShardDigest", "check_before_reading", "check_output", "content_problems", "digest_shard",
    "find_manifest", "is_record_name", "listing_problems", "load_for_checking", "manifest_field_problems",
    "manifest_path", "read_manifest",
    "record_files_in", "scopes_of", "warn_no_manifest", "write_manifest",
]

"""Reading and writing shard files: `read_shards` streams Scenarios, `write_shards` writes them.

Shards may be plain or gzip-compressed TFRecord files (`compression="gzip"`); readers tell them apart by
the gzip magic bytes, so nothing here needs to be told which.

Shard files are named `<split>-<index>-of-<count>.tfrecord`, beside a `manifest.json` that lists each one
with its record count and sha256 (see `scenariomax.manifest`). Readers check the manifest before streaming
(state complete, every listed shard present, no unlisted shard file) and compare record counts as they
go; a folder without a manifest is read with a warning. `scenariomax.pipeline` runs parallel, resumable
conversions; `write_shards` is the small sequential writer.
"""

from __future__ import annotations

import dataclasses
import glob
import os
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from scenariomax.codec import BudgetError, SchemaError, decode_scenario, encode_scenario
from scenariomax.errors import InputError
from scenariomax.io.example import ExampleError
from scenariomax.io.gzip_members import COMPRESSIONS
from scenariomax.io.tfrecord import RecordError, TFRecordWriter, iter_record_spans, iter_records, read_record_at
from scenariomax.manifest import (
    COMPLETE,
    MANIFEST,
    MANIFEST_TEMP,
    SHARD_SUFFIXES,
    WRITE_SHARDS,
    ManifestError,
    check_before_reading,
    file_sha256,
    is_record_name,
    read_manifest,
    record_count_message,
    scopes_of,
    write_manifest,
)
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes, load_schema


class ShardReadError(ValueError):
    """A record could not be read or decoded: the message names the file and record."""


class ShardWriteError(InputError):
    """`write_shards` refuses its output folder (it holds files write_shards did not write). One line."""


def shard_name(split: str, index: int, count: int) -> str:
    return f"{split}-{index:05d}-of-{count:05d}.tfrecord"


def _is_glob(text: str) -> bool:
    return any(ch in text for ch in "*?[")


def named_folder(path: str | os.PathLike) -> Path | None:
    """The folder `path` names, or None when it is a file or a glob."""
    text = str(path)
    return Path(text) if not _is_glob(text) and Path(text).is_dir() else None


def find_record_files(path: str | os.PathLike) -> list[Path]:
    """A directory, a file or a glob pattern resolved to a sorted list of record files, without any
    manifest check; empty for an empty folder. FileNotFoundError when `path` does not exist."""
    text = str(path)
    if _is_glob(text):
        files = [Path(p) for p in glob.glob(text)]
    elif Path(text).is_dir():
        files = [p for p in Path(text).iterdir() if is_record_name(p.name)]
    elif Path(text).is_file():
        files = [Path(text)]
    else:
        raise FileNotFoundError(f"{text}: no such file, directory or matching glob")
    return sorted(p for p in files if p.is_file() and not p.name.startswith("."))


def _checked_files(path: str | os.PathLike) -> tuple[list[Path], dict[Path, int]]:
    """The record files under `path` after the manifest's cheap checks, and the record count it lists for each."""
    files = find_record_files(path)
    expected = check_before_reading(scopes_of(files, named_folder(path)))
    if not files:
        raise FileNotFoundError(f"{path}: no .tfrecord files found")
    return files, expected


def list_shard_files(path: str | os.PathLike) -> list[Path]:
    """Resolves a directory, a file or a glob pattern to a sorted list of record files.

    Where a folder holds a manifest.json, raises ManifestError (an InputError, one line) when the output is
    incomplete or disagrees with it; warns (ManifestWarning) when a named folder has none."""
    return _checked_files(path)[0]


def _counted_records(path: str | os.PathLike,
                     records_of: Callable[[Path], Iterable]) -> Iterator[tuple[Path, int, Any]]:
    """(file, record index, item) for every item `records_of(file)` yields under `path`, the record counts
    compared with the manifest's; ShardReadError for a damaged record or a count that disagrees."""
    files, expected = _checked_files(path)
    for file in files:
        count = 0
        try:
            for item in records_of(file):
                yield file, count, item
                count += 1
        except RecordError as error:
            raise ShardReadError(str(error)) from None
        if file in expected and count != expected[file]:
            raise ShardReadError(record_count_message(file, count, expected[file]))


def iter_raw_records(path: str | os.PathLike) -> Iterator[tuple[Path, int, bytes]]:
    """Yields (file, record index, bytes) for every record under `path`; ShardReadError when a shard holds
    another number of records than its manifest lists."""
    yield from _counted_records(path, iter_records)


@dataclasses.dataclass(frozen=True)
class ShardRecord:
    """Where one record of a shard lies, to read later: a shuffle buffer of these holds a few bytes per record
    where one of Scenarios holds ~2 MB."""
    file: Path
    index: int  # the record's position in its file
    offset: int  # byte offset of its header
    length: int  # bytes of its payload

    def read(self, sizes: Sizes | None = None) -> Scenario:
        """The record's Scenario (its data CRC checked); ShardReadError when it is damaged or the file changed."""
        try:
            data = read_record_at(self.file, self.offset, self.length, self.index)
        except RecordError as error:
            raise ShardReadError(str(error)) from None
        return decode_record(data, self.file, self.index, sizes)


def iter_shard_records(path: str | os.PathLike) -> Iterator[ShardRecord]:
    """`read_shards` without the reading: where every record under `path` lies, from the length headers only
    (records are decoded by `ShardRecord.read`), with the same manifest checks."""
    for file, index, (offset, length) in _counted_records(path, iter_record_spans):
        yield ShardRecord(file, index, offset, length)


def read_shards(path: str | os.PathLike, sizes: Sizes | None = None) -> Iterator[Scenario]:
    """Streams Scenarios from shard files (a directory, a file or a glob)."""
    for file, index, data in iter_raw_records(path):
        yield decode_record(data, file, index, sizes)


def decode_record(data: bytes, file: Path | str, index: int, sizes: Sizes | None = None) -> Scenario:
    try:
        return decode_scenario(data, sizes)
    except (ExampleError, SchemaError, UnicodeDecodeError) as error:
        raise ShardReadError(f"{file}: record {index}: {error}") from None


# --- writing ---------------------------------------------------------------------------------------

def _is_own_temp(name: str) -> bool:
    """Hidden files write_shards makes and removes: shards being written, the manifest being replaced."""
    return name == MANIFEST_TEMP or (name.startswith(".") and name.endswith(".tfrecord.tmp"))


def _claim_folder(out: Path, overwrite: bool) -> dict | None:
    """Checks that write_shards may write into `out`; returns the manifest of its own earlier output there
    (to replace), else None. Refuses, touching nothing, a folder holding anything it did not write."""
    if out.exists() and not out.is_dir():
        raise ShardWriteError(f"{out}: exists and is not a folder; choose another output folder")
    if not out.exists():
        return None
    entries = sorted(entry.name for entry in out.iterdir() if not _is_own_temp(entry.name))
    if MANIFEST not in entries:
        if entries:
            raise ShardWriteError(f"{out}: not empty and holds no {MANIFEST} (e.g. {', '.join(entries[:3])}); "
                                  "write_shards writes only into a new or empty folder, or over its own output")
        return None
    try:
        previous = read_manifest(out)
    except ManifestError as error:
        raise ShardWriteError(str(error)) from None
    if previous["source_dataset"] != WRITE_SHARDS:
        raise ShardWriteError(f"{out}: holds the output of `scenariomax convert` ({MANIFEST}); write_shards writes "
                              "only into a new or empty folder, or over its own output")
    owned = {MANIFEST} | _listed_names(previous)
    foreign = [name for name in entries if name not in owned]
    if foreign:
        raise ShardWriteError(f"{out}: holds files its {MANIFEST} does not list (e.g. {', '.join(foreign[:3])}); "
                              "move them away or choose a new folder")
    if previous["state"] == COMPLETE and not overwrite:
        raise ShardWriteError(f"{out}: already holds shards written by write_shards; pass overwrite=True to replace "
                              "them, or choose a new folder")
    return previous


def _listed_names(manifest: dict) -> set[str]:
    return {entry[key] for entry in manifest["shards"] for key in ("file", "temp_file") if key in entry}


def _finish_temp_shard(path: Path) -> dict:
    """fsync + sha256 of a closed shard (one read, from the page cache)."""
    sha256 = file_sha256(path)
    with open(path, "rb") as stream:
        os.fsync(stream.fileno())
    return {"num_bytes": path.stat().st_size, "sha256": sha256}


def _write_temp_shards(scenarios: Iterable[Scenario], out: Path, sizes: Sizes | None, shard_size: int,
                       split: str, compression: str = "none") -> list[dict]:
    """Writes hidden temp shards; returns their manifest entries (without final names). Removes them on error."""
    entries: list[dict] = []
    writer: TFRecordWriter | None = None
    try:
        for scenario in scenarios:
            if writer is None or writer.num_records >= shard_size:
                if writer is not None:
                    writer.close()
                    entries[-1].update(num_records=writer.num_records, **_finish_temp_shard(writer.path))
                entries.append({"temp_file": f".{split}-{len(entries):05d}.tfrecord.tmp"})
                writer = TFRecordWriter(out / entries[-1]["temp_file"], compression)
            try:
                record = encode_scenario(scenario, sizes)
            except BudgetError as error:
                raise BudgetError(f"{scenario.scenario_id}: {error}; pass the scenarios' own sizes, or fit each "
                                  f"one first with scenariomax.fit_to_budget(scenario, sizes)") from None
            writer.write(record)
        if writer is not None:
            writer.close()
            entries[-1].update(num_records=writer.num_records, **_finish_temp_shard(writer.path))
    except BaseException:
        if writer is not None:
            writer.close()
        for entry in entries:
            (out / entry["temp_file"]).unlink(missing_ok=True)
        raise
    return entries


def _new_manifest(sizes: Sizes | None, shard_size: int, split: str, shards: list[dict],
                  compression: str = "none") -> dict:
    schema = load_schema()
    num_records = sum(entry["num_records"] for entry in shards)
    return {
        "schema": {"name": schema.name, "version": schema.version},
        "source_dataset": WRITE_SHARDS,
        "settings": {"split": split, "shard_size": shard_size, "sizes": sizes.as_dict() if sizes else None,
                     "compression": compression},
        "state": "finalizing",
        "counts": {"scenarios": num_records, "failures": 0},
        "shards": shards,
        "failures": [],
        "notes": [],
    }


def write_shards(scenarios: Iterable[Scenario], out: str | os.PathLike, sizes: Sizes | None = None,
                 shard_size: int = 1000, split: str = "train", overwrite: bool = False,
                 compression: str = "none") -> list[Path]:
    """Writes scenarios to `out/<split>-XXXXX-of-YYYYY.tfrecord` plus `out/manifest.json` (sequential).

    `out` must be new or empty, or hold an earlier output of write_shards: an interrupted one is replaced,
    a complete one only with `overwrite=True`. Anything else there (another conversion, shards without a
    manifest, other files) raises ShardWriteError, touching nothing. Shards are written to hidden temp files
    and renamed once the manifest lists them, so a crash never leaves an output that reads as complete.
    `compression="gzip"` writes TFRecord GZIP files (one gzip member per record; every reader detects it).
    Use `scenariomax.pipeline.convert` for parallel, resumable conversions.
    """
    out = Path(out)
    if compression not in COMPRESSIONS:
        raise ValueError(f"compression {compression!r}: use one of {', '.join(COMPRESSIONS)}")
    previous = _claim_folder(out, overwrite)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    for entry in out.iterdir():
        if _is_own_temp(entry.name):
            entry.unlink()  # leftovers of an interrupted write_shards
    try:
        temps = _write_temp_shards(scenarios, out, sizes, shard_size, split, compression)
    except BaseException:
        if created and not any(out.iterdir()):
            out.rmdir()  # a failed write leaves no empty folder of ours behind
        raise
    if previous is not None:  # the earlier output goes; until the new one is complete the folder reads as interrupted
        write_manifest(out, {**previous, "state": "running"})
        for name in sorted(_listed_names(previous)):
            (out / name).unlink(missing_ok=True)
    shards = [{"file": shard_name(split, index, len(temps)), **entry} for index, entry in enumerate(temps)]
    manifest = _new_manifest(sizes, shard_size, split, shards, compression)
    write_manifest(out, manifest)
    for entry in shards:
        os.replace(out / entry.pop("temp_file"), out / entry["file"])
    manifest["state"] = COMPLETE
    write_manifest(out, manifest)
    return [out / entry["file"] for entry in shards]


__all__ = ["read_shards", "write_shards", "list_shard_files", "find_record_files", "iter_raw_records",
           "ShardReadError", "ShardWriteError", "RecordError", "shard_name", "decode_record", "named_folder",
           "SHARD_SUFFIXES"]

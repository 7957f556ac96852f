"""A fast index of shard records for the viewer: where each record is and its scenario id.

`ShardIndex.build` walks the TFRecord framing with positioned reads (`os.pread`) and skims each
tf.Example for `scenario/id` without reading or decoding the rest of the record: it reads only the
frame headers and the first bytes of each map entry, and jumps over the values (`scenariomax.io.skim`).
A 1,000-scenario synthetic set (2.6 GB on disk) is indexed in a fraction of a second. Records are decoded
(and validated, and CRC-checked) only when one is opened: `ShardIndex.check`.

A gzip-compressed shard has no record bytes to skim in place: its records are decompressed once while
indexing (~4 ms each for 2.5 MB records) and read back by gzip member (`scenariomax.io.tfrecord`).
"""

from __future__ import annotations

import dataclasses
import os
import struct
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from scenariomax.errors import InputError
from scenariomax.inspect import summarize_scenario
from scenariomax.io.skim import MAX_ENTRIES_SKIMMED, skim_scenario_id, skim_scenario_id_in
from scenariomax.io.tfrecord import (
    RecordError,
    file_compression,
    iter_records_with_spans,
    masked_crc32c,
    read_record_at,
    record_length,
)
from scenariomax.validate import RecordCheck, check_record, resolve_files

_HEADER = struct.Struct("<QI")
SKIM_THREADS = 16


@dataclasses.dataclass(frozen=True)
class IndexEntry:
    file: int  # index into ShardIndex.files
    record: int  # record index within the file
    offset: int  # byte offset of the record's payload (gzip files: of its span, see `iter_record_spans`)
    length: int  # payload bytes
    scenario_id: str  # "" when the record holds none that the skim could find
    compressed: bool = False  # read with `read_record_at` (a gzip file), not in place


def _walk_gzip_file(path: Path, file_index: int) -> tuple[list[IndexEntry], str]:
    """(entries, error message or "") for one gzip TFRecord file: each record decompressed once, for its id."""
    entries: list[IndexEntry] = []
    try:
        for record, (offset, length, data) in enumerate(iter_records_with_spans(path)):
            entries.append(IndexEntry(file_index, record, offset, length, skim_scenario_id_in(data), True))
    except RecordError as error:
        return entries, str(error)  # the records before the damage stay listed
    except OSError as error:
        return entries, f"{path}: cannot read ({error.strerror or error})"
    return entries, ""


def _walk_file(path: Path, file_index: int) -> tuple[list[IndexEntry], str]:
    """(entries, error message or "") for one TFRecord file, reading frame headers only."""
    try:
        if file_compression(path) == "gzip":
            return _walk_gzip_file(path, file_index)
    except OSError as error:
        return [], f"{path}: cannot read ({error.strerror or error})"
    frames: list[tuple[int, int]] = []  # (payload offset, payload length)
    ids: list[str] = []
    error_text = ""
    try:
        with open(path, "rb") as stream:
            fd = stream.fileno()
            size = os.fstat(fd).st_size
            offset = 0
            while offset < size:
                try:  # the reader's own header check: "not a TFRecord file" / "corrupt record N" alike
                    length = record_length(os.pread(fd, _HEADER.size, offset), str(path), len(frames), offset)
                except RecordError as error:
                    error_text = str(error)
                    break  # the records before the damage stay listed
                if offset + _HEADER.size + length + 4 > size:
                    error_text = f"{path}: truncated record at byte {offset}"
                    break
                frames.append((offset + _HEADER.size, length))
                offset += _HEADER.size + length + 4
            # The skims are independent small reads: overlap them (os.pread releases the GIL), which is what
            # makes a cold-cache index of a large dataset fast.
            with ThreadPoolExecutor(max_workers=SKIM_THREADS) as pool:
                ids = list(pool.map(lambda frame: skim_scenario_id(fd, *frame), frames))
    except OSError as error:
        error_text = f"{path}: cannot read ({error.strerror or error})"
    ids += [""] * (len(frames) - len(ids))  # a read that failed part-way: the frames found stay listed
    entries = [IndexEntry(file_index, i, data, length, scenario_id)
               for i, ((data, length), scenario_id) in enumerate(zip(frames, ids))]
    return entries, error_text


@dataclasses.dataclass(frozen=True)
class ShardIndex:
    path: str
    files: tuple[Path, ...]
    entries: tuple[IndexEntry, ...]
    file_errors: tuple[str, ...]  # one line per damaged file (its records before the damage are indexed)

    @classmethod
    def build(cls, path: str | os.PathLike) -> ShardIndex:
        """Indexes every record under `path` (directory, file or glob). InputError when there is nothing."""
        files = resolve_files(path)
        entries: list[IndexEntry] = []
        errors = []
        for number, file in enumerate(files):
            found, error = _walk_file(file, number)
            entries += found
            if error:
                errors.append(error)
        if not entries:
            raise InputError(errors[0] if errors else f"{path}: no records in {len(files)} file(s)")
        return cls(str(path), tuple(files), tuple(entries), tuple(errors))

    def __len__(self) -> int:
        return len(self.entries)

    def find(self, scenario_id: str) -> int:
        """Position of the first record with this scenario id; InputError naming the path when absent."""
        for position, entry in enumerate(self.entries):
            if entry.scenario_id == scenario_id:
                return position
        raise InputError(f"{self.path}: no scenario with id {scenario_id!r} (among {len(self.entries)} records)")

    def read(self, position: int) -> bytes:
        """The payload of record `position`, CRC-checked (RecordError-like ValueError with the place)."""
        entry = self.entries[position]
        file = self.files[entry.file]
        if entry.compressed:
            return read_record_at(file, entry.offset, entry.length, entry.record)  # RecordError is a ValueError
        with open(file, "rb") as stream:
            data = os.pread(stream.fileno(), entry.length + 4, entry.offset)
        if len(data) < entry.length + 4:
            raise ValueError(f"{file}: record {entry.record} is truncated")
        payload, (crc,) = data[:-4], struct.unpack("<I", data[-4:])
        if masked_crc32c(payload) != crc:
            raise ValueError(f"{file}: record {entry.record}: corrupted record data (CRC mismatch)")
        return payload

    def check(self, position: int) -> RecordCheck:
        """Validates and decodes record `position` (see `scenariomax.validate.check_record`)."""
        try:
            data = self.read(position)
        except (ValueError, OSError) as error:
            return RecordCheck(self.entries[position].scenario_id, (str(error),), None, None)
        return check_record(data)

    def describe(self, position: int) -> dict:
        entry = self.entries[position]
        return {"id": entry.scenario_id or f"(record {entry.record})", "file": self.files[entry.file].name,
                "record": entry.record}


def compact_summary(check: RecordCheck) -> dict:
    """What the page's list and summary panel show for one record: the `inspect` numbers of the scenario
    and the problems `validate` found."""
    out: dict = {"problems": list(check.problems)}
    if check.scenario is None:
        return out
    full = summarize_scenario(check.scenario)
    sdc = full["sdc"] or {}
    speeds = sdc.get("speeds") or []
    out.update({
        "dataset": full["source_dataset"] or "(unset)",
        "objects": full["num_objects"], "objects_by_type": full["objects_by_type"],
        "lights": full["num_lights"], "light_states_now": full["light_states_now"],
        "paths": full["num_paths"], "on_route_paths": full["num_on_route_paths"],
        "controllable": full["num_controllable"], "roadgraph_points": full["roadgraph_valid_points"],
        "roadgraph_by_type": full["roadgraph_by_type"],
        "sdc_speed_mean": round(sum(speeds) / len(speeds), 2) if speeds else None,
        "sdc_distance_m": round(sdc["distance_m"], 1) if sdc else None,
    })
    return out


__all__ = ["MAX_ENTRIES_SKIMMED", "IndexEntry", "ShardIndex", "compact_summary", "skim_scenario_id"]

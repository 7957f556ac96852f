"""TFRecord framing: each record is

    uint64 length | uint32 masked_crc32c(length bytes) | data | uint32 masked_crc32c(data)

(little-endian). CRCs are checked on read; any damage raises `RecordError` naming the file once. A first
record whose length header fails its CRC means the file is not a TFRecord at all (a text file, a gzip
archive, a parquet table); a later failure means record N is corrupt.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import google_crc32c

_MASK_DELTA = 0xA282EAD8
_HEADER = struct.Struct("<QI")
_FOOTER = struct.Struct("<I")
# Refuse absurd lengths from corrupted headers before trying to allocate them.
MAX_RECORD_BYTES = 1 << 31


class RecordError(ValueError):
    """A file is not a TFRecord or is damaged: the message is `FILE: problem`, the file named once.

    `path` and `problem` hold the two parts, for callers that put the file in their own prefix."""

    path: str = ""
    problem: str = ""


def _record_error(name: str, problem: str) -> RecordError:
    error = RecordError(f"{name}: {problem}")
    error.path, error.problem = name, problem
    return error


_GZIP_MAGIC = b"\x1f\x8b"


def _not_a_tfrecord(name: str, header: bytes) -> RecordError:
    """The first record's header is not one: the file was never a TFRecord (say what it looks like when
    that is cheap to tell)."""
    if header.startswith(_GZIP_MAGIC):
        return _record_error(name, "not a TFRecord file (it is gzip-compressed: decompress it first, e.g. gunzip)")
    if len(header) < _HEADER.size:
        return _record_error(name, f"not a TFRecord file ({len(header)} bytes, too short for a record header)")
    return _record_error(name, f"not a TFRecord file (its first {_HEADER.size} bytes are not a record header)")


def masked_crc32c(data: bytes) -> int:
    crc = google_crc32c.value(data)
    return (((crc >> 15) | (crc << 17)) + _MASK_DELTA) & 0xFFFFFFFF


def frame_record(data: bytes) -> bytes:
    header = struct.pack("<Q", len(data))
    return header + struct.pack("<I", masked_crc32c(header)) + data + struct.pack("<I", masked_crc32c(data))


def iter_records(path: str | os.PathLike, check_crc: bool = True) -> Iterator[bytes]:
    """Yields the payload of every record in a TFRecord file, streaming."""
    path = Path(path)
    with open(path, "rb") as stream:
        yield from iter_records_from_stream(stream, str(path), check_crc)


def iter_records_from_stream(stream: BinaryIO, name: str, check_crc: bool = True) -> Iterator[bytes]:
    offset = 0
    index = 0
    while True:
        length = _read_length(stream, name, index, offset, check_crc)
        if length is None:
            return
        data = stream.read(length)
        footer = stream.read(_FOOTER.size)
        if len(data) < length or len(footer) < _FOOTER.size:
            raise _record_error(name, f"truncated record at byte {offset} (expected {length} bytes of data)")
        if check_crc and masked_crc32c(data) != _FOOTER.unpack(footer)[0]:
            raise _record_error(name, f"corrupt record {index}: data CRC mismatch at byte {offset}")
        yield data
        offset += _HEADER.size + length + _FOOTER.size
        index += 1


def _read_length(stream: BinaryIO, name: str, index: int, offset: int, check_crc: bool) -> int | None:
    """The data length of record `index` from its header at `offset`; None at a clean end of file."""
    header = stream.read(_HEADER.size)
    return record_length(header, name, index, offset, check_crc) if header else None


def record_length(header: bytes, name: str, index: int, offset: int, check_crc: bool = True) -> int:
    """The data length in the header of record `index` (at byte `offset` of file `name`). RecordError when it
    is not a valid header: on the first record the file is not a TFRecord, later the record is corrupt."""
    if len(header) < _HEADER.size:
        problem = "truncated"
    else:
        length, length_crc = _HEADER.unpack(header[:_HEADER.size])
        if check_crc and masked_crc32c(header[:8]) != length_crc:
            problem = "length CRC mismatch"
        elif length > MAX_RECORD_BYTES:  # refuse to allocate what a damaged header claims
            problem = f"implausible length {length}"
        else:
            return length
    if index == 0:
        raise _not_a_tfrecord(name, header)
    if problem == "truncated":
        raise _record_error(name, f"truncated record header at byte {offset}")
    raise _record_error(name, f"corrupt record {index}: {problem} at byte {offset}")


def count_records(path: str | os.PathLike, limit: int | None = None) -> int:
    """The number of records in a TFRecord file (at most `limit`), from the length headers only: the data
    is skipped, not read or checked (a truncated last record still counts). Raises RecordError like
    `iter_records` for a damaged header."""
    name = str(path)
    count, offset = 0, 0
    with open(path, "rb") as stream:
        while limit is None or count < limit:
            length = _read_length(stream, name, count, offset, check_crc=True)
            if length is None:
                break
            offset += _HEADER.size + length + _FOOTER.size
            stream.seek(offset)
            count += 1
    return count


def iter_record_spans(path: str | os.PathLike) -> Iterator[tuple[int, int]]:
    """(byte offset, data length) of every record in a TFRecord file, from the length headers only (the data is
    skipped, so a record can be read later with `read_record_at`). RecordError like `iter_records` for a
    damaged header or a record cut short by the end of the file."""
    name = str(path)
    index, offset = 0, 0
    with open(path, "rb") as stream:
        size = os.fstat(stream.fileno()).st_size
        while True:
            length = _read_length(stream, name, index, offset, check_crc=True)
            if length is None:
                return
            end = offset + _HEADER.size + length + _FOOTER.size
            if end > size:
                raise _record_error(name, f"truncated record at byte {offset} (expected {length} bytes of data)")
            yield offset, length
            offset, index = end, index + 1
            stream.seek(offset)


def read_record_at(path: str | os.PathLike, offset: int, length: int, index: int = 0) -> bytes:
    """The payload of the record whose header is at byte `offset` (a span of `iter_record_spans`), its data CRC
    checked; RecordError when the file changed since the span was taken."""
    name = str(path)
    with open(path, "rb") as stream:
        stream.seek(offset)
        if record_length(stream.read(_HEADER.size), name, max(index, 1), offset) != length:
            raise _record_error(name, f"record {index} at byte {offset} changed since the file was scanned")
        data = stream.read(length)
        footer = stream.read(_FOOTER.size)
    if len(data) < length or len(footer) < _FOOTER.size:
        raise _record_error(name, f"truncated record at byte {offset} (expected {length} bytes of data)")
    if masked_crc32c(data) != _FOOTER.unpack(footer)[0]:
        raise _record_error(name, f"corrupt record {index}: data CRC mismatch at byte {offset}")
    return data


class TFRecordWriter:
    """Writes framed records to a file. Use as a context manager."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._stream: BinaryIO | None = open(self.path, "wb")
        self.num_records = 0

    def write(self, data: bytes) -> None:
        assert self._stream is not None, "writer is closed"
        self._stream.write(frame_record(data))
        self.num_records += 1

    def close(self) -> None:
        if self._stream is not None:
            self._stream.flush()
            os.fsync(self._stream.fileno())
            self._stream.close()
            self._stream = None

    def __enter__(self) -> TFRecordWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

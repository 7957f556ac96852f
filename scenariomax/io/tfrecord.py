"""TFRecord framing: each record is

    uint64 length | uint32 masked_crc32c(length bytes) | data | uint32 masked_crc32c(data)

(little-endian). CRCs are checked on read; any damage raises `RecordError` naming file and offset.
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
    """A TFRecord file is damaged: the message names the file, the byte offset and the problem."""


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
    while True:
        header = stream.read(_HEADER.size)
        if not header:
            return
        if len(header) < _HEADER.size:
            raise RecordError(f"{name}: truncated record header at byte {offset}")
        length, length_crc = _HEADER.unpack(header)
        if check_crc and masked_crc32c(header[:8]) != length_crc:
            raise RecordError(f"{name}: corrupted record length (CRC mismatch) at byte {offset}")
        if length > MAX_RECORD_BYTES:
            raise RecordError(f"{name}: record length {length} is implausible at byte {offset}")
        data = stream.read(length)
        footer = stream.read(_FOOTER.size)
        if len(data) < length or len(footer) < _FOOTER.size:
            raise RecordError(f"{name}: truncated record at byte {offset} (expected {length} bytes of data)")
        if check_crc and masked_crc32c(data) != _FOOTER.unpack(footer)[0]:
            raise RecordError(f"{name}: corrupted record data (CRC mismatch) at byte {offset}")
        yield data
        offset += _HEADER.size + length + _FOOTER.size


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

"""TFRecord framing: each record is

    uint64 length | uint32 masked_crc32c(length bytes) | data | uint32 masked_crc32c(data)

(little-endian). CRCs are checked on read; any damage raises `RecordError` naming the file once. A first
record whose length header fails its CRC means the file is not a TFRecord at all (a text file, a parquet
table); a later failure means record N is corrupt.

Gzip-compressed files (TFRecord GZIP, what `TFRecordDataset(compression_type="GZIP")` reads) are found by
their magic bytes and read by every function here without a flag; `TFRecordWriter(path, compression="gzip")`
writes them one gzip member per record (`scenariomax.io.gzip_members`), which keeps random access by offset.
"""

from __future__ import annotations

import gzip
import os
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import google_crc32c

from scenariomax.io.gzip_members import (
    COMPRESSIONS,
    DEFAULT_LEVEL,
    HEADER_SIZE,
    MemberError,
    decompress_member,
    gzip_member,
    is_gzip,
    member_index,
)

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


def _not_a_tfrecord(name: str, header: bytes, compressed: bool = False) -> RecordError:
    """The first record's header is not one: the file was never a TFRecord (say what it looks like when
    that is cheap to tell)."""
    what = "what the gzip file holds is not a TFRecord" if compressed else "not a TFRecord file"
    if is_gzip(header):
        return _record_error(name, f"{what} (it is gzip-compressed{' twice' if compressed else ''}: "
                                   "decompress it first, e.g. gunzip)")
    if len(header) < _HEADER.size:
        return _record_error(name, f"{what} ({len(header)} bytes, too short for a record header)")
    return _record_error(name, f"{what} (its first {_HEADER.size} bytes are not a record header)")


def masked_crc32c(data: bytes) -> int:
    crc = google_crc32c.value(data)
    return (((crc >> 15) | (crc << 17)) + _MASK_DELTA) & 0xFFFFFFFF


def frame_pieces(data: bytes) -> tuple[bytes, bytes]:
    """What frames `data` as a TFRecord: the header before it (length, the length's CRC) and the footer after it
    (the data's CRC). Written around the data, they make the frame without copying 2 MB into a new buffer."""
    length = struct.pack("<Q", len(data))
    return length + struct.pack("<I", masked_crc32c(length)), struct.pack("<I", masked_crc32c(data))


def frame_record(data: bytes) -> bytes:
    header, footer = frame_pieces(data)
    return b"".join((header, data, footer))


def frame_for(data: bytes, compression: str = "none", level: int = DEFAULT_LEVEL) -> bytes:
    """The bytes one record takes in a file of this compression: its frame, or a gzip member holding it."""
    frame = frame_record(data)
    return gzip_member(frame, len(data), level) if compression == "gzip" else frame


def write_framed(stream: BinaryIO, data: bytes, compression: str = "none", level: int = DEFAULT_LEVEL) -> int:
    """Writes the bytes `frame_for` makes of one record to `stream` (a plain frame in three pieces, not copied
    into one buffer first). Returns how many bytes that was."""
    if compression == "gzip":
        return stream.write(frame_for(data, compression, level))
    header, footer = frame_pieces(data)
    return stream.write(header) + stream.write(data) + stream.write(footer)


class _Prefixed:
    """A read-only stream with the bytes already read from it (the magic-byte peek) put back in front."""

    def __init__(self, prefix: bytes, stream: BinaryIO):
        self._prefix, self._stream = prefix, stream
        self.position = 0  # bytes of the file handed out so far (where gzip damage is reported)

    def read(self, size: int = -1) -> bytes:
        data = self._read(size)
        self.position += len(data)
        return data

    def _read(self, size: int) -> bytes:
        if not self._prefix:
            return self._stream.read(size)
        if size is None or size < 0:
            head, self._prefix = self._prefix + self._stream.read(), b""
            return head
        head, self._prefix = self._prefix[:size], self._prefix[size:]
        return head + self._stream.read(size - len(head)) if len(head) < size else head


class _Gunzipped:
    """The decompressed bytes of a gzip stream (any number of members); damage is a RecordError naming the file."""

    def __init__(self, stream: _Prefixed, name: str):
        self._stream = stream
        self._file = gzip.GzipFile(fileobj=stream, mode="rb")
        self._name = name

    def read(self, size: int = -1) -> bytes:
        try:
            return self._file.read(size)
        except EOFError:
            raise _record_error(self._name, f"truncated gzip data (the file ends at byte {self._stream.position}, "
                                            "inside a compressed record)") from None
        except (gzip.BadGzipFile, zlib.error) as error:
            raise _record_error(self._name,
                                f"damaged gzip data before byte {self._stream.position} ({error})") from None


def decompressed(stream: BinaryIO, name: str) -> BinaryIO | _Gunzipped:
    """`stream` as TFRecord bytes: gunzipped when it starts with the gzip magic bytes, else as it is."""
    head = stream.read(2)
    prefixed = _Prefixed(head, stream)
    return _Gunzipped(prefixed, name) if is_gzip(head) else prefixed  # type: ignore[return-value]


def iter_records(path: str | os.PathLike, check_crc: bool = True) -> Iterator[bytes]:
    """Yields the payload of every record in a TFRecord file (plain or gzip-compressed), streaming."""
    path = Path(path)
    with open(path, "rb") as stream:
        yield from iter_records_from_stream(stream, str(path), check_crc)


def iter_records_from_stream(stream: BinaryIO, name: str, check_crc: bool = True) -> Iterator[bytes]:
    """`iter_records` of an open binary stream (only `read` is used), gunzipped when it is gzip data."""
    records = decompressed(stream, name)
    compressed = isinstance(records, _Gunzipped)
    offset = 0
    index = 0
    while True:
        length = _read_length(records, name, index, offset, check_crc, compressed)
        if length is None:
            return
        data = records.read(length)
        footer = records.read(_FOOTER.size)
        where = f"byte {offset}{' of the decompressed data' if compressed else ''}"
        if len(data) < length or len(footer) < _FOOTER.size:
            raise _record_error(name, f"truncated record at {where} (expected {length} bytes of data)")
        if check_crc and masked_crc32c(data) != _FOOTER.unpack(footer)[0]:
            raise _record_error(name, f"corrupt record {index}: data CRC mismatch at {where}")
        yield data
        offset += _HEADER.size + length + _FOOTER.size
        index += 1


def _read_length(stream, name: str, index: int, offset: int, check_crc: bool, compressed: bool = False) -> int | None:
    """The data length of record `index` from its header at `offset`; None at a clean end of file."""
    header = stream.read(_HEADER.size)
    return record_length(header, name, index, offset, check_crc, compressed) if header else None


def record_length(header: bytes, name: str, index: int, offset: int, check_crc: bool = True,
                  compressed: bool = False) -> int:
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
        raise _not_a_tfrecord(name, header, compressed)
    where = f"byte {offset}{' of the decompressed data' if compressed else ''}"
    if problem == "truncated":
        raise _record_error(name, f"truncated record header at {where}")
    raise _record_error(name, f"corrupt record {index}: {problem} at {where}")


def _is_gzip_file(stream: BinaryIO) -> bool:
    head = os.pread(stream.fileno(), 2, 0)
    return is_gzip(head)


def count_records(path: str | os.PathLike, limit: int | None = None) -> int:
    """The number of records in a TFRecord file (at most `limit`), from the length headers only: the data
    is skipped, not read or checked (a truncated last record still counts). Raises RecordError like
    `iter_records` for a damaged header. A gzip file is counted from its members' index headers (ours) or
    by decompressing it (another tool's)."""
    name = str(path)
    count, offset = 0, 0
    with open(path, "rb") as stream:
        if _is_gzip_file(stream):
            for _ in _gzip_spans(stream, name):
                count += 1
                if limit is not None and count >= limit:
                    break
            return count
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
    damaged header or a record cut short by the end of the file.

    In a gzip file written by `TFRecordWriter(compression="gzip")` the offset is that of the record's gzip
    member, from the members' index headers; in one written by another tool it is the record's offset in the
    decompressed stream, found by decompressing the file."""
    name = str(path)
    with open(path, "rb") as stream:
        if _is_gzip_file(stream):
            yield from _gzip_spans(stream, name)
            return
        index, offset = 0, 0
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


def _gzip_spans(stream: BinaryIO, name: str) -> Iterator[tuple[int, int]]:
    fd = stream.fileno()
    if member_index(os.pread(fd, HEADER_SIZE, 0)) is None:
        yield from _decompressed_spans(stream, name)
        return
    size = os.fstat(fd).st_size
    index, offset = 0, 0
    while offset < size:
        found = member_index(os.pread(fd, HEADER_SIZE, offset))
        if found is None:
            raise _record_error(name, f"corrupt record {index}: the gzip member at byte {offset} has no record "
                                      "index (damaged, or appended by another tool)")
        member_size, length = found
        if offset + member_size > size:
            raise _record_error(name, f"truncated record at byte {offset} (a gzip member of {member_size} bytes)")
        if length > MAX_RECORD_BYTES:
            raise _record_error(name, f"corrupt record {index}: implausible length {length} at byte {offset}")
        yield offset, length
        offset, index = offset + member_size, index + 1


def _decompressed_spans(stream: BinaryIO, name: str) -> Iterator[tuple[int, int]]:
    """Spans in the decompressed stream of a gzip file without member indexes (decompresses all of it)."""
    for offset, length, _ in _decompressed_records(stream, name):
        yield offset, length


def _decompressed_records(stream: BinaryIO, name: str) -> Iterator[tuple[int, int, bytes]]:
    stream.seek(0)
    offset = 0
    for payload in iter_records_from_stream(stream, name):
        yield offset, len(payload), payload
        offset += _HEADER.size + len(payload) + _FOOTER.size


def _frame_at(stream: BinaryIO, name: str, offset: int, length: int) -> bytes:
    """The framed record (header, data, footer) of a span of `iter_record_spans`, as many bytes as there are."""
    wanted = _HEADER.size + length + _FOOTER.size
    fd = stream.fileno()
    head = os.pread(fd, HEADER_SIZE, 0)
    if not is_gzip(head):
        return os.pread(fd, wanted, offset)
    if member_index(head) is None:  # another tool's gzip: decompress up to the record (slow, but correct)
        stream.seek(0)
        data = decompressed(stream, name)
        skipped = 0
        while skipped < offset:
            chunk = data.read(min(1 << 20, offset - skipped))
            if not chunk:
                return b""
            skipped += len(chunk)
        return data.read(wanted)
    found = member_index(os.pread(fd, HEADER_SIZE, offset))
    if found is None or found[1] != length:
        return b""  # not the member the span named: reported as a changed file
    try:
        return decompress_member(os.pread(fd, found[0], offset))
    except MemberError as error:
        raise _record_error(name, f"record at byte {offset}: {error}") from None


def read_record_at(path: str | os.PathLike, offset: int, length: int, index: int = 0) -> bytes:
    """The payload of the record at byte `offset` (a span of `iter_record_spans`), its data CRC checked;
    RecordError when the file changed since the span was taken."""
    name = str(path)
    with open(path, "rb") as stream:
        frame = _frame_at(stream, name, offset, length)
    changed = _record_error(name, f"record {index} at byte {offset} changed since the file was scanned")
    if len(frame) < _HEADER.size:
        raise changed
    if record_length(frame[:_HEADER.size], name, max(index, 1), offset) != length:
        raise changed
    data = frame[_HEADER.size:_HEADER.size + length]
    footer = frame[_HEADER.size + length:_HEADER.size + length + _FOOTER.size]
    if len(data) < length or len(footer) < _FOOTER.size:
        raise _record_error(name, f"truncated record at byte {offset} (expected {length} bytes of data)")
    if masked_crc32c(data) != _FOOTER.unpack(footer)[0]:
        raise _record_error(name, f"corrupt record {index}: data CRC mismatch at byte {offset}")
    return data


def iter_records_with_spans(path: str | os.PathLike) -> Iterator[tuple[int, int, bytes]]:
    """(offset, length, payload) of every record, each decompressed once: `iter_record_spans` and the records
    together, for indexes that also look inside the records (the viewer's ids) of gzip files."""
    name = str(path)
    with open(path, "rb") as stream:
        if _is_gzip_file(stream) and member_index(os.pread(stream.fileno(), HEADER_SIZE, 0)) is None:
            yield from _decompressed_records(stream, name)
            return
    for index, (offset, length) in enumerate(iter_record_spans(path)):
        yield offset, length, read_record_at(path, offset, length, index)


def file_compression(path: str | os.PathLike) -> str:
    """"gzip" or "none": what a record file holds, from its first two bytes."""
    with open(path, "rb") as stream:
        return "gzip" if is_gzip(stream.read(2)) else "none"


class TFRecordWriter:
    """Writes framed records to a file, plain or `compression="gzip"` (one gzip member per record). Use as a
    context manager."""

    def __init__(self, path: str | os.PathLike, compression: str = "none", level: int = DEFAULT_LEVEL):
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression {compression!r}: use one of {', '.join(COMPRESSIONS)}")
        self.path = Path(path)
        self.compression, self.level = compression, level
        self._stream: BinaryIO | None = open(self.path, "wb")
        self.num_records = 0

    def write(self, data: bytes) -> None:
        assert self._stream is not None, "writer is closed"
        write_framed(self._stream, data, self.compression, self.level)
        self.num_records += 1

    def write_frame(self, frame: bytes) -> None:
        """Appends a record already in the file's form (`frame_for` of it, made elsewhere: a worker process)."""
        assert self._stream is not None, "writer is closed"
        self._stream.write(frame)
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

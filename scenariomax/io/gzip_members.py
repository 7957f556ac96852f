"""Gzip-compressed TFRecord files, one gzip member per record.

A gzip file may hold several members back to back (RFC 1952 §2.2); `gunzip`, Python's `gzip` and tf.data's
`TFRecordDataset(compression_type="GZIP")` (TensorFlow >= 2.5) read them as one stream, so the whole file
is an ordinary TFRecord GZIP file. Writing one member per record keeps what the plain layout gives:

- random access: a record is read by decompressing its own member (the loader's shuffle buffer holds
  record locations, not records);
- appending and truncating at record boundaries (the pipeline's checkpoints and `--resume`);
- an index from headers only: each member's header carries an extra field (subfield id "SM") with the
  member's size in bytes and the record's payload length, so listing records skips the data like the
  plain layout does. Gzip readers ignore extra fields.

Gzip files written by other tools (one stream for the whole file) read the same way, streaming; a record
found in them is read back by decompressing the file up to it (see `scenariomax.io.tfrecord`).
"""

from __future__ import annotations

import struct
import zlib

GZIP_MAGIC = b"\x1f\x8b"
COMPRESSIONS = ("none", "gzip")
# zlib level 1: on real records it compresses in half the time of level 6 (gzip's default) for ~4% more bytes
# (docs/benchmarks.md, "Shard sizes"); conversion time is the scarcer resource (~20 ms a scenario at level 1).
DEFAULT_LEVEL = 1

_FEXTRA = 0x04
_OS_UNKNOWN = 255
_SUBFIELD = b"SM"
_INDEX = struct.Struct("<QQ")  # member size in bytes, record payload length
# ID1 ID2 CM FLG | MTIME (0: members are byte-identical run to run) | XFL OS | XLEN | SI1 SI2 LEN | index
_HEADER = struct.Struct("<2sBBIBBH2sH")
HEADER_SIZE = _HEADER.size + _INDEX.size
_TRAILER_SIZE = 8  # CRC32 and ISIZE of the uncompressed bytes


class MemberError(ValueError):
    """A gzip member is damaged; the message is the problem, without the file (callers add it)."""


def is_gzip(head: bytes) -> bool:
    return head[:2] == GZIP_MAGIC


def gzip_member(frame: bytes, payload_length: int, level: int = DEFAULT_LEVEL) -> bytes:
    """One gzip member holding `frame` (a framed TFRecord record), with the index extra field."""
    compressor = zlib.compressobj(level, zlib.DEFLATED, -zlib.MAX_WBITS)  # raw deflate: we write the wrapper
    body = compressor.compress(frame) + compressor.flush()
    size = HEADER_SIZE + len(body) + _TRAILER_SIZE
    header = _HEADER.pack(GZIP_MAGIC, 8, _FEXTRA, 0, 0, _OS_UNKNOWN, 4 + _INDEX.size, _SUBFIELD, _INDEX.size)
    trailer = struct.pack("<II", zlib.crc32(frame), len(frame) & 0xFFFFFFFF)
    return header + _INDEX.pack(size, payload_length) + body + trailer


def member_index(head: bytes) -> tuple[int, int] | None:
    """(member size, payload length) from the first HEADER_SIZE bytes of a member this module wrote; None for
    anything else (another tool's gzip member, or not gzip)."""
    if len(head) < HEADER_SIZE:
        return None
    magic, method, flags, _, _, _, xlen, subfield, sublen = _HEADER.unpack(head[:_HEADER.size])
    if (magic, method, flags, xlen, subfield, sublen) != (GZIP_MAGIC, 8, _FEXTRA, 4 + _INDEX.size, _SUBFIELD,
                                                          _INDEX.size):
        return None
    size, payload_length = _INDEX.unpack(head[_HEADER.size:HEADER_SIZE])
    return (size, payload_length) if size >= HEADER_SIZE + _TRAILER_SIZE else None


def decompress_member(member: bytes) -> bytes:
    """The bytes one whole gzip member holds, its CRC and length checked by zlib; MemberError when damaged."""
    inflater = zlib.decompressobj(16 + zlib.MAX_WBITS)
    try:
        data = inflater.decompress(member)
    except zlib.error as error:
        raise MemberError(f"damaged gzip data ({error})") from None
    if not inflater.eof:
        raise MemberError("truncated gzip member")
    if inflater.unused_data:
        raise MemberError("gzip member longer than its index says")
    return data


__all__ = ["COMPRESSIONS", "DEFAULT_LEVEL", "GZIP_MAGIC", "HEADER_SIZE", "MemberError", "decompress_member",
           "gzip_member", "is_gzip", "member_index"]

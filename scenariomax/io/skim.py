"""Skimming a tf.Example record for its `scenario/id` without decoding it.

`skim_scenario_id` walks the protobuf wire format with positioned reads (`os.pread`): it reads the first bytes
of each map entry and jumps over the values, so looking up the id of a record costs a few small reads whatever
its size. The viewer's index (`scenariomax.view.index`) and `scenariomax.inspect` both use it; it lives here,
beside the TFRecord framing, so neither has to import the other.
"""

from __future__ import annotations

import os

_ID_KEY = b"scenario/id"
_PEEK = 96  # bytes read at each map entry: tag, length, key tag, key length and a key of up to ~80 bytes
MAX_ENTRIES_SKIMMED = 4096


def _varint(buf: bytes, pos: int) -> tuple[int, int]:
    result = shift = 0
    while True:
        if pos >= len(buf) or shift > 63:
            raise ValueError("bad varint")
        byte = buf[pos]
        pos += 1
        result |= (byte & 0x7F) << shift
        if byte < 0x80:
            return result, pos
        shift += 7


def _skip_field(wire_type: int, buf: bytes, pos: int) -> int:
    """Position after a field's value (the tag already read), or ValueError."""
    if wire_type == 0:
        return _varint(buf, pos)[1]
    if wire_type == 1:
        return pos + 8
    if wire_type == 2:
        length, pos = _varint(buf, pos)
        return pos + length
    if wire_type == 5:
        return pos + 4
    raise ValueError(f"unsupported wire type {wire_type}")


def _bytes_value(feature: bytes) -> str | None:
    """The first value of a Feature's bytes_list, or None."""
    pos = 0
    while pos < len(feature):
        tag, pos = _varint(feature, pos)
        if tag == 0x0A:  # bytes_list
            length, pos = _varint(feature, pos)
            inner, end = feature[pos:pos + length], pos + length
            ipos = 0
            while ipos < len(inner):
                itag, ipos = _varint(inner, ipos)
                if itag == 0x0A:
                    n, ipos = _varint(inner, ipos)
                    return inner[ipos:ipos + n].decode("utf-8", "replace")
                ipos = _skip_field(itag & 7, inner, ipos)
            pos = end
        else:
            pos = _skip_field(tag & 7, feature, pos)
    return None


def _entry_id(entry: bytes) -> str:
    pos = 0
    while pos < len(entry):
        field, pos = _varint(entry, pos)
        if field == 0x12:  # the Feature value
            n, pos = _varint(entry, pos)
            return _bytes_value(entry[pos:pos + n]) or ""
        pos = _skip_field(field & 7, entry, pos)
    return ""


def skim_scenario_id(fd: int, offset: int, length: int) -> str:
    """`scenario/id` of the tf.Example at [offset, offset + length) of file descriptor `fd`, reading only
    the map entries' heads; "" when the record is not a tf.Example or has no id."""
    return _skim(lambda size, at: os.pread(fd, size, at), offset, length)


def skim_scenario_id_in(data: bytes) -> str:
    """`skim_scenario_id` of a record already in memory (a decompressed gzip record)."""
    view = memoryview(data)
    return _skim(lambda size, at: bytes(view[at:at + size]), 0, len(data))


def _skim(pread, offset: int, length: int) -> str:
    """The walk of `skim_scenario_id`; `pread(size, at)` reads the record's bytes."""
    try:
        head = pread(min(32, length), offset)
        tag, pos = _varint(head, 0)
        if tag != 0x0A:  # Example.features
            return ""
        features_length, pos = _varint(head, pos)
        cursor, end = offset + pos, min(offset + pos + features_length, offset + length)
        for _ in range(MAX_ENTRIES_SKIMMED):
            if cursor >= end:
                return ""
            peek = pread(min(_PEEK, end - cursor), cursor)
            tag, pos = _varint(peek, 0)
            if tag != 0x0A:  # not a map entry: skip an unknown field
                cursor += _skip_field(tag & 7, peek, pos)
                continue
            entry_length, pos = _varint(peek, pos)  # Features.feature map entry: key = 1, value = 2
            key_tag, kpos = _varint(peek, pos)
            if key_tag == 0x0A:
                key_length, kpos = _varint(peek, kpos)
                if key_length == len(_ID_KEY) and peek[kpos:kpos + key_length] == _ID_KEY:
                    return _entry_id(pread(entry_length, cursor + pos))
            cursor += pos + entry_length
    except (ValueError, OSError, IndexError):
        return ""
    return ""


__all__ = ["MAX_ENTRIES_SKIMMED", "skim_scenario_id", "skim_scenario_id_in"]

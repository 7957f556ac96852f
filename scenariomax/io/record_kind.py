"""Telling a raw WOMD `Scenario` proto apart from a shard's tf.Example, cheaply, to say what a file is.

Both are protobuf messages in TFRecord framing, so a WOMD Scenario file handed to a shard reader reads
fine and then fails with "missing feature scenario/id (and 70 more)". A tf.Example has one top-level
field (1: features); a Scenario has its tracks in field 2 and its id in field 5. Walking the top-level
field tags (lengths skipped, nothing decoded) tells them apart without the Scenario message class.
"""

from __future__ import annotations

WOMD_SCENARIO_NOT_A_SHARD = ("this is a WOMD Scenario proto file, not a V-Max shard; "
                             "convert it first with scenariomax convert --dataset womd")

_SCENARIO_TRACKS, _SCENARIO_ID = 2, 5
_LENGTH_DELIMITED = 2


def _varint(data: bytes, pos: int) -> tuple[int, int]:
    """(value, next position) of the varint at `pos`; ValueError when it runs past the end."""
    value, shift = 0, 0
    while True:
        if pos >= len(data) or shift > 63:
            raise ValueError("bad varint")
        byte = data[pos]
        value |= (byte & 0x7F) << shift
        pos += 1
        if byte < 0x80:
            return value, pos
        shift += 7


def top_level_fields(data: bytes) -> dict[int, int] | None:
    """{field number: wire type} of a protobuf message's top-level fields, or None when the bytes are not
    a well-formed message. Field contents are skipped, not parsed."""
    fields: dict[int, int] = {}
    pos = 0
    try:
        while pos < len(data):
            key, pos = _varint(data, pos)
            number, wire_type = key >> 3, key & 7
            if wire_type == 0:
                _, pos = _varint(data, pos)
            elif wire_type == 1:
                pos += 8
            elif wire_type == _LENGTH_DELIMITED:
                size, pos = _varint(data, pos)
                pos += size
            elif wire_type == 5:
                pos += 4
            else:  # groups (3, 4) and invalid types: neither message uses them
                return None
            if number == 0 or pos > len(data):
                return None
            fields.setdefault(number, wire_type)
    except ValueError:
        return None
    return fields


def looks_like_womd_scenario(data: bytes) -> bool:
    """True when the record is a WOMD Scenario proto (tracks and scenario id present), not a tf.Example."""
    fields = top_level_fields(data)
    return bool(fields) and all(fields.get(number) == _LENGTH_DELIMITED for number in (_SCENARIO_TRACKS, _SCENARIO_ID))


__all__ = ["WOMD_SCENARIO_NOT_A_SHARD", "looks_like_womd_scenario", "top_level_fields"]

"""Track states and map points of a bulk-parsed Scenario (`proto.ScenarioBulkProto`), read with numpy.

There each state and map point is its serialised message (bytes). The layouts Waymo writes -- every field
present, in field order -- are decoded for all messages at once; any other message is parsed on its own with
the regular message class. Either way the values are the ones the regular parse gives (doubles and floats
read bit for bit; a float field widened to float64 as Python's float() does).
"""

from __future__ import annotations

import operator

import numpy as np
from google.protobuf.message import DecodeError

from scenariomax.sources.womd import proto

STATE_FIELDS = ("center_x", "center_y", "center_z", "length", "width", "height", "heading", "velocity_x", "velocity_y")
_STATE_GETTER = operator.attrgetter(*STATE_FIELDS, "valid")
_POINT_GETTER = operator.attrgetter("x", "y", "z")


def _layout(fields: list[tuple[str, int, str]]) -> tuple[np.dtype, dict[str, int]]:
    """A packed record dtype of (tag byte, value) pairs, and the tag byte each field must carry.
    fields: (name, field number, value dtype: '<f8' double, '<f4' float, 'u1' one-byte varint)."""
    wire = {"<f8": 1, "<f4": 5, "u1": 0}  # fixed64, fixed32, varint
    items, tags = [], {}
    for name, number, kind in fields:
        items += [(f"tag_{name}", "u1"), (name, kind)]
        tags[f"tag_{name}"] = (number << 3) | wire[kind]
    return np.dtype(items), tags


# ObjectState with all its fields (59 bytes), and the invalid state Waymo writes as centre z + valid (11 bytes).
_STATE_FULL = _layout([("center_x", 2, "<f8"), ("center_y", 3, "<f8"), ("center_z", 4, "<f8"), ("length", 5, "<f4"),
                       ("width", 6, "<f4"), ("height", 7, "<f4"), ("heading", 8, "<f4"), ("velocity_x", 9, "<f4"),
                       ("velocity_y", 10, "<f4"), ("valid", 11, "u1")])
_STATE_Z_ONLY = _layout([("center_z", 4, "<f8"), ("valid", 11, "u1")])
_POINT_FULL = _layout([("x", 1, "<f8"), ("y", 2, "<f8"), ("z", 3, "<f8")])  # MapPoint, 27 bytes


def _matching(messages: list[bytes], lengths: np.ndarray,
              layout: tuple[np.dtype, dict[str, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Which messages are exactly `layout` (length, tag bytes, one-byte varints), and those decoded.
    lengths (n,) of the messages. -> (n,) bool, (k,) records"""
    dtype, tags = layout
    candidates = np.flatnonzero(lengths == dtype.itemsize)  # (c,)
    same = len(candidates) == len(messages)  # all of one length: join them all, no selection
    joined = b"".join(messages if same else [messages[row] for row in candidates.tolist()])
    records = np.frombuffer(joined, dtype)  # (c,)
    ok = np.ones(len(candidates), bool)
    for tag, value in tags.items():
        ok &= records[tag] == value
    for name in dtype.names:
        if dtype[name] == np.uint8 and not name.startswith("tag_"):
            ok &= records[name] < 0x80  # a one-byte varint (a longer one changes the layout)
    matched = np.zeros(len(lengths), bool)
    matched[candidates[ok]] = True
    return matched, records[ok]


def _lengths(messages: list[bytes]) -> np.ndarray:
    return np.fromiter(map(len, messages), np.int64, count=len(messages))


def _parse_each(message_class, messages: list[bytes], rows: np.ndarray, getter) -> list[tuple]:
    """The regular parse of the messages at `rows`; ValueError (one line) on bytes that are not one."""
    out = []
    for row in rows.tolist():
        try:
            out.append(getter(message_class.FromString(messages[row])))
        except (DecodeError, RuntimeError, ValueError) as error:
            raise ValueError(f"not a WOMD Scenario message ({error})") from None
    return out


def state_table(states: list[bytes]) -> np.ndarray:
    """Serialised ObjectStates -> (n, 10) float64: the state fields in STATE_FIELDS order, then valid as 1.0 / 0.0
    (what `attrgetter(*STATE_FIELDS, "valid")` of the parsed messages gives)."""
    table = np.zeros((len(states), len(STATE_FIELDS) + 1))
    if not states:
        return table
    lengths = _lengths(states)
    done = np.zeros(len(states), bool)
    full, records = _matching(states, lengths, _STATE_FULL)
    for column, name in enumerate(STATE_FIELDS):
        table[full, column] = records[name]
    table[full, -1] = records["valid"] != 0
    done |= full
    z_only, records = _matching(states, lengths, _STATE_Z_ONLY)
    table[z_only, STATE_FIELDS.index("center_z")] = records["center_z"]
    table[z_only, -1] = records["valid"] != 0
    done |= z_only
    rest = np.flatnonzero(~done)
    if len(rest):
        table[rest] = _parse_each(proto.ObjectStateProto, states, rest, _STATE_GETTER)
    return table


def point_table(points: list[bytes]) -> np.ndarray:
    """Serialised MapPoints -> (n, 3) float64 x, y, z (unset fields 0, as the parsed messages give)."""
    table = np.zeros((len(points), 3))
    if not points:
        return table
    full, records = _matching(points, _lengths(points), _POINT_FULL)
    for column, name in enumerate(("x", "y", "z")):
        table[full, column] = records[name]
    rest = np.flatnonzero(~full)
    if len(rest):
        table[rest] = _parse_each(proto.MapPointProto, points, rest, _POINT_GETTER)
    return table

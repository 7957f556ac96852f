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


def _states_start(track: bytes) -> int | None:
    """Where the states of a serialised Track begin when it starts as Waymo writes it (id, then object type, each
    optional), else None: a field boundary, walked to field by field."""
    pos = 0
    try:
        for tag in (0x08, 0x10):  # id, object_type: varints
            if track[pos] == tag:
                pos = _skip_varint(track, pos + 1)
    except IndexError:
        return None
    return pos if pos == len(track) or track[pos] == 0x1A else None


def track_state_table(tracks: list[bytes], num_steps: int) -> np.ndarray | None:
    """`state_table` of all the states of serialised Tracks (N * num_steps rows, track by track), decoded a whole
    log at once, or None (the caller decodes state by state) unless every track is id, type and then exactly
    `num_steps` states in Waymo's two layouts (all fields, 59 bytes; centre z and valid, 11 bytes) back to back
    to its end. The record boundaries are checked as a chain: each record ends where the next begins, from the
    first state field to the track's end, so no byte is read as a state that is not one."""
    starts = [_states_start(track) for track in tracks]
    if not tracks or None in starts or num_steps == 0:
        return None
    lengths = _lengths(tracks)  # (N,)
    offsets = np.concatenate([[0], np.cumsum(lengths)[:-1]])  # (N,) where each track begins in `data`
    first = offsets + np.array(starts, np.int64)  # (N,) its first state field
    data = np.frombuffer(b"".join(tracks), np.uint8)
    full_size, z_size = _STATE_FULL[0].itemsize, _STATE_Z_ONLY[0].itemsize
    # Record starts: the states field tag, a one-byte length of either layout, that layout's first tag.
    found = np.flatnonzero(data[:-2] == 0x1A)  # (c,) every tag byte, and a few bytes of values
    size, lead = data[found + 1], data[found + 2]
    found = found[((size == full_size) & (lead == _STATE_FULL[1]["tag_center_x"]))
                  | ((size == z_size) & (lead == _STATE_Z_ONLY[1]["tag_center_z"]))]
    owner = np.searchsorted(offsets, found, side="right") - 1  # (c,) the track of each
    found = found[found >= first[owner]]  # (c,) within the states of their track
    if len(found) != len(tracks) * num_steps:
        return None
    records = found.reshape(len(tracks), num_steps)  # (N, T) if each track holds num_steps of them
    ends = records + 2 + data[records + 1]  # (N, T) end of each record
    if not (np.array_equal(records[:, 0], first) and np.array_equal(ends[:, :-1], records[:, 1:])
            and np.array_equal(ends[:, -1], offsets + lengths)):
        return None
    records = records.ravel()
    full = data[records + 1] == full_size  # (N * T,)
    table = np.zeros((len(records), len(STATE_FIELDS) + 1))
    for layout, rows in ((_STATE_FULL, np.flatnonzero(full)), (_STATE_Z_ONLY, np.flatnonzero(~full))):
        dtype, tags = layout
        raw = np.lib.stride_tricks.sliding_window_view(data, dtype.itemsize)[records[rows] + 2]  # (r, size) copied
        decoded = raw.view(dtype)[:, 0]  # (r,)
        ok = decoded["valid"] < 0x80  # a one-byte varint
        for tag, value in tags.items():
            ok &= decoded[tag] == value
        if not ok.all():
            return None
        block = np.zeros((len(rows), len(STATE_FIELDS) + 1))  # (r, F + 1): filled by column, placed at once
        for name in dtype.names:
            if not name.startswith("tag_") and name != "valid":
                block[:, STATE_FIELDS.index(name)] = decoded[name]
        block[:, -1] = decoded["valid"] != 0
        table[rows] = block
    return table


_LANE_STATE_GETTER = operator.attrgetter("lane", "state", "stop_point.x", "stop_point.y", "stop_point.z")


def lane_state_table(states: list[bytes]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Serialised TrafficSignalLaneStates -> lane (n,) int64, state (n,) int64, stop point (n, 3) float64: what
    `attrgetter("lane", "state", "stop_point.x", "stop_point.y", "stop_point.z")` of the parsed messages gives.
    Waymo writes every field, in order: lane (a varint), state (one byte), a full stop point. The records of each
    length are decoded together; any other layout is parsed on its own."""
    n = len(states)
    lane, code, point = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros((n, 3))
    if not states:
        return lane, code, point
    lengths = _lengths(states)
    done = np.zeros(n, bool)
    point_dtype, point_tags = _POINT_FULL
    for size in np.unique(lengths).tolist():
        k = size - 32  # lane varint bytes: tag, k, tag, state, tag, length 27, point (27)
        if not 1 <= k <= 9:  # 9 bytes: up to 2^63 - 1; a 10-byte varint (a negative id) is parsed on its own
            continue
        rows = np.flatnonzero(lengths == size)  # (r,)
        raw = np.frombuffer(b"".join([states[row] for row in rows.tolist()]), np.uint8).reshape(len(rows), size)
        varint = raw[:, 1:1 + k]  # (r, k)
        ok = ((raw[:, 0] == 0x08) & (varint[:, :-1] >= 0x80).all(axis=1) & (varint[:, -1] < 0x80)
              & (raw[:, 1 + k] == 0x10) & (raw[:, 2 + k] < 0x80) & (raw[:, 3 + k] == 0x1A) & (raw[:, 4 + k] == 27))
        found = np.ascontiguousarray(raw[:, 5 + k:]).view(point_dtype)[:, 0]  # (r,)
        for tag, value in point_tags.items():
            ok &= found[tag] == value
        value = np.zeros(len(rows), np.int64)
        for byte in range(k):  # little-endian 7-bit groups (9 of them: 63 bits, never the sign bit)
            value |= (varint[:, byte] & 0x7F).astype(np.int64) << (7 * byte)
        rows, found = rows[ok], found[ok]
        lane[rows], code[rows] = value[ok], raw[ok, 2 + k]
        point[rows, 0], point[rows, 1], point[rows, 2] = found["x"], found["y"], found["z"]
        done[rows] = True
    rest = np.flatnonzero(~done)
    for row, values in zip(rest.tolist(), _parse_each(proto.TrafficSignalLaneStateProto, states, rest,
                                                      _LANE_STATE_GETTER)):
        lane[row], code[row], point[row] = values[0], values[1], values[2:]
    return lane, code, point


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


# --- map points a polyline at a time ---------------------------------------------------------------
# A serialised MapFeature as Waymo writes it: id, then the one geometry message, whose points are consecutive
# fields of 29 bytes (tag, length 27, a full MapPoint). Each such run is decoded in one numpy pass per map.
_RUN_RECORD = np.dtype([("tag", "u1"), ("length", "u1"),
                        *((name, _POINT_FULL[0][name]) for name in _POINT_FULL[0].names)])  # 29 bytes
# MapFeature tag of each geometry message -> (tag of its point field, header tags allowed before the points:
# fixed64 (8 bytes) or varint). Lane: speed_limit_mph, type, interpolating; road line / edge: type.
_GEOMETRY = {0x1A: (0x42, {0x09: 8, 0x10: 0, 0x18: 0}), 0x22: (0x12, {0x08: 0}), 0x2A: (0x12, {0x08: 0}),
             0x42: (0x0A, {}), 0x4A: (0x0A, {}), 0x52: (0x0A, {})}


def _skip_varint(data: bytes, pos: int) -> int:
    """Position after the varint at `pos` (IndexError past the end)."""
    while data[pos] & 0x80:
        pos += 1
    return pos + 1


def _read_varint(data: bytes, pos: int) -> tuple[int, int]:
    value, shift = 0, 0
    while True:
        byte = data[pos]
        value |= (byte & 0x7F) << shift
        pos, shift = pos + 1, shift + 7
        if byte < 0x80:
            return value, pos


def _run_start(feature: bytes, count: int) -> tuple[int, int] | None:
    """(point field tag, position of the first point field) of a serialised MapFeature laid out as Waymo writes it,
    with room for `count` points of 29 bytes from there to the end of its geometry message; None for any other
    layout. Walks the fields one by one up to the points, so the position is a field boundary."""
    try:
        pos = _skip_varint(feature, 1) if feature[0] == 0x08 else 0  # the id
        geometry = _GEOMETRY.get(feature[pos])
        if geometry is None:
            return None
        length, pos = _read_varint(feature, pos + 1)
        end = pos + length
        if end != len(feature):  # the geometry message is the feature's last and only other field
            return None
        point_tag, header = geometry
        while pos < end and feature[pos] != point_tag:
            size = header.get(feature[pos])
            if size is None:
                return None
            pos = pos + 1 + size if size else _skip_varint(feature, pos + 1)
    except IndexError:
        return None
    return (point_tag, pos) if pos + 29 * count <= end else None


def feature_points(features: list[bytes], counts: list[int]) -> list[np.ndarray | None]:
    """The points of serialised MapFeatures whose geometry has `counts[i]` points (the count the parsed message
    gives): (n_i, 3) float64 where the points are one run of full MapPoint fields (`_run_start`), else None (the
    caller parses those). The run holds all n_i point fields of the message, in order: it starts at a field
    boundary and its n_i fields are all of that number, which the message has n_i of."""
    out: list[np.ndarray | None] = [None] * len(features)
    found = []  # (feature, point tag, start)
    for row, (feature, count) in enumerate(zip(features, counts)):
        if count == 0:
            out[row] = np.zeros((0, 3))
            continue
        start = _run_start(feature, count)
        if start is not None:
            found.append((row, *start))
    if not found:
        return out
    runs = [features[row][start:start + 29 * counts[row]] for row, _, start in found]
    records = np.frombuffer(b"".join(runs), _RUN_RECORD)  # (n,)
    num = np.array([counts[row] for row, _, _ in found], np.int64)  # (r,)
    tags = np.repeat(np.array([tag for _, tag, _ in found], np.uint8), num)  # (n,)
    ok = (records["tag"] == tags) & (records["length"] == 27)
    for tag, value in _POINT_FULL[1].items():
        ok &= records[tag] == value
    good = np.logical_and.reduceat(ok, np.concatenate([[0], np.cumsum(num)[:-1]]))  # (r,) every point of the run
    table = np.empty((len(records), 3))
    table[:, 0], table[:, 1], table[:, 2] = records["x"], records["y"], records["z"]
    ends = np.cumsum(num).tolist()
    for (row, _, _), stop, count, fine in zip(found, ends, num.tolist(), good.tolist()):
        if fine:
            out[row] = table[stop - count:stop]
    return out

"""The tf.Example message, built from its public field numbers (no TensorFlow, no .proto compile).

    Example { Features features = 1; }
    Features { map<string, Feature> feature = 1; }
    Feature { oneof kind { BytesList bytes_list = 1; FloatList float_list = 2; Int64List int64_list = 3; } }
    BytesList { repeated bytes value = 1; }  FloatList { repeated float value = 1 [packed]; }
    Int64List { repeated int64 value = 1 [packed]; }
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import DecodeError

from scenariomax._compiled import kernels

_PACKAGE = "vmax.tfexample"
_F = descriptor_pb2.FieldDescriptorProto


def _build_example_class():
    file_proto = descriptor_pb2.FileDescriptorProto(name="vmax_tf_example.proto", package=_PACKAGE, syntax="proto3")

    def message(name: str):
        return file_proto.message_type.add(name=name)

    def repeated(msg, field_type, packed: bool) -> None:
        field = msg.field.add(name="value", number=1, type=field_type, label=_F.LABEL_REPEATED)
        if packed:
            field.options.packed = True

    repeated(message("BytesList"), _F.TYPE_BYTES, packed=False)
    repeated(message("FloatList"), _F.TYPE_FLOAT, packed=True)
    repeated(message("Int64List"), _F.TYPE_INT64, packed=True)
    feature = message("Feature")
    feature.oneof_decl.add(name="kind")
    for number, name in ((1, "bytes_list"), (2, "float_list"), (3, "int64_list")):
        type_name = f".{_PACKAGE}.{''.join(p.capitalize() for p in name.split('_')).replace('list', 'List')}"
        feature.field.add(name=name, number=number, type=_F.TYPE_MESSAGE, label=_F.LABEL_OPTIONAL,
                          type_name=type_name, oneof_index=0)
    features = message("Features")
    entry = features.nested_type.add(name="FeatureEntry")
    entry.options.map_entry = True
    entry.field.add(name="key", number=1, type=_F.TYPE_STRING, label=_F.LABEL_OPTIONAL)
    entry.field.add(name="value", number=2, type=_F.TYPE_MESSAGE, label=_F.LABEL_OPTIONAL,
                    type_name=f".{_PACKAGE}.Feature")
    features.field.add(name="feature", number=1, type=_F.TYPE_MESSAGE, label=_F.LABEL_REPEATED,
                       type_name=f".{_PACKAGE}.Features.FeatureEntry")
    example = message("Example")
    example.field.add(name="features", number=1, type=_F.TYPE_MESSAGE, label=_F.LABEL_OPTIONAL,
                      type_name=f".{_PACKAGE}.Features")
    pool = descriptor_pool.DescriptorPool()
    pool.Add(file_proto)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(f"{_PACKAGE}.Example"))


Example = _build_example_class()

FeatureValue = np.ndarray | list  # float32/int64 array, or list[bytes]


class ExampleError(ValueError):
    """Bytes that are not a valid tf.Example."""


def _varint(value: int) -> bytes:
    """One protobuf varint (value >= 0)."""
    out = bytearray()
    while value > 0x7F:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _header(tag: int, length: int) -> bytes:
    """The start of a length-delimited field: tag byte, length varint."""
    return bytes((tag,)) + _varint(length)


def _size(chunks: list[bytes]) -> int:
    return sum(map(len, chunks))


# A varint takes one more byte at each of these values (as uint64).
_VARINT_STEPS = np.left_shift(np.uint64(1), np.arange(7, 64, 7, dtype=np.uint64))  # (9,)


def _varints(v: np.ndarray) -> bytes:
    """Packed varints of uint64 values (the bit patterns of int64s). (n,) -> bytes"""
    if v.size == 0 or v.max() < 0x80:  # masks, types, small ids: one byte each
        return v.astype(np.uint8).tobytes()
    length = np.searchsorted(_VARINT_STEPS, v, side="right") + 1  # (n,) bytes per value, 1..10
    ends = np.cumsum(length)  # (n,) end of each value's bytes
    out = np.empty(int(ends[-1]), np.uint8)
    # Values of one byte length together (a shard has few: 1, 2, 3 and 10 for -1).
    for size in np.flatnonzero(np.bincount(length)):
        rows = np.flatnonzero(length == size)  # (r,)
        shifts = np.arange(0, 7 * size, 7, dtype=np.uint64)  # (size,)
        groups = ((v[rows, None] >> shifts) & np.uint64(0x7F)).astype(np.uint8)  # (r, size) 7-bit groups
        groups[:, :-1] |= 0x80  # continuation bit on every byte of a value but its last
        out[(ends[rows] - size)[:, None] + np.arange(size)] = groups
    return out.tobytes()


_VARINT_SHIFTS = np.arange(0, 70, 7, dtype=np.uint64)  # (10,) the 7-bit group of each varint byte


def _varint_rows(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each value's varint bytes, padded: (n, width) uint8 and the bytes each uses (n,). v (n,) uint64"""
    length = np.searchsorted(_VARINT_STEPS, v, side="right") + 1  # (n,) 1..10
    width = int(length.max())
    rows = ((v[:, None] >> _VARINT_SHIFTS[:width]) & np.uint64(0x7F)).astype(np.uint8)  # (n, width) 7-bit groups
    rows[np.arange(width) < (length - 1)[:, None]] |= 0x80  # continuation bit on every byte of a value but its last
    return rows, length


def _varint_runs(v: np.ndarray, starts: np.ndarray) -> bytes:
    """Packed varints of uint64 values made of runs of equal values (first index of each run: `starts` (r,)):
    each run's value encoded once, its bytes repeated. (n,) -> bytes"""
    rows, length = _varint_rows(v[starts])  # (r, width), (r,)
    counts = np.diff(np.append(starts, len(v)))  # (r,)
    rows, length = np.repeat(rows, counts, axis=0), np.repeat(length, counts)  # (n, width), (n,)
    return rows[np.arange(rows.shape[1]) < length[:, None]].tobytes()  # row order: the values in order


def varints(values: np.ndarray) -> bytes:
    """Packed protobuf varints of int64 values, as protobuf writes them (a negative value as its 64-bit two's
    complement: 10 bytes). (n,) -> bytes"""
    v = np.ascontiguousarray(values, np.int64).view(np.uint64)  # (n,)
    if v.size == 0:
        return b""
    compiled = kernels()
    if compiled is not None:  # the same bytes as below: the padding at the end is one varint repeated
        head = compiled.trailing_run(v)
        return compiled.varint_bytes(v[:head]).tobytes() + _varint(int(v[-1])) * (len(v) - head)
    return _varints_numpy(v)


def _varints_numpy(v: np.ndarray) -> bytes:
    """`varints` in numpy (where numba is missing; the reference the kernel is tested against). v (n >= 1,) uint64"""
    # Shard arrays end in padding (-1: 10 bytes each): the trailing run of one value is one varint repeated.
    differs = np.flatnonzero(v != v[-1])  # (k,)
    head = int(differs[-1]) + 1 if differs.size else 0
    tail = _varint(int(v[-1])) * (len(v) - head)  # one value: plain ints cost less than a numpy pass
    v = v[:head]
    if head == 0 or v.max() < 0x80:  # masks, types, small ids: one byte each
        return v.astype(np.uint8).tobytes() + tail
    # Roadgraph ids, lane links, timestamps repeat in runs (points of one polyline, padding -1 of a row): each run
    # encoded once. Without runs the values are encoded by byte length (fewer bytes to shift than padded rows).
    starts = np.flatnonzero(np.concatenate([[True], v[1:] != v[:-1]]))  # (r,)
    if 2 * len(starts) <= head:
        return _varint_runs(v, starts) + tail
    return _varints(v) + tail


def _feature_chunks(value: FeatureValue) -> list[bytes]:
    """The serialised Feature message of one value, in pieces (joined once for the whole record: a 2 MB
    record is not copied at every level of nesting)."""
    if isinstance(value, (bytes, str)):
        value = [value]
    if isinstance(value, list):
        items = [v.encode() if isinstance(v, str) else bytes(v) for v in value]
        inner = [part for item in items for part in (_header(0x0A, len(item)), item)]  # BytesList.value
        return [_header(0x0A, _size(inner)), *inner]  # Feature.bytes_list
    array = np.asarray(value)
    if array.dtype.kind == "f":
        tag, data = 0x12, array.astype("<f4", copy=False).ravel().tobytes()  # Feature.float_list
    elif array.dtype.kind == "b":
        tag, data = 0x1A, np.ascontiguousarray(array).view(np.uint8).tobytes()  # masks: 0 / 1, one byte each
    elif array.dtype.kind in "iu":
        tag, data = 0x1A, varints(array.ravel())  # Feature.int64_list
    else:
        raise TypeError(f"unsupported dtype {array.dtype}")
    inner = [_header(0x0A, len(data)), data] if data else []  # packed value; nothing when empty
    return [_header(tag, _size(inner)), *inner]


def _map_order(key: str) -> bytes:
    """Sort key of map entries as protobuf's (upb) deterministic serialisation orders them: bytewise, and a
    key that is a prefix of another after it (0xFF never occurs in UTF-8)."""
    return key.encode() + b"\xff"


def encode_example(features: Mapping[str, FeatureValue]) -> bytes:
    """Serialises {key: array} to tf.Example bytes. float arrays -> FloatList, integer/bool arrays
    -> Int64List, bytes/str (or lists of them) -> BytesList. Keys are written sorted, so equal
    inputs give byte-identical output.

    The wire format is written directly (numpy bytes and varints) rather than through the protobuf message:
    the message would turn a 2 MB record into a million Python numbers first. The bytes are those of
    `Example.SerializeToString(deterministic=True)` (tests compare them)."""
    chunks: list[bytes] = []
    for key in sorted(features, key=_map_order):
        try:
            feature = _feature_chunks(features[key])
        except TypeError as error:
            raise TypeError(f"feature {key!r}: {error}") from None
        name = key.encode()
        entry = [_header(0x0A, len(name)), name, _header(0x12, _size(feature)), *feature]  # map entry: key, value
        chunks += [_header(0x0A, _size(entry)), *entry]  # Features.feature
    if not chunks:
        return b""
    return b"".join([_header(0x0A, _size(chunks)), *chunks])  # Example.features


def decode_example(data: bytes) -> dict[str, FeatureValue]:
    """Parses tf.Example bytes into {key: float32 array | int64 array | list[bytes]} (flat arrays)."""
    example = Example()
    try:
        example.ParseFromString(data)
    except (DecodeError, RuntimeError, ValueError) as error:
        raise ExampleError(f"not a tf.Example message ({error})") from None
    out: dict[str, FeatureValue] = {}
    for key, feature in example.features.feature.items():
        kind = feature.WhichOneof("kind")
        if kind == "float_list":
            out[key] = np.array(feature.float_list.value, dtype=np.float32)
        elif kind == "int64_list":
            out[key] = np.array(feature.int64_list.value, dtype=np.int64)
        elif kind == "bytes_list":
            out[key] = list(feature.bytes_list.value)
        else:
            out[key] = np.zeros(0, dtype=np.float32)  # a Feature with no kind set: an empty list
    return out

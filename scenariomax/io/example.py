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


def encode_example(features: Mapping[str, FeatureValue]) -> bytes:
    """Serialises {key: array} to tf.Example bytes. float arrays -> FloatList, integer/bool arrays
    -> Int64List, bytes/str (or lists of them) -> BytesList. Keys are written sorted, so equal
    inputs give byte-identical output."""
    example = Example()
    feature_map = example.features.feature
    for key in sorted(features):
        value = features[key]
        if isinstance(value, (bytes, str)):
            value = [value]
        if isinstance(value, list):
            feature_map[key].bytes_list.value.extend(v.encode() if isinstance(v, str) else bytes(v) for v in value)
            continue
        array = np.asarray(value)
        if array.dtype.kind == "f":
            feature_map[key].float_list.value.extend(array.astype(np.float32, copy=False).ravel().tolist())
        elif array.dtype.kind in "iub":
            feature_map[key].int64_list.value.extend(array.astype(np.int64, copy=False).ravel().tolist())
        else:
            raise TypeError(f"feature {key!r}: unsupported dtype {array.dtype}")
    return example.SerializeToString(deterministic=True)


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

"""encode_example writes the tf.Example wire format itself: the bytes must be protobuf's own."""

from __future__ import annotations

import numpy as np
import pytest
from google.protobuf.internal import api_implementation

from scenariomax.io.example import Example, decode_example, encode_example, varints


def _protobuf_bytes(features) -> bytes:
    """The reference: the message built field by field, serialised deterministically."""
    example = Example()
    for key in sorted(features):
        value = features[key]
        value = [value] if isinstance(value, (bytes, str)) else value
        if isinstance(value, list):
            example.features.feature[key].bytes_list.value.extend(v.encode() if isinstance(v, str) else v
                                                                  for v in value)
        elif np.asarray(value).dtype.kind == "f":
            example.features.feature[key].float_list.value.extend(np.asarray(value, np.float32).ravel().tolist())
        else:
            example.features.feature[key].int64_list.value.extend(np.asarray(value).astype(np.int64).ravel().tolist())
    return example.SerializeToString(deterministic=True)


def _features(seed: int) -> dict:
    rng = np.random.default_rng(seed)
    edges = [0, 1, 127, 128, 16383, 16384, 2 ** 21, 2 ** 35, 2 ** 56, 2 ** 63 - 1, -1, -2, -128, -2 ** 63]
    return {
        "a": [b""], "ab": [b"x" * 300, "y"], "abc": "z",  # keys that are prefixes of others
        "state/x": rng.normal(size=(7, 11)).astype(np.float32), "state/empty": np.zeros(0, np.float32),
        "edges": np.array(edges, np.int64), "ids": np.concatenate([rng.integers(-5, 10 ** 6, 50), np.full(99, -1)]),
        "mask": rng.random(40) < 0.5, "small": rng.integers(0, 100, 30, dtype=np.int32),
        "empty_ints": np.zeros(0, np.int64), "f64": rng.normal(size=5) * 1e30,
        "special": np.array([np.inf, -np.inf, -0.0, 1e-45], np.float32),
    }


@pytest.mark.parametrize("seed", range(3))
def test_bytes_decode_to_the_same_features(seed):
    features = _features(seed)
    decoded = decode_example(encode_example(features))
    assert set(decoded) == set(features)
    for key, value in features.items():
        if isinstance(value, (list, str)):
            assert decoded[key] == [v.encode() if isinstance(v, str) else v for v in
                                    (value if isinstance(value, list) else [value])]
        else:
            want = np.asarray(value).ravel()
            np.testing.assert_array_equal(decoded[key], want.astype(np.float32 if want.dtype.kind == "f" else np.int64))


@pytest.mark.skipif(api_implementation.Type() != "upb", reason="map entry order of the upb protobuf backend")
@pytest.mark.parametrize("seed", range(3))
def test_bytes_are_protobufs_own(seed):
    features = _features(seed)
    assert encode_example(features) == _protobuf_bytes(features)
    assert encode_example({}) == _protobuf_bytes({}) == b""


def test_varints_match_protobuf():
    values = np.array([0, 1, 127, 128, 300, 2 ** 32, 2 ** 63 - 1, -1, -300, -2 ** 63], np.int64)
    example = Example()
    example.features.feature["v"].int64_list.value.extend(values.tolist())
    assert varints(values) in example.SerializeToString()
    assert varints(np.full(5, -1)) == bytes.fromhex("ffffffffffffffffff01") * 5


def test_varints_of_runs_match_protobuf():
    # Runs of equal values (roadgraph ids, padding inside rows) are encoded once per run: the bytes must not change.
    rng = np.random.default_rng(0)
    for _ in range(20):
        values = rng.integers(-2 ** 63, 2 ** 63 - 1, 30, dtype=np.int64) >> rng.integers(0, 64, 30)
        values[rng.random(30) < 0.3] = -1
        values = np.repeat(values, rng.integers(1, 12, 30))
        example = Example()
        example.features.feature["v"].int64_list.value.extend(values.tolist())
        assert varints(values) in example.SerializeToString()


def test_unsupported_dtype_is_named():
    with pytest.raises(TypeError, match="feature 'o'"):
        encode_example({"o": np.array(["a"], object)})

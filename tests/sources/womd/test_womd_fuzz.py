"""Truncated and corrupted WOMD files: a clean one-line InputError or Failure, never a crash or hang."""

from __future__ import annotations

import functools

from hypothesis import given, settings
from hypothesis import strategies as st

from scenariomax.errors import InputError
from scenariomax.io.tfrecord import frame_record
from scenariomax.scenario import Scenario
from scenariomax.sources.base import Failure
from scenariomax.sources.womd import WomdSource
from tests.sources.womd.fixtures import build_scenario

FUZZ = settings(max_examples=30, deadline=None)


@functools.lru_cache(maxsize=1)
def good_record() -> bytes:
    return build_scenario(num_steps=91)


def convert_bytes(tmp_path_factory, data: bytes, **kwargs) -> tuple[list, str | None]:
    path = tmp_path_factory.mktemp("fuzz") / "f.tfrecord"
    path.write_bytes(data)
    items, error = [], None
    try:
        items.extend(WomdSource(str(path), **kwargs).read_unit(str(path)))
    except InputError as exc:
        error = str(exc)
        assert str(path) in error and "\n" not in error
    for item in items:
        assert isinstance(item, (Scenario, Failure))
        if isinstance(item, Failure):
            assert item.unit == str(path) and "\n" not in item.reason and item.reason
    return items, error


@FUZZ
@given(cut=st.integers(min_value=1, max_value=10_000))
def test_truncated_file(tmp_path_factory, cut):
    data = frame_record(good_record())
    items, error = convert_bytes(tmp_path_factory, data[: max(len(data) - cut, 1)])
    assert error is not None and "truncated" in error and items == []


@FUZZ
@given(position=st.integers(min_value=0), value=st.integers(min_value=0, max_value=255))
def test_corrupted_byte_in_framed_file(tmp_path_factory, position, value):
    data = bytearray(frame_record(good_record()))
    position %= len(data)
    if data[position] == value:
        value ^= 0xFF
    data[position] = value
    _, error = convert_bytes(tmp_path_factory, bytes(data))
    assert error is not None  # the CRCs catch every single-byte change


@FUZZ
@given(data=st.data())
def test_corrupted_payload_with_valid_crc(tmp_path_factory, data):
    """Damage the proto itself and re-frame it (valid CRCs): the parser must fail cleanly."""
    payload = bytearray(good_record())
    for _ in range(data.draw(st.integers(1, 8))):
        payload[data.draw(st.integers(0, len(payload) - 1))] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(0, len(payload)))
    items, error = convert_bytes(tmp_path_factory, frame_record(bytes(payload[:cut])))
    assert error is None and len(items) >= 1


@FUZZ
@given(blob=st.binary(min_size=0, max_size=300))
def test_random_bytes(tmp_path_factory, blob):
    for fmt in ("auto", "tf_example"):
        convert_bytes(tmp_path_factory, frame_record(blob), womd_format=fmt)
        convert_bytes(tmp_path_factory, blob, womd_format=fmt)

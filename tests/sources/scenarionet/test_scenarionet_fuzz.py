"""Truncated and corrupted ScenarioNet pickles: a clean one-line InputError or Failure, never a crash."""

from __future__ import annotations

import functools
import pickle

from hypothesis import given, settings
from hypothesis import strategies as st

from scenariomax.errors import InputError
from scenariomax.scenario import Scenario
from scenariomax.sources.base import Failure
from scenariomax.sources.scenarionet import ScenarioNetSource
from tests.sources.scenarionet.fixtures import build_description, early_metadrive_description

FUZZ = settings(max_examples=30, deadline=None)


@functools.lru_cache(maxsize=1)
def good_bytes() -> bytes:
    return pickle.dumps(build_description(num_steps=41), protocol=4)


@functools.cache
def other_bytes(kind: str) -> bytes:
    """Protocol 2 (GLOBAL opcodes, _codecs.encode), 5 (BYTEARRAY8, _frombuffer) and an early-MetaDrive file."""
    if kind == "early":
        return pickle.dumps(early_metadrive_description(), protocol=4)
    return pickle.dumps(build_description(num_steps=41), protocol=int(kind))


def convert_bytes(tmp_path_factory, data: bytes) -> None:
    path = tmp_path_factory.mktemp("fuzz") / "sd_fuzz.pkl"
    path.write_bytes(data)
    try:
        items = list(ScenarioNetSource(str(path)).read_unit(str(path)))
    except InputError as error:
        assert str(path) in str(error) and "\n" not in str(error)
        return
    for item in items:
        assert isinstance(item, (Scenario, Failure))
        if isinstance(item, Failure):
            assert "\n" not in item.reason and item.reason


@FUZZ
@given(cut=st.integers(min_value=0, max_value=100_000))
def test_truncated_pickle(tmp_path_factory, cut):
    data = good_bytes()
    convert_bytes(tmp_path_factory, data[: cut % len(data)])


@FUZZ
@given(data=st.data())
def test_corrupted_pickle(tmp_path_factory, data):
    blob = bytearray(good_bytes())
    for _ in range(data.draw(st.integers(1, 6))):
        blob[data.draw(st.integers(0, len(blob) - 1))] = data.draw(st.integers(0, 255))
    convert_bytes(tmp_path_factory, bytes(blob))


@FUZZ
@given(blob=st.binary(max_size=200))
def test_random_bytes(tmp_path_factory, blob):
    convert_bytes(tmp_path_factory, blob)


@FUZZ
@given(data=st.data(), kind=st.sampled_from(["2", "5", "early"]))
def test_corrupted_pickle_other_protocols(tmp_path_factory, data, kind):
    blob = bytearray(other_bytes(kind))
    for _ in range(data.draw(st.integers(1, 6))):
        blob[data.draw(st.integers(0, len(blob) - 1))] = data.draw(st.integers(0, 255))
    convert_bytes(tmp_path_factory, bytes(blob[: data.draw(st.integers(1, len(blob)))]))

"""Truncated and corrupted AV2 files: a clean InputError or Failure, never a crash or a hang."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from scenariomax.errors import InputError
from scenariomax.scenario import Scenario
from scenariomax.sources.av2 import Av2Source
from scenariomax.sources.base import Failure
from tests.sources.av2.fixtures import map_of, parquet_of, write_scenario_dir


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> Path:
    return write_scenario_dir(tmp_path_factory.mktemp("av2-pristine"))


def _mutate(data: bytes, cut: int, flips: list[tuple[int, int]]) -> bytes:
    out = bytearray(data[: cut % (len(data) + 1)])
    for position, value in flips:
        if out:
            out[position % len(out)] = value
    return bytes(out)


def _convert_mutated(pristine: Path, which: str, cut: int, flips) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / pristine.name
        shutil.copytree(pristine, folder)
        target = parquet_of(folder) if which == "parquet" else map_of(folder)
        target.write_bytes(_mutate(target.read_bytes(), cut, flips))
        try:
            items = list(Av2Source(tmp).read_unit(str(folder)))
        except InputError as err:
            assert "\n" not in str(err) and str(folder) in str(err)
            return
        for item in items:
            assert isinstance(item, (Scenario, Failure))
            if isinstance(item, Failure):
                assert "\n" not in item.reason and str(folder) in item.unit
            else:
                assert item.validate() == []


mutations = {
    "cut": st.integers(min_value=0, max_value=1 << 20),
    "flips": st.lists(st.tuples(st.integers(min_value=0, max_value=1 << 20), st.integers(0, 255)), max_size=8),
}


@settings(max_examples=30, deadline=None)
@given(**mutations)
def test_corrupted_parquet(pristine, cut, flips):
    _convert_mutated(pristine, "parquet", cut, flips)


@settings(max_examples=30, deadline=None)
@given(**mutations)
def test_corrupted_map(pristine, cut, flips):
    _convert_mutated(pristine, "map", cut, flips)


@settings(max_examples=30, deadline=None)
@given(cut=st.integers(min_value=0, max_value=4000))
def test_truncated_parquet(pristine, cut):
    _convert_mutated(pristine, "parquet", cut, [])

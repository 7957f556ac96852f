"""`vmax-sim train` / `evaluate` check the shards before a long run: a CRC-bad record stops them at once (not a
minute and gigabytes in), `--deep` stops them on implausible values, each in one line naming file and record."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from scenariomax.errors import InputError
from tests.conftest import straight_road_scenario
from vmax_cli.vmax_cli import main as vmax_main
from vmax_sim.data.precheck import check_shards, shard_paths


def _write(out: Path, scenarios) -> Path:
    import scenariomax

    sizes = scenariomax.Sizes(num_objects=4, num_roadgraph=400)
    scenariomax.write_shards((scenariomax.fit_to_budget(s, sizes) for s in scenarios), out, sizes)
    return next(out.glob("*.tfrecord"))


@pytest.fixture
def shards(tmp_path) -> Path:
    _write(tmp_path / "shards", [straight_road_scenario(f"toy-{i}") for i in range(3)])
    return tmp_path / "shards"


def _flip_a_byte(file: Path, at_fraction: float) -> None:
    data = bytearray(file.read_bytes())
    data[int(len(data) * at_fraction)] ^= 0xFF
    file.write_bytes(bytes(data))


def test_clean_shards_pass_and_count_their_records(shards):
    assert check_shards([str(shards)], deep=True, progress=False) == 3


def test_a_crc_bad_record_is_named_by_file_and_record(shards):
    file = next(shards.glob("*.tfrecord"))
    _flip_a_byte(file, 0.9)  # inside the last record's data
    with pytest.raises(InputError) as raised:
        check_shards([str(file)], progress=False)
    message = str(raised.value)
    assert message.startswith(f"{file}: corrupt record 2: data CRC mismatch") and "\n" not in message, message


def test_deep_finds_a_position_of_a_million_km_that_the_quick_check_lets_through(tmp_path):
    far = straight_road_scenario("far-away")
    x = far.x.copy()
    x[1, 40] = 1e9
    file = _write(tmp_path / "far", [straight_road_scenario("near"), dataclasses.replace(far, x=x)])
    assert check_shards([str(file)], progress=False) == 2
    with pytest.raises(InputError) as raised:
        check_shards([str(file)], deep=True, progress=False)
    message = str(raised.value)
    assert message.startswith(f"{file}: record 1 (far-away): ") and "\n" not in message, message


def test_mixtures_are_checked_source_by_source_and_the_embedded_split_is_left_out():
    assert shard_paths(["synthetic:0.5,shards/womd:0.5", "", "held_out/"]) == ["shards/womd", "held_out/"]
    assert shard_paths(["a/", "a/"]) == ["a/"]


def test_train_stops_on_a_crc_bad_record_before_it_starts(shards, tmp_path):
    _flip_a_byte(next(shards.glob("*.tfrecord")), 0.5)
    result = CliRunner().invoke(vmax_main, ["train", "--data", str(shards), "--out", str(tmp_path / "run"),
                                            "--quiet", "train.total_env_steps=100"])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert lines[-1].startswith(f"error: {next(shards.glob('*.tfrecord'))}: corrupt record 1: data CRC"), lines
    assert not (tmp_path / "run").exists()  # nothing started


def test_evaluate_deep_names_the_implausible_record(tmp_path):
    far = straight_road_scenario("far-away")
    file = _write(tmp_path / "far", [dataclasses.replace(far, y=np.full_like(far.y, 1e9))])
    result = CliRunner().invoke(vmax_main, ["evaluate", "--policy", "expert", "--data", str(file), "--deep",
                                            "--quiet"])
    assert result.exit_code == 2, result.output
    assert result.output.strip().splitlines()[-1].startswith(f"error: {file}: record 0 (far-away): "), result.output

"""Bad input gives a one-line InputError naming the file, or a Failure for one scenario."""

from __future__ import annotations

import json

import pytest

from scenariomax.errors import InputError
from scenariomax.scenario import Scenario
from scenariomax.sources.av2 import Av2Source
from scenariomax.sources.base import Failure
from tests.sources.av2.fixtures import (
    map_of,
    parquet_of,
    tiny_map,
    tiny_rows,
    write_parquet,
    write_scenario_dir,
)


def _read(folder):
    return list(Av2Source(str(folder.parent)).read_unit(str(folder)))


def _input_error(folder, path) -> str:
    with pytest.raises(InputError) as info:
        _read(folder)
    message = str(info.value)
    assert str(path) in message and "\n" not in message
    return message


def test_missing_map_names_the_parquet(tmp_path):
    folder = write_scenario_dir(tmp_path)
    map_of(folder).unlink()
    assert "no map file" in _input_error(folder, parquet_of(folder))


def test_broken_json(tmp_path):
    folder = write_scenario_dir(tmp_path)
    map_of(folder).write_bytes(b'{"lane_segments": {"1": [')
    assert "invalid JSON" in _input_error(folder, map_of(folder))


@pytest.mark.parametrize("archive, expected", [
    ([], "top level is not a JSON object"),
    ({"pedestrian_crossings": {}}, "missing 'lane_segments'"),
    ({"lane_segments": {"1": {"id": 1, "right_lane_boundary": []}}}, "missing 'left_lane_boundary'"),
    ({"lane_segments": {"1": {"id": 1, "left_lane_boundary": [{"x": 0}], "right_lane_boundary": []}}},
     "at least 2 points"),
    ({"lane_segments": {"1": {"id": "one", "left_lane_boundary": [], "right_lane_boundary": []}}},
     "is not an integer"),
    ({"lane_segments": {"1": {"id": 1, "left_lane_boundary": [{"x": 0, "y": 0}, {"x": 9e5, "y": 0}],
                              "right_lane_boundary": []}}}, "longer than"),
])
def test_malformed_map_structure(tmp_path, archive, expected):
    folder = write_scenario_dir(tmp_path)
    map_of(folder).write_text(json.dumps(archive))
    assert expected in _input_error(folder, map_of(folder))


def test_broken_parquet(tmp_path):
    folder = write_scenario_dir(tmp_path)
    parquet_of(folder).write_bytes(b"PAR1 this is not a parquet file")
    assert "unreadable parquet" in _input_error(folder, parquet_of(folder))


def test_parquet_without_av2_columns(tmp_path):
    folder = write_scenario_dir(tmp_path)
    write_parquet(parquet_of(folder), [{"track_id": "AV", "timestep": 0}])
    assert "missing columns" in _input_error(folder, parquet_of(folder))


def test_scenario_without_av_is_a_failure(tmp_path):
    folder = write_scenario_dir(tmp_path, rows=[r for r in tiny_rows() if r["track_id"] != "AV"])
    (item,) = _read(folder)
    assert isinstance(item, Failure) and "no 'AV' track" in item.reason
    assert item.unit == str(parquet_of(folder))


def test_av_seen_too_briefly_is_a_failure(tmp_path):
    rows = [r for r in tiny_rows() if r["track_id"] != "AV" or r["timestep"] < 6]
    (item,) = _read(write_scenario_dir(tmp_path, rows=rows))
    assert isinstance(item, Failure) and "never valid" in item.reason


def test_window_avoids_steps_where_the_av_is_missing(tmp_path):
    rows = [r for r in tiny_rows() if r["track_id"] != "AV" or r["timestep"] < 100]
    (item,) = _read(write_scenario_dir(tmp_path, rows=rows))
    assert isinstance(item, Scenario) and item.metadata["window_start"] == 9 and item.valid[0].all()


def test_absurd_timesteps_are_a_failure(tmp_path):
    rows = tiny_rows()
    rows[0]["timestep"] = 10**9
    (item,) = _read(write_scenario_dir(tmp_path, rows=rows))
    assert isinstance(item, Failure) and "timesteps" in item.reason


def test_empty_source_folder(tmp_path):
    with pytest.raises(InputError, match="no AV2 scenarios"):
        Av2Source(str(tmp_path)).list_units()


def test_missing_unit(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        list(Av2Source(str(tmp_path)).read_unit(str(tmp_path / "gone")))


def test_map_fixture_is_json_serialisable():
    assert json.loads(json.dumps(tiny_map()))["lane_segments"]["1"]["id"] == 1

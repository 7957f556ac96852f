"""Bad nuPlan input: clear one-line InputErrors naming the file, Failures for single scenarios, and
corrupted/truncated bytes that never crash or hang the reader."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scenariomax import Scenario
from scenariomax.errors import InputError
from scenariomax.sources.base import Failure
from scenariomax.sources.nuplan import NuplanSource
from tests.sources.nuplan import builders as b


def _read(db: Path, maps_root: Path) -> list:
    return list(NuplanSource(str(db), str(maps_root)).read_unit(str(db)))


def _copy_db(files, tmp_path: Path) -> Path:
    target = tmp_path / files.db_path.name
    shutil.copyfile(files.db_path, target)
    return target


def test_missing_table_names_file_and_table(nuplan_files, tmp_path):
    db = _copy_db(nuplan_files, tmp_path)
    with sqlite3.connect(db) as conn:
        conn.execute("DROP TABLE lidar_box")
    with pytest.raises(InputError) as error:
        _read(db, nuplan_files.maps_root)
    assert str(error.value) == f"{db}: table 'lidar_box' is missing"


def test_missing_column_names_it(nuplan_files, tmp_path):
    db = _copy_db(nuplan_files, tmp_path)
    with sqlite3.connect(db) as conn:
        conn.execute("ALTER TABLE ego_pose DROP COLUMN angular_rate_z")
    with pytest.raises(InputError, match=r"\.db: table 'ego_pose' lacks column\(s\) angular_rate_z$"):
        _read(db, nuplan_files.maps_root)


def test_missing_map_layer_names_map_and_layer(tmp_path):
    files = b.write_fixture(tmp_path, skip_layers=("lanes_polygons",))
    with pytest.raises(InputError) as error:
        _read(files.db_path, files.maps_root)
    assert str(error.value) == f"{files.map_path}: layer 'lanes_polygons' is missing"


def test_missing_map_file_for_map_version(nuplan_files, tmp_path):
    db = _copy_db(nuplan_files, tmp_path)
    with sqlite3.connect(db) as conn:
        conn.execute("UPDATE log SET map_version = 'sg-one-north'")
    with pytest.raises(InputError, match=r"sg-one-north/9\.17\.1964/map\.gpkg: map file for map_version "
                                         r"'sg-one-north' is missing"):
        _read(db, nuplan_files.maps_root)


def test_map_version_with_gpkg_suffix_finds_the_map(nuplan_files, tmp_path):
    db = _copy_db(nuplan_files, tmp_path)
    with sqlite3.connect(db) as conn:
        conn.execute(f"UPDATE log SET map_version = '{b.LOCATION}.gpkg'")
    assert [type(item) for item in _read(db, nuplan_files.maps_root)] == [Scenario, Scenario]


def test_not_a_database(nuplan_files, tmp_path):
    db = tmp_path / "broken.db"
    db.write_bytes(b"this is not SQLite at all" * 10)
    with pytest.raises(InputError, match=r"broken\.db: unreadable SQLite file"):
        _read(db, nuplan_files.maps_root)


def test_window_without_ego_pose_fails_alone(nuplan_files, tmp_path):
    db = _copy_db(nuplan_files, tmp_path)
    anchor_time = b.lidar_time(40)
    with sqlite3.connect(db) as conn:
        conn.execute("DELETE FROM ego_pose WHERE timestamp BETWEEN ? AND ?", (anchor_time - 400_000,
                                                                             anchor_time + 400_000))
    first, second = _read(db, nuplan_files.maps_root)
    assert isinstance(first, Failure) and "no ego_pose within 250 ms" in first.reason
    assert first.scenario.endswith(b.token(5, 40).hex()) and first.unit == str(db)
    assert isinstance(second, Scenario) and second.validate() == []


def _check_outcome(db: Path, maps_root: Path) -> None:
    try:
        items = _read(db, maps_root)
    except InputError as exc:
        message = str(exc)
        assert "\n" not in message and str(db) in message or "map.gpkg" in message
        return
    for item in items:
        assert isinstance(item, (Scenario, Failure))
        if isinstance(item, Failure):
            assert "\n" not in item.reason


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_corrupted_or_truncated_db_is_a_clean_error(nuplan_files, tmp_path_factory, data):
    raw = bytearray(nuplan_files.db_path.read_bytes())
    if data.draw(st.booleans(), label="truncate"):
        raw = raw[: data.draw(st.integers(0, len(raw) - 1), label="length")]
    else:
        for _ in range(data.draw(st.integers(1, 40), label="flips")):
            raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
    db = tmp_path_factory.mktemp("corrupt") / nuplan_files.db_path.name
    db.write_bytes(bytes(raw))
    _check_outcome(db, nuplan_files.maps_root)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_corrupted_map_is_a_clean_error(nuplan_files, tmp_path_factory, data):
    raw = bytearray(nuplan_files.map_path.read_bytes())
    for _ in range(data.draw(st.integers(1, 40), label="flips")):
        raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
    root = tmp_path_factory.mktemp("corrupt_map")
    maps_root = root / "maps"
    relative = nuplan_files.map_path.relative_to(nuplan_files.maps_root)
    (maps_root / relative).parent.mkdir(parents=True)
    (maps_root / relative).write_bytes(bytes(raw))
    _check_outcome(nuplan_files.db_path, maps_root)

"""Finding scenario files: database indexes (mapping / summary), nested databases, loose pickles."""

from __future__ import annotations

import collections
from pathlib import Path

import pytest

from scenariomax.errors import InputError
from scenariomax.scenario import Scenario
from scenariomax.sources.scenarionet import ScenarioNetSource, find_scenario_files
from tests.sources.scenarionet.fixtures import build_description, write_pickle


def names(units) -> list[str]:
    return [Path(u).name for u in units]


def summary_of(*files) -> dict:
    # ScenarioNet writes summaries with defaultdicts inside.
    return {name: {"sdc_id": "ego", "object_summary": collections.defaultdict(int, a=1)} for name in files}


@pytest.fixture
def nested(tmp_path) -> Path:
    """root/ holds databases nuscenes_1 (files beside the index) and nuscenes_2 (mapping into a
    sub-folder, plus a file its index leaves out), and a loose folder with MetaDrive-style names."""
    root = tmp_path / "root"
    write_pickle(root / "nuscenes_1" / "sd_a.pkl", build_description(scenario_id="a"))
    write_pickle(root / "nuscenes_1" / "dataset_mapping.pkl", {"sd_a.pkl": ""})
    write_pickle(root / "nuscenes_1" / "dataset_summary.pkl", summary_of("sd_a.pkl"))
    write_pickle(root / "nuscenes_2" / "part_1" / "sd_b.pkl", build_description(scenario_id="b"))
    write_pickle(root / "nuscenes_2" / "part_1" / "sd_filtered_out.pkl", build_description(scenario_id="x"))
    write_pickle(root / "nuscenes_2" / "dataset_mapping.pkl", {"sd_b.pkl": "part_1"})
    write_pickle(root / "loose" / "0.pkl", build_description(scenario_id="c"))
    write_pickle(root / "loose" / "1.pkl", build_description(scenario_id="d"))
    (root / "loose" / "notes.txt").write_text("not data")
    return root


def test_nested_databases_and_loose_files(nested):
    units = ScenarioNetSource(str(nested)).list_units()
    assert names(units) == ["0.pkl", "1.pkl", "sd_a.pkl", "sd_b.pkl"]
    assert all(Path(u).is_absolute() and Path(u).is_file() for u in units)
    assert find_scenario_files(nested / "nuscenes_2") == [str(nested / "nuscenes_2" / "part_1" / "sd_b.pkl")]


def test_index_file_stands_for_its_database(nested):
    units = ScenarioNetSource(str(nested / "nuscenes_1" / "dataset_summary.pkl")).list_units()
    assert names(units) == ["sd_a.pkl"]


def test_summary_only_database(tmp_path):
    write_pickle(tmp_path / "db" / "sd_a.pkl", build_description(scenario_id="a"))
    write_pickle(tmp_path / "db" / "sd_b.pkl", build_description(scenario_id="b"))
    write_pickle(tmp_path / "db" / "dataset_summary.pkl", summary_of("sd_b.pkl"))
    assert names(ScenarioNetSource(str(tmp_path / "db")).list_units()) == ["sd_b.pkl"]


def test_missing_file_named_by_the_index_is_reported_when_read(tmp_path):
    write_pickle(tmp_path / "db" / "dataset_mapping.pkl", {"sd_gone.pkl": ""})
    source = ScenarioNetSource(str(tmp_path / "db"))
    (unit,) = source.list_units()
    with pytest.raises(InputError, match="cannot read"):
        list(source.read_unit(unit))


def test_bad_index_is_one_line_naming_it(tmp_path):
    write_pickle(tmp_path / "db" / "dataset_mapping.pkl", ["not", "a", "dict"])
    with pytest.raises(InputError) as info:
        ScenarioNetSource(str(tmp_path / "db")).list_units()
    assert "dataset_mapping.pkl" in str(info.value) and "\n" not in str(info.value)
    write_pickle(tmp_path / "db" / "dataset_mapping.pkl", {"sd_a.pkl": 3})
    with pytest.raises(InputError, match="relative folder"):
        ScenarioNetSource(str(tmp_path / "db")).list_units()


def test_empty_folder_and_glob(tmp_path, nested):
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no ScenarioNet scenario files"):
        ScenarioNetSource(str(tmp_path / "empty")).list_units()
    glob_units = ScenarioNetSource(str(nested / "nuscenes_1" / "*.pkl")).list_units()
    assert names(glob_units) == ["sd_a.pkl"]  # index files are never units


def test_every_listed_file_converts(nested):
    source = ScenarioNetSource(str(nested))
    items = [item for unit in source.list_units() for item in source.read_unit(unit)]
    assert sorted(s.scenario_id for s in items if isinstance(s, Scenario)) == ["a", "b", "c", "d"]

"""SyntheticSource as the conversion pipeline sees it."""

import pickle

import pytest

from scenariomax.errors import InputError
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.base import Failure
from scenariomax.sources.synthetic import SyntheticSource
from scenariomax.sources.synthetic import source as source_module


def test_units_cover_the_indices_in_sorted_ranges():
    source = SyntheticSource(num_scenarios=25, seed=1)
    units = source.list_units()
    assert units == ["synthetic:00000-00009", "synthetic:00010-00019", "synthetic:00020-00024"]
    assert units == sorted(units)
    assert SyntheticSource(num_scenarios=0).list_units() == []


def test_read_unit_yields_the_scenarios_of_its_range():
    source = SyntheticSource(num_scenarios=4, seed=2, scenarios_per_unit=2)
    items = list(source.read_unit("synthetic:00002-00003"))
    assert [s.scenario_id for s in items] == ["synthetic-2-000002", "synthetic-2-000003"]
    assert all(isinstance(s, Scenario) and s.validate() == [] for s in items)


def test_source_is_picklable_and_reports_its_settings():
    source = SyntheticSource(num_scenarios=30, seed=5, sizes=Sizes(num_objects=64), scenarios_per_unit=7)
    clone = pickle.loads(pickle.dumps(source))
    assert clone == source and clone.name == "synthetic"
    settings = source.settings()
    assert settings["seed"] == 5 and settings["num_scenarios"] == 30 and settings["scenarios_per_unit"] == 7
    assert settings["sizes"]["num_objects"] == 64


def test_smaller_budget_is_respected():
    source = SyntheticSource(num_scenarios=1, seed=0, sizes=Sizes(num_objects=16))
    (scenario,) = source.read_unit("synthetic:00000-00000")
    assert scenario.num_objects <= 16 and scenario.is_sdc[0]


def test_a_failing_index_becomes_a_failure_and_the_unit_goes_on(monkeypatch):
    real = source_module.generate_scenario

    def flaky(seed, index, sizes):
        if index == 0:
            raise RuntimeError("boom")
        return real(seed, index, sizes)

    monkeypatch.setattr(source_module, "generate_scenario", flaky)
    items = list(SyntheticSource(num_scenarios=2, scenarios_per_unit=2).read_unit("synthetic:00000-00001"))
    assert isinstance(items[0], Failure) and "boom" in items[0].reason
    assert items[0].scenario == "synthetic-0-000000" and isinstance(items[1], Scenario)


@pytest.mark.parametrize("unit", ["womd:1-2", "synthetic:5-2", "synthetic:abc", ""])
def test_bad_unit_ids_give_a_clear_error(unit):
    with pytest.raises(InputError, match="synthetic unit"):
        list(SyntheticSource(num_scenarios=10).read_unit(unit))


def test_a_unit_beyond_the_set_is_refused():
    with pytest.raises(InputError, match="beyond"):
        list(SyntheticSource(num_scenarios=10).read_unit("synthetic:00005-00020"))


def test_bad_settings_give_a_clear_error():
    with pytest.raises(InputError):
        SyntheticSource(num_scenarios=-1)

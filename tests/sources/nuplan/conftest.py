"""Session-wide nuPlan fixtures: one log + map written once in the real layout, converted once."""

from __future__ import annotations

import pytest

from scenariomax.sources.nuplan import NuplanSource
from tests.sources.nuplan.builders import write_fixture


@pytest.fixture(scope="session")
def nuplan_files(tmp_path_factory):
    return write_fixture(tmp_path_factory.mktemp("nuplan_utm"))


@pytest.fixture(scope="session")
def nuplan_lonlat_files(tmp_path_factory):
    return write_fixture(tmp_path_factory.mktemp("nuplan_lonlat"), lonlat=True)


@pytest.fixture(scope="session")
def nuplan_scenarios(nuplan_files):
    source = NuplanSource(str(nuplan_files.db_path), str(nuplan_files.maps_root))
    return list(source.read_unit(str(nuplan_files.db_path)))

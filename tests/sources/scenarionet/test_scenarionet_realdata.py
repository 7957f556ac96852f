"""The real ScenarioNet sample (nuScenes scene-0553): conversion checked against an independent read."""

from __future__ import annotations

import collections
import pickle

import numpy as np
import pytest

from scenariomax.codec import decode_scenario, encode_scenario
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.scenarionet import ScenarioNetSource
from tests.conftest import realdata_file

SAMPLE = "scenarionet/sd_nuscenes_v1.0-mini_scene-0553.pkl"
OUR_TYPES = {"LANE_SURFACE_STREET": 2, "ROAD_LINE_BROKEN_SINGLE_WHITE": 6, "ROAD_LINE_SOLID_SINGLE_WHITE": 7,
             "ROAD_LINE_SOLID_SINGLE_YELLOW": 11}


class _IndependentReader(pickle.Unpickler):
    """A separate minimal reader for the test (numpy arrays only), not the converter's unpickler."""

    def find_class(self, module, name):
        if name == "_reconstruct" and module in ("numpy.core.multiarray", "numpy._core.multiarray"):
            return np._core.multiarray._reconstruct
        if (module, name) in (("numpy", "ndarray"), ("numpy", "dtype")):
            return getattr(np, name)
        raise pickle.UnpicklingError(f"{module}.{name}")


@pytest.fixture(scope="module")
def sample():
    path = realdata_file(SAMPLE)
    with open(path, "rb") as stream:
        raw = _IndependentReader(stream).load()
    items = list(ScenarioNetSource(str(path), sizes=Sizes(num_roadgraph=100_000)).read_unit(str(path)))
    return raw, items


def test_real_sample_windows_are_valid(sample):
    raw, items = sample
    assert raw["length"] == 201
    assert [s.scenario_id for s in items] == ["scene-0553_t000", "scene-0553_t080"]
    for scenario in items:
        assert isinstance(scenario, Scenario) and scenario.validate() == []
        assert decode_scenario(encode_scenario(scenario, Sizes(num_roadgraph=100_000))).validate() == []


def test_real_sample_matches_raw(sample):
    raw, items = sample
    sdc = raw["tracks"][raw["metadata"]["sdc_id"]]["state"]
    raw_valid = sdc["valid"] > 0
    for scenario, start in zip(items, (0, 80)):
        assert scenario.num_objects == len(raw["tracks"]) == 57
        assert scenario.is_sdc[0]
        window = slice(start, start + 91)
        np.testing.assert_array_equal(scenario.valid[0], raw_valid[window])
        np.testing.assert_allclose(scenario.x[0], sdc["position"][window, 0], atol=1e-3, rtol=0)
        np.testing.assert_allclose(scenario.y[0], sdc["position"][window, 1], atol=1e-3, rtol=0)
        expected = collections.Counter(OUR_TYPES[f["type"]] for f in raw["map_features"].values())
        got = collections.Counter(
            t for t, _ in set(zip(scenario.roadgraph_type.tolist(), scenario.roadgraph_id.tolist())))
        assert got == expected and sum(got.values()) == len(raw["map_features"]) == 577
        types = collections.Counter(scenario.object_type.tolist())
        assert types == {1: 28, 4: 16, 2: 12, 3: 1}  # TRAFFIC_BARRIER -> other


def test_default_budget_keeps_the_map_near_the_sdc(sample):
    path = realdata_file(SAMPLE)
    items = list(ScenarioNetSource(str(path), sizes=Sizes(num_roadgraph=5000)).read_unit(str(path)))
    assert all(s.roadgraph_xyz.shape[0] == 5000 and s.validate() == [] for s in items)

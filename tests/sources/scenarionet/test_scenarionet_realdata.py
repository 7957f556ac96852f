"""The real ScenarioNet samples (nuScenes databases, MetaDrive's WOMD assets): conversion checked
against an independent read."""

from __future__ import annotations

import collections
import pickle

import numpy as np
import pytest

from scenariomax import schema as sch
from scenariomax.codec import decode_scenario, encode_scenario
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.base import MANIFEST_NOTES
from scenariomax.sources.scenarionet import ScenarioNetSource
from tests.conftest import realdata_file

SAMPLE = "scenarionet/sd_nuscenes_v1.0-mini_scene-0553.pkl"
OUR_TYPES = {"LANE_SURFACE_STREET": 2, "ROAD_LINE_BROKEN_SINGLE_WHITE": 6, "ROAD_LINE_SOLID_SINGLE_WHITE": 7,
             "ROAD_LINE_SOLID_SINGLE_YELLOW": 11}


class _IndependentReader(pickle.Unpickler):
    """A separate minimal reader for the test (numpy arrays, defaultdict(int)), not the converter's."""

    def find_class(self, module, name):
        if name == "_reconstruct" and module in ("numpy.core.multiarray", "numpy._core.multiarray"):
            return np._core.multiarray._reconstruct
        if (module, name) in (("numpy", "ndarray"), ("numpy", "dtype")):
            return getattr(np, name)
        if (module, name) == ("collections", "defaultdict"):
            return lambda factory: collections.defaultdict(int if factory is int else None)
        if (module, name) == ("builtins", "int"):
            return int
        raise pickle.UnpicklingError(f"{module}.{name}")


def independent_read(path):
    with open(path, "rb") as stream:
        return _IndependentReader(stream).load()


@pytest.fixture(scope="module")
def sample():
    path = realdata_file(SAMPLE)
    raw = independent_read(path)
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
        # the writer's "boundary_<n>" solid white lines are the drivable area's outline: road edges (15)
        expected = collections.Counter(15 if str(key).startswith("boundary_") else OUR_TYPES[f["type"]]
                                       for key, f in raw["map_features"].items())
        got = collections.Counter(
            t for t, _ in set(zip(scenario.roadgraph_type.tolist(), scenario.roadgraph_id.tolist())))
        assert got == expected and sum(got.values()) == len(raw["map_features"]) == 577
        types = collections.Counter(scenario.object_type.tolist())
        assert types == {1: 28, 4: 16, 2: 12, 3: 1}  # TRAFFIC_BARRIER -> other


def test_default_budget_keeps_the_map_near_the_sdc(sample):
    path = realdata_file(SAMPLE)
    items = list(ScenarioNetSource(str(path), sizes=Sizes(num_roadgraph=5000)).read_unit(str(path)))
    assert all(s.roadgraph_xyz.shape[0] == 5000 and s.validate() == [] for s in items)


# --- every database in ../shared/realdata/scenarionet ----------------------------------------------
EXPECTED = {"nuscenes": (4, 8), "womd_20s": (3, 6), "womd_91steps": (3, 3), SAMPLE.split("/")[1]: (1, 2)}


@pytest.fixture(scope="module")
def everything():
    """{unit: [items]} for every scenario file found under scenarionet/ (nested databases included)."""
    root = realdata_file("scenarionet")
    source = ScenarioNetSource(str(root))
    return root, {unit: list(source.read_unit(unit)) for unit in source.list_units()}


def test_every_real_database_converts(everything):
    root, converted = everything
    for entry, (num_files, num_windows) in EXPECTED.items():
        units = [u for u in converted if u.startswith(str(root / entry))]
        items = [item for u in units for item in converted[u]]
        assert len(units) == num_files and len(items) == num_windows, entry
        for item in items:
            assert isinstance(item, Scenario), item
            assert item.validate() == [] and item.is_sdc[0]
            assert decode_scenario(encode_scenario(item)).validate() == []


def contains_defaultdict(value) -> bool:
    if isinstance(value, collections.defaultdict):
        return True
    children = value.values() if isinstance(value, dict) else value if isinstance(value, (list, tuple)) else ()
    return any(contains_defaultdict(child) for child in children)


def test_nuscenes_databases_match_raw(everything):
    root, converted = everything
    for unit in (u for u in converted if "/nuscenes/" in u):
        raw = independent_read(unit)
        assert contains_defaultdict(raw)  # what the converter used to refuse
        ego = raw["tracks"]["ego"]["state"]
        for scenario, start in zip(converted[unit], (0, 80)):
            window = slice(start, start + 91)
            np.testing.assert_allclose(scenario.x[0], ego["position"][window, 0], atol=1e-3, rtol=0)
            np.testing.assert_allclose(scenario.y[0], ego["position"][window, 1], atol=1e-3, rtol=0)
            assert scenario.num_objects == min(len(raw["tracks"]), 128)
            # nuScenes egos arrive sideways (1.73 m long, 4.08 m wide): swapped, and said in the manifest notes
            assert float(np.median(ego["length"])) < 2.0 < float(np.median(ego["width"]))
            assert scenario.length[0, 0] == pytest.approx(float(np.median(ego["width"])), abs=1e-3)
            assert scenario.width[0, 0] == pytest.approx(float(np.median(ego["length"])), abs=1e-3)
            assert "ego" in scenario.metadata[MANIFEST_NOTES]["boxes_swapped"]


def test_nuscenes_lane_headings_are_not_read_as_heights(everything):
    """ScenarioNet's nuScenes converter writes lane centre lines as (x, y, yaw) poses: the yaw column is no height
    (the rest of a nuScenes map is 2-D), and read as one it tilted the lanes' directions up to vertical."""
    root, converted = everything
    units = [u for u in converted if "nuscenes" in u]
    assert units
    for unit in units:
        raw = independent_read(unit)
        lanes = [f for f in raw["map_features"].values() if str(f.get("type", "")).startswith("LANE")]
        assert any(np.abs(np.asarray(f["polyline"])[:, 2]).max() > 1.0 for f in lanes)  # the poses' yaw
        for scenario in converted[unit]:
            lane = scenario.roadgraph_valid & np.isin(scenario.roadgraph_type, sch.LANE_TYPES)
            assert lane.any() and not scenario.roadgraph_xyz[lane, 2].any()
            flat = np.linalg.norm(scenario.roadgraph_dir[lane, :2], axis=-1)  # 0 at a polyline's last point
            assert np.all((np.abs(flat - 1.0) < 1e-3) | (flat == 0.0)) and (flat > 0).mean() > 0.9
            assert "lane_z_was_heading" in scenario.metadata[MANIFEST_NOTES]


def test_womd_20s_lights_and_jittery_times(everything):
    """Early MetaDrive lights (per-step lane / stop point, 0 where not reported) and a log whose
    timestamps wobble (one 0.0894 s step): kept at the source steps, times from the data."""
    root, converted = everything
    for name in ("0.pkl", "1.pkl", "2.pkl"):
        unit = str(root / "womd_20s" / name)
        raw = independent_read(unit)
        ts = np.asarray(raw["metadata"]["ts"], np.float64)
        sdc = raw["tracks"][raw["metadata"]["sdc_id"]]["state"]
        for scenario, start in zip(converted[unit], (0, 80)):
            window = slice(start, start + 91)
            np.testing.assert_allclose(scenario.x[0], sdc["position"][window, 0], atol=1e-3, rtol=0)
            expected_micros = np.round((ts[window] - ts[start]) * 1e6)
            np.testing.assert_array_equal(scenario.timestamp_micros[0], expected_micros)
            for row, lane in enumerate(scenario.tl_lane_id.max(axis=1)):
                if lane < 0:
                    continue
                light = raw["dynamic_map_states"][str(lane)]["state"]
                reported = np.asarray(light["lane"])[window] != 0
                np.testing.assert_array_equal(scenario.tl_valid[row], reported)
                np.testing.assert_array_equal(scenario.tl_state[row][reported],
                                              np.asarray(light["object_state"])[window][reported])
        assert sum(s.tl_valid.sum() for s in converted[unit]) > 0


def test_womd_labels_survive_the_object_budget(everything):
    """211, 115 and 138 tracks for 128 slots: every tracks_to_predict / objects_of_interest track stays."""
    root, converted = everything
    for unit in (u for u in converted if "/womd_91steps/" in u):
        raw = independent_read(unit)
        (scenario,) = converted[unit]
        meta = raw["metadata"]
        kept = {int(i) for i in scenario.object_id}
        assert {int(k) for k in meta["tracks_to_predict"]} == {
            int(i) for i, flag in zip(scenario.object_id, scenario.tracks_to_predict) if flag}
        assert {int(k) for k in meta["objects_of_interest"]} <= kept
        assert scenario.object_id[0] == int(meta["sdc_id"])

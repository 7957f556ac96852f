"""Every real GPUDrive / Nocturne sample (../shared/realdata/{gpudrive,nocturne}): converted, validated, and
checked against an independent read of the JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenariomax.codec import decode_scenario, encode_scenario
from scenariomax.enrich.transform import make_transform
from scenariomax.pipeline import ConvertSettings, convert
from scenariomax.scenario import Scenario
from scenariomax.sources.base import MANIFEST_NOTES
from scenariomax.sources.gpudrive import GpuDriveSource
from scenariomax.validate import validate_shards
from tests.conftest import realdata_file

# file -> (layout, log steps, SDC rule)
EXPECTED = {
    "gpudrive/tfrecord-00000-of-00150_2d84b1ab55ab81d3.json": ("gpudrive-3d", 91, "last-track"),
    "gpudrive/tfrecord-00000-of-00150_78.json": ("gpudrive-metadata", 11, "named"),
    "gpudrive/tfrecord-00000-of-01000_325.json": ("gpudrive-metadata", 91, "named"),
    "gpudrive/tfrecord-00000-of-01000_4.json": ("gpudrive-metadata", 91, "named"),
    "gpudrive/tfrecord-00000-of-01000_402.json": ("gpudrive-metadata", 91, "named"),
    "gpudrive/tfrecord-00002-of-01000_407.json": ("gpudrive-metadata", 91, "named"),
    "gpudrive/tfrecord-00003-of-01000_109.json": ("nocturne", 91, "last-track"),
    "gpudrive/tfrecord-00012-of-01000_389.json": ("nocturne", 91, "last-track"),
    "gpudrive/tfrecord-00043-of-00150_223.json": ("gpudrive-metadata", 11, "named"),
    "gpudrive/tfrecord-00149-of-00150_111.json": ("gpudrive-metadata", 11, "named"),
    "nocturne/example_scenario.json": ("nocturne", 91, "last-track"),
}
GPUDRIVE_TYPES = {("lane", 0): 2, ("lane", 1): 1, ("lane", 2): 2, ("lane", 3): 3, ("road_edge", 15): 15,
                  ("road_edge", 16): 16, ("stop_sign", 17): 17, ("crosswalk", 18): 18, ("speed_bump", 19): 19,
                  ("driveway", 20): 20, **{("road_line", k): k for k in range(6, 14)}}


@pytest.fixture(scope="module")
def converted():
    """{relative path: (raw JSON read independently, [items])}."""
    out = {}
    for relative in EXPECTED:
        path = realdata_file(relative)
        raw = json.loads(path.read_text())
        out[relative] = (raw, list(GpuDriveSource(str(path)).read_unit(str(path))))
    return out


def test_every_file_converts_and_validates(converted):
    for relative, (_, items) in converted.items():
        assert len(items) == 1 and isinstance(items[0], Scenario), (relative, items)
        scenario = items[0]
        assert scenario.validate() == [], relative
        assert decode_scenario(encode_scenario(scenario)).validate() == [], relative
        layout, steps, rule = EXPECTED[relative]
        notes = scenario.metadata[MANIFEST_NOTES]
        assert (notes["layout"], notes["log_steps"], notes["sdc"]["rule"]) == (layout, steps, rule), relative
        assert notes["heading_unit"] == ("radians" if layout == "gpudrive-metadata" else "degrees"), relative


def test_sdc_is_the_named_or_last_track_and_matches_the_raw_log(converted):
    for relative, (raw, items) in converted.items():
        scenario = items[0]
        index = raw.get("metadata", {}).get("sdc_track_index", len(raw["objects"]) - 1)
        obj = raw["objects"][index]
        assert scenario.is_sdc[0] and scenario.metadata[MANIFEST_NOTES]["sdc"]["object_index"] == index
        if "id" in obj:
            assert scenario.object_id[0] == obj["id"]
        steps = len(obj["valid"])
        np.testing.assert_array_equal(scenario.valid[0, :steps], obj["valid"])
        assert not scenario.valid[0, steps:].any()
        x = np.array([p["x"] for p in obj["position"]])
        np.testing.assert_allclose(scenario.x[0, :steps], x, atol=2e-3, rtol=0)
        heading = np.array(obj["heading"], float)
        yaw = np.deg2rad(heading) if EXPECTED[relative][0] != "gpudrive-metadata" else heading
        np.testing.assert_allclose(np.cos(scenario.bbox_yaw[0, :steps] - yaw), 1.0, atol=1e-5)
        assert scenario.length[0, 10] == pytest.approx(obj["length"], abs=1e-5)


def test_objects_and_types(converted):
    for relative, (raw, items) in converted.items():
        scenario = items[0]
        assert scenario.num_objects == min(len(raw["objects"]), 128), relative
        expected = {"vehicle": 1, "pedestrian": 2, "cyclist": 3}
        if len(raw["objects"]) <= 128 and "id" in raw["objects"][0]:
            by_id = {o["id"]: expected.get(o["type"], 4) for o in raw["objects"]}
            assert dict(zip(scenario.object_id.tolist(), scenario.object_type.tolist())) == by_id, relative


def test_roads_keep_their_ids_and_types(converted):
    for relative, (raw, items) in converted.items():
        if "id" not in raw["roads"][0]:
            continue
        scenario = items[0]
        got = dict(zip(scenario.roadgraph_id.tolist(), scenario.roadgraph_type.tolist()))
        expected = {road["id"]: GPUDRIVE_TYPES[(road["type"], road["map_element_id"])] for road in raw["roads"]}
        assert got == expected, relative  # default budget 30000 points: every road is kept


def test_traffic_lights_of_the_3d_file(converted):
    raw, items = converted["gpudrive/tfrecord-00000-of-00150_2d84b1ab55ab81d3.json"]
    scenario = items[0]
    codes = {"unknown": 0, "arrow_stop": 1, "arrow_caution": 2, "arrow_go": 3, "stop": 4, "caution": 5, "go": 6}
    assert scenario.tl_state.shape[0] == len(raw["tl_states"]) == 16
    for row, lane in enumerate(scenario.tl_lane_id.max(axis=1)):
        light = raw["tl_states"][str(lane)]
        steps = np.array(light["time_index"])
        assert scenario.tl_valid[row].sum() == len(steps)
        np.testing.assert_array_equal(scenario.tl_state[row, steps], [codes[s] for s in light["state"]])
        np.testing.assert_allclose(scenario.tl_x[row, steps], light["x"], atol=2e-3)


def _signed_edge_distances(scenario: Scenario, corners: np.ndarray) -> np.ndarray:
    """Distance of each point (k, 2) to its nearest road-edge segment, negative on the segment's left."""
    edge = np.isin(scenario.roadgraph_type, (15, 16)) & scenario.roadgraph_valid
    xyz, ids = scenario.roadgraph_xyz[edge, :2].astype(np.float64), scenario.roadgraph_id[edge]
    same = ids[1:] == ids[:-1]
    start, end = xyz[:-1][same], xyz[1:][same]  # (s, 2) segments within one polyline
    seg = end - start
    rel = corners[:, None, :] - start[None]  # (k, s, 2)
    t = np.clip((rel * seg).sum(-1) / np.maximum((seg ** 2).sum(-1), 1e-12), 0.0, 1.0)
    dist = np.linalg.norm(rel - t[..., None] * seg, axis=-1)
    nearest = dist.argmin(axis=1)
    pick = np.arange(len(corners))
    cross = seg[nearest, 0] * rel[pick, nearest, 1] - seg[nearest, 1] * rel[pick, nearest, 0]
    return np.where(cross > 0, -1.0, 1.0) * dist[pick, nearest]


def test_logged_sdc_stays_on_the_road(converted):
    """The converted roadgraph (before enrichment) keeps every corner of the logged SDC box on the road side
    of its nearest road edge: road-edge orientation and heading units are right."""
    for relative, (_, items) in converted.items():
        s = items[0]
        steps = np.flatnonzero(s.valid[0])
        c, si = np.cos(s.bbox_yaw[0, steps]), np.sin(s.bbox_yaw[0, steps])
        half_l, half_w = s.length[0, steps] / 2, s.width[0, steps] / 2
        corners = np.concatenate([np.stack([s.x[0, steps] + a * half_l * c - b * half_w * si,
                                            s.y[0, steps] + a * half_l * si + b * half_w * c], axis=-1)
                                  for a in (-1, 1) for b in (-1, 1)]).astype(np.float64)
        assert _signed_edge_distances(s, corners).max() < 0.0, relative


def test_pipeline_with_enrichment_writes_valid_shards(tmp_path):
    folder = realdata_file("gpudrive")
    transform, transform_settings = make_transform()
    settings = ConvertSettings(out=tmp_path / "out", workers=1, progress=False, transform=transform,
                               transform_settings=transform_settings)
    result = convert(GpuDriveSource(str(folder)), settings)
    assert result.ok and result.num_scenarios == 10, result.failures
    assert validate_shards(tmp_path / "out").bad == ()
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert len(manifest["notes"]) == 10
    assert all("sdc" in entry["notes"] and "layout" in entry["notes"] for entry in manifest["notes"])


@pytest.mark.parametrize("relative", ["gpudrive/tfrecord-00000-of-00150_78.json",
                                      "gpudrive/tfrecord-00149-of-00150_111.json",
                                      "gpudrive/tfrecord-00043-of-00150_223.json"])
def test_files_without_never_valid_vehicles_keep_their_sdc(tmp_path, relative):
    """GPUDrive's writer since v0.4.0 leaves out the vehicles and cyclists that are never valid and keeps WOMD's
    indices in its metadata: these real files, so written, still convert with the same SDC and no misplaced
    tracks_to_predict."""
    raw = json.loads(realdata_file(relative).read_text())
    sdc_id = raw["objects"][raw["metadata"]["sdc_track_index"]]["id"]
    kept = [o for o in raw["objects"] if o["type"] not in ("vehicle", "cyclist") or any(o["valid"])]
    assert len(kept) < len(raw["objects"])
    path = tmp_path / "dropped.json"
    path.write_text(json.dumps(dict(raw, objects=kept)))
    items = list(GpuDriveSource(str(path)).read_unit(str(path)))
    assert len(items) == 1 and isinstance(items[0], Scenario), items
    scenario = items[0]
    assert scenario.is_sdc[0] and scenario.object_id[0] == sdc_id
    assert "track_indices_ignored" in scenario.metadata[MANIFEST_NOTES]
    assert not scenario.tracks_to_predict.any()

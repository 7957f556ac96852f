"""Waymo's own SDC paths (Scenario.sdc_paths, WOMD 1.3.1+): decoded, resampled to our layout, kept by enrichment.

The fixture's paths are encoded on the wire by hand (tag, length, packed arrays), independently of the
descriptors in scenariomax/sources/womd/proto.py, and appended to a Scenario built by fixtures.py:
appending a field to a serialised message is how protobuf concatenation works.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from scenariomax.enrich import EnrichSettings, enrich_scenario
from scenariomax.enrich.paths import PATHS_SOURCE
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes
from scenariomax.sources.base import MANIFEST_NOTES, Failure
from scenariomax.sources.womd import WomdSource
from scenariomax.sources.womd.convert import parse_scenario
from scenariomax.sources.womd.proto import SDC_PATHS_FIELD, ScenarioProto
from scenariomax.sources.womd.sdc_paths import decode_sdc_paths, waymo_path_arrays
from tests.sources.womd.fixtures import LANE_ID, NEXT_LANE_ID, build_scenario, write_records

SIZES = Sizes(num_paths=4, num_points_per_path=50)


def _varint(value: int) -> bytes:
    value &= (1 << 64) - 1  # negative int64 values take ten bytes, as protobuf writes them
    out = bytearray()
    while True:
        byte, value = value & 0x7F, value >> 7
        out.append(byte | (0x80 if value else 0))
        if not value:
            return bytes(out)


def _field(number: int, wire_type: int, payload: bytes) -> bytes:
    if wire_type == 2:
        payload = _varint(len(payload)) + payload
    return _varint(number << 3 | wire_type) + payload


def encode_sdc_path(xyz, ids=None, valid=None, on_route=False, arc_length=None) -> bytes:
    """One SDCPath: x=1, y=2, z=3, arc_length=4 (packed doubles), ids=5 (packed int64), valid=6 (packed
    bools), on_route=7 (bool)."""
    xyz = np.asarray(xyz, np.float64)
    doubles = lambda values: struct.pack(f"<{len(values)}d", *values)  # noqa: E731
    out = b"".join(_field(k + 1, 2, doubles(xyz[:, k])) for k in range(3))
    if arc_length is not None:
        out += _field(4, 2, doubles(arc_length))
    if ids is not None:
        out += _field(5, 2, b"".join(_varint(int(i)) for i in ids))
    if valid is not None:
        out += _field(6, 2, b"".join(_varint(int(v)) for v in valid))
    return out + _field(7, 0, _varint(int(on_route)))


def east_scenario(**kwargs) -> bytes:
    """fixtures.build_scenario with the SDC heading east as it drives (the fixture stores 3.5 rad, which leaves
    our reconstruction no aligned lane)."""
    message = ScenarioProto.FromString(build_scenario(**kwargs))
    for state in message.tracks[message.sdc_track_index].states:
        state.heading = 0.0
    return message.SerializeToString()


def scenario_with_paths(paths: list[bytes], **kwargs) -> bytes:
    return east_scenario(**kwargs) + b"".join(_field(SDC_PATHS_FIELD, 2, p) for p in paths)


def straight_path(x0=10.0, x1=90.0, step=2.5):
    """The SDC's route along y = 0 (as fixtures.py drives it), points every `step` m, lane ids by x."""
    x = np.arange(x0, x1 + 1e-9, step)
    return np.stack([x, np.zeros_like(x), np.full_like(x, 1.0)], 1), np.where(x < 40, LANE_ID, NEXT_LANE_ID)


def turn_path():
    """An off-route path: east to x = 20, then north."""
    xyz = [(10.0 + k, 0.0, 1.0) for k in range(11)] + [(20.0, float(k), 1.0) for k in range(1, 21)]
    return np.array(xyz)


def convert(path, **kwargs) -> list:
    source = WomdSource(str(path), sizes=SIZES, **kwargs)
    return [item for unit in source.list_units() for item in source.read_unit(unit)]


@pytest.fixture
def record():
    xyz, ids = straight_path()
    return scenario_with_paths([encode_sdc_path(turn_path(), on_route=False),
                                encode_sdc_path(xyz, ids=ids, on_route=True, arc_length=np.arange(len(xyz)) * 2.5)])


def test_decode_reads_the_wire_layout(record):
    paths = decode_sdc_paths(parse_scenario(record))
    assert [p.on_route for p in paths] == [False, True]
    xyz, ids = straight_path()
    np.testing.assert_allclose(paths[1].xyz, xyz)
    assert paths[1].lane_id.tolist() == ids.tolist() and (paths[0].lane_id == -1).all()


def test_resampled_to_our_layout_on_route_first(record):
    arrays = waymo_path_arrays(decode_sdc_paths(parse_scenario(record)), num_paths=4, points_per_path=50)
    assert arrays["path_xyz"].shape == (4, 50, 3)
    assert arrays["path_on_route"].tolist() == [True, False, False, False]
    assert arrays["path_valid"].sum(1).tolist() == [50, 31, 0, 0]  # 80 m cut to 50 points; 30 m -> 31 points
    np.testing.assert_allclose(arrays["path_xyz"][0, :50, 0], 10.0 + np.arange(50), atol=1e-5)  # 1 m apart
    np.testing.assert_allclose(arrays["path_arc_length"][0, :50], np.arange(50))
    assert arrays["path_lane_id"][0, 29] == LANE_ID and arrays["path_lane_id"][0, 30] == NEXT_LANE_ID
    np.testing.assert_allclose(arrays["path_xyz"][1, 30], [20.0, 20.0, 1.0], atol=1e-5)  # the turn's end


def test_invalid_points_dropped_and_short_paths_skipped():
    xyz, _ = straight_path(step=1.0)
    valid = np.ones(len(xyz), bool)
    valid[5:] = False
    message = parse_scenario(scenario_with_paths([encode_sdc_path(xyz, valid=valid, on_route=True),
                                                  encode_sdc_path(xyz[:1], on_route=False)]))
    (path,) = decode_sdc_paths(message)
    np.testing.assert_allclose(path.xyz, xyz[:5])


def test_auto_uses_waymo_paths_and_enrichment_keeps_them(tmp_path, record):
    (scenario,) = convert(write_records(tmp_path / "a.tfrecord", [record]))
    assert isinstance(scenario, Scenario)
    assert scenario.metadata[PATHS_SOURCE] == "waymo"
    assert scenario.metadata[MANIFEST_NOTES] == {PATHS_SOURCE: "waymo"}
    enriched = enrich_scenario(scenario, EnrichSettings(num_paths=4, points_per_path=50))
    np.testing.assert_array_equal(enriched.path_xyz, scenario.path_xyz)
    assert enriched.path_on_route.tolist() == [True, False, False, False]
    assert enriched.is_controllable is not None  # the other enrichments still run


def test_reconstruct_ignores_waymo_paths(tmp_path, record):
    (scenario,) = convert(write_records(tmp_path / "a.tfrecord", [record]), sdc_paths="reconstruct")
    assert PATHS_SOURCE not in scenario.metadata
    enriched = enrich_scenario(scenario, EnrichSettings(num_paths=4, points_per_path=50))
    np.testing.assert_allclose(enriched.path_xyz[0, 0, :2], [10.0, 0.0], atol=1e-5)  # from the SDC's position
    assert np.abs(enriched.path_xyz[..., 1][enriched.path_valid]).max() < 1.0  # along y = 0: not Waymo's turn


def test_waymo_mode_without_paths_is_a_one_line_failure(tmp_path):
    (failure,) = convert(write_records(tmp_path / "a.tfrecord", [east_scenario()]), sdc_paths="waymo")
    assert isinstance(failure, Failure)
    assert "no Waymo SDC paths" in failure.reason and "\n" not in failure.reason
    (scenario,) = convert(write_records(tmp_path / "b.tfrecord", [east_scenario()]))  # auto: reconstructed
    assert isinstance(scenario, Scenario) and PATHS_SOURCE not in scenario.metadata


def test_mismatched_arrays_are_a_failure_naming_the_path(tmp_path):
    broken = _field(1, 2, struct.pack("<3d", 0, 1, 2)) + _field(2, 2, struct.pack("<2d", 0, 0))
    (failure,) = convert(write_records(tmp_path / "a.tfrecord", [scenario_with_paths([broken])]))
    assert isinstance(failure, Failure) and "sdc path 0: y has 2 values, x has 3" in failure.reason


def test_waymo_paths_go_to_the_log_current_window_only(tmp_path):
    xyz, ids = straight_path()
    long_log = scenario_with_paths([encode_sdc_path(xyz, ids=ids, on_route=True)], num_steps=171)
    first, second = convert(write_records(tmp_path / "a.tfrecord", [long_log]))
    assert first.metadata.get(PATHS_SOURCE) == "waymo" and PATHS_SOURCE not in second.metadata
    failures = convert(write_records(tmp_path / "b.tfrecord", [long_log]), sdc_paths="waymo")
    assert isinstance(failures[0], Scenario) and isinstance(failures[1], Failure)


def test_manifest_names_the_paths_source(tmp_path, record):
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings
    from scenariomax.pipeline import convert as run

    transform, settings = make_transform(num_paths=4, points_per_path=50)
    source = WomdSource(str(write_records(tmp_path / "a.tfrecord", [record])), sizes=SIZES)
    result = run(source, ConvertSettings(out=tmp_path / "out", workers=1, progress=False, sizes=SIZES,
                                         transform=transform, transform_settings=settings))
    assert result.num_scenarios == 1 and result.ok
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert [n["notes"] for n in manifest["notes"]] == [{PATHS_SOURCE: "waymo"}]
    assert "auto" in json.dumps(manifest)  # the conversion's --sdc-paths setting

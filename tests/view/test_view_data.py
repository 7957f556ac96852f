"""The viewer's data side (no browser): packed scenes, the fast shard index, the page file and the CLI's errors."""

from __future__ import annotations

import base64
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import scenariomax
from scenariomax.io.tfrecord import frame_record
from scenariomax.view import ShardIndex, pack_scene, render_page, scene_from_scenario, unpack_scene, write_view
from scenariomax.view.scene import roadgraph_polylines
from tests.conftest import realdata_file, straight_road_scenario
from tests.integration_sim.conftest import SMALL_SIZES, braking_scenario, cruising_scenario
from vmax_cli.scenariomax_cli import main

MAX_SINGLE_SCENARIO_HTML = 2_000_000


@pytest.fixture(scope="module")
def shards(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("view_shards")
    scenariomax.write_shards([cruising_scenario("cruise"), braking_scenario("brake"), straight_road_scenario("toy")],
                             out, sizes=SMALL_SIZES, shard_size=2)  # two files
    return out


def embedded_scenes(page: str) -> dict[int, tuple[dict, dict]]:
    found = re.findall(r'<script type="application/octet-stream" id="scene-(\d+)">([^<]*)</script>', page)
    return {int(i): unpack_scene(base64.b64decode(text)) for i, text in found}


def test_a_packed_scene_keeps_positions_to_half_a_centimetre_and_headings_to_1e4_rad():
    s = braking_scenario("brake")
    meta, arrays = unpack_scene(pack_scene(*scene_from_scenario(s)))
    assert meta["id"] == "brake" and meta["scale"] == 0.01 and meta["num_objects"] == 2 and meta["sdc"] == 0
    x = arrays["obj_x"].reshape(2, -1) * meta["scale"] + meta["origin"][0]
    assert np.max(np.abs(x - s.x)) <= 0.005 + 1e-6
    assert np.allclose(arrays["obj_yaw"] * meta["yaw_units"], 0.0) and np.all(arrays["obj_valid"] == 1)
    assert np.allclose(arrays["obj_len"] * meta["size_units"], 4.5) and arrays["obj_speed"][0] == 1000  # cm/s
    assert meta["path_on_route"] == [True] and arrays["path_start"].tolist() == [0, 300]
    assert arrays["tl_state"].reshape(1, -1)[0, 0] == 6 and meta["num_lights"] == 1


def test_a_large_map_gets_a_coarser_scale_and_still_fits_int16():
    s = straight_road_scenario("wide")
    far = s.roadgraph_xyz.copy()
    far[0, 0] = -2000.0  # a point 2 km away
    meta, arrays = unpack_scene(pack_scene(*scene_from_scenario(s.replace(roadgraph_xyz=far))))
    assert 0.01 < meta["scale"] < 0.2
    rg_x = arrays["rg_x"] * meta["scale"] + meta["origin"][0]
    valid_x = far[s.roadgraph_valid, 0]
    assert np.max(np.abs(rg_x - valid_x)) <= meta["scale"] / 2 + 1e-6


def test_roadgraph_runs_split_at_feature_changes_and_gaps_but_keep_polygons_whole():
    xy = np.array([[0, 0], [1, 0], [2, 0], [20, 0], [21, 0], [0, 5], [10, 5], [10, 15]], float)
    types = np.array([2, 2, 2, 2, 2, 18, 18, 18])
    ids = np.array([1, 1, 1, 1, 1, 7, 7, 7])
    starts, run_types = roadgraph_polylines(xy, types, ids)
    assert starts.tolist() == [0, 3, 5, 8] and run_types.tolist() == [2, 2, 18]  # the 18 m gap splits the lane


def test_the_index_skims_the_ids_of_every_record_without_decoding(shards):
    index = ShardIndex.build(shards)
    assert len(index.files) == 2 and [e.scenario_id for e in index.entries] == ["cruise", "brake", "toy"]
    assert index.find("toy") == 2 and index.check(1).scenario.scenario_id == "brake"
    with pytest.raises(scenariomax.errors.InputError, match="no scenario with id 'nope'"):
        index.find("nope")


def test_the_index_reads_a_real_womd_tf_example():
    path = realdata_file("womd/motion_data_one_example.tfrecord")
    index = ShardIndex.build(path)
    assert [e.scenario_id for e in index.entries] == [next(scenariomax.read_shards(path)).scenario_id]


def test_a_corrupted_record_is_listed_with_its_problem_and_a_truncated_file_is_reported(tmp_path):
    good = scenariomax.encode_scenario(braking_scenario("brake"), SMALL_SIZES)
    bad = bytearray(scenariomax.encode_scenario(cruising_scenario("cruise"), SMALL_SIZES))
    bad[len(bad) // 2] ^= 0xFF
    framed_bad = bytearray(frame_record(bytes(good)))
    framed_bad[-10] ^= 0xFF  # payload byte flipped after framing: the CRC no longer matches
    (tmp_path / "a.tfrecord").write_bytes(frame_record(good) + bytes(framed_bad))
    (tmp_path / "b.tfrecord").write_bytes(frame_record(good)[:-7])  # cut short
    index = ShardIndex.build(tmp_path)
    assert len(index) == 2 and index.file_errors == (f"{tmp_path / 'b.tfrecord'}: truncated record at byte 0",)
    assert "CRC mismatch" in index.check(1).problems[0] and index.check(1).scenario is None
    page = write_view(tmp_path, tmp_path / "view.html").out.read_text()
    scenes = embedded_scenes(page)
    assert "error" not in scenes[0][0] and "CRC mismatch" in scenes[1][0]["error"]
    assert "truncated record at byte 0" in page


def test_the_html_is_self_contained_and_caps_the_embedded_scenarios(shards, tmp_path):
    result = write_view(shards, tmp_path / "v.html", max_scenarios=2)
    page = result.out.read_text()
    assert result.num_embedded == 2 and result.num_records == 3 and "2 of 3 scenarios embedded" in result.note
    assert sorted(embedded_scenes(page)) == [0, 1]
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", page), "the page must not load anything"
    assert "fetch(" in page and "__JS__" not in page and "__CONFIG__" not in page
    summary = embedded_scenes(page)[1][0]["summary"]
    assert summary["dataset"] == "test" and summary["objects"] == 2 and summary["problems"] == []


def test_a_single_real_scenario_page_stays_under_2_mb(tmp_path):
    from scenariomax.sources.synthetic.generator import generate_scenario

    full = tmp_path / "full"
    scenariomax.write_shards([generate_scenario(0, 3)], full)  # default budget: 128 objects, 30000 points
    assert (full / "train-00000-of-00001.tfrecord").stat().st_size > 2_000_000
    result = write_view(full, tmp_path / "one.html", scenario_id="synthetic-0-000003")
    assert result.num_embedded == 1 and result.size_bytes < MAX_SINGLE_SCENARIO_HTML
    womd = realdata_file("womd/motion_data_one_example.tfrecord")  # 128 objects, 20000 roadgraph points
    assert write_view(womd, tmp_path / "womd.html").size_bytes < MAX_SINGLE_SCENARIO_HTML


def test_page_assets_come_from_the_package():
    page = render_page({"mode": "embedded", "title": "t</script><b>", "entries": []})
    assert "<title>t&lt;/script&gt;&lt;b&gt;</title>" in page and "function decodeScene" in page
    assert '"title":"t<\\/script><b>"' in page  # the config cannot close its <script>


@pytest.mark.parametrize("args, message", [
    (["/no/such/dir"], "/no/such/dir: no such file, directory or matching glob"),
    (["{empty}"], "no .tfrecord files found"),
    (["{shards}", "--scenario", "nope"], "no scenario with id 'nope'"),
    (["{shards}", "--out", "{shards}"], "is a directory"),
])
def test_bad_input_gives_one_line_and_no_traceback(shards, tmp_path, args, message):
    (tmp_path / "empty").mkdir()
    args = [a.format(shards=shards, empty=tmp_path / "empty") for a in args]
    result = CliRunner().invoke(main, ["view", *args])
    assert result.exit_code != 0 and message in result.output, result.output
    assert "Traceback" not in result.output and isinstance(result.exception, SystemExit)
    assert [line for line in result.output.splitlines() if line.startswith("Error")] == [
        result.output.strip().splitlines()[-1]]  # one error line (click may print its usage hint above it)


def test_cli_writes_view_html_by_default_and_prints_its_path(shards, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["view", str(shards)])
    assert result.exit_code == 0, result.output
    assert result.output.strip().splitlines()[-1] == "view.html" and (tmp_path / "view.html").is_file()
    assert "3 scenario(s)" in result.output

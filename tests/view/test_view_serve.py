"""`scenariomax view --serve`: the small local server (index at start, scenes and summaries on demand), its page in
headless Chromium, its errors, and the 1,000-scenario start-up time (slow)."""

from __future__ import annotations

import contextlib
import json
import socket
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from click.testing import CliRunner

import scenariomax
from scenariomax.io.tfrecord import frame_record
from scenariomax.view import make_server, unpack_scene
from tests.integration_sim.conftest import SMALL_SIZES, braking_scenario, cruising_scenario
from tests.view.browser import colour_mask, needs_browser, rgb, run_chromium, status
from vmax_cli.scenariomax_cli import main

OPEN_BUDGET_S = 3.0  # index + first page + the first scene, for 1,000 scenarios


@pytest.fixture(scope="module")
def shards(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("serve_shards")
    scenariomax.write_shards([cruising_scenario("cruise"), braking_scenario("brake")], out, sizes=SMALL_SIZES)
    return out


@contextlib.contextmanager
def serving(path, **kwargs):
    server, viewer = make_server(path, port=0, **kwargs)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/", viewer
    finally:
        server.shutdown()
        viewer.stop.set()
        server.server_close()


def get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=30) as response:
        return response.read()


def test_the_api_lists_records_then_summaries_and_packs_scenes_on_demand(shards):
    with serving(shards) as (url, viewer):
        index = json.loads(get(url + "api/index"))
        assert [e["id"] for e in index["entries"]] == ["cruise", "brake"] and index["file_errors"] == []
        viewer.worker.join(timeout=30)
        summaries = json.loads(get(url + "api/summaries?since=0"))
        assert summaries["done"] == summaries["total"] == 2
        assert summaries["summaries"]["1"]["objects"] == 2 and summaries["summaries"]["1"]["problems"] == []
        assert json.loads(get(url + "api/summaries?since=2"))["summaries"] == {}
        meta, arrays = unpack_scene(get(url + "api/scene/1"))
        assert meta["id"] == "brake" and meta["summary"]["dataset"] == "test" and arrays["obj_x"].size == 2 * 91
        assert b"function decodeScene" in get(url) and b'"mode":"serve"' in get(url)
        for bad, code in (("api/scene/7", 404), ("api/scene/x", 400), ("nothing", 404)):
            with pytest.raises(urllib.error.HTTPError) as error:
                get(url + bad)
            assert error.value.code == code


def test_a_taken_port_is_a_one_line_error(shards):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = CliRunner().invoke(main, ["view", str(shards), "--serve", "--port", str(port)])
    assert result.exit_code == 1 and f"port {port} on 127.0.0.1 is in use" in result.output, result.output
    assert "Traceback" not in result.output


@needs_browser
def test_the_served_page_loads_the_index_then_the_scene_it_shows(shards, tmp_path):
    with serving(shards) as (url, viewer):
        dom, console = run_chromium(url + "?scenario=cruise&frame=30")
        state = status(dom)
        assert console == [] and state["ready"] == "1" and state["errors"] == "", (console, state)
        assert state["entries"] == "2" and state["scenario"] == "cruise" and state["drawn"] == "3"
        png = tmp_path / "served.png"  # kept as the test's artifact
        _, console = run_chromium(url + "?scenario=cruise&frame=30", screenshot=png)
        image = rgb(png)
        assert console == [] and colour_mask(image, "#e6007e").sum() > 100 and colour_mask(image, "#2a6fdb").sum() > 100
        dom, console = run_chromium(url + "?scenario=nope")  # an unknown id in the URL: a message, no crash
        assert console == [] and "no scenario with id nope" in dom
        assert sorted(viewer.cache) == [0]  # only the scene that was viewed was read and packed


@pytest.mark.slow  # writes 1,000 full-size records (2.6 GB)
def test_a_thousand_scenario_dataset_opens_in_under_3_s(tmp_path):
    from scenariomax.sources.synthetic.generator import generate_scenario

    record = scenariomax.encode_scenario(generate_scenario(0, 0))  # default budget: 30000 points, 128 objects
    old_id = b"synthetic-0-000000"
    assert record.count(old_id) == 1
    out = tmp_path / "thousand"
    out.mkdir()
    with open(out / "train-00000-of-00001.tfrecord", "wb") as stream:
        for i in range(1000):  # same-length ids: the bytes stay a valid tf.Example
            stream.write(frame_record(record.replace(old_id, f"synthetic-0-{i:06d}".encode())))
    start = time.perf_counter()
    with serving(out) as (url, viewer):
        get(url)
        entries = json.loads(get(url + "api/index"))["entries"]
        meta, _ = unpack_scene(get(url + "api/scene/0"))
        elapsed = time.perf_counter() - start
    assert len(entries) == 1000 and entries[999]["id"] == "synthetic-0-000999" and meta["id"] == "synthetic-0-000000"
    print(f"1,000 scenarios: index + page + first scene in {elapsed:.2f} s")
    assert elapsed < OPEN_BUDGET_S

"""`vmax-sim bench`: the large-batch rows, the memory-per-scene column and `--compare-waymax`.

Waymax is never installed here: the comparison is tested with fake interpreters that speak the timing
script's JSON protocol, with the project's own interpreter (which has no Waymax), and, when the variable
VMAX_WAYMAX_PYTHON names an interpreter with Waymax installed, against the real Waymax.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from vmax_cli.vmax_cli import main
from vmax_sim import bench
from vmax_sim.bench import format_table, run_bench


def _stub_row(batch: int, num_objects: int, roadgraph: int, config: str, steps: int) -> dict:
    speed = {"env": 100_000, "env+metrics+obs": 40_000}.get(config, 50_000)
    return {"env": "real", "config": config, "batch": batch, "roadgraph": roadgraph, "compile_s": 0.1,
            "scene_steps_per_s": speed, "median_scene_steps_per_s": speed, "runs": 5, "bytes_per_scene": 1_000_000}


def _fake_interpreter(tmp_path: Path, body: str) -> Path:
    """An executable that stands in for a Waymax venv's python: it runs `body` with argv as the bench calls it
    (argv[1] the timing script, argv[2] the scenes .npz, argv[3] the request JSON)."""
    path = tmp_path / "fake-python"
    path.write_text(f"#!{sys.executable}\nimport json, sys\n{body}\n")
    path.chmod(0o755)
    return path


# A fake Waymax that checks what it was sent and answers 200,000 median scene-steps/s at every batch.
FAKE_WAYMAX = """
import numpy as np
scenes = np.load(sys.argv[2])
request = json.loads(sys.argv[3])
assert scenes["0/obj_xy"].shape == (request["num_objects"], 91, 2), scenes["0/obj_xy"].shape
with open(sys.argv[2] + ".request.json", "w") as out:
    json.dump({"request": request, "num_scenes": len({key.split("/")[0] for key in scenes.files}),
               "roadgraph": scenes["0/xyz"].shape[0]}, out)
rows = [{"batch": run["batch"], "compile_s": 0.5, "runs": run["repeats"], "best_scene_steps_per_s": 210000,
         "median_scene_steps_per_s": 200000, "bytes_per_scene": 1500000} for run in request["runs"]]
print("some library's banner on stdout")
print(json.dumps({"waymax": "0.1.0", "jax": "0.0-fake", "device": "cpu:cpu", "rows": rows, "skipped": []}))
"""


@pytest.mark.slow  # 8-9 s on 2 cores: the default suite stays under 10 minutes
def test_rows_report_median_and_memory_per_scene(monkeypatch):
    monkeypatch.setattr(bench, "_device_peak_bytes", lambda: 123_000_000)  # what an accelerator's allocator reports
    results = run_bench(batch_sizes=(2,), num_objects=16, roadgraph_sizes=(2000,), steps=2, configs=("env",))
    row = results["configs"][0]
    assert row["bytes_per_scene"] == bench._scene_bytes(16, 2000)  # the whole state of one scene, map index included
    assert 0 < row["map_index_bytes_per_scene"] < row["bytes_per_scene"]
    assert 0 < row["median_scene_steps_per_s"] <= row["scene_steps_per_s"] and row["runs"] >= 5
    assert row["device_peak_bytes"] == 123_000_000
    table = format_table(results)
    assert "MB/scene" in table and "peak MB" in table and f"{row['bytes_per_scene'] / 1e6:.2f}" in table


def test_default_bench_includes_1024_and_4096_with_fewer_runs():
    help_text = CliRunner().invoke(main, ["bench", "--help"]).output
    assert "1,32,256,1024,4096" in help_text and "--compare-waymax" in help_text
    assert bench.DEFAULT_BATCH_SIZES == (1, 32, 256, 1024, 4096)
    assert bench.timing_runs(4096)["repeats"] < bench.timing_runs(32)["repeats"]
    assert bench.timing_runs(1024)["min_seconds"] == 0 and bench.timing_runs(256)["min_seconds"] > 0


def test_a_batch_that_does_not_fit_in_memory_is_skipped_with_a_note(monkeypatch, capsys):
    monkeypatch.setattr(bench, "_timed", _stub_row)
    monkeypatch.setattr(bench, "_available_bytes", lambda: 2_000_000_000)  # 2 GB free
    results = run_bench(batch_sizes=(1, 4096), num_objects=16, roadgraph_sizes=(1000,), steps=2, configs=("env",))
    assert {row["batch"] for row in results["configs"]} == {1}
    assert [skip["batch"] for skip in results["skipped"]] == [4096] and "GB free" in results["skipped"][0]["reason"]
    assert "skipped batch 4096: needs ~" in capsys.readouterr().out


def test_compare_waymax_prints_the_ratios(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(bench, "_timed", _stub_row)
    python = _fake_interpreter(tmp_path, FAKE_WAYMAX)
    results = run_bench(batch_sizes=(2, 32), num_objects=16, roadgraph_sizes=(1000,), steps=4,
                        configs=("env", "env+metrics+obs"), compare_waymax=str(python))
    rows = {row["batch"]: row for row in results["waymax"]["rows"]}
    assert rows[32]["physics_ratio"] == 0.5 and rows[32]["full_over_waymax_physics"] == 0.2  # 100k, 40k vs 200k
    out = capsys.readouterr().out
    assert "ours/Waymax" in out and "0.50x" in out and "0.20x" in out and str(python) in out


def test_compare_waymax_sends_the_bench_configuration(tmp_path, monkeypatch):
    monkeypatch.setattr(bench, "_timed", _stub_row)
    python = _fake_interpreter(tmp_path, FAKE_WAYMAX)
    sent = []
    real_run = bench.subprocess.run

    def run_and_read_request(args, **kwargs):
        done = real_run(args, **kwargs)
        sent.append(json.loads(Path(args[2] + ".request.json").read_text()))
        return done
    monkeypatch.setattr(bench.subprocess, "run", run_and_read_request)
    run_bench(batch_sizes=(2, 1024), num_objects=16, roadgraph_sizes=(1000, 3000), steps=80, configs=("env",),
              compare_waymax=str(python))
    request = sent[0]["request"]
    assert request["steps"] == 80 and request["num_objects"] == 16 and request["init_steps"] == bench.HISTORY
    assert [run["batch"] for run in request["runs"]] == [2, 1024] and request["runs"][1]["repeats"] == 3
    assert sent[0]["roadgraph"] == 3000 and sent[0]["num_scenes"] == 4  # the largest roadgraph, 4 distinct scenes


@pytest.mark.parametrize("make_python, expected", [
    (lambda tmp: tmp / "no-such-venv" / "bin" / "python", "no such file"),
    (lambda tmp: tmp, "not an executable file"),
    (lambda tmp: _fake_interpreter(tmp, "sys.stderr.write('Traceback\\nRuntimeError: boom\\n'); sys.exit(1)"),
     "the Waymax timing script failed: RuntimeError: boom"),
    (lambda tmp: _fake_interpreter(tmp, "print(json.dumps({'error': 'cannot import waymax: no module'})); "
                                        "sys.exit(2)"), "cannot import waymax"),
])
def test_compare_waymax_errors_are_one_line_before_any_timing(tmp_path, monkeypatch, make_python, expected):
    monkeypatch.setattr(bench, "_timed", lambda *args: pytest.fail("timed our step before checking Waymax"))
    python = make_python(tmp_path)
    result = CliRunner().invoke(main, ["bench", "--batch-sizes", "2", "--compare-waymax", str(python)])
    assert result.exit_code == 2
    lines = [line for line in result.output.splitlines() if not line.startswith("timing Waymax")]
    assert len(lines) == 1 and expected in lines[0] and lines[0].count(str(python)) == 1


@pytest.mark.skipif(importlib.util.find_spec("waymax") is not None, reason="this environment has a waymax module")
def test_an_interpreter_without_waymax_gets_one_line(monkeypatch):
    """The real timing script, run by this project's interpreter (no Waymax in it)."""
    monkeypatch.setattr(bench, "_timed", lambda *args: pytest.fail("timed our step before checking Waymax"))
    result = CliRunner().invoke(main, ["bench", "--batch-sizes", "1", "--compare-waymax", sys.executable])
    assert result.exit_code == 2
    message = result.output.strip().splitlines()[-1]
    assert "cannot import waymax" in message and "github.com/waymo-research/waymax" in message


@pytest.mark.skipif(not os.environ.get("VMAX_WAYMAX_PYTHON"),
                    reason="set VMAX_WAYMAX_PYTHON to a Python interpreter with Waymax installed")
def test_real_waymax_times_the_same_scenes():
    waymax = bench.time_waymax(os.environ["VMAX_WAYMAX_PYTHON"], (2,), num_objects=16, num_roadgraph=2000, steps=5)
    assert waymax["rows"][0]["batch"] == 2 and waymax["rows"][0]["median_scene_steps_per_s"] > 0
    assert waymax["rows"][0]["bytes_per_scene"] > 0 and waymax["waymax"]


def test_roadgraph_scaling_reuses_the_full_step_already_timed(monkeypatch):
    calls = []
    monkeypatch.setattr(bench, "_timed", lambda *args: calls.append(args) or _stub_row(*args))
    results = run_bench(batch_sizes=(32,), num_objects=16, roadgraph_sizes=(1000, 2000), steps=2,
                        configs=("env+metrics+obs",))
    assert [(args[0], args[2]) for args in calls] == [(32, 2000), (32, 1000)]  # batch, roadgraph: no third run
    assert [row["roadgraph"] for row in results["roadgraph_scaling"]] == [1000, 2000]


def test_the_table_prints_each_timed_row_once_and_explains_its_columns(monkeypatch, capsys):
    monkeypatch.setattr(bench, "_timed", _stub_row)
    run_bench(batch_sizes=(32,), num_objects=16, roadgraph_sizes=(1000, 2000), steps=2, configs=("env+metrics+obs",))
    table = capsys.readouterr().out
    rows = [line for line in table.splitlines() if line.startswith("real")]
    assert len(rows) == len(set(rows)) == 2  # the full step at 2000 points is the scaling row for 2000 as well
    legend = table.split(rows[-1], 1)[1]
    for said in ("scene-steps/s: scenes x steps simulated per second", "median", "config: env =", "compile s:",
                 "MB/scene:"):
        assert said in legend

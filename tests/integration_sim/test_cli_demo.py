"""The `vmax-sim` CLI (evaluate, bench, demo) and `run_demo`."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from vmax_cli.vmax_cli import main
from vmax_sim.demo import run_demo


def test_evaluate_command_prints_the_summary_and_writes_json(road_shards, tmp_path):
    out = tmp_path / "results.json"
    result = CliRunner().invoke(main, ["evaluate", "--policy", "expert", "--data", str(road_shards), "--num-objects",
                                       "8", "--batch-size", "2", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "vmax_score" in result.output and "episodes: 3" in result.output
    summary = json.loads(out.read_text())
    assert summary["accuracy"] == 1.0 and summary["num_episodes"] == 3


def test_evaluate_command_gives_one_line_errors(tmp_path):
    result = CliRunner().invoke(main, ["evaluate", "--policy", "expert", "--data", str(tmp_path / "nope")])
    assert result.exit_code == 2
    assert result.output.startswith("error: ") and len(result.output.strip().splitlines()) == 1
    assert "Traceback" not in result.output
    result = CliRunner().invoke(main, ["evaluate", "--policy", "expert", "--data", str(tmp_path),
                                       "--mode", "sideways"])
    assert result.exit_code == 2 and "unknown evaluation mode 'sideways'" in result.output


def test_bench_rejects_bad_batch_sizes():
    result = CliRunner().invoke(main, ["bench", "--batch-sizes", "1,x"])
    assert result.exit_code == 2 and "comma-separated integers" in result.output


@pytest.mark.slow
def test_run_demo_trains_evaluates_and_draws(tmp_path):
    lines = []
    tiny = ["network.mlp_hidden=32", "network.embed_dim=16", "network.output_dim=32", "algo.num_envs=4",
            "algo.updates_per_step=2", "algo.policy_hidden_sizes=32", "train.chunk_steps=10", "train.pool_size=4"]
    summary = run_demo(tmp_path / "demo", num_scenarios=4, num_eval_scenarios=4, workers=1, train_steps=80,
                       print_fn=lines.append, progress=False, overrides=tiny)
    out = tmp_path / "demo"
    assert (out / "scenario.png").stat().st_size > 1000 and (out / "rollout.png").stat().st_size > 10_000
    assert (out / "run" / "learning_curve.png").stat().st_size > 10_000
    assert list((out / "shards").glob("*.tfrecord")) and (out / "eval_shards" / "manifest.json").exists()
    written = json.loads((out / "summary.json").read_text())
    assert written == json.loads(json.dumps(summary))
    assert set(written) >= {"shards", "scenario_png", "conversion", "inspect", "evaluation", "training"}
    assert set(written["evaluation"]) == {"expert", "constant", "trained BC"}
    for policy_summary in written["evaluation"].values():
        assert {"accuracy", "accuracy_at_fault", "nuplan_score", "vmax_score", "metrics"} <= set(policy_summary)
        assert policy_summary["num_episodes"] == 4
    assert written["evaluation"]["expert"]["accuracy"] == 1.0
    assert written["training"]["env_steps"] == 80
    table = (out / "comparison.md").read_text()
    # evaluate's table under a title and a line saying what was trained on what
    assert table.startswith("# V-Max demo: held-out evaluation") and "4 held-out synthetic scenarios" in table
    assert "| Metric (%) | expert | constant | trained BC |" in table and "| Accuracy | 100.00 |" in table
    assert any(line.startswith("[3/5] training") for line in lines)

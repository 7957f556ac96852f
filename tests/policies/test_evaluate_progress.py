"""`vmax-sim evaluate` shows the scenarios done of the total on stderr; --json's stdout stays pure JSON."""

from __future__ import annotations

import json

from click.testing import CliRunner

from vmax_cli.vmax_cli import main
from vmax_sim.evaluation.report import expected_num_scenarios

ARGS = ["evaluate", "--policy", "expert", "--num-objects", "8", "--batch-size", "2"]


def test_json_stdout_stays_parseable_with_progress_on_stderr(policy_shards):
    result = CliRunner().invoke(main, ARGS + ["--data", str(policy_shards), "--json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["num_episodes"] == 4
    # stderr is not a terminal here: plain lines, with the total, no carriage-return frames
    assert "evaluating expert: 4/4 scenarios (100%)" in result.stderr
    assert "\r" not in result.stderr


def test_quiet_evaluation_prints_no_progress(policy_shards):
    result = CliRunner().invoke(main, ARGS + ["--data", str(policy_shards), "--num-scenarios", "3", "--quiet"])
    assert result.exit_code == 0, result.output
    assert "scenarios" not in result.stderr and "episodes: 3" in result.stdout


def test_the_total_counts_records_and_respects_num_scenarios(policy_shards, tmp_path):
    assert expected_num_scenarios(str(policy_shards)) == 4
    assert expected_num_scenarios(str(policy_shards), num_scenarios=3) == 3
    assert expected_num_scenarios(str(policy_shards), num_scenarios=10) == 4
    (tmp_path / "x.tfrecord").write_text("not records")
    assert expected_num_scenarios(str(tmp_path), num_scenarios=5) == 5  # unknown: the reader reports the file
    assert expected_num_scenarios(None) is None

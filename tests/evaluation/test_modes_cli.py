"""`vmax-sim evaluate --mode ...`: the reactive row, one-line errors, and the comparison table's mode rows."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from tests.evaluation import modes_scenes
from vmax_cli.vmax_cli import main
from vmax_sim.evaluation.evaluate import EvaluationResult
from vmax_sim.evaluation.modes import EvalMode, parse_mode
from vmax_sim.evaluation.report import PolicyRun, comparison_rows

parked_shards = modes_scenes.parked_shards  # the fixture


def _one_line_error(args, fragment):
    result = CliRunner().invoke(main, ["evaluate", "--policy", "expert", "--data", "nowhere"] + args)
    assert result.exit_code == 2, result.output
    assert result.output.startswith("error: ") and len(result.output.strip().splitlines()) == 1
    assert fragment in result.output and "Traceback" not in result.output


def test_bad_modes_and_options_give_one_line_errors():
    _one_line_error(["--mode", "bogus"], "unknown evaluation mode 'bogus'")
    _one_line_error(["--mode", "adversarial", "--perturb-sigma", "1"], "applies to --mode perturbed")
    _one_line_error(["--mode", "reactive", "--agents", "zombie"], "unknown agent driver 'zombie'")
    _one_line_error(["--agents", "pdm"], "apply to --mode reactive")
    _one_line_error(["--mode", "reactive", "--perturb-sigma", "2"], "applies to --mode perturbed")
    _one_line_error(["--agents-free"], "apply to --mode reactive")
    _one_line_error(["--mode", "reactive", "--agents", "same", "--agents-free"], "with the evaluated policy itself")


def test_parse_mode():
    assert parse_mode("reactive", agents="same", max_agents=4) == EvalMode("reactive", agents="same", max_agents=4)
    assert parse_mode("perturbed", perturb_sigma=0.5, seed=3).perturb.sigma == 0.5
    assert parse_mode("perturbed", seed=3).seed == 3
    assert parse_mode("reactive").agent_follow_log  # the agents keep behind their logs unless told otherwise
    assert not parse_mode("reactive", agents="pdm", agents_follow_log=False).agent_follow_log
    with pytest.raises(ValueError, match="inside the EvalMode"):
        parse_mode(EvalMode("reactive"), agents="idm")


def _run(name, summary_metrics):
    summary = {"policy": name, "mode": "x", "num_episodes": 1, "accuracy": 1.0, "accuracy_at_fault": 1.0,
               "nuplan_score": 1.0, "vmax_score": 1.0, "metrics": summary_metrics}
    return PolicyRun(name, EvaluationResult(summary=summary, episodes={}, scenario_ids=("a",)), 1.0, 1)


def test_other_collisions_row_only_in_reactive_tables():
    plain = [label for label, _ in comparison_rows([_run("idm", {"overlap": 0.0})])]
    assert "Other collisions (non-SDC)" not in plain
    rows = dict(comparison_rows([_run("idm", {"other_collision": 0.015}), _run("pdm", {"other_collision": 0.0})]))
    assert rows["Other collisions (non-SDC)"] == pytest.approx([1.5, 0.0])


def test_cli_reactive_prints_the_other_collisions_row(parked_shards):
    args = ["evaluate", "--policy", "constant", "--data", str(parked_shards), "--num-objects", "8", "--batch-size",
            "2", "--mode", "reactive", "--agents", "same", "--quiet"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "mode: reactive" in result.output and "agents=same" in result.output
    row = next(line for line in result.output.splitlines() if "other_collisions (non-SDC)" in line)
    assert float(row.split()[-1]) == 1.0  # the constant-velocity agent drives into the parked car

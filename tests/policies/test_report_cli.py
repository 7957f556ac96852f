"""The comparison of several policies: table rows and columns, report files, the CLI."""

from __future__ import annotations

import csv
import json
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

from vmax_cli.vmax_cli import main
from vmax_sim.evaluation.report import TABLE_ROWS, compare_policies, format_markdown, table_csv, write_report


@pytest.fixture(scope="module")
def runs(policy_shards):
    return compare_policies(["expert", "idm"], str(policy_shards), batch_size=2, num_objects=8, progress=False)


@pytest.mark.slow  # with the next test, their runs (~20 s) on 2 cores: kept out of the 10-minute default suite
def test_comparison_table_has_the_benchmark_rows_and_one_column_per_policy(runs):
    assert [run.name for run in runs] == ["expert", "idm"]
    assert runs[0].result.scenario_ids == ("cruise", "brake", "lead", "red")
    lines = format_markdown(runs).splitlines()
    assert lines[0] == "| Metric (%) | expert | idm |"
    labels = [line.split("|")[1].strip() for line in lines[2:2 + len(TABLE_ROWS)]]
    assert labels == [label for label, _ in TABLE_ROWS]
    assert labels[0] == "Accuracy" and labels[-2:] == ["nuPlan score", "V-Max score"]
    # the logged SDC of "red" runs its red light (the expert replays it), IDM stops
    assert "| Accuracy | 75.00 | 100.00 |" in lines and "| Red light | 25.00 | 0.00 |" in lines
    rows = list(csv.reader(table_csv(runs).splitlines()))
    assert rows[0] == ["metric", "expert", "idm"] and len(rows) == 1 + len(TABLE_ROWS) + 2
    assert rows[-2] == ["episodes", "4", "4"]


@pytest.mark.slow  # shares the runs above on 2 cores: kept out of the 10-minute default suite
def test_report_files(runs, tmp_path):
    paths = write_report(tmp_path / "report", runs)
    assert sorted(p.name for p in paths) == ["episodes-expert.csv", "episodes-idm.csv", "table.csv", "table.md"]
    episodes = list(csv.DictReader((tmp_path / "report" / "episodes-idm.csv").open()))
    assert [row["scenario_id"] for row in episodes] == ["cruise", "brake", "lead", "red"]
    assert {"vmax_score", "overlap", "ego_progress", "accurate"} <= set(episodes[0])


def test_unknown_entries_and_missing_data_are_one_line_errors(tmp_path):
    with pytest.raises(ValueError, match="neither one of"):
        compare_policies(["expert", "idmm"], str(tmp_path), progress=False)
    result = CliRunner().invoke(main, ["evaluate", "--policy", "idm,pdm"])
    assert result.exit_code == 2 and result.output.startswith("error: --data is required")
    assert len(result.output.strip().splitlines()) == 1


def test_brake_guard_option_refuses_bad_values_and_policies_that_are_not_runs(policy_shards):
    wrong = CliRunner().invoke(main, ["evaluate", "--policy", "idm", "--data", str(policy_shards),
                                      "--brake-guard", "soon"])
    assert wrong.exit_code == 2 and "--brake-guard" in wrong.output and "expected run, off, or seconds" in wrong.output
    too_long = CliRunner().invoke(main, ["evaluate", "--policy", "idm", "--data", str(policy_shards),
                                         "--brake-guard", "11"])
    assert too_long.exit_code == 2 and "got '11'" in too_long.output
    no_guard_to_shape = CliRunner().invoke(main, ["evaluate", "--policy", "idm", "--data", str(policy_shards),
                                                  "--brake-guard", "0+hold"])
    assert no_guard_to_shape.exit_code == 2 and "got '0+hold'" in no_guard_to_shape.output
    no_run = CliRunner().invoke(main, ["evaluate", "--policy", "idm,pdm", "--data", str(policy_shards),
                                       "--brake-guard", "off"])
    assert no_run.exit_code == 2
    assert no_run.output.strip() == "error: --brake-guard acts on training run directories; --policy names none"


def test_run_directories_go_to_the_run_evaluator_the_caller_passes(tmp_path):
    # evaluation does not import training (above it): a run directory needs the evaluator from the caller
    run = tmp_path / "run"
    run.mkdir()
    with pytest.raises(ValueError, match=r"run: a training run directory; .*run_evaluator="):
        compare_policies([str(run)], None, progress=False)
    calls = []

    def fake_evaluate_run(entry, data, **kwargs):
        calls.append((entry, data, kwargs["num_scenarios"]))
        return SimpleNamespace(summary={"policy": "sac-mlp@run", "num_episodes": 2})

    (column,) = compare_policies([str(run)], None, num_scenarios=2, progress=False, print_fn=lambda line: None,
                                 run_evaluator=fake_evaluate_run)
    assert calls == [(str(run), None, 2)] and column.name == "sac-mlp@run"


@pytest.mark.slow  # ~38 s on 2 cores: kept out of the 10-minute default suite
def test_cli_compares_two_policies_and_writes_the_report(policy_shards, tmp_path):
    out = tmp_path / "cmp"
    args = ["evaluate", "--policy", "expert, idm", "--data", str(policy_shards), "--num-objects", "8",
            "--batch-size", "2", "--num-scenarios", "3", "--out", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "| Metric (%) | expert | idm |" in result.output and "| V-Max score |" in result.output
    assert (out / "table.md").read_text().startswith("| Metric (%) | expert | idm |")
    summaries = json.loads((out / "summaries.json").read_text())
    assert set(summaries) == {"expert", "idm"} and summaries["idm"]["num_episodes"] == 3
    assert len((out / "episodes-expert.csv").read_text().splitlines()) == 1 + 3

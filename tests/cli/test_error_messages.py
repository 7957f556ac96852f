"""Bad inputs through both command lines: one line per problem, the file named once, the format named."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from tests.conftest import realdata_file
from vmax_cli.scenariomax_cli import main as scenariomax_main

NOT_A_SHARD = ("this is a WOMD Scenario proto file, not a V-Max shard; "
               "convert it first with scenariomax convert --dataset womd")


def _stderr_lines_naming(result, path) -> list[str]:
    assert "Traceback" not in result.output, result.output
    lines = [line for line in result.stderr.splitlines() if str(path) in line]
    assert lines, f"no stderr line names {path}:\n{result.stderr}"
    for line in lines:
        assert line.count(str(path)) == 1, f"the path appears more than once: {line}"
    return lines


@pytest.fixture
def bad_inputs(tmp_path):
    text = tmp_path / "notes.tfrecord"
    text.write_text("this is a text file, not records\n" * 3)
    json_file = tmp_path / "scene.json"
    json_file.write_text("not json")
    pickle_file = tmp_path / "scene.pkl"
    pickle_file.write_bytes(b"\x80\x05garbage")
    return {"text": text, "json": json_file, "pickle": pickle_file}


@pytest.mark.parametrize("args, key, problem", [
    (["convert", "--dataset", "womd", "--src"], "text", "not a TFRecord file"),
    (["convert", "--dataset", "gpudrive", "--src"], "json", "invalid JSON"),
    (["convert", "--dataset", "scenarionet", "--src"], "pickle", "not a readable pickle"),
    (["build-sdc-paths"], "text", "not a TFRecord file"),
])
def test_a_bad_input_file_is_named_once_in_its_failure_line(bad_inputs, tmp_path, args, key, problem):
    path = bad_inputs[key]
    result = CliRunner().invoke(scenariomax_main, args + [str(path), "--out", str(tmp_path / "out"), "--workers", "1"])
    assert result.exit_code != 0
    (line,) = _stderr_lines_naming(result, path)
    assert problem in line and "CRC" not in line


def test_validate_names_a_non_tfrecord_file_once(bad_inputs):
    result = CliRunner().invoke(scenariomax_main, ["validate", str(bad_inputs["text"])])
    assert result.exit_code == 1
    # validate lists the bad records and its verdict on stdout (they are its output)
    (line,) = [line for line in result.stdout.splitlines() if str(bad_inputs["text"]) in line]
    assert line == f"{bad_inputs['text']}: not a TFRecord file (its first 12 bytes are not a record header)"


def test_build_sdc_paths_on_a_raw_womd_scenario_file_names_the_format(tmp_path):
    raw = realdata_file("womd/motion_data_one_scenario.tfrecord")
    result = CliRunner().invoke(scenariomax_main, ["build-sdc-paths", str(raw), "--out", str(tmp_path / "out"),
                                                   "--workers", "1"])
    assert result.exit_code == 1
    (line,) = _stderr_lines_naming(result, raw)
    assert line.endswith(f"{raw}: {NOT_A_SHARD}")
    assert "missing feature" not in result.output and not (tmp_path / "out").exists()


def test_evaluate_on_a_raw_womd_or_non_tfrecord_file_says_what_it_is(bad_inputs):
    from vmax_cli.vmax_cli import main as vmax_main

    raw = realdata_file("womd/motion_data_one_scenario.tfrecord")
    for path, problem in ((raw, NOT_A_SHARD), (bad_inputs["text"], "not a TFRecord file")):
        result = CliRunner().invoke(vmax_main, ["evaluate", "--policy", "constant", "--data", str(path), "--json"])
        assert result.exit_code == 2 and result.stdout == ""
        (line,) = _stderr_lines_naming(result, path)
        assert line.startswith("error: ") and problem in line and "missing feature" not in line

"""The `scenariomax` commands as a user types them."""

import json

import pytest
from click.testing import CliRunner

from vmax_cli.scenariomax_cli import main


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture(scope="module")
def synthetic_shards(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "syn"
    result = _run("convert", "--dataset", "synthetic", "--num-scenarios", 6, "--seed", 3, "--out", out,
                  "--workers", 2, "--shard-size", 4)
    assert result.exit_code == 0, result.output
    return out


def test_convert_then_validate_passes(synthetic_shards):
    assert sorted(p.name for p in synthetic_shards.glob("*.tfrecord")) == [
        "train-00000-of-00002.tfrecord", "train-00001-of-00002.tfrecord"]
    manifest = json.loads((synthetic_shards / "manifest.json").read_text())
    assert manifest["counts"]["scenarios"] == 6 and manifest["source_dataset"] == "synthetic"
    result = _run("validate", synthetic_shards)
    assert result.exit_code == 0, result.output


def test_same_seed_gives_byte_identical_shards(synthetic_shards, tmp_path):
    again = tmp_path / "again"
    assert _run("convert", "--num-scenarios", 6, "--seed", 3, "--out", again, "--workers", 1,
                "--shard-size", 4).exit_code == 0
    for shard in synthetic_shards.glob("*.tfrecord"):
        assert (again / shard.name).read_bytes() == shard.read_bytes()


def test_inspect_json_and_render(synthetic_shards, tmp_path):
    png = tmp_path / "scene.png"
    result = _run("inspect", synthetic_shards, "--json", "--render", png)
    assert result.exit_code == 0, result.output
    stats = json.loads(result.output[: result.output.rindex("}") + 1])
    assert stats["num_records"] == 6
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_validate_reports_a_damaged_file_in_one_line(synthetic_shards, tmp_path):
    shard = next(synthetic_shards.glob("*.tfrecord"))
    broken = tmp_path / "broken.tfrecord"
    broken.write_bytes(shard.read_bytes()[:5000])
    result = _run("validate", broken)
    assert result.exit_code == 1
    assert "broken.tfrecord" in result.output and "Traceback" not in result.output


def test_validate_takes_several_paths_and_prints_one_verdict_on_stdout(synthetic_shards, tmp_path):
    result = CliRunner().invoke(main, ["validate", str(synthetic_shards), str(synthetic_shards)])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines() == ["12 records in 4 files: all valid"]
    assert "records in" not in result.stderr


def test_validate_exits_1_when_any_of_its_paths_has_a_bad_record(synthetic_shards, tmp_path):
    shard = next(synthetic_shards.glob("*.tfrecord"))
    broken = tmp_path / "broken.tfrecord"
    broken.write_bytes(shard.read_bytes()[:5000])
    result = CliRunner().invoke(main, ["validate", str(synthetic_shards), str(broken)])
    assert result.exit_code == 1
    *problems, verdict = result.stdout.splitlines()
    assert len(problems) == 1 and problems[0].startswith(f"{broken}: ")
    assert verdict == "6 records in 3 files: 1 problems"


def test_validate_names_an_unreadable_path_in_one_line_before_validating_the_others(synthetic_shards, tmp_path):
    result = CliRunner().invoke(main, ["validate", str(synthetic_shards), str(tmp_path / "nope")])
    assert result.exit_code == 1
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:") and "nope" in lines[0]


def test_build_sdc_paths_counts_its_progress_in_scenarios_of_the_input_records(synthetic_shards, tmp_path):
    result = CliRunner().invoke(main, ["build-sdc-paths", str(synthetic_shards), "--out", str(tmp_path / "out"),
                                       "--workers", "1", "--num-paths", "4", "--points-per-path", "50"])
    assert result.exit_code == 0, result.output
    assert "converting: 6/6 scenarios (100%)" in result.stderr, result.stderr


def test_the_records_source_expects_the_records_before_a_damaged_frame(synthetic_shards, tmp_path):
    from scenariomax.sources.shard_records import ShardRecordsSource

    first, second = sorted(synthetic_shards.glob("*.tfrecord"))  # 4 and 2 records
    data = first.read_bytes()
    (tmp_path / "a.tfrecord").write_bytes(second.read_bytes())
    (tmp_path / "b.tfrecord").write_bytes(data[:len(data) - 100])  # the last of its 4 records cut short
    assert ShardRecordsSource(src=str(synthetic_shards)).expected_num_scenarios() == 6
    assert ShardRecordsSource(src=str(tmp_path / "*.tfrecord")).expected_num_scenarios() == 2 + 3


def test_missing_input_is_a_one_line_error(tmp_path):
    result = _run("convert", "--dataset", "womd", "--src", tmp_path / "nope", "--out", tmp_path / "o")
    assert result.exit_code == 1
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:") and "nope" in lines[0]


def test_existing_output_needs_resume(synthetic_shards):
    result = _run("convert", "--num-scenarios", 6, "--seed", 3, "--out", synthetic_shards)
    assert result.exit_code == 1 and "--resume" in result.output
    resumed = _run("convert", "--num-scenarios", 6, "--seed", 3, "--out", synthetic_shards, "--resume",
                   "--shard-size", 4)
    assert resumed.exit_code == 0, resumed.output

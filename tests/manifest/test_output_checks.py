"""What the tester saw, reproduced: damaged or incomplete outputs are named precisely by `validate`, make
`inspect` exit non-zero, and stop readers with one line instead of being read as complete."""

from __future__ import annotations

import shutil
import warnings

import pytest
from click.testing import CliRunner

from scenariomax import read_shards
from scenariomax.errors import InputError
from scenariomax.io.tfrecord import TFRecordWriter
from scenariomax.manifest import ManifestError, ManifestWarning, check_output
from scenariomax.shards import ShardReadError, list_shard_files
from tests.manifest.outputs import (
    convert_output,
    copy_output,
    interrupt_during_renames,
    load,
    save,
    shard_files,
    write_output,
)
from vmax_cli.scenariomax_cli import main


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def _lines(result) -> list[str]:
    return [line for line in result.output.splitlines() if line.strip()]


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    return convert_output(tmp_path_factory.mktemp("converted") / "out")


@pytest.fixture
def output(converted, tmp_path):
    """A fresh copy of the converted output, to damage."""
    return copy_output(converted, tmp_path / "out")


def _only_problem(out) -> str:
    result = _run("validate", out)
    assert result.exit_code == 1 and "Traceback" not in result.output
    problems = [line for line in _lines(result) if not line.startswith("warning:")][:-1]  # the last: the verdict
    assert len(problems) == 1, result.output
    return problems[0]


def _reader_error(out) -> str:
    with pytest.raises(InputError) as error:
        list(read_shards(out))
    assert "\n" not in str(error.value)
    return str(error.value)


def test_a_sound_output_validates_and_inspects_with_exit_0(output):
    result = _run("validate", output)
    assert result.exit_code == 0 and _lines(result) == ["23 records in 5 files: all valid"]
    inspected = _run("inspect", output)
    assert inspected.exit_code == 0
    assert "manifest           OK (complete: every listed shard present, none unlisted, record counts match)" \
        in inspected.output


def test_a_kill_during_the_final_renames_is_an_incomplete_output(output):
    interrupt_during_renames(output, num_renamed=3)
    expected = (f"{output}: incomplete output: manifest.json state is 'finalizing' (3 of 5 listed shards in place); "
                "the conversion was interrupted: rerun the same `scenariomax convert ...` command with --resume")
    assert _only_problem(output) == expected
    assert _reader_error(output) == expected
    inspected = _run("inspect", output)
    assert inspected.exit_code == 1 and expected in inspected.output


def test_a_kill_while_running_is_an_incomplete_output(output):
    manifest = load(output)
    manifest.update(state="running", open_shard={"file": ".sealing-train-00005.tfrecord", "num_records": 2,
                                                 "bytes": 100})
    save(output, manifest)
    assert "incomplete output: manifest.json state is 'running'" in _only_problem(output)
    with pytest.raises(ManifestError, match="state is 'running'"):
        list_shard_files(output)


def test_a_deleted_shard_is_named(output):
    (output / "train-00002-of-00005.tfrecord").unlink()
    expected = (f"{output / 'train-00002-of-00005.tfrecord'}: listed in manifest.json (5 records) but missing: "
                "restore it, or convert again")
    assert _only_problem(output) == expected
    assert _reader_error(output) == expected
    assert _run("inspect", output).exit_code == 1


def test_an_unlisted_shard_file_is_named_and_not_read(output):
    shutil.copy(output / "train-00000-of-00005.tfrecord", output / "train-00000-of-00001.tfrecord")
    result = _run("validate", output)
    assert result.exit_code == 1
    unlisted = output / "train-00000-of-00001.tfrecord"
    assert (f"{unlisted}: not listed in manifest.json, so not part of this output (a leftover, or added by hand): "
            "move it out of the folder") in _lines(result)
    assert any("duplicate scenario id" in line for line in _lines(result))  # its records repeat shard 0's
    assert "not listed in manifest.json" in _reader_error(output)
    assert "not listed in manifest.json" in _reader_error(unlisted)  # also when named on its own


def test_duplicate_scenario_ids_name_both_places(tmp_path):
    from scenariomax import write_shards
    from tests.inspect.scenes import SIZES, make_scenario

    write_shards([make_scenario("a"), make_scenario("b"), make_scenario("a")], tmp_path, sizes=SIZES, shard_size=2)
    first, second = tmp_path / "train-00000-of-00002.tfrecord", tmp_path / "train-00001-of-00002.tfrecord"
    assert _only_problem(tmp_path) == f"{second}: record 0 (a): duplicate scenario id, first seen in {first}: record 0"
    assert _run("inspect", tmp_path).exit_code == 1


def test_a_replaced_shard_fails_its_sha256(output):
    first, second = output / "train-00000-of-00005.tfrecord", output / "train-00001-of-00005.tfrecord"
    data = first.read_bytes()
    first.write_bytes(second.read_bytes())
    second.write_bytes(data)  # swapped: same record counts, both sha256 wrong
    result = _run("validate", output)
    assert result.exit_code == 1
    assert _lines(result)[:2] == [
        f"{first}: sha256 differs from manifest.json: the file was changed or damaged after it was written",
        f"{second}: sha256 differs from manifest.json: the file was changed or damaged after it was written",
    ]
    assert check_output(output)[:1] == [f"{first}: sha256 differs from manifest.json: the file was changed or "
                                        "damaged after it was written"]


def test_a_record_count_that_disagrees_is_named_by_validate_and_by_readers(output):
    manifest = load(output)
    manifest["shards"][0]["num_records"] = 4
    manifest["counts"]["scenarios"] -= 1
    save(output, manifest)
    shard = output / "train-00000-of-00005.tfrecord"
    assert _only_problem(output) == f"{shard}: holds 5 records, manifest.json lists 4"
    with pytest.raises(ShardReadError) as error:
        list(read_shards(output))
    assert str(error.value) == (f"{shard}: holds 5 records, manifest.json lists 4: the output is damaged "
                                "(`scenariomax validate` checks it)")


def test_a_truncated_shard_in_a_conversion_output_stops_readers(output):
    shard = output / "train-00003-of-00005.tfrecord"
    shard.write_bytes(shard.read_bytes()[:-100])
    result = _run("validate", output)
    assert result.exit_code == 1 and f"{shard}: truncated record at byte" in result.output
    # conversion manifests list each shard's size: readers see the cut before reading a record
    with pytest.raises((ShardReadError, ManifestError), match="truncated record|cut short"):
        list(read_shards(output))
    assert _run("inspect", output).exit_code == 1


def test_unrelated_record_files_in_a_write_shards_output_are_reported(tmp_path):
    out = write_output(tmp_path / "out")
    with TFRecordWriter(out / "other.tfrecord") as writer:
        writer.write(b"not an example")
    lines = _lines(_run("validate", out))
    assert f"{out / 'other.tfrecord'}: not listed in manifest.json" in lines[0]


def test_a_folder_without_manifest_reads_with_a_one_line_warning(tmp_path):
    out = write_output(tmp_path / "out")
    (out / "manifest.json").unlink()  # as shards written by hand, or by an older version
    with pytest.warns(ManifestWarning) as caught:
        ids = [s.scenario_id for s in read_shards(out)]
    assert ids == ["s0", "s1", "s2", "s3", "s4"]
    (warning,) = caught
    assert str(warning.message).startswith(f"{out}: no manifest.json, so completeness cannot be checked")
    result = _run("validate", out)
    assert result.exit_code == 0
    assert _lines(result) == [f"warning: {warning.message}",
                              "5 records in 3 files: all valid (completeness not checked: no manifest.json)"]
    inspected = _run("inspect", out)
    assert inspected.exit_code == 0 and "manifest           none: completeness cannot be checked" in inspected.output


def test_a_single_file_outside_any_output_reads_silently(tmp_path):
    out = write_output(tmp_path / "out")
    loose = tmp_path / "loose.tfrecord"
    shutil.copy(out / "train-00000-of-00003.tfrecord", loose)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert [s.scenario_id for s in read_shards(loose)] == ["s0", "s1"]


def test_a_glob_is_checked_against_the_manifest_of_its_folder(output):
    interrupt_during_renames(output, num_renamed=5)  # every shard in place, but the state says unfinished
    with pytest.raises(ManifestError, match="state is 'finalizing'"):
        list(read_shards(output / "train-0000[01]*"))


def test_the_simulator_loader_refuses_an_incomplete_output(output):
    from tests.sim_core.conftest import small_config
    from vmax_sim.data.loader import load_batch, make_data_iterator

    (output / "train-00004-of-00005.tfrecord").unlink()
    for start in (make_data_iterator, load_batch):
        with pytest.raises(InputError) as error:
            start(small_config(output))
        assert str(error.value).startswith(f"{output / 'train-00004-of-00005.tfrecord'}: listed in manifest.json")


def test_inspect_exits_non_zero_on_a_corrupt_record(tmp_path):
    out = write_output(tmp_path / "out")
    shard = out / "train-00000-of-00003.tfrecord"
    data = bytearray(shard.read_bytes())
    data[200] ^= 0xFF  # breaks the first record's CRC
    shard.write_bytes(bytes(data))
    result = _run("inspect", out)
    assert result.exit_code == 1
    assert "schema validation  1 bad record(s)" in result.output
    # same size, so the manifest's cheap checks pass; the CRC names the damage (validate adds the sha256)
    assert _lines(result)[-1] == (f"{out}: 1 bad record(s), 0 manifest problem(s); `scenariomax validate` lists "
                                  "them all")


def test_inspect_of_an_unknown_scenario_fails_at_once_in_one_line(tmp_path):
    out = write_output(tmp_path / "out")
    result = _run("inspect", out, "--scenario", "nope")
    assert result.exit_code == 1
    assert _lines(result) == [f"Error: no scenario 'nope' in {out}; ids look like: s0, s1, s2"]


def test_inspect_renders_a_scenario_it_found(tmp_path):
    out = write_output(tmp_path / "out")
    png = tmp_path / "s3.png"
    result = _run("inspect", out, "--scenario", "s3", "--render", png)
    assert result.exit_code == 0, result.output
    assert png.read_bytes()[:4] == b"\x89PNG" and "rendered s3" in result.output


def test_build_sdc_paths_into_its_own_input_is_refused(tmp_path):
    out = write_output(tmp_path / "out")
    before = {path.name: path.read_bytes() for path in out.iterdir()}
    for extra in ((), ("--resume",)):
        result = _run("build-sdc-paths", out, "--out", out, "--workers", 1, *extra)
        assert result.exit_code == 1 and len(_lines(result)) == 1 and "Traceback" not in result.output
    assert {path.name: path.read_bytes() for path in out.iterdir()} == before
    assert check_output(out) == []


def test_the_damage_shown_by_validate_covers_each_shard(output):
    for shard in shard_files(output)[:2]:
        shard.unlink()
    assert len(_lines(_run("validate", output))) == 3  # two missing shards and the verdict

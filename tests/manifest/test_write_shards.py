"""`write_shards` leaves a checkable, owned output: a manifest, atomic replacement, and refusal of folders
holding anything it did not write."""

from __future__ import annotations

import hashlib

import pytest

from scenariomax import read_shards, write_shards
from scenariomax.manifest import check_output
from scenariomax.shards import ShardWriteError
from tests.inspect.scenes import SIZES, make_scenario
from tests.manifest.outputs import convert_output, load, save, write_output


def _snapshot(folder) -> dict:
    return {path.name: path.read_bytes() for path in sorted(folder.iterdir())}


def test_the_manifest_lists_every_shard_with_count_size_and_sha256(tmp_path):
    files = write_shards([make_scenario(f"s{i}") for i in range(5)], tmp_path, sizes=SIZES, shard_size=2)
    manifest = load(tmp_path)
    assert (manifest["state"], manifest["source_dataset"], manifest["counts"]) == (
        "complete", "write_shards", {"scenarios": 5, "failures": 0})
    assert manifest["schema"] == {"name": "vmax-shard", "version": "1.0.0"}
    assert manifest["settings"] == {"split": "train", "shard_size": 2, "sizes": SIZES.as_dict(), "compression": "none"}
    assert [entry["file"] for entry in manifest["shards"]] == [file.name for file in files]
    assert [entry["num_records"] for entry in manifest["shards"]] == [2, 2, 1]
    for entry, file in zip(manifest["shards"], files):
        assert entry["sha256"] == hashlib.sha256(file.read_bytes()).hexdigest()
        assert entry["num_bytes"] == file.stat().st_size and "temp_file" not in entry
    assert sorted(path.name for path in tmp_path.iterdir()) == ["manifest.json"] + [file.name for file in files]
    assert check_output(tmp_path) == []


def test_shards_without_a_manifest_are_refused_untouched(tmp_path):
    out = write_output(tmp_path / "out")
    (out / "manifest.json").unlink()
    before = _snapshot(out)
    with pytest.raises(ShardWriteError) as error:
        write_shards([make_scenario("new")], out, sizes=SIZES)
    assert str(error.value) == (f"{out}: not empty and holds no manifest.json (e.g. train-00000-of-00003.tfrecord, "
                                "train-00001-of-00003.tfrecord, train-00002-of-00003.tfrecord); write_shards writes "
                                "only into a new or empty folder, or over its own output")
    assert _snapshot(out) == before


def test_a_conversion_output_is_refused(tmp_path):
    out = convert_output(tmp_path / "out")
    before = _snapshot(out)
    with pytest.raises(ShardWriteError, match=r"holds the output of `scenariomax convert`"):
        write_shards([make_scenario("new")], out, sizes=SIZES, overwrite=True)
    assert _snapshot(out) == before


def test_a_file_its_manifest_does_not_list_is_refused(tmp_path):
    out = write_output(tmp_path / "out")
    (out / "notes.txt").write_text("mine")
    with pytest.raises(ShardWriteError, match=r"holds files its manifest.json does not list \(e.g. notes.txt\)"):
        write_shards([make_scenario("new")], out, sizes=SIZES, overwrite=True)


def test_its_own_complete_output_is_replaced_only_with_overwrite(tmp_path):
    out = write_output(tmp_path / "out")  # 3 shards
    with pytest.raises(ShardWriteError, match="already holds shards written by write_shards; pass overwrite=True"):
        write_shards([make_scenario("new")], out, sizes=SIZES)
    write_shards([make_scenario("new")], out, sizes=SIZES, overwrite=True)
    assert sorted(path.name for path in out.iterdir()) == ["manifest.json", "train-00000-of-00001.tfrecord"]
    assert [s.scenario_id for s in read_shards(out)] == ["new"] and check_output(out) == []


def test_a_failing_scenario_stream_leaves_the_earlier_output_intact(tmp_path):
    out = write_output(tmp_path / "out")
    before = _snapshot(out)

    def scenarios():
        yield make_scenario("new")
        raise RuntimeError("the generator broke")

    with pytest.raises(RuntimeError, match="the generator broke"):
        write_shards(scenarios(), out, sizes=SIZES, overwrite=True)
    assert _snapshot(out) == before  # no temp file left, nothing replaced


def test_an_interrupted_write_reads_as_incomplete_and_a_rerun_replaces_it(tmp_path):
    out = write_output(tmp_path / "out")
    manifest = load(out)
    manifest["state"] = "finalizing"  # killed between the manifest listing the new shards and their renames
    manifest["shards"][2]["temp_file"] = ".train-00002.tfrecord.tmp"
    (out / manifest["shards"][2]["file"]).rename(out / ".train-00002.tfrecord.tmp")
    save(out, manifest)
    (problem,) = check_output(out)
    assert problem == (f"{out}: incomplete output: manifest.json state is 'finalizing' (2 of 3 listed shards in "
                       "place); write_shards was interrupted: run it again into this folder")
    write_shards([make_scenario("again")], out, sizes=SIZES)  # no overwrite needed: nothing complete is lost
    assert sorted(path.name for path in out.iterdir()) == ["manifest.json", "train-00000-of-00001.tfrecord"]
    assert check_output(out) == []


def test_a_file_in_place_of_the_folder_is_refused(tmp_path):
    (tmp_path / "out").write_text("")
    with pytest.raises(ShardWriteError, match="exists and is not a folder"):
        write_shards([make_scenario("x")], tmp_path / "out", sizes=SIZES)


def test_no_scenarios_give_an_empty_complete_output(tmp_path):
    assert write_shards([], tmp_path / "out") == []
    assert load(tmp_path / "out")["shards"] == [] and check_output(tmp_path / "out") == []

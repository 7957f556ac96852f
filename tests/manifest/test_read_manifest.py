"""`read_manifest` and `check_output`: a sound manifest passes, each kind of damage is one precise line."""

from __future__ import annotations

import json

import pytest

from scenariomax.errors import InputError
from scenariomax.manifest import ManifestError, ManifestMissingError, check_output, read_manifest
from tests.manifest.outputs import convert_output, load, save, write_output


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    return write_output(tmp_path_factory.mktemp("written") / "out")


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    return convert_output(tmp_path_factory.mktemp("converted") / "out")


def test_outputs_of_write_shards_and_of_a_conversion_check_clean(written, converted):
    assert check_output(written) == [] and check_output(converted) == []
    assert read_manifest(converted)["counts"]["scenarios"] == 23


def test_a_folder_without_manifest_cannot_prove_completeness(tmp_path):
    with pytest.raises(ManifestMissingError) as error:
        read_manifest(tmp_path)
    assert isinstance(error.value, FileNotFoundError) and isinstance(error.value, InputError)
    (problem,) = check_output(tmp_path)
    assert problem.startswith(f"{tmp_path / 'manifest.json'}: no manifest")


def _damaged(out, text: str):
    (out / "manifest.json").write_text(text)
    with pytest.raises(ManifestError) as error:
        read_manifest(out)
    message = str(error.value)
    assert "\n" not in message and message.count(str(out / "manifest.json")) == 1, message
    return message.split(": ", 1)[1]


@pytest.mark.parametrize(("text", "expected"), [
    ("", "not valid JSON (the file is empty)"),
    ('{"schema": {"name": "vmax-shard"', "not valid JSON (expecting ',' delimiter, ends early (truncated?))"),
    ("[1, 2]", "holds an array, not a JSON object"),
    ('"complete"', "holds a string, not a JSON object"),
    ("{} garbage", "not valid JSON (extra data, at line 1)"),
])
def test_unreadable_json_is_one_line(tmp_path, text, expected):
    assert _damaged(tmp_path, text).startswith(expected)


def test_binary_garbage_is_one_line(tmp_path):
    (tmp_path / "manifest.json").write_bytes(b"\xff\xfe\x00garbage\x80")
    with pytest.raises(ManifestError, match="not valid JSON"):
        read_manifest(tmp_path)


@pytest.mark.parametrize(("change", "expected"), [
    (lambda m: m.pop("shards"), "missing key shards"),
    (lambda m: [m.pop("state"), m.pop("counts")], "missing key state, counts"),
    (lambda m: m.update(state=3), "'state' is an integer, expected a string"),
    (lambda m: m.update(state="done"), "'state' is 'done', expected one of running, finalizing, complete"),
    (lambda m: m.update(shards={"a": 1}), "'shards' is an object, expected an array"),
    (lambda m: m["shards"].__setitem__(0, "train.tfrecord"), "shards[0] is a string, expected an object"),
    (lambda m: m["shards"][1].update(num_records="2"), "shards[1].num_records is '2', expected a count"),
    (lambda m: m["shards"][1].update(num_records=-1), "shards[1].num_records is -1, expected a count"),
    (lambda m: m["shards"][0].pop("sha256"), "shards[0] has no 'sha256'"),
    (lambda m: m["shards"][0].update(sha256="abc"), "shards[0].sha256 is not 64 lowercase hex digits"),
    (lambda m: m["shards"][0].update(file="../x.tfrecord"), "shards[0].file '../x.tfrecord' is not a file name"),
    (lambda m: m["counts"].update(scenarios=True), "counts.scenarios is True, expected a count"),
    (lambda m: m.update(schema={"name": "vmax-shard"}), "'schema' needs a string 'name' and 'version'"),
])
def test_missing_and_mistyped_keys_are_named(written, tmp_path, change, expected):
    manifest = load(written)
    change(manifest)
    message = _damaged(tmp_path, json.dumps(manifest))
    assert message.startswith(expected), message
    assert message.endswith("move the folder away and convert (or write) it again")


def test_check_output_returns_the_read_error_as_its_problem(written, tmp_path):
    (tmp_path / "manifest.json").write_text("{")
    (problem,) = check_output(tmp_path)
    assert problem.startswith(f"{tmp_path / 'manifest.json'}: not valid JSON")


def test_inconsistent_counts_and_schema_are_problems(written, tmp_path):
    import shutil

    shutil.copytree(written, tmp_path / "out")
    manifest = load(tmp_path / "out")
    manifest["counts"]["scenarios"] = 40
    manifest["schema"]["version"] = "2.0.0"
    manifest["shards"].append(dict(manifest["shards"][0]))
    save(tmp_path / "out", manifest)
    where = tmp_path / "out" / "manifest.json"
    assert check_output(tmp_path / "out") == [
        f"{where}: written with schema vmax-shard 2.0.0; this scenariomax reads vmax-shard 1.0.0",
        f"{where}: counts.scenarios is 40 but its shards hold 7 records",
        f"{where}: lists a shard file twice",
    ]

"""Fuzz: random damage to manifest.json or to the shards always comes out as one-line problems (library,
`validate`, `inspect` and readers): never a traceback, never "valid"."""

from __future__ import annotations

import json
import shutil

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scenariomax import read_shards
from scenariomax.errors import InputError
from scenariomax.manifest import ManifestError, check_output, read_manifest
from scenariomax.shards import ShardReadError
from scenariomax.validate import format_bad, validate_shards
from tests.manifest.outputs import convert_output, write_output
from vmax_cli.scenariomax_cli import main

REQUIRED = {"schema": dict, "source_dataset": str, "settings": dict, "state": str, "counts": dict, "shards": list}
JSON_VALUES = [None, 0, -3, 2.5, True, "x", "complete", [], [1, "a"], {}, {"file": 1}]
FUZZ = settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module")
def bases(tmp_path_factory):
    """A write_shards output (3 shards) and a conversion output (5 shards)."""
    return {"written": write_output(tmp_path_factory.mktemp("fuzz-base") / "written"),
            "converted": convert_output(tmp_path_factory.mktemp("fuzz-base") / "converted")}


def _fresh_copy(tmp_path_factory, bases, which: str):
    out = tmp_path_factory.mktemp("fuzz") / "out"
    shutil.copytree(bases[which], out)
    return out


def _assert_one_line(text: str) -> None:
    assert text and "\n" not in text and "Traceback" not in text, text


def _assert_rejected_everywhere(out, readers_must_fail: bool, inspect_must_fail: bool = False) -> None:
    for problem in check_output(out):
        _assert_one_line(problem)
    report = validate_shards(out)
    assert not report.ok
    for entry in report.bad:
        _assert_one_line(format_bad(entry))
    result = CliRunner().invoke(main, ["validate", str(out)], catch_exceptions=False)
    assert result.exit_code == 1 and "all valid" not in result.output and "Traceback" not in result.output
    inspected = CliRunner().invoke(main, ["inspect", str(out)], catch_exceptions=False)
    assert "Traceback" not in inspected.output
    if inspect_must_fail:
        assert inspected.exit_code == 1
    if readers_must_fail:
        with pytest.raises((InputError, ShardReadError)) as error:
            list(read_shards(out))
        _assert_one_line(str(error.value))


@st.composite
def manifest_damage(draw):
    """(function from the manifest's text to the damaged bytes, whether its layout breaks, whether the readers'
    cheap checks must catch it)."""
    kind = draw(st.sampled_from(["truncate", "garbage", "drop_key", "retype_key", "shard_field"]))
    if kind == "truncate":
        fraction = draw(st.floats(0.0, 0.999))
        return lambda text: text[: int(len(text) * fraction)].encode(), True, True
    if kind == "garbage":
        data = draw(st.binary(max_size=64))
        return lambda text: data, True, True
    key = draw(st.sampled_from(sorted(REQUIRED)))
    if kind == "drop_key":
        return lambda text: json.dumps({k: v for k, v in json.loads(text).items() if k != key}).encode(), True, True
    if kind == "retype_key":
        value = draw(st.sampled_from([v for v in JSON_VALUES if type(v) is not REQUIRED[key]]))
        return lambda text: json.dumps({**json.loads(text), key: value}).encode(), True, True
    field = draw(st.sampled_from(["file", "num_records", "sha256"]))
    value = draw(st.sampled_from(JSON_VALUES + ["../up.tfrecord", "other.tfrecord", 7, "ab" * 32]))
    index = draw(st.integers(0, 2))

    def damage(text: str) -> bytes:
        manifest = json.loads(text)
        manifest["shards"][index][field] = value
        return json.dumps(manifest).encode()

    # a well-formed but wrong value (another name, count or digest) keeps the layout: the folder check objects
    plain_name = field == "file" and isinstance(value, str) and "/" not in value and value not in ("", ".", "..")
    layout_breaks = not (value in ("other.tfrecord", 7, "ab" * 32) or (field == "num_records" and value == 0)
                         or plain_name)
    sha256_only = field == "sha256" and value == "ab" * 32  # a wrong digest is for validate: readers do not hash
    return damage, layout_breaks, not sha256_only


@FUZZ
@given(which=st.sampled_from(["written", "converted"]), damage=manifest_damage())
def test_damaged_manifest_is_never_valid(tmp_path_factory, bases, which, damage):
    damage_fn, layout_breaks, readers_must_fail = damage
    out = _fresh_copy(tmp_path_factory, bases, which)
    path = out / "manifest.json"
    path.write_bytes(damage_fn(path.read_text()))
    if layout_breaks:
        with pytest.raises(ManifestError) as error:
            read_manifest(out)
        _assert_one_line(str(error.value))
        assert str(error.value).count(str(path)) == 1
    _assert_rejected_everywhere(out, readers_must_fail)


@FUZZ
@given(which=st.sampled_from(["written", "converted"]), op=st.sampled_from(["delete", "truncate", "extra", "copy"]),
       index=st.integers(0, 4), other=st.integers(0, 4), fraction=st.floats(0.0, 0.999))
def test_damaged_shards_are_never_valid(tmp_path_factory, bases, which, op, index, other, fraction):
    out = _fresh_copy(tmp_path_factory, bases, which)
    shards = sorted(out.glob("*.tfrecord"))
    shard, source = shards[index % len(shards)], shards[other % len(shards)]
    readers_must_fail = True
    if op == "delete":
        shard.unlink()
    elif op == "truncate":
        data = shard.read_bytes()
        shard.write_bytes(data[: int(len(data) * fraction)])
    elif op == "extra":
        shutil.copy(source, out / f"extra-{other}.tfrecord")
    else:
        if source == shard:
            source = shards[(index + 1) % len(shards)]
        shutil.copy(source, shard)  # two shards with the same records: duplicate ids and a wrong sha256
        readers_must_fail = shard.stat().st_size != source.stat().st_size and which == "written"
    _assert_rejected_everywhere(out, readers_must_fail, inspect_must_fail=True)

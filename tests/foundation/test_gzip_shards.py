"""Gzip-compressed shards (`--compression gzip`): written one gzip member per record, read by every reader
without a flag (read_shards, random access by offset, validate, inspect, the viewer's index, the vmax_sim
loader), damage reported in one line. tf.data reading them: tests/interop/test_tensorflow.py (`-m tf`)."""

from __future__ import annotations

import gzip
import json

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from scenariomax import read_shards, write_shards
from scenariomax.inspect import inspect_shards, scenario_ids
from scenariomax.io.tfrecord import (
    RecordError,
    TFRecordWriter,
    count_records,
    file_compression,
    iter_record_spans,
    iter_records,
    read_record_at,
)
from scenariomax.pipeline import ConversionError, ConvertSettings, convert
from scenariomax.shards import ShardReadError, iter_shard_records
from scenariomax.validate import validate_shards
from scenariomax.view.index import ShardIndex
from tests.foundation.toy_source import ToySource
from tests.inspect.scenes import SIZES, make_scenario

IDS = [f"s{i}" for i in range(5)]


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    """The same five hand-made scenes written plain and gzip-compressed, in shards of 2."""
    root = tmp_path_factory.mktemp("gzip")
    scenes = [make_scenario(i) for i in IDS]
    plain = write_shards(scenes, root / "plain", sizes=SIZES, shard_size=2)
    packed = write_shards(scenes, root / "gzip", sizes=SIZES, shard_size=2, compression="gzip")
    return root / "plain", root / "gzip", plain, packed


def test_a_gzip_shard_is_the_plain_shard_gzipped_and_the_manifest_says_so(outputs):
    plain_dir, gzip_dir, plain, packed = outputs
    for ours, theirs in zip(packed, plain):
        assert ours.name == theirs.name  # same names: readers tell by the magic bytes, not the suffix
        assert ours.read_bytes()[:2] == b"\x1f\x8b" and file_compression(ours) == "gzip"
        assert gzip.decompress(ours.read_bytes()) == theirs.read_bytes()  # gunzip gives the plain file back
        assert ours.stat().st_size < 0.4 * theirs.stat().st_size
    assert json.loads((gzip_dir / "manifest.json").read_text())["settings"]["compression"] == "gzip"
    assert json.loads((plain_dir / "manifest.json").read_text())["settings"]["compression"] == "none"


def test_read_shards_and_random_access_read_gzip_shards(outputs):
    plain_dir, gzip_dir, plain, packed = outputs
    assert [s.scenario_id for s in read_shards(gzip_dir)] == IDS
    located = list(iter_shard_records(gzip_dir))
    assert [record.index for record in located] == [0, 1, 0, 1, 0]
    assert [record.read().scenario_id for record in reversed(located)] == IDS[::-1]  # any order, by member
    assert [count_records(file) for file in packed] == [2, 2, 1]
    assert count_records(packed[0], limit=1) == 1


def test_validate_inspect_and_the_viewer_read_gzip_shards(outputs):
    plain_dir, gzip_dir, plain, packed = outputs
    report = validate_shards(gzip_dir)  # sha256 of the compressed files against the manifest included
    assert (report.num_records, report.bad, report.warnings) == (5, (), ())
    stats, plain_stats = inspect_shards(gzip_dir), inspect_shards(plain_dir)
    assert stats["num_scenarios"] == plain_stats["num_scenarios"] == 5
    assert stats["validation"] == plain_stats["validation"]
    assert list(scenario_ids(packed)) == IDS
    index = ShardIndex.build(gzip_dir)
    assert [entry.scenario_id for entry in index.entries] == IDS and index.file_errors == ()
    assert index.check(4).scenario.scenario_id == "s4"
    assert index.read(3) == ShardIndex.build(plain_dir).read(3)


def test_the_vmax_sim_loader_reads_gzip_shards_in_the_same_shuffled_order(outputs):
    pytest.importorskip("jax")
    from vmax_sim.data.config import DataConfig
    from vmax_sim.data.loader import iter_scenarios

    plain_dir, gzip_dir, _, _ = outputs

    def order(path):
        config = DataConfig(path=str(path), shuffle_seed=7, shuffle_buffer=3, repeat=False, map_index_cache=False)
        return [scenario.scenario_id for scenario in iter_scenarios(config)]

    assert order(gzip_dir) == order(plain_dir) and sorted(order(gzip_dir)) == IDS


def test_another_tools_gzip_file_one_stream_reads_in_order_and_by_offset(outputs, tmp_path):
    """What tf.io.TFRecordWriter(GZIP) or `gzip` writes: one gzip stream, no member index."""
    _, _, plain, _ = outputs
    one_stream = tmp_path / "other.tfrecord"
    one_stream.write_bytes(gzip.compress(plain[0].read_bytes() + plain[1].read_bytes()))
    assert [s.scenario_id for s in read_shards(one_stream)] == IDS[:4]
    located = list(iter_shard_records(one_stream))
    assert [record.read().scenario_id for record in reversed(located)] == IDS[3::-1]
    assert count_records(one_stream) == 4
    assert list(scenario_ids([one_stream])) == IDS[:4]


def test_a_truncated_or_corrupted_gzip_shard_is_one_line_naming_the_file(outputs, tmp_path):
    _, gzip_dir, _, packed = outputs
    data = packed[0].read_bytes()
    cut = tmp_path / "cut.tfrecord"
    cut.write_bytes(data[:len(data) - 100])
    with pytest.raises(ShardReadError) as error:
        list(read_shards(cut))
    assert str(error.value) == (f"{cut}: truncated gzip data (the file ends at byte {len(data) - 100}, inside a "
                                "compressed record)")
    with pytest.raises(ShardReadError, match=f"^{cut}: truncated record at byte \\d+"):
        list(iter_shard_records(cut))
    flipped = tmp_path / "flipped.tfrecord"
    damaged = bytearray(data)
    damaged[len(data) // 4] ^= 0xFF  # inside the first record's compressed data
    flipped.write_bytes(bytes(damaged))
    with pytest.raises(ShardReadError, match=f"^{flipped}: "):
        list(read_shards(flipped))
    first = next(iter_shard_records(flipped))
    with pytest.raises(ShardReadError, match=f"^{flipped}: "):
        first.read()
    report = validate_shards(flipped)
    assert len(report.bad) == 1 and "\n" not in report.bad[0].reason


def test_the_cli_validates_a_truncated_gzip_shard_without_a_traceback(outputs, tmp_path):
    from vmax_cli.scenariomax_cli import main

    _, _, _, packed = outputs
    cut = tmp_path / "cut.tfrecord"
    cut.write_bytes(packed[0].read_bytes()[:-50])
    result = CliRunner().invoke(main, ["validate", str(cut)])
    assert result.exit_code != 0 and "Traceback" not in result.output
    assert f"{cut}: truncated gzip data" in result.output


def test_a_record_that_moved_since_the_scan_is_reported(outputs, tmp_path):
    _, _, _, packed = outputs
    (offset, length), _ = list(iter_record_spans(packed[0]))
    with pytest.raises(RecordError, match="changed since the file was scanned"):
        read_record_at(packed[0], offset, length + 1, 1)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_damaged_gzip_bytes_give_a_record_error_never_a_crash(tmp_path, data):
    path = tmp_path / "small.tfrecord"
    with TFRecordWriter(path, compression="gzip") as writer:
        for size in (0, 30, 500):
            writer.write(bytes(range(256)) * (size // 256) + b"x" * (size % 256))
    raw = bytearray(path.read_bytes())
    if data.draw(st.booleans(), label="truncate"):
        raw = raw[:data.draw(st.integers(0, len(raw) - 1), label="cut")]
    else:
        for _ in range(data.draw(st.integers(1, 4), label="flips")):
            raw[data.draw(st.integers(0, len(raw) - 1))] ^= data.draw(st.integers(1, 255))
    path.write_bytes(bytes(raw))
    for read in (lambda: list(iter_records(path)), lambda: count_records(path),
                 lambda: [read_record_at(path, o, n, i) for i, (o, n) in enumerate(iter_record_spans(path))]):
        try:
            read()
        except RecordError as error:
            assert str(error).startswith(f"{path}: ") and "\n" not in str(error)


def test_the_pipeline_writes_gzip_shards_whose_gunzip_is_the_plain_output(tmp_path):
    """Workers compress (in parallel); the main process appends members; resume and settings checks hold."""
    plain, packed = tmp_path / "plain", tmp_path / "gzip"
    common = dict(sizes=SIZES, shard_size=5, progress=False, workers=1)
    before = convert(ToySource(), ConvertSettings(out=plain, **common))  # the toy source fails one scene on purpose
    result = convert(ToySource(), ConvertSettings(out=packed, compression="gzip", **common))
    assert (result.num_scenarios, result.failures, result.shards) == (before.num_scenarios, before.failures,
                                                                      before.shards)
    for name in result.shards:
        assert gzip.decompress((packed / name).read_bytes()) == (plain / name).read_bytes()
    assert [s.scenario_id for s in read_shards(packed)] == [s.scenario_id for s in read_shards(plain)]
    assert validate_shards(packed).bad == ()
    with pytest.raises(ConversionError, match="settings differ"):  # a resume may not switch compression
        convert(ToySource(), ConvertSettings(out=packed, resume=True, **common))
    with pytest.raises(ConversionError, match="--compression 'zstd'"):
        convert(ToySource(), ConvertSettings(out=tmp_path / "x", compression="zstd", **common))


def test_a_manifest_from_before_compression_resumes_as_uncompressed(tmp_path):
    out = tmp_path / "old"
    common = dict(sizes=SIZES, shard_size=5, progress=False, workers=1)
    before = convert(ToySource(), ConvertSettings(out=out, **common))
    manifest = json.loads((out / "manifest.json").read_text())
    del manifest["settings"]["compression"]
    (out / "manifest.json").write_text(json.dumps(manifest))
    assert convert(ToySource(), ConvertSettings(out=out, resume=True, **common)).num_scenarios == before.num_scenarios


def test_the_cli_converts_with_compression_gzip_and_every_command_reads_it(tmp_path):
    from vmax_cli.scenariomax_cli import main

    out = tmp_path / "shards"
    runner = CliRunner()
    result = runner.invoke(main, ["convert", "--dataset", "synthetic", "--num-scenarios", "2", "--num-objects", "8",
                                  "--roadgraph-points", "500", "--num-paths", "2", "--points-per-path", "20",
                                  "--no-enrich", "--workers", "1", "--compression", "gzip", "--out", str(out)])
    assert result.exit_code == 0, result.output
    files = sorted(out.glob("*.tfrecord"))
    assert files and all(file_compression(file) == "gzip" for file in files)
    assert json.loads((out / "manifest.json").read_text())["settings"]["compression"] == "gzip"
    for command in (["validate", str(out)], ["inspect", str(out)],
                    ["view", str(out), "--out", str(tmp_path / "view.html")]):
        outcome = runner.invoke(main, command)
        assert outcome.exit_code == 0, (command, outcome.output)
    assert "2 records in 1 files: all valid" in runner.invoke(main, ["validate", str(out)]).output

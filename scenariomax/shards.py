"""Reading and writing shard files: `read_shards` streams Scenarios, `write_shards` writes them.

Shard files are named `<split>-<index>-of-<count>.tfrecord`; see `scenariomax.pipeline` for the
parallel, resumable conversion that produces them together with `manifest.json`.
"""

from __future__ import annotations

import glob
import os
from collections.abc import Iterable, Iterator
from pathlib import Path

from scenariomax.codec import SchemaError, decode_scenario, encode_scenario
from scenariomax.io.example import ExampleError
from scenariomax.io.tfrecord import RecordError, TFRecordWriter, iter_records
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes

SHARD_SUFFIXES = (".tfrecord", ".tfrecords")


class ShardReadError(ValueError):
    """A record could not be read or decoded: the message names the file and record."""


def shard_name(split: str, index: int, count: int) -> str:
    return f"{split}-{index:05d}-of-{count:05d}.tfrecord"


def list_shard_files(path: str | os.PathLike) -> list[Path]:
    """Resolves a directory, a file or a glob pattern to a sorted list of record files."""
    text = str(path)
    if any(ch in text for ch in "*?["):
        files = [Path(p) for p in glob.glob(text)]
    elif Path(text).is_dir():
        files = [p for p in Path(text).iterdir() if p.name.endswith(SHARD_SUFFIXES) or ".tfrecord-" in p.name]
    elif Path(text).is_file():
        files = [Path(text)]
    else:
        raise FileNotFoundError(f"{text}: no such file, directory or matching glob")
    files = sorted(p for p in files if p.is_file() and not p.name.startswith("."))
    if not files:
        raise FileNotFoundError(f"{text}: no .tfrecord files found")
    return files


def iter_raw_records(path: str | os.PathLike) -> Iterator[tuple[Path, int, bytes]]:
    """Yields (file, record index, bytes) for every record under `path`."""
    for file in list_shard_files(path):
        try:
            for index, data in enumerate(iter_records(file)):
                yield file, index, data
        except RecordError as error:
            raise ShardReadError(str(error)) from None


def read_shards(path: str | os.PathLike, sizes: Sizes | None = None) -> Iterator[Scenario]:
    """Streams Scenarios from shard files (a directory, a file or a glob)."""
    for file, index, data in iter_raw_records(path):
        yield decode_record(data, file, index, sizes)


def decode_record(data: bytes, file: Path | str, index: int, sizes: Sizes | None = None) -> Scenario:
    try:
        return decode_scenario(data, sizes)
    except (ExampleError, SchemaError, UnicodeDecodeError) as error:
        raise ShardReadError(f"{file}: record {index}: {error}") from None


def write_shards(scenarios: Iterable[Scenario], out: str | os.PathLike, sizes: Sizes | None = None,
                 shard_size: int = 1000, split: str = "train") -> list[Path]:
    """Writes scenarios to `out/<split>-XXXXX-of-YYYYY.tfrecord` (sequential, no manifest).

    Use `scenariomax.pipeline.convert` for parallel, resumable conversions with a manifest.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    temp_files: list[Path] = []
    writer: TFRecordWriter | None = None
    for scenario in scenarios:
        if writer is None or writer.num_records >= shard_size:
            if writer is not None:
                writer.close()
            temp_files.append(out / f".{split}-{len(temp_files):05d}.tfrecord.tmp")
            writer = TFRecordWriter(temp_files[-1])
        writer.write(encode_scenario(scenario, sizes))
    if writer is not None:
        writer.close()
    final = [out / shard_name(split, i, len(temp_files)) for i in range(len(temp_files))]
    for temp, path in zip(temp_files, final):
        os.replace(temp, path)
    return final


__all__ = ["read_shards", "write_shards", "list_shard_files", "iter_raw_records", "ShardReadError",
           "RecordError", "shard_name", "decode_record"]

"""Small shard outputs for the manifest tests, and ways to damage a copy of one as a user or a crash would."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from scenariomax import write_shards
from scenariomax.pipeline import ConvertSettings, convert
from tests.foundation.toy_source import ToySource
from tests.inspect.scenes import SIZES, make_scenario

TOY_SIZES = SIZES  # 8 objects, 600 roadgraph points: records of ~77 kB


def write_output(out: Path, num_scenarios: int = 5, shard_size: int = 2) -> Path:
    """A write_shards output: `num_scenarios` hand-made scenes s0, s1, ... in shards of `shard_size`."""
    write_shards([make_scenario(f"s{i}") for i in range(num_scenarios)], out, sizes=SIZES, shard_size=shard_size)
    return out


def convert_output(out: Path) -> Path:
    """A pipeline output of the toy source: 23 scenarios in 5 shards (train-00000-of-00005 ... 00004)."""
    convert(ToySource(), ConvertSettings(out=out, sizes=TOY_SIZES, shard_size=5, progress=False, workers=1))
    return out


def copy_output(source: Path, out: Path) -> Path:
    shutil.copytree(source, out)
    return out


def load(out: Path) -> dict:
    return json.loads((out / "manifest.json").read_text())


def save(out: Path, manifest: dict) -> None:
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1))


def interrupt_during_renames(out: Path, num_renamed: int) -> None:
    """The folder as `pipeline._ShardSink.finalize` leaves it when killed after `num_renamed` final renames."""
    manifest = load(out)
    manifest["state"] = "finalizing"
    for index, shard in enumerate(manifest["shards"]):
        shard["temp_file"] = f".sealed-train-{index:05d}.tfrecord"
        if index >= num_renamed:
            (out / shard["file"]).rename(out / shard["temp_file"])
    save(out, manifest)


def shard_files(out: Path) -> list[Path]:
    return sorted(out.glob("*.tfrecord"))

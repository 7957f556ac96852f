"""Bytes per scenario of plain and gzip shards, and what gzip costs in conversion and reading time.

    python benchmarks/shard_sizes.py [--realdata ../shared/realdata] [--num-synthetic 20] [--repeats 2]

Converts each dataset twice into a temporary folder (`--compression none`, then `gzip`; one worker, enrichment
on, the CLI's default sizes) and prints the markdown table of docs/benchmarks.md ("Shard sizes"). Conversion
time is the pipeline's own (best of `--repeats`); read time is `read_shards` decoding every scenario.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import zlib
from pathlib import Path

from scenariomax import Sizes, read_shards
from scenariomax.enrich.transform import make_transform
from scenariomax.io.tfrecord import iter_records
from scenariomax.pipeline import ConvertSettings, convert
from scenariomax.sources.registry import make_source

REAL = [  # (label, dataset, path under the realdata folder)
    ("WOMD Scenario proto", "womd", "womd/motion_data_one_scenario.tfrecord"),
    ("WOMD tf.Example", "womd", "womd/motion_data_one_example.tfrecord"),
    ("AV2", "av2", "av2"),
    ("ScenarioNet nuScenes", "scenarionet", "scenarionet/nuscenes"),
    ("ScenarioNet WOMD 91 steps", "scenarionet", "scenarionet/womd_91steps"),
    ("GPUDrive JSON (WOMD)", "gpudrive", "gpudrive"),
]


def _convert(dataset: str, src: str | None, out: Path, compression: str, num_synthetic: int) -> tuple[int, float]:
    sizes = Sizes()
    source = make_source(dataset, src=src, sizes=sizes, num_scenarios=num_synthetic,
                         orient_edges=False)  # as `scenariomax convert`: the enrichment orients road edges
    transform, transform_settings = make_transform()
    settings = ConvertSettings(out=out, sizes=sizes, workers=1, progress=False, transform=transform,
                               transform_settings=transform_settings, compression=compression, overwrite=True)
    result = convert(source, settings)
    return result.num_scenarios, result.elapsed_s


def _shard_bytes(out: Path) -> int:
    return sum(path.stat().st_size for path in out.glob("*.tfrecord"))


def _read_s(out: Path) -> float:
    start = time.perf_counter()
    for _ in read_shards(out):
        pass
    return time.perf_counter() - start


def measure(label: str, dataset: str, src: str | None, root: Path, num_synthetic: int, repeats: int) -> dict:
    row: dict = {"label": label}
    for compression in ("none", "gzip"):
        out = root / f"{label.replace(' ', '_')}-{compression}"
        times = [_convert(dataset, src, out, compression, num_synthetic) for _ in range(repeats)]
        count = times[0][0]
        row[compression] = {"scenarios": count, "bytes": _shard_bytes(out), "convert_s": min(t for _, t in times),
                            "read_s": min(_read_s(out) for _ in range(repeats))}
    return row


def levels(root: Path) -> list[str]:
    """zlib level vs size and time (one record = one gzip member), on the synthetic records and on the real ones."""
    synthetic = list(iter_records(next((root / "synthetic-none").glob("*.tfrecord"))))
    real = [record for folder in sorted(root.glob("*-none")) if folder.name != "synthetic-none"
            for file in folder.glob("*.tfrecord") for record in iter_records(file)]
    lines = ["| records | zlib level | bytes vs plain | compress ms/scenario | decompress ms/scenario |",
             "|---|---|---|---|---|"]
    for label, records in (("synthetic", synthetic), (f"real ({len(real)})", real)):
        if not records:
            continue
        raw = sum(map(len, records))
        for level in (1, 3, 6, 9):
            start = time.perf_counter()
            packed = [zlib.compress(record, level) for record in records]
            compress = (time.perf_counter() - start) / len(records) * 1e3
            start = time.perf_counter()
            for blob in packed:
                zlib.decompress(blob)
            decompress = (time.perf_counter() - start) / len(records) * 1e3
            ratio = sum(map(len, packed)) / raw
            lines.append(f"| {label} | {level} | {ratio:.1%} | {compress:.1f} | {decompress:.1f} |")
    return lines


def table(rows: list[dict]) -> list[str]:
    lines = ["| data | scenarios | plain MB/scenario | gzip MB/scenario | gzip/plain "
             "| convert s/scenario plain -> gzip | read_shards ms/scenario plain -> gzip |",
             "|---|---|---|---|---|---|---|"]
    for row in rows:
        plain, packed = row["none"], row["gzip"]
        n = plain["scenarios"] or 1
        lines.append(
            f"| {row['label']} | {n} | {plain['bytes'] / n / 1e6:.3f} | {packed['bytes'] / n / 1e6:.3f} | "
            f"{packed['bytes'] / plain['bytes']:.1%} | {plain['convert_s'] / n:.3f} -> {packed['convert_s'] / n:.3f} | "
            f"{plain['read_s'] / n * 1e3:.1f} -> {packed['read_s'] / n * 1e3:.1f} |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realdata", default=str(Path(__file__).resolve().parents[1].parent / "shared" / "realdata"))
    parser.add_argument("--num-synthetic", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    realdata = Path(args.realdata)
    with tempfile.TemporaryDirectory(prefix="shard-sizes-") as tmp:
        root = Path(tmp)
        rows = [measure("synthetic", "synthetic", None, root, args.num_synthetic, args.repeats)]
        for label, dataset, path in REAL:
            if (realdata / path).exists():
                rows.append(measure(label, dataset, str(realdata / path), root, args.num_synthetic, args.repeats))
            else:
                print(f"(skipped {label}: {realdata / path} is absent)")
        print("\n".join(table(rows)))
        print()
        print("\n".join(levels(root)))


if __name__ == "__main__":
    main()

"""What `--engine ray` costs against `--engine process`: scenarios/s of the same synthetic conversion.

    python benchmarks/ray_overhead.py [--num-scenarios 40] [--repeats 2] [--workers 1 2] [--address HOST:PORT]
    python benchmarks/ray_overhead.py --driver-ceiling   # records/s the one writing process can take

Each run is the CLI in a fresh process (what a user types: enrichment on, the default sizes), so the ray rows
include starting a local Ray instance; with `--address` the same conversion also runs on that cluster (already
started: its rows are the steady-state cost, the object-store round trip of every unit's records). Runs are
interleaved, best of `--repeats`; the load average before and after is printed because the numbers are only
comparable on a quiet machine. Prints the markdown table of docs/scale.md.

`--driver-ceiling` times the part no cluster parallelises: the main process appending every record to the shards
(write, fsync at checkpoints, sha256 at each seal), fed with real synthetic records already in memory as Ray hands
them over, plain and gzip.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SUMMARY = re.compile(r"elapsed\s+([0-9.]+) s")


def _convert(out: Path, num_scenarios: int, engine: str, workers: int | None,
             address: str | None) -> tuple[float, float]:
    """(pipeline seconds as the summary reports them, wall seconds of the whole command)."""
    args = [sys.executable, "-m", "vmax_cli.scenariomax_cli", "convert", "--num-scenarios", str(num_scenarios),
            "--engine", engine, "--out", str(out), "--overwrite"]
    args += ["--workers", str(workers)] if workers else []
    args += ["--address", address] if address else []
    start = time.perf_counter()
    done = subprocess.run(args, capture_output=True, text=True, check=True)
    wall = time.perf_counter() - start
    return float(SUMMARY.search(done.stdout).group(1)), wall


def _configs(workers: list[int], address: str | None) -> list[tuple[str, str, int | None, str | None]]:
    rows = [(f"process, {w} worker{'s' * (w > 1)}", "process", w, None) for w in workers]
    rows += [(f"ray, local instance of {w} CPU{'s' * (w > 1)}", "ray", w, None) for w in workers]
    if address:
        rows.append(("ray, running cluster (--address)", "ray", None, address))
    return rows


def _driver_ceiling(num_records: int = 400, shard_size: int = 100) -> None:
    from scenariomax import Sizes
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings, UnitResult, _ShardSink, convert_unit_in_memory
    from scenariomax.sources.registry import make_source

    source = make_source("synthetic", num_scenarios=10)
    transform, transform_settings = make_transform()
    print("| shards | MB/record | records/s | MB/s |")
    print("|---|---:|---:|---:|")
    for compression in ("none", "gzip"):
        unit = source.list_units()[0]
        frames = convert_unit_in_memory(source, unit, Sizes(), transform, compression).records
        with tempfile.TemporaryDirectory() as tmp:
            settings = ConvertSettings(out=Path(tmp), shard_size=shard_size, compression=compression,
                                       transform_settings=transform_settings)
            units = [f"u{index}" for index in range(num_records // len(frames))]
            sink = _ShardSink(Path(tmp), source, settings, units, None)
            start = time.perf_counter()
            for name in units:
                sink.add_unit_result(UnitResult(name, None, frames, len(frames), ()))
            sink.finalize()
            seconds = time.perf_counter() - start
        megabytes = sum(map(len, frames)) / len(frames) / 1e6
        rate = len(units) * len(frames) / seconds
        print(f"| {compression} | {megabytes:.3f} | {rate:.0f} | {rate * megabytes:.0f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-scenarios", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--address", default=None)
    parser.add_argument("--driver-ceiling", action="store_true")
    args = parser.parse_args()
    if args.driver_ceiling:
        _driver_ceiling()
        return
    configs = _configs(args.workers, args.address)
    best: dict[str, tuple[float, float]] = {}
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeats):
            for label, engine, workers, address in configs:
                elapsed, wall = _convert(Path(tmp) / "out", args.num_scenarios, engine, workers, address)
                old = best.get(label)
                best[label] = (min(elapsed, old[0]), min(wall, old[1])) if old else (elapsed, wall)
    print(f"load average before {load_before[0]:.1f}, after {os.getloadavg()[0]:.1f}; "
          f"{args.num_scenarios} scenarios, best of {args.repeats}\n")
    print("| engine | pipeline s | scenarios/s | command wall s |")
    print("|---|---:|---:|---:|")
    for label, _, _, _ in configs:
        elapsed, wall = best[label]
        print(f"| {label} | {elapsed:.1f} | {args.num_scenarios / elapsed:.2f} | {wall:.1f} |")


if __name__ == "__main__":
    main()

"""Scenarios per second of the data loader, map indices built vs read from the cache:
`python benchmarks/loader.py [--data SHARDS] [--num-scenarios 400] [--batch-size 32] [--workers 0] [--json]`.

Four passes over the same scenarios through `make_data_iterator` (prefetch thread, device batches):
no map index (decode + crop only: the ceiling), map index built (cache off: the loader before the cache),
cold (built and written to an empty cache) and warm (every index read from the cache). The cache lives in a
temporary folder unless --cache-dir is given. Default data: the synthetic training shards `vmax-sim train`
generates (~/.cache/vmax_sim/synthetic/seed0-n400-objects64). Results go to docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import tempfile
import time
from pathlib import Path


def read_into_page_cache(path: str) -> None:
    """Reads the shard files once, so that no pass pays the first read from disk."""
    from scenariomax import list_shard_files

    for file in list_shard_files(path):
        with open(file, "rb") as stream:
            while stream.read(1 << 24):
                pass


def scenarios_per_second(config, num_scenarios: int) -> float:
    """Scenarios/s of `config`'s iterator over its first `num_scenarios` (whole batches), device-ready."""
    import jax

    from vmax_sim.data import make_data_iterator

    iterator = make_data_iterator(config)
    start = time.perf_counter()
    count = 0
    for batch in iterator:
        jax.block_until_ready(batch)
        count += int(batch.timestep.shape[0])
        if count >= num_scenarios:
            break
    elapsed = time.perf_counter() - start
    if hasattr(iterator, "close"):
        iterator.close()
    return count / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=None, help="shard folder, file or glob (default: the synthetic shards)")
    parser.add_argument("--num-scenarios", type=int, default=400)
    parser.add_argument("--batch-size", type=int, default=32)
    parser.add_argument("--workers", type=int, default=0, help="DataConfig.num_workers")
    parser.add_argument("--cache-dir", default=None, help="VMAX_CACHE_DIR for the cold and warm passes "
                                                           "(default: a temporary folder, removed at the end)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()

    from vmax_sim.data import DataConfig, cache_dir

    args.data = args.data or str(cache_dir() / "synthetic" / "seed0-n400-objects64")
    if not Path(args.data.split("*")[0]).exists():
        parser.exit(2, f"{args.data}: no such shards; run `vmax-sim train` once (it generates them) or pass --data\n")

    read_into_page_cache(args.data)
    with tempfile.TemporaryDirectory(prefix="vmax-loader-bench-") as temp:
        os.environ["VMAX_CACHE_DIR"] = args.cache_dir or temp
        os.environ.pop("VMAX_MAP_INDEX_CACHE", None)
        base = DataConfig(path=args.data, batch_size=args.batch_size, num_objects=64, num_workers=args.workers)
        passes = {
            "no map index": dataclasses.replace(base, include_map_index=False),
            "map index built (cache off)": dataclasses.replace(base, map_index_cache=False),
            "cold cache (built + written)": base,
            "warm cache (read)": base,
        }
        results = {name: scenarios_per_second(config, args.num_scenarios) for name, config in passes.items()}
    if args.json:
        print(json.dumps({"data": args.data, "batch_size": args.batch_size, "workers": args.workers,
                          "scenarios_per_s": results}))
        return
    print(f"{args.data}: {args.num_scenarios} scenarios, batch {args.batch_size}, {args.workers} workers, "
          f"{os.cpu_count()} cores")
    for name, rate in results.items():
        print(f"  {name:<30} {rate:8.1f} scenarios/s")


if __name__ == "__main__":
    main()

"""Throughput of the scenariomax half, one process (= one core) per measurement.

- records read + decoded to Scenario per second at 30000 roadgraph points (goal >= 300/s/core);
- synthetic scenarios generated (+ enriched) and written per second;
- conversion of each real sample (scenarios/s, peak RSS of the worker);
- build-sdc-paths (enrichment) scenarios/s on the real WOMD tf.Example.

Usage: python benchmarks/io_and_conversion.py [--json]
Numbers go to docs/benchmarks.md with the machine they were taken on.
"""

from __future__ import annotations

import json
import os
import platform
import resource
import sys
import tempfile
import time
from pathlib import Path

REALDATA = Path(__file__).resolve().parents[1].parent / "shared" / "realdata"


def _rate(count: int, seconds: float) -> float:
    return count / seconds if seconds > 0 else float("nan")


def bench_read_decode(num_records: int = 200) -> dict:
    from scenariomax import read_shards, write_shards
    from scenariomax.sources.synthetic import generate_scenario

    scenarios = [generate_scenario(0, i) for i in range(20)]
    with tempfile.TemporaryDirectory() as tmp:
        write_shards(scenarios * (num_records // len(scenarios)), tmp)
        for _ in read_shards(tmp):  # warm the page cache
            pass
        start = time.perf_counter()
        count = sum(1 for _ in read_shards(tmp))
        elapsed = time.perf_counter() - start
    return {"records": count, "records_per_s": _rate(count, elapsed), "roadgraph_points": 30000}


def bench_synthetic(num: int = 40) -> dict:
    from scenariomax import Sizes
    from scenariomax.codec import encode_scenario
    from scenariomax.enrich import EnrichSettings, enrich_scenario
    from scenariomax.sources.synthetic import generate_scenario

    sizes = Sizes()
    start = time.perf_counter()
    scenarios = [generate_scenario(1, i, sizes) for i in range(num)]
    generated = time.perf_counter()
    enriched = [enrich_scenario(s, EnrichSettings()) for s in scenarios]
    enriched_t = time.perf_counter()
    for s in enriched:
        encode_scenario(s, sizes)
    done = time.perf_counter()
    return {
        "scenarios": num,
        "generate_per_s": _rate(num, generated - start),
        "enrich_per_s": _rate(num, enriched_t - generated),
        "encode_per_s": _rate(num, done - enriched_t),
        "end_to_end_per_s": _rate(num, done - start),
    }


def bench_source(dataset: str, src: Path, repeats: int = 5) -> dict:
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import prepare_scenario
    from scenariomax.schema import Sizes
    from scenariomax.sources.base import Failure
    from scenariomax.sources.registry import make_source

    if not src.exists():
        return {"skipped": f"{src} not found"}
    sizes = Sizes()
    source = make_source(dataset, src=str(src), sizes=sizes)
    transform, _ = make_transform(True)
    results = {}
    for label, fn in (("convert", None), ("convert+enrich", transform)):
        count, start = 0, time.perf_counter()
        for _ in range(repeats):
            for unit in source.list_units():
                for item in source.read_unit(unit):
                    if not isinstance(item, Failure):
                        prepare_scenario(item, sizes, fn)
                        count += 1
        results[f"{label}_per_s"] = _rate(count, time.perf_counter() - start)
    results["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return results


def main() -> None:
    report = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, {platform.system()}",
        "read_decode": bench_read_decode(),
        "synthetic": bench_synthetic(),
        "sources": {
            "womd_scenario": bench_source("womd", REALDATA / "womd" / "motion_data_one_scenario.tfrecord"),
            "womd_tf_example": bench_source("womd", REALDATA / "womd" / "motion_data_one_example.tfrecord"),
            "av2": bench_source("av2", REALDATA / "av2"),
            "scenarionet": bench_source("scenarionet", REALDATA / "scenarionet"),
        },
    }
    if "--json" in sys.argv:
        print(json.dumps(report, indent=1))
        return
    print(f"machine: {report['machine']}")
    rd = report["read_decode"]
    print(f"read+decode: {rd['records_per_s']:.0f} records/s (30000 roadgraph points, {rd['records']} records)")
    syn = report["synthetic"]
    print("synthetic: generate {generate_per_s:.1f}/s, enrich {enrich_per_s:.1f}/s, encode {encode_per_s:.1f}/s, "
          "end to end {end_to_end_per_s:.1f}/s".format(**syn))
    for name, values in report["sources"].items():
        print(f"{name}: " + ", ".join(f"{k} {v:.1f}" if isinstance(v, float) else f"{k} {v}"
                                      for k, v in values.items()))


if __name__ == "__main__":
    main()

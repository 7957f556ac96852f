"""Throughput of the scenariomax half, one process (= one core) per measurement.

- records read + decoded to Scenario per second at 30000 roadgraph points (goal >= 300/s/core);
- synthetic scenarios generated (+ enriched) and written per second;
- conversion of each real sample (scenarios/s, peak RSS of the worker): read, sanity repairs, enrichment
  (or not), budget fit, validation and encoding, as a pipeline worker does them; the median of several passes,
  per second of process CPU time (robust on a shared machine) and of wall time;
- build-sdc-paths (enrichment) scenarios/s on the real WOMD tf.Example.

Usage: python benchmarks/io_and_conversion.py [--json] [--sources-only]
Numbers go to docs/benchmarks.md with the machine they were taken on. To measure another tree (e.g. the
commit before a change), put its root first: PYTHONPATH=/path/to/old/tree python benchmarks/...
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


def _median(values: list[float]) -> float:
    ordered = sorted(values)
    return ordered[len(ordered) // 2]


def bench_source(dataset: str, src: Path, min_seconds: float = 6.0, min_passes: int = 3) -> dict:
    """Scenarios/s of one real sample through a pipeline worker's steps: medians over passes (each pass reads
    every file once), per second of CPU time and of wall time."""
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import SANITIZED_SOURCES, prepare_scenario, sanitize_scenario
    from scenariomax.schema import Sizes
    from scenariomax.sources.base import Failure
    from scenariomax.sources.registry import make_source

    if not src.exists():
        return {"skipped": f"{src} not found"}
    try:  # as every conversion worker does (absent from trees before 2026-12-01)
        from scenariomax._allocator import keep_freed_memory

        keep_freed_memory()
    except ImportError:
        pass
    sizes = Sizes()
    transform, _ = make_transform(True)

    def one_pass(source, fn) -> int:
        count = 0
        for unit in source.list_units():
            for item in source.read_unit(unit):
                if not isinstance(item, Failure):
                    item = sanitize_scenario(item) if source.name in SANITIZED_SOURCES else item
                    prepare_scenario(item, sizes, fn)
                    count += 1
        return count

    results = {}
    for label, fn in (("convert", None), ("convert+enrich", transform)):
        # as `scenariomax convert`: a source orients road edges only when no enrichment (which orients them) follows
        source = make_source(dataset, src=str(src), sizes=sizes, orient_edges=fn is None)
        one_pass(source, fn)  # warm-up: imports, caches
        cpu, wall, stop = [], [], time.perf_counter() + min_seconds
        while len(cpu) < min_passes or time.perf_counter() < stop:
            cpu_start, wall_start = time.process_time(), time.perf_counter()
            count = one_pass(source, fn)
            cpu.append(_rate(count, time.process_time() - cpu_start))
            wall.append(_rate(count, time.perf_counter() - wall_start))
        results[f"{label}_per_cpu_s"] = _median(cpu)
        results[f"{label}_per_s"] = _median(wall)
    results["peak_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return results


def main() -> None:
    report = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, {platform.system()}",
        "load_average": os.getloadavg(),
        "sources": {
            "womd_scenario": bench_source("womd", REALDATA / "womd" / "motion_data_one_scenario.tfrecord"),
            "womd_tf_example": bench_source("womd", REALDATA / "womd" / "motion_data_one_example.tfrecord"),
            "gpudrive_json": bench_source("gpudrive", REALDATA / "gpudrive"),
            "av2": bench_source("av2", REALDATA / "av2"),
            "scenarionet": bench_source("scenarionet", REALDATA / "scenarionet"),
        },
    }
    if "--sources-only" not in sys.argv:
        report["read_decode"] = bench_read_decode()
        report["synthetic"] = bench_synthetic()
    report["load_average_after"] = os.getloadavg()
    if "--json" in sys.argv:
        print(json.dumps(report, indent=1))
        return
    print(f"machine: {report['machine']}; load average {report['load_average']} -> {report['load_average_after']}")
    if "read_decode" in report:
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

"""The conversion pipeline shared by every source: units -> workers -> shards + manifest.

Workers turn a unit (a raw file, or a chunk of synthetic seeds) into encoded records written to a
private file under `OUT/.work/`; the main process appends them, in unit order, to shards of
`shard_size` records. A shard is sealed (fsync + rename) when full and the manifest is rewritten
atomically after every seal, recording how many records of each unit are sealed. Because sources
are deterministic, `--resume` re-runs unfinished units and skips their sealed records: nothing is
lost or duplicated after a crash or `kill -9`. At the end shards get their final names
`<split>-XXXXX-of-YYYYY.tfrecord`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import multiprocessing
import os
import shutil
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from scenariomax.codec import encode_scenario
from scenariomax.enrich.budget import fit_to_budget
from scenariomax.io.tfrecord import TFRecordWriter, iter_records
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes, load_schema
from scenariomax.shards import shard_name
from scenariomax.sources.base import MANIFEST_NOTES, Failure, InputError, Source

MANIFEST = "manifest.json"
WORK_DIR = ".work"

Transform = Callable[[Scenario], Scenario]


class ConversionError(RuntimeError):
    """The conversion cannot start or continue (bad output dir, settings mismatch on resume...)."""


@dataclasses.dataclass(frozen=True)
class ConvertSettings:
    out: Path
    split: str = "train"
    shard_size: int = 1000
    workers: int | None = None  # None: one per core
    resume: bool = False
    sizes: Sizes = dataclasses.field(default_factory=Sizes)
    engine: str = "process"  # "process" | "ray"
    ray_address: str | None = None
    progress: bool = True
    transform: Transform | None = None  # enrichment applied to every scenario before the budget fit
    transform_settings: dict = dataclasses.field(default_factory=dict)  # recorded in the manifest


@dataclasses.dataclass(frozen=True)
class UnitResult:
    unit: str
    records_path: str | None  # file of framed records (process engine)
    records: tuple[bytes, ...] | None  # in-memory records (ray engine)
    num_records: int
    failures: tuple[Failure, ...]
    peak_rss_mib: float = 0.0  # the worker's peak resident memory so far (reported in the manifest)
    notes: tuple[dict, ...] = ()  # {"unit", "scenario", "notes"} of written scenarios that carry manifest notes


@dataclasses.dataclass(frozen=True)
class ConversionResult:
    out: Path
    num_units: int
    num_units_skipped: int  # already finished before a --resume
    num_scenarios: int
    num_failures: int
    shards: tuple[str, ...]
    elapsed_s: float
    failures: tuple[dict, ...]

    @property
    def ok(self) -> bool:
        return self.num_failures == 0

    def summary_rows(self) -> list[tuple[str, str]]:
        rate = self.num_scenarios / self.elapsed_s if self.elapsed_s > 0 else 0.0
        return [
            ("output", str(self.out)),
            ("inputs", f"{self.num_units} ({self.num_units_skipped} already done)"),
            ("scenarios written", str(self.num_scenarios)),
            ("failures", str(self.num_failures)),
            ("shards", str(len(self.shards))),
            ("elapsed", f"{self.elapsed_s:.1f} s"),
            ("throughput", f"{rate:.1f} scenarios/s"),
        ]


def _one_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    message = text[0] if text else ""
    return f"{type(error).__name__}: {message}" if not isinstance(error, (InputError, ValueError)) else message


def prepare_scenario(scenario: Scenario, sizes: Sizes, transform: Transform | None) -> bytes:
    """Enrich, fit to budget, validate and encode one scenario. Raises ValueError on problems."""
    if transform is not None:
        scenario = transform(scenario)
    scenario = fit_to_budget(scenario, sizes)
    problems = scenario.validate()
    if problems:
        raise ValueError("; ".join(problems[:3]))
    return encode_scenario(scenario, sizes)


def _iter_unit_records(source: Source, unit: str, sizes: Sizes, transform: Transform | None,
                       failures: list[Failure], notes: list[dict] | None = None) -> Iterator[bytes]:
    position = 0
    try:
        for item in source.read_unit(unit):
            if isinstance(item, Failure):
                failures.append(item)
                continue
            try:
                record = prepare_scenario(item, sizes, transform)
            except Exception as error:  # per-scenario isolation: record and continue
                failures.append(Failure(unit, item.scenario_id or f"#{position}", _one_line(error)))
            else:
                if notes is not None and item.metadata.get(MANIFEST_NOTES):
                    notes.append({"unit": unit, "scenario": item.scenario_id, "notes": item.metadata[MANIFEST_NOTES]})
                yield record
            position += 1
    except InputError as error:
        failures.append(Failure(unit, "*", _one_line(error)))
    except Exception as error:  # a reader bug must not kill the run either
        failures.append(Failure(unit, "*", f"{unit}: {_one_line(error)}"))


def convert_unit_to_file(source: Source, unit: str, work_dir: str, sizes: Sizes,
                         transform: Transform | None) -> UnitResult:
    """Worker: converts one unit into a private record file (memory stays bounded)."""
    failures: list[Failure] = []
    notes: list[dict] = []
    digest = hashlib.sha1(unit.encode()).hexdigest()[:16]
    temp = Path(work_dir) / f"unit-{digest}.tmp"
    final = Path(work_dir) / f"unit-{digest}.rec"
    with TFRecordWriter(temp) as writer:
        for record in _iter_unit_records(source, unit, sizes, transform, failures, notes):
            writer.write(record)
        count = writer.num_records
    os.replace(temp, final)
    return UnitResult(unit, str(final), None, count, tuple(failures), _peak_rss_mib(), tuple(notes))


def convert_unit_in_memory(source: Source, unit: str, sizes: Sizes, transform: Transform | None) -> UnitResult:
    """Ray task body: records travel back through the object store (works across machines)."""
    failures: list[Failure] = []
    notes: list[dict] = []
    records = tuple(_iter_unit_records(source, unit, sizes, transform, failures, notes))
    return UnitResult(unit, None, records, len(records), tuple(failures), _peak_rss_mib(), tuple(notes))


def _peak_rss_mib() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux reports KiB


def _convert_unit_star(args) -> UnitResult:
    return convert_unit_to_file(*args)


# --------------------------------------------------------------------------------------------------
# Manifest and shard bookkeeping (main process only).


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _write_json_atomic(path: Path, data: dict) -> None:
    temp = path.with_name(f".{path.name}.tmp")
    with open(temp, "w") as stream:
        json.dump(data, stream, indent=1, sort_keys=False)
        stream.flush()
        os.fsync(stream.fileno())
    os.replace(temp, path)


def _run_settings(source: Source, settings: ConvertSettings) -> dict:
    return {
        "source": source.settings(),
        "split": settings.split,
        "shard_size": settings.shard_size,
        "sizes": settings.sizes.as_dict(),
        "transform": settings.transform_settings,
    }


class _ShardSink:
    """Appends records to sealed shards and keeps the manifest in step with what is on disk."""

    def __init__(self, out: Path, source: Source, settings: ConvertSettings, units: Sequence[str]):
        self.out = out
        self.settings = settings
        self.path = out / MANIFEST
        run_settings = _run_settings(source, settings)
        if settings.resume and self.path.exists():
            self.manifest = json.loads(self.path.read_text())
            if self.manifest.get("settings") != run_settings:
                raise ConversionError(f"{self.path}: settings differ from the interrupted run; "
                                      "rerun with the same options or use a new --out")
        else:
            self.manifest = {
                "schema": {"name": load_schema().name, "version": load_schema().version},
                "source_dataset": source.name,
                "settings": run_settings,
                "state": "running",
                "counts": {},
                "shards": [],
                "units": {unit: {"sealed_records": 0, "done": False, "num_records": 0} for unit in units},
                "failures": [],
                "notes": [],  # per-scenario decisions and repairs the source reports (see MANIFEST_NOTES)
            }
        self.open_writer: TFRecordWriter | None = None
        self.open_path: Path | None = None
        self.open_units: dict[str, int] = {}  # unit -> records in the open shard
        self.finished_units: set[str] = set()  # all records handed over (maybe not yet sealed)
        self.pending_failures: dict[str, list[dict]] = {}
        self.pending_notes: dict[str, list[dict]] = {}

    # Units -----------------------------------------------------------------------------------------
    def unit_state(self, unit: str) -> dict:
        return self.manifest["units"].setdefault(unit, {"sealed_records": 0, "done": False, "num_records": 0})

    def add_unit_result(self, result: UnitResult) -> int:
        """Appends a unit's records, skipping those already sealed by an earlier run."""
        skip = self.unit_state(result.unit)["sealed_records"]
        written = 0
        for index, record in enumerate(self._records(result)):
            if index < skip:
                continue
            self._append(result.unit, record)
            written += 1
        if result.records_path:
            Path(result.records_path).unlink(missing_ok=True)
        self.unit_state(result.unit)["num_records"] = result.num_records
        self.manifest["peak_worker_rss_mib"] = round(max(self.manifest.get("peak_worker_rss_mib", 0.0),
                                                         result.peak_rss_mib), 1)
        self.pending_failures[result.unit] = [dataclasses.asdict(f) for f in result.failures]
        self.pending_notes[result.unit] = list(result.notes)
        self.finished_units.add(result.unit)
        if result.unit not in self.open_units:
            self._mark_done(result.unit)
            self._save()
        return written

    @staticmethod
    def _records(result: UnitResult) -> Iterator[bytes]:
        if result.records is not None:
            yield from result.records
        elif result.records_path:
            yield from iter_records(result.records_path)

    def _mark_done(self, unit: str) -> None:
        state = self.unit_state(unit)
        state["done"] = True
        self.manifest["failures"] = [f for f in self.manifest["failures"] if f["unit"] != unit]
        self.manifest["failures"] += self.pending_failures.pop(unit, [])
        notes = [n for n in self.manifest.get("notes", []) if n["unit"] != unit] + self.pending_notes.pop(unit, [])
        self.manifest["notes"] = notes

    # Shards ----------------------------------------------------------------------------------------
    def _append(self, unit: str, record: bytes) -> None:
        if self.open_writer is None:
            index = len(self.manifest["shards"])
            self.open_path = self.out / f".sealing-{self.settings.split}-{index:05d}.tfrecord"
            self.open_writer = TFRecordWriter(self.open_path)
        self.open_writer.write(record)
        self.open_units[unit] = self.open_units.get(unit, 0) + 1
        if self.open_writer.num_records >= self.settings.shard_size:
            self.seal()

    def seal(self) -> None:
        if self.open_writer is None:
            return
        self.open_writer.close()
        index = len(self.manifest["shards"])
        sealed = self.out / f".sealed-{self.settings.split}-{index:05d}.tfrecord"
        os.replace(self.open_path, sealed)
        self.manifest["shards"].append({"file": sealed.name, "num_records": self.open_writer.num_records,
                                        "sha256": _sha256(sealed)})
        for unit, count in self.open_units.items():
            self.unit_state(unit)["sealed_records"] += count
            if unit in self.finished_units:
                self._mark_done(unit)
        self.open_writer, self.open_path, self.open_units = None, None, {}
        self._save()

    def _save(self) -> None:
        units = self.manifest["units"].values()
        self.manifest["counts"] = {
            "units": len(self.manifest["units"]),
            "units_done": sum(u["done"] for u in units),
            "scenarios": sum(s["num_records"] for s in self.manifest["shards"]),
            "failures": len(self.manifest["failures"]),
        }
        _write_json_atomic(self.path, self.manifest)

    def finalize(self) -> list[str]:
        """Seals the last shard and gives every shard its final `-of-` name (crash-safe)."""
        self.seal()
        shards = self.manifest["shards"]
        if self.manifest["state"] != "finalizing":
            for index, shard in enumerate(shards):
                shard["temp_file"] = shard["file"]
                shard["file"] = shard_name(self.settings.split, index, len(shards))
            self.manifest["state"] = "finalizing"
            self._save()
        for shard in shards:
            temp = self.out / shard.get("temp_file", shard["file"])
            if temp.exists():
                os.replace(temp, self.out / shard["file"])
        for shard in shards:
            shard.pop("temp_file", None)
        self.manifest["state"] = "complete"
        self._save()
        return [shard["file"] for shard in shards]


# --------------------------------------------------------------------------------------------------


def _prepare_out(out: Path, resume: bool) -> None:
    manifest = out / MANIFEST
    if out.exists() and not resume and manifest.exists():
        raise ConversionError(f"{out}: already holds a conversion (manifest.json); "
                              "use --resume to continue it or choose a new --out")
    out.mkdir(parents=True, exist_ok=True)
    if not resume or not manifest.exists():
        for stale in list(out.glob(".sealing-*")) + list(out.glob(".sealed-*")):
            stale.unlink()
    work = out / WORK_DIR
    if work.exists():
        shutil.rmtree(work)  # leftovers of a killed run are recomputed
    work.mkdir()


def _results_process(source: Source, units: Sequence[str], settings: ConvertSettings, work: Path,
                     workers: int) -> Iterator[UnitResult]:
    tasks = [(source, unit, str(work), settings.sizes, settings.transform) for unit in units]
    if workers <= 1 or len(tasks) <= 1:
        for task in tasks:
            yield _convert_unit_star(task)
        return
    # forkserver: safe even when the caller has JAX/threads loaded. Results are taken in unit order
    # (deterministic shards) with a bounded number of units in flight (bounded memory and disk).
    # Unlike multiprocessing.Pool, the executor fails loudly if a worker dies (e.g. OOM-killed).
    context = multiprocessing.get_context("forkserver")
    window = 2 * workers
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        pending: deque = deque()
        next_task = 0
        while next_task < len(tasks) or pending:
            while next_task < len(tasks) and len(pending) < window:
                pending.append((tasks[next_task][1], pool.submit(_convert_unit_star, tasks[next_task])))
                next_task += 1
            unit, future = pending.popleft()
            try:
                yield future.result()
            except BrokenProcessPool:
                raise ConversionError(f"a worker process died while converting {unit} (out of memory?); "
                                      "rerun with --resume to continue") from None


def _results_ray(source: Source, units: Sequence[str], settings: ConvertSettings, workers: int) -> Iterator[UnitResult]:
    try:
        import ray  # optional extra
    except ImportError:
        raise ConversionError("--engine ray needs the ray extra: pip install 'vmax[ray]'") from None
    if not ray.is_initialized():
        if settings.ray_address:
            ray.init(address=settings.ray_address, ignore_reinit_error=True, log_to_driver=False)
        else:
            ray.init(num_cpus=workers, ignore_reinit_error=True, log_to_driver=False, include_dashboard=False)
    remote = ray.remote(convert_unit_in_memory)
    window = max(2 * workers, 2)  # bounded number of units in flight
    refs: list = []
    next_unit = 0
    while next_unit < len(units) or refs:
        while next_unit < len(units) and len(refs) < window:
            refs.append(remote.remote(source, units[next_unit], settings.sizes, settings.transform))
            next_unit += 1
        yield ray.get(refs.pop(0))  # in order, so shards are deterministic


def convert(source: Source, settings: ConvertSettings) -> ConversionResult:
    """Runs a conversion (see module docstring). Returns counts; never raises for bad inputs."""
    start = time.perf_counter()
    out = Path(settings.out)
    try:
        units = list(source.list_units())
    except InputError as error:
        raise ConversionError(str(error)) from None
    if not units:
        where = getattr(source, "src", None)
        raise ConversionError(f"{where + ': ' if where else ''}no {source.name} inputs found, nothing to convert")
    _prepare_out(out, settings.resume)
    sink = _ShardSink(out, source, settings, units)
    if sink.manifest["state"] == "complete":
        todo: list[str] = []
    else:
        todo = [unit for unit in units if not sink.unit_state(unit)["done"]]
    skipped = len(units) - len(todo)
    workers = settings.workers or os.cpu_count() or 1
    if settings.engine == "ray":
        results = _results_ray(source, todo, settings, workers)
    elif settings.engine == "process":
        results = _results_process(source, todo, settings, out / WORK_DIR, workers)
    else:
        raise ConversionError(f"unknown engine {settings.engine!r} (use 'process' or 'ray')")
    progress = _progress_bar(settings.progress, getattr(source, "expected_num_scenarios", lambda: None)())
    try:
        for result in results:
            written = sink.add_unit_result(result)
            progress.update(written)
            progress.set_postfix(
                failures=len(sink.manifest["failures"]) + sum(map(len, sink.pending_failures.values())))
    finally:
        progress.close()
    shards = sink.finalize()
    shutil.rmtree(out / WORK_DIR, ignore_errors=True)
    manifest = sink.manifest
    return ConversionResult(
        out=out, num_units=len(units), num_units_skipped=skipped,
        num_scenarios=manifest["counts"]["scenarios"], num_failures=len(manifest["failures"]),
        shards=tuple(shards), elapsed_s=time.perf_counter() - start, failures=tuple(manifest["failures"]),
    )


def _progress_bar(enabled: bool, total: int | None):
    from tqdm import tqdm

    return tqdm(total=total, unit="scenario", disable=not enabled, dynamic_ncols=True, desc="converting")


def read_manifest(out: str | os.PathLike) -> dict:
    path = Path(out) / MANIFEST
    if not path.exists():
        raise FileNotFoundError(f"{path}: no manifest (not a conversion output)")
    return json.loads(path.read_text())

"""The conversion pipeline shared by every source: units -> workers -> shards + manifest.

Workers turn a unit (a raw file, or a chunk of synthetic seeds) into encoded records written to a
private file under `OUT/.work/`; the main process appends them, in unit order, to shards of
`shard_size` records. The manifest is written before any other file and rewritten atomically after
every seal and every few seconds (a checkpoint of the open shard: its byte length is fsynced and
recorded), so it always lists every file the run created and how many records of each unit are safe
on disk. Because sources are deterministic, `--resume` truncates the open shard to its checkpoint,
re-runs unfinished units and skips their saved records: a kill loses at most the units in flight
and the last few seconds, and the resumed output equals an uninterrupted one byte for byte. At the
end shards get their final names `<split>-XXXXX-of-YYYYY.tfrecord`.

Ownership: a run writes only into a new or empty folder, or one whose manifest it continues
(`--resume`, same inputs and settings) or replaces (`--overwrite`, which deletes only the files
that manifest lists). Worker processes watch the main process and exit when it is gone.
"""

from __future__ import annotations

import dataclasses
import hashlib
import multiprocessing
import os
import re
import shutil
import socket
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from scenariomax._allocator import keep_freed_memory
from scenariomax._lifeline import exit_with_parent, watch_process
from scenariomax.codec import encode_scenario
from scenariomax.enrich.budget import fit_to_budget
from scenariomax.errors import InputError, describe_os_error
from scenariomax.io.gzip_members import COMPRESSIONS
from scenariomax.io.tfrecord import frame_for, write_framed
from scenariomax.locks import LOCK_FILE, FolderBusyError, FolderLock
from scenariomax.manifest import (
    MANIFEST,
    MANIFEST_TEMP,
    ManifestError,
    read_manifest,
    write_manifest,
)
from scenariomax.progress import Progress
from scenariomax.scenario import Scenario
from scenariomax.schema import Sizes, load_schema
from scenariomax.shards import shard_name
from scenariomax.sources.base import MANIFEST_NOTES, Failure, Source
from scenariomax.sources.sanity import SANITIZED_SOURCES, sanitize_scenario

WORK_DIR = ".work"
CHECKPOINT_EVERY_S = 2.0  # at most this much appended work is lost to a kill (plus the units in flight)
SPLIT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")

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
    overwrite: bool = False  # replace a finished or interrupted conversion (only the files its manifest lists)
    sizes: Sizes = dataclasses.field(default_factory=Sizes)
    engine: str = "process"  # "process" | "ray"
    ray_address: str | None = None
    progress: bool = True
    transform: Transform | None = None  # enrichment applied to every scenario before the budget fit
    transform_settings: dict = dataclasses.field(default_factory=dict)  # recorded in the manifest
    compression: str = "none"  # "gzip": TFRecord GZIP shards, one gzip member per record (see scenariomax.io)


@dataclasses.dataclass(frozen=True)
class UnitResult:
    unit: str
    records_path: str | None  # file of shard-ready frames back to back (process engine): `frame_for` of each record
    records: tuple[bytes, ...] | None  # in-memory shard-ready frames (ray engine): `frame_for` of each record
    num_records: int
    failures: tuple[Failure, ...]
    peak_rss_mib: float = 0.0  # the worker's peak resident memory so far (reported in the manifest)
    notes: tuple[dict, ...] = ()  # {"unit", "scenario", "notes"} of written scenarios that carry manifest notes
    frame_sizes: tuple[int, ...] = ()  # bytes of each frame in `records_path`, in order


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
    notes: tuple[dict, ...] = ()  # the manifest's {"unit", "scenario", "notes"}: what was repaired or is doubtful

    @property
    def ok(self) -> bool:
        return self.num_failures == 0 and self.num_scenarios > 0

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
        ] + ([("notes", notes_summary(self.notes))] if self.notes else [])


def notes_summary(notes: tuple[dict, ...] | list[dict]) -> str:
    """`N scenarios (note 3, other 1; see manifest.json)`: how many scenarios carry each kind of note."""
    counts: dict[str, int] = {}
    for entry in notes:
        for key in entry["notes"]:
            counts[key] = counts.get(key, 0) + 1
    kinds = ", ".join(f"{key} {count}" for key, count in sorted(counts.items()))
    return f"{len(notes)} scenario{'s' * (len(notes) != 1)} ({kinds}; see manifest.json)"


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
    keep_freed_memory()  # every engine's worker (and an in-process conversion) comes through here
    position = 0
    try:
        for item in source.read_unit(unit):
            if isinstance(item, Failure):
                failures.append(item)
                continue
            try:
                if source.name in SANITIZED_SOURCES:  # physical sanity of every real source, noted per scenario
                    item = sanitize_scenario(item)
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
        failures.append(Failure(unit, "*", _one_line(error)))  # the failure's unit names the file


def convert_unit_to_file(source: Source, unit: str, work_dir: str, sizes: Sizes,
                         transform: Transform | None, compression: str = "none") -> UnitResult:
    """Worker: converts one unit into a private record file (memory stays bounded). Each record there is the
    bytes its shard will hold (compressed here, so compression runs in parallel in the workers)."""
    failures: list[Failure] = []
    notes: list[dict] = []
    temp, final = (Path(work_dir) / name for name in unit_work_files(unit))
    # The frames as the shard will hold them, back to back, and their sizes: the main process copies them over as
    # they are (no second framing to strip, no CRC to check again). Not synced: a run never reads another's.
    sizes_written: list[int] = []
    with open(temp, "wb") as stream:
        for record in _iter_unit_records(source, unit, sizes, transform, failures, notes):
            sizes_written.append(write_framed(stream, record, compression))
    os.replace(temp, final)
    return UnitResult(unit, str(final), None, len(sizes_written), tuple(failures), _peak_rss_mib(), tuple(notes),
                      tuple(sizes_written))


def unit_work_files(unit: str) -> tuple[str, str]:
    """The names of a unit's private files under `.work/` (in progress, finished): derived from the unit id,
    so the manifest's unit list names every work file a run can leave behind."""
    digest = hashlib.sha1(unit.encode()).hexdigest()[:16]
    return f"unit-{digest}.tmp", f"unit-{digest}.rec"


def convert_unit_in_memory(source: Source, unit: str, sizes: Sizes, transform: Transform | None,
                           compression: str = "none") -> UnitResult:
    """Ray task body: shard-ready frames travel back through the object store (works across machines)."""
    failures: list[Failure] = []
    notes: list[dict] = []
    records = tuple(frame_for(record, compression)
                    for record in _iter_unit_records(source, unit, sizes, transform, failures, notes))
    return UnitResult(unit, None, records, len(records), tuple(failures), _peak_rss_mib(), tuple(notes))


def _peak_rss_mib() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux reports KiB


def _convert_unit_star(args) -> UnitResult:
    return convert_unit_to_file(*args)


# --------------------------------------------------------------------------------------------------
# Manifest and shard bookkeeping (main process only).


def _run_settings(source: Source, settings: ConvertSettings) -> dict:
    return {
        "source": source.settings(),
        "split": settings.split,
        "shard_size": settings.shard_size,
        "sizes": settings.sizes.as_dict(),
        "transform": settings.transform_settings,
        "compression": settings.compression,
    }


class _OpenShard:
    """The shard being filled: framed records appended to a hidden file; `checkpoint` makes them durable."""

    def __init__(self, path: Path, num_records: int = 0, keep_bytes: int | None = None):
        self.path = path
        # The manifest's sha256, hashed as the bytes are written (reading the sealed shard back cost ~3% of a
        # conversion).
        self._digest = hashlib.sha256()
        if keep_bytes is None:
            self._stream = open(path, "wb")
        else:  # resume: drop whatever was appended after the last checkpoint
            self._stream = open(path, "r+b")
            self._stream.truncate(keep_bytes)
            for block in iter(lambda: self._stream.read(1 << 20), b""):
                self._digest.update(block)
            self._stream.seek(keep_bytes)
        self.num_records = num_records

    def write(self, frame: bytes) -> None:
        """Appends one record as `frame_for` made it (plain frame or gzip member: the shard's compression)."""
        self._stream.write(frame)
        self._digest.update(frame)
        self.num_records += 1

    def sha256(self) -> str:
        """The sha256 of every byte in the file so far."""
        return self._digest.hexdigest()

    def checkpoint(self) -> int:
        """Flushes to disk; returns the durable length in bytes."""
        self._stream.flush()
        os.fsync(self._stream.fileno())
        return self._stream.tell()

    def close(self) -> None:
        self.checkpoint()
        self._stream.close()


class _ShardSink:
    """Appends records to shards and keeps the manifest in step with what is on disk.

    Per unit the manifest records `saved_records` (records durable in sealed shards or in the open shard
    up to its checkpoint) and `done` (every record of the unit saved). `open_shard` names the file being
    filled, its record count and its byte length at the last checkpoint.
    """

    def __init__(self, out: Path, source: Source, settings: ConvertSettings, units: Sequence[str],
                 previous: dict | None):
        self.out = out
        self.settings = settings
        self.path = out / MANIFEST
        if previous is not None:  # --resume, checked against the run settings and inputs by the caller
            self.manifest = previous
            for state in previous["units"].values():  # manifests of earlier versions said sealed_records
                state.setdefault("saved_records", state.pop("sealed_records", 0))
            previous.setdefault("open_shard", None)
        else:
            self.manifest = {
                "schema": {"name": load_schema().name, "version": load_schema().version},
                "source_dataset": source.name,
                "settings": _run_settings(source, settings),
                "state": "running",
                "counts": {},
                "shards": [],
                "open_shard": None,
                "units": {unit: {"saved_records": 0, "done": False, "num_records": 0} for unit in units},
                "failures": [],
                "notes": [],  # per-scenario decisions and repairs the source reports (see MANIFEST_NOTES)
            }
        self.open: _OpenShard | None = None
        self.unsaved: dict[str, int] = {}  # unit -> records appended since the last seal or checkpoint
        self.finished_units: set[str] = set()  # all records handed over (maybe not yet saved)
        self.pending_failures: dict[str, list[dict]] = {}
        self.pending_notes: dict[str, list[dict]] = {}
        self.last_checkpoint = time.monotonic()
        self._reopen_interrupted_shard()
        self._save()  # before any other file: the manifest always lists what this run may create

    def _reopen_interrupted_shard(self) -> None:
        state = self.manifest.get("open_shard")
        if not state:
            return
        path = self.out / state["file"]
        sealed = self.out / _sealed_name(state["file"])
        if not path.exists() and sealed.exists():  # killed between the seal's rename and its manifest update
            os.replace(sealed, path)
        if path.exists() and path.stat().st_size >= state["bytes"]:
            self.open = _OpenShard(path, state["num_records"], keep_bytes=state["bytes"])
            return
        if not path.exists() and state["bytes"] == 0:  # killed after listing the shard, before creating it
            self.open = _OpenShard(path)
            return
        raise ConversionError(f"{path}: the interrupted shard is missing or shorter than its checkpoint; "
                              "convert again with --overwrite")

    # Units -----------------------------------------------------------------------------------------
    def unit_state(self, unit: str) -> dict:
        return self.manifest["units"].setdefault(unit, {"saved_records": 0, "done": False, "num_records": 0})

    def add_unit_result(self, result: UnitResult) -> int:
        """Appends a unit's records, skipping those already saved by an earlier run."""
        skip = self.unit_state(result.unit)["saved_records"]
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
        if result.unit not in self.unsaved:
            self._mark_done(result.unit)
            self._save()
        if time.monotonic() - self.last_checkpoint >= CHECKPOINT_EVERY_S:
            self.checkpoint()
        return written

    @staticmethod
    def _records(result: UnitResult) -> Iterator[bytes]:
        if result.records is not None:
            yield from result.records
        elif result.records_path:
            with open(result.records_path, "rb") as stream:
                for size in result.frame_sizes:
                    frame = stream.read(size)
                    if len(frame) < size:  # only if something else truncated our private file
                        raise ConversionError(f"{result.records_path}: cut short while copying {result.unit} "
                                              f"(disk trouble?); rerun with --resume to continue")
                    yield frame

    def num_saved_records(self) -> int:
        return sum(state["saved_records"] for state in self.manifest["units"].values()) + sum(self.unsaved.values())

    def _mark_done(self, unit: str) -> None:
        state = self.unit_state(unit)
        state["done"] = True
        self.manifest["failures"] = [f for f in self.manifest["failures"] if f["unit"] != unit]
        self.manifest["failures"] += self.pending_failures.pop(unit, [])
        notes = [n for n in self.manifest.get("notes", []) if n["unit"] != unit] + self.pending_notes.pop(unit, [])
        self.manifest["notes"] = notes

    def _commit_unsaved(self) -> None:
        """The records appended since the last save point are durable now: count them, close finished units."""
        for unit, count in self.unsaved.items():
            self.unit_state(unit)["saved_records"] += count
            if unit in self.finished_units:
                self._mark_done(unit)
        self.unsaved = {}
        self.last_checkpoint = time.monotonic()

    # Shards ----------------------------------------------------------------------------------------
    def _append(self, unit: str, record: bytes) -> None:
        if self.open is None:
            index = len(self.manifest["shards"])
            name = f".sealing-{self.settings.split}-{index:05d}.tfrecord"
            self.manifest["open_shard"] = {"file": name, "num_records": 0, "bytes": 0}
            self._save()  # listed before it exists: an interrupted run never leaves an unlisted file
            self.open = _OpenShard(self.out / name)
        self.open.write(record)
        self.unsaved[unit] = self.unsaved.get(unit, 0) + 1
        if self.open.num_records >= self.settings.shard_size:
            self.seal()

    def checkpoint(self) -> None:
        """Makes the open shard's records durable and records its length (bounded loss on a kill)."""
        if self.open is not None:
            self.manifest["open_shard"].update(num_records=self.open.num_records, bytes=self.open.checkpoint())
        self._commit_unsaved()
        self._save()

    def seal(self) -> None:
        if self.open is None:
            return
        self.open.close()
        sealed = self.out / _sealed_name(self.open.path.name)
        os.replace(self.open.path, sealed)
        self.manifest["shards"].append({"file": sealed.name, "num_records": self.open.num_records,
                                        "num_bytes": sealed.stat().st_size, "sha256": self.open.sha256()})
        self.manifest["open_shard"] = None
        self.open = None
        self._commit_unsaved()
        self._save()

    def _save(self) -> None:
        units = self.manifest["units"].values()
        self.manifest["counts"] = {
            "units": len(self.manifest["units"]),
            "units_done": sum(u["done"] for u in units),
            "scenarios": sum(s["num_records"] for s in self.manifest["shards"]),
            "failures": len(self.manifest["failures"]),
        }
        write_manifest(self.out, self.manifest)

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


def _sealed_name(open_name: str) -> str:
    return open_name.replace(".sealing-", ".sealed-", 1)


# --------------------------------------------------------------------------------------------------
# Ownership of the output folder.


def owned_files(manifest: dict) -> set[str]:
    """Names (relative to the output folder) of every file a run with this manifest may have created."""
    names = {MANIFEST, MANIFEST_TEMP, WORK_DIR}
    for shard in manifest.get("shards", []):
        names.update(shard[key] for key in ("file", "temp_file") if isinstance(shard, dict) and key in shard)
    open_shard = manifest.get("open_shard")
    if open_shard:
        names.update({open_shard["file"], _sealed_name(open_shard["file"])})
    for unit in manifest.get("units", {}):
        names.update(f"{WORK_DIR}/{name}" for name in unit_work_files(unit))
    return names


def _foreign_entries(out: Path, owned: set[str]) -> list[str]:
    """Entries of `out` (and of its work folder) that no manifest lists: the user's, never ours to touch."""
    foreign = [entry.name for entry in sorted(out.iterdir()) if entry.name not in owned and entry.name != LOCK_FILE]
    work = out / WORK_DIR
    if work.is_dir():
        foreign += [f"{WORK_DIR}/{entry.name}" for entry in sorted(work.iterdir())
                    if f"{WORK_DIR}/{entry.name}" not in owned]
    return foreign


def _claim_output(out: Path, settings: ConvertSettings) -> dict | None:
    """Checks that this run may write into `out` and clears what an earlier run of ours left there.

    Returns the previous manifest to continue (with --resume), else None. Refuses, without touching
    anything, a folder holding files that no manifest of ours lists.
    """
    if out.exists() and not out.is_dir():
        raise ConversionError(f"{out}: exists and is not a folder; choose another --out")
    if not out.exists():
        return None
    manifest_path = out / MANIFEST
    if not manifest_path.exists():
        foreign = _foreign_entries(out, set())
        if foreign:
            raise ConversionError(f"{out}: not empty and holds no {MANIFEST} (e.g. {', '.join(foreign[:3])}): "
                                  "these are not files of a conversion; choose an empty or new --out")
        return None
    try:
        previous = read_manifest(out)
    except ManifestError as error:
        raise ConversionError(str(error)) from None
    owned = owned_files(previous)
    foreign = _foreign_entries(out, owned)
    if settings.resume:
        return previous
    if not settings.overwrite:
        raise ConversionError(f"{out}: already holds a conversion ({MANIFEST}); add --resume to continue it, "
                              "--overwrite to replace it, or choose a new --out")
    if foreign:
        raise ConversionError(f"{out}: --overwrite replaces only the files its {MANIFEST} lists, and the folder "
                              f"also holds {', '.join(foreign[:3])}; move them away or choose a new --out")
    for name in sorted(owned - {MANIFEST, WORK_DIR}, reverse=True):
        (out / name).unlink(missing_ok=True)
    if (out / WORK_DIR).is_dir():
        (out / WORK_DIR).rmdir()  # empty now: everything in it was listed
    manifest_path.unlink()  # last: until here a crash leaves a folder that --overwrite still owns
    return None


def _refuse_inputs_inside(out: Path, units: Sequence[str]) -> None:
    """Reading and writing one folder would duplicate records, and --overwrite would delete the inputs."""
    root = out.resolve()
    for unit in units:
        path = Path(unit)
        if path.exists() and (path.resolve() == root or root in path.resolve().parents):
            raise ConversionError(f"{out}: holds the inputs of this conversion ({path.name}); choose another --out")


def _check_resumable(previous: dict, source: Source, settings: ConvertSettings, units: Sequence[str],
                     out: Path) -> None:
    path = out / MANIFEST
    before = {"compression": "none", **(previous.get("settings") or {})}  # manifests older than compression
    source_before = before.get("source")
    if isinstance(source_before, dict) and previous.get("source_dataset") in ("womd", "scenarionet"):
        before["source"] = {"orient_edges": True, **source_before}  # manifests older than orient_edges
    if before != _run_settings(source, settings):
        raise ConversionError(f"{path}: settings differ from that conversion's; rerun with the same options, "
                              "or use --overwrite or a new --out")
    done_before = previous.get("units") or {}
    new = [unit for unit in units if unit not in done_before]
    missing = [unit for unit in done_before if unit not in set(units)]
    if new or missing:
        example = (new or missing)[0]
        raise ConversionError(f"{path}: the inputs differ from that conversion's ({len(new)} new, {len(missing)} "
                              f"missing, e.g. {example}); convert them into a new --out")


def _clear_work_dir(out: Path, manifest: dict) -> Path:
    """Recreates `.work/` empty of our files (a killed run's leftovers are recomputed)."""
    work = out / WORK_DIR
    for name in owned_files(manifest):
        if name.startswith(f"{WORK_DIR}/"):
            (out / name).unlink(missing_ok=True)
    work.mkdir(exist_ok=True)
    return work


# --------------------------------------------------------------------------------------------------
# Worker processes.


def _watch_main_process(main_pid: int) -> None:
    """Worker initializer: exit as soon as the main process is gone (kill -9 included, on every platform).

    The executor's own shutdown needs a live main process; without this a killed conversion leaves its
    workers blocked on a pipe forever.
    """
    exit_with_parent()  # the parent is the fork server, which itself dies with the main process
    watch_process(main_pid)


def _results_process(source: Source, units: Sequence[str], settings: ConvertSettings, work: Path,
                     workers: int) -> Iterator[UnitResult]:
    tasks = [(source, unit, str(work), settings.sizes, settings.transform, settings.compression) for unit in units]
    if workers <= 1 or len(tasks) <= 1:
        for task in tasks:
            yield _convert_unit_star(task)
        return
    # forkserver: safe even when the caller has JAX/threads loaded. Results are taken in unit order
    # (deterministic shards) with a bounded number of units in flight (bounded memory and disk).
    # Unlike multiprocessing.Pool, the executor fails loudly if a worker dies (e.g. OOM-killed).
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["scenariomax._forkserver_preload"])  # the fork server too dies with this process
    window = 2 * workers
    with ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_watch_main_process,
                             initargs=(os.getpid(),)) as pool:
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


def ray_init_options(address: str | None, environ: Mapping[str, str], workers: int) -> dict:
    """`ray.init` keywords: join the cluster `--address` or RAY_ADDRESS names (`ray job submit` sets it; Ray
    refuses `num_cpus` when joining), else start a local instance with one CPU per worker."""
    address = address or environ.get("RAY_ADDRESS")
    if address:
        return {"address": address}
    return {"num_cpus": workers, "include_dashboard": False}


def ray_window(requested_workers: int | None, cluster_cpus: float) -> int:
    """Units in flight: two per cluster CPU, or per `--workers` when given. The driver's own core count says
    nothing about a cluster's, and a window sized by it would leave most of a large cluster idle."""
    slots = requested_workers or int(cluster_cpus) or 1
    return 2 * slots


def check_ray_address(address: str | None, timeout_s: float = 5.0) -> None:
    """ConversionError (one line) when nothing listens at a `HOST:PORT` (or `ray://HOST:PORT`) cluster address:
    `ray.init` would wait minutes on it before failing with a traceback. "auto" / "local" are Ray's to resolve."""
    if not address or address in ("auto", "local"):
        return
    where = address.removeprefix("ray://")
    host, _, port = where.rpartition(":")
    if not host or not port.isdigit():
        raise ConversionError(f"--address {address!r}: expected HOST:PORT (or ray://HOST:PORT, or auto)")
    try:
        socket.create_connection((host, int(port)), timeout=timeout_s).close()
    except OSError as error:
        raise ConversionError(f"--address {address}: no Ray cluster answers there ({error.strerror or error}); "
                              "start one with `ray start --head` or fix the address") from None


def ray_failure(unit: str, error: BaseException) -> ConversionError:
    """The one-line error of a Ray task that failed outside the converter's own per-scenario handling (its worker
    or node died, the object store ran out): bad inputs never get here, they are manifest failures."""
    first_line = (str(error).strip().splitlines() or [""])[0][:200]
    return ConversionError(f"the Ray task converting {unit} failed ({type(error).__name__}: {first_line}); "
                           "rerun with --resume to continue")


def _results_ray(source: Source, units: Sequence[str], settings: ConvertSettings, workers: int) -> Iterator[UnitResult]:
    try:
        import ray  # optional extra
    except ImportError:
        raise ConversionError("--engine ray needs the ray extra: pip install 'vmax[ray]'") from None
    if not ray.is_initialized():
        options = ray_init_options(settings.ray_address, os.environ, workers)
        check_ray_address(options.get("address"))
        ray.init(**options, ignore_reinit_error=True, log_to_driver=False)
    remote = ray.remote(convert_unit_in_memory)
    window = ray_window(settings.workers, ray.cluster_resources().get("CPU", 0))
    refs: list = []  # (unit, object ref), oldest first
    next_unit = 0
    while next_unit < len(units) or refs:
        while next_unit < len(units) and len(refs) < window:
            refs.append((units[next_unit], remote.remote(source, units[next_unit], settings.sizes,
                                                         settings.transform, settings.compression)))
            next_unit += 1
        unit, ref = refs.pop(0)
        try:
            result = ray.get(ref)  # in order, so shards are deterministic
        except ray.exceptions.RayError as error:
            raise ray_failure(unit, error) from None
        yield result


def convert(source: Source, settings: ConvertSettings) -> ConversionResult:
    """Runs a conversion (see module docstring). Returns counts; never raises for bad inputs.

    Raises ConversionError (one line) when it cannot start or continue, including OS errors such as a
    read-only or full disk; what was saved until then stays resumable.
    """
    start = time.perf_counter()
    out = Path(settings.out)
    _check_settings(settings)
    try:
        units = list(source.list_units())
    except InputError as error:
        raise ConversionError(str(error)) from None
    if not units:
        where = getattr(source, "src", None)
        raise ConversionError(f"{where + ': ' if where else ''}no {source.name} inputs found, nothing to convert")
    try:
        return _convert_into(out, source, settings, units, start)
    except OSError as error:
        raise ConversionError(describe_os_error(error, resume_with="--resume")) from None


def _check_settings(settings: ConvertSettings) -> None:
    if not SPLIT_NAME.fullmatch(settings.split):
        raise ConversionError(f"--split {settings.split!r}: use letters, digits, '_', '-' or '.' (it names files)")
    if settings.shard_size < 1:
        raise ConversionError(f"--shard-size {settings.shard_size}: must be at least 1")
    if settings.workers is not None and settings.workers < 1:
        raise ConversionError(f"--workers {settings.workers}: must be at least 1 (leave it out for one per core)")
    if settings.compression not in COMPRESSIONS:
        raise ConversionError(f"--compression {settings.compression!r}: use one of {', '.join(COMPRESSIONS)}")
    if settings.resume and settings.overwrite:
        raise ConversionError("--resume and --overwrite exclude each other: continue the conversion, or replace it")


def _convert_into(out: Path, source: Source, settings: ConvertSettings, units: list[str],
                  start: float) -> ConversionResult:
    _refuse_inputs_inside(out, units)
    if out.exists() and not out.is_dir():
        raise ConversionError(f"{out}: exists and is not a folder; choose another --out")
    try:
        with FolderLock(out, "conversion", note=False) as lock:  # one writer per output folder
            return _convert_locked(out, source, settings, units, start, lock)
    except FolderBusyError as error:
        raise ConversionError(str(error)) from None


def _convert_locked(out: Path, source: Source, settings: ConvertSettings, units: list[str],
                    start: float, lock: FolderLock) -> ConversionResult:
    previous = _claim_output(out, settings)
    lock.note_holder()  # the folder is ours: say who writes it
    if previous is not None:
        _check_resumable(previous, source, settings, units, out)
    out.mkdir(parents=True, exist_ok=True)
    sink = _ShardSink(out, source, settings, units, previous)
    work = _clear_work_dir(out, sink.manifest)
    todo = [] if sink.manifest["state"] == "complete" else [u for u in units if not sink.unit_state(u)["done"]]
    skipped = len(units) - len(todo)
    workers = settings.workers or os.cpu_count() or 1
    if settings.engine == "ray":
        results = _results_ray(source, todo, settings, workers)
    elif settings.engine == "process":
        results = _results_process(source, todo, settings, work, workers)
    else:
        raise ConversionError(f"unknown engine {settings.engine!r} (use 'process' or 'ray')")
    progress = _progress(settings.progress, source, sink, len(units), skipped)
    by_scenario = progress.unit == "scenarios"
    with progress:
        for result in results:
            written = sink.add_unit_result(result)
            progress.update(scenarios_settled(result, written) if by_scenario else 1)
            counts = {} if by_scenario else {"scenarios": sink.num_saved_records()}
            progress.set_postfix(**counts, failures=len(sink.manifest["failures"]) + sum(
                map(len, sink.pending_failures.values())))
    shards = sink.finalize()
    shutil.rmtree(work, ignore_errors=True)
    manifest = sink.manifest
    return ConversionResult(
        out=out, num_units=len(units), num_units_skipped=skipped,
        num_scenarios=manifest["counts"]["scenarios"], num_failures=len(manifest["failures"]),
        shards=tuple(shards), elapsed_s=time.perf_counter() - start, failures=tuple(manifest["failures"]),
        notes=tuple(manifest.get("notes", [])),
    )


def scenarios_settled(result: UnitResult, written: int) -> int:
    """Scenarios a unit's result settles, for a progress display counting scenarios of an expected total: those
    written and those that failed one by one (a whole-unit failure, scenario "*", stands for none of the total)."""
    return written + sum(failure.scenario != "*" for failure in result.failures)


def _progress(enabled: bool, source: Source, sink: _ShardSink, num_units: int, num_units_done: int) -> Progress:
    """Scenarios of the known total (synthetic, the records of build-sdc-paths' inputs), else inputs of all
    inputs: either way with an ETA. A resumed run starts at what was saved before."""
    expected = getattr(source, "expected_num_scenarios", lambda: None)()
    if expected is not None:
        return Progress("converting", total=expected, unit="scenarios", enabled=enabled,
                        initial=sink.num_saved_records())
    return Progress("converting", total=num_units, unit="inputs", enabled=enabled, initial=num_units_done)

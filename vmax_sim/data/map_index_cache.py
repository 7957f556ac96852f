"""Disk cache of built map indices: a scenario's index is built once per (shard content, index version).

Building a scenario's map index on the host (`vmax_sim.map_index.build`, numpy) costs several times its
decode, and the loader used to rebuild it every epoch of every run. The indices of one shard live under
`$VMAX_CACHE_DIR/map_index/<version>/<shard sha256>/`:

- `<version>` hashes everything an index depends on besides the shard: the MapIndexConfig values, the roadgraph
  crop (`DataConfig.num_roadgraph_points`), the MapIndex layout (path, dtype and shape of every leaf and the
  static fields, read off a probe build: no field is named here) and the source of the code that builds it, so
  a changed config, layout or algorithm never reads an old entry.
- an entry is one `.npy` per leaf with a leading row axis (row i = record i of the shard; one row is read per
  scenario, with positioned reads, not a memory map) and `meta.json` (scenario ids, one CRC32 per row, sizes).
  It is filled in a hidden temp folder as the shard's scenarios are converted and renamed into place once every
  row is in: readers see a whole entry or none, and when two processes write the same entry one rename wins and
  the other copy is dropped.
- a hit is checked (structure when opened; scenario id and CRC of every row read): any mismatch or damage is a
  miss: the entry is removed, the index built, and the entry written again.
- the shard key is the sha256 its manifest.json lists; a shard without one is hashed once and its hash
  remembered by (path, size, mtime).
- the size is bounded (`DataConfig.map_index_cache_max_gb`): entries unused for a while and since before this
  process started are evicted, least recently used first; when the rest still does not fit, the new shard is
  not cached (a dataset larger than the cache then keeps a fixed part cached instead of thrashing).

Turn it off with `DataConfig(map_index_cache=False)` or the environment variable `VMAX_MAP_INDEX_CACHE=0`.
"""

from __future__ import annotations

import dataclasses
import errno
import hashlib
import inspect
import json
import os
import secrets
import shutil
import socket
import threading
import time
import warnings
import weakref
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

import vmax_sim.map_index
from vmax_sim.data import convert
from vmax_sim.data.config import DataConfig, cache_dir

FORMAT = 1  # layout of an entry on disk (bump when this module writes entries differently)
ENV_SWITCH = "VMAX_MAP_INDEX_CACHE"  # 0 / false / off / no: no cache
META = "meta.json"
_IN_USE_S = 600.0  # an entry used this recently may belong to a run beside this one: never evicted
_STALE_TEMP_S = 86400.0  # temp folders of other hosts older than this are leftovers of a crash
_PROCESS_START = time.time()
_LOCK = threading.Lock()  # guards the process-wide memos below
_LAYOUTS: dict = {}  # (map index config repr, num roadgraph points) -> Layout
_SHARD_KEYS: dict = {}  # (real path, size, mtime_ns) -> ShardKey
_MANIFESTS: dict = {}  # (folder, manifest size, mtime_ns) -> {file name: (sha256, record count)}
_CLEANED: set = set()  # version folders whose leftovers this process removed
_WARNED: dict = {}  # warnings registry: each message once per process


class MapIndexCacheWarning(UserWarning):
    """The map index cache could not be used for something (it then builds the index, as without it)."""


def _warn(message: str) -> None:
    # warn_explicit without a source line: prints as one line
    warnings.warn_explicit(message, MapIndexCacheWarning, "vmax_sim.data", 0, registry=_WARNED)


def map_index_cache_dir() -> Path:
    return cache_dir() / "map_index"


def cache_enabled(config: DataConfig) -> bool:
    """Whether `config`'s loader reads and writes the map index cache."""
    switch = os.environ.get(ENV_SWITCH, "1").strip().lower()
    return config.include_map_index and config.map_index_cache and switch not in ("0", "false", "off", "no")


# ----------------------------------------------------------------------------- what an entry depends on

@dataclasses.dataclass(frozen=True)
class Layout:
    """The pytree structure of a built MapIndex and its leaves' (path, dtype, shape)."""

    treedef: Any
    leaves: tuple[tuple[str, str, tuple[int, ...]], ...]

    @property
    def row_bytes(self) -> int:
        return sum(np.dtype(dtype).itemsize * int(np.prod(shape)) for _, dtype, shape in self.leaves)

    def describe(self) -> list[dict]:
        return [{"path": path, "dtype": dtype, "shape": list(shape)} for path, dtype, shape in self.leaves]


def layout_of(index: Any) -> Layout:
    """The layout of a built index, whatever its fields (every leaf of the pytree)."""
    with_paths, treedef = jax.tree_util.tree_flatten_with_path(index)
    leaves = tuple((jax.tree_util.keystr(path), np.dtype(leaf.dtype).str, tuple(int(n) for n in np.shape(leaf)))
                   for path, leaf in with_paths)
    return Layout(treedef, leaves)


def _probe_index(config: DataConfig) -> Any:
    """The index of an empty roadgraph of the configured size, built the way the loader builds one."""
    from vmax_sim.datatypes import RoadgraphPoints

    n = config.num_roadgraph_points
    zeros = np.zeros(n, np.float32)
    roadgraph = RoadgraphPoints(x=zeros, y=zeros, z=zeros, dir_x=zeros, dir_y=zeros, dir_z=zeros,
                                types=np.zeros(n, np.int32), ids=np.full(n, -1, np.int32), valid=np.zeros(n, bool),
                                speed_limit=np.full(n, -1.0, np.float32))
    return convert.build_map_index_for(roadgraph, np.zeros(2), config)


def _index_config_values(config: DataConfig) -> Any:
    index_config = config.map_index_config or vmax_sim.map_index.MapIndexConfig()
    if dataclasses.is_dataclass(index_config):
        return {"type": type(index_config).__name__, **dataclasses.asdict(index_config)}
    return repr(index_config)


def _code_fingerprint() -> str:
    """sha256 of the code a built index depends on: the map_index package and the loader's crop and call."""
    digest = hashlib.sha256()
    for file in sorted(Path(vmax_sim.map_index.__file__).parent.glob("*.py")):
        digest.update(file.name.encode() + b"\0" + file.read_bytes())
    for function in (convert.sdc_positions, convert.distance_to_points, convert.roadgraph_selection,
                     convert._roadgraph, convert.build_map_index_for, convert.scenario_to_numpy_state):
        digest.update(inspect.getsource(function).encode())
    return digest.hexdigest()


# Read when this module is imported, just after the code it hashes: the code this process runs, whatever
# edits of the files come later (entries are labelled with the code that built them).
_CODE_SHA256 = _code_fingerprint()


def version_description(config: DataConfig, layout: Layout) -> dict:
    return {"format": FORMAT, "map_index_config": _index_config_values(config),
            "num_roadgraph_points": config.num_roadgraph_points, "treedef": str(layout.treedef),
            "leaves": layout.describe(), "code_sha256": _CODE_SHA256}


def version_key(description: dict) -> str:
    text = json.dumps(description, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


# ----------------------------------------------------------------------------- shard keys

@dataclasses.dataclass(frozen=True)
class ShardKey:
    sha256: str
    num_records: int
    num_bytes: int  # file size when keyed: a shard changed behind its manifest's back is a miss


def _listed_shards(manifest: Any) -> dict[str, tuple[str, int]]:
    """{file name: (sha256, record count)} of a parsed manifest.json; entries without both are left out."""
    shards = manifest.get("shards") if isinstance(manifest, dict) else None
    listed = {}
    for entry in shards if isinstance(shards, list) else []:
        if not isinstance(entry, dict):
            continue
        name, sha256, count = entry.get("file"), entry.get("sha256"), entry.get("num_records")
        if isinstance(name, str) and isinstance(sha256, str) and len(sha256) == 64 and type(count) is int:
            listed[name] = (sha256, count)
    return listed


def _manifest_entries(folder: Path) -> dict[str, tuple[str, int]]:
    """The shards `folder/manifest.json` lists (the loader has checked it against the folder before reading)."""
    manifest = folder / "manifest.json"
    try:
        stat = manifest.stat()
    except OSError:
        return {}
    memo_key = (str(folder), stat.st_size, stat.st_mtime_ns)
    with _LOCK:
        if memo_key in _MANIFESTS:
            return _MANIFESTS[memo_key]
    try:
        listed = _listed_shards(json.loads(manifest.read_bytes()))
    except (OSError, ValueError, RecursionError):  # unreadable: the reader reports it; shards are hashed instead
        listed = {}
    with _LOCK:
        _MANIFESTS[memo_key] = listed
    return listed


def _write_json_atomically(path: Path, value: Any) -> None:
    temp = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
    temp.write_text(json.dumps(value))
    os.replace(temp, path)


def _hashed_key(file: Path, stat: os.stat_result, hashes_dir: Path) -> ShardKey | None:
    """The sha256 and record count of a shard its folder's manifest does not list: read once, then remembered."""
    from scenariomax.io import RecordError, count_records

    identity = f"{file.resolve()}|{stat.st_size}|{stat.st_mtime_ns}"
    remembered = hashes_dir / f"{hashlib.sha256(identity.encode()).hexdigest()[:32]}.json"
    try:
        value = json.loads(remembered.read_text())
        if value.get("identity") == identity:
            return ShardKey(value["sha256"], int(value["num_records"]), stat.st_size)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        pass
    try:
        num_records = count_records(file)
    except RecordError:
        return None  # damaged framing: the reader reports it
    key = ShardKey(_file_sha256(file), num_records, stat.st_size)
    try:
        hashes_dir.mkdir(parents=True, exist_ok=True)
        _write_json_atomically(remembered, {"identity": identity, "sha256": key.sha256, "num_records": num_records})
    except OSError:
        pass  # hashed again next time
    return key


def _file_sha256(file: Path) -> str:
    digest = hashlib.sha256()
    with open(file, "rb") as stream:
        while block := stream.read(1 << 22):
            digest.update(block)
    return digest.hexdigest()


def shard_key(file: Path, hashes_dir: Path) -> ShardKey | None:
    """What identifies a shard's content: its manifest's sha256, else the file's own (hashed once)."""
    stat = file.stat()
    listed = _manifest_entries(file.parent).get(file.name)
    if listed is not None:
        return ShardKey(listed[0], listed[1], stat.st_size)
    memo_key = (str(file.resolve()), stat.st_size, stat.st_mtime_ns)
    with _LOCK:
        if memo_key in _SHARD_KEYS:
            return _SHARD_KEYS[memo_key]
    key = _hashed_key(file, stat, hashes_dir)
    with _LOCK:
        _SHARD_KEYS[memo_key] = key
    return key


# ----------------------------------------------------------------------------- entries on disk

def _leaf_file(position: int) -> str:
    return f"leaf-{position:03d}.npy"


def _row_crc(leaves: list[np.ndarray]) -> int:
    crc = 0
    for leaf in leaves:
        crc = zlib.crc32(np.ascontiguousarray(leaf), crc)
    return crc


def _remove(folder: Path) -> None:
    """Removes an entry or temp folder: renamed aside first, so no reader ever sees half of it."""
    trash = folder.with_name(f".trash~{folder.name.lstrip('.')}~{secrets.token_hex(4)}")
    try:
        os.rename(folder, trash)
    except OSError:
        return  # already gone (another process removed or replaced it)
    shutil.rmtree(trash, ignore_errors=True)


class LeafFile:
    """One leaf's `.npy` file (rows of the leaf's shape after the header), read and written with pread / pwrite.

    Not memory-mapped: a mapped file cut short, or a full disk under a mapped write, kills the process with
    SIGBUS, where positioned I/O raises an error the cache turns into a miss."""

    def __init__(self, path: Path, dtype: np.dtype, shape: tuple[int, ...], num_rows: int, create: bool):
        self.dtype, self.shape = dtype, shape
        self.row_bytes = dtype.itemsize * int(np.prod(shape))
        self._file = open(path, "w+b" if create else "rb", buffering=0)  # closed by close() or with the object
        if create:
            header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                      "shape": (num_rows,) + shape}
            np.lib.format.write_array_header_2_0(self._file, header)
            self.offset = self._file.tell()
            return
        version = np.lib.format.read_magic(self._file)
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
            np.lib.format.read_array_header_2_0
        found_shape, fortran_order, found_dtype = read_header(self._file)
        self.offset = self._file.tell()
        size = os.fstat(self._file.fileno()).st_size
        if (found_dtype != dtype or fortran_order or found_shape != (num_rows,) + shape
                or size != self.offset + num_rows * self.row_bytes):
            raise ValueError(f"{path.name} holds {found_dtype} {found_shape} in {size} bytes, expected {dtype} "
                             f"{(num_rows,) + shape}")

    def read_row(self, row: int) -> np.ndarray:
        data = os.pread(self._file.fileno(), self.row_bytes, self.offset + row * self.row_bytes)
        if len(data) != self.row_bytes:
            raise ValueError(f"row {row} cut short")
        return np.frombuffer(data, self.dtype).reshape(self.shape)

    def write_row(self, row: int, leaf: np.ndarray) -> None:
        data = memoryview(np.ascontiguousarray(leaf)).cast("B")
        if os.pwrite(self._file.fileno(), data, self.offset + row * self.row_bytes) != self.row_bytes:
            raise OSError(errno.ENOSPC, "short write")

    def close(self) -> None:
        self._file.close()


def _folder_bytes(folder: Path) -> int:
    total = 0
    for file in folder.iterdir():
        try:
            total += file.stat().st_size
        except OSError:
            pass
    return total


class CacheEntry:
    """A complete entry: rows are read (and checked) one scenario at a time."""

    def __init__(self, folder: Path, layout: Layout, files: list[LeafFile], meta: dict):
        self.folder = folder
        self._layout = layout
        self._files = files
        self._scenario_ids = meta["scenario_ids"]
        self._row_crcs = meta["row_crc32"]
        self._damaged = False

    def read_row(self, row: int, scenario_id: str) -> Any | None:
        """The map index of record `row`, or None (and the entry removed) when it does not check out."""
        if self._damaged:
            return None
        if row >= len(self._scenario_ids) or self._scenario_ids[row] != scenario_id:
            return self._discard(f"record {row} is not scenario {scenario_id}")
        try:
            leaves = [file.read_row(row) for file in self._files]
        except (OSError, ValueError) as error:  # changed since it was opened
            return self._discard(f"unreadable ({error})")
        if _row_crc(leaves) != self._row_crcs[row]:
            return self._discard(f"record {row} fails its CRC")
        return jax.tree.unflatten(self._layout.treedef, leaves)

    def _discard(self, reason: str) -> None:
        self._damaged = True
        _warn(f"{self.folder}: damaged map index cache entry ({reason}); removed, its indices are built again")
        _remove(self.folder)
        return None


def _open_entry(folder: Path, layout: Layout, version: str, key: ShardKey) -> CacheEntry | None:
    """The entry in `folder` if it is whole and made for this version and shard; None (removed if present) if not."""
    try:
        meta = json.loads((folder / META).read_text())
    except FileNotFoundError:
        if folder.exists():
            _remove(folder)  # a folder without its meta is not an entry
        return None
    except (OSError, ValueError) as error:
        return _reject(folder, f"meta.json unreadable ({error})")
    expected = {"format": FORMAT, "version": version, "shard_sha256": key.sha256, "shard_bytes": key.num_bytes,
                "num_rows": key.num_records, "leaves": layout.describe()}
    if not isinstance(meta, dict) or any(meta.get(name) != value for name, value in expected.items()):
        return _reject(folder, "made for other data or another index layout")
    ids, crcs = meta.get("scenario_ids"), meta.get("row_crc32")
    if not (isinstance(ids, list) and isinstance(crcs, list) and len(ids) == len(crcs) == key.num_records):
        return _reject(folder, "meta.json lists the wrong number of records")
    files = []
    for position, (_, dtype, shape) in enumerate(layout.leaves):
        try:
            files.append(LeafFile(folder / _leaf_file(position), np.dtype(dtype), shape, key.num_records, False))
        except (OSError, ValueError, EOFError) as error:
            return _reject(folder, f"{_leaf_file(position)} unreadable ({error})")
    try:
        os.utime(folder / META)  # last used: the eviction order
    except OSError:
        pass  # a read-only cache still serves hits
    return CacheEntry(folder, layout, files, meta)


def _reject(folder: Path, reason: str) -> None:
    _warn(f"{folder}: map index cache entry not used ({reason}); removed, its indices are built again")
    _remove(folder)
    return None


class EntryWriter:
    """Fills an entry in a hidden temp folder as the shard's scenarios are converted; renames it when whole."""

    def __init__(self, cache: MapIndexCache, key: ShardKey):
        self._cache = cache
        self._key = key
        self.final = cache.version_dir / key.sha256
        self.temp = cache.version_dir / f".tmp~{os.getpid()}~{socket.gethostname()}~{secrets.token_hex(4)}"
        self.temp.mkdir(parents=True)
        self._cleanup = weakref.finalize(self, shutil.rmtree, str(self.temp), True)  # never completed: dropped
        self._files = [LeafFile(self.temp / _leaf_file(position), np.dtype(dtype), shape, key.num_records, True)
                       for position, (_, dtype, shape) in enumerate(cache.layout.leaves)]
        self._scenario_ids: list[str | None] = [None] * key.num_records
        self._row_crcs: list[int] = [0] * key.num_records
        self._num_stored = 0
        self.done = False  # committed or abandoned

    def store(self, row: int, scenario_id: str, index: Any) -> None:
        if self.done:
            return
        try:
            self._store(row, scenario_id, index)
        except OSError as error:  # disk full, folder removed, ...
            _warn(f"{self.temp}: cannot write the map index cache ({error.strerror or error}); indices are built "
                  f"every time until it can (free space, or set {ENV_SWITCH}=0)")
            self.abandon()

    def _store(self, row: int, scenario_id: str, index: Any) -> None:
        leaves, treedef = jax.tree.flatten(index)
        leaves = [np.asarray(leaf) for leaf in leaves]
        if row >= self._key.num_records or treedef != self._cache.layout.treedef or any(
                leaf.dtype.str != dtype or leaf.shape != shape
                for leaf, (_, dtype, shape) in zip(leaves, self._cache.layout.leaves)):
            self.abandon()  # the shard or the index is not what the key and layout say: cache nothing
            return
        for file, leaf in zip(self._files, leaves):
            file.write_row(row, leaf)
        if self._scenario_ids[row] is None:
            self._num_stored += 1
        self._scenario_ids[row] = scenario_id
        self._row_crcs[row] = _row_crc(leaves)
        if self._num_stored == self._key.num_records:
            self._commit()

    def _commit(self) -> None:
        self._close_files()
        meta = {"format": FORMAT, "version": self._cache.version, "shard_sha256": self._key.sha256,
                "shard_bytes": self._key.num_bytes, "num_rows": self._key.num_records,
                "leaves": self._cache.layout.describe(), "scenario_ids": self._scenario_ids,
                "row_crc32": self._row_crcs}
        (self.temp / META).write_text(json.dumps(meta))
        self.done = True
        self._cache.forget_writer(self)
        try:
            os.rename(self.temp, self.final)
        except OSError:
            if not self.final.exists():
                raise
            # another process renamed its copy of the same entry first: keep that one, drop this one
        self._cleanup()  # removes the temp folder if it is still there

    def _close_files(self) -> None:
        for file in self._files:
            file.close()
        self._files = []

    def abandon(self) -> None:
        self.done = True
        self._close_files()
        self._cache.forget_writer(self)
        self._cleanup()


# ----------------------------------------------------------------------------- where a scenario's index comes from

@dataclasses.dataclass(frozen=True)
class CachedRow:
    """A hit: the index is read from the entry (built again when the row does not check out)."""

    entry: CacheEntry
    row: int
    builds_index = False  # the conversion skips the build

    def finish(self, state: Any, scenario_id: str, build: Callable[[], Any]) -> Any:
        index = self.entry.read_row(self.row, scenario_id)
        return state.replace(map_index=build() if index is None else index)


@dataclasses.dataclass(frozen=True)
class PendingRow:
    """A miss: the conversion builds the index, which is then written into the shard's entry."""

    writer: EntryWriter
    row: int
    builds_index = True

    def finish(self, state: Any, scenario_id: str, build: Callable[[], Any]) -> Any:
        self.writer.store(self.row, scenario_id, state.map_index)
        return state


IndexSource = CachedRow | PendingRow


class ShardRows:
    """The index source of each record of one shard (None: build it, and cache nothing)."""

    def __init__(self, entry: CacheEntry | None = None, writer: EntryWriter | None = None):
        self._entry = entry
        self._writer = writer

    def source(self, row: int) -> IndexSource | None:
        if self._entry is not None:
            return CachedRow(self._entry, row)
        if self._writer is not None and not self._writer.done:
            return PendingRow(self._writer, row)
        return None


# ----------------------------------------------------------------------------- the cache

class MapIndexCache:
    """The entries of one index version (one DataConfig's MapIndexConfig, roadgraph crop, layout and code)."""

    def __init__(self, root: Path, layout: Layout, description: dict, max_bytes: int):
        self.root = root
        self.layout = layout
        self.version = version_key(description)
        self.version_dir = root / self.version
        self.max_bytes = max_bytes
        self._writers: weakref.WeakValueDictionary = weakref.WeakValueDictionary()  # sha256 -> open writer
        self.version_dir.mkdir(parents=True, exist_ok=True)
        if not (self.version_dir / "version.json").exists():
            _write_json_atomically(self.version_dir / "version.json", description)  # for people, never read
        self._remove_leftovers()

    def shard_rows(self, file: Path) -> ShardRows:
        """Where the indices of `file`'s records come from: its entry, else a writer filling it, else a build."""
        try:
            key = shard_key(file, self.root / "shard_hashes")
            if key is None or key.num_records == 0:
                return ShardRows()
            entry = _open_entry(self.version_dir / key.sha256, self.layout, self.version, key)
            if entry is not None:
                return ShardRows(entry=entry)
            return ShardRows(writer=self._writer(key))
        except OSError as error:
            _warn(f"{self.root}: cannot use the map index cache ({error.strerror or error}); indices are built "
                  f"every time (set {ENV_SWITCH}=0 to silence this)")
            return ShardRows()

    def _writer(self, key: ShardKey) -> EntryWriter | None:
        with _LOCK:
            writer = self._writers.get(key.sha256)
            if writer is not None and not writer.done:
                return writer  # a second pass over a shard whose first is still being converted
        if not self._make_room(key.num_records * self.layout.row_bytes):
            return None
        writer = EntryWriter(self, key)
        with _LOCK:
            self._writers[key.sha256] = writer
        return writer

    def forget_writer(self, writer: EntryWriter) -> None:
        with _LOCK:
            if self._writers.get(writer.final.name) is writer:
                del self._writers[writer.final.name]

    def _entries(self) -> list[tuple[float, int, Path]]:
        """(last used, bytes, folder) of every complete entry of every version."""
        found = []
        for version_dir in self.root.iterdir():
            if not version_dir.is_dir() or version_dir.name == "shard_hashes":
                continue
            for folder in version_dir.iterdir():
                if folder.name.startswith(".") or not folder.is_dir():
                    continue
                try:
                    found.append(((folder / META).stat().st_mtime, _folder_bytes(folder), folder))
                except OSError:
                    continue  # being removed, or not complete
        return found

    def _make_room(self, needed: int) -> bool:
        """Evicts entries not in use until `needed` more bytes fit under the bound; False when they cannot."""
        entries = sorted(self._entries())
        total = sum(size for _, size, _ in entries)
        evictable_before = min(_PROCESS_START, time.time() - _IN_USE_S)
        for last_used, size, folder in entries:
            if total + needed <= self.max_bytes:
                break
            if last_used < evictable_before:
                _remove(folder)
                total -= size
        if total + needed <= self.max_bytes:
            return True
        _warn(f"{self.root}: the map index cache is full ({total / 2**30:.1f} of {self.max_bytes / 2**30:.1f} GiB in "
              "use by recent runs); further shards are not cached (raise DataConfig.map_index_cache_max_gb)")
        return False

    def _remove_leftovers(self) -> None:
        """Temp and trash folders of processes that died before finishing them."""
        with _LOCK:
            if self.version_dir in _CLEANED:
                return
            _CLEANED.add(self.version_dir)
        host = socket.gethostname()
        for folder in self.version_dir.iterdir():
            if not folder.name.startswith((".tmp~", ".trash~")):
                continue
            parts = folder.name.split("~")
            try:
                ours_and_dead = (folder.name.startswith(".tmp~") and parts[2] == host
                                 and not _pid_alive(int(parts[1])))
                old = time.time() - folder.stat().st_mtime > _STALE_TEMP_S
            except (IndexError, ValueError, OSError):
                continue
            if folder.name.startswith(".trash~") or ours_and_dead or old:
                shutil.rmtree(folder, ignore_errors=True)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _layout(config: DataConfig) -> Layout:
    memo_key = (repr(config.map_index_config), config.num_roadgraph_points)
    with _LOCK:
        if memo_key in _LAYOUTS:
            return _LAYOUTS[memo_key]
    layout = layout_of(_probe_index(config))
    with _LOCK:
        _LAYOUTS[memo_key] = layout
    return layout


def open_map_index_cache(config: DataConfig) -> MapIndexCache | None:
    """The cache for `config`'s indices, or None when it is off (or its folder cannot be written)."""
    if not cache_enabled(config):
        return None
    layout = _layout(config)
    root = map_index_cache_dir()
    try:
        return MapIndexCache(root, layout, version_description(config, layout),
                             int(config.map_index_cache_max_gb * 2**30))
    except OSError as error:
        _warn(f"{root}: cannot use the map index cache ({error.strerror or error}); indices are built every time "
              f"(set {ENV_SWITCH}=0 to silence this)")
        return None

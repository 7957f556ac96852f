"""What vmax_sim keeps under $VMAX_CACHE_DIR, how big it is, and clearing it (`vmax-sim cache info|clear`).

Two kinds of entries, both rebuilt on demand when missing: the embedded synthetic splits (`synthetic/<name>/`,
shards generated once per seed, size and knobs) and the map-index cache (`map_index/<version>/<shard>/`).
Clearing removes only these folders, never anything else under the cache root.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
from pathlib import Path

from vmax_sim.data.config import cache_dir

KINDS = ("synthetic", "map_index")  # the sub-folders of the cache root that are ours
# measured (docs/benchmarks.md): a default synthetic scenario (64 objects, 30k roadgraph points) in a shard, and
# its map index in the cache; used to say how big a cache will grow before building it
SYNTHETIC_BYTES_PER_SCENARIO = 2.2e6  # 4.5 GB for the default 2,000 scenes
MAP_INDEX_BYTES_PER_SCENARIO = 0.28e6  # 576 MB for 2,100 synthetic scenes


@dataclasses.dataclass(frozen=True)
class CacheEntry:
    kind: str  # one of KINDS
    path: Path
    bytes: int


def folder_bytes(folder: Path) -> int:
    """Bytes of the files under `folder` (0 when missing)."""
    total = 0
    for root, _, files in os.walk(folder):
        for name in files:
            try:
                total += (Path(root) / name).stat().st_size
            except OSError:  # removed meanwhile
                pass
    return total


def cache_entries(root: Path | None = None) -> list[CacheEntry]:
    """One entry per synthetic split and per map-index version, largest first."""
    root = root or cache_dir()
    entries = []
    for kind in KINDS:
        folder = root / kind
        if folder.is_dir():
            entries += [CacheEntry(kind, path, folder_bytes(path)) for path in sorted(folder.iterdir())
                        if path.is_dir()]
    return sorted(entries, key=lambda entry: -entry.bytes)


def clear_cache(kind: str = "all", root: Path | None = None) -> int:
    """Removes the cache's `kind` folders ("all", "synthetic" or "map_index"); returns the bytes freed."""
    if kind != "all" and kind not in KINDS:
        raise ValueError(f"unknown cache kind {kind!r}; choose all, {', '.join(KINDS)}")
    root = root or cache_dir()
    freed = 0
    for name in KINDS if kind == "all" else (kind,):
        folder = root / name
        if folder.is_dir():
            freed += folder_bytes(folder)
            shutil.rmtree(folder)
    return freed


def human_bytes(count: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if abs(count) < 1000 or unit == "GB":
            return f"{count:,.0f} {unit}" if unit == "B" else f"{count:,.1f} {unit}"
        count /= 1000
    return f"{count:,.1f} TB"


def format_cache_info(root: Path | None = None) -> str:
    """The `vmax-sim cache info` report: the root, each entry with its size, the total."""
    root = root or cache_dir()
    entries = cache_entries(root)
    lines = [f"cache root: {root} (set VMAX_CACHE_DIR to move it)"]
    if not entries:
        return "\n".join(lines + ["  empty"])
    width = max(len(str(entry.path.relative_to(root))) for entry in entries)
    lines += [f"  {str(entry.path.relative_to(root)):<{width}}  {human_bytes(entry.bytes):>10}" for entry in entries]
    lines.append(f"  {'total':<{width}}  {human_bytes(sum(entry.bytes for entry in entries)):>10}")
    lines.append("clear with: vmax-sim cache clear [synthetic|map_index|all]  (rebuilt when needed)")
    return "\n".join(lines)

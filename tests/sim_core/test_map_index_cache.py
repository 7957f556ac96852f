"""The disk cache of built map indices (vmax_sim.data.map_index_cache): hits equal builds, bit for bit."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
import pytest
from conftest import small_config

import scenariomax
from vmax_sim.data import DataConfig, iter_numpy_batches, load_batch
from vmax_sim.data.map_index_cache import (
    MapIndexCacheWarning,
    layout_of,
    open_map_index_cache,
    version_description,
    version_key,
)
from vmax_sim.map_index import MapIndexConfig

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def cache_root(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("VMAX_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("VMAX_MAP_INDEX_CACHE", raising=False)
    return tmp_path / "cache" / "map_index"


@pytest.fixture
def builds(monkeypatch) -> list:
    """Counts real map-index builds (the cache's probe builds an empty roadgraph: not counted)."""
    import vmax_sim.map_index.build as build_module

    calls: list = []
    original = build_module.build_map_index

    def counting(xyz, dir, types, ids, valid, *args, **kwargs):
        if np.any(valid):
            calls.append(1)
        return original(xyz, dir, types, ids, valid, *args, **kwargs)

    monkeypatch.setattr(build_module, "build_map_index", counting)
    return calls


def config(shard_dir, **changes) -> DataConfig:
    return small_config(shard_dir, include_map_index=True, **changes)


def host_batches(data_config: DataConfig) -> list:
    return list(iter_numpy_batches(data_config))


def assert_bit_identical(batches, reference) -> None:
    assert len(batches) == len(reference)
    for got, want in zip(batches, reference):
        got_leaves, got_tree = jax.tree.flatten(got)
        want_leaves, want_tree = jax.tree.flatten(want)
        assert got_tree == want_tree
        for a, b in zip(got_leaves, want_leaves):
            a, b = np.asarray(a), np.asarray(b)
            assert a.dtype == b.dtype and a.shape == b.shape
            assert a.tobytes() == b.tobytes()


def entries(cache_root: Path) -> list[Path]:
    return sorted(p for p in cache_root.glob("*/*") if p.is_dir() and not p.name.startswith("."))


def test_a_hit_gives_the_built_arrays_bit_for_bit_without_building(shard_dir, cache_root, builds):
    reference = host_batches(config(shard_dir, map_index_cache=False))
    assert len(builds) == 6 and not cache_root.exists()
    builds.clear()
    cold = host_batches(config(shard_dir))
    assert len(builds) == 6 and len(entries(cache_root)) == 2  # one entry per shard
    builds.clear()
    warm = host_batches(config(shard_dir))
    assert builds == []  # every index came from the cache
    assert_bit_identical(cold, reference)
    assert_bit_identical(warm, reference)
    assert_bit_identical([load_batch(config(shard_dir), num_scenarios=3)], [reference[0]])
    assert builds == []


def test_worker_processes_read_the_cache_too(shard_dir, cache_root):
    serial = host_batches(config(shard_dir))
    parallel = host_batches(config(shard_dir, num_workers=2))
    assert_bit_identical(parallel, serial)


def test_a_changed_config_is_a_miss(shard_dir, cache_root, builds):
    host_batches(config(shard_dir))
    builds.clear()
    for changes in ({"map_index_config": MapIndexConfig(grid_size=32)}, {"num_roadgraph_points": 500}):
        fresh = host_batches(config(shard_dir, **changes))
        assert len(builds) == 6  # built again, not read from the first config's entries
        builds.clear()
        assert_bit_identical(fresh, host_batches(config(shard_dir, map_index_cache=False, **changes)))
        builds.clear()
    assert len(entries(cache_root)) == 6  # 3 versions x 2 shards
    host_batches(config(shard_dir, num_objects=4, batch_size=2))  # not an input of the index: still a hit
    assert builds == []


def test_a_changed_index_layout_changes_the_version(shard_dir, cache_root):
    data_config = config(shard_dir)
    cache = open_map_index_cache(data_config)
    zeros = [np.zeros(shape, dtype) for _, dtype, shape in cache.layout.leaves]
    index = jax.tree.unflatten(cache.layout.treedef, zeros)
    leaves, treedef = jax.tree.flatten(index)
    narrower = jax.tree.unflatten(treedef, [leaves[0].astype(np.float16)] + leaves[1:])
    same = version_key(version_description(data_config, layout_of(index)))
    assert same == cache.version
    assert version_key(version_description(data_config, layout_of(narrower))) != same


def _truncate_leaf(entry: Path) -> None:
    leaf = entry / "leaf-000.npy"
    with open(leaf, "r+b") as stream:
        stream.truncate(leaf.stat().st_size // 2)


def _flip_last_byte(entry: Path) -> None:
    leaf = entry / "leaf-000.npy"
    data = bytearray(leaf.read_bytes())
    data[-1] ^= 0xFF  # inside the shard's last row
    leaf.write_bytes(bytes(data))


def _garbage_meta(entry: Path) -> None:
    (entry / "meta.json").write_text("{not json")


def _meta_of_other_shard(entry: Path) -> None:
    meta = json.loads((entry / "meta.json").read_text())
    meta["scenario_ids"] = [f"other-{i}" for i in range(len(meta["scenario_ids"]))]
    (entry / "meta.json").write_text(json.dumps(meta))


@pytest.mark.parametrize("damage", [_truncate_leaf, _flip_last_byte, _garbage_meta, _meta_of_other_shard])
def test_a_damaged_entry_is_a_miss_that_is_rebuilt_and_rewritten(shard_dir, cache_root, builds, damage):
    reference = host_batches(config(shard_dir, map_index_cache=False))
    host_batches(config(shard_dir))
    damage(entries(cache_root)[0])
    builds.clear()
    with pytest.warns(MapIndexCacheWarning, match="removed, its indices are built again"):
        assert_bit_identical(host_batches(config(shard_dir)), reference)
    assert builds  # the damaged entry's indices were built again
    assert_bit_identical(host_batches(config(shard_dir)), reference)  # rewritten now at the latest
    builds.clear()
    assert_bit_identical(host_batches(config(shard_dir)), reference)
    assert builds == [] and len(entries(cache_root)) == 2


def test_a_disabled_cache_writes_nothing(shard_dir, cache_root, monkeypatch, builds):
    host_batches(config(shard_dir, map_index_cache=False))
    monkeypatch.setenv("VMAX_MAP_INDEX_CACHE", "0")
    host_batches(config(shard_dir))
    load_batch(config(shard_dir))
    assert not cache_root.parent.exists()
    assert len(builds) == 6 + 6 + 6


@pytest.mark.filterwarnings("ignore::scenariomax.manifest.ManifestWarning")
def test_shards_without_a_manifest_are_hashed_once(tmp_path, shard_dir, cache_root, builds):
    bare = tmp_path / "bare"
    bare.mkdir()
    for shard in sorted(shard_dir.glob("*.tfrecord")):
        shutil.copy(shard, bare / shard.name)
    host_batches(config(bare))
    builds.clear()
    assert_bit_identical(host_batches(config(bare)), host_batches(config(shard_dir, map_index_cache=False)))
    assert len(builds) == 6  # the reference only
    assert len(list((cache_root / "shard_hashes").glob("*.json"))) == 2


def test_the_size_bound_evicts_old_entries_and_then_stops_caching(shard_dir, cache_root, builds):
    host_batches(config(shard_dir))
    one_entry = sum(f.stat().st_size for f in entries(cache_root)[0].iterdir())
    shutil.rmtree(cache_root)
    bound_gb = 1.5 * one_entry / 2**30  # room for one shard's entry, not two
    with pytest.warns(MapIndexCacheWarning, match="cache is full"):
        host_batches(config(shard_dir, map_index_cache_max_gb=bound_gb))
    assert len(entries(cache_root)) == 1  # the second shard was not cached: the first is in use (recent)
    (old,) = entries(cache_root)
    long_ago = time.time() - 2 * 86400
    os.utime(old / "meta.json", (long_ago, long_ago))  # last used by a run two days ago
    second_shard = sorted(shard_dir.glob("*.tfrecord"))[1]
    host_batches(config(second_shard, map_index_cache_max_gb=bound_gb))
    assert len(entries(cache_root)) == 1 and entries(cache_root)[0] != old  # evicted, the new one admitted


_WRITER = """
import sys
from vmax_sim.data import DataConfig, iter_numpy_batches
config = DataConfig(path=sys.argv[1], batch_size=3, num_objects=8, num_roadgraph_points=1000, num_paths=2,
                    num_points_per_path=300, max_num_lights=4, prefetch=0)
print(sum(1 for _ in iter_numpy_batches(config)))
"""


def test_two_processes_writing_the_same_entries_leave_whole_ones(shard_dir, cache_root, builds):
    env = {**os.environ, "PYTHONPATH": str(REPO), "JAX_PLATFORMS": "cpu"}
    writers = [subprocess.Popen([sys.executable, "-c", _WRITER, str(shard_dir)], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True) for _ in range(2)]
    for writer in writers:
        out, err = writer.communicate(timeout=120)
        assert writer.returncode == 0, err
        assert out.strip() == "2"
    assert len(entries(cache_root)) == 2
    assert not [p for p in cache_root.glob("*/.*") if p.is_dir()]  # no temp folder left behind
    reference = host_batches(config(shard_dir, map_index_cache=False))
    builds.clear()
    assert_bit_identical(host_batches(config(shard_dir)), reference)
    assert builds == []


def test_the_same_entry_committed_twice_keeps_one_whole_copy(shard_dir, cache_root, builds):
    from vmax_sim.data.map_index_cache import EntryWriter, shard_key

    data_config = config(shard_dir)
    cache = open_map_index_cache(data_config)
    file = sorted(shard_dir.glob("*.tfrecord"))[0]
    key = shard_key(file, cache.root / "shard_hashes")
    first, second = EntryWriter(cache, key), EntryWriter(cache, key)
    states = host_batches(config(shard_dir, map_index_cache=False, batch_size=1))[:3]
    ids = [s.scenario_id for s in scenariomax.read_shards(file)]
    for writer in (first, second):  # interleaved rows, then both renames: the second finds the entry in place
        for row in range(3):
            writer.store(row, ids[row], jax.tree.map(lambda a: a[0], states[row].map_index))
    assert first.done and second.done
    assert len(entries(cache_root)) == 1
    assert not [p for p in cache_root.glob("*/.*") if p.is_dir()]
    builds.clear()
    host_batches(config(shard_dir))
    assert len(builds) == 3  # the other shard only

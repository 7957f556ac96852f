"""`vmax-sim cache info|clear`: what the cache holds, and clearing only our folders."""

from __future__ import annotations

from click.testing import CliRunner

from vmax_cli.vmax_cli import main
from vmax_sim.data.cache_admin import cache_entries, clear_cache
from vmax_sim.training.run import disk_estimate


def _fill(root):
    (root / "synthetic" / "seed0-n10-objects64").mkdir(parents=True)
    (root / "synthetic" / "seed0-n10-objects64" / "train-00000-of-00001.tfrecord").write_bytes(b"x" * 5000)
    (root / "map_index" / "abc").mkdir(parents=True)
    (root / "map_index" / "abc" / "leaf.npy").write_bytes(b"y" * 700)
    (root / "mine.txt").write_text("a user's file")


def test_info_lists_each_entry_with_its_size_and_clear_frees_only_ours(tmp_path, monkeypatch):
    _fill(tmp_path)
    monkeypatch.setenv("VMAX_CACHE_DIR", str(tmp_path))
    assert [(e.kind, e.bytes) for e in cache_entries()] == [("synthetic", 5000), ("map_index", 700)]
    info = CliRunner().invoke(main, ["cache", "info"])
    assert info.exit_code == 0 and "synthetic/seed0-n10-objects64" in info.output and "5.0 KB" in info.output
    assert str(tmp_path) in info.output and "total" in info.output
    assert clear_cache("map_index") == 700 and not (tmp_path / "map_index").exists()
    cleared = CliRunner().invoke(main, ["cache", "clear"])
    assert cleared.exit_code == 0 and "freed 5.0 KB" in cleared.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.txt"]  # never the user's files


def test_the_help_names_the_cache_folder_variable():
    assert "VMAX_CACHE_DIR" in CliRunner().invoke(main, ["--help"]).output


def test_a_synthetic_split_says_how_big_it_will_be():
    assert "about 4.4 GB of shards" in disk_estimate(2000, 64)

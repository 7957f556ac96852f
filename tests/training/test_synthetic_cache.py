"""The embedded synthetic splits are generated once into the cache, and a leftover folder never blocks them."""

import json

from vmax_sim.training.run import synthetic_split


def test_a_leftover_cache_folder_is_regenerated_then_reused(tmp_path, monkeypatch):
    monkeypatch.setenv("VMAX_CACHE_DIR", str(tmp_path))
    folder = tmp_path / "synthetic" / "seed3-n3-objects16"
    folder.mkdir(parents=True)
    (folder / "manifest.json").write_text("{\"state\": ")  # another version's, cut short by a crash
    lines: list[str] = []
    assert synthetic_split(3, 3, 16, lines.append) == str(folder)
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["state"] == "complete" and manifest["counts"]["scenarios"] == 3 and len(lines) == 1
    stamp = (folder / "manifest.json").stat().st_mtime_ns
    assert synthetic_split(3, 3, 16, lines.append) == str(folder)
    assert len(lines) == 1 and (folder / "manifest.json").stat().st_mtime_ns == stamp  # reused, not regenerated

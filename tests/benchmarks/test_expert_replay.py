"""benchmarks/expert_replay.py: the expert replayed on real recordings, its table, JSON and failure pictures."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from tests.conftest import realdata_file

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from expert_replay import main  # noqa: E402

CHEAP_GROUPS = ("nocturne", "av2")  # one scenario each: a couple of compilations' worth of time


@pytest.mark.slow
def test_replay_on_real_data_writes_rows_and_a_picture_per_failure(tmp_path, capsys):
    realdata_file("nocturne/example_scenario.json")
    realdata = realdata_file("av2").parent
    out = tmp_path / "replay"
    assert main(["--realdata", str(realdata), "--out", str(out), "--only", ",".join(CHEAP_GROUPS)]) == 0
    printed = capsys.readouterr().out
    table = (out / "expert_replay.md").read_text()
    for name in (*CHEAP_GROUPS, "**total**"):
        assert f"| {name} |" in table and f"| {name} |" in printed, name
    report = json.loads((out / "expert_replay.json").read_text())
    rows = report["groups"] + [report["total"]]
    assert [row["group"] for row in report["groups"]] == list(CHEAP_GROUPS)
    for row in rows:
        assert "error" not in row, row.get("error")
        assert 0.0 <= row["accuracy"] <= 1.0 and 0.0 <= row["vmax_score"] <= 1.0
        assert 0 < row["judged"] <= row["scenarios"]
    assert report["total"]["scenarios"] == sum(row["scenarios"] for row in report["groups"])
    for failure in report["total"]["failed_episodes"]:
        assert failure["metrics"], failure
        assert failure["picture"] and Path(failure["picture"]).is_file(), failure
        assert Path(failure["picture"]).with_suffix(".gif").is_file()
        assert failure["picture"] in table
    for name in CHEAP_GROUPS:
        assert (out / name / "index.html").is_file()


def test_bad_folders_end_with_one_line(tmp_path, capsys):
    assert main(["--realdata", str(tmp_path / "missing"), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.strip().count("\n") == 0
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("")
    assert main(["--realdata", str(tmp_path), "--out", str(not_a_folder)]) == 2
    error = capsys.readouterr().err.strip()
    assert error.count("\n") == 0 and "not a folder" in error
    assert main(["--realdata", str(tmp_path), "--out", str(tmp_path / "out"), "--only", "nope"]) == 2
    assert "unknown group" in capsys.readouterr().err

"""benchmarks/expert_replay.py: the real-WOMD clean share (the issue's >= 98% bar), by hand."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from expert_replay import GROUPS, _parse, format_womd_clean, womd_clean  # noqa: E402


def _row(judged: int, accurate: float, womd: bool = True, **extra) -> dict:
    return {"judged": judged, "sums": {"accurate": accurate, "vmax_score": accurate}, "womd": womd, **extra}


def test_clean_share_counts_only_judged_womd_groups():
    rows = [_row(80, 77.0), _row(3, 3.0), _row(8, 2.0, womd=False), _row(0, 0.0, error="no scenario converted")]
    summary = womd_clean(rows)
    assert summary == {"judged": 83, "clean": 80, "share": 80 / 83, "meets_bar": False}  # the 96.4%
    assert "80 of 83" in format_womd_clean(summary) and "96.4%" in format_womd_clean(summary)
    assert womd_clean([_row(50, 49.0)])["meets_bar"]  # 98.0% meets it
    assert womd_clean([_row(8, 8.0, womd=False)]) is None


def test_womd_groups_and_num_objects_option():
    assert {g.name for g in GROUPS if g.womd} == {"womd-example", "womd-scenario", "scenarionet-womd_20s",
                                                 "scenarionet-womd_91steps", "gpudrive", "nocturne"}
    assert _parse([]).num_objects == 128 and _parse(["--num-objects", "64"]).num_objects == 64

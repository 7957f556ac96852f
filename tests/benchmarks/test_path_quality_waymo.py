"""benchmarks/sdc_path_quality.py --compare-waymo: Waymo's SDC paths against ours on a Scenario proto built here."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from tests.sources.womd.fixtures import write_records
from tests.sources.womd.test_womd_sdc_paths import east_scenario, encode_sdc_path, scenario_with_paths, straight_path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from sdc_path_quality import _compare_table, compare_with_waymo, path_gap  # noqa: E402


def test_path_gap_by_hand():
    ours = np.array([[0.0, 0.0], [10.0, 0.0]])
    theirs = np.array([[0.0, 0.5], [20.0, 0.5]])  # parallel, 0.5 m apart, longer: compared over 10 m only
    gap = path_gap(ours, theirs)
    assert gap == {"mean_m": 0.5, "max_m": 0.5, "common_length_m": 10.0}


def test_compare_waymo_paths_with_ours(tmp_path):
    xyz, ids = straight_path()
    shifted = xyz + [0.0, 0.4, 0.0]  # Waymo's on-route path 0.4 m beside the lane centre the SDC drives
    records = [scenario_with_paths([encode_sdc_path(shifted, ids=ids, on_route=True)], scenario_id="with-paths"),
               east_scenario(scenario_id="without-paths")]
    stats = compare_with_waymo(str(write_records(tmp_path / "a.tfrecord", records)), per_scenario=True)
    assert (stats["scenarios"], stats["compared"], stats["both_on_route"]) == (2, 1, 1)
    (row,) = stats["per_scenario"]
    assert row["scenario_id"] == "with-paths" and row["waymo_paths"] == 1
    assert abs(row["gap"]["mean_m"] - 0.4) < 1e-3  # ours runs on the centre line y = 0
    assert row["waymo_log_within_1m"] == 1.0  # every logged position within 0.4 m
    assert "with-paths" in _compare_table(stats)

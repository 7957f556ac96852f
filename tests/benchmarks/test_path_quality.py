"""benchmarks/sdc_path_quality.py: SDC and per-agent path coverage of the log, on a hand-made scene."""

from __future__ import annotations

import sys
from pathlib import Path

from scenariomax import write_shards
from scenariomax.enrich import EnrichSettings, PathSettings, enrich_scenario
from tests.enrich.scenes import make_scenario, straight_xy, track
from tests.enrich.test_follow_log import _smooth_shift, _unlinked_lanes

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from sdc_path_quality import agent_path_coverage, path_quality  # noqa: E402


def _scene():
    """Lanes without neighbour links; the SDC and agent 1 change lanes, agent 2 stays on its lane."""
    polylines, links = _unlinked_lanes()
    objects = [track(_smooth_shift(straight_xy(10, 10.0), 30, 60, 3.5)),
               track(_smooth_shift(straight_xy(40, 8.0), 30, 55, 3.5)), track(straight_xy(60, 8.0, y=3.5))]
    return make_scenario(polylines, objects, **links)


def test_agent_coverage_and_summary(tmp_path):
    scenario = _scene()
    lane_only = enrich_scenario(scenario, EnrichSettings(infer_lights=False, paths=PathSettings(follow_log=False)))
    before = agent_path_coverage(lane_only)
    assert set(before) == {1, 2} and before[1] < 0.95 and before[2] == 1.0
    after = enrich_scenario(scenario, EnrichSettings(infer_lights=False))
    assert agent_path_coverage(after) == {1: 1.0, 2: 1.0}
    write_shards([lane_only], tmp_path / "before")
    write_shards([after], tmp_path / "after")
    old, new = path_quality(str(tmp_path / "before"), per_scenario=True), path_quality(str(tmp_path / "after"))
    assert (old["scenarios_with_95pct_within_1m"], old["agents_covered_95pct"], old["agents_with_path"]) == (0, 1, 2)
    assert old["per_scenario"][0]["agents_failing"] == [1]
    assert new["scenarios_with_95pct_within_1m"] == 1
    assert (new["agents_covered_95pct"], new["agent_share_covered"]) == (2, 1.0)

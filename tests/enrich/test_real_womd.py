"""Bars on the real WOMD tf.Example (no lane links: the graph is rebuilt from points)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import scenariomax
from scenariomax.enrich import enrich_scenario
from scenariomax.enrich.geometry import polyline_runs, project_to_polyline

REAL = Path(__file__).resolve().parents[2] / ".." / "shared" / "realdata" / "womd" / "motion_data_one_example.tfrecord"


@pytest.fixture(scope="module")
def scenario():
    if not REAL.exists():
        pytest.skip(f"real WOMD sample not found at {REAL} (the shared folder is absent)")
    return next(scenariomax.read_shards(REAL))


@pytest.fixture(scope="module")
def enriched(scenario):
    return enrich_scenario(scenario)


def test_logged_sdc_follows_an_on_route_path(scenario, enriched):
    assert enriched.path_on_route.any() and enriched.path_on_route[0]
    sdc, start = scenario.sdc_index, scenario.current_time_index
    mask = scenario.valid[sdc, start:]
    track = np.stack([scenario.x[sdc, start:][mask], scenario.y[sdc, start:][mask]], 1)
    path = enriched.path_xyz[0][enriched.path_valid[0]]
    dist = project_to_polyline(track, path)[0]
    print(f"SDC-to-path distance: median {np.median(dist):.3f} m, p95 {np.percentile(dist, 95):.3f} m, "
          f"max {dist.max():.3f} m")
    assert np.mean(dist <= 1.0) >= 0.95
    assert enriched.lane_valid.sum() > 50 and (enriched.lane_successors >= 0).any()


def test_directions_unit_wherever_the_polyline_continues(enriched):
    runs = polyline_runs(enriched.roadgraph_id, enriched.roadgraph_valid)
    has_next = np.zeros(len(enriched.roadgraph_id), bool)
    for start, stop in runs:
        has_next[start:stop - 1] = True
    norms = np.linalg.norm(enriched.roadgraph_dir, axis=1)
    np.testing.assert_allclose(norms[has_next], 1.0, atol=1e-5)
    assert np.all(norms[runs[:, 1] - 1] == 0)


def test_enriched_scenario_is_valid_and_round_trips(scenario, enriched):
    assert enriched.validate() == []
    sizes = scenariomax.Sizes(num_roadgraph=scenario.roadgraph_xyz.shape[0])
    back = scenariomax.decode_scenario(scenariomax.encode_scenario(enriched, sizes))
    assert back.path_on_route[0] and (back.roadgraph_speed_limit[back.roadgraph_type == 2] == np.float32(13.4)).all()
    known = scenario.tl_valid & (scenario.tl_state != 0)
    np.testing.assert_array_equal(enriched.tl_state[known], scenario.tl_state[known])
    assert not enriched.tl_inferred[known].any()

"""How well the reconstructed SDC paths cover the logged SDC trajectory, over a shard set.

For each scenario: is there an on-route path, and the distance from each valid logged SDC position
(from the current step on: paths start at the SDC's current position) to the nearest on-route path.
Usage: python benchmarks/sdc_path_quality.py SHARDS [--json]
"""

from __future__ import annotations

import json
import sys

import numpy as np

from scenariomax import read_shards
from scenariomax.enrich.geometry import project_to_polyline


def scenario_path_distances(scenario) -> np.ndarray | None:
    """Distances of the SDC's valid positions (current step on) to the closest on-route path, or None."""
    sdc, now = scenario.sdc_index, scenario.current_time_index
    mask = scenario.valid[sdc, now:]
    points = np.stack([scenario.x[sdc, now:][mask], scenario.y[sdc, now:][mask]], 1).astype(np.float64)
    best = None
    for p in np.flatnonzero(scenario.path_on_route):
        line = scenario.path_xyz[p][scenario.path_valid[p]][:, :2].astype(np.float64)
        if len(line) == 0:
            continue
        dist = project_to_polyline(points, line)[0]
        best = dist if best is None else np.minimum(best, dist)
    return best


def path_quality(path: str) -> dict:
    num, with_route, within, all_dist = 0, 0, [], []
    for scenario in read_shards(path):
        num += 1
        dist = scenario_path_distances(scenario)
        if dist is None:
            continue
        with_route += 1
        within.append(float((dist <= 1.0).mean()))
        all_dist.append(dist)
    dist = np.concatenate(all_dist) if all_dist else np.zeros(0)
    share = np.array(within)
    return {
        "scenarios": num,
        "with_on_route_path": with_route,
        "scenarios_with_95pct_within_1m": int((share >= 0.95).sum()),
        "steps_within_1m": float((dist <= 1.0).mean()) if dist.size else 0.0,
        "distance_m": {q: float(np.percentile(dist, v)) for q, v in
                       (("median", 50), ("p95", 95), ("p99", 99), ("max", 100))} if dist.size else {},
    }


if __name__ == "__main__":
    stats = path_quality(sys.argv[1])
    print(json.dumps(stats, indent=1))

"""How well the reconstructed paths cover the logged trajectories, over a shard set.

SDC: for each scenario, is there an on-route path, and the distance from each valid logged SDC position
(from the current step on: paths start at the SDC's current position) to the nearest on-route path.
Agents: for each controllable agent besides the SDC with a per-agent path (`agent_path_*`), the share of
its valid logged positions (current step on) within 1 m of it; "covered" when >= 95%. Agents without a
path are counted apart (all `num_agent_paths` slots taken, or no lane near their start).
`--per-scenario` lists each scenario's SDC coverage and the agents below 95% or without a path.
Usage: python benchmarks/sdc_path_quality.py SHARDS [--json] [--per-scenario]
"""

from __future__ import annotations

import json
import sys

import numpy as np

from scenariomax import read_shards
from scenariomax.enrich.geometry import project_to_polyline

TOLERANCE_M = 1.0
COVERED = 0.95  # a path "covers" a log when this share of its positions lies within TOLERANCE_M


def _logged(scenario, index: int) -> np.ndarray:
    """Valid positions (m, 2) of one object from the current step on."""
    now = scenario.current_time_index
    mask = scenario.valid[index, now:]
    return np.stack([scenario.x[index, now:][mask], scenario.y[index, now:][mask]], 1).astype(np.float64)


def scenario_path_distances(scenario) -> np.ndarray | None:
    """Distances of the SDC's valid positions (current step on) to the closest on-route path, or None."""
    points = _logged(scenario, scenario.sdc_index)
    best = None
    for p in np.flatnonzero(scenario.path_on_route):
        line = scenario.path_xyz[p][scenario.path_valid[p]][:, :2].astype(np.float64)
        if len(line) == 0:
            continue
        dist = project_to_polyline(points, line)[0]
        best = dist if best is None else np.minimum(best, dist)
    return best


def agent_path_coverage(scenario) -> dict[int, float | None]:
    """Object index -> share of its logged positions (current step on) within 1 m of its own path, for
    every controllable agent besides the SDC (None: no path in the shard)."""
    rows = _agent_rows(scenario)
    out: dict[int, float | None] = {}
    for index in np.flatnonzero(scenario.is_controllable):
        if index == scenario.sdc_index:
            continue
        row = rows.get(int(index))
        if row is None:
            out[int(index)] = None
            continue
        line = scenario.agent_path_xyz[row][scenario.agent_path_valid[row]][:, :2].astype(np.float64)
        points = _logged(scenario, int(index))
        if len(line) == 0 or len(points) == 0:
            out[int(index)] = 0.0 if len(points) else 1.0
            continue
        out[int(index)] = float((project_to_polyline(points, line)[0] <= TOLERANCE_M).mean())
    return out


def _agent_rows(scenario) -> dict[int, int]:
    """Object index -> row of its per-agent path."""
    return {int(i): r for r, i in enumerate(scenario.agent_path_object_index) if i >= 0}


def path_quality(path: str, per_scenario: bool = False) -> dict:
    num, with_route, within, all_dist, listing = 0, 0, [], [], []
    agents = []  # coverage per controllable agent (None: no path)
    over_budget = 0  # controllable agents without a path because every agent-path slot is taken
    for scenario in read_shards(path):
        num += 1
        dist = scenario_path_distances(scenario)
        coverage = agent_path_coverage(scenario)
        agents.extend(coverage.values())
        if len(_agent_rows(scenario)) == len(scenario.agent_path_object_index):
            over_budget += sum(c is None for c in coverage.values())
        share = None
        if dist is not None:
            with_route += 1
            share = float((dist <= TOLERANCE_M).mean()) if dist.size else 1.0
            within.append(share)
            all_dist.append(dist)
        if per_scenario:
            failing = sorted(i for i, c in coverage.items() if c is None or c < COVERED)
            listing.append({"scenario_id": scenario.scenario_id, "sdc_within_1m": share,
                            "sdc_max_m": float(dist.max()) if dist is not None and dist.size else None,
                            "agents": len(coverage), "agents_failing": failing})
    dist = np.concatenate(all_dist) if all_dist else np.zeros(0)
    share = np.array(within)
    with_path = [c for c in agents if c is not None]
    stats = {
        "scenarios": num,
        "with_on_route_path": with_route,
        "scenarios_with_95pct_within_1m": int((share >= COVERED).sum()),
        "steps_within_1m": float((dist <= TOLERANCE_M).mean()) if dist.size else 0.0,
        "distance_m": {q: float(np.percentile(dist, v)) for q, v in
                       (("median", 50), ("p95", 95), ("p99", 99), ("max", 100))} if dist.size else {},
        "controllable_agents": len(agents),
        "agents_with_path": len(with_path),
        "agents_without_path_slots_full": over_budget,
        "agents_covered_95pct": int(sum(c >= COVERED for c in with_path)),
        "agent_share_covered": float(np.mean([c >= COVERED for c in with_path])) if with_path else 1.0,
    }
    if per_scenario:
        stats["per_scenario"] = listing
    return stats


def _table(stats: dict) -> str:
    lines = [f"scenarios {stats['scenarios']}, on-route path {stats['with_on_route_path']}, "
             f"SDC covered (>=95% within 1 m) {stats['scenarios_with_95pct_within_1m']}, "
             f"agents with a path covered {stats['agents_covered_95pct']} / {stats['agents_with_path']} "
             f"({stats['controllable_agents']} controllable, {stats['agents_without_path_slots_full']} without a "
             f"path: slots full)"]
    for row in stats.get("per_scenario", []):
        share = "-" if row["sdc_within_1m"] is None else f"{row['sdc_within_1m']:.3f}"
        worst = "-" if row["sdc_max_m"] is None else f"{row['sdc_max_m']:.2f}"
        lines.append(f"  {row['scenario_id']:<40} SDC {share} (max {worst} m)  agents {row['agents']}"
                     f"  failing {row['agents_failing']}")
    return "\n".join(lines)


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    stats = path_quality(args[0], per_scenario="--per-scenario" in sys.argv)
    print(json.dumps(stats, indent=1) if "--json" in sys.argv else _table(stats))

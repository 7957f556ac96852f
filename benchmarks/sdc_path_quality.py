"""How well the reconstructed paths cover the logged trajectories, over a shard set.

SDC: for each scenario, is there an on-route path, and the distance from each valid logged SDC position
(from the current step on: paths start at the SDC's current position) to the nearest on-route path.
Agents: for each controllable agent besides the SDC with a per-agent path (`agent_path_*`), the share of
its valid logged positions (current step on) within 1 m of it; "covered" when >= 95%. Agents without a
path are counted apart (all `num_agent_paths` slots taken, or no lane near their start).
`--per-scenario` lists each scenario's SDC coverage and the agents below 95% or without a path.

Waymo's paths against ours (`--compare-waymo RAW`): WOMD Scenario protos that carry Waymo's own SDC paths
(1.3.1+) are converted twice, with `--sdc-paths auto` (Waymo's where present) and `--sdc-paths reconstruct`
(ours), and each scenario that got Waymo's paths is compared: the distance between the two first on-route
paths (both directions, over the length both cover) and the share of the logged SDC positions within 1 m of
each source's on-route paths.
Usage: python benchmarks/sdc_path_quality.py SHARDS [--json] [--per-scenario]
       python benchmarks/sdc_path_quality.py --compare-waymo RAW_WOMD [--json] [--per-scenario]
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

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


# --- Waymo's paths against ours -------------------------------------------------------------------

def _first_on_route(scenario) -> np.ndarray | None:
    """(q, 2) points of the first on-route path, or None."""
    for p in np.flatnonzero(scenario.path_on_route):
        line = scenario.path_xyz[p][scenario.path_valid[p]][:, :2].astype(np.float64)
        if len(line) >= 2:
            return line
    return None


def path_gap(ours: np.ndarray, theirs: np.ndarray) -> dict[str, float]:
    """Distances between two paths from the same start, over the length both cover: each path's points
    within the other's length, projected onto the other (both directions). -> mean and max, metres."""
    length = min(float(np.linalg.norm(np.diff(ours, axis=0), axis=1).sum()),
                 float(np.linalg.norm(np.diff(theirs, axis=0), axis=1).sum()))
    dists = []
    for a, b in ((ours, theirs), (theirs, ours)):
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(a, axis=0), axis=1))])
        dists.append(project_to_polyline(a[cum <= length + 1e-6], b)[0])
    dist = np.concatenate(dists)
    return {"mean_m": float(dist.mean()), "max_m": float(dist.max()), "common_length_m": length}


def _log_coverage(scenario) -> float | None:
    """Share of the SDC's logged positions (current step on) within 1 m of an on-route path (None: none)."""
    dist = scenario_path_distances(scenario)
    if dist is None:
        return None
    return float((dist <= TOLERANCE_M).mean()) if dist.size else 1.0


def _convert(raw: str, out: Path, sdc_paths: str) -> tuple[dict, set]:
    """(scenario id -> scenario, ids whose paths are Waymo's per the manifest notes), converted as
    `scenariomax convert --dataset womd --sdc-paths ...` does."""
    from scenariomax.enrich.transform import make_transform
    from scenariomax.pipeline import ConvertSettings, convert
    from scenariomax.sources.womd import WomdSource

    transform, settings = make_transform()
    source = WomdSource(raw, sdc_paths=sdc_paths, orient_edges=False)  # the enrichment orients road edges
    convert(source, ConvertSettings(out=out, workers=1, progress=False, transform=transform,
                                    transform_settings=settings))
    if not (out / "manifest.json").is_file():
        return {}, set()
    notes = json.loads((out / "manifest.json").read_text()).get("notes", [])
    from_waymo = {n["scenario"] for n in notes if n["notes"].get("paths_source") == "waymo"}
    return {s.scenario_id: s for s in read_shards(str(out))}, from_waymo


def compare_with_waymo(raw: str, per_scenario: bool = False) -> dict:
    """Waymo's SDC paths against our reconstruction on the same WOMD Scenario protos."""
    with tempfile.TemporaryDirectory(prefix="sdc-paths-") as tmp:
        waymo, from_waymo = _convert(raw, Path(tmp) / "waymo", "auto")
        ours, _ = _convert(raw, Path(tmp) / "ours", "reconstruct")
    rows = []
    for sid, theirs in waymo.items():
        if sid not in ours:
            continue
        a, b = _first_on_route(ours[sid]), _first_on_route(theirs)
        rows.append({"scenario_id": sid,
                     "waymo_paths": int(theirs.path_valid.any(axis=1).sum()) if sid in from_waymo else 0,
                     "our_paths": int(ours[sid].path_valid.any(axis=1).sum()),
                     "gap": path_gap(a, b) if a is not None and b is not None else None,
                     "ours_log_within_1m": _log_coverage(ours[sid]),
                     "waymo_log_within_1m": _log_coverage(theirs)})
    compared = [r for r in rows if r["waymo_paths"]]
    gaps = [r["gap"] for r in compared if r["gap"] is not None]

    def covered(key: str) -> int:
        return sum(r[key] is not None and r[key] >= COVERED for r in compared)

    stats = {
        "scenarios": len(waymo), "in_both": len(rows),
        "note": "scenarios are compared only when the Scenario proto carries Waymo's paths (WOMD 1.3.1+)",
        "compared": len(compared),
        "both_on_route": len(gaps),
        "gap_mean_m": float(np.mean([g["mean_m"] for g in gaps])) if gaps else None,
        "gap_max_m": float(np.max([g["max_m"] for g in gaps])) if gaps else None,
        "ours_log_covered": covered("ours_log_within_1m"),
        "waymo_log_covered": covered("waymo_log_within_1m"),
    }
    if per_scenario:
        stats["per_scenario"] = compared
    return stats


def _compare_table(stats: dict) -> str:
    if not stats["compared"]:
        return (f"scenarios {stats['scenarios']}: none carries Waymo's SDC paths (WOMD 1.3.1+ Scenario protos "
                "do), nothing to compare")
    gap = "-" if stats["gap_mean_m"] is None else f"{stats['gap_mean_m']:.2f} m mean, {stats['gap_max_m']:.2f} m max"
    lines = [f"scenarios with Waymo's paths {stats['compared']} / {stats['scenarios']}; both with an on-route "
             f"path {stats['both_on_route']}; ours vs Waymo's on-route path: {gap}; log covered (>=95% within "
             f"1 m): ours {stats['ours_log_covered']}, Waymo's {stats['waymo_log_covered']}"]
    for row in stats.get("per_scenario", []):
        share = lambda v: "-" if v is None else f"{v:.3f}"  # noqa: E731
        gap = "-" if row["gap"] is None else f"{row['gap']['mean_m']:.2f}/{row['gap']['max_m']:.2f} m"
        lines.append(f"  {row['scenario_id']:<40} gap {gap}  log within 1 m: ours "
                     f"{share(row['ours_log_within_1m'])}, Waymo's {share(row['waymo_log_within_1m'])}")
    return "\n".join(lines)


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
    if not args:
        sys.exit(__doc__.split("Usage: ")[-1])
    per = "--per-scenario" in sys.argv
    if "--compare-waymo" in sys.argv:
        stats, table = compare_with_waymo(args[0], per_scenario=per), _compare_table
    else:
        stats, table = path_quality(args[0], per_scenario=per), _table
    print(json.dumps(stats, indent=1) if "--json" in sys.argv else table(stats))

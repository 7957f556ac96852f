"""Scenario enrichment: roadgraph sampling, budgets, SDC paths, controllable labels, light inference."""

from scenariomax.enrich.controllable import (
    ControllableSettings,
    ControllableStats,
    controllable_mask,
    controllable_stats,
    is_moving,
)
from scenariomax.enrich.directions import roadgraph_directions, with_recomputed_directions
from scenariomax.enrich.ids import stable_id, with_missing_ids_assigned
from scenariomax.enrich.lane_graph import (
    LaneGraph,
    LaneGraphSettings,
    lane_graph_to_arrays,
    rebuild_lane_graph,
    scenario_lane_graph,
)
from scenariomax.enrich.lanes import Lanes, extract_lanes
from scenariomax.enrich.orientation import edges_to_reverse, with_edges_oriented
from scenariomax.enrich.paths import Path, PathSettings, paths_to_arrays, search_paths
from scenariomax.enrich.pipeline import EnrichSettings, enrich_scenario
from scenariomax.enrich.speed_limits import DEFAULT_SPEED_LIMITS_MPS, fill_speed_limits, with_speed_limits
from scenariomax.enrich.traffic_lights import LightSettings, light_evidence, with_inferred_lights

__all__ = [
    "DEFAULT_SPEED_LIMITS_MPS",
    "ControllableSettings",
    "ControllableStats",
    "EnrichSettings",
    "LaneGraph",
    "LaneGraphSettings",
    "Lanes",
    "LightSettings",
    "Path",
    "PathSettings",
    "controllable_mask",
    "controllable_stats",
    "edges_to_reverse",
    "enrich_scenario",
    "extract_lanes",
    "fill_speed_limits",
    "is_moving",
    "lane_graph_to_arrays",
    "light_evidence",
    "paths_to_arrays",
    "rebuild_lane_graph",
    "roadgraph_directions",
    "scenario_lane_graph",
    "search_paths",
    "stable_id",
    "with_edges_oriented",
    "with_inferred_lights",
    "with_missing_ids_assigned",
    "with_recomputed_directions",
    "with_speed_limits",
]

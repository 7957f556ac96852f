"""Driving metrics of the scored agent (SDC) on plain arrays: Waymax, nuPlan and V-Max sets.

`step_metrics` runs every per-step metric at one step; stack its outputs over time and call
`episode_metrics`; `aggregate_episodes` averages episodes. See docs/metrics.md for definitions.
"""

from vmax_sim.metrics.config import MetricsConfig
from vmax_sim.metrics.episode import (
    aggregate_episodes,
    comfort_score,
    comfort_signals,
    driving_direction_score,
    episode_metrics,
    multiple_lanes_score,
    nuplan_score,
    savgol_derivative_matrix,
    speed_limit_compliance,
    vmax_score,
)
from vmax_sim.metrics.objects import at_fault_collisions, overlaps, select_candidates, time_to_collision
from vmax_sim.metrics.step import (
    SharedQueries,
    StepInputs,
    finite_difference_motion,
    off_route,
    offroad,
    on_multiple_lanes,
    red_light_violation,
    route_distances,
    sdc_box_at,
    shared_queries,
    speed_violation,
    step_metrics,
    wrong_way,
)

__all__ = [
    "MetricsConfig",
    "SharedQueries",
    "StepInputs",
    "aggregate_episodes",
    "at_fault_collisions",
    "comfort_score",
    "comfort_signals",
    "driving_direction_score",
    "episode_metrics",
    "finite_difference_motion",
    "multiple_lanes_score",
    "nuplan_score",
    "off_route",
    "offroad",
    "on_multiple_lanes",
    "overlaps",
    "red_light_violation",
    "route_distances",
    "savgol_derivative_matrix",
    "sdc_box_at",
    "select_candidates",
    "shared_queries",
    "speed_limit_compliance",
    "speed_violation",
    "step_metrics",
    "time_to_collision",
    "vmax_score",
    "wrong_way",
]

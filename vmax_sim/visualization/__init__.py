"""Pictures of rollouts (the map, the logged SDC and the simulated SDCs of several policies) and the web viewer."""

from vmax_sim.visualization.rollouts import render_rollouts, rollout_figure, rollout_paths
from vmax_sim.visualization.view import RolloutCollector, write_rollout_view

__all__ = ["RolloutCollector", "render_rollouts", "rollout_figure", "rollout_paths", "write_rollout_view"]

"""Pictures of rollouts (the map, the logged SDC and the simulated SDCs of several policies)."""

from vmax_sim.visualization.rollouts import render_rollouts, rollout_paths

__all__ = ["render_rollouts", "rollout_paths"]

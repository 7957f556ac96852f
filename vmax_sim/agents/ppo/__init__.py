"""Proximal Policy Optimization: GAE with truncation handling, clipped surrogate, epochs of minibatches."""

from vmax_sim.agents.ppo.config import PRESETS, PPOConfig, get_config
from vmax_sim.agents.ppo.learner import PPOTrainState, make_learner
from vmax_sim.agents.ppo.networks import PPONetworks, PPOParams, make_networks

__all__ = ["PRESETS", "PPOConfig", "PPONetworks", "PPOParams", "PPOTrainState", "get_config", "make_learner",
           "make_networks"]

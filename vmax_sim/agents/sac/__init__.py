"""Soft Actor-Critic: twin Q heads, target critic, tanh-Gaussian actor, learned or fixed temperature."""

from vmax_sim.agents.sac.config import PRESETS, SACConfig, get_config
from vmax_sim.agents.sac.learner import SACTrainState, build_learner, make_learner
from vmax_sim.agents.sac.networks import SACNetworks, make_networks

__all__ = ["PRESETS", "SACConfig", "SACNetworks", "SACTrainState", "build_learner", "get_config", "make_learner",
           "make_networks"]

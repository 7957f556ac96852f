"""Behaviour cloning: maximum likelihood of expert actions under the tanh-Gaussian policy."""

from vmax_sim.agents.bc.config import PRESETS, BCConfig, get_config
from vmax_sim.agents.bc.learner import BCTrainState, make_learner
from vmax_sim.agents.bc.networks import make_networks

__all__ = ["PRESETS", "BCConfig", "BCTrainState", "get_config", "make_learner", "make_networks"]

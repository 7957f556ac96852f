"""BC's network: the tanh-Gaussian actor alone."""

from __future__ import annotations

from vmax_sim.agents.bc.config import BCConfig
from vmax_sim.agents.networks import Actor, EncoderFactory


def make_networks(config: BCConfig, encoder_factory: EncoderFactory, action_dim: int) -> Actor:
    return Actor(encoder_factory, action_dim, config.policy_hidden_sizes, config.activation, config.log_std_min,
                 config.log_std_max)

"""SAC's networks: a tanh-Gaussian actor and a critic with twin Q heads on one shared encoder."""

from __future__ import annotations

from typing import NamedTuple

from vmax_sim.agents.networks import Actor, Critic, EncoderFactory
from vmax_sim.agents.sac.config import SACConfig


class SACNetworks(NamedTuple):
    actor: Actor  # obs (B, ...) -> TanhGaussian (B, A)
    critic: Critic  # (obs (B, ...), action (B, A)) -> Q (num_critics, B)


def make_networks(config: SACConfig, encoder_factory: EncoderFactory, action_dim: int) -> SACNetworks:
    actor = Actor(encoder_factory, action_dim, config.policy_hidden_sizes, config.activation,
                  config.log_std_min, config.log_std_max)
    critic = Critic(encoder_factory, config.value_hidden_sizes, config.activation, config.num_critics)
    return SACNetworks(actor=actor, critic=critic)

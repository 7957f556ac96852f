"""PPO's networks: a tanh-Gaussian policy and a state-value network, each with its own encoder."""

from __future__ import annotations

from typing import NamedTuple

import flax.struct

from vmax_sim.agents.networks import Actor, EncoderFactory, ValueNet
from vmax_sim.agents.ppo.config import PPOConfig
from vmax_sim.agents.types import Params


class PPONetworks(NamedTuple):
    policy: Actor  # obs (B, ...) -> TanhGaussian (B, A)
    value: ValueNet  # obs (B, ...) -> V (B,)


@flax.struct.dataclass
class PPOParams:
    policy: Params
    value: Params


def make_networks(config: PPOConfig, encoder_factory: EncoderFactory, action_dim: int) -> PPONetworks:
    policy = Actor(encoder_factory, action_dim, config.policy_hidden_sizes, config.activation, config.log_std_min,
                   config.log_std_max)
    value = ValueNet(encoder_factory, config.value_hidden_sizes, config.activation)
    return PPONetworks(policy=policy, value=value)

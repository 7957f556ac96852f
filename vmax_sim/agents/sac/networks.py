"""SAC's networks: a tanh-Gaussian actor and a critic with twin Q heads on one shared encoder.

With `shared_encoder` the actor owns no encoder: it reads the critic encoder's features, detached (the
encoder learns from the critic loss only, as in DrQ-v2). One update then runs the encoder forward and
backward once on s and forward once on s' (instead of five forwards and two backwards), about half the cost.
"""

from __future__ import annotations

from typing import NamedTuple

import jax

from vmax_sim.agents.distributions import TanhGaussian
from vmax_sim.agents.networks import Actor, Critic, EncoderFactory, Identity
from vmax_sim.agents.sac.config import SACConfig
from vmax_sim.agents.types import Params


class SACNetworks(NamedTuple):
    actor: Actor  # actor input (B, ...) -> TanhGaussian (B, A); the input is obs, or features when shared
    critic: Critic  # (obs (B, ...), action (B, A)) -> Q (num_critics, B)
    shared_encoder: bool = False

    def actor_input(self, critic_params: Params, obs):
        """What the actor reads: obs, or the critic encoder's features (B, D) with the gradient stopped."""
        if not self.shared_encoder:
            return obs
        return jax.lax.stop_gradient(self.critic.apply(critic_params, obs, method="encode"))

    def q_of_input(self, critic_params: Params, actor_input, action: jax.Array) -> jax.Array:
        """Q (num_critics, B) of (actor input, action): the full critic on obs, the heads alone on features."""
        if not self.shared_encoder:
            return self.critic.apply(critic_params, actor_input, action)
        return self.critic.apply(critic_params, actor_input, action, method="q_from_features")

    def policy(self, policy_params: Params, obs) -> TanhGaussian:
        """The acting distribution on obs from `policy_params` (see `policy_params_of`)."""
        if not self.shared_encoder:
            return self.actor.apply(policy_params, obs)
        return self.actor.apply(policy_params["actor"], self.actor_input(policy_params["critic"], obs))

    def policy_params_of(self, actor_params: Params, critic_params: Params) -> Params:
        """What acting needs: the actor's parameters, plus the critic's (its encoder) when shared."""
        return {"actor": actor_params, "critic": critic_params} if self.shared_encoder else actor_params


def make_networks(config: SACConfig, encoder_factory: EncoderFactory, action_dim: int) -> SACNetworks:
    critic = Critic(encoder_factory, config.value_hidden_sizes, config.activation, config.num_critics)
    actor = Actor(Identity if config.shared_encoder else encoder_factory, action_dim, config.policy_hidden_sizes,
                  config.activation, config.log_std_min, config.log_std_max)
    return SACNetworks(actor=actor, critic=critic, shared_encoder=config.shared_encoder)

"""SAC losses: pure array maths (hand-testable) and their network-level wrappers.

Shapes: B batch, A action dim, N Q heads.
    y      = reward_scale * r + gamma * discount * (min_i Q'_i(s', a') - alpha * log pi(a'|s')),  a' ~ pi(.|s')
    L_Q    = 1/2 * sum_i mean_B (Q_i(s, a) - y)^2                       (y held constant)
    L_pi   = mean_B (alpha * log pi(a~|s) - min_i Q_i(s, a~)),  a~ ~ pi(.|s) reparameterised
    L_alpha = -log(alpha) * mean_B (log pi(a~|s) + target_entropy)     (log pi held constant)

With row weights w (B,) (`Transition.mask`: self-play's empty and finished agent slots weigh 0) every mean_B is the
weighted one, sum_B w * x / sum_B w.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

from vmax_sim.agents import distributions as D
from vmax_sim.agents.common import row_mean, scalar
from vmax_sim.agents.sac.config import SACConfig
from vmax_sim.agents.sac.networks import SACNetworks
from vmax_sim.agents.types import Metrics, Params, Transition


def soft_td_target(reward: jax.Array, discount: jax.Array, next_q: jax.Array, next_log_prob: jax.Array,
                   alpha: jax.Array | float, gamma: float, reward_scale: float = 1.0) -> jax.Array:
    """Soft Bellman target y (B,) from reward (B,), discount (B,), target-critic Q (N, B) at (s', a') and
    log pi(a'|s') (B,)."""
    soft_value = jnp.min(next_q, axis=0) - alpha * next_log_prob
    return reward_scale * reward + gamma * discount * soft_value


def critic_loss(q: jax.Array, target: jax.Array, weights: jax.Array | None = None) -> jax.Array:
    """1/2 sum over heads of the mean squared TD error: q (N, B), target (B,), weights (B,) or None -> ()."""
    return 0.5 * jnp.sum(row_mean(jnp.square(q - target[None]), weights))


def actor_loss(q: jax.Array, log_prob: jax.Array, alpha: jax.Array | float,
               weights: jax.Array | None = None) -> jax.Array:
    """mean(alpha * log pi - min_i Q_i): q (N, B), log_prob (B,), weights (B,) or None -> ()."""
    return row_mean(alpha * log_prob - jnp.min(q, axis=0), weights)


def temperature_loss(log_alpha: jax.Array, log_prob: jax.Array, target_entropy: float,
                     weights: jax.Array | None = None) -> jax.Array:
    """-log_alpha * mean(log pi + target_entropy): (), (B,), weights (B,) or None -> (). Raises alpha when the
    policy's entropy (-log pi) is below the target."""
    return -log_alpha * row_mean(jax.lax.stop_gradient(log_prob) + target_entropy, weights)


class SACLosses(NamedTuple):
    """Network-level losses; each returns (loss (), aux)."""

    # (critic_params, target_critic_params, actor_params, alpha, batch, key) -> (loss, (metrics, actor_input)):
    # actor_input is what the actor loss reads for batch.obs (obs, or the detached encoder features when shared)
    critic: Callable[..., tuple[jax.Array, tuple[Metrics, object]]]
    # (actor_params, critic_params, alpha, batch, key) -> (loss, (log_prob (B,), metrics))
    actor: Callable[..., tuple[jax.Array, tuple[jax.Array, Metrics]]]
    # (dist, critic_params, alpha, actor_input, key, weights) -> (loss, (log_prob (B,), metrics)): the actor loss
    # once the policy distribution on obs is known (BC+SAC adds its imitation term to the same forward pass)
    actor_from_dist: Callable[..., tuple[jax.Array, tuple[jax.Array, Metrics]]]


def make_losses(networks: SACNetworks, config: SACConfig) -> SACLosses:
    def critic(critic_params: Params, target_critic_params: Params, actor_params: Params, alpha: jax.Array,
               batch: Transition, key: jax.Array):
        # shared encoder: the actor and the target heads read the online encoder's features of s' (DrQ-v2)
        next_input = networks.actor_input(critic_params, batch.next_obs)
        next_action, next_log_prob = D.sample_and_log_prob(networks.actor.apply(actor_params, next_input), key)
        next_q = networks.q_of_input(target_critic_params, next_input, next_action)  # (N, B)
        target = soft_td_target(batch.reward, batch.discount, next_q, next_log_prob, alpha, config.gamma,
                                config.reward_scale)
        target = jax.lax.stop_gradient(target)
        if networks.shared_encoder:
            features = networks.critic.apply(critic_params, batch.obs, method="encode")  # (B, D)
            q = networks.q_of_input(critic_params, features, batch.action)
            actor_input = jax.lax.stop_gradient(features)
        else:
            q = networks.critic.apply(critic_params, batch.obs, batch.action)  # (N, B)
            actor_input = batch.obs
        loss = critic_loss(q, target, batch.mask)
        # the logged means, as the losses, over the agent rows only
        return loss, ({"critic_loss": scalar(loss), "q_mean": scalar(jnp.mean(row_mean(q, batch.mask))),
                       "target_q_mean": scalar(row_mean(target, batch.mask))}, actor_input)

    def actor_from_dist(dist: D.TanhGaussian, critic_params: Params, alpha: jax.Array, obs, key: jax.Array,
                        weights: jax.Array | None = None):
        action, log_prob = D.sample_and_log_prob(dist, key)
        q = networks.q_of_input(critic_params, obs, action)
        loss = actor_loss(q, log_prob, alpha, weights)
        metrics = {"actor_loss": scalar(loss), "entropy": scalar(-row_mean(log_prob, weights)),
                   "policy_std": scalar(row_mean(jnp.mean(jnp.exp(dist.log_std), axis=-1), weights))}
        return loss, (log_prob, metrics)

    def actor(actor_params: Params, critic_params: Params, alpha: jax.Array, batch: Transition, key: jax.Array):
        return actor_from_dist(networks.actor.apply(actor_params, batch.obs), critic_params, alpha, batch.obs, key,
                               batch.mask)

    return SACLosses(critic=critic, actor=actor, actor_from_dist=actor_from_dist)

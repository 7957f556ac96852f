"""PPO maths: GAE with truncation, the clipped surrogate, the value loss; and the network-level loss.

Shapes: T time, B batch, N flat minibatch, A action dim.

GAE(gamma, lambda) over a rollout, for t = T-1 .. 0 (a reverse scan):
    delta_t = r_t + gamma * d_t * V(s'_t) - V(s_t)
    A_t     = delta_t + gamma * lambda * d_t * (1 - done_t) * A_{t+1},        returns_t = A_t + V(s_t)
d_t is the discount (0 at termination) and done_t ends the episode (termination or truncation), so the
recursion never crosses an episode boundary. V(s'_t) is V(s_{t+1}) inside an episode, the bootstrap value
after the last step, and V(next_obs_t) -- the true last state -- at a truncation.

    ratio   = exp(log pi(a|s) - log pi_old(a|s))
    L_clip  = -mean(min(ratio * A, clip(ratio, 1 - eps, 1 + eps) * A))
    L_V     = 1/2 mean((V - R)^2)   or, clipped, 1/2 mean(max((V - R)^2, (V_old + clip(V - V_old, -e, e) - R)^2))
    L       = L_clip + value_coef * L_V - entropy_coef * H[pi]
              (+ imitation_coef * mean |mode(pi) - a_teacher|^2, or * mean -log pi(a_teacher | s))
"""

from __future__ import annotations

from collections.abc import Callable

import flax.struct
import jax
import jax.numpy as jnp

from vmax_sim.agents import distributions as D
from vmax_sim.agents.common import scalar
from vmax_sim.agents.ppo.config import PPOConfig
from vmax_sim.agents.ppo.networks import PPONetworks, PPOParams
from vmax_sim.agents.types import Metrics, Observation


def next_values_with_truncation(values: jax.Array, bootstrap_value: jax.Array, truncated: jax.Array,
                                truncation_values: jax.Array) -> jax.Array:
    """V(s'_t) (T, B): values (T, B) shifted by one with bootstrap_value (B,) appended, replaced by
    truncation_values (T, B) (V of next_obs) where truncated (T, B)."""
    shifted = jnp.concatenate([values[1:], bootstrap_value[None]], axis=0)
    return jnp.where(jnp.asarray(truncated, bool), truncation_values, shifted)


def compute_gae(rewards: jax.Array, values: jax.Array, next_values: jax.Array, discounts: jax.Array,
                dones: jax.Array, gamma: float, gae_lambda: float) -> tuple[jax.Array, jax.Array]:
    """(advantages (T, B), returns (T, B)) from rewards, V(s_t), V(s'_t), discounts and dones, all (T, B)."""
    deltas = rewards + gamma * discounts * next_values - values
    decays = gamma * gae_lambda * discounts * (1.0 - dones.astype(deltas.dtype))

    def backward(next_advantage, step):
        delta, decay = step
        advantage = delta + decay * next_advantage
        return advantage, advantage

    _, advantages = jax.lax.scan(backward, jnp.zeros_like(deltas[0]), (deltas, decays), reverse=True)
    return advantages, advantages + values


def masked_mean(x: jax.Array, mask: jax.Array | None = None) -> jax.Array:
    """Mean of x over the entries where mask (same shape, 0 / 1) is 1; the plain mean without a mask."""
    if mask is None:
        return jnp.mean(x)
    return jnp.sum(x * mask) / jnp.maximum(jnp.sum(mask), 1.0)


def normalize(x: jax.Array, eps: float = 1e-8, mask: jax.Array | None = None) -> jax.Array:
    """(x - mean) / (std + eps), mean and std over all entries (the masked ones with a mask)."""
    mean = masked_mean(x, mask)
    std = jnp.sqrt(masked_mean(jnp.square(x - mean), mask))
    return (x - mean) / (std + eps)


def clipped_surrogate_loss(log_prob: jax.Array, old_log_prob: jax.Array, advantages: jax.Array,
                           clip_eps: float, mask: jax.Array | None = None) -> tuple[jax.Array, jax.Array]:
    """(L_clip (), fraction of entries whose ratio lies outside [1 - eps, 1 + eps] ()), inputs (N,)."""
    ratio = jnp.exp(log_prob - old_log_prob)
    surrogate = jnp.minimum(ratio * advantages, jnp.clip(ratio, 1.0 - clip_eps, 1.0 + clip_eps) * advantages)
    return -masked_mean(surrogate, mask), masked_mean((jnp.abs(ratio - 1.0) > clip_eps).astype(jnp.float32), mask)


def value_loss(values: jax.Array, returns: jax.Array, old_values: jax.Array | None = None,
               clip_eps: float | None = None, mask: jax.Array | None = None) -> jax.Array:
    """1/2 mean squared error (N,) -> (); with clip_eps, the pessimistic max with the clipped prediction."""
    loss = jnp.square(values - returns)
    if clip_eps is not None:
        clipped = old_values + jnp.clip(values - old_values, -clip_eps, clip_eps)
        loss = jnp.maximum(loss, jnp.square(clipped - returns))
    return 0.5 * masked_mean(loss, mask)


def approx_kl(log_prob: jax.Array, old_log_prob: jax.Array, mask: jax.Array | None = None) -> jax.Array:
    """KL(pi_old || pi) estimate mean((ratio - 1) - log ratio) >= 0, (N,) -> ()."""
    log_ratio = log_prob - old_log_prob
    return masked_mean(jnp.expm1(log_ratio) - log_ratio, mask)


@flax.struct.dataclass
class PPOBatch:
    """A flat minibatch of rollout data with its advantage targets."""

    obs: Observation  # pytree, leaves (N, ...)
    action: jax.Array  # (N, A)
    log_prob: jax.Array  # (N,) behaviour log pi(a|s)
    value: jax.Array  # (N,) behaviour V(s)
    advantage: jax.Array  # (N,) GAE advantage (not normalised)
    target: jax.Array  # (N,) GAE return, the value target
    mask: jax.Array  # (N,) float32, 1 for real experience, 0 for padding rows (empty or finished agent slots)
    expert_action: jax.Array  # (N, A) the teacher's label of the state (read only with imitation_coef > 0)


def make_loss(networks: PPONetworks, config: PPOConfig) -> Callable[..., tuple[jax.Array, Metrics]]:
    """loss(params: PPOParams, batch: PPOBatch, key) -> (L (), metrics)."""

    def loss(params: PPOParams, batch: PPOBatch, key: jax.Array):
        dist = networks.policy.apply(params.policy, batch.obs)
        log_prob = D.log_prob(dist, batch.action)
        mask = batch.mask
        advantages = normalize(batch.advantage, mask=mask) if config.normalize_advantages else batch.advantage
        policy_loss, clip_fraction = clipped_surrogate_loss(log_prob, batch.log_prob, advantages, config.clip_eps,
                                                            mask)
        values = networks.value.apply(params.value, batch.obs)
        v_loss = value_loss(values, batch.target, batch.value, config.value_clip_eps, mask)
        if config.entropy_estimate == "gaussian":
            entropy = masked_mean(D.entropy(dist), mask)
        else:
            entropy = masked_mean(D.sample_entropy(dist, key), mask)
        total = policy_loss + config.value_coef * v_loss - config.entropy_coef * entropy
        imitation = {}
        if config.imitation_coef > 0:
            squared_error = jnp.sum(jnp.square(D.mode(dist) - batch.expert_action), axis=-1)
            imitation_mse = masked_mean(squared_error, mask)
            imitation = {"imitation_mse": scalar(imitation_mse)}
            term = imitation_mse
            if config.imitation_loss == "nll":
                term = -masked_mean(D.log_prob(dist, batch.expert_action), mask)
                imitation["imitation_nll"] = scalar(term)
            total = total + config.imitation_coef * term
        metrics = {**imitation, "loss": scalar(total), "policy_loss": scalar(policy_loss), "value_loss": scalar(v_loss),
                   "entropy": scalar(entropy), "clip_fraction": scalar(clip_fraction),
                   "approx_kl": scalar(approx_kl(log_prob, batch.log_prob, mask)),
                   "policy_std": scalar(masked_mean(jnp.mean(jnp.exp(dist.log_std), axis=-1), mask))}
        return total, metrics

    return loss

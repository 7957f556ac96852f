"""BC+SAC actor loss: the SAC actor loss plus, on every `bc_every`-th update, a weighted BC term.

    L_pi = mean_B(alpha log pi(a~|s) - min_i Q_i(s, a~)) + w_k * L_BC(s, a_E),
    w_k  = bc_weight if k % bc_every == 0 else 0          (k: the update index)

Both terms share one actor forward pass; the SAC and BC pieces are the functions of `sac.losses` and
`bc.losses`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.agents.bc.losses import bc_loss
from vmax_sim.agents.bc_sac.config import BCSACConfig
from vmax_sim.agents.common import scalar
from vmax_sim.agents.sac.learner import ActorLossFn
from vmax_sim.agents.sac.losses import SACLosses
from vmax_sim.agents.sac.networks import SACNetworks
from vmax_sim.agents.types import Params, Transition


def bc_weight_at(step: jax.Array, bc_every: int, bc_weight: float) -> jax.Array:
    """() float32: bc_weight on updates step = 0, bc_every, 2 bc_every, ...; 0 otherwise."""
    return jnp.where(jnp.mod(step, bc_every) == 0, bc_weight, 0.0).astype(jnp.float32)


def make_actor_loss(networks: SACNetworks, sac: SACLosses, config: BCSACConfig) -> ActorLossFn:
    def actor_loss(actor_params: Params, critic_params: Params, alpha: jax.Array, batch: Transition,
                   key: jax.Array, step: jax.Array):
        dist = networks.actor.apply(actor_params, batch.obs)
        rl_loss, (log_prob, metrics) = sac.actor_from_dist(dist, critic_params, alpha, batch.obs, key, batch.mask)
        imitation, bc_metrics = bc_loss(dist, batch.expert_action, 1.0, config.bc_mse_weight,
                                        config.expert_action_eps, batch.mask)
        weight = bc_weight_at(step, config.bc_every, config.bc_weight)
        loss = rl_loss + weight * imitation
        return loss, (log_prob, {**metrics, **bc_metrics, "bc_weight": weight, "actor_total_loss": scalar(loss)})

    return actor_loss

"""SAC learner: `make_learner(config, encoder_factory, action_dim) -> Learner`.

One `update` is one critic step, one actor step (against the freshly updated critic), one temperature
step (with the actor step's log-probabilities) and one Polyak step of the target critic, on one batch.
"""

from __future__ import annotations

from collections.abc import Callable

import flax.struct
import jax
import jax.numpy as jnp
import optax

from vmax_sim.agents.common import apply_gradients, global_norm, make_optimizer, polyak_update, scalar
from vmax_sim.agents.networks import EncoderFactory
from vmax_sim.agents.policy import batch_size_of, make_act_fns
from vmax_sim.agents.sac import losses as sac_losses
from vmax_sim.agents.sac.config import SACConfig
from vmax_sim.agents.sac.networks import SACNetworks, make_networks
from vmax_sim.agents.types import Learner, Metrics, Params, Transition

# (actor_params, critic_params, alpha, batch, key, step) -> (loss, (log_prob (B,), metrics))
ActorLossFn = Callable[..., tuple[jax.Array, tuple[jax.Array, Metrics]]]


@flax.struct.dataclass
class SACTrainState:
    actor_params: Params
    critic_params: Params
    target_critic_params: Params  # Polyak average of critic_params
    log_alpha: jax.Array  # () temperature, log scale
    actor_opt_state: optax.OptState
    critic_opt_state: optax.OptState
    alpha_opt_state: optax.OptState
    step: jax.Array  # () int32, updates done


def build_learner(config: SACConfig, networks: SACNetworks,
                  actor_loss_factory: Callable[[sac_losses.SACLosses], ActorLossFn] | None = None) -> Learner:
    """The SAC learner on given networks. `actor_loss_factory(losses)` may return a replacement actor loss
    built from SAC's losses (BC+SAC adds its imitation term this way)."""
    losses = sac_losses.make_losses(networks, config)
    if actor_loss_factory is None:
        def actor_loss_fn(actor_params, critic_params, alpha, batch, key, step):
            return losses.actor(actor_params, critic_params, alpha, batch, key)
    else:
        actor_loss_fn = actor_loss_factory(losses)

    action_dim = networks.actor.action_dim
    target_entropy = config.target_entropy_for(action_dim)
    actor_opt = make_optimizer(config.learning_rate, config.max_grad_norm)
    critic_opt = make_optimizer(config.critic_learning_rate or config.learning_rate, config.max_grad_norm)
    alpha_opt = make_optimizer(config.alpha_learning_rate or config.learning_rate)

    def init(key: jax.Array, obs_example) -> SACTrainState:
        actor_key, critic_key = jax.random.split(key)
        action = jnp.zeros((batch_size_of(obs_example), action_dim), jnp.float32)
        critic_params = networks.critic.init(critic_key, obs_example, action)
        actor_params = networks.actor.init(actor_key, networks.actor_input(critic_params, obs_example))
        log_alpha = jnp.asarray(jnp.log(config.init_alpha), jnp.float32)
        return SACTrainState(
            actor_params=actor_params, critic_params=critic_params, target_critic_params=critic_params,
            log_alpha=log_alpha, actor_opt_state=actor_opt.init(actor_params),
            critic_opt_state=critic_opt.init(critic_params), alpha_opt_state=alpha_opt.init(log_alpha),
            step=jnp.zeros((), jnp.int32))

    def update(state: SACTrainState, batch: Transition, key: jax.Array) -> tuple[SACTrainState, Metrics]:
        critic_key, actor_key = jax.random.split(key)
        alpha = jnp.exp(state.log_alpha)

        (_, (critic_metrics, actor_input)), grads = jax.value_and_grad(losses.critic, has_aux=True)(
            state.critic_params, state.target_critic_params, state.actor_params, alpha, batch, critic_key)
        batch = batch.replace(obs=actor_input)  # the shared encoder's features of s, computed once
        critic_grad_norm = global_norm(grads)
        critic_params, critic_opt_state = apply_gradients(critic_opt, grads, state.critic_opt_state,
                                                          state.critic_params)

        (_, (log_prob, actor_metrics)), grads = jax.value_and_grad(actor_loss_fn, has_aux=True)(
            state.actor_params, critic_params, alpha, batch, actor_key, state.step)
        actor_grad_norm = global_norm(grads)
        actor_params, actor_opt_state = apply_gradients(actor_opt, grads, state.actor_opt_state, state.actor_params)

        if config.learn_alpha:
            alpha_loss, grads = jax.value_and_grad(sac_losses.temperature_loss)(state.log_alpha, log_prob,
                                                                                 target_entropy, batch.mask)
            log_alpha, alpha_opt_state = apply_gradients(alpha_opt, grads, state.alpha_opt_state, state.log_alpha)
        else:
            alpha_loss = sac_losses.temperature_loss(state.log_alpha, log_prob, target_entropy, batch.mask)
            log_alpha, alpha_opt_state = state.log_alpha, state.alpha_opt_state

        new_state = SACTrainState(
            actor_params=actor_params, critic_params=critic_params,
            target_critic_params=polyak_update(critic_params, state.target_critic_params, config.tau),
            log_alpha=log_alpha, actor_opt_state=actor_opt_state, critic_opt_state=critic_opt_state,
            alpha_opt_state=alpha_opt_state, step=state.step + 1)
        metrics = {**critic_metrics, **actor_metrics, "alpha_loss": scalar(alpha_loss), "alpha": scalar(alpha),
                   "critic_grad_norm": scalar(critic_grad_norm), "actor_grad_norm": scalar(actor_grad_norm)}
        return new_state, metrics

    act, act_with_info = make_act_fns(networks.policy)
    return Learner(init=init, update=update, act=act,
                   policy_params=lambda state: networks.policy_params_of(state.actor_params, state.critic_params),
                   act_with_info=act_with_info, value=None)


def make_learner(config: SACConfig, encoder_factory: EncoderFactory, action_dim: int) -> Learner:
    """SAC on networks built from `encoder_factory` (a fresh obs (B, ...) -> (B, D) module per call)."""
    return build_learner(config, make_networks(config, encoder_factory, action_dim))

"""Behaviour cloning learner: `make_learner(config, encoder_factory, action_dim) -> Learner`.

One `update` is one Adam step on `bc_loss` over a batch of Transitions (obs, expert_action used), then (when
`config.ema_decay` > 0) one step of the parameters' moving average, which is then the policy that acts.
With `config.members` M > 1 every parameter and optimiser leaf carries a leading member axis (M, ...), the batch
holds M minibatches one after the other (M * batch_size rows), each member takes its own step on its own, and the
members act as one (the mean of their actions).
"""

from __future__ import annotations

import flax.struct
import jax
import jax.numpy as jnp
import optax

from vmax_sim.agents.bc.config import BCConfig
from vmax_sim.agents.bc.losses import bc_loss, row_weights
from vmax_sim.agents.bc.networks import make_networks
from vmax_sim.agents.common import apply_gradients, ema_weight, global_norm, make_optimizer, polyak_update, scalar
from vmax_sim.agents.networks import EncoderFactory
from vmax_sim.agents.policy import combine_members, make_act_fns
from vmax_sim.agents.types import Learner, Metrics, Params, Transition


@flax.struct.dataclass
class BCTrainState:
    policy_params: Params
    opt_state: optax.OptState
    step: jax.Array  # () int32, updates done
    ema_params: Params | None = None  # moving average of policy_params (None when config.ema_decay == 0)


@flax.struct.dataclass
class ScheduledBCTrainState(BCTrainState):
    """The state of a learner whose rate falls over the run (config.lr_end_fraction < 1): a class of its own, so
    the checkpoints of constant-rate runs keep their layout and load as before."""
    lr_scale: jax.Array | None = None  # () float32, the learning rate's share, set by the loop before each chunk


def make_learner(config: BCConfig, encoder_factory: EncoderFactory, action_dim: int) -> Learner:
    actor = make_networks(config, encoder_factory, action_dim)
    optimizer = make_optimizer(config.learning_rate, config.max_grad_norm)
    members = config.members

    def init_member(key: jax.Array, obs_example):
        params = actor.init(key, obs_example)
        return params, optimizer.init(params)

    def init(key: jax.Array, obs_example) -> BCTrainState:
        if members == 1:
            params, opt_state = init_member(key, obs_example)
        else:  # each member from its own initialisation
            params, opt_state = jax.vmap(init_member, in_axes=(0, None))(jax.random.split(key, members), obs_example)
        state = BCTrainState(policy_params=params, opt_state=opt_state, step=jnp.zeros((), jnp.int32),
                             ema_params=params if config.ema_decay > 0 else None)
        if config.lr_end_fraction < 1.0:
            return ScheduledBCTrainState(**vars(state), lr_scale=jnp.ones((), jnp.float32))
        return state

    def loss_fn(params: Params, batch: Transition):
        weights = None
        if config.standing_weight != 1.0 or config.pull_away_weight != 1.0 or config.braking_weight != 1.0:
            weights = row_weights(batch.obs.sdc, batch.expert_action, config.standing_speed, config.standing_weight,
                                  config.pull_away_accel, config.pull_away_weight, config.braking_accel,
                                  config.braking_weight)
        # self-play's empty and finished agent slots are buffer rows too (mask 0): they carry no label
        weights = batch.mask if weights is None else weights * batch.mask
        return bc_loss(actor.apply(params, batch.obs), batch.expert_action, config.nll_weight, config.mse_weight,
                       config.expert_action_eps, weights, config.likelihood)

    def member_step(params: Params, opt_state, batch: Transition):
        (_, metrics), grads = jax.value_and_grad(loss_fn, has_aux=True)(params, batch)
        new_params, opt_state = apply_gradients(optimizer, grads, opt_state, params)
        return new_params, opt_state, {**metrics, "grad_norm": scalar(global_norm(grads))}

    def update(state: BCTrainState, batch: Transition, key: jax.Array) -> tuple[BCTrainState, Metrics]:
        del key  # the loss is deterministic
        if members == 1:
            params, opt_state, metrics = member_step(state.policy_params, state.opt_state, batch)
        else:  # (M * B, ...) rows -> M minibatches (M, B, ...), one per member; the metrics their mean
            minibatches = jax.tree.map(lambda x: x.reshape((members, -1) + x.shape[1:]), batch)
            params, opt_state, metrics = jax.vmap(member_step)(state.policy_params, state.opt_state, minibatches)
            metrics = jax.tree.map(jnp.mean, metrics)
        if isinstance(state, ScheduledBCTrainState):  # Adam's step times the share: the scaled learning rate's step
            params = jax.tree.map(lambda old, new: old + state.lr_scale * (new - old), state.policy_params, params)
        ema = state.ema_params
        if config.ema_decay > 0:
            ema = polyak_update(params, ema, ema_weight(state.step, config.ema_decay))
        return state.replace(policy_params=params, opt_state=opt_state, step=state.step + 1, ema_params=ema), metrics

    def acting_params(state: BCTrainState) -> Params:
        return state.ema_params if config.ema_decay > 0 else state.policy_params

    act, act_with_info = make_act_fns(actor.apply)
    if members > 1:
        act, act_with_info = combine_members(act, config.member_rule)
    return Learner(init=init, update=update, act=act, policy_params=acting_params, act_with_info=act_with_info,
                   value=None)

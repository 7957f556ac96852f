"""PPO learner: `make_learner(config, encoder_factory, action_dim) -> Learner`.

`update(state, rollout, key, bootstrap_value=None)` takes a rollout Transition with leading (T, B) dims
collected with the current policy (its log_prob and value fields filled by `act_with_info`), computes
GAE once with the behaviour values, then runs `num_epochs` epochs of `num_minibatches` shuffled
minibatch steps, all inside one `lax.scan` over epochs of a `lax.scan` over minibatches; with
`active_minibatch_size` N the epochs step through the rows with mask 1 only, N at a time (a `fori_loop` of
ceil(active / N) steps), so self-play's empty agent slots cost no gradient work.
"""

from __future__ import annotations

import flax.struct
import jax
import jax.numpy as jnp
import optax

from vmax_sim.agents.common import apply_gradients, ema_weight, global_norm, make_optimizer, polyak_update, scalar
from vmax_sim.agents.networks import EncoderFactory
from vmax_sim.agents.policy import make_act_fns
from vmax_sim.agents.ppo import losses as ppo_losses
from vmax_sim.agents.ppo.config import PPOConfig
from vmax_sim.agents.ppo.networks import PPOParams, make_networks
from vmax_sim.agents.types import Learner, Metrics, Transition


@flax.struct.dataclass
class PPOTrainState:
    params: PPOParams
    opt_state: optax.OptState
    step: jax.Array  # () int32, updates (rollouts) done
    ema_params: PPOParams | None = None  # moving average of params (None when config.ema_decay == 0)


def _flatten_time(tree):
    """(T, B, ...) -> (T * B, ...) leaf by leaf."""
    return jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), tree)


def make_learner(config: PPOConfig, encoder_factory: EncoderFactory, action_dim: int) -> Learner:
    networks = make_networks(config, encoder_factory, action_dim)
    loss_fn = ppo_losses.make_loss(networks, config)
    optimizer = make_optimizer(config.learning_rate, config.max_grad_norm)

    def init(key: jax.Array, obs_example) -> PPOTrainState:
        policy_key, value_key = jax.random.split(key)
        params = PPOParams(policy=networks.policy.init(policy_key, obs_example),
                           value=networks.value.init(value_key, obs_example))
        return PPOTrainState(params=params, opt_state=optimizer.init(params), step=jnp.zeros((), jnp.int32),
                             ema_params=params if config.ema_decay > 0 else None)

    def value(params: PPOParams, obs) -> jax.Array:
        return networks.value.apply(params.value, obs)

    def advantages_and_returns(params: PPOParams, rollout: Transition, bootstrap_value):
        """GAE (T, B) with the behaviour values; V(next_obs) is evaluated only when a step was truncated."""
        num_steps, num_envs = rollout.reward.shape
        if bootstrap_value is None:
            bootstrap_value = value(params, jax.tree.map(lambda x: x[-1], rollout.next_obs))
        truncation_values = jax.lax.cond(
            jnp.any(jnp.asarray(rollout.truncated, bool)),
            lambda: value(params, _flatten_time(rollout.next_obs)).reshape(num_steps, num_envs),
            lambda: jnp.zeros((num_steps, num_envs), jnp.float32))
        next_values = ppo_losses.next_values_with_truncation(rollout.value, bootstrap_value, rollout.truncated,
                                                              truncation_values)
        return ppo_losses.compute_gae(config.reward_scale * rollout.reward, rollout.value, next_values,
                                      rollout.discount, rollout.done, config.gamma, config.gae_lambda)

    def sgd_step(carry, minibatch):
        params, opt_state = carry
        batch, key = minibatch
        (_, metrics), grads = jax.value_and_grad(loss_fn, has_aux=True)(params, batch, key)
        params, opt_state = apply_gradients(optimizer, grads, opt_state, params)
        return (params, opt_state), {**metrics, "grad_norm": scalar(global_norm(grads))}

    def active_epochs(carry, data: ppo_losses.PPOBatch, epoch_keys: jax.Array):
        """`num_epochs` passes over the rows with mask 1 only, `active_minibatch_size` of them per gradient step:
        ceil(active / size) steps per epoch, the last one filled up with active rows drawn again. Self-play's
        empty and finished agent slots (most rows) then cost no gradient work. -> (carry, metrics averaged over
        the steps taken; zeros when no row is active)"""
        size = config.active_minibatch_size
        num_rows = data.mask.shape[0]
        active = data.mask > 0  # (N,)
        num_active = jnp.sum(active.astype(jnp.int32))
        steps_per_epoch = (num_active + size - 1) // size
        metrics_shape = jax.eval_shape(sgd_step, carry, (jax.tree.map(lambda x: x[:size], data), epoch_keys[0]))[1]
        zeros = jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), metrics_shape)

        def epoch(scan_carry, epoch_key):
            perm_key, loss_key = jax.random.split(epoch_key)
            # the active rows first, in random order (an inactive row's key is >= 1)
            order = jnp.argsort(jax.random.uniform(perm_key, (num_rows,)) + (~active).astype(jnp.float32))

            def step(i, loop_carry):
                params_and_opt, sums = loop_carry
                rows = order[(i * size + jnp.arange(size)) % jnp.maximum(num_active, 1)]
                batch = jax.tree.map(lambda x: x[rows], data)
                params_and_opt, step_metrics = sgd_step(params_and_opt, (batch, jax.random.fold_in(loss_key, i)))
                return params_and_opt, jax.tree.map(jnp.add, sums, step_metrics)

            return jax.lax.fori_loop(0, steps_per_epoch, step, scan_carry), None

        (carry, sums), _ = jax.lax.scan(epoch, (carry, zeros), epoch_keys)
        taken = jnp.maximum(steps_per_epoch * len(epoch_keys), 1).astype(jnp.float32)
        return carry, jax.tree.map(lambda total: total / taken, sums)

    def update(state: PPOTrainState, rollout: Transition, key: jax.Array,
               bootstrap_value: jax.Array | None = None) -> tuple[PPOTrainState, Metrics]:
        num_steps, num_envs = rollout.reward.shape
        num_samples = num_steps * num_envs
        if num_samples % config.num_minibatches and not config.active_minibatch_size:
            raise ValueError(f"a rollout of T * B = {num_steps} * {num_envs} transitions does not split into "
                             f"{config.num_minibatches} minibatches")
        minibatch_size = num_samples // config.num_minibatches
        advantages, returns = advantages_and_returns(state.params, rollout, bootstrap_value)
        data = ppo_losses.PPOBatch(obs=_flatten_time(rollout.obs), action=_flatten_time(rollout.action),
                                   log_prob=rollout.log_prob.reshape(-1), value=rollout.value.reshape(-1),
                                   advantage=advantages.reshape(-1), target=returns.reshape(-1),
                                   mask=rollout.mask.reshape(-1),
                                   expert_action=_flatten_time(rollout.expert_action))

        def epoch(carry, epoch_key):
            perm_key, loss_key = jax.random.split(epoch_key)
            order = jax.random.permutation(perm_key, num_samples)
            shuffled = jax.tree.map(
                lambda x: x[order].reshape((config.num_minibatches, minibatch_size) + x.shape[1:]), data)
            keys = jax.random.split(loss_key, config.num_minibatches)
            return jax.lax.scan(sgd_step, carry, (shuffled, keys))

        epoch_keys = jax.random.split(key, config.num_epochs)
        if config.active_minibatch_size:
            (params, opt_state), metrics = active_epochs((state.params, state.opt_state), data, epoch_keys)
        else:
            (params, opt_state), metrics = jax.lax.scan(epoch, (state.params, state.opt_state), epoch_keys)
            metrics = jax.tree.map(jnp.mean, metrics)  # over epochs and minibatches
        mask = rollout.mask
        return_mean = ppo_losses.masked_mean(returns, mask)
        residual = returns - rollout.value
        residual_var = ppo_losses.masked_mean(jnp.square(residual - ppo_losses.masked_mean(residual, mask)), mask)
        return_var = ppo_losses.masked_mean(jnp.square(returns - return_mean), mask)
        metrics.update(advantage_mean=scalar(ppo_losses.masked_mean(advantages, mask)),
                       return_mean=scalar(return_mean),
                       explained_variance=scalar(1.0 - residual_var / (return_var + 1e-8)))
        ema = state.ema_params
        if config.ema_decay > 0:
            ema = polyak_update(params, ema, ema_weight(state.step, config.ema_decay))
        return PPOTrainState(params=params, opt_state=opt_state, step=state.step + 1, ema_params=ema), metrics

    act, policy_act_with_info = make_act_fns(lambda params, obs: networks.policy.apply(params.policy, obs))

    def act_with_info(params: PPOParams, obs, key: jax.Array, deterministic=False):
        action, info = policy_act_with_info(params, obs, key, deterministic)
        return action, {**info, "value": value(params, obs)}

    def policy_params(state: PPOTrainState) -> PPOParams:  # evaluated and saved as the run's policy
        return state.ema_params if config.ema_decay > 0 else state.params

    return Learner(init=init, update=update, act=act, policy_params=policy_params, act_with_info=act_with_info,
                   value=value, behaviour_params=lambda state: state.params)

"""A 1-D point-reaching task in pure JAX, a tiny encoder, and minimal training loops for the learners.

Each of N parallel envs holds a position p and a target g, both drawn in [-1, 1] at reset. The action
a in [-1, 1] is a velocity: p' = clip(p + a, -2, 2); the reward is -|p' - g|. Episodes are cut by the time
limit after EPISODE_LENGTH steps (a truncation: discount stays 1, next_obs is the true last state) and
the env resets itself. The expert plays clip(g - p, -1, 1), which reaches any target within 1 in one
step. Observations are a dict pytree {"position": (N, 1), "target": (N, 1)}.
"""

from __future__ import annotations

import flax.linen as nn
import flax.struct
import jax
import jax.numpy as jnp

from vmax_sim.agents import Transition

EPISODE_LENGTH = 20
ACTION_DIM = 1


class ToyEncoder(nn.Module):
    """Concatenates the flattened leaves of the observation pytree: (B, ...) -> (B, D); a Dense + relu
    layer when `features` is set."""

    features: int | None = 32

    @nn.compact
    def __call__(self, obs):
        leaves = [x.reshape(x.shape[0], -1) for x in jax.tree.leaves(obs)]
        x = jnp.concatenate(leaves, axis=-1).astype(jnp.float32)
        return x if self.features is None else nn.relu(nn.Dense(self.features)(x))


@flax.struct.dataclass
class ToyState:
    position: jax.Array  # (N,)
    target: jax.Array  # (N,)
    t: jax.Array  # (N,) int32 steps taken in the episode


def reset(key: jax.Array, num_envs: int) -> ToyState:
    pos_key, target_key = jax.random.split(key)
    return ToyState(position=jax.random.uniform(pos_key, (num_envs,), minval=-1.0, maxval=1.0),
                    target=jax.random.uniform(target_key, (num_envs,), minval=-1.0, maxval=1.0),
                    t=jnp.zeros((num_envs,), jnp.int32))


def observe(state: ToyState) -> dict:
    return {"position": state.position[:, None], "target": state.target[:, None]}


def expert_action(state: ToyState) -> jax.Array:
    return jnp.clip(state.target - state.position, -1.0, 1.0)[:, None]


def step(key: jax.Array, state: ToyState, action: jax.Array) -> tuple[ToyState, Transition]:
    """Applies action (N, 1); returns the (auto-reset) next state and the Transition of this step."""
    obs = observe(state)
    moved = ToyState(position=jnp.clip(state.position + action[:, 0], -2.0, 2.0), target=state.target, t=state.t + 1)
    reward = -jnp.abs(moved.position - moved.target)
    truncated = moved.t >= EPISODE_LENGTH
    fresh = reset(key, state.position.shape[0])
    next_state = jax.tree.map(lambda a, b: jnp.where(truncated, a, b), fresh, moved)
    transition = Transition.make(obs=obs, action=action, reward=reward, discount=jnp.ones_like(reward),
                                 next_obs=observe(moved), expert_action=expert_action(state), truncated=truncated,
                                 done=truncated)
    return next_state, transition


def episode_return(policy_fn, key: jax.Array, num_envs: int = 256) -> jax.Array:
    """Mean undiscounted return of one episode of `policy_fn(obs, key) -> (N, 1)` from fresh resets."""
    reset_key, key = jax.random.split(key)
    state = reset(reset_key, num_envs)

    def body(carry, step_key):
        state, total = carry
        act_key, env_key = jax.random.split(step_key)
        state, transition = step(env_key, state, policy_fn(observe(state), act_key))
        return (state, total + transition.reward), None

    (_, total), _ = jax.lax.scan(body, (state, jnp.zeros(num_envs)), jax.random.split(key, EPISODE_LENGTH))
    return jnp.mean(total)


def random_policy(obs, key):
    return jax.random.uniform(key, (obs["position"].shape[0], ACTION_DIM), minval=-1.0, maxval=1.0)


def train_off_policy(learner, key: jax.Array, *, num_envs: int, num_iterations: int, warmup_iterations: int,
                     updates_per_step: int, batch_size: int):
    """Collect into an on-device buffer (uniform random actions during warm-up, then the learner's stochastic
    policy) and run `updates_per_step` updates on uniform samples per env step after warm-up.

    Returns (learner state, metrics of the last update)."""
    init_key, env_key, key = jax.random.split(key, 3)
    env_state = reset(env_key, num_envs)
    state = learner.init(init_key, observe(env_state))
    _, example = step(env_key, env_state, jnp.zeros((num_envs, ACTION_DIM)))
    buffer = jax.tree.map(lambda x: jnp.zeros((num_envs * num_iterations,) + x.shape[1:], x.dtype), example)
    _, metrics = jax.eval_shape(learner.update, state, jax.tree.map(lambda x: x[:batch_size], buffer), key)
    metrics = jax.tree.map(lambda m: jnp.zeros(m.shape, m.dtype), metrics)

    def iteration(carry, inputs):
        env_state, state, buffer, metrics = carry
        it, iteration_key = inputs
        act_key, env_key, update_key = jax.random.split(iteration_key, 3)
        obs = observe(env_state)
        action = jnp.where(it < warmup_iterations, random_policy(obs, act_key),
                           learner.act(learner.policy_params(state), obs, act_key, False))
        env_state, transition = step(env_key, env_state, action)
        buffer = jax.tree.map(lambda b, x: jax.lax.dynamic_update_slice_in_dim(b, x, it * num_envs, 0),
                              buffer, transition)

        def one_update(state_metrics, k):
            sample_key, k = jax.random.split(k)
            index = jax.random.randint(sample_key, (batch_size,), 0, (it + 1) * num_envs)
            return learner.update(state_metrics[0], jax.tree.map(lambda x: x[index], buffer), k), None

        def updates(state_metrics):
            return jax.lax.scan(one_update, state_metrics, jax.random.split(update_key, updates_per_step))[0]

        state, metrics = jax.lax.cond(it >= warmup_iterations, updates, lambda sm: sm, (state, metrics))
        return (env_state, state, buffer, metrics), None

    inputs = (jnp.arange(num_iterations), jax.random.split(key, num_iterations))
    (_, state, _, metrics), _ = jax.jit(lambda c: jax.lax.scan(iteration, c, inputs))(
        (env_state, state, buffer, metrics))
    return state, metrics


def train_on_policy(learner, key: jax.Array, *, num_envs: int, unroll_length: int, num_updates: int,
                    pass_bootstrap: bool = True):
    """PPO-style loop: unroll `unroll_length` steps with act_with_info, then one update on the (T, B) rollout."""
    init_key, env_key, key = jax.random.split(key, 3)
    env_state = reset(env_key, num_envs)
    state = learner.init(init_key, observe(env_state))

    def unroll_step(carry, step_key):
        env_state, params = carry
        act_key, env_key = jax.random.split(step_key)
        action, info = learner.act_with_info(params, observe(env_state), act_key)
        env_state, transition = step(env_key, env_state, action)
        return (env_state, params), transition.replace(log_prob=info["log_prob"], value=info["value"])

    def iteration(carry, iteration_key):
        env_state, state = carry
        unroll_key, update_key = jax.random.split(iteration_key)
        params = learner.policy_params(state)
        (env_state, _), rollout = jax.lax.scan(unroll_step, (env_state, params),
                                               jax.random.split(unroll_key, unroll_length))
        if pass_bootstrap:  # V of the state after the unroll (auto-reset where the last step ended an episode)
            state, metrics = learner.update(state, rollout, update_key,
                                            bootstrap_value=learner.value(params, observe(env_state)))
        else:  # the learner evaluates V(next_obs[-1]) itself
            state, metrics = learner.update(state, rollout, update_key)
        return (env_state, state), metrics

    (_, state), metrics = jax.jit(lambda c: jax.lax.scan(iteration, c, jax.random.split(key, num_updates)))(
        (env_state, state))
    return state, jax.tree.map(lambda m: m[-1], metrics)


def random_batch(key: jax.Array, batch_size: int) -> Transition:
    """Transitions from random states under uniform random actions (with the expert's labels)."""
    state_key, action_key, step_key = jax.random.split(key, 3)
    state = reset(state_key, batch_size)
    state = state.replace(t=jax.random.randint(step_key, (batch_size,), 0, EPISODE_LENGTH))
    _, transition = step(step_key, state, random_policy(observe(state), action_key))
    return transition


def assert_trees_equal(a, b) -> None:
    import numpy as np

    jax.tree.map(lambda x, y: np.testing.assert_array_equal(np.asarray(x), np.asarray(y)), a, b)

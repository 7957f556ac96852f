"""Data the learners consume and the `Learner` they expose.

Shapes use B for the batch, T for time (on-policy rollouts carry (T, B) leading dims), A for the
action dimension. Observations are arbitrary pytrees whose leaves carry the same leading dims.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import flax.struct
import jax
import jax.numpy as jnp

Params = Any  # a pytree of arrays (flax variables)
Observation = Any  # a pytree of arrays with leading batch dims
Metrics = dict[str, jax.Array]  # every value () float32


@flax.struct.dataclass
class Transition:
    """One environment step per batch entry (replay-buffer sample or on-policy rollout).

    `discount` is 0 when the episode terminated at this step and 1 otherwise: a time-limit truncation
    keeps discount 1 and `next_obs` holds the true last state (not the auto-reset one), so targets
    bootstrap through it. The on-policy fields are ignored by the off-policy learners; `make` fills
    any field not given with zeros (False for flags, 1 for `mask`), so one structure serves every learner.
    """

    obs: Observation  # pytree, leaves (B, ...) or (T, B, ...)
    action: jax.Array  # (B, A) squashed action in [-1, 1] that was applied
    reward: jax.Array  # (B,)
    discount: jax.Array  # (B,) float, 0 at termination, 1 otherwise (truncation included)
    next_obs: Observation  # pytree, leaves (B, ...): the true next state, even at truncation
    expert_action: jax.Array  # (B, A) log/expert action in [-1, 1]; zeros when unknown
    log_prob: jax.Array  # (B,) behaviour log-probability of `action` (on-policy data)
    value: jax.Array  # (B,) behaviour value estimate V(obs) (on-policy data)
    truncated: jax.Array  # (B,) bool, episode cut by the time limit at this step
    done: jax.Array  # (B,) bool, episode ended at this step (terminated or truncated)
    # (B,) float32, 1 where the row is real experience: 0 for an agent slot that is empty or whose agent already
    # finished (self-play's flat envs x agents batch); the learners weight their losses by it
    mask: jax.Array

    @classmethod
    def make(cls, obs, action, reward, discount, next_obs, expert_action=None, log_prob=None, value=None,
             truncated=None, done=None, mask=None) -> Transition:
        """A Transition whose optional fields default to zeros shaped like `reward` / `action`."""
        reward = jnp.asarray(reward, jnp.float32)
        action = jnp.asarray(action, jnp.float32)

        def or_zeros(x, like, dtype):
            return jnp.zeros(like.shape, dtype) if x is None else jnp.asarray(x, dtype)

        return cls(obs=obs, action=action, reward=reward, discount=jnp.asarray(discount, jnp.float32),
                   next_obs=next_obs,
                   expert_action=or_zeros(expert_action, action, jnp.float32),
                   log_prob=or_zeros(log_prob, reward, jnp.float32),
                   value=or_zeros(value, reward, jnp.float32),
                   truncated=or_zeros(truncated, reward, bool),
                   done=or_zeros(done, reward, bool),
                   mask=jnp.ones(reward.shape, jnp.float32) if mask is None else jnp.asarray(mask, jnp.float32))


class Learner(NamedTuple):
    """A learning algorithm as pure functions (Optax's `(init, update)` model). All are jittable.

    init(key, obs_example) -> state
        obs_example: a *batched* observation pytree (leading batch dim, any B >= 1); only shapes are used.
    update(state, batch, key) -> (state, metrics)
        batch: Transition (B, ...) for sac / bc / bc_sac; a rollout Transition (T, B, ...) for ppo, which
        also takes `bootstrap_value=` (B,) V of the state after the last step (computed when omitted).
        metrics: dict of () float32.
    act(params, obs, key, deterministic) -> action (B, A) in [-1, 1]
        deterministic: python or traced bool; the tanh of the Gaussian mean when true, a sample otherwise.
    policy_params(state) -> params for `act` / `act_with_info` / `value`.
    act_with_info(params, obs, key, deterministic=False) -> (action (B, A), info)
        info: {"log_prob": (B,)} (log-probability of the returned action) and, for ppo, "value": (B,).
    value(params, obs) -> (B,) state value; None for learners without a value function.
    behaviour_params(state) -> params that collect on-policy rollouts (ppo: the raw parameters when policy_params
        is their moving average); None: policy_params.
    """

    init: Callable[..., Any]
    update: Callable[..., tuple[Any, Metrics]]
    act: Callable[..., jax.Array]
    policy_params: Callable[[Any], Params]
    act_with_info: Callable[..., tuple[jax.Array, Metrics]]
    value: Callable[..., jax.Array] | None = None
    behaviour_params: Callable[[Any], Params] | None = None

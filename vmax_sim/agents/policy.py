"""Acting with a tanh-Gaussian actor: the policy functions every learner exposes."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from vmax_sim.agents import distributions as D
from vmax_sim.agents.types import Params


def batch_size_of(obs) -> int:
    """Leading dim of the observation pytree's leaves."""
    leaves = jax.tree.leaves(obs)
    if not leaves:
        raise ValueError("the observation pytree has no array leaves")
    return int(jnp.shape(leaves[0])[0])


def select_action(dist: D.TanhGaussian, key: jax.Array, deterministic) -> jax.Array:
    """tanh(loc) when `deterministic` (python or traced bool), a sample otherwise: (B, A)."""
    if isinstance(deterministic, bool):  # static: trace only the branch taken
        return D.mode(dist) if deterministic else D.sample(dist, key)
    return jnp.where(deterministic, D.mode(dist), D.sample(dist, key))


def make_act_fns(dist_fn: Callable[[Params, object], D.TanhGaussian]):
    """(act, act_with_info) from `dist_fn(params, obs) -> TanhGaussian (B, A)`.

    The info's log_prob is `distributions.log_prob` of the returned (squashed, clipped) action, the same
    function the PPO ratio uses at update time, so the first epoch's ratio is exactly 1.
    """

    def act(params: Params, obs, key: jax.Array, deterministic=False) -> jax.Array:
        return select_action(dist_fn(params, obs), key, deterministic)

    def act_with_info(params: Params, obs, key: jax.Array, deterministic=False):
        dist = dist_fn(params, obs)
        action = select_action(dist, key, deterministic)
        return action, {"log_prob": D.log_prob(dist, action)}

    return act, act_with_info


def mean_of_members(act: Callable) -> tuple[Callable, Callable]:
    """(act, act_with_info) of several policies driving as one: `act`'s parameters stacked on a leading member axis
    (M, ...), the action the mean of the members' actions (B, A). A mean of members has no density: the info's
    log_prob is 0."""

    def mean_act(params: Params, obs, key: jax.Array, deterministic=False) -> jax.Array:
        actions = jax.vmap(lambda member: act(member, obs, key, deterministic))(params)  # (M, B, A)
        return jnp.mean(actions, axis=0)

    def mean_act_with_info(params: Params, obs, key: jax.Array, deterministic=False):
        action = mean_act(params, obs, key, deterministic)
        return action, {"log_prob": jnp.zeros(action.shape[:1], action.dtype)}

    return mean_act, mean_act_with_info

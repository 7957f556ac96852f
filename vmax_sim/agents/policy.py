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


# how several policies' actions become the one they drive with (`train.ensemble_rule`, bc's `algo.member_rule`)
MEMBER_RULES = ("mean", "median", "cautious")


def check_member_rule(rule: str, setting: str = "member rule") -> None:
    """Refuses a `rule` not in MEMBER_RULES, naming the `setting` it came from."""
    if rule not in MEMBER_RULES:
        raise ValueError(f"{setting} must be one of {', '.join(MEMBER_RULES)}, got {rule!r}")


def combine_actions(actions: jax.Array, rule: str = "mean") -> jax.Array:
    """The members' actions (M, B, A) as one (B, A). "mean": their mean. "median": each component's median, which
    one member far from the others (a confident go among brakes, or a stall among goes) does not move.
    "cautious": their mean, but the smallest acceleration (component 0 of the bicycle models' (acceleration,
    curvature) actions): where one member brakes the group brakes, where the mean of a confident go and a brake
    would still go (docs/learning.md, session 52)."""
    check_member_rule(rule)
    if rule == "median":
        return jnp.median(actions, axis=0)
    mean = jnp.mean(actions, axis=0)
    if rule == "mean":
        return mean
    return mean.at[..., 0].set(jnp.min(actions[..., 0], axis=0))


def combine_members(act: Callable, rule: str = "mean") -> tuple[Callable, Callable]:
    """(act, act_with_info) of several policies driving as one: `act`'s parameters stacked on a leading member axis
    (M, ...), the action the members' actions (B, A) combined by `rule` (`combine_actions`). A combination of
    members has no density: the info's log_prob is 0."""
    check_member_rule(rule)

    def combined_act(params: Params, obs, key: jax.Array, deterministic=False) -> jax.Array:
        actions = jax.vmap(lambda member: act(member, obs, key, deterministic))(params)  # (M, B, A)
        return combine_actions(actions, rule)

    def combined_act_with_info(params: Params, obs, key: jax.Array, deterministic=False):
        action = combined_act(params, obs, key, deterministic)
        return action, {"log_prob": jnp.zeros(action.shape[:1], action.dtype)}

    return combined_act, combined_act_with_info

"""Policies for evaluation: the log expert, a constant-velocity baseline, and user callables.

A `Policy` (vmax_sim.policies.base) maps (params, state, observation or None, key) to an `Action` for every
object of one unbatched scenario; `make_policy` turns a name, a `Policy` or a callable into one. `Policy`,
`ActionFn` and `sdc_action` live below evaluation (the rule policies and the learning environment use them
too) and are re-exported here, where they were first defined.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable

import jax.numpy as jnp

from vmax_sim.datatypes import Action, sdc_action
from vmax_sim.dynamics import BICYCLE_NAMES
from vmax_sim.policies.base import ActionFn, Policy

POLICY_NAMES = ("expert", "constant", "idm", "pdm", "random")


def expert_policy(env) -> Policy:
    """Inverse-dynamics expert: follows the SDC's log, closing the loop on the simulated state."""
    return Policy("expert", lambda params, state, observation, key: env.expert_action(state))


def constant_policy(env) -> Policy:
    """Keeps the current speed and heading (zero action of the bicycle / delta models)."""
    if env.dynamics.name not in BICYCLE_NAMES:
        raise ValueError(f"the constant policy needs the bicycle dynamics, not {env.dynamics.name!r}")

    def action_fn(params, state, observation, key):
        num_objects = state.num_objects
        zero = jnp.zeros((num_objects, env.action_dim), jnp.float32)
        if env.config.normalize_actions:  # the physical zero action in [-1, 1] units
            zero = env.dynamics.normalize(zero)
        return Action(data=zero, valid=jnp.ones((num_objects, 1), bool))

    return Policy("constant", action_fn)


def callable_policy(fn: Callable, name: str | None = None, inputs: str = "observation") -> Policy:
    """Wraps a user function `fn(observation, key)` (or `fn(state, key)` with inputs="state").

    It returns either an (action_dim,) array for the SDC or a full `Action`; it must be jittable.
    """
    if inputs not in ("observation", "state"):
        raise ValueError(f"policy inputs must be 'observation' or 'state', got {inputs!r}")

    def action_fn(params, state, observation, key):
        out = fn(observation if inputs == "observation" else state, key)
        return out if isinstance(out, Action) else sdc_action(state, out)

    return Policy(name or getattr(fn, "__name__", "callable"), action_fn, needs_observation=inputs == "observation")


def make_policy(policy, env) -> Policy:
    """A `Policy` from a name (see POLICY_NAMES; "idm", "pdm" and "random" with their default configs from
    `vmax_sim.policies`), a `Policy`, or a callable (see `callable_policy`)."""
    if isinstance(policy, Policy):
        return policy
    if isinstance(policy, str):
        if policy == "expert":
            return expert_policy(env)
        if policy == "constant":
            return constant_policy(env)
        if policy in ("idm", "pdm", "random"):
            from vmax_sim import policies

            return getattr(policies, f"{policy}_policy")(env)
        raise ValueError(f"unknown policy {policy!r}; choose one of {POLICY_NAMES} or pass a callable")
    if callable(policy):
        num_params = len(inspect.signature(policy).parameters)
        if num_params != 2:
            raise ValueError(f"a policy callable takes (observation, key); {policy!r} takes {num_params} arguments")
        return callable_policy(policy)
    raise ValueError(f"a policy is a name {POLICY_NAMES}, a Policy or a callable, got {type(policy).__name__}")


__all__ = ["POLICY_NAMES", "ActionFn", "Policy", "callable_policy", "constant_policy", "expert_policy",
           "make_policy", "sdc_action"]

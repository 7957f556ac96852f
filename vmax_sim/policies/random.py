"""Uniformly random actions within the dynamics model's bounds (a floor for every score)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import Action
from vmax_sim.policies.base import Policy


def random_policy(env) -> Policy:
    """Every object gets an action drawn uniformly within the bounds from the step's key."""
    low, high = env.dynamics.action_low, env.dynamics.action_high  # raises for models without bounds

    def action_fn(params, state, observation, key):
        shape = (state.num_objects, env.action_dim)
        data = jax.random.uniform(key, shape, jnp.float32, low, high)
        if env.config.normalize_actions:
            data = env.dynamics.normalize(data)
        return Action(data=data, valid=jnp.ones((state.num_objects, 1), bool))

    return Policy("random", action_fn)

"""`MultiAgentEnvironment`: the policy (or policies) drive the SDC and every controllable object.

Used for reactive evaluation: objects flagged `is_controllable` in the shards (or an explicit
mask) move by the dynamics model from actions the caller composes, e.g. the SDC from the learned
policy and the others from IDM, with `merge_actions`.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import Action, SimulatorState
from vmax_sim.dynamics import DynamicsModel
from vmax_sim.env.config import EnvConfig
from vmax_sim.env.environment import Environment
from vmax_sim.env.termination import TerminationFn


class MultiAgentEnvironment(Environment):
    """Environment whose controlled set is `controllable` (unless the config gives an explicit mask)."""

    def __init__(self, config: EnvConfig | None = None, termination_fn: TerminationFn | None = None,
                 dynamics: DynamicsModel | None = None):
        config = config or EnvConfig()
        if config.controlled == "sdc":
            config = dataclasses.replace(config, controlled="controllable")
        super().__init__(config, termination_fn, dynamics)


def merge_actions(first: Action, second: Action, use_first: jax.Array) -> Action:
    """Per object, `first` where use_first (..., N) else `second` (e.g. SDC policy + agent policy)."""
    mask = use_first[..., None]
    return Action(data=jnp.where(mask, first.data, second.data), valid=jnp.where(mask, first.valid, second.valid))


def sdc_and_agents_action(state: SimulatorState, sdc_action: Action, agents_action: Action) -> Action:
    """The SDC's row from `sdc_action`, every other object's from `agents_action`."""
    return merge_actions(sdc_action, agents_action, state.object_metadata.is_sdc)

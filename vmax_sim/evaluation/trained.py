"""Trained policies: a learner's `act` as an evaluation `Policy`.

Loading one from a training run directory needs the run's configuration and learner, which training owns:
`vmax_sim.training.run_policy` (`load_trained_policy`, `evaluate_run`) builds on this module, never the reverse.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import sdc_action
from vmax_sim.dynamics import BICYCLE
from vmax_sim.policies.base import Policy
from vmax_sim.policies.brake_guard import BrakeGuard, guarded_acceleration


def trained_policy(learner, name: str = "trained", guard: BrakeGuard | None = None) -> Policy:
    """The deterministic policy (tanh of the Gaussian mean) of a learner; its params are the rollout's argument.

    The environment must take actions in [-1, 1] (EnvConfig.normalize_actions, as in training). `guard`: PDM-Closed's
    emergency brake over the policy's acceleration (bicycle actions: [acceleration, curvature]).
    """
    def action_fn(params, state, observation, key):
        batched = jax.tree.map(lambda a: a[None], observation)
        action = learner.act(params, batched, key, True)[0]
        if guard is not None:
            physical = BICYCLE.denormalize(action)
            braked = physical.at[0].set(guarded_acceleration(state, physical[0], guard))
            # only a step where the guard brakes changes: elsewhere the policy's own action, to the last bit
            action = jnp.where(braked[0] < physical[0], BICYCLE.normalize(braked), action)
        return sdc_action(state, action)

    return Policy(name, action_fn, needs_observation=True)


__all__ = ["trained_policy"]

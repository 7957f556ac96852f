"""Trained policies: a learner's `act` as an evaluation `Policy`.

Loading one from a training run directory needs the run's configuration and learner, which training owns:
`vmax_sim.training.run_policy` (`load_trained_policy`, `evaluate_run`) builds on this module, never the reverse.
"""

from __future__ import annotations

import jax

from vmax_sim.datatypes import sdc_action
from vmax_sim.policies.base import Policy


def trained_policy(learner, name: str = "trained") -> Policy:
    """The deterministic policy (tanh of the Gaussian mean) of a learner; its params are the rollout's argument.

    The environment must take actions in [-1, 1] (EnvConfig.normalize_actions, as in training).
    """
    def action_fn(params, state, observation, key):
        batched = jax.tree.map(lambda a: a[None], observation)
        action = learner.act(params, batched, key, True)[0]
        return sdc_action(state, action)

    return Policy(name, action_fn, needs_observation=True)


__all__ = ["trained_policy"]

"""The `Policy` type every policy is built as: rule-based (this package), evaluation's baselines, trained ones.

A `Policy` maps (params, state, observation or None, key) to an `Action` for every object of one
unbatched scenario, in the environment's action convention; the environment applies it to the
objects it controls. `params` is whatever the policy was trained to (None for rule-based ones); it
is an argument of the jitted rollout, so evaluating new parameters never recompiles.

It lives here, on the policies floor, so that the rule policies and evaluation both import it from below
(tests/foundation/test_import_boundaries.py).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax

from vmax_sim.datatypes import Action, SimulatorState
from vmax_sim.observation import Observation

ActionFn = Callable[[object, SimulatorState, "Observation | None", jax.Array], Action]


@dataclasses.dataclass(frozen=True)
class Policy:
    name: str
    action_fn: ActionFn  # (params, state (), observation or None, key) -> Action (N, action_dim)
    needs_observation: bool = False  # build an Observation each step for it


__all__ = ["ActionFn", "Policy"]

"""Policies for evaluation: the log expert, a constant-velocity baseline, and user callables.

A `Policy` maps (params, state, observation or None, key) to an `Action` for every object of one
unbatched scenario, in the environment's action convention; the environment applies it to the
objects it controls. `params` is whatever the policy was trained to (None for rule-based ones); it
is an argument of the jitted rollout, so evaluating new parameters never recompiles.
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import Action, SimulatorState
from vmax_sim.observation import Observation

ActionFn = Callable[[object, SimulatorState, "Observation | None", jax.Array], Action]
POLICY_NAMES = ("expert", "constant", "idm", "pdm", "random")


@dataclasses.dataclass(frozen=True)
class Policy:
    name: str
    action_fn: ActionFn  # (params, state (), observation or None, key) -> Action (N, action_dim)
    needs_observation: bool = False  # build an Observation each step for it


def expert_policy(env) -> Policy:
    """Inverse-dynamics expert: follows the SDC's log, closing the loop on the simulated state."""
    return Policy("expert", lambda params, state, observation, key: env.expert_action(state))


def constant_policy(env) -> Policy:
    """Keeps the current speed and heading (zero action of the bicycle / delta models)."""
    if env.dynamics.name not in ("bicycle",):
        raise ValueError(f"the constant policy needs the bicycle dynamics, not {env.dynamics.name!r}")

    def action_fn(params, state, observation, key):
        num_objects = state.num_objects
        zero = jnp.zeros((num_objects, env.action_dim), jnp.float32)
        if env.config.normalize_actions:  # the physical zero action in [-1, 1] units
            zero = env.dynamics.normalize(zero)
        return Action(data=zero, valid=jnp.ones((num_objects, 1), bool))

    return Policy("constant", action_fn)


def sdc_action(state: SimulatorState, action: jax.Array) -> Action:
    """Puts one (action_dim,) action in the SDC's slot of a full Action (any leading batch dims)."""
    is_sdc = state.object_metadata.is_sdc  # (..., N)
    data = jnp.where(is_sdc[..., None], jnp.asarray(action, jnp.float32)[..., None, :], 0.0)
    return Action(data=data, valid=is_sdc[..., None])


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

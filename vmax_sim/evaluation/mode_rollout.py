"""Jitted closed-loop episodes of the reactive and perturbed modes (see `vmax_sim.evaluation.modes`).

Same structure as `vmax_sim.evaluation.rollout.run_episode` (reset, one `lax.scan` over the policy
steps, the SDC's metrics after every step) with the mode's parts added:
- reactive: after reset the chosen agents are marked controlled; each step their actions (one vmap
  over the agents) are merged with the SDC's, and `other_collision` is recorded beside the SDC's
  metrics (episode value: any valid step). It never enters the SDC's scores.
- perturbed: after reset the SDC's history is bent off the log (`perturb_start`), from a key drawn
  per scenario: `scenario_keys(seed, scenario ids)`, so a scenario gets the same start whatever its
  batch. The applied offset, heading error and scale are episode values.
`make_batch_runner` gives every mode (non_reactive through the existing rollout) one calling convention.
"""

from __future__ import annotations

import dataclasses
import functools
import zlib
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState
from vmax_sim.env.agent_view import control_agents
from vmax_sim.env.chunked_vmap import chunked_vmap
from vmax_sim.env.metrics_adapter import reference_arcs, sdc_observation, step_inputs
from vmax_sim.env.multi_agent import sdc_and_agents_action
from vmax_sim.evaluation.adversary import plan_adversary
from vmax_sim.evaluation.modes import EvalMode
from vmax_sim.evaluation.perturb import perturb_start
from vmax_sim.evaluation.policies import Policy
from vmax_sim.evaluation.reactive import (
    agents_action,
    check_agent_paths,
    choose_agents,
    make_agent_fn,
    other_collision,
    stop_sign_points,
)
from vmax_sim.evaluation.rollout import Rollout, episode_extent, make_rollout_fn, recorded_trajectory
from vmax_sim.metrics import MetricsConfig, episode_metrics, shared_queries, step_metrics
from vmax_sim.observation import ObservationConfig


def run_mode_episode(env, policy: Policy, mode: EvalMode, state: SimulatorState, key: jax.Array,
                     mode_key: jax.Array, metrics_config: MetricsConfig, obs_config: ObservationConfig,
                     params=None, agent_fn=None, record_trajectory: bool = False) -> Rollout:
    """One unbatched episode of a reactive or perturbed mode. agent_fn: the agents' driver
    (`make_agent_fn`; built here when None). mode_key: the scenario's perturbation key.
    record_trajectory: also return the simulated boxes (`Rollout.trajectory`, as `run_episode`)."""
    first = env.config.first_policy_timestep
    state = env.reset(state)
    first_timestep = state.timestep
    extra: dict = {}
    if mode.is_perturbed:
        state, extra = perturb_start(state, mode_key, mode.perturb, first, metrics_config)
    if mode.is_adversarial:
        state, extra = plan_adversary(state, mode.adversary, first, env.config.episode_length)
    if mode.is_reactive:
        check_agent_paths(state)
        agent_fn = agent_fn or make_agent_fn(mode, env, policy, metrics_config, obs_config)
        slots, slot_valid = choose_agents(state, mode.max_agents, first)
        signs = stop_sign_points(state)  # once per episode: the agents never scan the whole roadgraph
        state = control_agents(state, slots, slot_valid)
        extra["num_agents"] = jnp.sum(slot_valid).astype(jnp.float32)
    arcs = reference_arcs(state, env.config)
    num_steps = env.config.episode_length

    def body(carry, step_key):
        state, done, shared = carry
        sdc_key, agents_key = jax.random.split(step_key)
        observation = sdc_observation(state, shared, obs_config) if policy.needs_observation else None
        action = policy.action_fn(params, state, observation, sdc_key)
        if mode.is_reactive:
            others = agents_action(state, slots, slot_valid, agent_fn, params, agents_key, env.action_dim, signs)
            action = sdc_and_agents_action(state, action, others)
        state = env.step(state, action)
        inputs = step_inputs(state, arcs)
        shared = shared_queries(inputs, metrics_config)
        metrics = step_metrics(state.map_index, inputs, metrics_config, shared)
        own = {"other_collision": other_collision(state, slots, slot_valid)} if mode.is_reactive else {}
        terminated = env.is_terminated(state)
        return (state, done | terminated | env.is_truncated(state), shared), (metrics, own, ~done, terminated)

    first_shared = shared_queries(step_inputs(state, arcs), metrics_config)
    keys = jax.random.split(key, num_steps)
    carry = (state, env.is_truncated(state), first_shared)  # a log ending at the start step: no step judged
    (last, _, _), (per_step, own, step_valid, terminated) = jax.lax.scan(body, carry, keys)
    episode = episode_metrics(per_step, step_valid, metrics_config)
    for name, flags in own.items():  # any valid step
        episode[name] = jnp.any(flags & step_valid).astype(jnp.float32)
    episode.update({name: jnp.asarray(value, jnp.float32) for name, value in extra.items()})
    per_step = {**per_step, **{name: flags.astype(jnp.float32) for name, flags in own.items()}}
    episode.update(episode_extent(state, env, step_valid))
    trajectory = recorded_trajectory(last, first_timestep) if record_trajectory else None
    return Rollout(per_step=per_step, step_valid=step_valid, terminated=terminated, episode=episode,
                   trajectory=trajectory)


@functools.lru_cache(maxsize=16)
def make_mode_rollout_fn(env, policy: Policy, metrics_config: MetricsConfig, obs_config: ObservationConfig,
                         mode: EvalMode, record_trajectory: bool = False) -> Callable:
    """Jitted batched episodes: states (B, ...), keys (B, 2), mode keys (B, 2), params (shared) -> Rollout (B)."""
    agent_fn = make_agent_fn(mode, env, policy, metrics_config, obs_config) if mode.is_reactive else None

    def episode(state, key, mode_key, params):
        return run_mode_episode(env, policy, mode, state, key, mode_key, metrics_config, obs_config, params,
                                agent_fn, record_trajectory)

    return jax.jit(chunked_vmap(episode, in_axes=(0, 0, 0, None)))


def scenario_keys(seed: int, scenario_ids: Sequence[str], batch_size: int) -> jax.Array:
    """One key per scenario from (seed, scenario id), padded to batch_size by repeating the last. -> (B, 2)"""
    ids = list(scenario_ids) + [scenario_ids[-1]] * (batch_size - len(scenario_ids))
    hashes = jnp.asarray([zlib.crc32(i.encode()) & 0x7FFFFFFF for i in ids], jnp.uint32)
    return jax.vmap(lambda h: jax.random.fold_in(jax.random.PRNGKey(seed), h))(hashes)


def make_batch_runner(env, policy: Policy, metrics_config: MetricsConfig, obs_config: ObservationConfig,
                      mode: EvalMode, record_trajectory: bool = False) -> Callable:
    """fn(states (B, ...), keys (B, 2), scenario ids, params) -> Rollout (B) for any mode."""
    if mode.name == "non_reactive":
        # positional arguments only without recording: the same cache entry as other callers of make_rollout_fn
        args = (env, policy, metrics_config, obs_config) + ((True,) if record_trajectory else ())
        rollout_fn = make_rollout_fn(*args)
        return lambda states, keys, ids, params: rollout_fn(states, keys, params)
    # the seed only picks the host-side scenario keys: one compilation for every seed
    rollout_fn = make_mode_rollout_fn(env, policy, metrics_config, obs_config, dataclasses.replace(mode, seed=0),
                                      record_trajectory)

    def run(states, keys, ids, params):
        if mode.is_reactive:
            check_agent_paths(states)
        return rollout_fn(states, keys, scenario_keys(mode.seed, ids, keys.shape[0]), params)

    return run

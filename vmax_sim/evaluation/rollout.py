"""One jitted closed-loop episode per scenario: reset, `lax.scan` over the policy steps, metrics.

`make_rollout_fn` returns a jitted function over a batch of states (vmap over the batch); it is
built once per (environment config, policy, metric and observation configs) so every batch of the
same shape reuses one compilation.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import flax.struct
import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState
from vmax_sim.env.chunked_vmap import chunked_vmap
from vmax_sim.env.metrics_adapter import log_end_timestep, reference_arcs, sdc_observation, step_inputs
from vmax_sim.evaluation.policies import Policy
from vmax_sim.metrics import MetricsConfig, episode_metrics, shared_queries, step_metrics
from vmax_sim.observation import ObservationConfig


@flax.struct.dataclass
class Rollout:
    """What one episode (or a batch of them, leading axis B) produced."""

    per_step: dict  # name -> (..., num_steps) float32, `step_metrics` after each policy step
    step_valid: jax.Array  # (..., num_steps) bool, the step belongs to the episode (not after termination or
    # truncation: the time limit or the end of the SDC's log)
    terminated: jax.Array  # (..., num_steps) bool, a termination predicate fired after this step
    episode: dict  # name -> (...) float32, `episode_metrics` over the valid steps
    # Only with record_trajectory (None otherwise): the simulated boxes of every object at the end of the
    # episode, name -> (..., num_objects, num_timesteps) for x, y, yaw, length, width, valid, plus
    # "first_timestep" (...) int32, the timestep reset() set (policy step k lands at first_timestep + k + 1).
    trajectory: dict | None = None


def run_episode(env, policy: Policy, state: SimulatorState, key: jax.Array, metrics_config: MetricsConfig,
                obs_config: ObservationConfig, params=None, record_trajectory: bool = False) -> Rollout:
    """One unbatched episode from the log state `state` (any timestep): reset, then
    `env.config.episode_length` policy steps; metrics after every step; steps after the first
    termination or truncation (`env.is_truncated`: the time limit, or the end of the SDC's log, so a
    padded invalid future is never judged) are masked out of the episode metrics. The episode value
    "end_of_log" is 1 when the SDC's log ends before the episode's last step. record_trajectory: also
    return the simulated boxes of all objects (`Rollout.trajectory`, for pictures of the episode)."""
    state = env.reset(state)
    first_timestep = state.timestep
    arcs = reference_arcs(state, env.config)  # logged start / end along the paths, once per episode
    num_steps = env.config.episode_length

    def body(carry, step_key):
        state, done, shared = carry
        observation = sdc_observation(state, shared, obs_config) if policy.needs_observation else None
        action = policy.action_fn(params, state, observation, step_key)
        state = env.step(state, action)
        inputs = step_inputs(state, arcs)
        shared = shared_queries(inputs, metrics_config)  # reused by next step's observation
        metrics = step_metrics(state.map_index, inputs, metrics_config, shared)
        terminated = env.is_terminated(state)
        return (state, done | terminated | env.is_truncated(state), shared), (metrics, ~done, terminated)

    first_shared = shared_queries(step_inputs(state, arcs), metrics_config)
    keys = jax.random.split(key, num_steps)
    carry = (state, env.is_truncated(state), first_shared)  # a log ending at the start step: no step judged
    (last, _, _), (per_step, step_valid, terminated) = jax.lax.scan(body, carry, keys)
    episode = episode_metrics(per_step, step_valid, metrics_config)
    episode.update(episode_extent(state, env, step_valid))
    trajectory = recorded_trajectory(last, first_timestep) if record_trajectory else None
    return Rollout(per_step=per_step, step_valid=step_valid, terminated=terminated, episode=episode,
                   trajectory=trajectory)


def end_of_log(state: SimulatorState, env) -> jax.Array:
    """1.0 when the logged SDC ends before the episode's last step (the episode stopped there). () float32"""
    return (log_end_timestep(state, env.config) < env.config.last_timestep).astype(jnp.float32)


def episode_extent(state: SimulatorState, env, step_valid: jax.Array) -> dict:
    """Episode values saying how much of the episode was judged: "end_of_log" (see `end_of_log`) and
    "judged_steps", the number of steps scored (0 when the SDC's log ends at the start step: such an
    episode says nothing about the policy and is left out of the summary's means). step_valid (S,)."""
    return {"end_of_log": end_of_log(state, env), "judged_steps": jnp.sum(step_valid).astype(jnp.float32)}


def recorded_trajectory(last: SimulatorState, first_timestep: jax.Array) -> dict:
    """The simulated boxes of every object at the episode's end (the gallery and the viewer draw them):
    name -> (N, T) arrays, plus the episode's first step."""
    sim = last.sim_trajectory
    trajectory = {name: getattr(sim, name) for name in ("x", "y", "yaw", "length", "width", "valid")}
    trajectory["first_timestep"] = first_timestep
    return trajectory


@functools.lru_cache(maxsize=16)
def make_rollout_fn(env, policy: Policy, metrics_config: MetricsConfig,
                    obs_config: ObservationConfig,
                    record_trajectory: bool = False) -> Callable[[SimulatorState, jax.Array, object], Rollout]:
    """Jitted batched episodes: states (B, ...), keys (B, 2), policy params (shared) -> Rollout, leading axis B."""
    def episode(state, key, params):
        return run_episode(env, policy, state, key, metrics_config, obs_config, params, record_trajectory)
    return jax.jit(chunked_vmap(episode, in_axes=(0, 0, None)))

"""Reactive agents in evaluation: who drives the controllable objects (IDM, PDM, the evaluated or another
trained policy) and the collisions among them.

How an agent is driven (its view of the state, `agents_action`) is `vmax_sim.env.agent_view`, the IDM driver
`vmax_sim.policies.traffic`: both shared with IDM traffic while training. Everything works on one unbatched
state and is jittable; the mode rollout vmaps it over scenarios.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState
from vmax_sim.env.agent_view import (  # noqa: F401 (re-exported)
    AgentFn,
    agent_view,
    agents_action,
    check_agent_paths,
    choose_agents,
    stop_sign_points,
)
from vmax_sim.env.metrics_adapter import sdc_index, sdc_observation, step_inputs
from vmax_sim.evaluation.modes import EvalMode
from vmax_sim.evaluation.policies import Policy
from vmax_sim.metrics import MetricsConfig, overlaps, shared_queries
from vmax_sim.observation import ObservationConfig
from vmax_sim.policies.traffic import idm_driver, log_cap_acceleration, logged_top_speed  # noqa: F401 (re-exported)


def other_collision(state: SimulatorState, slots: jax.Array, slot_valid: jax.Array) -> jax.Array:
    """Some driven agent overlaps another non-SDC object now, both valid. () bool

    Pairs between a driven agent and anything but the SDC are checked (separating axes, as the
    `overlap` metric): K x N box tests. The SDC's own collisions are the `overlap` metric's.
    """
    sim, t = state.sim_trajectory, state.timestep
    now = jax.tree.map(lambda a: jax.lax.dynamic_index_in_dim(a, t, axis=-1, keepdims=False), sim)
    boxes = jnp.stack([now.x, now.y, now.length, now.width, now.yaw], -1).astype(jnp.float32)  # (N, 5)
    valid = now.valid & ~state.object_metadata.is_sdc
    index = jnp.arange(state.num_objects)

    def one(slot):
        return jnp.any(overlaps(boxes[slot], boxes, valid & (index != slot)))

    return jnp.any(jax.vmap(one)(slots) & slot_valid & valid[slots])


def idm_agent_fn(env, mode: EvalMode) -> AgentFn:
    """IDM agents with the mode's settings (`vmax_sim.policies.traffic.idm_driver`)."""
    return idm_driver(env, mode.agent_idm, mode.agent_speed, mode.agent_follow_log)


def policy_agent_fn(policy: Policy, metrics_config: MetricsConfig, obs_config: ObservationConfig) -> AgentFn:
    """Any evaluation `Policy` as an agent driver: it acts for "the SDC" of the agent's view (its own
    observation is built from the view when it needs one). Self-play when `policy` is the evaluated one."""
    def agent_fn(params, view, key):
        observation = None
        if policy.needs_observation:
            observation = sdc_observation(view, shared_queries(step_inputs(view), metrics_config), obs_config)
        action = policy.action_fn(params, view, observation, key)
        slot = sdc_index(view)
        return action.data[slot], action.valid[slot, 0]

    return agent_fn


def make_agent_fn(mode: EvalMode, env, policy: Policy, metrics_config: MetricsConfig,
                  obs_config: ObservationConfig) -> AgentFn:
    """The agents' driver of a reactive mode: IDM, PDM-Closed (default configs), the evaluated policy, or a
    trained policy of their own (learned traffic: its parameters are fixed, whatever the evaluated policy's)."""
    if mode.agents == "idm":
        return idm_agent_fn(env, mode)
    if mode.agents == "pdm":
        return pdm_agent_fn(env, mode)
    if mode.agents == "learned":
        agent_policy, agent_params, agent_obs_config = mode.agent_policy
        drive = policy_agent_fn(agent_policy, metrics_config, agent_obs_config)

        def learned(params, view, key):  # the traffic's own weights, whatever the evaluated policy's
            return in_env_units(env, *drive(agent_params, view, key))

        return behind_the_log(env, learned) if mode.agent_follow_log else learned
    return policy_agent_fn(policy, metrics_config, obs_config)


def in_env_units(env, action: jax.Array, valid: jax.Array) -> tuple[jax.Array, jax.Array]:
    """A trained policy's action, in [-1, 1] as its training environment took it, in `env`'s convention: an
    evaluation of a rule-based SDC steps in physical units, where -1 would brake at 1 m/s^2 instead of 6."""
    return (action if env.config.normalize_actions else env.dynamics.denormalize(action)), valid


def behind_the_log(env, agent_fn: AgentFn) -> AgentFn:
    """`agent_fn` (actions in `env`'s convention) kept from overtaking the agent's own log: its acceleration capped
    by `log_cap_acceleration`, as the IDM agents' (`EvalMode.agent_follow_log`). A learned agent then still brakes,
    steers and falls behind as it likes, but reaches junctions no earlier than its logged driver did, whose
    yielding the replayed objects around it were recorded with (docs/selfplay.md: self-play agents that drive faster
    than their logs run into lane changes and crossings the log had timed)."""
    from vmax_sim.policies.idm import IDMConfig, check_bicycle, perceive

    check_bicycle(env, "reactive agents' log-following")
    config, first = IDMConfig(), env.config.first_policy_timestep
    normalized = env.config.normalize_actions

    def capped(params, view, key):
        action, valid = agent_fn(params, view, key)
        physical = env.dynamics.denormalize(action) if normalized else action
        cap = log_cap_acceleration(view, perceive(view, config, first), config)
        physical = physical.at[0].set(jnp.minimum(physical[0], cap))
        return (env.dynamics.normalize(physical) if normalized else physical), valid

    return capped


def pdm_agent_fn(env, mode: EvalMode) -> AgentFn:
    """PDM-Closed (default `PDMConfig`) along the agent's own path; with mode.agent_follow_log its
    acceleration is capped like the IDM agents' (`behind_the_log`)."""
    from vmax_sim.policies.idm import as_env_action, check_bicycle
    from vmax_sim.policies.pdm import PDMConfig, pdm_action

    check_bicycle(env, "reactive PDM agents'")
    config = PDMConfig()
    first = env.config.first_policy_timestep

    def agent_fn(params, view, key):
        full = as_env_action(env, view, pdm_action(view, config, first))
        slot = sdc_index(view)
        return full.data[slot], full.valid[slot, 0]

    return behind_the_log(env, agent_fn) if mode.agent_follow_log else agent_fn

"""Rollout functions for the realism metric: `(state, key) -> SimTrajectories (R, N, T)`.

A rollout function receives one unbatched scene as loaded (its log, map index and agent paths; timestep
anywhere) and a PRNG key, and returns R rollouts of every object over all T steps (the logged history
included). Any simulator that can do this plugs into `vmax_sim.evaluation.realism_run.evaluate_realism`,
e.g. a self-play policy that drives every agent of a multi-agent environment. The objects scored are
`evaluated_objects`: the SDC and the controllable agents present at the current step, nearest the SDC first;
a rollout function must move at least these (the others may replay their logs, as here).

Built here:
- `log_rollout_fn`: the log itself (the reference: it maximises every time-pooled feature's likelihood).
- `policy_rollout_fn`: an SDC policy plus a per-agent driver (`reactive.AgentFn`) for the evaluated agents,
  one `lax.scan` over the episode, vmapped over the rollouts. `named_rollout_fn` builds it for "constant"
  (everyone keeps speed and heading) and "idm" (IDM + pure pursuit along each one's path);
  `trained_rollout_fn` for a trained learner that samples its actions and drives everyone (self-play).
Deterministic drivers run one rollout that stands for R identical ones (`SimTrajectories.copies`) unless
`action_noise` makes the rollouts differ.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import Action, SimulatorState, sdc_action
from vmax_sim.env.agent_view import control_agents
from vmax_sim.env.metrics_adapter import sdc_index, sdc_observation, step_inputs
from vmax_sim.env.multi_agent import sdc_and_agents_action
from vmax_sim.evaluation.modes import EvalMode
from vmax_sim.evaluation.policies import Policy, constant_policy
from vmax_sim.evaluation.reactive import (
    AgentFn,
    agents_action,
    choose_agents,
    idm_agent_fn,
    policy_agent_fn,
    stop_sign_points,
)
from vmax_sim.evaluation.realism import SimTrajectories, log_trajectories
from vmax_sim.metrics import MetricsConfig, shared_queries
from vmax_sim.observation import ObservationConfig

RolloutFn = Callable[[SimulatorState, jax.Array], SimTrajectories]
ROLLOUT_POLICIES = ("log", "constant", "idm")  # and training run directories


def evaluated_objects(state: SimulatorState, max_agents: int, timestep: int) -> tuple[jax.Array, jax.Array]:
    """The SDC first, then up to max_agents controllable agents present at `timestep` (with a path), nearest
    the SDC first. -> slots (E,) int32, valid (E,) bool; E = 1 + min(max_agents, N)."""
    agents, agents_valid = choose_agents(state, max_agents, timestep)
    sdc = jnp.asarray(sdc_index(state), jnp.int32)[None]
    return jnp.concatenate([sdc, agents]), jnp.concatenate([jnp.ones(1, bool), agents_valid])


def log_rollout_fn(num_rollouts: int) -> RolloutFn:
    """Replays the log: one rollout standing for num_rollouts identical ones."""
    return lambda state, key: log_trajectories(state, copies=num_rollouts)


def accel_noise(action: Action, key: jax.Array, env, sigma: float) -> Action:
    """Adds N(0, sigma^2) m/s^2 to every object's acceleration (the bicycle action's first entry), in the
    environment's action convention (normalised or not). -> Action (N, action_dim)"""
    data = env.dynamics.denormalize(action.data) if env.config.normalize_actions else action.data
    data = data.at[:, 0].add(sigma * jax.random.normal(key, data.shape[:1]))
    return action.replace(data=env.dynamics.normalize(data) if env.config.normalize_actions else data)


def policy_rollout_fn(env, sdc_policy: Policy, agent_fn: AgentFn | None, num_rollouts: int, max_agents: int,
                      *, stochastic: bool = False, action_noise: float = 0.0, params=None,
                      metrics_config: MetricsConfig | None = None,
                      obs_config: ObservationConfig | None = None) -> RolloutFn:
    """Rollouts where `sdc_policy` drives the SDC and `agent_fn` each evaluated agent (on its own view,
    `reactive.agent_view`); agent_fn None: `sdc_policy`'s action drives every controlled row (e.g. constant).
    The evaluated objects are controlled, everyone else replays the log. stochastic: the drivers sample
    (otherwise, and without action_noise, one rollout is run and weighted as num_rollouts identical ones).
    action_noise: standard deviation of an acceleration noise (m/s^2) added to every action each step.
    Jitted; params are an argument of the compiled function (new weights never recompile)."""
    metrics_config, obs_config = metrics_config or MetricsConfig(), obs_config or ObservationConfig()
    first, num_steps = env.config.first_policy_timestep, env.config.episode_length
    distinct = stochastic or action_noise > 0.0
    runs, copies = (num_rollouts, 1) if distinct else (1, num_rollouts)

    def one(state, key, params):
        state = env.reset(state)
        slots, valid = evaluated_objects(state, max_agents, first)
        agents, agents_valid = slots[1:], valid[1:]
        state = control_agents(state, agents, agents_valid)
        signs = stop_sign_points(state) if agent_fn is not None else None

        def body(state, step_key):
            sdc_key, agents_key, noise_key = jax.random.split(step_key, 3)
            observation = None
            if sdc_policy.needs_observation:
                observation = sdc_observation(state, shared_queries(step_inputs(state), metrics_config), obs_config)
            action = sdc_policy.action_fn(params, state, observation, sdc_key)
            if agent_fn is not None:
                others = agents_action(state, agents, agents_valid, agent_fn, params, agents_key, env.action_dim,
                                       signs)
                action = sdc_and_agents_action(state, action, others)
            if action_noise > 0.0:
                action = accel_noise(action, noise_key, env, action_noise)
            return env.step(state, action), None

        last, _ = jax.lax.scan(body, state, jax.random.split(key, num_steps))
        sim = last.sim_trajectory
        return sim.x, sim.y, sim.yaw, sim.valid

    @jax.jit
    def rollouts(state, key, params):
        x, y, yaw, valid = jax.vmap(one, in_axes=(None, 0, None))(state, jax.random.split(key, runs), params)
        return SimTrajectories(x=x, y=y, yaw=yaw, valid=valid, copies=copies)

    return lambda state, key: rollouts(state, key, params)


def idm_agent_mode(max_agents: int) -> EvalMode:
    """The IDM agents' settings here: no future of the log beyond the path (no cap at the logged position, the
    lane's speed limit as desired speed, as the SDC's IDM), unlike reactive evaluation, whose agents keep the
    logged timing on purpose."""
    return EvalMode(name="reactive", agents="idm", max_agents=max_agents, agent_speed="limit",
                    agent_follow_log=False)


def named_rollout_fn(name: str, env, num_rollouts: int, max_agents: int, action_noise: float = 0.0) -> RolloutFn:
    """"log", "constant" (the evaluated objects keep their speed and heading) or "idm" (the SDC and every
    evaluated agent: IDM + pure pursuit along its path, `idm_agent_mode`)."""
    if name == "log":
        return log_rollout_fn(num_rollouts)
    if name == "constant":
        return policy_rollout_fn(env, constant_policy(env), None, num_rollouts, max_agents, action_noise=action_noise)
    if name == "idm":
        from vmax_sim.policies import idm_policy

        return policy_rollout_fn(env, idm_policy(env), idm_agent_fn(env, idm_agent_mode(max_agents)), num_rollouts,
                                 max_agents, action_noise=action_noise)
    raise ValueError(f"unknown realism policy {name!r}; choose one of {ROLLOUT_POLICIES} or a training run directory")


def sampled_policy(learner, name: str = "trained") -> Policy:
    """A learner's stochastic policy (a sample of its action distribution) as a `Policy` for the SDC of a state;
    rollouts then differ as the policy's own randomness makes them."""
    def action_fn(params, state, observation, key):
        batched = jax.tree.map(lambda a: a[None], observation)
        return sdc_action(state, learner.act(params, batched, key, False)[0])

    return Policy(name, action_fn, needs_observation=True)


def trained_rollout_fn(learner, params, env, obs_config: ObservationConfig, num_rollouts: int, max_agents: int,
                       *, deterministic: bool = False, action_noise: float = 0.0, name: str = "trained",
                       metrics_config: MetricsConfig | None = None) -> RolloutFn:
    """A trained learner drives the SDC and every evaluated agent (self-play through `reactive.agent_view`),
    sampling its actions (deterministic: the mean action, one rollout for all unless action_noise)."""
    from vmax_sim.evaluation.trained import trained_policy

    metrics_config = metrics_config or MetricsConfig()
    policy = trained_policy(learner, name) if deterministic else sampled_policy(learner, name)
    return policy_rollout_fn(env, policy, policy_agent_fn(policy, metrics_config, obs_config), num_rollouts,
                             max_agents, stochastic=not deterministic, action_noise=action_noise, params=params,
                             metrics_config=metrics_config, obs_config=obs_config)


__all__ = ["ROLLOUT_POLICIES", "RolloutFn", "accel_noise", "evaluated_objects", "idm_agent_mode", "log_rollout_fn",
           "named_rollout_fn", "policy_rollout_fn", "sampled_policy", "trained_rollout_fn"]

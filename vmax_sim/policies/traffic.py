"""Traffic drivers: planners that drive objects other than the SDC along their own paths.

Every planner of the project drives "the SDC of a state along `state.sdc_paths`". An agent is driven
by handing the planner the agent's view of the state (`agent_view`): the same state with the SDC
flag moved to the agent's slot and its own path (`SimulatorState.agent_paths`) as the only route.
The planner then sees every other object, the real SDC included, as traffic: IDM's leader detection,
red lights, stop signs and bend speeds work for agents unchanged. `agents_action` vmaps this over
the chosen agent slots (static count, no Python loop) and scatters the actions into one `Action`.

Reactive evaluation (`vmax_sim.evaluation.reactive`) and IDM traffic while training
(`LearningEnv(traffic="idm")`) both drive their agents with these. Everything works on one unbatched
state and is jittable.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import Action, RoadgraphPoints, SimulatorState
from vmax_sim.env.agent_view import agent_view
from vmax_sim.env.metrics_adapter import sdc_index

MAX_STOP_SIGN_POINTS = 64  # stop-sign points handed to the agents' views (the nearest the SDC)
LOG_CAP_WINDOW_M = (10.0, 60.0)  # m behind / ahead of the agent where its logged position is looked for
AGENT_SPEEDS = ("limit", "log")  # an IDM agent's desired speed: its fastest logged speed, or the lane's limit

# (params, agent view, key) -> the agent's action (action_dim,) in the env's convention, and its validity ()
AgentFn = Callable[[object, SimulatorState, jax.Array], tuple[jax.Array, jax.Array]]


def stop_sign_points(state: SimulatorState, max_points: int = MAX_STOP_SIGN_POINTS) -> RoadgraphPoints:
    """The roadgraph's stop-sign points (nearest the SDC first, at most max_points), as a small
    RoadgraphPoints: the only part of `roadgraph_points` the planners read (map queries go through the
    map index). Handing it to the agents' views keeps K agents from each scanning the whole roadgraph
    every step. -> RoadgraphPoints (max_points,)."""
    from scenariomax.schema import RG_STOP_SIGN

    rg = state.roadgraph_points
    sdc = sdc_index(state)
    t = state.timestep
    centre = jnp.stack([state.log_trajectory.x[sdc, t], state.log_trajectory.y[sdc, t]])
    is_sign = rg.valid & (rg.types == RG_STOP_SIGN)
    distance = jnp.hypot(rg.x - centre[0], rg.y - centre[1])
    k = min(max_points, rg.x.shape[-1])
    _, index = jax.lax.top_k(-jnp.where(is_sign, distance, jnp.inf), k)
    kept = jax.tree.map(lambda a: a[index], rg)
    return kept.replace(valid=is_sign[index])


def agents_action(state: SimulatorState, slots: jax.Array, slot_valid: jax.Array, agent_fn: AgentFn, params,
                  key: jax.Array, action_dim: int, roadgraph: RoadgraphPoints | None = None) -> Action:
    """Actions of the agents in `slots` (K,) (where slot_valid) from `agent_fn` on their views (`agent_view`,
    with `roadgraph` in them when given); every other row is zero and invalid. -> Action (N, action_dim)."""
    num = state.num_objects
    keys = jax.random.split(key, slots.shape[0])
    data, valid = jax.vmap(lambda slot, k: agent_fn(params, agent_view(state, slot, roadgraph), k))(slots, keys)
    target = jnp.where(slot_valid, slots, num)  # out of range: dropped by the scatter
    full = jnp.zeros((num, action_dim), jnp.float32).at[target].set(data.astype(jnp.float32), mode="drop")
    full_valid = jnp.zeros((num, 1), bool).at[target, 0].set(valid & slot_valid, mode="drop")
    return Action(data=full, valid=full_valid)


def logged_top_speed(state: SimulatorState, first: int, last: int) -> jax.Array:
    """Each object's fastest logged speed between steps first and last (inclusive). -> (N,) m/s"""
    log = state.log_trajectory
    speed = jnp.hypot(log.vel_x, log.vel_y)[:, first:last + 1]
    return jnp.max(jnp.where(log.valid[:, first:last + 1], speed, 0.0), axis=-1)


def log_cap_acceleration(view: SimulatorState, scene, config) -> jax.Array:
    """The acceleration that puts the agent ("the SDC" of `view`) at its logged position of the next step,
    measured along its path (inf when that position is not logged): taking the minimum with IDM's
    keeps the agent from overtaking its own log, so it reaches junctions no earlier than the log did
    (the logged driver's yielding decisions stay valid) while it still slows down for whatever is in
    its way. -> () m/s^2, bounded like IDM's."""
    from vmax_sim.policies.idm import bounded_acceleration
    from vmax_sim.policies.route import project

    log, i = view.log_trajectory, sdc_index(view)
    t = jnp.minimum(view.timestep + 1, view.num_timesteps - 1)
    target = jnp.stack([log.x[i, t], log.y[i, t]])[None]
    arc = project(scene.path, target, scene.ego_arc - LOG_CAP_WINDOW_M[0], scene.ego_arc + LOG_CAP_WINDOW_M[1])[0][0]
    speed, dt = jnp.maximum(scene.ego.speed, 0.0), config.dt
    accel = 2.0 * (arc - scene.ego_arc - speed * dt) / dt**2
    accel = jnp.where(log.valid[i, t], accel, jnp.inf)
    return jnp.where(jnp.isfinite(accel), bounded_acceleration(jnp.where(jnp.isfinite(accel), accel, 0.0), speed,
                                                               config, dt), jnp.inf)


def idm_driver(env, config=None, speed: str = "log", follow_log: bool = True) -> AgentFn:
    """IDM + pure pursuit along the agent's own path (`vmax_sim.policies.idm`; config: an IDMConfig, None for its
    defaults). speed "log": the desired speed is at most the agent's fastest logged speed in the episode (at least
    1 m/s), so that on a free road it keeps its logged pace instead of speeding up to the limit; "limit": the
    lane's limit, as the SDC's IDM. follow_log: never get ahead of the agent's logged position along its path
    (`log_cap_acceleration`)."""
    from vmax_sim.policies.idm import (
        IDMConfig,
        as_env_action,
        check_bicycle,
        corridor_leader,
        idm_step_acceleration,
        perceive,
        steer,
    )

    if speed not in AGENT_SPEEDS:
        raise ValueError(f"IDM agents' speed must be one of {AGENT_SPEEDS}, got {speed!r}")
    check_bicycle(env, "IDM agents'")
    config = config or IDMConfig()
    first, last = env.config.first_policy_timestep, env.config.last_timestep

    def agent_fn(params, view, key):
        scene = perceive(view, config, first)
        desired = scene.desired_speed
        if speed == "log":
            top = logged_top_speed(view, first, last)[sdc_index(view)]
            desired = jnp.minimum(desired, jnp.maximum(top, 1.0))
        ego = scene.ego
        gap, lead_speed = corridor_leader(scene.objects, scene.ego_arc, 0.0, 0.5 * ego.length, config.lane_half_width)
        accel = idm_step_acceleration(scene, scene.ego_arc, ego.speed, desired, gap, lead_speed, config, config.dt)
        if follow_log:
            accel = jnp.minimum(accel, log_cap_acceleration(view, scene, config))
        curvature = steer(scene.path, ego, scene.ego_arc, jnp.zeros(()), config)
        action = as_env_action(env, view, jnp.stack([accel, curvature]).astype(jnp.float32))
        slot = sdc_index(view)
        return action.data[slot], action.valid[slot, 0]

    return agent_fn

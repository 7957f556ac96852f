"""IDM traffic: IDM + pure pursuit driving an agent along its own path, as an `AgentFn`.

Every planner of the project drives "the SDC of a state along `state.sdc_paths`"; handed an agent's view
(`vmax_sim.env.agent_view`), IDM drives that agent and sees every other object, the real SDC included, as
traffic: leader detection, red lights, stop signs and bend speeds work for agents unchanged.

Reactive evaluation (`vmax_sim.evaluation.reactive`) and IDM traffic while training (`LearningEnv(traffic=
idm_traffic)`, `train.traffic=idm`) both drive their agents with `idm_driver`. Jittable, one unbatched view.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState
from vmax_sim.env.agent_view import AgentFn
from vmax_sim.env.metrics_adapter import sdc_index

LOG_CAP_WINDOW_M = (10.0, 60.0)  # m behind / ahead of the agent where its logged position is looked for
AGENT_SPEEDS = ("limit", "log")  # an IDM agent's desired speed: its fastest logged speed, or the lane's limit


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
        idm_step_acceleration,
        perceive,
        scene_leader,
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
        gap, lead_speed = scene_leader(scene, config)
        accel = idm_step_acceleration(scene, scene.ego_arc, ego.speed, desired, gap, lead_speed, config, config.dt)
        if follow_log:
            accel = jnp.minimum(accel, log_cap_acceleration(view, scene, config))
        curvature = steer(scene.path, ego, scene.ego_arc, jnp.zeros(()), config)
        action = as_env_action(env, view, jnp.stack([accel, curvature]).astype(jnp.float32))
        slot = sdc_index(view)
        return action.data[slot], action.valid[slot, 0]

    return agent_fn


# room `train.traffic=idm_pass` leaves beside a car at rest (a parked car reaching into the lane,
# `data.synthetic.parked_reach`, is passed as the log passes it, with the generator's 0.3 m, not queued behind)
TRAFFIC_STANDING_CLEARANCE_M = 0.2


def idm_traffic(env, standing_clearance: float | None = None) -> AgentFn:
    """The IDM traffic of training (`train.traffic=idm`): the reactive evaluation's default agents, at most their
    logged pace and never ahead of their logged position; with `standing_clearance` (m, `idm_pass`) passing a car
    at rest beside their lane with that much room (IDMConfig.standing_clearance)."""
    from vmax_sim.policies.idm import IDMConfig

    return idm_driver(env, IDMConfig(standing_clearance=standing_clearance), speed="log", follow_log=True)

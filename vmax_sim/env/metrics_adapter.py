"""Adapter from `SimulatorState` to the metrics' `StepInputs` and the observation's `ObservationInputs`,
plus the metric-based termination functions the `Environment` takes (`vmax_sim.env.factory.make_environment`
builds it with them).

Everything here works on one unbatched state (vmap for batches), is pure and jittable. The
scored agent is the SDC; the SDC's own slot is never an "other object".
"""

from __future__ import annotations

from collections.abc import Mapping

import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState, Trajectory
from vmax_sim.datatypes.trajectory import read_unfused
from vmax_sim.env.config import EnvConfig
from vmax_sim.env.termination import TerminationFn, combine_termination_fns
from vmax_sim.geometry.reductions import first_true
from vmax_sim.map_index.query import lane_candidates, nearest_lane, route_reference_arcs
from vmax_sim.metrics import (
    MetricsConfig,
    SharedQueries,
    StepInputs,
    offroad,
    overlaps,
    red_light_violation,
    sdc_box_at,
    select_candidates,
)
from vmax_sim.observation import Observation, ObservationConfig, ObservationInputs, observe

METRIC_HISTORY = 3  # steps of SDC history the per-step metrics need (finite differences)


def sdc_index(state: SimulatorState) -> jax.Array:
    """Slot of the SDC. () int32"""
    return first_true(state.object_metadata.is_sdc)


def _window(values: jax.Array, timestep: jax.Array, length: int) -> jax.Array:
    """The last `length` steps ending at `timestep` along the time (last) axis. (..., T) -> (..., length).

    Before step length - 1 the window starts at 0 (so "now" is not last); the env always has
    at least init_steps >= length steps of history, so that never happens during an episode.
    """
    start = jnp.clip(timestep - length + 1, 0, values.shape[-1] - length)
    return jax.lax.dynamic_slice_in_dim(values, start, length, axis=-1)


def _sdc_windows(sim: Trajectory, sdc: jax.Array, timestep: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The SDC's last METRIC_HISTORY x, y, yaw, each (METRIC_HISTORY,), read as `select_timestep` reads
    (`read_unfused`): fused into the step's in-place write, the read made XLA copy whole buffers."""
    def read(x, y, yaw):
        return tuple(_window(values[sdc], timestep, METRIC_HISTORY) for values in (x, y, yaw))
    return read_unfused(read, timestep, sim.x, sim.y, sim.yaw)


def fields_now(state: SimulatorState) -> Trajectory:
    """Every simulated field at the current step (the step's cached copy when it has one). -> (N,) fields"""
    return jax.tree.map(lambda a: a[..., 0], state.current_sim_trajectory)


def _size_of(now: Trajectory, index: jax.Array) -> jax.Array:
    """One object's length and width now. -> (2,) m"""
    return jnp.stack([now.length[index], now.width[index]])


def boxes_now(now: Trajectory) -> jax.Array:
    """[x, y, length, width, yaw] per object. (N,) fields -> (N, 5)"""
    return jnp.stack([now.x, now.y, now.length, now.width, now.yaw], axis=-1).astype(jnp.float32)


def log_end_timestep(state: SimulatorState, config: EnvConfig) -> jax.Array:
    """Last step of the episode window at which the logged SDC is valid. () int32"""
    valid = state.log_trajectory.valid[sdc_index(state)]  # (T,)
    steps = jnp.arange(valid.shape[-1])
    in_window = valid & (steps <= config.last_timestep)
    return jnp.max(jnp.where(in_window, steps, 0)).astype(jnp.int32)


def reference_arcs(state: SimulatorState, config: EnvConfig) -> jax.Array:
    """Arcs of the logged SDC start (first policy step) and end along every SDC path; compute at reset.

    -> (P, 2) float32, the `StepInputs.path_log_arc` of the whole episode.
    """
    sdc = sdc_index(state)
    log = state.log_trajectory
    start, end = config.first_policy_timestep, log_end_timestep(state, config)
    start_xy = jnp.stack([log.x[sdc, start], log.y[sdc, start]])
    end_xy = jnp.stack([log.x[sdc, end], log.y[sdc, end]])
    paths = state.sdc_paths
    return route_reference_arcs(paths.xy, paths.valid, paths.arc_length, start_xy, end_xy)


def step_inputs(state: SimulatorState, path_log_arc: jax.Array | None = None) -> StepInputs:
    """The metrics' view of the current step of `state` (unbatched).

    path_log_arc (P, 2) from `reference_arcs` (zeros when None: progress metrics are then meaningless,
    which the termination functions do not use).
    """
    t = state.timestep
    sdc = sdc_index(state)
    sim, log = state.sim_trajectory, state.log_trajectory
    now = fields_now(state)
    lights = state.log_traffic_light
    light_now = jax.tree.map(lambda a: jax.lax.dynamic_index_in_dim(a, t, axis=-1, keepdims=False), lights)
    paths = state.sdc_paths
    if path_log_arc is None:
        path_log_arc = jnp.zeros(paths.x.shape[:-1] + (2,), jnp.float32)
    sdc_x, sdc_y, sdc_yaw = _sdc_windows(sim, sdc, t)
    return StepInputs(
        sdc_xy=jnp.stack([sdc_x, sdc_y], axis=-1),
        sdc_yaw=sdc_yaw,
        sdc_size=_size_of(now, sdc),
        sdc_log_xy=jnp.stack([log.x[sdc, t], log.y[sdc, t]]),
        object_boxes=boxes_now(now),
        object_vel=jnp.stack([now.vel_x, now.vel_y], axis=-1),
        object_valid=now.valid & ~state.object_metadata.is_sdc,
        light_xy=jnp.stack([light_now.x, light_now.y], axis=-1),
        light_lane_id=light_now.lane_ids,
        light_state=light_now.state,
        light_valid=light_now.valid,
        path_xy=paths.xy,
        path_valid=paths.valid,
        path_arc=paths.arc_length,
        path_on_route=paths.on_route,
        path_log_arc=path_log_arc,
    )


def observation_inputs(state: SimulatorState, num_history: int = 5) -> ObservationInputs:
    """The observation's view of the current step of `state` (unbatched), `num_history` steps (last = now)."""
    t = state.timestep
    sdc = sdc_index(state)
    sim = state.sim_trajectory
    window = jax.tree.map(lambda a: _window(a, t, num_history), sim)  # (N, k) fields
    now = fields_now(state)
    lights = jax.tree.map(lambda a: jax.lax.dynamic_index_in_dim(a, t, axis=-1, keepdims=False),
                          state.log_traffic_light)
    light_valid = lights.valid if state.lights_hidden is None else lights.valid & ~state.lights_hidden
    paths = state.sdc_paths
    xy = jnp.stack([window.x, window.y], axis=-1)
    vel = jnp.stack([window.vel_x, window.vel_y], axis=-1)
    return ObservationInputs(
        sdc_xy=xy[sdc], sdc_yaw=window.yaw[sdc], sdc_vel=vel[sdc], sdc_valid=window.valid[sdc],
        sdc_size=_size_of(now, sdc),
        object_xy=xy, object_yaw=window.yaw, object_vel=vel,
        object_size=jnp.stack([now.length, now.width], axis=-1),
        object_type=state.object_metadata.object_types,
        object_valid=window.valid & ~state.object_metadata.is_sdc[:, None],
        light_xy=jnp.stack([lights.x, lights.y], axis=-1), light_state=lights.state, light_valid=light_valid,
        path_xy=paths.xy, path_valid=paths.valid, path_arc=paths.arc_length, path_on_route=paths.on_route,
    )


def sdc_observation(state: SimulatorState, shared: SharedQueries, config: ObservationConfig,
                    key: jax.Array | None = None) -> Observation:
    """The SDC's observation of one unbatched state, reusing the metrics' candidate objects and path
    projection of this step (`shared_queries`) when there are enough candidates."""
    inputs = observation_inputs(state, config.num_history)
    enough = shared.candidate_index.shape[0] >= config.num_objects
    candidates = ((shared.candidate_index[:config.num_objects], shared.candidate_valid[:config.num_objects])
                  if enough else None)
    return observe(state.map_index, inputs, config, key=key, candidates=candidates,
                   path_projection=shared.path_projection)


# ----------------------------------------------------------------------------- termination


def _sdc_box(inputs: StepInputs) -> jax.Array:
    return sdc_box_at(inputs.sdc_xy[-1], inputs.sdc_yaw[-1], inputs.sdc_size)


def collision_now(state: SimulatorState, config: MetricsConfig) -> jax.Array:
    """The SDC overlaps another valid object now (same rule as the `overlap` metric). () bool"""
    inputs = step_inputs(state)
    box = _sdc_box(inputs)
    idx, valid = select_candidates(box, inputs.object_boxes, inputs.object_valid, config.num_candidates)
    return jnp.any(overlaps(box, inputs.object_boxes[idx], valid))


def offroad_now(state: SimulatorState, config: MetricsConfig) -> jax.Array:
    """A corner of the SDC's box is outside the road edges (the `offroad` metric). () bool"""
    del config
    is_offroad, _ = offroad(state.map_index, _sdc_box(step_inputs(state)))
    return is_offroad


def red_light_now(state: SimulatorState, config: MetricsConfig) -> jax.Array:
    """The SDC's front bumper crossed a red light's stop point on its lane this step (the `red_light` metric)."""
    inputs = step_inputs(state)
    xy, yaw, length = inputs.sdc_xy[-1], inputs.sdc_yaw[-1], inputs.sdc_size[0]
    lanes = lane_candidates(state.map_index, xy)
    k = nearest_lane(lanes, yaw)
    lane_id = jnp.where(lanes.distance[k] < config.lane_match_distance, lanes.lane_id[k], -1)
    before = inputs.sdc_xy[-2] + 0.5 * length * jnp.stack([jnp.cos(inputs.sdc_yaw[-2]), jnp.sin(inputs.sdc_yaw[-2])])
    front = xy + 0.5 * length * jnp.stack([jnp.cos(yaw), jnp.sin(yaw)])
    return red_light_violation(before, front, lane_id, jnp.stack([lanes.dir_x[k], lanes.dir_y[k]]),
                               inputs.light_xy, inputs.light_lane_id, inputs.light_state, inputs.light_valid,
                               config.red_light_states, config.red_light_lateral)


def _batched(fn, config: MetricsConfig) -> TerminationFn:
    """state (...) -> (...) bool, mapping `fn` over any leading batch dims."""
    def termination_fn(state: SimulatorState) -> jax.Array:
        mapped = lambda s: fn(s, config)  # noqa: E731
        for _ in state.batch_shape:
            mapped = jax.vmap(mapped)
        return mapped(state)
    return termination_fn


def termination_fns(config: MetricsConfig | None = None) -> Mapping[str, TerminationFn]:
    """Named metric predicates usable in `EnvConfig.terminate_on`."""
    config = config or MetricsConfig()
    return {"collision": _batched(collision_now, config), "offroad": _batched(offroad_now, config),
            "red_light": _batched(red_light_now, config)}


def make_termination_fn(env_config: EnvConfig, metrics_config: MetricsConfig | None = None) -> TerminationFn | None:
    """The OR of the predicates named in `env_config.terminate_on` (None when empty)."""
    return combine_termination_fns(termination_fns(metrics_config), env_config.terminate_on)

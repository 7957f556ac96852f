"""What the rule-based planners read off one unbatched `SimulatorState`: the SDC now, the route path
it follows, the other objects in that path's frame, and the stop points of red lights on the route.

Every function is pure and jittable on one scenario (vmap for batches); shapes are in the
docstrings: N objects, M path points, L traffic lights.
"""

from __future__ import annotations

import flax.struct
import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState
from vmax_sim.dynamics.bicycle import heading_speed
from vmax_sim.geometry.transforms import wrap_angle
from vmax_sim.map_index import lane_candidates, nearest_lane, project_on_paths

PATH_SPACING_M = 1.0  # spacing of the straight extension past the end of a path (shards: ~1 m)
NO_PATH_BACK_M = 20.0  # without any SDC path, a straight one starting this far behind the SDC


@flax.struct.dataclass
class Ego:
    """The SDC at the current step."""

    xy: jax.Array  # (2,) float32, box centre
    yaw: jax.Array  # () float32
    speed: jax.Array  # () float32, velocity along the heading (negative when reversing)
    length: jax.Array  # () float32
    width: jax.Array  # () float32
    prev_speed: jax.Array  # () float32, speed one step earlier (equal to `speed` at the first step)


@flax.struct.dataclass
class RoutePath:
    """The path the SDC follows, extended straight past its last valid point so that it never ends."""

    xy: jax.Array  # (M, 2) float32
    arc: jax.Array  # (M,) float32, cumulative length along xy (recomputed, strictly increasing)
    yaw: jax.Array  # (M,) float32, heading towards the next point (unwrapped)
    curvature: jax.Array  # (M,) float32, smoothed d yaw / d arc, 1/m
    lane_id: jax.Array  # (M,) int32, lane under each point (-1 on the extension)
    exists: jax.Array  # () bool, False when the scenario has no SDC path (a straight line is used)


@flax.struct.dataclass
class Objects:
    """Every other object now, with its projection on the route path."""

    boxes: jax.Array  # (N, 5) float32, [x, y, length, width, yaw]
    vel: jax.Array  # (N, 2) float32, m/s
    valid: jax.Array  # (N,) bool, valid now and not the SDC
    arc: jax.Array  # (N,) float32, arc of the centre's projection on the path
    lateral: jax.Array  # (N,) float32, signed offset from the path (+ left)
    half_along: jax.Array  # (N,) float32, half the box's extent along the path direction
    half_across: jax.Array  # (N,) float32, half the box's extent across it
    speed_along: jax.Array  # (N,) float32, velocity component along the path direction


def _now(values: jax.Array, timestep: jax.Array) -> jax.Array:
    """(..., T) -> (...) at `timestep`."""
    return jax.lax.dynamic_index_in_dim(values, timestep, axis=-1, keepdims=False)


def sdc_slot(state: SimulatorState) -> jax.Array:
    """() int32"""
    return jnp.argmax(state.object_metadata.is_sdc).astype(jnp.int32)


def ego_now(state: SimulatorState) -> Ego:
    """The SDC's pose, signed speed and size at the current step of one unbatched state."""
    sim, t, i = state.sim_trajectory, state.timestep, sdc_slot(state)
    traj = jax.tree.map(lambda a: a[i], sim)  # (T,) fields
    speed = heading_speed(traj)  # (T,)
    before = jnp.maximum(t - 1, 0)
    return Ego(xy=jnp.stack([_now(traj.x, t), _now(traj.y, t)]), yaw=_now(traj.yaw, t), speed=_now(speed, t),
               length=_now(traj.length, t), width=_now(traj.width, t),
               prev_speed=jnp.where(_now(traj.valid, before), _now(speed, before), _now(speed, t)))


def _extend(xy: jax.Array, valid: jax.Array, fallback_dir: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Points past the last valid one continue straight along the last segment. (M, 2), (M,) -> (M, 2), (M,) arc."""
    m = xy.shape[0]
    idx = jnp.arange(m)
    last = jnp.max(jnp.where(valid, idx, 0))
    prev = jnp.maximum(last - 1, 0)
    step = xy[last] - xy[prev]
    norm = jnp.linalg.norm(step)
    direction = jnp.where(norm > 1e-3, step / jnp.maximum(norm, 1e-3), fallback_dir)
    extra = (idx - last).astype(jnp.float32) * PATH_SPACING_M
    inside = (idx <= last)[:, None]
    xy = jnp.where(inside, xy, xy[last] + extra[:, None] * direction)
    seg = jnp.maximum(jnp.linalg.norm(jnp.diff(xy, axis=0), axis=-1), 1e-3)  # strictly increasing arc
    return xy, jnp.concatenate([jnp.zeros(1, xy.dtype), jnp.cumsum(seg)])


def smoothed_curvature(xy: jax.Array, arc: jax.Array, window: int = 5) -> tuple[jax.Array, jax.Array]:
    """Heading (unwrapped) and curvature averaged over `window` points. (M, 2), (M,) -> (M,), (M,)."""
    d = jnp.diff(xy, axis=0)
    yaw = jnp.unwrap(jnp.arctan2(d[:, 1], d[:, 0]))
    yaw = jnp.concatenate([yaw, yaw[-1:]])  # (M,)
    ds = jnp.maximum(jnp.diff(arc), 1e-3)
    kappa = jnp.concatenate([jnp.diff(yaw) / ds, jnp.zeros(1, xy.dtype)])  # (M,)
    kernel = jnp.ones(window, xy.dtype) / window
    return yaw, jnp.convolve(kappa, kernel, mode="same")


def choose_route(state: SimulatorState, ego: Ego) -> RoutePath:
    """The on-route SDC path nearest the SDC (as the progress metrics choose it), else the nearest path,
    else a straight line along the SDC's heading; extended straight past its end."""
    paths = state.sdc_paths
    proj = project_on_paths(paths.xy, paths.valid, paths.arc_length, ego.xy)
    has_points = jnp.any(paths.valid, axis=1)  # (P,)
    distance = jnp.where(has_points, proj.distance, jnp.inf)
    on_route = jnp.where(paths.on_route, distance, jnp.inf)
    index = jnp.where(jnp.isfinite(jnp.min(on_route)), jnp.argmin(on_route), jnp.argmin(distance))
    exists = jnp.any(has_points)
    heading = jnp.stack([jnp.cos(ego.yaw), jnp.sin(ego.yaw)])
    m = paths.x.shape[-1]
    straight = ego.xy + (jnp.arange(m, dtype=jnp.float32) * PATH_SPACING_M - NO_PATH_BACK_M)[:, None] * heading
    xy = jnp.where(exists, paths.xy[index], straight)
    valid = jnp.where(exists, paths.valid[index], True)
    xy, arc = _extend(xy, valid, heading)
    yaw, curvature = smoothed_curvature(xy, arc)
    lane_id = jnp.where(exists & valid, paths.ids[index], -1).astype(jnp.int32)
    return RoutePath(xy=xy, arc=arc, yaw=yaw, curvature=curvature, lane_id=lane_id, exists=exists)


def point_at(path: RoutePath, arc: jax.Array, offset: jax.Array | float = 0.0) -> tuple[jax.Array, jax.Array]:
    """Position and heading at `arc` along the path, shifted `offset` metres to its left.

    arc (...), offset broadcastable -> xy (..., 2), yaw (...).
    """
    x = jnp.interp(arc, path.arc, path.xy[:, 0])
    y = jnp.interp(arc, path.arc, path.xy[:, 1])
    yaw = jnp.interp(arc, path.arc, path.yaw)
    offset = jnp.asarray(offset, jnp.float32)
    return jnp.stack([x - offset * jnp.sin(yaw), y + offset * jnp.cos(yaw)], -1), yaw


def project(path: RoutePath, points: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Arc, signed lateral offset (+ left) and path heading at the projection of each point.

    points (Q, 2) -> (Q,), (Q,), (Q,).
    """
    ones = jnp.ones(path.arc.shape, bool)[None]

    def one(p):
        proj = project_on_paths(path.xy[None], ones, path.arc[None], p)
        return proj.arc[0], proj.direction[0], proj.distance[0]

    arc, direction, distance = jax.vmap(one)(points)
    closest, _ = point_at(path, arc)
    rel = points - closest
    side = direction[:, 0] * rel[:, 1] - direction[:, 1] * rel[:, 0]
    # the magnitude is the true distance to the polyline: a point beyond an end is not "on" the path
    lateral = jnp.where(side < 0.0, -distance, distance)
    return arc, lateral, jnp.arctan2(direction[:, 1], direction[:, 0])


def objects_now(state: SimulatorState, path: RoutePath) -> Objects:
    """Every object at the current step, projected on the route path (the SDC's slot is invalid)."""
    sim, t = state.sim_trajectory, state.timestep
    now = jax.tree.map(lambda a: _now(a, t), sim)  # (N,) fields
    boxes = jnp.stack([now.x, now.y, now.length, now.width, now.yaw], -1).astype(jnp.float32)
    vel = jnp.stack([now.vel_x, now.vel_y], -1).astype(jnp.float32)
    valid = now.valid & ~state.object_metadata.is_sdc
    arc, lateral, path_yaw = project(path, boxes[:, :2])
    rel = wrap_angle(now.yaw - path_yaw)
    cos, sin = jnp.abs(jnp.cos(rel)), jnp.abs(jnp.sin(rel))
    return Objects(boxes=boxes, vel=vel, valid=valid, arc=arc, lateral=lateral,
                   half_along=0.5 * (now.length * cos + now.width * sin),
                   half_across=0.5 * (now.length * sin + now.width * cos),
                   speed_along=vel[:, 0] * jnp.cos(path_yaw) + vel[:, 1] * jnp.sin(path_yaw))


def lane_speed_limit(state: SimulatorState, xy: jax.Array, yaw: jax.Array, match_distance: float) -> jax.Array:
    """Speed limit of the lane driven at xy (nearest heading-aware lane within match_distance, as the
    speed-limit metric reads it), -1 when unknown. (2,), () -> ()."""
    lanes = lane_candidates(state.map_index, xy)
    k = nearest_lane(lanes, yaw)
    return jnp.where(lanes.distance[k] < match_distance, lanes.speed_limit[k], -1.0)


def current_lane_id(state: SimulatorState, xy: jax.Array, yaw: jax.Array, match_distance: float) -> jax.Array:
    """Id of the lane the SDC drives on (as the red-light metric finds it), -1 when none. () int32"""
    lanes = lane_candidates(state.map_index, xy)
    k = nearest_lane(lanes, yaw)
    return jnp.where(lanes.distance[k] < match_distance, lanes.lane_id[k], -1)


def light_stop_arc(state: SimulatorState, path: RoutePath, ego: Ego, own_lane: jax.Array,
                   stop_states: tuple[int, ...], caution_states: tuple[int, ...], caution_decel: float,
                   max_lateral: float) -> jax.Array:
    """Arc of the nearest stop point ahead of the SDC's front bumper that it must stop at, inf if none.

    A light counts when its state is a stop state (or a caution state the SDC can still stop for
    braking at most `caution_decel`), its controlled lane is a lane of the route path or the lane
    the SDC drives on, and its stop point lies within `max_lateral` of the path. -> () float32.
    """
    t = state.timestep
    lights = jax.tree.map(lambda a: _now(a, t), state.log_traffic_light)  # (L,) fields
    stop_xy = jnp.stack([lights.x, lights.y], -1).astype(jnp.float32)
    arc, lateral, _ = project(path, stop_xy)  # (L,)
    on_route = jnp.any((lights.lane_ids[:, None] == path.lane_id[None]) & (path.lane_id[None] >= 0), axis=1)
    controls_us = (on_route | (lights.lane_ids == own_lane)) & (lights.lane_ids >= 0)
    ego_arc = project(path, ego.xy[None])[0][0]
    ahead = arc - (ego_arc + 0.5 * ego.length)  # (L,) distance from the front bumper to the stop point
    speed = jnp.maximum(ego.speed, 0.0)
    can_stop = speed * speed <= 2.0 * caution_decel * jnp.maximum(ahead, 0.0)
    must_stop = (jnp.isin(lights.state, jnp.asarray(stop_states))
                 | (jnp.isin(lights.state, jnp.asarray(caution_states)) & can_stop))
    relevant = lights.valid & controls_us & must_stop & (ahead > 0.0) & (jnp.abs(lateral) < max_lateral)
    return jnp.min(jnp.where(relevant, arc, jnp.inf))


def allowed_speed_profile(path: RoutePath, lateral_accel: float, decel: float) -> jax.Array:
    """Reverse-cumulative bound for bends: A_i = min over j >= i of (v_bend_j^2 + 2 decel arc_j),
    where v_bend = sqrt(lateral_accel / |curvature|). The speed allowed at arc s (before point i) is
    sqrt(A_i - 2 decel s) (`allowed_speed`). (M,) -> (M,)."""
    v_bend_sq = lateral_accel / jnp.maximum(jnp.abs(path.curvature), 1e-4)
    reach = jnp.minimum(v_bend_sq, 1e4) + 2.0 * decel * path.arc
    return jax.lax.cummin(reach, reverse=True)


def allowed_speed(path: RoutePath, profile: jax.Array, arc: jax.Array, decel: float) -> jax.Array:
    """Highest speed at `arc` from which every bend ahead is reached slowly enough. (...) -> (...)."""
    i = jnp.clip(jnp.searchsorted(path.arc, arc), 0, path.arc.shape[0] - 1)
    return jnp.sqrt(jnp.maximum(profile[i] - 2.0 * decel * arc, 0.0))

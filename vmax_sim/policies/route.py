"""What the rule-based planners read off one unbatched `SimulatorState`: the SDC now, the route path
it follows, the other objects in that path's frame, and the stop points of red lights on the route.

Every function is pure and jittable on one scenario (vmap for batches); shapes are in the
docstrings: N objects, M path points, L traffic lights.
"""

from __future__ import annotations

import flax.struct
import jax
import jax.numpy as jnp

from scenariomax.schema import RG_STOP_SIGN
from vmax_sim.datatypes import SimulatorState
from vmax_sim.dynamics.bicycle import DT, heading_speed
from vmax_sim.env.metrics_adapter import sdc_index
from vmax_sim.geometry.transforms import to_local_points, wrap_angle
from vmax_sim.map_index.query import lane_candidates, nearest_lane, project_on_paths

PATH_SPACING_M = 1.0  # spacing of the straight extension past the end of a path (shards: ~1 m)
NO_PATH_BACK_M = 20.0  # without any SDC path, a straight one starting this far behind the SDC
ARC_WINDOW_M = 10.0  # m of slack around the arc the SDC's driven distance predicts
OBJECT_WINDOW_M = (-30.0, 150.0)  # m; objects and lights are projected on this part of the path around the SDC
MIN_WINDOW_M = 24.0  # m, the narrowest projection window (the coarse search looks at every 10th point)
ROUTE_TIE_M = 1.0  # m; on-route paths this much further than the nearest still count as nearest


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
    yaw_rate: jax.Array  # (N,) float32, rad/s over the last step (0 where the previous step is invalid)


def _now(values: jax.Array, timestep: jax.Array) -> jax.Array:
    """(..., T) -> (...) at `timestep`."""
    return jax.lax.dynamic_index_in_dim(values, timestep, axis=-1, keepdims=False)


def ego_now(state: SimulatorState) -> Ego:
    """The SDC's pose, signed speed and size at the current step of one unbatched state."""
    sim, t, i = state.sim_trajectory, state.timestep, sdc_index(state)
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


def total_turning(xy: jax.Array, valid: jax.Array) -> jax.Array:
    """Sum of absolute heading changes along each path, radians. (P, M, 2), (P, M) -> (P,)."""
    d = jnp.diff(xy, axis=1)  # (P, M - 1, 2)
    ok = valid[:, 1:] & valid[:, :-1] & (jnp.sum(d * d, -1) > 1e-4)
    yaw = jnp.arctan2(d[..., 1], d[..., 0])
    turn = jnp.abs(wrap_angle(jnp.diff(yaw, axis=1)))  # (P, M - 2)
    return jnp.sum(jnp.where(ok[:, 1:] & ok[:, :-1], turn, 0.0), axis=1)


def choose_route(state: SimulatorState, ego: Ego, tie_distance: float = ROUTE_TIE_M) -> RoutePath:
    """The on-route SDC path nearest the SDC (as the progress metrics choose it), else the nearest path,
    else a straight line along the SDC's heading; extended straight past its end.

    On-route paths within `tie_distance` of the nearest one count as equally near, and the one that
    turns least in all wins: where several on-route paths share the logged part and fork after it,
    the choice stays on one branch instead of flipping between them, and a path that loops a
    roundabout once more before taking the logged exit loses to the one taking it directly.
    """
    paths = state.sdc_paths
    proj = project_on_paths(paths.xy, paths.valid, paths.arc_length, ego.xy)
    has_points = jnp.any(paths.valid, axis=1)  # (P,)
    distance = jnp.where(has_points, proj.distance, jnp.inf)
    on_route = jnp.where(paths.on_route, distance, jnp.inf)
    near = on_route <= jnp.min(on_route) + tie_distance
    turning = jnp.where(near, total_turning(paths.xy, paths.valid), jnp.inf)
    index = jnp.where(jnp.isfinite(jnp.min(on_route)), jnp.argmin(turning), jnp.argmin(distance))
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


def project(path: RoutePath, points: jax.Array, arc_min: jax.Array | float = -1e9,
            arc_max: jax.Array | float = 1e9) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Arc, signed lateral offset (+ left) and path heading at the projection of each point on the part
    of the path between arc_min and arc_max (the whole path when that part is shorter than 2 points).

    A path that loops (a roundabout) passes near itself; the window keeps a point from snapping to
    the wrong lap. points (Q, 2) -> (Q,), (Q,), (Q,).
    """
    # the coarse search looks at every 10th point: keep the window at least 2 x 10 m wide
    middle = 0.5 * (arc_min + arc_max)
    lo = jnp.minimum(arc_min, middle - MIN_WINDOW_M / 2)
    hi = jnp.maximum(arc_max, middle + MIN_WINDOW_M / 2)
    window = (path.arc >= lo) & (path.arc <= hi)
    window = jnp.where(jnp.sum(window) >= 2, window, True)[None]  # (1, M)

    def one(p):
        proj = project_on_paths(path.xy[None], window, path.arc[None], p)
        return proj.arc[0], proj.direction[0], proj.distance[0]

    arc, direction, distance = jax.vmap(one)(points)
    closest, _ = point_at(path, arc)
    rel = points - closest
    side = direction[:, 0] * rel[:, 1] - direction[:, 1] * rel[:, 0]
    # the magnitude is the true distance to the polyline: a point beyond an end is not "on" the path
    lateral = jnp.where(side < 0.0, -distance, distance)
    return arc, lateral, jnp.arctan2(direction[:, 1], direction[:, 0])


def travelled_distance(state: SimulatorState, first_timestep: int) -> jax.Array:
    """Distance the SDC has driven since `first_timestep` (the episode's start). () float32"""
    sim, t, i = state.sim_trajectory, state.timestep, sdc_index(state)
    xy = jnp.stack([sim.x[i], sim.y[i]], -1)  # (T, 2)
    step = jnp.linalg.norm(jnp.diff(xy, axis=0), axis=-1)  # (T - 1,), step k -> k + 1
    k = jnp.arange(1, xy.shape[0])
    counted = (k > first_timestep) & (k <= t) & sim.valid[i, 1:] & sim.valid[i, :-1]
    return jnp.sum(jnp.where(counted, step, 0.0))


def ego_arc_on(state: SimulatorState, path: RoutePath, ego: Ego, first_timestep: int) -> tuple[jax.Array, jax.Array]:
    """Arc and signed lateral offset (+ left) of the SDC on the path, searched near where its driven
    distance puts it. -> (), () float32

    The window runs from start arc + 0.6 x driven - 10 m to start arc + driven + 10 m, the start arc
    being the projection of the SDC's position at `first_timestep` (a path starts at the SDC).
    """
    sim, i = state.sim_trajectory, sdc_index(state)
    start_xy = jnp.stack([sim.x[i, first_timestep], sim.y[i, first_timestep]])[None]
    start_arc = project(path, start_xy)[0][0]
    driven = travelled_distance(state, first_timestep)
    arc, lateral, _ = project(path, ego.xy[None], start_arc + 0.6 * driven - ARC_WINDOW_M,
                              start_arc + driven + ARC_WINDOW_M)
    return arc[0], lateral[0]


def objects_now(state: SimulatorState, path: RoutePath, ego_arc: jax.Array) -> Objects:
    """Every object at the current step, projected on the route path near the SDC (the SDC's slot is invalid)."""
    sim, t = state.sim_trajectory, state.timestep
    now = jax.tree.map(lambda a: _now(a, t), sim)  # (N,) fields
    before = jax.tree.map(lambda a: _now(a, jnp.maximum(t - 1, 0)), sim)
    yaw_rate = jnp.where(before.valid & now.valid & (t > 0), wrap_angle(now.yaw - before.yaw) / DT, 0.0)
    boxes = jnp.stack([now.x, now.y, now.length, now.width, now.yaw], -1).astype(jnp.float32)
    vel = jnp.stack([now.vel_x, now.vel_y], -1).astype(jnp.float32)
    valid = now.valid & ~state.object_metadata.is_sdc
    arc, lateral, path_yaw = project(path, boxes[:, :2], ego_arc + OBJECT_WINDOW_M[0],
                                     ego_arc + OBJECT_WINDOW_M[1])
    rel = wrap_angle(now.yaw - path_yaw)
    cos, sin = jnp.abs(jnp.cos(rel)), jnp.abs(jnp.sin(rel))
    return Objects(boxes=boxes, vel=vel, valid=valid, arc=arc, lateral=lateral,
                   half_along=0.5 * (now.length * cos + now.width * sin),
                   half_across=0.5 * (now.length * sin + now.width * cos),
                   speed_along=vel[:, 0] * jnp.cos(path_yaw) + vel[:, 1] * jnp.sin(path_yaw),
                   yaw_rate=yaw_rate.astype(jnp.float32))


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


def light_stop_arc(state: SimulatorState, path: RoutePath, ego: Ego, ego_arc: jax.Array, own_lane: jax.Array,
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
    arc, lateral, _ = project(path, stop_xy, ego_arc + OBJECT_WINDOW_M[0], ego_arc + OBJECT_WINDOW_M[1])  # (L,)
    on_route = jnp.any((lights.lane_ids[:, None] == path.lane_id[None]) & (path.lane_id[None] >= 0), axis=1)
    controls_us = (on_route | (lights.lane_ids == own_lane)) & (lights.lane_ids >= 0)
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


def stop_sign_arc(state: SimulatorState, path: RoutePath, ego: Ego, ego_arc: jax.Array, max_lateral: float,
                  max_ahead: float = 60.0, stop_sign_type: int = RG_STOP_SIGN) -> jax.Array:
    """Arc of the nearest stop sign ahead of the SDC's front bumper on its path, inf if none. () float32

    Stop signs are roadgraph points of `stop_sign_type`; one counts when it lies within `max_lateral`
    of the path (a sign drawn on the lane's stop line, as the synthetic and many converted maps place
    it; a sign at the kerbside further away is not seen). All R roadgraph points are scanned once.
    """
    rg = state.roadgraph_points
    local = to_local_points(rg.xy, ego.xy, ego.yaw)  # (R, 2)
    front = 0.5 * ego.length
    candidate = rg.valid & (rg.types == stop_sign_type) & (local[:, 0] > front) & (local[:, 0] < max_ahead)
    candidate &= jnp.abs(local[:, 1]) < 2.0 * max_lateral  # a cheap pre-filter before the path projection
    k = jnp.argmin(jnp.where(candidate, local[:, 0], jnp.inf))
    arc, lateral, _ = project(path, rg.xy[k][None], ego_arc, ego_arc + max_ahead)
    ok = candidate[k] & (jnp.abs(lateral[0]) < max_lateral) & (arc[0] > ego_arc + front)
    return jnp.where(ok, arc[0], jnp.inf)


def stopped_recently(state: SimulatorState, window_steps: int, max_speed: float) -> jax.Array:
    """The SDC's speed was below max_speed at some step of the last window_steps (now included). () bool"""
    sim, t, i = state.sim_trajectory, state.timestep, sdc_index(state)
    speed = jnp.hypot(sim.vel_x[i], sim.vel_y[i])  # (T,)
    steps = jnp.arange(speed.shape[0])
    recent = (steps <= t) & (steps > t - window_steps) & sim.valid[i]
    return jnp.any(recent & (speed < max_speed))


def path_conflict(path: RoutePath, objects: Objects, ego: Ego, start_arc: jax.Array, zone_length: float,
                  horizon: float, lane_half_width: float, min_speed: float = 0.5, num_times: int = 17,
                  num_zone_points: int = 13) -> jax.Array:
    """Some moving object, driving at constant velocity, comes within lane_half_width + its half width
    of the path between start_arc and start_arc + zone_length within `horizon` seconds. Objects behind
    the SDC driving its way (followers) do not count. Used to accept a gap after a stop sign. -> () bool.
    """
    zone_xy, _ = point_at(path, start_arc + jnp.linspace(0.0, zone_length, num_zone_points))  # (Z, 2)
    times = jnp.linspace(0.0, horizon, num_times)  # (H,)
    # x and y apart, squared distances and their minimum before the test: a trailing 2-wide axis, a square root
    # per (object, time, zone point) and a boolean reduction over two axes made this the costliest part of IDM's
    # step on a CPU (~100 us of ~160 per agent view; now ~20)
    future_x = objects.boxes[:, 0:1] + objects.vel[:, 0:1] * times  # (N, H)
    future_y = objects.boxes[:, 1:2] + objects.vel[:, 1:2] * times
    gap_sq = ((future_x[:, :, None] - zone_xy[:, 0]) ** 2
              + (future_y[:, :, None] - zone_xy[:, 1]) ** 2)  # (N, H, Z)
    reach = lane_half_width + 0.5 * objects.boxes[:, 3]  # (N,)
    hits = jnp.min(gap_sq.reshape(gap_sq.shape[0], -1), axis=1) < reach * reach  # (N,)
    heading = jnp.stack([jnp.cos(ego.yaw), jnp.sin(ego.yaw)])
    speed = jnp.linalg.norm(objects.vel, axis=-1)
    behind = (objects.boxes[:, :2] - ego.xy) @ heading < 0.0
    same_way = objects.vel @ heading > 0.7 * speed
    return jnp.any(hits & objects.valid & (speed > min_speed) & ~(behind & same_way))


def lane_turn_rate(state: SimulatorState, xy: jax.Array, yaw: jax.Array, speed: jax.Array,
                   match_distance: float, preview_time: float = 3.0, num_hops: int = 3) -> jax.Array:
    """Yaw rate that keeps an object on its lane: speed x the lane's mean curvature over the next
    `preview_time` seconds of travel (6 to 36 m), found by hopping along the lane `num_hops` times
    (each hop re-projects on the lane, preferring the same lane id); 0 without a lane within
    match_distance. xy (K, 2), yaw (K,), speed (K,) -> (K,) rad/s."""
    def one(p, heading, v):
        here = lane_candidates(state.map_index, p)
        k = nearest_lane(here, heading)
        found = here.distance[k] < match_distance
        start_heading = jnp.arctan2(here.dir_y[k], here.dir_x[k])
        reach = jnp.clip(jnp.abs(v) * preview_time, 6.0, 36.0)
        hop = reach / num_hops

        def step(carry, _):
            point, lane_heading, lane_id, turned, ok = carry
            ahead = lane_candidates(state.map_index, point + hop * jnp.stack([jnp.cos(lane_heading),
                                                                               jnp.sin(lane_heading)]))
            same = (ahead.lane_id == lane_id) & ahead.valid
            j = nearest_lane(ahead.replace(distance=jnp.where(same, ahead.distance, ahead.distance + 5.0)),
                             lane_heading)
            new_heading = jnp.arctan2(ahead.dir_y[j], ahead.dir_x[j])
            turned = turned + wrap_angle(new_heading - lane_heading)
            ok = ok & (ahead.distance[j] < match_distance)
            return (jnp.stack([ahead.closest_x[j], ahead.closest_y[j]]), new_heading, ahead.lane_id[j], turned,
                    ok), None

        start = (jnp.stack([here.closest_x[k], here.closest_y[k]]), start_heading, here.lane_id[k],
                 jnp.zeros(()), found)
        (_, _, _, turned, ok), _ = jax.lax.scan(step, start, None, length=num_hops)
        return jnp.where(ok, v * turned / reach, 0.0)

    return jax.vmap(one)(xy, yaw, speed)

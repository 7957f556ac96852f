"""Intelligent Driver Model along the SDC's route path, with pure-pursuit steering.

Longitudinal (Treiber, Hennecke & Helbing 2000):
    a_idm = a [1 - (v / v0)^delta - (s* / s)^2],   s* = s0 + max(0, v T + v (v - v_lead) / (2 sqrt(a b)))
with v0 the desired speed (the lane's speed limit, lowered ahead of bends), s the bumper-to-bumper
gap to the leader along the path and v_lead its speed along the path. The leader is the nearest
object ahead whose box reaches into the lane corridor around the path, the stop point of a red
(or stoppable yellow) light on the route, or a stop sign until the SDC has stopped there and the
way is clear. Lateral: pure pursuit (Coulter 1992) on a point of the path a speed-dependent
distance ahead, curvature = 2 y / d^2 in the SDC's frame. See docs/baselines.md.

Everything works on one unbatched state and is jittable; the rollout vmaps it over scenarios.
"""

from __future__ import annotations

import dataclasses

import flax.struct
import jax
import jax.numpy as jnp

from scenariomax.schema import TL_ARROW_CAUTION, TL_ARROW_STOP, TL_CAUTION, TL_FLASHING_STOP, TL_STOP
from vmax_sim.datatypes import Action, SimulatorState, sdc_action
from vmax_sim.dynamics import BICYCLE_NAMES
from vmax_sim.dynamics.bicycle import ACCEL_BOUNDS, CURVATURE_BOUNDS, DT, stop_at_zero
from vmax_sim.geometry.transforms import to_local_points
from vmax_sim.policies.base import Policy
from vmax_sim.policies.route import (
    Ego,
    Objects,
    RoutePath,
    allowed_speed,
    allowed_speed_profile,
    choose_route,
    current_lane_id,
    ego_arc_on,
    ego_now,
    lane_speed_limit,
    light_stop_arc,
    objects_now,
    path_conflict,
    point_at,
    stop_sign_arc,
    stopped_recently,
)


@dataclasses.dataclass(frozen=True)
class IDMConfig:
    """IDM and pure-pursuit parameters (defaults: the textbook IDM values for city traffic)."""

    default_speed: float = 13.4  # m/s (30 mph) desired speed where the lane's limit is unknown
    speed_factor: float = 1.0  # desired speed = factor x speed limit
    max_accel: float = 1.5  # a, m/s^2
    comfort_decel: float = 2.0  # b, m/s^2
    time_headway: float = 1.5  # T, s
    min_gap: float = 2.0  # s0, m (also kept before a red light's stop point)
    delta: float = 4.0  # acceleration exponent
    max_decel: float = 6.0  # m/s^2, the hardest braking (the bicycle model's bound)
    lane_half_width: float = 1.75  # m; an object is in the corridor when |lateral| < this + its half width
    # m; when set, an object at rest (< stop_speed) leads only when |lateral| < the car's half width + this + its
    # half width, so a car parked beside the lane is passed with this much room (None: the lane corridor for all)
    standing_clearance: float | None = None
    bend_lateral_accel: float = 2.0  # m/s^2 accepted in bends: v <= sqrt(this / curvature)
    bend_decel: float = 1.5  # m/s^2 used to slow down ahead of a bend
    bend_preview_s: float = 1.0  # s; the bend speed is read this far ahead (IDM lags a falling desired speed)
    caution_decel: float = 3.0  # m/s^2; stop at a yellow light only when braking this hard suffices
    stop_states: tuple[int, ...] = (TL_ARROW_STOP, TL_STOP, TL_FLASHING_STOP)  # the red-light metric's states
    caution_states: tuple[int, ...] = (TL_ARROW_CAUTION, TL_CAUTION)
    light_lateral: float = 2.5  # m, a stop point this close to the path is on it
    lane_match_distance: float = 3.0  # m, lanes further away give no speed limit / light
    stop_speed: float = 0.3  # m/s; below it the SDC has come to a stop at a stop sign
    stop_memory_s: float = 3.0  # s; a stop this recent, within stop_release_gap of the sign, counts
    stop_release_gap: float = 5.0  # m from the front bumper to the sign
    yield_zone: float = 20.0  # m of path past a stop sign that must stay clear...
    yield_horizon: float = 3.0  # s ...of objects driving at constant velocity for this long
    lookahead_min: float = 3.0  # m, pure-pursuit lookahead at standstill
    lookahead_time: float = 0.6  # s, lookahead grows by speed x this
    lookahead_max: float = 25.0  # m
    dt: float = DT  # s, the simulator step (stopping at zero speed, the stop-sign memory)

    def __post_init__(self):
        for name in ("max_accel", "comfort_decel", "time_headway", "delta", "max_decel", "bend_lateral_accel",
                     "bend_decel", "lookahead_min", "dt"):
            if getattr(self, name) <= 0:
                raise ValueError(f"IDMConfig.{name} must be positive, got {getattr(self, name)}")
        if self.lookahead_max < self.lookahead_min:
            raise ValueError("IDMConfig.lookahead_max must be at least lookahead_min")


def idm_acceleration(speed: jax.Array, desired_speed: jax.Array, gap: jax.Array, lead_speed: jax.Array,
                     config: IDMConfig) -> jax.Array:
    """IDM acceleration (not clipped). All arguments broadcast: (...) -> (...); gap inf = free road."""
    v = jnp.maximum(speed, 0.0)
    v0 = jnp.maximum(desired_speed, 0.1)
    free = 1.0 - (v / v0) ** config.delta
    dynamic = v * config.time_headway + v * (v - lead_speed) / (2.0 * jnp.sqrt(config.max_accel * config.comfort_decel))
    desired_gap = config.min_gap + jnp.maximum(dynamic, 0.0)
    interaction = jnp.where(jnp.isfinite(gap), (desired_gap / jnp.maximum(gap, 0.1)) ** 2, 0.0)
    return config.max_accel * (free - interaction)


def bounded_acceleration(accel: jax.Array, speed: jax.Array, config: IDMConfig, dt: float) -> jax.Array:
    """Clip to [-max_decel, max_accel] and never brake below zero speed within one step of dt. (...) -> (...)."""
    accel = jnp.clip(accel, -config.max_decel, config.max_accel)
    accel = stop_at_zero(accel, speed, dt)  # reversing is never planned
    return jnp.clip(accel, *ACCEL_BOUNDS)


def corridor_leader(objects: Objects, ego_arc: jax.Array, ego_offset: jax.Array, ego_half_length: jax.Array,
                    lane_half_width: float, standing_half_width: jax.Array | None = None,
                    stop_speed: float = 0.0) -> tuple[jax.Array, jax.Array]:
    """Gap (bumper to bumper, along the path) and speed of the nearest object ahead in the corridor
    around the path shifted `ego_offset` to the left. -> (), () (inf, 0 when there is none).
    standing_half_width (): the corridor's half width for objects slower than stop_speed (None: lane_half_width)."""
    half_width = lane_half_width
    if standing_half_width is not None:
        standing = jnp.hypot(objects.vel[:, 0], objects.vel[:, 1]) < stop_speed
        half_width = jnp.where(standing, standing_half_width, lane_half_width)
    in_corridor = objects.valid & (jnp.abs(objects.lateral - ego_offset) < half_width + objects.half_across)
    ahead = objects.arc > ego_arc
    gap = jnp.where(in_corridor & ahead, objects.arc - ego_arc - ego_half_length - objects.half_along, jnp.inf)
    k = jnp.argmin(gap)
    return gap[k], jnp.where(jnp.isfinite(gap[k]), jnp.maximum(objects.speed_along[k], 0.0), 0.0)


def pure_pursuit_curvature(xy: jax.Array, yaw: jax.Array, target_xy: jax.Array) -> jax.Array:
    """Curvature of the arc from the pose (xy (2,), yaw ()) through target_xy (2,): 2 y / d^2. -> ()."""
    local = to_local_points(target_xy, xy, yaw)
    return 2.0 * local[1] / jnp.maximum(jnp.sum(local * local), 1e-2)


def lookahead_distance(speed: jax.Array, config: IDMConfig) -> jax.Array:
    """(...) -> (...) metres."""
    return jnp.clip(config.lookahead_min + config.lookahead_time * jnp.abs(speed), config.lookahead_min,
                    config.lookahead_max)


def steer(path: RoutePath, ego: Ego, ego_arc: jax.Array, offset: jax.Array, config: IDMConfig) -> jax.Array:
    """Pure-pursuit curvature towards the path shifted `offset` to the left, clipped to the model's bounds. ()"""
    target, _ = point_at(path, ego_arc + lookahead_distance(ego.speed, config), offset)
    return jnp.clip(pure_pursuit_curvature(ego.xy, ego.yaw, target), *CURVATURE_BOUNDS)


@flax.struct.dataclass
class Scene:
    """What both planners perceive at one step (IDM drives on it directly, PDM simulates proposals on it)."""

    ego: Ego
    path: RoutePath
    ego_arc: jax.Array  # () float32, the SDC's arc along the path
    ego_lateral: jax.Array  # () float32, its signed offset from the path (+ left)
    objects: Objects  # (N,) every other object, projected on the path
    stop_arc: jax.Array  # () float32, arc of the point the front bumper must stop before (inf: none)
    speed_limit: jax.Array  # () float32, m/s, the lane's limit (-1 unknown)
    desired_speed: jax.Array  # () float32, m/s, speed_factor x (the limit, or default_speed when unknown)
    bend_profile: jax.Array  # (M,) float32, `allowed_speed_profile` of the path


def stop_arc(state: SimulatorState, path: RoutePath, ego: Ego, ego_arc: jax.Array, objects: Objects,
             config: IDMConfig) -> jax.Array:
    """Arc the front bumper must stop before (inf if none): a red light's stop point, or a stop sign until
    the SDC has stopped there and no moving object will cross its path soon. ()"""
    own_lane = current_lane_id(state, ego.xy, ego.yaw, config.lane_match_distance)
    light_arc = light_stop_arc(state, path, ego, ego_arc, own_lane, config.stop_states, config.caution_states,
                               config.caution_decel, config.light_lateral)
    front = ego_arc + 0.5 * ego.length
    sign_arc = stop_sign_arc(state, path, ego, ego_arc, config.lane_half_width)
    has_stopped = stopped_recently(state, round(config.stop_memory_s / config.dt), config.stop_speed)
    released = has_stopped & (sign_arc - front < config.stop_release_gap) & ~path_conflict(
        path, objects, ego, front, config.yield_zone, config.yield_horizon, config.lane_half_width)
    return jnp.minimum(light_arc, jnp.where(released, jnp.inf, sign_arc))


def perceive(state: SimulatorState, config: IDMConfig, first_timestep: int) -> Scene:
    """The route, the SDC on it, the objects, where to stop and how fast to go, from one unbatched state.

    first_timestep: the episode's first step (EnvConfig.first_policy_timestep); the distance driven
    since then tells where along a looping path the SDC is.
    """
    ego = ego_now(state)
    path = choose_route(state, ego)
    ego_arc, ego_lateral = ego_arc_on(state, path, ego, first_timestep)
    objects = objects_now(state, path, ego_arc)
    limit = lane_speed_limit(state, ego.xy, ego.yaw, config.lane_match_distance)
    return Scene(ego=ego, path=path, ego_arc=ego_arc, ego_lateral=ego_lateral, objects=objects,
                 stop_arc=stop_arc(state, path, ego, ego_arc, objects, config), speed_limit=limit,
                 desired_speed=jnp.where(limit > 0.0, limit, config.default_speed) * config.speed_factor,
                 bend_profile=allowed_speed_profile(path, config.bend_lateral_accel, config.bend_decel))


def idm_step_acceleration(scene: Scene, arc: jax.Array, speed: jax.Array, desired: jax.Array, gap: jax.Array,
                          lead_speed: jax.Array, config: IDMConfig, dt: float) -> jax.Array:
    """IDM towards min(desired, the bend speed bend_preview_s ahead of `arc`), behind the leader and before
    the stop point, bounded. All (...) -> (...)."""
    preview = arc + jnp.maximum(speed, 0.0) * config.bend_preview_s
    v0 = jnp.minimum(desired, allowed_speed(scene.path, scene.bend_profile, preview, config.bend_decel))
    stop_gap = scene.stop_arc - arc - 0.5 * scene.ego.length
    accel = jnp.minimum(idm_acceleration(speed, v0, gap, lead_speed, config),
                        idm_acceleration(speed, v0, stop_gap, 0.0, config))
    return bounded_acceleration(accel, speed, config, dt)


def scene_leader(scene: Scene, config: IDMConfig) -> tuple[jax.Array, jax.Array]:
    """`corridor_leader` of the perceived scene on the path itself, passing objects at rest with
    `config.standing_clearance` when it is set. -> (), ()"""
    ego = scene.ego
    standing = None if config.standing_clearance is None else 0.5 * ego.width + config.standing_clearance
    return corridor_leader(scene.objects, scene.ego_arc, 0.0, 0.5 * ego.length, config.lane_half_width, standing,
                           config.stop_speed)


def idm_action(state: SimulatorState, config: IDMConfig = IDMConfig(), first_timestep: int = 10) -> jax.Array:
    """The SDC's [acceleration m/s^2, curvature 1/m] under IDM + pure pursuit. One unbatched state -> (2,)."""
    scene = perceive(state, config, first_timestep)
    ego = scene.ego
    gap, lead_speed = scene_leader(scene, config)
    accel = idm_step_acceleration(scene, scene.ego_arc, ego.speed, scene.desired_speed, gap, lead_speed, config,
                                  config.dt)
    curvature = steer(scene.path, ego, scene.ego_arc, jnp.zeros(()), config)
    return jnp.stack([accel, curvature]).astype(jnp.float32)


def check_bicycle(env, name: str) -> None:
    if env.dynamics.name not in BICYCLE_NAMES:
        raise ValueError(f"the {name} policy needs the bicycle dynamics, not {env.dynamics.name!r}")


def as_env_action(env, state: SimulatorState, action: jax.Array) -> Action:
    """The SDC's physical (2,) action in its slot of a full Action, in the env's convention."""
    if env.config.normalize_actions:
        action = env.dynamics.normalize(action)
    return sdc_action(state, action)


def rule_policy(env, name: str, plan_fn) -> Policy:
    """A rule-based `Policy` (no parameters, no observation) from plan_fn(state, first_timestep) -> the SDC's
    physical (2,) bicycle action."""
    check_bicycle(env, name)

    def action_fn(params, state, observation, key):
        return as_env_action(env, state, plan_fn(state, env.config.first_policy_timestep))

    return Policy(name, action_fn)


def idm_policy(env, config: IDMConfig | None = None) -> Policy:
    """IDM + pure pursuit as an evaluation `Policy`."""
    config = config or IDMConfig()
    return rule_policy(env, "idm", lambda state, first: idm_action(state, config, first))

"""PDM-Closed (Dauner et al., "Parting with Misconceptions about Learning-based Vehicle Motion
Planning", CoRL 2023) on the V-Max simulator.

Every step:
1. Proposals: IDM along the route path and along copies shifted sideways (default +-1 m), each
   with the desired speed at a fraction of the speed limit (default 20/40/60/80/100%): 15 proposals.
   The SDC's sideways offset relaxes from where it is to the copy's offset over one pure-pursuit
   lookahead of travelled distance; the proposals' acceleration changes by at most `max_jerk`.
2. Forecasts: the `num_objects` objects most relevant to the SDC keep their speed; by default they
   turn with their lane's bend and stop at a red light's stop point ahead of them
   (`forecast="constant_velocity"`, `stop_at_red=False` gives the paper's constant velocity and heading).
3. Simulation: each proposal is rolled out over `horizon_s` in steps of `step_s`: IDM behind the
   nearest forecast object in its corridor and before the stop point of a red light or stop sign.
4. Scoring with the project's metric functions, as nuPlan's score: multipliers (no at-fault
   collision, `at_fault_collisions` at each object's first contact; on the road, `offroad` via the
   map index; making progress) times the weighted mean of TTC within bound (`time_to_collision`),
   progress (relative to the best proposal), speed-limit compliance, comfort (`comfort_signals` /
   `comfort_score`) and the V-Max multiple-lanes term (`on_multiple_lanes`), with MetricsConfig's
   weights. A proposal rear-ended by a forecast object is scaled by `rear_collision_factor`.
5. The best proposal's first acceleration is applied, steering by pure pursuit on its path;
   when the SDC's own constant-velocity time to collision with an object ahead drops below
   `emergency_ttc`, it brakes at `emergency_decel` instead.

Everything works on one unbatched state, is jittable with static shapes, and has no Python control
flow on traced values; the rollout vmaps it over scenarios.
"""

from __future__ import annotations

import dataclasses

import flax.struct
import jax
import jax.numpy as jnp

from scenariomax.schema import OBJECT_TYPE_PEDESTRIAN
from vmax_sim.datatypes import SimulatorState
from vmax_sim.geometry.transforms import to_local_points, vector_length
from vmax_sim.map_index.query import lane_candidates
from vmax_sim.metrics import (
    MetricsConfig,
    at_fault_collisions,
    comfort_score,
    comfort_signals,
    offroad,
    on_multiple_lanes,
    overlaps,
    time_to_collision,
)
from vmax_sim.metrics.step import sdc_box_at
from vmax_sim.policies.base import Policy
from vmax_sim.policies.idm import (
    IDMConfig,
    Scene,
    bounded_acceleration,
    idm_step_acceleration,
    lookahead_distance,
    perceive,
    rule_policy,
    steer,
)
from vmax_sim.policies.route import lane_turn_rate, point_at, project

FORECASTS = ("constant_velocity", "constant_turn", "lane")
MAX_FORECAST_YAW_RATE = 0.6  # rad/s


@dataclasses.dataclass(frozen=True)
class PDMConfig:
    """PDM-Closed settings; the IDM part (and pure pursuit) comes from `idm`, thresholds from `metrics`."""

    # PDM-Closed's IDM brakes at most 3 m/s^2 in its proposals; harder braking is the emergency brake's
    idm: IDMConfig = dataclasses.field(default_factory=lambda: IDMConfig(max_decel=3.0))
    metrics: MetricsConfig = dataclasses.field(default_factory=MetricsConfig)
    lateral_offsets: tuple[float, ...] = (0.0, 1.0, -1.0)  # m to the left of the route path; ties go to the first
    speed_fractions: tuple[float, ...] = (1.0, 0.8, 0.6, 0.4, 0.2)  # of the desired speed
    horizon_s: float = 4.0  # s simulated per proposal
    step_s: float = 0.2  # s per simulation step
    # how other objects move over the horizon: "constant_velocity" (velocity and heading, as PDM-Closed),
    # "constant_turn" (their last yaw rate too) or "lane" (the yaw rate that follows their lane's bend)
    forecast: str = "lane"
    max_jerk: float = 4.0  # m/s^3 the proposals' acceleration may change by (nuPlan's comfort bound: 4.13); 0: off
    # proposals whose first step jerks away from the acceleration executed last score no comfort. Off (with
    # max_jerk 0), the plan is a function of the current state alone, not of the last action: a teacher whose
    # label a student can read off what it observes (train.teacher=pdm_state)
    first_step_comfort: bool = True
    stop_at_red: bool = True  # forecast objects stop at a red light's stop point straight ahead of them
    corridor_margin: float = 0.75  # m beside the SDC's half width in which a forecast object leads a proposal
    num_objects: int = 16  # objects forecast (nearest the SDC, those in its corridor ahead first)
    ttc_horizon_s: float = 4.0  # s of each proposal checked for time to collision
    num_map_samples: int = 12  # poses along each shifted path checked for off-road and multiple lanes
    min_progress: float = 1.0  # m; when no proposal gets this far, progress scores 1 for all
    edge_margin: float = 0.3  # m; a shifted path must keep the SDC's corners this far inside the road edge
    rear_collision_factor: float = 0.5  # score multiplier of a proposal hit from behind (not at fault):
    # other agents replay their logs, so being rear-ended still counts against accuracy
    emergency_ttc: float = 2.0  # s; brake at emergency_decel when the SDC's own TTC is below it (0 disables)
    emergency_decel: float = 3.0  # m/s^2 (6 and 4 were tried: the harsher stops cost more comfort than they saved)

    def __post_init__(self):
        if not self.lateral_offsets or not self.speed_fractions:
            raise ValueError("PDMConfig needs at least one lateral offset and one speed fraction")
        if self.step_s <= 0 or self.horizon_s < self.step_s:
            raise ValueError(f"PDMConfig needs 0 < step_s <= horizon_s, got {self.step_s} and {self.horizon_s}")
        if self.forecast not in FORECASTS:
            raise ValueError(f"PDMConfig.forecast must be one of {FORECASTS}, got {self.forecast!r}")
        if self.num_objects < 1 or self.num_map_samples < 1:
            raise ValueError("PDMConfig.num_objects and num_map_samples must be at least 1")
        object.__setattr__(self, "lateral_offsets", tuple(float(v) for v in self.lateral_offsets))
        object.__setattr__(self, "speed_fractions", tuple(float(v) for v in self.speed_fractions))

    @property
    def num_steps(self) -> int:
        return max(round(self.horizon_s / self.step_s), 1)


@flax.struct.dataclass
class Forecast:
    """The chosen objects at each simulated time (index 0 = now)."""

    boxes: jax.Array  # (H + 1, K, 5) float32
    vel: jax.Array  # (H + 1, K, 2) float32
    valid: jax.Array  # (K,) bool
    arc: jax.Array  # (H + 1, K) float32, projection on the route path
    lateral: jax.Array  # (H + 1, K) float32
    half_along: jax.Array  # (K,) float32, half extent along the path (at time 0)
    half_across: jax.Array  # (K,) float32
    speed_along: jax.Array  # (H + 1, K) float32, velocity along the path at the projection


@flax.struct.dataclass
class Proposals:
    """Simulated proposals (P of them) over H steps."""

    offset: jax.Array  # (P,) float32, m left of the path
    arc: jax.Array  # (P, H + 1) float32
    speed: jax.Array  # (P, H + 1) float32
    accel: jax.Array  # (P, H) float32
    lateral: jax.Array  # (P, H + 1) float32, the SDC's offset from the path
    xy: jax.Array  # (P, H + 1, 2) float32
    yaw: jax.Array  # (P, H + 1) float32


def proposal_grid(config: PDMConfig) -> tuple[jax.Array, jax.Array]:
    """Offsets and speed fractions of the P = offsets x fractions proposals (offset-major). -> (P,), (P,)."""
    offsets = jnp.repeat(jnp.asarray(config.lateral_offsets, jnp.float32), len(config.speed_fractions))
    fractions = jnp.tile(jnp.asarray(config.speed_fractions, jnp.float32), len(config.lateral_offsets))
    return offsets, fractions


def select_objects(scene: Scene, num: int, lane_half_width: float) -> jax.Array:
    """Indices (num,) of the objects to forecast: nearest the SDC, those in its corridor ahead counted
    at a quarter of their distance (a leader 60 m ahead matters more than a car 20 m to the side)."""
    obj = scene.objects
    distance = vector_length(obj.boxes[:, :2] - scene.ego.xy)
    in_lane = (jnp.abs(obj.lateral) < lane_half_width + obj.half_across + 1.0) & (obj.arc > scene.ego_arc)
    key = jnp.where(obj.valid, jnp.where(in_lane, 0.25 * distance, distance), jnp.inf)
    k = min(num, key.shape[0])
    _, idx = jax.lax.top_k(-key, k)
    return jnp.pad(idx, (0, num - k), constant_values=idx[0]) if num > k else idx


def red_light_stop_time(state: SimulatorState, boxes: jax.Array, vel: jax.Array, stop_states: tuple[int, ...],
                        max_lateral: float = 2.0, max_ahead: float = 80.0) -> jax.Array:
    """When each object reaches the stop point of a red light straight ahead of it (inf: none).

    A stop point counts when it lies ahead of the object's front along its direction of travel and
    within max_lateral of that line. boxes (K, 5), vel (K, 2) -> (K,) seconds.
    """
    t = state.timestep
    lights = jax.tree.map(lambda a: jax.lax.dynamic_index_in_dim(a, t, axis=-1, keepdims=False),
                          state.log_traffic_light)  # (L,) fields
    red = lights.valid & jnp.isin(lights.state, jnp.asarray(stop_states))  # (L,)
    speed = vector_length(vel)  # (K,)
    heading = vel / jnp.maximum(speed, 1e-3)[:, None]  # (K, 2)
    rel = jnp.stack([lights.x, lights.y], -1)[None] - boxes[:, None, :2]  # (K, L, 2)
    ahead = jnp.sum(rel * heading[:, None], -1) - 0.5 * boxes[:, None, 2]  # (K, L) from the front bumper
    lateral = jnp.abs(rel[..., 0] * heading[:, None, 1] - rel[..., 1] * heading[:, None, 0])
    relevant = red[None] & (ahead > 0.0) & (ahead < max_ahead) & (lateral < max_lateral) & (speed[:, None] > 0.5)
    distance = jnp.min(jnp.where(relevant, ahead, jnp.inf), axis=1)  # (K,)
    return distance / jnp.maximum(speed, 0.5)


def forecast(scene: Scene, idx: jax.Array, times: jax.Array, yaw_rate: jax.Array | None = None,
             stop_time: jax.Array | None = None) -> Forecast:
    """Forecasts of objects `idx` (K,) at `times` (H + 1,), projected on the path: constant velocity and
    heading, or constant speed and `yaw_rate` (K,) when given; an object with a `stop_time` (K,) stands
    still from then on."""
    obj = scene.objects
    boxes, vel0 = obj.boxes[idx], obj.vel[idx]  # (K, 5), (K, 2)
    omega = jnp.zeros(idx.shape) if yaw_rate is None else yaw_rate  # (K,)
    stop_time = jnp.full(idx.shape, jnp.inf) if stop_time is None else stop_time
    t = jnp.minimum(times[:, None], stop_time[None])  # (H + 1, K) time spent moving
    wt = omega[None] * t  # (H + 1, K) heading change
    along = t * jnp.sinc(wt / jnp.pi)  # integral of cos(w tau): sin(wt) / w
    across = t * 0.5 * wt * jnp.sinc(wt / (2 * jnp.pi)) ** 2  # integral of sin(w tau): (1 - cos(wt)) / w
    vx, vy = vel0[None, :, 0], vel0[None, :, 1]
    xy = boxes[None, :, :2] + jnp.stack([along * vx - across * vy, across * vx + along * vy], -1)  # (H + 1, K, 2)
    cos, sin = jnp.cos(wt), jnp.sin(wt)
    moving = (times[:, None] < stop_time[None])[..., None]
    vel = jnp.where(moving, jnp.stack([cos * vx - sin * vy, sin * vx + cos * vy], -1), 0.0)  # (H + 1, K, 2)
    size = jnp.broadcast_to(boxes[None, :, 2:4], xy.shape)
    moved = jnp.concatenate([xy, size, (boxes[None, :, 4] + wt)[..., None]], -1)
    h, k = xy.shape[:2]
    lo, hi = scene.ego_arc - 30.0, scene.ego_arc + 150.0
    arc, lateral, path_yaw = project(scene.path, xy.reshape(h * k, 2), lo, hi)
    path_yaw = path_yaw.reshape(h, k)
    speed_along = vel[..., 0] * jnp.cos(path_yaw) + vel[..., 1] * jnp.sin(path_yaw)
    return Forecast(boxes=moved, vel=vel, valid=obj.valid[idx], arc=arc.reshape(h, k),
                    lateral=lateral.reshape(h, k), half_along=obj.half_along[idx], half_across=obj.half_across[idx],
                    speed_along=speed_along)


def forecast_yaw_rate(state: SimulatorState, scene: Scene, idx: jax.Array, config: PDMConfig) -> jax.Array | None:
    """Yaw rates (K,) the forecast uses, None for constant heading (config.forecast)."""
    obj = scene.objects
    if config.forecast == "constant_velocity":
        return None
    if config.forecast == "constant_turn":
        rate = obj.yaw_rate[idx]
    else:
        speed = obj.vel[idx, 0] * jnp.cos(obj.boxes[idx, 4]) + obj.vel[idx, 1] * jnp.sin(obj.boxes[idx, 4])
        is_vehicle = state.object_metadata.object_types[idx] != OBJECT_TYPE_PEDESTRIAN
        rate = jnp.where(is_vehicle, lane_turn_rate(state, obj.boxes[idx, :2], obj.boxes[idx, 4], speed,
                                                    config.idm.lane_match_distance), 0.0)
    return jnp.clip(rate, -MAX_FORECAST_YAW_RATE, MAX_FORECAST_YAW_RATE)


def simulate(scene: Scene, fc: Forecast, offsets: jax.Array, fractions: jax.Array, config: PDMConfig) -> Proposals:
    """Roll every proposal out with IDM behind the forecast objects. (P,) offsets/fractions -> Proposals."""
    idm, dt = config.idm, config.step_s
    ego = scene.ego
    half_len = 0.5 * ego.length
    start_lateral = scene.ego_lateral
    relax = lookahead_distance(ego.speed, idm)  # m of travel over which the offset is reached (1/e)
    corridor = 0.5 * ego.width + config.corridor_margin  # half width swept by the SDC along a proposal

    def lateral_at(arc):  # (P,) -> (P,)
        return offsets + (start_lateral - offsets) * jnp.exp(-jnp.maximum(arc - scene.ego_arc, 0.0) / relax)

    accel_now = (ego.speed - ego.prev_speed) / idm.dt  # executed last step

    def body(carry, h):
        arc, speed, previous = carry  # (P,)
        lat = lateral_at(arc)
        in_corridor = fc.valid[None] & (jnp.abs(fc.lateral[h][None] - lat[:, None])
                                        < corridor + fc.half_across[None])  # (P, K)
        gaps = fc.arc[h][None] - arc[:, None] - half_len - fc.half_along[None]
        gaps = jnp.where(in_corridor & (fc.arc[h][None] > arc[:, None]), gaps, jnp.inf)
        k = jnp.argmin(gaps, axis=1)
        gap = jnp.take_along_axis(gaps, k[:, None], 1)[:, 0]
        lead = jnp.where(jnp.isfinite(gap), jnp.maximum(fc.speed_along[h][k], 0.0), 0.0)
        accel = idm_step_acceleration(scene, arc, speed, fractions * scene.desired_speed, gap, lead, idm, dt)
        if config.max_jerk > 0:  # the first step lasts one simulator step
            change = config.max_jerk * jnp.where(h == 0, idm.dt, dt)
            accel = bounded_acceleration(jnp.clip(accel, previous - change, previous + change), speed, idm, dt)
        new_speed = jnp.maximum(speed + accel * dt, 0.0)
        new_arc = arc + 0.5 * (speed + new_speed) * dt
        return (new_arc, new_speed, accel), (new_arc, new_speed, accel)

    num = offsets.shape[0]
    start = (jnp.full((num,), scene.ego_arc), jnp.full((num,), jnp.maximum(ego.speed, 0.0)),
             jnp.full((num,), accel_now))
    _, (arcs, speeds, accels) = jax.lax.scan(body, start, jnp.arange(config.num_steps))
    arc = jnp.concatenate([start[0][:, None], arcs.T], 1)  # (P, H + 1)
    speed = jnp.concatenate([start[1][:, None], speeds.T], 1)
    lateral = lateral_at(arc.T).T  # (P, H + 1)
    xy, yaw = point_at(scene.path, arc, lateral)
    return Proposals(offset=offsets, arc=arc, speed=speed, accel=accels.T, lateral=lateral, xy=xy, yaw=yaw)


def map_checks(state: SimulatorState, scene: Scene, offsets: jax.Array, reach: jax.Array,
               config: PDMConfig) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Off-road and multiple-lanes flags at `num_map_samples` arcs up to `reach` m ahead along each
    shifted path. offsets (O,) -> arcs (J,), off-road (O, J) bool, multiple lanes (O, J) bool.

    A pose is off-road when a corner is outside the road edges, or (for a shifted path) when a
    corner comes within `edge_margin` of the edge and nearer to it than on the route path itself:
    pure pursuit tracks a shifted path only roughly, so a proposal hugging the kerb is not on the road.
    """
    ego, metrics = scene.ego, config.metrics
    arcs = scene.ego_arc + reach * (jnp.arange(config.num_map_samples) + 1.0) / config.num_map_samples  # (J,)
    relax = lookahead_distance(ego.speed, config.idm)
    decay = jnp.exp(-(arcs - scene.ego_arc) / relax)  # (J,)
    rows = jnp.concatenate([jnp.zeros(1, jnp.float32), offsets])  # (O + 1,), the route path first
    lateral = rows[:, None] + (scene.ego_lateral - rows[:, None]) * decay[None]  # (O + 1, J)
    xy, yaw = point_at(scene.path, jnp.broadcast_to(arcs, lateral.shape), lateral)  # (O + 1, J, 2), (O + 1, J)
    size = jnp.stack([ego.length, ego.width])

    def one(p, heading):
        _, distance = offroad(state.map_index, sdc_box_at(p, heading, size))
        lanes = lane_candidates(state.map_index, p)
        multiple = on_multiple_lanes(lanes, p, heading, ego.width, metrics.lane_half_width, metrics.lane_max_angle_deg)
        return distance, multiple

    distance, multiple = jax.vmap(jax.vmap(one))(xy, yaw)  # (O + 1, J)
    centre = distance[0]
    off = (distance[1:] > 0.0) | ((distance[1:] > -config.edge_margin) & (distance[1:] > centre[None] + 0.05))
    return arcs, off, multiple[1:]


def score(state: SimulatorState, scene: Scene, fc: Forecast, props: Proposals, config: PDMConfig) -> dict:
    """nuPlan-style score of each proposal and its terms. -> dict of (P,) float32 ("score" and the terms)."""
    metrics, dt = config.metrics, config.step_s
    ego = scene.ego
    size = jnp.stack([ego.length, ego.width])
    boxes = jnp.concatenate([props.xy, jnp.broadcast_to(size, props.yaw.shape + (2,)), props.yaw[..., None]], -1)
    heading = jnp.stack([jnp.cos(props.yaw), jnp.sin(props.yaw)], -1)
    vel = props.speed[..., None] * heading  # (P, H + 1, 2)
    obj_speed = vector_length(fc.vel[0])  # (K,)

    shifted = jnp.abs(props.offset) > 0.1  # (P,) off the lane centre: a side hit is the SDC's fault

    def at_step(box, v, speed, h, off_centre):  # one proposal pose against the forecasts at step h
        objs = fc.boxes[h]
        hit = overlaps(box, objs, fc.valid)
        fault = at_fault_collisions(box, speed, objs, obj_speed, hit, off_centre, jnp.zeros((), bool),
                                    metrics.stopped_speed)
        local = to_local_points(objs[:, :2], box[:2], box[4])
        from_behind = hit & (jnp.abs(jnp.arctan2(local[:, 1], local[:, 0])) > jnp.deg2rad(150.0))
        ttc = time_to_collision(box, v, objs, fc.vel[h], fc.valid, metrics.ttc_threshold)
        return hit, fault, from_behind, (ttc <= metrics.ttc_threshold) & (speed > metrics.ttc_ego_min_speed)

    steps = jnp.arange(props.arc.shape[1])
    hit, fault, behind, ttc_bad = jax.vmap(jax.vmap(at_step, in_axes=(0, 0, 0, 0, None)),
                                           in_axes=(0, 0, 0, None, 0))(boxes, vel, props.speed, steps, shifted)
    # each collision is judged at its first contact (as nuPlan does): a forecast that keeps driving
    # through the SDC from behind must not turn into a front hit later
    later = (steps >= 1)[None, :, None]  # (1, H + 1, 1): the pose now is the same for every proposal
    hit = hit & later  # (P, H + 1, K)
    first = jnp.argmax(hit, axis=1)  # (P, K) first step in contact

    def at_first(flags):  # (P, H + 1, K) -> (P,) any object whose first contact has the flag
        return jnp.any(jnp.any(hit, axis=1) & jnp.take_along_axis(flags, first[:, None], 1)[:, 0], axis=1)

    no_fault = 1.0 - at_first(fault).astype(jnp.float32)
    not_hit = jnp.where(at_first(behind), config.rear_collision_factor, 1.0)
    later = later[..., 0]
    ttc_ok = 1.0 - jnp.any(ttc_bad & later & (steps[None] * dt <= config.ttc_horizon_s + 1e-6),
                           axis=1).astype(jnp.float32)

    # map: flags along each distinct shifted path, read up to each proposal's final arc
    offsets = jnp.asarray(config.lateral_offsets, jnp.float32)
    progress = props.arc[:, -1] - scene.ego_arc  # (P,)
    reach = jnp.maximum(jnp.max(progress), 1.0)
    arcs, off, multiple = map_checks(state, scene, offsets, reach, config)
    which = jnp.repeat(jnp.arange(offsets.shape[0]), len(config.speed_fractions))  # (P,) row of each proposal
    covered = arcs[None] <= props.arc[:, -1:] + 1e-3  # (P, J)
    on_road = 1.0 - jnp.any(off[which] & covered, axis=1).astype(jnp.float32)
    lanes_ok = 1.0 - jnp.sum(multiple[which] & covered, 1) / jnp.maximum(jnp.sum(covered, 1), 1)

    best = jnp.max(progress)
    progress_ratio = jnp.where(best > config.min_progress, jnp.clip(progress / jnp.maximum(best, 1e-6), 0.0, 1.0), 1.0)
    making_progress = (progress_ratio >= metrics.min_progress_ratio).astype(jnp.float32)

    overspeed = jnp.where(scene.speed_limit > 0.0, jnp.maximum(props.speed[:, 1:] - scene.speed_limit, 0.0), 0.0)
    speed_ok = jnp.maximum(0.0, 1.0 - jnp.mean(overspeed, axis=1) / metrics.max_overspeed)

    # jerk includes the step from the acceleration executed last (the bicycle model's speed change)
    accel_now = (ego.speed - ego.prev_speed) / config.idm.dt
    first_jerk = (props.accel[:, :1] - accel_now) / config.idm.dt
    # nuPlan's comfort on each proposal's poses (Savitzky-Golay derivatives at step_s), and a first step
    # that does not jerk away from the acceleration executed last
    coarse = dataclasses.replace(metrics, dt=dt)
    valid = jnp.ones(props.arc.shape[1], bool)
    smooth = jax.vmap(lambda x, y, yaw: comfort_score(comfort_signals(x, y, yaw, valid, coarse), coarse))(
        props.xy[..., 0], props.xy[..., 1], props.yaw)
    comfortable = smooth
    if config.first_step_comfort:
        comfortable = smooth * (jnp.abs(first_jerk[:, 0]) <= metrics.max_abs_lon_jerk).astype(jnp.float32)

    terms = {"ttc_within_bound": ttc_ok, "ego_progress": progress_ratio, "speed_limit_compliance": speed_ok,
             "comfort": comfortable, "multiple_lanes_score": lanes_ok}
    weights = tuple(metrics.nuplan_weights) + tuple(metrics.vmax_extra_weights)
    weighted = sum(w * terms[name] for name, w in weights) / sum(w for _, w in weights)
    total = no_fault * not_hit * on_road * making_progress * weighted
    return {"score": total, "no_at_fault_collision": no_fault, "not_hit": not_hit, "on_road": on_road,
            "making_progress": making_progress, **terms}


def pdm_plan(state: SimulatorState, config: PDMConfig = PDMConfig(),
             first_timestep: int = 10) -> tuple[jax.Array, Proposals, dict]:
    """PDM-Closed on one unbatched state. -> SDC action (2,) [accel, curvature], the proposals, their scores."""
    idm = config.idm
    scene = perceive(state, idm, first_timestep)
    times = jnp.arange(config.num_steps + 1, dtype=jnp.float32) * config.step_s
    idx = select_objects(scene, config.num_objects, idm.lane_half_width)
    stop_time = None
    if config.stop_at_red:
        stop_time = red_light_stop_time(state, scene.objects.boxes[idx], scene.objects.vel[idx], idm.stop_states)
    fc = forecast(scene, idx, times, forecast_yaw_rate(state, scene, idx, config), stop_time)
    offsets, fractions = proposal_grid(config)
    props = simulate(scene, fc, offsets, fractions, config)
    scores = score(state, scene, fc, props, config)
    best = jnp.argmax(scores["score"])
    ego = scene.ego
    accel = props.accel[best, 0]
    # emergency brake: the SDC's own constant-velocity time to collision with an object ahead
    ego_box = sdc_box_at(ego.xy, ego.yaw, jnp.stack([ego.length, ego.width]))
    ego_vel = ego.speed * jnp.stack([jnp.cos(ego.yaw), jnp.sin(ego.yaw)])
    ttc_now = time_to_collision(ego_box, ego_vel, fc.boxes[0], fc.vel[0], fc.valid, max(config.emergency_ttc, 1e-3))
    hardest = jnp.maximum(-config.emergency_decel, -jnp.maximum(ego.speed, 0.0) / idm.dt)  # never reverse
    accel = jnp.where(ttc_now < config.emergency_ttc, hardest, accel)
    curvature = steer(scene.path, ego, scene.ego_arc, props.offset[best], idm)
    return jnp.stack([accel, curvature]).astype(jnp.float32), props, scores


def pdm_action(state: SimulatorState, config: PDMConfig = PDMConfig(), first_timestep: int = 10) -> jax.Array:
    """The SDC's [acceleration m/s^2, curvature 1/m] under PDM-Closed. One unbatched state -> (2,)."""
    return pdm_plan(state, config, first_timestep)[0]


def pdm_policy(env, config: PDMConfig | None = None) -> Policy:
    """PDM-Closed as an evaluation `Policy`."""
    config = config or PDMConfig()
    return rule_policy(env, "pdm", lambda state, first: pdm_action(state, config, first))

"""Sim-agent realism: a WOSAC-style meta-metric (Waymo Open Sim Agents Challenge) over sampled rollouts.

For every evaluated object nine features are computed over the simulated future, in each of the N rollouts
and in the log: linear speed and acceleration, angular speed and acceleration (central differences), distance
to the nearest object (rounded boxes), collision (that distance < 0), time to collision with the object
followed, distance to the road edge (signed, > 0 off the road) and off-road (that distance > 0). Each
feature's likelihood is that of the logged values under a histogram of the simulated ones (bins, ranges,
smoothing and weights: the 2024 challenge definition, `CHALLENGE_2024`); the meta-metric is their weighted
sum. docs/realism.md lists the numbers and what differs from WOSAC.

Everything here is pure JAX on one scene: trajectories in, likelihoods out. Who produced the trajectories
(log replay, a rule policy, a trained or self-play policy) is the business of
`vmax_sim.evaluation.realism_rollouts`.
"""

from __future__ import annotations

import dataclasses

import flax.struct
import jax
import jax.numpy as jnp

from vmax_sim.datatypes import SimulatorState
from vmax_sim.geometry.boxes import box_axes, box_corners
from vmax_sim.map_index.query import signed_edge_distance

LARGE_DISTANCE = 1e10  # m; stands for "no other object" (clipped into the last bin)


@dataclasses.dataclass(frozen=True)
class FeatureConfig:
    """How one feature is scored (the challenge's `FeatureConfig`)."""

    weight: float  # share of the meta-metric
    kind: str = "histogram"  # "histogram" or "bernoulli" (per object: did it happen at some valid step)
    min_val: float = 0.0  # histogram range; values outside are clipped into the end bins
    max_val: float = 1.0
    num_bins: int = 10
    pseudocount: float = 0.1  # added to every bin's count so that an empty bin is not log(0)
    independent_timesteps: bool = True  # one histogram per object over all steps x rollouts (else per step)


# The 2024 challenge definition (waymo-open-dataset, challenge_2024_config.textproto); the 2025 sim-agents
# config differs only in the road-edge weight (0.05) and a traffic-light feature (0.05) that is not scored here.
CHALLENGE_2024: tuple[tuple[str, FeatureConfig], ...] = (
    ("linear_speed", FeatureConfig(0.05, min_val=0.0, max_val=25.0, num_bins=10)),
    ("linear_acceleration", FeatureConfig(0.05, min_val=-12.0, max_val=12.0, num_bins=11)),
    ("angular_speed", FeatureConfig(0.05, min_val=-0.628, max_val=0.628, num_bins=11)),
    ("angular_acceleration", FeatureConfig(0.05, min_val=-3.14, max_val=3.14, num_bins=11)),
    ("distance_to_nearest_object", FeatureConfig(0.10, min_val=-5.0, max_val=40.0, num_bins=10)),
    ("collision_indication", FeatureConfig(0.25, kind="bernoulli", pseudocount=0.001)),
    ("time_to_collision", FeatureConfig(0.10, min_val=0.0, max_val=5.0, num_bins=10)),
    ("distance_to_road_edge", FeatureConfig(0.10, min_val=-20.0, max_val=40.0, num_bins=10)),
    ("offroad_indication", FeatureConfig(0.25, kind="bernoulli", pseudocount=0.001)),
)
FEATURE_NAMES = tuple(name for name, _ in CHALLENGE_2024)
BUCKETS = {"kinematic": FEATURE_NAMES[:4], "interactive": FEATURE_NAMES[4:7], "map_based": FEATURE_NAMES[7:]}


@dataclasses.dataclass(frozen=True)
class RealismConfig:
    features: tuple[tuple[str, FeatureConfig], ...] = CHALLENGE_2024
    dt: float = 0.1  # s per step
    current_timestep: int = 10  # the last logged step; the scored future is every step after it
    corner_rounding: float = 0.7  # boxes for object distances: rounded corners (0 sharp, 1 capsule)
    num_candidates: int = 8  # nearest objects (bounding-circle gap) whose exact box distance is computed
    max_ttc: float = 5.0  # s; also the value when no object is followed
    ttc_max_heading_diff: float = 1.3089969  # rad (75 deg): the object ahead drives roughly our way
    ttc_small_overlap_heading_diff: float = 0.17453293  # rad (10 deg) required when the lateral overlap is small
    ttc_small_overlap: float = 0.5  # m

    def feature(self, name: str) -> FeatureConfig:
        return dict(self.features)[name]

    def __post_init__(self):
        names = tuple(name for name, _ in self.features)
        if names != FEATURE_NAMES:
            raise ValueError(f"RealismConfig.features must list {FEATURE_NAMES} in that order, got {names}")


@flax.struct.dataclass
class SimTrajectories:
    """What a rollout function returns: R rollouts of every object of one scene over all T steps (the logged
    history included, so that finite differences reach the first simulated step). Boxes keep the log's size."""

    x: jax.Array  # (R, N, T) float32, box centre, m
    y: jax.Array  # (R, N, T) float32
    yaw: jax.Array  # (R, N, T) float32, rad
    valid: jax.Array  # (R, N, T) bool
    # Static: each rollout stands for this many identical ones (a deterministic policy returns R = 1 rollout
    # with copies = N: its histograms are weighted as N identical rollouts'; WOSAC's smoothing then acts as with
    # N submitted copies).
    copies: int = flax.struct.field(pytree_node=False, default=1)

    @property
    def num_rollouts(self) -> int:
        return int(self.x.shape[0]) * self.copies


def log_trajectories(state: SimulatorState, copies: int = 1) -> SimTrajectories:
    """The log as one rollout. -> SimTrajectories (1, N, T)"""
    log = state.log_trajectory
    return SimTrajectories(x=log.x[None], y=log.y[None], yaw=log.yaw[None], valid=log.valid[None], copies=copies)


# ----------------------------------------------------------------------------- estimators


def histogram_log_likelihood(log_values: jax.Array, sim_values: jax.Array, sim_weight: jax.Array,
                             feature: FeatureConfig) -> jax.Array:
    """Log-probability of each logged value's bin under the weighted histogram of the simulated values.

    Bins: num_bins equal bins over [min_val, max_val] (values outside are clipped in); every bin's count gets
    `pseudocount` added. log_values (B, L), sim_values (B, S), sim_weight (B, S) (0 for invalid samples)
    -> (B, L)."""
    width = (feature.max_val - feature.min_val) / feature.num_bins

    def bins(values):
        index = jnp.floor((jnp.clip(values, feature.min_val, feature.max_val) - feature.min_val) / width)
        return jnp.clip(index, 0, feature.num_bins - 1).astype(jnp.int32)

    one_hot = jax.nn.one_hot(bins(sim_values), feature.num_bins, dtype=jnp.float32)  # (B, S, K)
    counts = jnp.sum(one_hot * sim_weight[..., None], axis=1) + feature.pseudocount  # (B, K)
    log_prob = jnp.log(counts) - jnp.log(jnp.sum(counts, axis=-1, keepdims=True))
    return jnp.take_along_axis(log_prob, bins(log_values), axis=1)


def bernoulli_log_likelihood(log_values: jax.Array, sim_values: jax.Array, sim_weight: jax.Array,
                             feature: FeatureConfig) -> jax.Array:
    """A two-bin histogram of booleans (bins [-0.5, 0.5) and [0.5, 1.5]). Shapes as `histogram_log_likelihood`."""
    two_bins = dataclasses.replace(feature, min_val=-0.5, max_val=1.5, num_bins=2)
    return histogram_log_likelihood(log_values.astype(jnp.float32), sim_values.astype(jnp.float32), sim_weight,
                                    two_bins)


def timeseries_log_likelihood(log_values: jax.Array, sim_values: jax.Array, sim_weight: jax.Array,
                              feature: FeatureConfig) -> jax.Array:
    """Per object: one histogram over all steps and rollouts (independent_timesteps) or one per step over the
    rollouts. log_values (E, T), sim_values / sim_weight (R, E, T) -> (E, T) log-likelihoods."""
    num_rollouts, num_objects, num_steps = sim_values.shape
    if feature.independent_timesteps:
        pooled = lambda a: jnp.transpose(a, (1, 0, 2)).reshape(num_objects, num_rollouts * num_steps)  # noqa: E731
        return histogram_log_likelihood(log_values, pooled(sim_values), pooled(sim_weight), feature)
    per_step = lambda a: jnp.transpose(a, (1, 2, 0)).reshape(num_objects * num_steps, num_rollouts)  # noqa: E731
    out = histogram_log_likelihood(log_values.reshape(-1, 1), per_step(sim_values), per_step(sim_weight), feature)
    return out.reshape(num_objects, num_steps)


def masked_mean(values: jax.Array, mask: jax.Array) -> jax.Array:
    """Mean of values where mask (NaN when nothing is masked in). () float32"""
    return jnp.sum(jnp.where(mask, values, 0.0)) / jnp.sum(mask)


# ----------------------------------------------------------------------------- features


def central_difference(values: jax.Array) -> jax.Array:
    """(v[t+1] - v[t-1]) / 2 along the last axis, 0 at both ends. (..., T) -> (..., T)"""
    inner = 0.5 * (values[..., 2:] - values[..., :-2])
    pad = jnp.zeros_like(values[..., :1])
    return jnp.concatenate([pad, inner, pad], axis=-1)


def central_valid(valid: jax.Array) -> jax.Array:
    """Steps whose central difference is defined: both neighbours valid. (..., T) bool -> (..., T) bool"""
    inner = valid[..., 2:] & valid[..., :-2]
    pad = jnp.zeros_like(valid[..., :1])
    return jnp.concatenate([pad, inner, pad], axis=-1)


def wrap_angle(angle: jax.Array) -> jax.Array:
    return (angle + jnp.pi) % (2 * jnp.pi) - jnp.pi


def kinematic_features(x: jax.Array, y: jax.Array, yaw: jax.Array, dt: float) -> dict:
    """Linear speed (m/s) and acceleration (m/s^2), angular speed (rad/s) and acceleration (rad/s^2), by central
    differences. A heading change is wrapped after doubling (the two-step change must be the acute one).
    x, y, yaw (..., T) -> name -> (..., T)"""
    speed = jnp.hypot(central_difference(x), central_difference(y)) / dt
    accel = central_difference(speed) / dt
    yaw_step = wrap_angle(2.0 * central_difference(yaw)) / 2.0
    yaw_accel_step = wrap_angle(2.0 * central_difference(yaw_step)) / 2.0
    return {"linear_speed": speed, "linear_acceleration": accel, "angular_speed": yaw_step / dt,
            "angular_acceleration": yaw_accel_step / dt**2}


def _segment_distance(points: jax.Array, start: jax.Array, end: jax.Array) -> jax.Array:
    """Distance of points to segments, all pairs. points (..., P, 2), start / end (..., S, 2) -> (..., P, S)"""
    d = (end - start)[..., None, :, :]
    r = points[..., :, None, :] - start[..., None, :, :]
    t = jnp.clip(jnp.sum(r * d, -1) / jnp.maximum(jnp.sum(d * d, -1), 1e-12), 0.0, 1.0)
    return jnp.linalg.norm(r - t[..., None] * d, axis=-1)


def rectangle_signed_distance(box_a: jax.Array, box_b: jax.Array) -> jax.Array:
    """Signed distance between two oriented rectangles: the gap when apart, minus the smallest penetration
    depth (over the 4 edge normals) when they overlap. box (..., 5) [x, y, length, width, yaw] -> (...,)"""
    box_a, box_b = jnp.broadcast_arrays(box_a, box_b)
    ha, la = box_axes(box_a[..., 4])
    hb, lb = box_axes(box_b[..., 4])
    axes = jnp.stack([ha, la, hb, lb], axis=-2)  # (..., 4, 2)

    def half_extent(box, heading, left):
        return (0.5 * box[..., None, 2] * jnp.abs(jnp.sum(heading[..., None, :] * axes, -1))
                + 0.5 * box[..., None, 3] * jnp.abs(jnp.sum(left[..., None, :] * axes, -1)))

    gap = jnp.abs(jnp.sum((box_b[..., None, :2] - box_a[..., None, :2]) * axes, -1))
    penetration = half_extent(box_a, ha, la) + half_extent(box_b, hb, lb) - gap  # (..., 4)
    ca, cb = box_corners(box_a), box_corners(box_b)  # (..., 4, 2)
    ea, eb = jnp.roll(ca, -1, axis=-2), jnp.roll(cb, -1, axis=-2)
    apart = jnp.minimum(jnp.min(_segment_distance(ca, cb, eb), axis=(-2, -1)),
                        jnp.min(_segment_distance(cb, ca, ea), axis=(-2, -1)))
    overlapping = jnp.all(penetration > 0.0, axis=-1)
    return jnp.where(overlapping, -jnp.min(penetration, axis=-1), apart)


def rounded_box_distance(box_a: jax.Array, box_b: jax.Array, rounding: float) -> jax.Array:
    """Signed distance between boxes whose corners are rounded: each box is shrunk by s = rounding x
    min(length, width) / 2 on every side and inflated back by a disc of radius s. (..., 5) -> (...,)"""
    def core(box):
        s = rounding * 0.5 * jnp.minimum(box[..., 2], box[..., 3])
        return box.at[..., 2].add(-2 * s).at[..., 3].add(-2 * s), s

    core_a, sa = core(box_a)
    core_b, sb = core(box_b)
    return rectangle_signed_distance(core_a, core_b) - sa - sb


def object_boxes(x: jax.Array, y: jax.Array, yaw: jax.Array, length: jax.Array, width: jax.Array) -> jax.Array:
    """(N, T) fields (length / width (N,) or (N, T)) -> (N, T, 5) boxes"""
    length = jnp.broadcast_to(length if length.ndim == x.ndim else length[:, None], x.shape)
    width = jnp.broadcast_to(width if width.ndim == x.ndim else width[:, None], x.shape)
    return jnp.stack([x, y, length, width, yaw], axis=-1).astype(jnp.float32)


def distance_to_nearest_object(boxes: jax.Array, valid: jax.Array, slots: jax.Array,
                               config: RealismConfig) -> jax.Array:
    """Rounded-box signed distance from each evaluated object to the nearest other valid object. The exact
    distance is computed for the `num_candidates` objects whose bounding circles come closest.
    boxes (N, T, 5), valid (N, T), slots (E,) -> (E, T) m (LARGE_DISTANCE when no other object is valid)."""
    num_objects = boxes.shape[0]
    k = min(config.num_candidates, num_objects - 1)
    radius = 0.5 * jnp.hypot(boxes[..., 2], boxes[..., 3])  # (N, T)

    def one(slot):
        own = boxes[slot]  # (T, 5)
        centre_gap = jnp.hypot(boxes[..., 0] - own[:, 0], boxes[..., 1] - own[:, 1]) - radius - radius[slot]
        usable = valid & (jnp.arange(num_objects) != slot)[:, None]  # (N, T)
        _, index = jax.lax.top_k(-jnp.where(usable, centre_gap, jnp.inf).T, k)  # (T, k)
        others = jnp.take_along_axis(jnp.swapaxes(boxes, 0, 1), index[..., None], axis=1)  # (T, k, 5)
        distance = rounded_box_distance(own[:, None], others, config.corner_rounding)
        ok = jnp.take_along_axis(usable.T, index, axis=1)
        return jnp.min(jnp.where(ok, distance, LARGE_DISTANCE), axis=-1)

    return jax.vmap(one)(slots)


def time_to_collision(boxes: jax.Array, speed: jax.Array, valid: jax.Array, slots: jax.Array,
                      config: RealismConfig) -> jax.Array:
    """Time until an evaluated object reaches the object it follows at constant speeds (WOSAC's definition):
    among valid objects ahead of its front bumper (gap > 0), overlapping its straight trail sideways, heading
    within 75 deg (within 10 deg when the lateral overlap is under 0.5 m), the nearest; TTC = gap / closing
    speed, at most max_ttc (max_ttc when nothing is followed or the gap opens).
    boxes (N, T, 5), speed (N, T), valid (N, T), slots (E,) -> (E, T) s"""
    num_objects = boxes.shape[0]

    def one(slot):
        own = boxes[slot]  # (T, 5)
        diff = wrap_angle(boxes[..., 4] - own[:, 4])  # (N, T)
        cos_d, sin_d = jnp.abs(jnp.cos(diff)), jnp.abs(jnp.sin(diff))
        half_l, half_w = 0.5 * boxes[..., 2], 0.5 * boxes[..., 3]
        heading, left = box_axes(own[:, 4])  # (T, 2)
        rel = boxes[..., :2] - own[:, :2]  # (N, T, 2)
        along, across = jnp.sum(rel * heading, -1), jnp.sum(rel * left, -1)
        gap = along - 0.5 * own[:, 2] - (half_l * cos_d + half_w * sin_d)
        lateral = jnp.abs(across) - 0.5 * own[:, 3] - (half_l * sin_d + half_w * cos_d)
        abs_d = jnp.abs(diff)
        following = ((gap > 0.0) & (abs_d <= config.ttc_max_heading_diff) & (lateral < 0.0)
                     & ((lateral < -config.ttc_small_overlap) | (abs_d <= config.ttc_small_overlap_heading_diff)))
        following &= valid & (jnp.arange(num_objects) != slot)[:, None]
        masked = jnp.where(following, gap, LARGE_DISTANCE)
        ahead = jnp.argmin(masked, axis=0)  # (T,)
        distance = jnp.take_along_axis(masked, ahead[None], axis=0)[0]
        closing = speed[slot] - jnp.take_along_axis(speed, ahead[None], axis=0)[0]
        ttc = jnp.where(closing > 0.0, distance / jnp.where(closing > 0.0, closing, 1.0), config.max_ttc)
        return jnp.minimum(ttc, config.max_ttc)

    return jax.vmap(one)(slots)


def distance_to_road_edge(map_index, boxes: jax.Array) -> jax.Array:
    """Largest signed distance of a box's 4 corners to the nearest road edge (> 0: off the road), from the
    map index (`signed_edge_distance`, a window around each box centre). boxes (..., 5) -> (...,) m"""
    flat = boxes.reshape(-1, 5)
    distance = jax.vmap(lambda box: jnp.max(signed_edge_distance(map_index, box_corners(box), box[:2])))(flat)
    return distance.reshape(boxes.shape[:-1])


def scene_features(state: SimulatorState, x: jax.Array, y: jax.Array, yaw: jax.Array, valid: jax.Array,
                   slots: jax.Array, config: RealismConfig) -> tuple[dict, dict]:
    """The nine features of the evaluated objects in one rollout, over the future steps.
    x, y, yaw, valid (N, T); slots (E,) -> (features name -> (E, F), validity name -> (E, F)), F = T - current - 1."""
    log = state.log_trajectory
    now = config.current_timestep
    size_length, size_width = log.length[:, now], log.width[:, now]  # boxes keep their current size
    boxes = object_boxes(x, y, yaw, size_length, size_width)  # (N, T, 5)
    kinematics = kinematic_features(x[slots], y[slots], yaw[slots], config.dt)  # (E, T)
    speed_valid = central_valid(valid[slots])
    accel_valid = central_valid(speed_valid)
    all_speed = jnp.hypot(central_difference(x), central_difference(y)) / config.dt  # (N, T)
    nearest = distance_to_nearest_object(boxes, valid, slots, config)
    ttc = time_to_collision(boxes, all_speed, valid, slots, config)
    edge = distance_to_road_edge(state.map_index, boxes[slots])
    future = slice(now + 1, None)
    own_valid = valid[slots]
    features = {**kinematics, "distance_to_nearest_object": nearest, "collision_indication": nearest < 0.0,
                "time_to_collision": ttc, "distance_to_road_edge": edge, "offroad_indication": edge > 0.0}
    validity = {name: own_valid for name in features}
    validity.update(linear_speed=speed_valid, angular_speed=speed_valid, linear_acceleration=accel_valid,
                    angular_acceleration=accel_valid)
    return ({name: value[:, future] for name, value in features.items()},
            {name: value[:, future] for name, value in validity.items()})


# ----------------------------------------------------------------------------- one scene


def scene_likelihoods(log_features: dict, log_valid: dict, sim_features: dict, sim_valid: dict,
                      object_valid: jax.Array, config: RealismConfig, copies: int = 1) -> dict:
    """Each feature's likelihood in [0, 1] (exp of the mean log-likelihood, as WOSAC aggregates them) and the
    meta-metric. Histogram features: mean over the (object, step) pairs valid in the log. Bernoulli features:
    per object "at some step valid in the log", mean over objects. Simulated samples count where the rollout is
    valid (times `copies`). log_* name -> (E, F); sim_* name -> (R, E, F); object_valid (E,) the evaluated
    slots in use. -> name -> () float32 (NaN when no step of the scene can score that feature)."""
    out = {}
    for name, feature in config.features:
        log_mask = log_valid[name] & object_valid[:, None]
        sim_weight = (sim_valid[name] & object_valid[None, :, None]).astype(jnp.float32) * copies
        if feature.kind == "bernoulli":
            happened_log = jnp.any(log_features[name] & log_mask, axis=-1)  # (E,)
            # a simulated event counts only at steps the log has the object (WOSAC masks by log validity)
            happened_sim = jnp.any(sim_features[name] & sim_valid[name] & log_mask[None], axis=-1)  # (R, E)
            weight = (jnp.any(sim_weight > 0, axis=-1)).astype(jnp.float32) * copies  # (R, E)
            ll = bernoulli_log_likelihood(happened_log[:, None], happened_sim.T, weight.T, feature)[:, 0]
            scored = object_valid & jnp.any(log_mask, axis=-1)
            out[name] = jnp.exp(masked_mean(ll, scored))
        else:
            ll = timeseries_log_likelihood(log_features[name], sim_features[name], sim_weight, feature)
            out[name] = jnp.exp(masked_mean(ll, log_mask))
    out["metametric"] = metametric(out, config)
    return out


def metametric(likelihoods: dict, config: RealismConfig) -> jax.Array:
    """Sum of weight x likelihood over the features. () float32"""
    return sum(feature.weight * likelihoods[name] for name, feature in config.features)


def scene_realism(state: SimulatorState, sim: SimTrajectories, slots: jax.Array, slot_valid: jax.Array,
                  config: RealismConfig = RealismConfig()) -> dict:
    """Likelihoods, meta-metric and rollout statistics of one scene (jittable).

    state: the scene as loaded (its log and map index). sim: the rollouts (R, N, T). slots (E,) / slot_valid (E,):
    the evaluated objects (`realism_rollouts.evaluated_objects`). Besides the likelihoods: "collision_rate" and
    "offroad_rate" (share of evaluated objects x rollouts with the event), "ade" (mean distance to the log over
    valid future steps) and "min_ade" (ADE of the best rollout). -> name -> () float32"""
    log = state.log_trajectory
    log_features, log_valid = scene_features(state, log.x, log.y, log.yaw, log.valid, slots, config)
    sim_features, sim_valid = jax.vmap(lambda x, y, yaw, valid: scene_features(state, x, y, yaw, valid, slots,
                                                                               config))(sim.x, sim.y, sim.yaw,
                                                                                        sim.valid)
    out = scene_likelihoods(log_features, log_valid, sim_features, sim_valid, slot_valid, config, sim.copies)
    future = slice(config.current_timestep + 1, None)
    log_future = log.valid[slots][:, future] & slot_valid[:, None]  # (E, F)
    for name, key in (("collision_indication", "collision_rate"), ("offroad_indication", "offroad_rate")):
        event = jnp.any(sim_features[name] & sim_valid[name] & log_future[None], axis=-1)  # (R, E)
        out[key] = masked_mean(event.astype(jnp.float32), jnp.broadcast_to(slot_valid, event.shape))
    error = jnp.hypot(sim.x[:, slots] - log.x[slots], sim.y[:, slots] - log.y[slots])[..., future]  # (R, E, F)
    per_rollout = jax.vmap(lambda e: masked_mean(e, log_future))(error)  # (R,)
    out["ade"] = jnp.mean(per_rollout)
    out["min_ade"] = jnp.min(per_rollout)
    return out


def aggregate_scenes(per_scene: dict, config: RealismConfig = RealismConfig()) -> dict:
    """Dataset values: the mean over scenes of each value (scenes where a feature cannot be scored are left
    out of that feature's mean); the meta-metric is recomputed from the feature means (equal to the mean of
    the scenes' meta-metrics when every scene scores every feature), and the bucket scores are the weighted
    means of their features, as WOSAC's leaderboard shows. per_scene: name -> (S,) numpy -> name -> float"""
    import numpy as np

    out = {}
    for name, values in per_scene.items():
        values = np.asarray(values, np.float64)
        finite = values[np.isfinite(values)]
        out[name] = float(finite.mean()) if finite.size else float("nan")
    out["metametric"] = float(sum(f.weight * out[name] for name, f in config.features))
    for bucket, names in BUCKETS.items():
        weights = [config.feature(name).weight for name in names]
        out[bucket] = float(sum(w * out[n] for w, n in zip(weights, names)) / sum(weights))
    return out


__all__ = ["BUCKETS", "CHALLENGE_2024", "FEATURE_NAMES", "FeatureConfig", "RealismConfig", "SimTrajectories",
           "aggregate_scenes", "bernoulli_log_likelihood", "distance_to_nearest_object", "distance_to_road_edge",
           "histogram_log_likelihood", "kinematic_features", "log_trajectories", "metametric",
           "rectangle_signed_distance", "rounded_box_distance", "scene_features", "scene_likelihoods",
           "scene_realism", "time_to_collision", "timeseries_log_likelihood"]

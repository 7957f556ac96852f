"""SDC-frame, normalised, fixed-shape observation features with validity masks."""

from __future__ import annotations

import flax.struct
import jax
import jax.numpy as jnp

from scenariomax.schema import (
    TL_ARROW_CAUTION,
    TL_ARROW_GO,
    TL_CAUTION,
    TL_FLASHING_CAUTION,
    TL_GO,
)
from vmax_sim.geometry.boxes import boxes_overlap
from vmax_sim.geometry.reductions import argmin_packed
from vmax_sim.geometry.segments import point_segment_distance, side_of_segment
from vmax_sim.geometry.transforms import to_local_points, to_local_vectors, vector_length
from vmax_sim.map_index.query import PathProjection, observation_points, project_on_paths
from vmax_sim.map_index.structure import MapIndex
from vmax_sim.metrics.config import DEFAULT_METRICS_CONFIG
from vmax_sim.observation.config import DEFAULT_OBSERVATION_CONFIG, ObservationConfig

NUM_OBJECT_TYPES = 4  # vehicle, pedestrian, cyclist, other (enum 1..4)
OBJECT_FEATURES = 8 + NUM_OBJECT_TYPES  # x, y, vx, vy, cos, sin, length, width, type one-hot
ROADGRAPH_FEATURES = 5 + 3  # x, y, dir x, dir y, speed limit, edge / lane / line one-hot
LIGHT_STATES = ("red", "yellow", "green", "unknown")  # the order of the lights' state one-hot
LIGHT_FEATURES = 2 + len(LIGHT_STATES)  # x, y, state one-hot
SDC_FEATURES = 6  # x, y, vx, vy, cos, sin; + length, width with `ObservationConfig.sdc_size`
ROUTE_FRAME_FEATURES = 2  # along the SDC's route, across it (`ObservationConfig.object_route_frame`)
ROUTE_ACROSS_SCALE = 5.0  # m; offsets across the route are divided by it (a lane is ~3.5 m wide)...
ROUTE_ACROSS_CLIP = 4.0  # ...and clipped to +-4 (20 m): further off, only "far off the route" matters


def sdc_feature_count(config: ObservationConfig) -> int:
    """The width of `Observation.sdc`'s last axis under `config`."""
    return SDC_FEATURES + (2 if config.sdc_size else 0)


def object_feature_count(config: ObservationConfig) -> int:
    """The width of `Observation.objects`' last axis under `config`."""
    return OBJECT_FEATURES + (ROUTE_FRAME_FEATURES if config.object_route_frame else 0)


@flax.struct.dataclass
class ObservationInputs:
    """What the observation needs at one step, as plain arrays."""

    sdc_xy: jnp.ndarray  # (k, 2) float32, SDC centre history, last = now
    sdc_yaw: jnp.ndarray  # (k,) float32
    sdc_vel: jnp.ndarray  # (k, 2) float32
    sdc_valid: jnp.ndarray  # (k,) bool
    sdc_size: jnp.ndarray  # (2,) float32, the SDC's length and width now (m)
    object_xy: jnp.ndarray  # (N, k, 2) float32, other objects' history
    object_yaw: jnp.ndarray  # (N, k) float32
    object_vel: jnp.ndarray  # (N, k, 2) float32
    object_size: jnp.ndarray  # (N, 2) float32, length and width
    object_type: jnp.ndarray  # (N,) int32, object_type enum
    object_valid: jnp.ndarray  # (N, k) bool; False for the SDC's own slot
    light_xy: jnp.ndarray  # (L, 2) float32
    light_state: jnp.ndarray  # (L,) int32
    light_valid: jnp.ndarray  # (L,) bool
    path_xy: jnp.ndarray  # (P, M, 2) float32
    path_valid: jnp.ndarray  # (P, M) bool
    path_arc: jnp.ndarray  # (P, M) float32
    path_on_route: jnp.ndarray  # (P,) bool


@flax.struct.dataclass
class Observation:
    # (k, sdc_feature_count) float32, SDC history: x, y, vx, vy, cos, sin (SDC frame, normalised) [, length, width]
    sdc: jnp.ndarray
    sdc_valid: jnp.ndarray  # (k,) bool
    objects: jnp.ndarray  # (n, k, object_feature_count) float32
    objects_valid: jnp.ndarray  # (n, k) bool
    roadgraph: jnp.ndarray  # (m, ROADGRAPH_FEATURES) float32
    roadgraph_valid: jnp.ndarray  # (m,) bool
    lights: jnp.ndarray  # (num_lights, LIGHT_FEATURES) float32
    lights_valid: jnp.ndarray  # (num_lights,) bool
    path_targets: jnp.ndarray  # (num_path_targets, 2) float32
    path_targets_valid: jnp.ndarray  # (num_path_targets,) bool


def _heading_features(xy, vel, yaw, origin, origin_yaw, config: ObservationConfig):
    """x, y, vx, vy, cos, sin in the SDC frame, normalised. (..., 2), (..., 2), (...,) -> (..., 6)."""
    local = to_local_points(xy, origin, origin_yaw) / config.max_distance
    local_vel = to_local_vectors(vel, origin_yaw) / config.max_speed
    rel_yaw = yaw - origin_yaw
    return jnp.concatenate([local, local_vel, jnp.cos(rel_yaw)[..., None], jnp.sin(rel_yaw)[..., None]], -1)


def nearest_objects(sdc_xy: jnp.ndarray, object_xy: jnp.ndarray, valid: jnp.ndarray,
                    num: int) -> tuple[jnp.ndarray, jnp.ndarray]:
    """The `num` valid objects nearest the SDC now (padded when there are fewer slots).

    (2,), (N, 2), (N,) -> indices (num,) int32, valid (num,) bool.
    """
    return lowest_ranked(jnp.where(valid, vector_length(object_xy - sdc_xy), jnp.inf), num)


def lowest_ranked(rank: jnp.ndarray, num: int) -> tuple[jnp.ndarray, jnp.ndarray]:
    """The `num` entries of lowest finite rank, padded when there are fewer. (N,) -> (num,) int32, (num,) bool."""
    k = min(num, rank.shape[0])
    neg, idx = jax.lax.top_k(-rank, k)
    return (jnp.pad(idx.astype(jnp.int32), (0, num - k)), jnp.pad(jnp.isfinite(neg), (0, num - k)))


def route_first_objects(inputs: ObservationInputs, targets: jnp.ndarray, targets_valid: jnp.ndarray,
                        config: ObservationConfig) -> tuple[jnp.ndarray, jnp.ndarray]:
    """The `config.num_objects` slots filled first with the valid objects within `route_corridor_m` of the route
    ahead (the polyline from the SDC through its first `route_near_targets` targets), now or, for those ahead of the
    SDC, at one of the `route_forecast_times` at their present velocity, nearest first, then with the nearest others;
    then `route_far_slots` more with the nearest on-route objects along all the targets not chosen.

    targets (T, 2) SDC-frame normalised route points, targets_valid (T,) -> indices (n,) int32, valid (n,) bool.
    """
    origin, origin_yaw = inputs.sdc_xy[-1], inputs.sdc_yaw[-1]
    local = to_local_points(inputs.object_xy[:, -1], origin, origin_yaw)  # (N, 2) m
    dist = vector_length(local)
    valid = inputs.object_valid[:, -1]
    near = config.route_near_targets
    on_route = objects_on_route(local, targets[:near], targets_valid[:near], config)  # (N,)
    on_route = on_route | objects_heading_onto_route(inputs, targets[:near], targets_valid[:near], config)
    # on-route objects rank before every other (distances are far below the offset); invalid ones last
    chosen = lowest_ranked(jnp.where(valid, dist - jnp.where(on_route, 1e6, 0.0), jnp.inf), config.num_objects)
    if not config.route_far_slots:
        return chosen
    taken = jnp.zeros(dist.shape, bool).at[chosen[0]].max(chosen[1])  # (N,)
    far = valid & ~taken & objects_on_route(local, targets, targets_valid, config)
    extra = lowest_ranked(jnp.where(far, dist, jnp.inf), config.route_far_slots)
    return jnp.concatenate([chosen[0], extra[0]]), jnp.concatenate([chosen[1], extra[1]])


def objects_on_route(local: jnp.ndarray, targets: jnp.ndarray, targets_valid: jnp.ndarray,
              config: ObservationConfig) -> jnp.ndarray:
    """Whether each object (N, 2) m, SDC frame, lies within `route_corridor_m` of the route through `targets`. (N,)"""
    points, seg_valid = route_polyline(targets, targets_valid, config)
    to_route = point_segment_distance(local[:, None], points[None, :-1], points[None, 1:])  # (N, T)
    return jnp.any((to_route <= config.route_corridor_m) & seg_valid[None], axis=1)


def objects_heading_onto_route(inputs: ObservationInputs, targets: jnp.ndarray, targets_valid: jnp.ndarray,
                               config: ObservationConfig) -> jnp.ndarray:
    """Whether each object ahead of the SDC lies on the route through `targets` at one of `route_forecast_times`,
    moving at its present velocity: a car crossing into the route before it is in the way. Objects behind are left
    out (a follower's forecast runs up the route behind the SDC). (N,)"""
    num = inputs.object_xy.shape[0]
    if not config.route_forecast_times:
        return jnp.zeros(num, bool)
    origin, origin_yaw = inputs.sdc_xy[-1], inputs.sdc_yaw[-1]
    times = jnp.asarray(config.route_forecast_times, jnp.float32)[:, None, None]  # (K, 1, 1) s
    forecast = inputs.object_xy[None, :, -1] + times * inputs.object_vel[None, :, -1]  # (K, N, 2) m, world frame
    # every forecast position against the route at once: one route polyline, not one per time
    on_route = objects_on_route(to_local_points(forecast.reshape(-1, 2), origin, origin_yaw), targets, targets_valid,
                                config).reshape(-1, num)  # (K, N)
    ahead = to_local_points(inputs.object_xy[:, -1], origin, origin_yaw)[:, 0] > 0.0
    return on_route.any(axis=0) & ahead


def route_polyline(targets: jnp.ndarray, targets_valid: jnp.ndarray,
                   config: ObservationConfig) -> tuple[jnp.ndarray, jnp.ndarray]:
    """The SDC's route ahead as a polyline from the SDC (the origin) through its path targets.

    targets (T, 2) SDC-frame normalised, targets_valid (T,) -> points (T + 1, 2) m, segment valid (T,).
    """
    points = jnp.concatenate([jnp.zeros((1, 2)), targets * config.max_distance])
    return points, jnp.concatenate([targets_valid[:1], targets_valid[:-1] & targets_valid[1:]])


def object_features(inputs: ObservationInputs, indices: jnp.ndarray, index_valid: jnp.ndarray,
                    config: ObservationConfig, targets: jnp.ndarray | None = None,
                    targets_valid: jnp.ndarray | None = None):
    """(n, k, object_feature_count) features and (n, k) validity of the chosen objects; with
    `config.object_route_frame`, `targets` / `targets_valid` (the path targets) give the route they are read along."""
    origin, origin_yaw = inputs.sdc_xy[-1], inputs.sdc_yaw[-1]
    xy, vel, yaw = inputs.object_xy[indices], inputs.object_vel[indices], inputs.object_yaw[indices]
    valid = inputs.object_valid[indices] & index_valid[:, None]
    motion = _heading_features(xy, vel, yaw, origin, origin_yaw, config)
    size = jnp.broadcast_to(inputs.object_size[indices][:, None] / config.max_size, xy.shape)
    one_hot = jax.nn.one_hot(inputs.object_type[indices] - 1, NUM_OBJECT_TYPES)
    one_hot = jnp.broadcast_to(one_hot[:, None], xy.shape[:2] + (NUM_OBJECT_TYPES,))
    parts = [motion, size, one_hot]
    if config.object_route_frame:
        along, across = route_frame(to_local_points(xy, origin, origin_yaw), targets, targets_valid, config)
        parts.append(jnp.stack([along / config.max_distance,
                                jnp.clip(across / ROUTE_ACROSS_SCALE, -ROUTE_ACROSS_CLIP, ROUTE_ACROSS_CLIP)], -1))
    feats = jnp.concatenate(parts, -1)
    return jnp.where(valid[..., None], feats, 0.0), valid


def route_frame(local: jnp.ndarray, targets: jnp.ndarray, targets_valid: jnp.ndarray,
                config: ObservationConfig) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Where points lie along the SDC's route ahead (the polyline from the SDC through its path targets) and across
    it: the per-object MLP cannot tell from x, y alone whether a car on a bend or across a junction is in the SDC's
    way, which its teacher reads along the route. The first segment reaches back behind the SDC and the last valid
    one on past the route's end; with no target, the route is the SDC's heading.

    local (..., 2) SDC-frame m; targets (T, 2) normalised, targets_valid (T,) -> along (...,) m, across (...,) m
    (left of the route > 0).
    """
    points, seg_valid = route_polyline(targets, targets_valid, config)  # (T + 1, 2), (T,)
    heading = jnp.array([config.path_target_spacing, 0.0])  # no first target: the first segment along the heading
    points = points.at[1].set(jnp.where(targets_valid[0], points[1], heading))
    seg_valid = seg_valid.at[0].set(True)
    start, seg = points[:-1], points[1:] - points[:-1]  # (T, 2)
    length = jnp.maximum(vector_length(seg), 1e-6)  # (T,)
    rel = local[..., None, :] - start  # (..., T, 2)
    t = jnp.sum(rel * seg, -1) / jnp.square(length)  # (..., T)
    index = jnp.arange(seg_valid.shape[0])
    last = jnp.max(jnp.where(seg_valid, index, 0))
    t = jnp.clip(t, jnp.where(index == 0, -jnp.inf, 0.0), jnp.where(index == last, jnp.inf, 1.0))
    gap = jnp.where(seg_valid, vector_length(rel - t[..., None] * seg), jnp.inf)  # (..., T)
    nearest = jnp.argmin(gap, -1)[..., None]  # (..., 1)
    start_arc = jnp.cumsum(length) - length  # (T,) m along the route at each segment's start

    def pick(a):  # (..., T) -> (...,)
        return jnp.take_along_axis(a, nearest, -1)[..., 0]

    along = pick(start_arc + t * length)
    across = pick(side_of_segment(local[..., None, :], start, points[1:]) / length)
    return along, across


def compact(valid: jnp.ndarray, num: int) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Slots for up to `num` of the valid entries, evenly thinned when there are more (no sort).

    valid (M,) -> source index per output slot (num,) int32, slot valid (num,) bool.
    """
    count = jnp.sum(valid)
    stride = jnp.maximum((count + num - 1) // num, 1)
    rank = jnp.cumsum(valid) - 1
    keep = valid & (rank % stride == 0)
    kept_before = jnp.cumsum(keep)  # non-decreasing: output slot j takes the first entry with j + 1 kept
    slots = jnp.arange(num, dtype=kept_before.dtype)
    source = jnp.searchsorted(kept_before, slots, side="right", method="scan_unrolled").astype(jnp.int32)
    filled = slots < kept_before[-1]
    return jnp.minimum(source, valid.shape[0] - 1), filled


def _point_transform(sdc_xy: jnp.ndarray, sdc_yaw: jnp.ndarray, config: ObservationConfig):
    """Affine map of MapIndex.obs_points rows into the normalised SDC frame: rows @ m + b."""
    cos, sin = jnp.cos(sdc_yaw), jnp.sin(sdc_yaw)
    rot = jnp.array([[cos, -sin], [sin, cos]])  # row vector @ rot = world -> SDC frame
    m = jnp.zeros((8, 8), jnp.float32)
    m = m.at[:2, :2].set(rot / config.max_distance).at[2:4, 2:4].set(rot)
    m = m.at[4, 4].set(1.0 / config.max_speed).at[5, 5].set(1.0).at[6, 6].set(1.0).at[7, 7].set(1.0)
    b = jnp.zeros(8, jnp.float32).at[:2].set(-(sdc_xy @ rot) / config.max_distance)
    return m, b


def roadgraph_features(map_index: MapIndex, sdc_xy: jnp.ndarray, sdc_yaw: jnp.ndarray,
                       config: ObservationConfig):
    """Map points inside the box ahead of the SDC, from the observation cells around the box
    centre (no full-roadgraph top_k). -> (m, ROADGRAPH_FEATURES), (m,) valid, where m is
    config.num_roadgraph_points or all window points."""
    shift = 0.5 * (config.roadgraph_front - config.roadgraph_back)
    box_centre = sdc_xy + shift * jnp.stack([jnp.cos(sdc_yaw), jnp.sin(sdc_yaw)])
    pts = observation_points(map_index, box_centre, config.roadgraph_window)
    m, b = _point_transform(sdc_xy, sdc_yaw, config)
    feats = pts.features @ m + b  # (M, 8)
    lx, ly = feats[:, 0] * config.max_distance, feats[:, 1] * config.max_distance
    in_box = ((lx <= config.roadgraph_front) & (lx >= -config.roadgraph_back)
              & (jnp.abs(ly) <= config.roadgraph_side))
    # the type set is a union of the edge / lane / line groups: read it off the one-hot columns
    groups = {"edges": (5,), "edges+lanes": (5, 6), "edges+lanes+lines": (5, 6, 7)}[config.roadgraph_types]
    wanted = sum(feats[:, col] for col in groups) > 0.5
    valid = pts.valid & in_box & wanted
    if config.num_roadgraph_points is not None:
        source, valid = compact(valid, config.num_roadgraph_points)
        feats = feats[source]
    return jnp.where(valid[:, None], feats, 0.0), valid


def light_features(inputs: ObservationInputs, config: ObservationConfig):
    """The closest traffic lights with their state. -> (num_lights, LIGHT_FEATURES), (num_lights,)."""
    origin, origin_yaw = inputs.sdc_xy[-1], inputs.sdc_yaw[-1]
    dist = jnp.where(inputs.light_valid, vector_length(inputs.light_xy - origin), jnp.inf)
    num = min(config.num_lights, dist.shape[0])
    neg, idx = jax.lax.top_k(-dist, num)
    state = inputs.light_state[idx]
    red = jnp.isin(state, jnp.asarray(DEFAULT_METRICS_CONFIG.red_light_states))
    yellow = jnp.isin(state, jnp.asarray((TL_CAUTION, TL_ARROW_CAUTION, TL_FLASHING_CAUTION)))
    green = jnp.isin(state, jnp.asarray((TL_GO, TL_ARROW_GO)))
    masks = {"red": red, "yellow": yellow, "green": green, "unknown": ~(red | yellow | green)}
    feats = jnp.concatenate([to_local_points(inputs.light_xy[idx], origin, origin_yaw) / config.max_distance,
                             jnp.stack([masks[name] for name in LIGHT_STATES], -1).astype(jnp.float32)], -1)
    valid = jnp.isfinite(neg)
    feats = jnp.where(valid[:, None], feats, 0.0)
    pad = config.num_lights - num
    return jnp.pad(feats, ((0, pad), (0, 0))), jnp.pad(valid, (0, pad))


def path_targets(inputs: ObservationInputs, config: ObservationConfig, projection: PathProjection | None = None,
                 count: int | None = None):
    """Points every `path_target_spacing` m ahead along the on-route path nearest the SDC.

    projection: the SDC's `project_on_paths` result when already computed (the metrics have it).
    count: how many points (default `num_path_targets`); each point does not depend on how many are taken.
    -> (count, 2) SDC-frame normalised, (count,) valid.
    """
    origin, origin_yaw = inputs.sdc_xy[-1], inputs.sdc_yaw[-1]
    proj = projection or project_on_paths(inputs.path_xy, inputs.path_valid, inputs.path_arc, origin)
    usable = jnp.any(inputs.path_valid, axis=1) & inputs.path_on_route
    route = argmin_packed(jnp.where(usable, proj.distance, jnp.inf))
    pxy, pvalid, parc = inputs.path_xy[route], inputs.path_valid[route], inputs.path_arc[route]
    big = jnp.finfo(jnp.float32).max
    arc = jnp.where(pvalid, parc, big)
    count = config.num_path_targets if count is None else count
    targets = proj.arc[route] + config.path_target_spacing * (1 + jnp.arange(count))
    hi = jnp.clip(jnp.searchsorted(arc, targets), 1, arc.shape[0] - 1)
    lo = hi - 1
    frac = jnp.clip((targets - arc[lo]) / jnp.maximum(arc[hi] - arc[lo], 1e-6), 0.0, 1.0)
    xy = pxy[lo] + frac[:, None] * (pxy[hi] - pxy[lo])
    valid = usable[route] & (targets <= jnp.max(jnp.where(pvalid, parc, -big))) & pvalid[lo] & pvalid[hi]
    local = to_local_points(xy, origin, origin_yaw) / config.max_distance
    return jnp.where(valid[:, None], local, 0.0), valid


def apply_noise(key: jax.Array, inputs: ObservationInputs, indices: jnp.ndarray, index_valid: jnp.ndarray,
                config: ObservationConfig) -> tuple[ObservationInputs, jnp.ndarray]:
    """Gaussian position noise, distance-based dropout and line-of-sight occlusion of the chosen
    objects. -> noisy inputs, (n,) bool visibility of the chosen objects."""
    noise = config.noise
    key_pos, key_drop = jax.random.split(key)
    xy = inputs.object_xy + noise.position_std * jax.random.normal(key_pos, inputs.object_xy.shape)
    origin = inputs.sdc_xy[-1]
    now = inputs.object_xy[indices, -1]
    dist = vector_length(now - origin)
    ramp = jnp.clip((dist - noise.dropout_start) / max(config.max_distance - noise.dropout_start, 1e-3), 0.0, 1.0)
    visible = jax.random.uniform(key_drop, dist.shape) >= noise.dropout_max_prob * ramp
    if noise.occlusion:
        boxes = jnp.concatenate([now, inputs.object_size[indices], inputs.object_yaw[indices, -1:]], -1)
        valid_now = inputs.object_valid[indices, -1] & index_valid
        # sight line to each object as a zero-width box, tested against every nearer object
        mid, delta = 0.5 * (origin + now), now - origin
        sight = jnp.concatenate([mid, vector_length(delta)[:, None],
                                 jnp.full_like(dist[:, None], 1e-3),
                                 jnp.arctan2(delta[:, 1], delta[:, 0])[:, None]], -1)
        blocks = boxes_overlap(sight[:, None], boxes[None]) & valid_now[None] & (dist[None] < dist[:, None])
        visible = visible & ~jnp.any(blocks, axis=1)
    return inputs.replace(object_xy=xy), visible


def light_row(local_xy_m: tuple[float, float], state: str, max_distance: float) -> jnp.ndarray:
    """One light's features as light_features writes them: at local_xy_m (SDC frame, m) in `state` (one of
    LIGHT_STATES); max_distance the observation's position scale (m). -> (LIGHT_FEATURES,)"""
    one_hot = jnp.zeros(len(LIGHT_STATES)).at[LIGHT_STATES.index(state)].set(1.0)
    return jnp.concatenate([jnp.asarray(local_xy_m, jnp.float32) / max_distance, one_hot])


def observed_sdc_speed(sdc: jnp.ndarray) -> jnp.ndarray:
    """The SDC's speed now as its observation shows it, in the observation's units (m/s over max_speed):
    sdc (..., k, F), `Observation.sdc` -> (...)."""
    return jnp.linalg.norm(sdc[..., -1, 2:4].astype(jnp.float32), axis=-1)


def observe(map_index: MapIndex, inputs: ObservationInputs, config: ObservationConfig = DEFAULT_OBSERVATION_CONFIG,
            key: jax.Array | None = None, candidates: tuple[jnp.ndarray, jnp.ndarray] | None = None,
            path_projection: PathProjection | None = None) -> Observation:
    """Build the observation of one scene at one step (vmap for batches).

    candidates (indices (n,), valid (n,)) may pass the objects already chosen for the metrics
    (`vmax_sim.metrics.shared_queries`) so both share one selection; otherwise the n nearest (with
    `object_selection="nearest"`; "route" always makes its own choice, `route_first_objects`).
    path_projection may pass the SDC's projection on the paths the metrics computed.
    key drives the optional perception noise.
    """
    # one pass along the route: the path targets are the first num_path_targets of the points the route-first slots
    # read out to route_selection_m
    shown, reach = config.num_path_targets, config.route_selection_targets
    route_xy, route_valid = path_targets(inputs, config, path_projection, max(shown, reach))
    targets, targets_valid = route_xy[:shown], route_valid[:shown]
    if config.object_selection == "route":  # its own choice: the metrics' candidates are the nearest
        candidates = route_first_objects(inputs, route_xy[:reach], route_valid[:reach], config)
    elif candidates is None:
        candidates = nearest_objects(inputs.sdc_xy[-1], inputs.object_xy[:, -1], inputs.object_valid[:, -1],
                                     config.num_objects)
    indices, index_valid = candidates
    noise = config.noise
    if key is not None and noise.on_objects:
        inputs, visible = apply_noise(key, inputs, indices, index_valid, config)
        index_valid = index_valid & visible
    objects, objects_valid = object_features(inputs, indices, index_valid, config, targets, targets_valid)
    origin, origin_yaw = inputs.sdc_xy[-1], inputs.sdc_yaw[-1]
    sdc = _heading_features(inputs.sdc_xy, inputs.sdc_vel, inputs.sdc_yaw, origin, origin_yaw, config)
    if config.sdc_size:  # the car's own box, so one student can keep the margins of cars of every size
        size = jnp.broadcast_to(inputs.sdc_size / config.max_size, sdc.shape[:-1] + (2,))
        sdc = jnp.concatenate([sdc, size], -1)
    sdc_valid = inputs.sdc_valid
    if config.sdc_history is not None:  # the older steps hidden, as if never recorded
        sdc_valid = sdc_valid & (jnp.arange(sdc_valid.shape[0]) >= sdc_valid.shape[0] - config.sdc_history)
    if key is not None and noise.sdc_history_dropout > 0:  # the past hidden at a fresh share of the steps
        hide_past = jax.random.uniform(jax.random.fold_in(key, 3)) < noise.sdc_history_dropout
        sdc_valid = sdc_valid & ~(hide_past & (jnp.arange(sdc_valid.shape[0]) < sdc_valid.shape[0] - 1))
    roadgraph, roadgraph_valid = roadgraph_features(map_index, origin, origin_yaw, config)
    if key is not None and noise.map_dropout > 0:  # a fresh sample of the map's points every step
        shown = jax.random.uniform(jax.random.fold_in(key, 2), roadgraph_valid.shape) >= noise.map_dropout
        roadgraph_valid = roadgraph_valid & shown
        roadgraph = jnp.where(roadgraph_valid[..., None], roadgraph, 0.0)
    lights, lights_valid = light_features(inputs, config)
    return Observation(sdc=jnp.where(sdc_valid[:, None], sdc, 0.0), sdc_valid=sdc_valid,
                       objects=objects, objects_valid=objects_valid, roadgraph=roadgraph,
                       roadgraph_valid=roadgraph_valid, lights=lights, lights_valid=lights_valid,
                       path_targets=targets, path_targets_valid=targets_valid)

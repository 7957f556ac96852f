"""Per-step metrics of the scored agent (SDC) on plain arrays, and `step_metrics` which runs them all.

Every function here is jittable, works on one scene (vmap for batches) and returns float32/bool
scalars or small arrays.
"""

from __future__ import annotations

import flax.struct
import jax.numpy as jnp

from vmax_sim.geometry.boxes import box_corners
from vmax_sim.geometry.reductions import argmin_packed
from vmax_sim.geometry.transforms import vector_length, wrap_angle
from vmax_sim.map_index.query import (
    LaneCandidates,
    PathProjection,
    lane_candidates,
    nearest_lane,
    project_on_paths,
    signed_edge_distance,
)
from vmax_sim.map_index.structure import MapIndex
from vmax_sim.metrics.config import DEFAULT_METRICS_CONFIG, MetricsConfig
from vmax_sim.metrics.objects import at_fault_collisions, overlaps, select_candidates, time_to_collision


@flax.struct.dataclass
class StepInputs:
    """What the metrics need at one step, as plain arrays (the env builds it from its state)."""

    sdc_xy: jnp.ndarray  # (H, 2) float32, SDC centre at steps t-H+1 .. t (H >= 3), last = now
    sdc_yaw: jnp.ndarray  # (H,) float32, SDC heading over the same steps
    sdc_size: jnp.ndarray  # (2,) float32, SDC length and width
    sdc_log_xy: jnp.ndarray  # (2,) float32, logged SDC centre at step t
    object_boxes: jnp.ndarray  # (N, 5) float32, other objects [x, y, length, width, yaw] at t
    object_vel: jnp.ndarray  # (N, 2) float32, their velocities at t
    object_valid: jnp.ndarray  # (N,) bool, valid at t; False for the SDC's own slot
    light_xy: jnp.ndarray  # (L, 2) float32, traffic-light stop points at t
    light_lane_id: jnp.ndarray  # (L,) int32, lane each light controls
    light_state: jnp.ndarray  # (L,) int32, traffic_light_state enum at t
    light_valid: jnp.ndarray  # (L,) bool
    path_xy: jnp.ndarray  # (P, M, 2) float32, SDC paths
    path_valid: jnp.ndarray  # (P, M) bool
    path_arc: jnp.ndarray  # (P, M) float32, arc length along each path
    path_on_route: jnp.ndarray  # (P,) bool
    path_log_arc: jnp.ndarray  # (P, 2) float32, arcs of the logged start / end (`route_reference_arcs`)


@flax.struct.dataclass
class SharedQueries:
    """Per-step queries computed once and shared by the metrics and the observation."""

    candidate_index: jnp.ndarray  # (K,) int32, objects nearest the SDC (`select_candidates`)
    candidate_valid: jnp.ndarray  # (K,) bool
    path_projection: PathProjection  # the SDC projected on every path, (P,) fields


def shared_queries(inputs: StepInputs, config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> SharedQueries:
    """Choose the candidate objects and project the SDC on the paths, once per step."""
    sdc_box = sdc_box_at(inputs.sdc_xy[-1], inputs.sdc_yaw[-1], inputs.sdc_size)
    idx, valid = select_candidates(sdc_box, inputs.object_boxes, inputs.object_valid, config.num_candidates)
    proj = project_on_paths(inputs.path_xy, inputs.path_valid, inputs.path_arc, inputs.sdc_xy[-1])
    return SharedQueries(candidate_index=idx, candidate_valid=valid, path_projection=proj)


def sdc_box_at(xy: jnp.ndarray, yaw: jnp.ndarray, size: jnp.ndarray) -> jnp.ndarray:
    """[x, y, length, width, yaw]. (2,), (), (2,) -> (5,)."""
    return jnp.concatenate([xy, size, yaw[None]])


def finite_difference_motion(xy: jnp.ndarray, yaw: jnp.ndarray, dt: float) -> dict:
    """Speed, velocity, acceleration and curvature at the last of >= 3 samples. (H, 2), (H,) -> dict."""
    vel_now = (xy[-1] - xy[-2]) / dt
    vel_before = (xy[-2] - xy[-3]) / dt
    speed_now, speed_before = vector_length(vel_now), vector_length(vel_before)
    dyaw = wrap_angle(yaw[-1] - yaw[-2])
    step_len = speed_now * dt
    curvature = jnp.where(step_len > 0.05, dyaw / jnp.maximum(step_len, 1e-6), 0.0)
    return {"velocity": vel_now, "speed": speed_now, "accel": (speed_now - speed_before) / dt,
            "curvature": curvature, "yaw_rate": dyaw / dt}


def offroad(map_index: MapIndex, sdc_box: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Off-road if any corner is right of (outside) its nearest road edge (at a shared vertex, outside
    by the vertex rule of `signed_edge_distance`). -> (bool, max signed m)."""
    distance = signed_edge_distance(map_index, box_corners(sdc_box), sdc_box[:2])
    worst = jnp.max(distance)
    return worst > 0.0, worst


def route_distances(path_distance: jnp.ndarray, path_valid_any: jnp.ndarray,
                    on_route: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray, jnp.ndarray]:
    """Nearest distance to any path, to on-route paths, to off-route paths. (P,) x3 -> 3 x ()."""
    d = jnp.where(path_valid_any, path_distance, jnp.inf)
    return jnp.min(d), jnp.min(jnp.where(on_route, d, jnp.inf)), jnp.min(jnp.where(on_route, jnp.inf, d))


def wrong_way(nearest_path_distance: jnp.ndarray, threshold: float) -> jnp.ndarray:
    """Waymax wrong-way: further than `threshold` from every SDC path (False without paths)."""
    return jnp.isfinite(nearest_path_distance) & (nearest_path_distance > threshold)


def off_route(on_route_distance, off_route_distance, max_distance: float, max_relative: float):
    """Waymax off-route: far from the route, or clearly closer to an off-route path. () -> bool."""
    far = jnp.isfinite(on_route_distance) & (on_route_distance > max_distance)
    closer_elsewhere = (on_route_distance - off_route_distance) > max_relative
    return far | (jnp.isfinite(on_route_distance) & closer_elsewhere)


def speed_violation(speed: jnp.ndarray, speed_limit: jnp.ndarray) -> jnp.ndarray:
    """nuPlan per-step overspeed max(0, speed - limit); 0 where the limit is unknown (< 0)."""
    return jnp.where(speed_limit > 0.0, jnp.maximum(speed - speed_limit, 0.0), 0.0)


BOUNDARY_TOLERANCE_M = 0.3


def on_multiple_lanes(lanes: LaneCandidates, sdc_xy: jnp.ndarray, sdc_yaw: jnp.ndarray, sdc_width,
                      lane_half_width: float, max_angle_deg: float) -> jnp.ndarray:
    """True when the SDC's box straddles the boundary between two side-by-side lanes.

    Without lane polygons, the boundary between two adjacent parallel centrelines is taken halfway
    between them, so the rule uses the map's real lane spacing (real lanes are often narrower than
    the standard 3.7 m). The adjacent lanes are the nearest parallel centrelines more than 1 m to each
    side of the SDC's own lane (segments of one lane line up and never pair), at most
    3.2 * lane_half_width away. The SDC straddles when its box crosses a boundary
    by more than BOUNDARY_TOLERANCE_M (the midpoint is only an estimate of the painted line).
    """
    cos, sin = jnp.cos(sdc_yaw), jnp.sin(sdc_yaw)
    parallel = jnp.abs(lanes.dir_x * cos + lanes.dir_y * sin) > jnp.cos(jnp.deg2rad(max_angle_deg))
    near = lanes.valid & parallel & (lanes.distance < 3.2 * lane_half_width + 0.5 * sdc_width)
    offset = (lanes.closest_y - sdc_xy[1]) * cos - (lanes.closest_x - sdc_xy[0]) * sin  # (K,) to the SDC's left
    own = argmin_packed(jnp.where(near, jnp.abs(offset), jnp.inf))  # the lane the SDC's centre is in
    own_offset = offset[own]
    # The adjacent lanes: the nearest centrelines on each side of the SDC's own lane.
    left = jnp.min(jnp.where(near & (offset > own_offset + 1.0), offset, jnp.inf))
    right = jnp.max(jnp.where(near & (offset < own_offset - 1.0), offset, -jnp.inf))
    max_spacing = 3.2 * lane_half_width
    reach = 0.5 * sdc_width - BOUNDARY_TOLERANCE_M
    crosses_left = (left - own_offset < max_spacing) & (jnp.abs(0.5 * (own_offset + left)) < reach)
    crosses_right = (own_offset - right < max_spacing) & (jnp.abs(0.5 * (own_offset + right)) < reach)
    return jnp.any(near) & (crosses_left | crosses_right)


def red_light_violation(front_before: jnp.ndarray, front_now: jnp.ndarray, lane_id: jnp.ndarray,
                        lane_dir: jnp.ndarray, light_xy, light_lane_id, light_state, light_valid,
                        red_states: tuple[int, ...], max_lateral: float) -> jnp.ndarray:
    """The SDC's front bumper passed the stop point of a red light on the lane it drives along.

    front_* (2,), lane_id (), lane_dir (2,), light_* (L,...) -> () bool.
    """
    is_red = jnp.isin(light_state, jnp.asarray(red_states)) & light_valid & (light_lane_id == lane_id)
    ahead_before = (light_xy - front_before) @ lane_dir
    ahead_now = (light_xy - front_now) @ lane_dir
    rel = light_xy - front_now
    lateral = jnp.abs(rel[:, 0] * lane_dir[1] - rel[:, 1] * lane_dir[0])
    crossed = (ahead_before > 0.0) & (ahead_now <= 0.0) & (lateral < max_lateral)
    return jnp.any(is_red & crossed & (lane_id >= 0))


def containing_lane(lanes: LaneCandidates, yaw: jnp.ndarray, half_width: float) -> tuple[jnp.ndarray, jnp.ndarray]:
    """The lane a point is in, as nuPlan puts the ego in a lane polygon: only lanes whose centreline is within
    `half_width` of the point contain it; where several do (junction connectors crossing the lane the agent
    follows), `nearest_lane` picks the one it follows. A farther lane never wins on heading, so an agent inside
    the oncoming lane is in that lane. -> (index into the candidates () int32, found () bool).
    """
    inside = lanes.distance <= half_width  # invalid candidates are at inf
    return nearest_lane(lanes.replace(distance=jnp.where(inside, lanes.distance, jnp.inf)), yaw), jnp.any(inside)


def step_metrics(map_index: MapIndex, inputs: StepInputs, config: MetricsConfig = DEFAULT_METRICS_CONFIG,
                 shared: SharedQueries | None = None) -> dict[str, jnp.ndarray]:
    """All per-step metrics of the SDC at one step. -> dict of () float32 arrays.

    Keys: overlap, offroad, offroad_distance, wrong_way, off_route, progress_ratio,
    log_divergence, kinematic_infeasibility, at_fault_collision, ttc, ttc_violation, speed,
    speed_limit, speed_violation, lane_progress, red_light, multiple_lanes, ego_progress,
    expert_progress, sdc_x, sdc_y, sdc_yaw (these three feed the episode's comfort metric), accel and
    yaw_rate (finite differences; the per-step comfort reward term reads them).
    vmap over a leading batch axis of both arguments for batches. `shared` (from
    `shared_queries`) lets the observation reuse the same candidate objects and path projection.
    """
    shared = shared or shared_queries(inputs, config)
    xy, yaw, size = inputs.sdc_xy[-1], inputs.sdc_yaw[-1], inputs.sdc_size
    sdc_box = sdc_box_at(xy, yaw, size)
    motion = finite_difference_motion(inputs.sdc_xy, inputs.sdc_yaw, config.dt)

    # objects: one candidate set shared by overlap, at-fault and TTC
    idx, cand_valid = shared.candidate_index, shared.candidate_valid
    boxes, vels = inputs.object_boxes[idx], inputs.object_vel[idx]
    colliding = overlaps(sdc_box, boxes, cand_valid)

    # map
    is_offroad, offroad_distance = offroad(map_index, sdc_box)
    lanes = lane_candidates(map_index, xy)
    lane_k = nearest_lane(lanes, yaw)
    lane_found = lanes.distance[lane_k] < config.lane_match_distance
    lane_id = jnp.where(lane_found, lanes.lane_id[lane_k], -1)
    speed_limit = jnp.where(lane_found, lanes.speed_limit[lane_k], -1.0)
    # driving direction (nuPlan): progress along the lane the SDC's centre is in, none when it is in no lane. A
    # connector crossing its lane in a junction is not its lane; an oncoming lane it drives in is (the only one)
    own_k, in_lane = containing_lane(lanes, yaw, config.lane_half_width)
    lane_progress = jnp.where(in_lane, (inputs.sdc_xy[-1] - inputs.sdc_xy[-2])
                              @ jnp.stack([lanes.dir_x[own_k], lanes.dir_y[own_k]]), 0.0)
    multiple = on_multiple_lanes(lanes, xy, yaw, size[1], config.lane_half_width, config.lane_max_angle_deg)

    fault = at_fault_collisions(sdc_box, motion["speed"], boxes, vector_length(vels), colliding,
                                multiple, is_offroad, config.stopped_speed)
    ttc = time_to_collision(sdc_box, motion["velocity"], boxes, vels, cand_valid, config.ttc_threshold)
    ttc = jnp.where(motion["speed"] > config.ttc_ego_min_speed, ttc, jnp.inf)

    # routes: project the SDC on every path; the logged start / end arcs come precomputed
    proj = shared.path_projection
    path_ok = jnp.any(inputs.path_valid, axis=1)
    nearest_any, nearest_on, nearest_off = route_distances(proj.distance, path_ok, inputs.path_on_route)
    route = argmin_packed(jnp.where(path_ok & inputs.path_on_route, proj.distance, jnp.inf))
    has_route = jnp.isfinite(nearest_on)
    start_arc, end_arc = inputs.path_log_arc[route, 0], inputs.path_log_arc[route, 1]
    ego_progress = jnp.where(has_route, proj.arc[route] - start_arc, 0.0)
    expert_progress = jnp.where(has_route, end_arc - start_arc, 0.0)
    progress_ratio = jnp.where(expert_progress > config.min_expert_progress,
                               ego_progress / jnp.maximum(expert_progress, 1e-6), 1.0)

    heading_before = jnp.stack([jnp.cos(inputs.sdc_yaw[-2]), jnp.sin(inputs.sdc_yaw[-2])])
    heading_now = jnp.stack([jnp.cos(yaw), jnp.sin(yaw)])
    red = red_light_violation(inputs.sdc_xy[-2] + 0.5 * size[0] * heading_before, xy + 0.5 * size[0] * heading_now,
                              lane_id, jnp.stack([lanes.dir_x[lane_k], lanes.dir_y[lane_k]]), inputs.light_xy,
                              inputs.light_lane_id,
                              inputs.light_state, inputs.light_valid, config.red_light_states,
                              config.red_light_lateral)
    infeasible = (jnp.abs(motion["accel"]) > config.max_accel) | (jnp.abs(motion["curvature"]) > config.max_curvature)

    out = {
        "overlap": jnp.any(colliding), "offroad": is_offroad, "offroad_distance": offroad_distance,
        "wrong_way": wrong_way(nearest_any, config.wrong_way_distance),
        "off_route": off_route(nearest_on, nearest_off, config.off_route_distance,
                               config.off_route_relative_distance),
        "progress_ratio": progress_ratio,
        "log_divergence": vector_length(xy - inputs.sdc_log_xy),
        "kinematic_infeasibility": infeasible,
        "at_fault_collision": jnp.any(fault),
        "ttc": jnp.minimum(ttc, 1e3), "ttc_violation": ttc <= config.ttc_threshold,
        "speed": motion["speed"], "speed_limit": speed_limit,
        "speed_violation": speed_violation(motion["speed"], speed_limit),
        "lane_progress": lane_progress, "red_light": red, "multiple_lanes": multiple,
        "ego_progress": ego_progress, "expert_progress": expert_progress,
        "sdc_x": xy[0], "sdc_y": xy[1], "sdc_yaw": yaw,
        "accel": motion["accel"], "yaw_rate": motion["yaw_rate"],
    }
    return {k: jnp.asarray(v, jnp.float32) for k, v in out.items()}

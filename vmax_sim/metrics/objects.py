"""SDC-versus-object checks on a small candidate set chosen once per step."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.geometry.boxes import bounding_radius, boxes_overlap, contact_time
from vmax_sim.geometry.transforms import to_local_points, vector_length


def select_candidates(sdc_box: jnp.ndarray, boxes: jnp.ndarray, valid: jnp.ndarray,
                      num: int) -> tuple[jnp.ndarray, jnp.ndarray]:
    """The `num` objects whose bounding circles come closest to the SDC's.

    Shared by overlap, at-fault, TTC and the observation. Exact for overlap: a box that touches
    the SDC has a gap <= 0, so it is always among the first unless more than `num` touch.
    sdc_box (5,), boxes (N, 5), valid (N,) -> indices (num,) int32, valid (num,) bool.
    """
    gap = (vector_length(boxes[:, :2] - sdc_box[:2]) - bounding_radius(boxes)
           - bounding_radius(sdc_box))
    gap = jnp.where(valid, gap, jnp.inf)
    k = min(num, gap.shape[0])
    neg_gap, idx = jax.lax.top_k(-gap, k)
    return jnp.pad(idx.astype(jnp.int32), (0, num - k)), jnp.pad(jnp.isfinite(neg_gap), (0, num - k))


def overlaps(sdc_box: jnp.ndarray, boxes: jnp.ndarray, valid: jnp.ndarray) -> jnp.ndarray:
    """Which boxes overlap the SDC (separating-axis test). (5,), (K, 5), (K,) -> (K,) bool."""
    return boxes_overlap(sdc_box, boxes) & valid


def _bumper_box(sdc_box: jnp.ndarray, sign: float, depth: float = 0.2) -> jnp.ndarray:
    """Thin box along the front (sign=+1) or rear (sign=-1) bumper of the SDC. (5,) -> (5,)."""
    shift = sign * (0.5 * sdc_box[2] - 0.5 * depth)
    centre = sdc_box[:2] + shift * jnp.stack([jnp.cos(sdc_box[4]), jnp.sin(sdc_box[4])])
    return jnp.concatenate([centre, jnp.stack([jnp.asarray(depth, sdc_box.dtype), sdc_box[3], sdc_box[4]])])


def at_fault_collisions(sdc_box: jnp.ndarray, sdc_speed: jnp.ndarray, boxes: jnp.ndarray,
                        speeds: jnp.ndarray, colliding: jnp.ndarray, on_multiple_lanes: jnp.ndarray,
                        offroad: jnp.ndarray, stopped_speed: float) -> jnp.ndarray:
    """nuPlan at-fault rule for each colliding object. -> (K,) bool.

    A stopped ego is never at fault. Otherwise a hit on a stopped object is at fault; a hit on an
    object behind the ego (its centre more than 150 degrees off the ego's heading) never is; a
    hit with the front bumper is; a lateral hit is at fault only while the ego occupies several
    lanes (or is off the road). sdc_box (5,), sdc_speed (), boxes (K, 5), speeds (K,),
    colliding (K,), on_multiple_lanes (), offroad ().
    """
    local = to_local_points(boxes[:, :2], sdc_box[:2], sdc_box[4])
    rear = jnp.abs(jnp.arctan2(local[:, 1], local[:, 0])) > jnp.deg2rad(150.0)
    front = boxes_overlap(_bumper_box(sdc_box, 1.0), boxes) & ~rear
    lateral = ~front & ~rear
    object_stopped = speeds < stopped_speed
    fault = object_stopped | front | (lateral & (on_multiple_lanes | offroad))
    return colliding & fault & (sdc_speed >= stopped_speed)


def time_to_collision(sdc_box: jnp.ndarray, sdc_vel: jnp.ndarray, boxes: jnp.ndarray,
                      vels: jnp.ndarray, valid: jnp.ndarray, horizon: float) -> jnp.ndarray:
    """Least time to collision with objects ahead under constant velocity, exact and analytic.

    Objects already touching the SDC are left to the collision metric; objects behind the SDC's
    centre are ignored (nuPlan counts agents ahead only). Returns inf when none within horizon.
    sdc_box (5,), sdc_vel (2,), boxes (K, 5), vels (K, 2), valid (K,) -> () float32.
    """
    ahead = to_local_points(boxes[:, :2], sdc_box[:2], sdc_box[4])[:, 0] > 0.0
    t = contact_time(sdc_box, sdc_vel, boxes, vels, horizon)
    t = jnp.where(valid & ahead & (t > 0.0), t, jnp.inf)
    return jnp.min(t)

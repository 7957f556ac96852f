"""Oriented boxes: corners, separating-axis overlap, swept contact time and circle covers.

A box is a `(..., 5)` float array `[x, y, length, width, yaw]` (centre, full extents, heading).
"""

from __future__ import annotations

import jax.numpy as jnp


def box_axes(yaw: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Unit heading and left-normal vectors of boxes. (...,) -> (..., 2), (..., 2)."""
    cos, sin = jnp.cos(yaw), jnp.sin(yaw)
    return jnp.stack([cos, sin], -1), jnp.stack([-sin, cos], -1)


def box_corners(box: jnp.ndarray) -> jnp.ndarray:
    """Corners front-left, rear-left, rear-right, front-right. (..., 5) -> (..., 4, 2)."""
    heading, left = box_axes(box[..., 4])
    half_len = 0.5 * box[..., 2:3] * heading  # (..., 2)
    half_wid = 0.5 * box[..., 3:4] * left
    centre = box[..., :2]
    return jnp.stack(
        [centre + half_len + half_wid, centre - half_len + half_wid,
         centre - half_len - half_wid, centre + half_len - half_wid], axis=-2)


def bounding_radius(box: jnp.ndarray) -> jnp.ndarray:
    """Radius of the circle around the box centre that holds the whole box. (..., 5) -> (...,)."""
    return 0.5 * jnp.hypot(box[..., 2], box[..., 3])


def _half_extent_on_axis(box: jnp.ndarray, axis: jnp.ndarray) -> jnp.ndarray:
    """Half the box's shadow on a unit axis. box (..., 5), axis (..., 2) -> (...,)."""
    heading, left = box_axes(box[..., 4])
    return (0.5 * box[..., 2] * jnp.abs(jnp.sum(heading * axis, -1))
            + 0.5 * box[..., 3] * jnp.abs(jnp.sum(left * axis, -1)))


def _candidate_axes(box_a: jnp.ndarray, box_b: jnp.ndarray) -> jnp.ndarray:
    """The four separating-axis candidates of two rectangles. -> (..., 4, 2)."""
    ha, la = box_axes(box_a[..., 4])
    hb, lb = box_axes(box_b[..., 4])
    ha, la = jnp.broadcast_to(ha, hb.shape), jnp.broadcast_to(la, lb.shape)
    return jnp.stack([ha, la, hb, lb], axis=-2)


def boxes_overlap(box_a: jnp.ndarray, box_b: jnp.ndarray) -> jnp.ndarray:
    """True where two oriented boxes overlap (touching counts as not overlapping).

    Separating-axis test on the 4 edge normals. box_a, box_b broadcast: (..., 5) -> (...,) bool.
    """
    box_a, box_b = jnp.broadcast_arrays(box_a, box_b)
    axes = _candidate_axes(box_a, box_b)  # (..., 4, 2)
    gap = jnp.abs(jnp.sum((box_b[..., None, :2] - box_a[..., None, :2]) * axes, -1))
    reach = (_half_extent_on_axis(box_a[..., None, :], axes)
             + _half_extent_on_axis(box_b[..., None, :], axes))
    return jnp.all(gap < reach, axis=-1)


def contact_time(box_a: jnp.ndarray, vel_a: jnp.ndarray, box_b: jnp.ndarray, vel_b: jnp.ndarray,
                 horizon: float) -> jnp.ndarray:
    """First time in [0, horizon] at which two boxes moving at constant velocity touch, else inf.

    Continuous separating-axis test: on each axis the projected gap changes linearly in time, so
    the boxes overlap on the intersection of four closed-form time intervals (exact for
    translation without rotation, as in nuPlan's constant-velocity projection). Boxes that already
    overlap give 0. box (..., 5), vel (..., 2) -> (...,) float32.
    """
    box_a, box_b = jnp.broadcast_arrays(box_a, box_b)
    axes = _candidate_axes(box_a, box_b)  # (..., 4, 2)
    offset = jnp.sum((box_b[..., None, :2] - box_a[..., None, :2]) * axes, -1)  # (..., 4)
    rate = jnp.sum((vel_b - vel_a)[..., None, :] * axes, -1)  # d offset / dt
    reach = (_half_extent_on_axis(box_a[..., None, :], axes)
             + _half_extent_on_axis(box_b[..., None, :], axes))
    # overlap on the axis while -reach < offset + rate * t < reach
    safe_rate = jnp.where(jnp.abs(rate) < 1e-6, 1e-6, rate)
    t1 = (-reach - offset) / safe_rate
    t2 = (reach - offset) / safe_rate
    moving = jnp.abs(rate) >= 1e-6
    inside_now = jnp.abs(offset) < reach
    t_enter = jnp.where(moving, jnp.minimum(t1, t2), jnp.where(inside_now, -jnp.inf, jnp.inf))
    t_exit = jnp.where(moving, jnp.maximum(t1, t2), jnp.where(inside_now, jnp.inf, -jnp.inf))
    enter = jnp.max(t_enter, -1)
    leave = jnp.min(t_exit, -1)
    hit = (enter < leave) & (leave > 0.0) & (enter <= horizon)
    return jnp.where(hit, jnp.maximum(enter, 0.0), jnp.inf).astype(jnp.float32)


def circle_cover(box: jnp.ndarray, num_circles: int = 3) -> tuple[jnp.ndarray, jnp.ndarray]:
    """`num_circles` equal circles along the box's length that together cover it.

    Returns centres (..., num_circles, 2) and the shared radius (...,).
    """
    heading, _ = box_axes(box[..., 4])
    length, width = box[..., 2], box[..., 3]
    step = length / num_circles
    offsets = (jnp.arange(num_circles, dtype=box.dtype) + 0.5) * step[..., None] - 0.5 * length[..., None]
    centres = box[..., None, :2] + offsets[..., None] * heading[..., None, :]
    radius = jnp.hypot(0.5 * width, 0.5 * step)
    return centres, radius

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


def _frame(box: jnp.ndarray) -> tuple[jnp.ndarray, ...]:
    """Centre, heading cosine / sine and half extents as separate (...,) arrays.

    The box checks below run on scalars per box rather than trailing 2-wide axes: XLA on the CPU vectorises
    over the leading (proposal, step, object) axes then, which made PDM-Closed ~3x cheaper per view. The two boxes
    are not broadcast up front: each one's sine and cosine are taken once, and the arithmetic broadcasts them.
    """
    return (box[..., 0], box[..., 1], jnp.cos(box[..., 4]), jnp.sin(box[..., 4]),
            0.5 * box[..., 2], 0.5 * box[..., 3])


def _separating_axes(box_a: jnp.ndarray, box_b: jnp.ndarray) -> list[tuple[jnp.ndarray, ...]]:
    """Per candidate axis (the edge normals of both boxes): centre offset along it and both boxes' half shadows.

    -> list of 4 (offset along the axis, summed half shadows, axis x, axis y), each (...,).
    """
    xa, ya, ca, sa, la, wa = _frame(box_a)
    xb, yb, cb, sb, lb, wb = _frame(box_b)
    dx, dy = xb - xa, yb - ya
    axes = []
    for ux, uy in ((ca, sa), (-sa, ca), (cb, sb), (-sb, cb)):
        shadow_a = la * jnp.abs(ca * ux + sa * uy) + wa * jnp.abs(-sa * ux + ca * uy)
        shadow_b = lb * jnp.abs(cb * ux + sb * uy) + wb * jnp.abs(-sb * ux + cb * uy)
        axes.append((dx * ux + dy * uy, shadow_a + shadow_b, ux, uy))
    return axes


def boxes_overlap(box_a: jnp.ndarray, box_b: jnp.ndarray) -> jnp.ndarray:
    """True where two oriented boxes overlap (touching counts as not overlapping).

    Separating-axis test on the 4 edge normals. box_a, box_b broadcast: (..., 5) -> (...,) bool.
    """
    inside = [jnp.abs(offset) < reach for offset, reach, _, _ in _separating_axes(box_a, box_b)]
    return inside[0] & inside[1] & inside[2] & inside[3]


def contact_time(box_a: jnp.ndarray, vel_a: jnp.ndarray, box_b: jnp.ndarray, vel_b: jnp.ndarray,
                 horizon: float) -> jnp.ndarray:
    """First time in [0, horizon] at which two boxes moving at constant velocity touch, else inf.

    Continuous separating-axis test: on each axis the projected gap changes linearly in time, so
    the boxes overlap on the intersection of four closed-form time intervals (exact for
    translation without rotation, as in nuPlan's constant-velocity projection). Boxes that already
    overlap give 0. box (..., 5), vel (..., 2) -> (...,) float32.
    """
    rel_vx, rel_vy = vel_b[..., 0] - vel_a[..., 0], vel_b[..., 1] - vel_a[..., 1]
    enter, leave = -jnp.inf, jnp.inf
    for offset, reach, ux, uy in _separating_axes(box_a, box_b):
        rate = rel_vx * ux + rel_vy * uy  # d offset / dt
        # overlap on the axis while -reach < offset + rate * t < reach
        moving = jnp.abs(rate) >= 1e-6
        safe_rate = jnp.where(moving, rate, 1e-6)
        t1 = (-reach - offset) / safe_rate
        t2 = (reach - offset) / safe_rate
        inside_now = jnp.abs(offset) < reach
        enter = jnp.maximum(enter, jnp.where(moving, jnp.minimum(t1, t2), jnp.where(inside_now, -jnp.inf, jnp.inf)))
        leave = jnp.minimum(leave, jnp.where(moving, jnp.maximum(t1, t2), jnp.where(inside_now, jnp.inf, -jnp.inf)))
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

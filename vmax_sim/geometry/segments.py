"""Points against line segments: projection, distance and signed side."""

from __future__ import annotations

import jax.numpy as jnp


def project_on_segment(point: jnp.ndarray, start: jnp.ndarray, end: jnp.ndarray) -> jnp.ndarray:
    """Clamped fraction t in [0, 1] of the closest segment point. (..., 2) x3 -> (...,)."""
    seg = end - start
    length_sq = jnp.sum(seg * seg, -1)
    t = jnp.sum((point - start) * seg, -1) / jnp.maximum(length_sq, 1e-12)
    return jnp.clip(t, 0.0, 1.0)


def point_segment_distance(point: jnp.ndarray, start: jnp.ndarray, end: jnp.ndarray) -> jnp.ndarray:
    """Euclidean distance from points to segments (broadcasting). (..., 2) x3 -> (...,)."""
    t = project_on_segment(point, start, end)
    closest = start + t[..., None] * (end - start)
    return jnp.linalg.norm(point - closest, axis=-1)


def side_of_segment(point: jnp.ndarray, start: jnp.ndarray, end: jnp.ndarray) -> jnp.ndarray:
    """Cross product of the segment direction with the point offset: > 0 left, < 0 right.

    (..., 2) x3 -> (...,) (signed area, not normalised).
    """
    seg = end - start
    rel = point - start
    return seg[..., 0] * rel[..., 1] - seg[..., 1] * rel[..., 0]

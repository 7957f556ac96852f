"""Rigid transforms into an agent's frame (x forward, y left)."""

from __future__ import annotations

import jax.numpy as jnp


def rotate(vec: jnp.ndarray, angle: jnp.ndarray) -> jnp.ndarray:
    """Rotate 2-D vectors by `angle` radians counter-clockwise. (..., 2), broadcast () -> (..., 2)."""
    cos, sin = jnp.cos(angle)[..., None], jnp.sin(angle)[..., None]
    return jnp.concatenate([cos * vec[..., :1] - sin * vec[..., 1:2],
                            sin * vec[..., :1] + cos * vec[..., 1:2]], -1)


def to_local_points(xy: jnp.ndarray, origin_xy: jnp.ndarray, origin_yaw: jnp.ndarray) -> jnp.ndarray:
    """World points into the frame at `origin_xy` heading `origin_yaw`. (..., 2), (2,), () -> (..., 2)."""
    return rotate(xy - origin_xy, -origin_yaw)


def to_local_vectors(vec: jnp.ndarray, origin_yaw: jnp.ndarray) -> jnp.ndarray:
    """World direction/velocity vectors into the frame heading `origin_yaw`. (..., 2) -> (..., 2)."""
    return rotate(vec, -origin_yaw)


def wrap_angle(angle: jnp.ndarray) -> jnp.ndarray:
    """Angles wrapped to [-pi, pi). (...,) -> (...,)."""
    return (angle + jnp.pi) % (2 * jnp.pi) - jnp.pi


def vector_length(vec: jnp.ndarray) -> jnp.ndarray:
    """Length of 2-D vectors. (..., 2) -> (...,).

    Written out: `jnp.linalg.norm(..., axis=-1)` is a reduction over an axis of 2, which XLA's CPU backend
    hands to a library call per use (measured slower than this one fused expression).
    """
    return jnp.sqrt(vec[..., 0] * vec[..., 0] + vec[..., 1] * vec[..., 1])

"""`RoadgraphPoints`: sampled map polylines (about 1 m apart) with unit directions."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class RoadgraphPoints:
    x: jax.Array  # (..., num_points) float32, metres
    y: jax.Array  # (..., num_points) float32
    z: jax.Array  # (..., num_points) float32
    dir_x: jax.Array  # (..., num_points) float32, unit vector to the next point of the polyline
    dir_y: jax.Array  # (..., num_points) float32
    dir_z: jax.Array  # (..., num_points) float32
    types: jax.Array  # (..., num_points) int32, enum roadgraph_type
    ids: jax.Array  # (..., num_points) int32, map feature id (-1 pads)
    valid: jax.Array  # (..., num_points) bool
    speed_limit: jax.Array  # (..., num_points) float32, m/s, -1 unknown

    @property
    def num_points(self) -> int:
        return int(self.x.shape[-1])

    @property
    def xy(self) -> jax.Array:
        """(..., num_points, 2)"""
        return jnp.stack([self.x, self.y], axis=-1)

    @property
    def dir_xy(self) -> jax.Array:
        """(..., num_points, 2)"""
        return jnp.stack([self.dir_x, self.dir_y], axis=-1)

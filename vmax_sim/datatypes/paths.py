"""`Paths`: candidate routes for the SDC, sampled about 1 m apart along lane centrelines."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class Paths:
    x: jax.Array  # (..., num_paths, num_points) float32, metres
    y: jax.Array  # (..., num_paths, num_points) float32
    z: jax.Array  # (..., num_paths, num_points) float32
    ids: jax.Array  # (..., num_paths, num_points) int32, lane id under each point (-1 pads)
    valid: jax.Array  # (..., num_paths, num_points) bool
    arc_length: jax.Array  # (..., num_paths, num_points) float32, metres from the path start
    on_route: jax.Array  # (..., num_paths) bool, the path the logged SDC followed

    @property
    def num_paths(self) -> int:
        return int(self.x.shape[-2])

    @property
    def num_points_per_path(self) -> int:
        return int(self.x.shape[-1])

    @property
    def xy(self) -> jax.Array:
        """(..., num_paths, num_points, 2)"""
        return jnp.stack([self.x, self.y], axis=-1)

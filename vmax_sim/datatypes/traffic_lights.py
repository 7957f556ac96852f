"""`TrafficLights`: per-light stop points and states over time."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class TrafficLights:
    x: jax.Array  # (..., num_lights, num_timesteps) float32, stop point, metres
    y: jax.Array  # (..., num_lights, num_timesteps) float32
    z: jax.Array  # (..., num_lights, num_timesteps) float32
    state: jax.Array  # (..., num_lights, num_timesteps) int32, enum traffic_light_state
    lane_ids: jax.Array  # (..., num_lights, num_timesteps) int32, controlled lane id (-1 none)
    valid: jax.Array  # (..., num_lights, num_timesteps) bool

    @property
    def num_lights(self) -> int:
        return int(self.x.shape[-2])

    @property
    def xy(self) -> jax.Array:
        """(..., num_lights, num_timesteps, 2)"""
        return jnp.stack([self.x, self.y], axis=-1)

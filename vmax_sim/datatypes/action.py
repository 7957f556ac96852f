"""`Action`: one action vector per object; `valid` says which objects the action applies to."""

from __future__ import annotations

import jax
from flax import struct


@struct.dataclass
class Action:
    data: jax.Array  # (..., num_objects, action_dim) float32, in the dynamics model's units
    valid: jax.Array  # (..., num_objects, 1) bool

    @property
    def action_dim(self) -> int:
        return int(self.data.shape[-1])

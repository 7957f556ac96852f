"""`ObjectMetadata`: per-object flags and ids that do not change over the episode."""

from __future__ import annotations

import jax
from flax import struct


@struct.dataclass
class ObjectMetadata:
    ids: jax.Array  # (..., num_objects) int32, track id from the log (-1 pads)
    object_types: jax.Array  # (..., num_objects) int32, enum object_type (0 unset pads)
    is_sdc: jax.Array  # (..., num_objects) bool, exactly one True per scenario
    is_controlled: jax.Array  # (..., num_objects) bool, moved by the policy (set by the env)
    is_controllable: jax.Array  # (..., num_objects) bool, may be driven by a policy (multi-agent)
    is_valid: jax.Array  # (..., num_objects) bool, valid at some step of the log
    objects_of_interest: jax.Array  # (..., num_objects) bool, interacting tracks from the source

    @property
    def num_objects(self) -> int:
        return int(self.ids.shape[-1])

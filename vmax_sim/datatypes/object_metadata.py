"""`ObjectMetadata`: per-object flags and ids that do not change over the episode."""

from __future__ import annotations

import dataclasses

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
    # Static: at most this many objects per scenario are controlled (None: no bound). `Environment.reset` sets 1
    # for controlled="sdc", and the step then runs the dynamics model on that one row instead of on every
    # object. Replacing is_controlled without giving it resets it to None, so a bound can never be stale.
    max_controlled: int | None = struct.field(pytree_node=False, default=None)

    @property
    def num_objects(self) -> int:
        return int(self.ids.shape[-1])


def _replace_keeping_bound_true(self: ObjectMetadata, **updates) -> ObjectMetadata:
    """`replace` that drops `max_controlled` when is_controlled changes without a new bound."""
    if "is_controlled" in updates and "max_controlled" not in updates:
        updates["max_controlled"] = None
    return dataclasses.replace(self, **updates)


ObjectMetadata.replace = _replace_keeping_bound_true  # flax's decorator installs a plain dataclasses.replace

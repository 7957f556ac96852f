"""`Action`: one action vector per object; `valid` says which objects the action applies to.

`sdc_action` builds the Action that drives the SDC only: the learning environment, the rule policies and
evaluation all use it, so it lives with the type, below all of them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from vmax_sim.datatypes.simulator_state import SimulatorState


@struct.dataclass
class Action:
    data: jax.Array  # (..., num_objects, action_dim) float32, in the dynamics model's units
    valid: jax.Array  # (..., num_objects, 1) bool

    @property
    def action_dim(self) -> int:
        return int(self.data.shape[-1])


def sdc_action(state: SimulatorState, action: jax.Array) -> Action:
    """Puts one (action_dim,) action in the SDC's slot of a full Action (any leading batch dims)."""
    is_sdc = state.object_metadata.is_sdc  # (..., N)
    data = jnp.where(is_sdc[..., None], jnp.asarray(action, jnp.float32)[..., None, :], 0.0)
    return Action(data=data, valid=is_sdc[..., None])

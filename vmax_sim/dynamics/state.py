"""Direct-state dynamics: the action is the next (x, y, yaw, vel_x, vel_y) itself."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.datatypes.trajectory import STEP_MICROS, Trajectory, select_timestep
from vmax_sim.dynamics.bicycle import DT

STATE_FIELDS = ("x", "y", "yaw", "vel_x", "vel_y")


def state_forward(action: jax.Array, current: Trajectory, dt: float = DT) -> Trajectory:
    """action (..., N, 5) [x, y, yaw, vel_x, vel_y]; current (..., N, 1) -> (..., N, 1)."""
    del dt
    values = {name: action[..., i:i + 1] for i, name in enumerate(STATE_FIELDS)}
    return current.replace(timestamp_micros=current.timestamp_micros + STEP_MICROS, **values)


def state_inverse_step(current: Trajectory, target: Trajectory, dt: float = DT) -> jax.Array:
    """current, target (..., N, 1) -> action (..., N, 5): the target's state."""
    del current, dt
    return jnp.concatenate([getattr(target, n) for n in STATE_FIELDS], axis=-1).astype(jnp.float32)


def state_inverse(trajectory: Trajectory, timestep: jax.Array, dt: float = DT) -> jax.Array:
    """trajectory (..., N, T); timestep () or (...) -> action (..., N, 5)."""
    target = select_timestep(trajectory, jnp.asarray(timestep) + 1)
    return state_inverse_step(target, target, dt)

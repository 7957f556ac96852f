"""Delta dynamics: the action is a displacement (dx, dy, dyaw) per step, local or global frame.

Local: (dx, dy) is in the object's frame (x forward, y left) at the current step. Velocity is
set to displacement / dt. Both are exactly invertible.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.datatypes.trajectory import STEP_MICROS, Trajectory, select_timestep
from vmax_sim.dynamics.bicycle import DT, wrap_angle

DELTA_LOCAL_BOUNDS = ((-1.0, 4.0), (-0.5, 0.5), (-0.3, 0.3))  # dx m, dy m, dyaw rad per step
DELTA_GLOBAL_BOUNDS = ((-4.0, 4.0), (-4.0, 4.0), (-0.3, 0.3))


def _rotate(dx: jax.Array, dy: jax.Array, angle: jax.Array) -> tuple[jax.Array, jax.Array]:
    cos, sin = jnp.cos(angle), jnp.sin(angle)
    return dx * cos - dy * sin, dx * sin + dy * cos


def _apply_delta(dx: jax.Array, dy: jax.Array, dyaw: jax.Array, current: Trajectory, dt: float) -> Trajectory:
    return current.replace(
        x=current.x + dx, y=current.y + dy, yaw=wrap_angle(current.yaw + dyaw),
        vel_x=dx / dt, vel_y=dy / dt, timestamp_micros=current.timestamp_micros + STEP_MICROS,
    )


def delta_global_forward(action: jax.Array, current: Trajectory, dt: float = DT) -> Trajectory:
    """action (..., N, 3) [dx, dy, dyaw] in the global frame; current (..., N, 1) -> (..., N, 1)."""
    return _apply_delta(action[..., 0:1], action[..., 1:2], action[..., 2:3], current, dt)


def delta_local_forward(action: jax.Array, current: Trajectory, dt: float = DT) -> Trajectory:
    """action (..., N, 3) [dx, dy, dyaw] in the object frame; current (..., N, 1) -> (..., N, 1)."""
    dx, dy = _rotate(action[..., 0:1], action[..., 1:2], current.yaw)
    return _apply_delta(dx, dy, action[..., 2:3], current, dt)


def delta_global_inverse_step(current: Trajectory, target: Trajectory, dt: float = DT) -> jax.Array:
    """current, target (..., N, 1) -> action (..., N, 3)."""
    del dt
    parts = [target.x - current.x, target.y - current.y, wrap_angle(target.yaw - current.yaw)]
    return jnp.concatenate(parts, axis=-1).astype(jnp.float32)


def delta_local_inverse_step(current: Trajectory, target: Trajectory, dt: float = DT) -> jax.Array:
    """current, target (..., N, 1) -> action (..., N, 3)."""
    del dt
    dx, dy = _rotate(target.x - current.x, target.y - current.y, -current.yaw)
    return jnp.concatenate([dx, dy, wrap_angle(target.yaw - current.yaw)], axis=-1).astype(jnp.float32)


def delta_global_inverse(trajectory: Trajectory, timestep: jax.Array, dt: float = DT) -> jax.Array:
    """trajectory (..., N, T); timestep () or (...) -> action (..., N, 3)."""
    return delta_global_inverse_step(
        select_timestep(trajectory, timestep), select_timestep(trajectory, jnp.asarray(timestep) + 1), dt)


def delta_local_inverse(trajectory: Trajectory, timestep: jax.Array, dt: float = DT) -> jax.Array:
    """trajectory (..., N, T); timestep () or (...) -> action (..., N, 3)."""
    return delta_local_inverse_step(
        select_timestep(trajectory, timestep), select_timestep(trajectory, jnp.asarray(timestep) + 1), dt)

"""Invertible kinematic bicycle model: actions are (acceleration m/s^2, curvature 1/m).

Over one step of `dt` the object drives a constant-curvature arc at constant acceleration:
  s    = v dt + a dt^2 / 2                       distance along the arc (signed)
  yaw' = yaw + k s
  xy'  = xy + s sinc(k s / 2) (cos, sin)(yaw + k s / 2)   exact chord of the arc
  v'   = v + a dt,  vel' = v' (cos yaw', sin yaw')
where v is the velocity projected on the heading (negative when reversing). The chord form makes
a constant-curvature, constant-speed log exact, and a smooth log accurate to O(dt^3) per step.
`inverse` reads (a, k) off two consecutive states so that forward reproduces speed and heading
exactly. `bicycle_forward_no_reverse` is the same car whose brake stops it: it never drives backwards.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.datatypes.trajectory import STEP_MICROS, Trajectory, select_timestep
from vmax_sim.geometry.transforms import wrap_angle  # noqa: F401 (shared; re-exported)

DT = 0.1  # seconds per step
ACCEL_BOUNDS = (-6.0, 6.0)  # m/s^2, used to normalise actions to [-1, 1]
CURVATURE_BOUNDS = (-0.3, 0.3)  # 1/m (a turning radius of 3.3 m)
_MIN_DISTANCE = 1e-3  # metres; below this the heading change says nothing about curvature


def heading_speed(trajectory: Trajectory) -> jax.Array:
    """Velocity projected on the box heading (signed). (..., N, T)"""
    return trajectory.vel_x * jnp.cos(trajectory.yaw) + trajectory.vel_y * jnp.sin(trajectory.yaw)


def bicycle_forward(action: jax.Array, current: Trajectory, dt: float = DT) -> Trajectory:
    """Next state under the bicycle model.

    action (..., N, 2) float32 [accel, curvature]; current (..., N, 1) -> next (..., N, 1).
    Box size and validity are carried over; the timestamp advances by one step.
    """
    accel, curvature = action[..., 0:1], action[..., 1:2]
    speed = heading_speed(current)
    distance = speed * dt + 0.5 * accel * dt**2
    turn = curvature * distance
    chord = distance * jnp.sinc(turn / (2 * jnp.pi))  # jnp.sinc is sin(pi x) / (pi x)
    chord_yaw = current.yaw + turn / 2
    new_yaw = current.yaw + turn
    new_speed = speed + accel * dt
    return current.replace(
        x=current.x + chord * jnp.cos(chord_yaw),
        y=current.y + chord * jnp.sin(chord_yaw),
        yaw=wrap_angle(new_yaw),
        vel_x=new_speed * jnp.cos(new_yaw),
        vel_y=new_speed * jnp.sin(new_yaw),
        timestamp_micros=current.timestamp_micros + STEP_MICROS,
    )


def stop_at_zero(accel: jax.Array, speed: jax.Array, dt: float = DT) -> jax.Array:
    """Acceleration that brakes at most down to zero speed within one step (a brake does not reverse a car); an
    object already reversing is brought back to rest. accel, speed (...) -> (...)"""
    accel = jnp.maximum(accel, -jnp.maximum(speed, 0.0) / dt)
    return jnp.where(speed < 0.0, -speed / dt, accel)


def bicycle_forward_no_reverse(action: jax.Array, current: Trajectory, dt: float = DT) -> Trajectory:
    """`bicycle_forward` with the acceleration passed through `stop_at_zero`: a learned driver's small negative
    acceleration at rest holds it still instead of backing it into the car behind (docs/learning.md).
    action (..., N, 2); current (..., N, 1) -> next (..., N, 1)."""
    accel = stop_at_zero(action[..., 0:1], heading_speed(current), dt)
    return bicycle_forward(jnp.concatenate([accel, action[..., 1:2]], axis=-1), current, dt)


def bicycle_inverse_step(current: Trajectory, target: Trajectory, dt: float = DT) -> jax.Array:
    """Action that takes `current` to the speed and heading of `target`.

    current, target (..., N, 1) -> action (..., N, 2) float32 [accel, curvature] (not clipped).
    """
    speed, new_speed = heading_speed(current), heading_speed(target)
    accel = (new_speed - speed) / dt
    distance = speed * dt + 0.5 * accel * dt**2  # = (speed + new_speed) dt / 2
    turn = wrap_angle(target.yaw - current.yaw)
    is_moving = jnp.abs(distance) > _MIN_DISTANCE
    curvature = jnp.where(is_moving, turn / jnp.where(is_moving, distance, 1.0), 0.0)
    return jnp.concatenate([accel, curvature], axis=-1).astype(jnp.float32)


def bicycle_inverse(trajectory: Trajectory, timestep: jax.Array, dt: float = DT) -> jax.Array:
    """Action taking the trajectory from `timestep` to `timestep + 1`.

    trajectory (..., N, T); timestep () or (...) int32 -> action (..., N, 2).
    """
    current = select_timestep(trajectory, timestep)
    target = select_timestep(trajectory, jnp.asarray(timestep) + 1)
    return bicycle_inverse_step(current, target, dt)


def bicycle_tracking_inverse_step(current: Trajectory, target: Trajectory, dt: float = DT,
                                  position_gain: float = 0.3, min_distance: float = 0.1,
                                  max_curvature_correction: float = 0.3) -> jax.Array:
    """`bicycle_inverse_step` plus feedback that pulls the position towards the target's.

    Logged headings are often biased by a degree or two against the direction of motion (and
    speeds against position differences), so matching heading and speed alone drifts by a metre
    or more over 8 s of a real log. Here a fraction `position_gain` of the remaining position error
    (after the pure inverse) is added back: longitudinally through the acceleration, laterally
    through the curvature (only above `min_distance` metres per step, where curvature can steer).
    current, target (..., N, 1) -> action (..., N, 2) [accel, curvature].
    """
    base = bicycle_inverse_step(current, target, dt)
    predicted = bicycle_forward(base, current, dt)
    speed = heading_speed(current)
    chord_yaw = current.yaw + base[..., 1:2] * (speed * dt + 0.5 * base[..., 0:1] * dt**2) / 2
    ex, ey = target.x - predicted.x, target.y - predicted.y
    error_lon = ex * jnp.cos(chord_yaw) + ey * jnp.sin(chord_yaw)
    error_lat = -ex * jnp.sin(chord_yaw) + ey * jnp.cos(chord_yaw)
    accel = base[..., 0:1] + position_gain * 2 * error_lon / dt**2
    distance = speed * dt + 0.5 * accel * dt**2
    can_steer = jnp.abs(distance) > min_distance
    correction = position_gain * 2 * error_lat / jnp.where(can_steer, distance**2, 1.0)
    correction = jnp.where(can_steer, jnp.clip(correction, -max_curvature_correction, max_curvature_correction), 0.0)
    # Reversing flips which way a curvature turns the chord.
    curvature = base[..., 1:2] + correction * jnp.sign(distance)
    return jnp.concatenate([accel, curvature], axis=-1).astype(jnp.float32)

"""Datatype helpers: time slicing (batched and not), box corners, masking."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from vmax_sim.datatypes import Trajectory, fill_invalid, select_timestep, update_timestep


def ramp_trajectory(batch=(), num_objects=2, num_timesteps=5) -> Trajectory:
    shape = batch + (num_objects, num_timesteps)
    x = jnp.broadcast_to(jnp.arange(num_timesteps, dtype=jnp.float32), shape)  # x == timestep
    ones = jnp.ones(shape, jnp.float32)
    return Trajectory(x=x, y=2 * x, z=0 * x, vel_x=ones, vel_y=0 * ones, yaw=0 * ones, length=4 * ones,
                      width=2 * ones, height=ones, valid=ones > 0, timestamp_micros=(x * 100_000).astype(jnp.int32))


def test_select_and_update_a_timestep_unbatched():
    traj = ramp_trajectory()
    now = select_timestep(traj, jnp.int32(3))
    assert now.x.shape == (2, 1) and now.x.tolist() == [[3.0], [3.0]]
    written = update_timestep(traj, jnp.int32(1), now.replace(x=jnp.full((2, 1), 9.0)))
    assert written.x[0].tolist() == [0.0, 9.0, 2.0, 3.0, 4.0]


def test_batched_timesteps_pick_per_scenario_steps():
    traj = ramp_trajectory(batch=(3,))
    timestep = jnp.array([0, 2, 4], jnp.int32)
    now = select_timestep(traj, timestep)
    assert now.x[:, 0, 0].tolist() == [0.0, 2.0, 4.0]
    written = update_timestep(traj, timestep, now.replace(y=jnp.full((3, 2, 1), -1.0)))
    assert written.y[1, 0].tolist() == [0.0, 2.0, -1.0, 6.0, 8.0]
    # The same as mapping the unbatched helper.
    mapped = jax.vmap(select_timestep)(traj, timestep)
    np.testing.assert_array_equal(mapped.x, now.x)


def test_box_corners_speed_and_masking():
    traj = ramp_trajectory(num_objects=1, num_timesteps=1).replace(yaw=jnp.full((1, 1), jnp.pi / 2))
    corners = np.asarray(traj.bbox_corners[0, 0])  # centre (0, 0), 4 x 2 m box facing +y
    np.testing.assert_allclose(corners, [[-1, 2], [-1, -2], [1, -2], [1, 2]], atol=1e-6)
    assert float(traj.speed[0, 0]) == 1.0 and float(traj.vel_yaw[0, 0]) == 0.0
    masked = fill_invalid(ramp_trajectory(), jnp.arange(5) <= 2)
    assert masked.valid[0].tolist() == [True, True, True, False, False]
    assert masked.x[0].tolist() == [0.0, 1.0, 2.0, 0.0, 0.0]
    assert masked.timestamp_micros[0, 4] == -1

"""`Trajectory`: per-object box states over time, float32, leading batch dims allowed."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from flax import struct

# Fields indexed (..., num_objects, num_timesteps); every one of them is sliced in time together.
TRAJECTORY_FIELDS = (
    "x", "y", "z", "vel_x", "vel_y", "yaw", "length", "width", "height", "valid", "timestamp_micros",
)
STEP_MICROS = 100_000  # 10 Hz logs


@struct.dataclass
class Trajectory:
    x: jax.Array  # (..., num_objects, num_timesteps) float32, box centre, metres
    y: jax.Array  # (..., num_objects, num_timesteps) float32
    z: jax.Array  # (..., num_objects, num_timesteps) float32
    vel_x: jax.Array  # (..., num_objects, num_timesteps) float32, m/s, global frame
    vel_y: jax.Array  # (..., num_objects, num_timesteps) float32
    yaw: jax.Array  # (..., num_objects, num_timesteps) float32, box heading, radians
    length: jax.Array  # (..., num_objects, num_timesteps) float32, metres
    width: jax.Array  # (..., num_objects, num_timesteps) float32
    height: jax.Array  # (..., num_objects, num_timesteps) float32
    valid: jax.Array  # (..., num_objects, num_timesteps) bool
    timestamp_micros: jax.Array  # (..., num_objects, num_timesteps) int32 (int32 holds 35 min)

    @property
    def shape(self) -> tuple[int, ...]:
        """(..., num_objects, num_timesteps)"""
        return tuple(self.x.shape)

    @property
    def num_objects(self) -> int:
        return int(self.x.shape[-2])

    @property
    def num_timesteps(self) -> int:
        return int(self.x.shape[-1])

    @property
    def xy(self) -> jax.Array:
        """(..., num_objects, num_timesteps, 2)"""
        return jnp.stack([self.x, self.y], axis=-1)

    @property
    def xyz(self) -> jax.Array:
        """(..., num_objects, num_timesteps, 3)"""
        return jnp.stack([self.x, self.y, self.z], axis=-1)

    @property
    def vel_xy(self) -> jax.Array:
        """(..., num_objects, num_timesteps, 2)"""
        return jnp.stack([self.vel_x, self.vel_y], axis=-1)

    @property
    def speed(self) -> jax.Array:
        """Norm of the velocity. (..., num_objects, num_timesteps)"""
        return jnp.sqrt(self.vel_x**2 + self.vel_y**2)

    @property
    def vel_yaw(self) -> jax.Array:
        """Direction of the velocity. (..., num_objects, num_timesteps)"""
        return jnp.arctan2(self.vel_y, self.vel_x)

    @property
    def bbox_corners(self) -> jax.Array:
        """Box corners, counter-clockwise from front-left. (..., num_objects, num_timesteps, 4, 2)"""
        cos, sin = jnp.cos(self.yaw), jnp.sin(self.yaw)
        half_l, half_w = self.length / 2, self.width / 2
        signs_l = jnp.array([1.0, -1.0, -1.0, 1.0], jnp.float32)
        signs_w = jnp.array([1.0, 1.0, -1.0, -1.0], jnp.float32)
        dl = half_l[..., None] * signs_l
        dw = half_w[..., None] * signs_w
        cx = self.x[..., None] + dl * cos[..., None] - dw * sin[..., None]
        cy = self.y[..., None] + dl * sin[..., None] + dw * cos[..., None]
        return jnp.stack([cx, cy], axis=-1)


def select_timestep(trajectory: Trajectory, timestep: jax.Array, written: bool = True) -> Trajectory:
    """The trajectory at `timestep`, keeping a time axis of 1.

    trajectory (..., N, T); timestep () or (...) int32 -> (..., N, 1). Indices clamp to [0, T-1].
    `written=False` for a trajectory no step writes (the log): read plainly, XLA may fuse the read into its
    users; a trajectory a rollout writes is read with `read_unfused`.
    """
    timestep = jnp.asarray(timestep, jnp.int32)
    if timestep.ndim > 0:  # batched: map over the leading axis (faster than a one-hot select)
        return jax.vmap(lambda tr, t: select_timestep(tr, t, written))(trajectory, timestep)
    if not written:
        return _slice_timestep(trajectory, timestep)
    return read_unfused(_slice_timestep, timestep, trajectory, timestep)


def read_outside_fusion() -> bool:
    """Whether `read_unfused` reads through a conditional (the CPU backend)."""
    return jax.default_backend() == "cpu"


def read_unfused(read: Callable, timestep: jax.Array, *operands):
    """read(*operands), on CPU inside a conditional whose two branches are `read` (timestep () int32 >= 0).

    XLA cannot fuse a read made inside a conditional into the in-place write of the next step that a rollout
    does right after it. Fused, each written field's update read the other fields' buffers, and XLA copied
    every field's whole (N, T) buffer twice per step to write it (the physics step 4x slower;
    docs/benchmarks.md). Elsewhere a conditional may cost a device-to-host read of its predicate per step, so
    accelerators read plainly.
    """
    if read_outside_fusion():
        return jax.lax.cond(timestep >= 0, read, read, *operands)
    return read(*operands)


def _slice_timestep(trajectory: Trajectory, timestep: jax.Array) -> Trajectory:
    return jax.tree.map(lambda a: jax.lax.dynamic_slice_in_dim(a, timestep, 1, axis=-1), trajectory)


def update_timestep(trajectory: Trajectory, timestep: jax.Array, values: Trajectory) -> Trajectory:
    """Writes `values` (..., N, 1) into `trajectory` (..., N, T) at `timestep` () or (...)."""
    timestep = jnp.asarray(timestep, jnp.int32)
    if timestep.ndim > 0:
        return jax.vmap(update_timestep)(trajectory, timestep, values)
    return jax.tree.map(
        lambda a, v: jax.lax.dynamic_update_slice_in_dim(a, v.astype(a.dtype), timestep, axis=-1),
        trajectory, values)


def stack_fields(trajectory: Trajectory, names: tuple[str, ...]) -> jax.Array:
    """Chosen fields stacked on a new last axis. (..., N, T, len(names)) float32"""
    return jnp.stack([getattr(trajectory, n).astype(jnp.float32) for n in names], axis=-1)


def fill_invalid(trajectory: Trajectory, is_kept: jax.Array) -> Trajectory:
    """Zeroes every entry where `is_kept` (broadcastable to (..., N, T)) is False and marks it invalid."""
    def mask(name, a):
        if name == "valid":
            return a & is_kept
        fill = -1 if name == "timestamp_micros" else 0
        return jnp.where(is_kept, a, jnp.asarray(fill, a.dtype))
    return trajectory.replace(**{n: mask(n, getattr(trajectory, n)) for n in TRAJECTORY_FIELDS})

"""Replay buffer on the device: a fixed-size ring of transitions, written and sampled inside jit.

Any pytree of arrays is stored with leading (num_blocks, rows_per_block) axes. Each block receives
an equal share of every added batch and supplies an equal share of every sample, so with the block
axis sharded over devices (one block per device) adding and sampling stay local to each device and
only the gradients are averaged. With one device there is one block.

Floating-point leaves may be stored in a narrower dtype (float16 halves the memory of observations;
they are normalised to about [-1, 1], where float16 keeps ~3 significant digits) and are returned
as float32.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct


@struct.dataclass
class ReplayBuffer:
    data: object  # pytree, every leaf (num_blocks, rows_per_block, ...)
    position: jax.Array  # () int32, next row to write in every block
    size: jax.Array  # () int32, rows written so far in every block (at most rows_per_block)

    @property
    def num_blocks(self) -> int:
        return jax.tree.leaves(self.data)[0].shape[0]

    @property
    def rows_per_block(self) -> int:
        return jax.tree.leaves(self.data)[0].shape[1]

    @property
    def capacity(self) -> int:
        return self.num_blocks * self.rows_per_block


def storage_dtype(dtype, float_dtype) -> np.dtype:
    """The dtype a leaf of `dtype` is stored in: `float_dtype` for floating-point leaves."""
    return np.dtype(float_dtype) if jnp.issubdtype(dtype, jnp.floating) else np.dtype(dtype)


def buffer_init(example, capacity: int, float_dtype=jnp.float32, num_blocks: int = 1) -> ReplayBuffer:
    """An empty buffer for transitions shaped like `example` (one unbatched transition).

    capacity is rounded up to a multiple of num_blocks.
    """
    if capacity < 1 or num_blocks < 1:
        raise ValueError(f"replay buffer capacity and blocks must be at least 1, got {capacity}, {num_blocks}")
    rows = -(-capacity // num_blocks)
    data = jax.tree.map(lambda leaf: jnp.zeros((num_blocks, rows) + jnp.shape(leaf),
                                               storage_dtype(jnp.result_type(leaf), float_dtype)), example)
    return ReplayBuffer(data=data, position=jnp.zeros((), jnp.int32), size=jnp.zeros((), jnp.int32))


def transition_bytes(example, float_dtype=jnp.float32) -> int:
    """Bytes one stored transition takes (for the memory budget printed before training)."""
    return int(sum(np.prod(jnp.shape(leaf), dtype=np.int64)
                   * storage_dtype(jnp.result_type(leaf), float_dtype).itemsize
                   for leaf in jax.tree.leaves(example)))


def buffer_add(buffer: ReplayBuffer, batch) -> ReplayBuffer:
    """Writes a batch (leading axis B, a multiple of num_blocks, B / num_blocks <= rows_per_block):
    block k takes rows k*B/num_blocks .. (k+1)*B/num_blocks - 1, overwriting its oldest rows."""
    batch_size = jax.tree.leaves(batch)[0].shape[0]
    blocks, rows_per_block = buffer.num_blocks, buffer.rows_per_block
    if batch_size % blocks:
        raise ValueError(f"a batch of {batch_size} transitions does not split into {blocks} buffer blocks")
    share = batch_size // blocks
    rows = (buffer.position + jnp.arange(share)) % rows_per_block

    def write(store, new):
        new = new.reshape((blocks, share) + new.shape[1:]).astype(store.dtype)
        return jax.vmap(lambda block, values: block.at[rows].set(values))(store, new)

    data = jax.tree.map(write, buffer.data, batch)
    return ReplayBuffer(data=data, position=((buffer.position + share) % rows_per_block).astype(jnp.int32),
                        size=jnp.minimum(buffer.size + share, rows_per_block).astype(jnp.int32))


def sample_rows(buffer: ReplayBuffer, key: jax.Array, batch_size: int) -> jax.Array:
    """Row indices of `batch_size` transitions drawn uniformly (with replacement) from the rows written, an
    equal share from every block: (num_blocks, batch_size / num_blocks) int32."""
    blocks = buffer.num_blocks
    if batch_size % blocks:
        raise ValueError(f"a sample of {batch_size} does not split into {blocks} buffer blocks")
    return jax.random.randint(key, (blocks, batch_size // blocks), 0, jnp.maximum(buffer.size, 1))


def gather_rows(store, rows: jax.Array):
    """The rows (num_blocks, share) of a per-block pytree `store` (leaves (num_blocks, N, ...)), blocks
    flattened into one batch axis; floats returned as float32."""
    def take(leaf):
        values = jax.vmap(lambda block, index: block[index])(leaf, rows)
        values = values.reshape((rows.size,) + values.shape[2:])
        return values.astype(jnp.float32) if jnp.issubdtype(values.dtype, jnp.floating) else values

    return jax.tree.map(take, store)


def buffer_sample(buffer: ReplayBuffer, key: jax.Array, batch_size: int):
    """`batch_size` transitions drawn uniformly (with replacement) from the rows written, an equal
    share from every block; floats returned as float32. batch_size must be a multiple of num_blocks."""
    return gather_rows(buffer.data, sample_rows(buffer, key, batch_size))

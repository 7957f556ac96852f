"""`chunked_vmap`: a batch of whole episodes, vmapped in cache-sized chunks on the CPU.

XLA runs a vmapped program one operation at a time over the whole batch, so every intermediate of the step
(lane candidates, observation points, path windows ...) is batch-sized. At batch 32 they stay in the CPU's
caches; at batch 1024 each one streams through main memory, and a scene-step cost twice as much on CPU as at
batch 32 (docs/benchmarks.md). Running the batch as a sequential `lax.map` over chunks of `CPU_CHUNK` vmapped
episodes keeps the intermediates cache-sized at any batch: the per-scene cost stays that of the chunk.

Use it for functions that run whole episodes (a `lax.scan` inside): each chunk then updates its trajectories in
place for the whole episode. A function that takes one step of a carried batch state would have its outputs
stacked anew by `lax.map`, a full copy of the state per call, so training keeps plain `jax.vmap`.
Accelerators get plain `jax.vmap`: there the whole batch in one operation is what fills the device.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp

CPU_CHUNK = 32  # scenes per chunk: the batch at which the full step is fastest per scene on CPU (benchmarks.md)


def chunked_vmap(fn: Callable, in_axes: int | None | Sequence[int | None] = 0, chunk: int | None = None) -> Callable:
    """`jax.vmap(fn, in_axes)` (batch axis 0 of the mapped arguments, outputs batched on axis 0), run on the CPU
    backend as a `lax.map` over chunks of `chunk` (default CPU_CHUNK) when the batch is larger than a chunk.

    A batch that is not a multiple of the chunk is padded with copies of its last element, whose results are
    dropped. The results equal plain `jax.vmap`'s.
    """
    vmapped = jax.vmap(fn, in_axes=in_axes)

    def run(*args):
        axes = in_axes if isinstance(in_axes, (tuple, list)) else (in_axes,) * len(args)
        mapped = [arg for arg, axis in zip(args, axes, strict=True) if axis is not None]
        batch = jax.tree.leaves(mapped)[0].shape[0]
        size = chunk or CPU_CHUNK
        if jax.default_backend() != "cpu" or batch <= size:
            return vmapped(*args)
        num_chunks = -(-batch // size)
        padded = num_chunks * size

        def split(tree):  # (B, ...) -> (num_chunks, size, ...), padded with the last element
            def one(leaf):
                if padded > batch:
                    leaf = jnp.concatenate([leaf, jnp.repeat(leaf[-1:], padded - batch, axis=0)])
                return leaf.reshape((num_chunks, size) + leaf.shape[1:])
            return jax.tree.map(one, tree)

        chunks = [split(arg) if axis is not None else None for arg, axis in zip(args, axes, strict=True)]

        def one_chunk(chunked_args):
            full = [c if axis is not None else arg for c, arg, axis in zip(chunked_args, args, axes, strict=True)]
            return vmapped(*full)

        out = jax.lax.map(one_chunk, chunks)
        return jax.tree.map(lambda leaf: leaf.reshape((padded,) + leaf.shape[2:])[:batch], out)

    return run

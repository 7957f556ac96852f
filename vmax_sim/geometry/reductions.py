"""Index reductions (argmin, first true) as single plain min-reductions.

XLA's CPU backend lowers `jnp.argmin` / `jnp.argmax` to a variadic (value, index) reduction that it
does not vectorise: over the ~150 lane candidates of a step it costs ~12x a plain `min` (measured at
batch 32; docs/benchmarks.md). Packing the index into the low bits of an order-preserving integer key
turns the argmin into one integer `min`, which is vectorised and fused like any other reduction.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def _sortable_key(x: jax.Array) -> jax.Array:
    """int32 keys ordered as the float32 values are (-inf < ... < -0 <= 0 < ... < inf). (...) -> (...)."""
    bits = jax.lax.bitcast_convert_type(x.astype(jnp.float32), jnp.int32)
    # negative floats order backwards as integers: flip their magnitude bits
    return bits ^ (jax.lax.shift_right_arithmetic(bits, 31) & 0x7FFFFFFF)


def argmin_packed(x: jax.Array, axis: int = -1) -> jax.Array:
    """Index of the smallest value along `axis`, as `jnp.argmin` up to near-ties. (..., n, ...) -> (...) int32.

    The index replaces the lowest ceil(log2 n) bits of each value's key, so values closer than
    2 ** (ceil(log2 n) - 23) relative (3e-5 for n = 256) count as equal and the first of them wins,
    as `jnp.argmin` resolves exact ties. All +inf gives 0, like `jnp.argmin`. NaN counts as largest.
    """
    axis = axis % x.ndim
    n = x.shape[axis]
    index_bits = max(1, (n - 1).bit_length())
    index = jax.lax.broadcasted_iota(jnp.int32, x.shape, axis)
    key = (_sortable_key(x) & ~((1 << index_bits) - 1)) | index
    return jnp.min(key, axis=axis) & ((1 << index_bits) - 1)


def first_true(mask: jax.Array, axis: int = -1) -> jax.Array:
    """Index of the first True along `axis`, 0 when there is none (as `jnp.argmax` of a bool array). -> int32."""
    axis = axis % mask.ndim
    n = mask.shape[axis]
    index = jax.lax.broadcasted_iota(jnp.int32, mask.shape, axis)
    first = jnp.min(jnp.where(mask, index, n), axis=axis)
    return jnp.where(first == n, 0, first)

"""The device replay buffer: ring order, wrap-around, narrow storage, blocks, sampling inside jit."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vmax_sim.training import buffer_add, buffer_init, buffer_sample, transition_bytes


def example():
    return {"obs": jnp.zeros((3,), jnp.float32), "valid": jnp.zeros((3,), bool), "reward": jnp.zeros(())}


def batch(start: int, size: int):
    values = jnp.arange(start, start + size, dtype=jnp.float32)
    return {"obs": values[:, None] * jnp.ones(3), "valid": jnp.ones((size, 3), bool), "reward": values}


def test_ring_overwrites_the_oldest_rows():
    buffer = buffer_init(example(), capacity=5)
    buffer = buffer_add(buffer, batch(0, 3))
    assert int(buffer.size) == 3 and int(buffer.position) == 3
    buffer = buffer_add(buffer, batch(3, 3))  # rows 3, 4 then wraps to row 0
    assert int(buffer.size) == 5 and int(buffer.position) == 1
    np.testing.assert_array_equal(buffer.data["reward"][0], [5, 1, 2, 3, 4])


def test_samples_come_only_from_written_rows_and_as_float32():
    buffer = buffer_add(buffer_init(example(), 100, jnp.float16), batch(10, 4))
    assert buffer.data["obs"].dtype == jnp.float16 and buffer.data["valid"].dtype == jnp.bool_
    sample = jax.jit(buffer_sample, static_argnums=2)(buffer, jax.random.PRNGKey(0), 64)
    assert sample["obs"].dtype == jnp.float32 and sample["obs"].shape == (64, 3)
    assert set(np.asarray(sample["reward"]).tolist()) <= {10.0, 11.0, 12.0, 13.0}
    assert len(set(np.asarray(sample["reward"]).tolist())) > 1


def test_blocks_split_writes_and_samples_evenly():
    buffer = buffer_init(example(), capacity=8, num_blocks=2)
    buffer = buffer_add(buffer, batch(0, 4))  # block 0 gets 0, 1; block 1 gets 2, 3
    np.testing.assert_array_equal(buffer.data["reward"][:, :2], [[0, 1], [2, 3]])
    sample = buffer_sample(buffer, jax.random.PRNGKey(1), 6)
    first, second = np.asarray(sample["reward"][:3]), np.asarray(sample["reward"][3:])
    assert set(first) <= {0.0, 1.0} and set(second) <= {2.0, 3.0}
    with pytest.raises(ValueError, match="does not split"):
        buffer_add(buffer, batch(0, 3))


def test_memory_budget_counts_the_storage_dtype():
    assert transition_bytes(example()) == 3 * 4 + 3 + 4
    assert transition_bytes(example(), jnp.float16) == 3 * 2 + 3 + 2

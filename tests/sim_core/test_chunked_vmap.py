"""`chunked_vmap` runs a large batch as chunks on the CPU and gives plain `jax.vmap`'s results."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vmax_sim.env.chunked_vmap import chunked_vmap


def _episode(state, scale):
    """A small scan per element, as an episode is: a carried state updated in place over steps."""
    def body(carry, step):
        carry = carry.at[step % carry.shape[0]].add(scale * jnp.sin(carry.sum() + step))
        return carry, carry[0]
    final, outs = jax.lax.scan(body, state["x"], jnp.arange(7))
    return {"final": final, "outs": outs, "label": state["label"] * 2}


@pytest.mark.parametrize("batch", [5, 32, 70, 96])
def test_chunked_results_equal_plain_vmap_whatever_the_batch(batch):
    rng = np.random.default_rng(batch)
    states = {"x": jnp.asarray(rng.normal(size=(batch, 4)), jnp.float32), "label": jnp.arange(batch)}
    expected = jax.jit(jax.vmap(_episode, in_axes=(0, None)))(states, 0.5)
    got = jax.jit(chunked_vmap(_episode, in_axes=(0, None), chunk=16))(states, 0.5)
    for key in expected:
        assert got[key].shape == expected[key].shape
        np.testing.assert_allclose(got[key], expected[key], rtol=1e-6, atol=1e-6)


def test_a_large_batch_runs_as_a_loop_over_chunks_on_cpu():
    states = {"x": jnp.zeros((64, 4), jnp.float32), "label": jnp.arange(64)}
    text = jax.jit(chunked_vmap(_episode, in_axes=(0, None), chunk=16)).lower(states, 0.5).as_text()
    plain = jax.jit(jax.vmap(_episode, in_axes=(0, None))).lower(states, 0.5).as_text()
    if jax.default_backend() == "cpu":
        assert "tensor<16x4xf32>" in text and "tensor<16x4xf32>" not in plain  # the episode sees 16 scenes at a time
    else:  # accelerators map the whole batch at once
        assert "tensor<16x4xf32>" not in text

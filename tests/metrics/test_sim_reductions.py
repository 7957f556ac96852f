"""The packed argmin and first-true reductions pick what `jnp.argmin` / `jnp.argmax` pick."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vmax_sim.geometry.reductions import argmin_packed, first_true


@pytest.mark.parametrize("size", [1, 2, 7, 30, 144, 300])
def test_argmin_packed_finds_the_smallest_value(size):
    rng = np.random.default_rng(size)
    values = (rng.normal(size=(50, size)) * 10.0 ** rng.uniform(-3, 3, size=(50, 1))).astype(np.float32)
    values[rng.random(values.shape) < 0.2] = np.inf
    values[rng.random(values.shape) < 0.05] = -np.inf
    picked = np.asarray(argmin_packed(jnp.asarray(values)))
    rows = np.arange(values.shape[0])
    expected = np.argmin(values, axis=-1)
    # the chosen value is the minimum (up to the documented near-tie band, which random draws never reach)
    np.testing.assert_array_equal(values[rows, picked], values[rows, expected])
    np.testing.assert_array_equal(picked, expected)


def test_argmin_packed_resolves_ties_to_the_first_and_works_on_any_axis():
    values = jnp.array([[3.0, 1.0, 1.0, 2.0], [jnp.inf] * 4, [-0.5, -2.0, -2.0, 5.0]])
    np.testing.assert_array_equal(argmin_packed(values), [1, 0, 1])
    np.testing.assert_array_equal(argmin_packed(values.T, axis=0), [1, 0, 1])
    batched = jax.vmap(argmin_packed)(values)
    np.testing.assert_array_equal(batched, [1, 0, 1])


def test_argmin_packed_counts_near_ties_as_ties():
    # values one float32 step apart are one tie for a 4-slot axis (2 index bits): the first wins, as documented
    values = jnp.array([np.nextafter(np.float32(1.0), np.float32(2.0)), 1.0, 2.0, 3.0], jnp.float32)
    assert int(argmin_packed(values)) == 0
    # a real difference is never lost
    assert int(argmin_packed(jnp.array([1.001, 1.0, 2.0, 3.0]))) == 1


def test_first_true_matches_argmax_of_a_mask():
    masks = jnp.array([[False, True, True], [False, False, False], [True, False, True]])
    np.testing.assert_array_equal(first_true(masks), jnp.argmax(masks, axis=-1))
    np.testing.assert_array_equal(first_true(masks.T, axis=0), jnp.argmax(masks, axis=-1))

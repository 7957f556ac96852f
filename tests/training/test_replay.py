"""The replay that stores each observation once gives the samples of a buffer of whole transitions."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vmax_sim.agents import Transition
from vmax_sim.training import buffer_add, buffer_init, buffer_sample
from vmax_sim.training.replay import (
    lost_last_observations,
    replay_add,
    replay_bytes,
    replay_init,
    replay_sample,
)

NUM_ENVS = 4


def observation(values: np.ndarray) -> dict:
    """A small observation pytree: a float leaf and a mask, both derived from one number per env."""
    values = jnp.asarray(values, jnp.float32)
    return {"x": values[:, None] * jnp.arange(1.0, 4.0), "valid": (values[:, None] + jnp.arange(3)) % 2 > 0}


def toy_steps(num_steps: int, seed: int, end_probability: float = 0.25):
    """Transitions of NUM_ENVS toy environments with auto-reset: observations count up, an episode ends
    (terminated or truncated at random) with `end_probability`, and its true last observation is negative
    while the next episode starts on a fresh positive number."""
    rng = np.random.default_rng(seed)
    obs = np.arange(NUM_ENVS, dtype=np.float32) + 1.0
    counter = obs.max()
    for _ in range(num_steps):
        ends = rng.random(NUM_ENVS) < end_probability
        terminated = ends & (rng.random(NUM_ENVS) < 0.5)
        truncated = ends & ~terminated
        following = counter + 1.0 + np.arange(NUM_ENVS, dtype=np.float32)
        counter = following.max()
        next_obs = np.where(ends, -following, following)  # the true next observation
        yield Transition.make(obs=observation(obs), action=jnp.asarray(rng.uniform(-1, 1, (NUM_ENVS, 2))),
                              reward=jnp.asarray(rng.normal(size=NUM_ENVS)), discount=1.0 - terminated,
                              next_obs=observation(next_obs), truncated=jnp.asarray(truncated),
                              done=jnp.asarray(ends))
        obs = np.where(ends, following + 0.5, next_obs)  # auto-reset: the next episode's first observation


def example() -> Transition:
    return jax.tree.map(lambda a: a[0], next(toy_steps(1, 0)))


@pytest.mark.parametrize("capacity, num_blocks", [
    pytest.param(10, 1, marks=pytest.mark.slow), pytest.param(12, 1, marks=pytest.mark.slow),
    (16, 2)])  # 5-10 s each on 2 cores: one in the default suite
def test_samples_equal_a_buffer_of_whole_transitions_across_episode_ends(capacity, num_blocks):
    whole = buffer_init(example(), capacity, jnp.float16, num_blocks)
    # a ring of last observations for every row: the toy's episodes are far shorter than the default sizing
    replay = replay_init(example(), capacity, NUM_ENVS, jnp.float16, num_blocks, min_truncated_length=1)
    add, sample = jax.jit(replay_add), jax.jit(replay_sample, static_argnums=2)
    for step, transition in enumerate(toy_steps(40, seed=capacity)):  # wraps the ring several times
        whole, replay = buffer_add(whole, transition), add(replay, transition)
        key = jax.random.PRNGKey(step)
        expected, got = buffer_sample(whole, key, 32), sample(replay, key, 32)
        for name in ("obs", "action", "reward", "discount", "truncated", "done"):
            jax.tree.map(np.testing.assert_array_equal, getattr(got, name), getattr(expected, name))
        # a terminated transition (discount 0) bootstraps nothing: only there may next_obs differ
        bootstrapped = np.asarray(expected.discount) > 0
        for name in ("x", "valid"):
            np.testing.assert_array_equal(np.asarray(got.next_obs[name])[bootstrapped],
                                          np.asarray(expected.next_obs[name])[bootstrapped])
    assert lost_last_observations(replay) == 0


def test_a_replay_sized_to_the_run_samples_what_a_larger_one_does():
    # the default preset's buffer holds exactly its 500k env steps (was 600k, 0.5 GB more): while a run writes
    # no more rows than the smaller capacity, every add and sample is the same, so training is unchanged
    small = replay_init(example(), 40, NUM_ENVS, jnp.float16, min_truncated_length=1)
    large = replay_init(example(), 64, NUM_ENVS, jnp.float16, min_truncated_length=1)
    add, sample = jax.jit(replay_add), jax.jit(replay_sample, static_argnums=2)
    for step, transition in enumerate(toy_steps(10, seed=3)):  # 40 transitions: the small one just full
        small, large = add(small, transition), add(large, transition)
        key = jax.random.PRNGKey(step)
        jax.tree.map(np.testing.assert_array_equal, sample(small, key, 32), sample(large, key, 32))


def test_truncations_beyond_the_sized_ring_are_counted():
    replay = replay_init(example(), 40, NUM_ENVS)  # 10 steps held: a ring of 4 * (1 + 1) last observations
    for transition in toy_steps(30, seed=1, end_probability=1.0):  # every step ends every episode
        replay = replay_add(replay, transition)
    assert lost_last_observations(replay) > 0


def test_memory_is_about_half_of_whole_transitions():
    big = jnp.zeros((1, 500))  # observations dominate a transition, as in training (~4.5 kB)
    one = jax.tree.map(lambda a: a[0], Transition.make(obs=big, action=jnp.zeros((1, 2)), reward=jnp.zeros(1),
                                                       discount=jnp.ones(1), next_obs=big))
    whole = buffer_init(one, 1000, jnp.float16)
    whole_bytes = sum(leaf.nbytes for leaf in jax.tree.leaves(whole.data))
    assert replay_bytes(one, 1000, NUM_ENVS, jnp.float16) < 0.6 * whole_bytes
    with pytest.raises(ValueError, match="cannot hold one step"):
        replay_init(example(), 3, NUM_ENVS)


def test_checkpoint_round_trip_of_the_replay_in_slices(tmp_path, monkeypatch):
    from vmax_sim.training import checkpoint
    from vmax_sim.training.loop import TrainCarry

    monkeypatch.setattr(checkpoint, "SLICE_BYTES", 100)  # many slices per block, and a shorter last one
    replay = replay_init(example(), 40, NUM_ENVS, jnp.float16, num_blocks=2, min_truncated_length=1)
    for transition in toy_steps(13, seed=2):
        replay = replay_add(replay, transition)
    carry = TrainCarry(learner={"w": jnp.arange(3.0)}, env={"t": jnp.ones(2)}, buffer=replay,
                       key=jax.random.PRNGKey(1), env_steps=jnp.asarray(52, jnp.int32))
    store = checkpoint.CheckpointStore(tmp_path / "checkpoints")
    store.save(52, carry, {"consumed": 0}, with_buffer=True)
    fresh = carry.replace(buffer=replay_init(example(), 40, NUM_ENVS, jnp.float16, num_blocks=2,
                                             min_truncated_length=1))
    restored = store.restore(52, fresh, with_buffer=True)
    jax.tree.map(np.testing.assert_array_equal, restored.buffer, replay)
    assert int(restored.env_steps) == 52

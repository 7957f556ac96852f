"""The step runs the dynamics only on the controlled rows it may drive (ObjectMetadata.max_controlled), with the
same next state as running it on every object."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import make_scenario, small_config

from vmax_sim.data import scenarios_to_batch
from vmax_sim.datatypes import Action
from vmax_sim.env import EnvConfig, Environment
from vmax_sim.env.environment import merge_next_state

N = 8


@pytest.fixture(scope="module")
def batch():
    return scenarios_to_batch([make_scenario(seed) for seed in range(3)], small_config())


def random_action(key, batch_shape=()):
    data = jax.random.uniform(key, batch_shape + (N, 2), minval=-1.0, maxval=1.0) * jnp.array([4.0, 0.2])
    return Action(data=data, valid=jnp.ones(batch_shape + (N, 1), bool))


def every_object_step(env, state, action):
    """The next state with the dynamics run on every object (the reference)."""
    current = state.current_sim_trajectory
    predicted = env.dynamics.forward(action.data, current)
    return merge_next_state(current, predicted, state.next_log_trajectory, state.object_metadata.is_controlled,
                            action.valid)


def assert_same_trajectory(got, want):
    for name in ("x", "y", "yaw", "vel_x", "vel_y", "valid", "length", "timestamp_micros"):
        np.testing.assert_allclose(np.asarray(getattr(got, name)), np.asarray(getattr(want, name)), rtol=0, atol=0,
                                   err_msg=name)


def test_an_sdc_env_drives_one_row_and_gets_the_every_object_result(batch):
    env = Environment(EnvConfig(max_num_objects=N))
    state = env.reset(batch)  # batched: (3, N)
    assert state.object_metadata.max_controlled == 1
    for step in range(5):
        action = random_action(jax.random.PRNGKey(step), (3,))
        want = every_object_step(env, state, action)
        state = env.step(state, action)
        assert_same_trajectory(state.current_sim_trajectory, want)
    moved = state.current_sim_trajectory.x[:, 0, 0] != state.log_trajectory.x[:, 0, state.timestep[0]]
    assert bool(jnp.all(moved))  # the SDC really was driven off its log


def test_a_bound_of_two_drives_the_first_two_controlled_objects_only(batch):
    scene = jax.tree.map(lambda a: a[0], batch)
    env = Environment(EnvConfig(max_num_objects=N))
    present = np.flatnonzero(np.asarray(env.reset(scene).current_sim_trajectory.valid[:, 0]))
    assert len(present) >= 3
    first, second, third = (int(i) for i in present[:3])
    mask = tuple(i in (first, second, third) for i in range(N))
    state = Environment(EnvConfig(max_num_objects=N, controlled=mask)).reset(scene)
    meta = state.object_metadata
    state = state.replace(object_metadata=meta.replace(is_controlled=meta.is_controlled, max_controlled=2))
    action = random_action(jax.random.PRNGKey(7))
    full = every_object_step(env, state, action)
    got = env.step(state, action).current_sim_trajectory
    for slot in (first, second):  # driven by the model, as with every object
        assert float(got.x[slot, 0]) == float(full.x[slot, 0])
    # the third controlled object is past the bound: it follows its log
    assert float(got.x[third, 0]) == float(state.next_log_trajectory.x[third, 0])
    assert float(got.x[third, 0]) != float(full.x[third, 0])


def test_changing_is_controlled_lifts_the_bound(batch):
    """Reactive evaluation adds agents to is_controlled after reset: every one of them must be driven."""
    env = Environment(EnvConfig(max_num_objects=N))
    state = env.reset(jax.tree.map(lambda a: a[1], batch))
    meta = state.object_metadata
    state = state.replace(object_metadata=meta.replace(is_controlled=meta.is_sdc | (jnp.arange(N) < 4)))
    assert state.object_metadata.max_controlled is None
    action = random_action(jax.random.PRNGKey(3))
    assert_same_trajectory(env.step(state, action).current_sim_trajectory, every_object_step(env, state, action))

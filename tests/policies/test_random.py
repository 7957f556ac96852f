"""Uniformly random actions: within the bounds, a function of the key."""

from __future__ import annotations

import jax
import numpy as np

from tests.policies.scenes import ENV_CONFIG, as_state, empty_road_scenario, episode
from vmax_sim.env import EnvConfig, make_environment
from vmax_sim.policies import random_policy


def test_random_actions_lie_within_the_bounds_and_follow_the_key():
    env = make_environment(ENV_CONFIG)
    policy = random_policy(env)
    state = env.reset(as_state(empty_road_scenario()))
    first = policy.action_fn(None, state, None, jax.random.PRNGKey(1))
    again = policy.action_fn(None, state, None, jax.random.PRNGKey(1))
    other = policy.action_fn(None, state, None, jax.random.PRNGKey(2))
    data = np.asarray(first.data)
    assert data.shape == (8, 2) and bool(np.all(first.valid))
    assert np.all(np.abs(data[:, 0]) <= 6.0) and np.all(np.abs(data[:, 1]) <= 0.3)
    np.testing.assert_array_equal(data, np.asarray(again.data))
    assert not np.allclose(data, np.asarray(other.data))
    normalised = random_policy(make_environment(EnvConfig(max_num_objects=8, normalize_actions=True)))
    assert np.all(np.abs(np.asarray(normalised.action_fn(None, state, None, jax.random.PRNGKey(1)).data)) <= 1.0)


def test_random_policy_runs_an_episode():
    rollout, steps = episode("random", empty_road_scenario())
    assert np.all(np.abs(steps["accel"]) <= 6.0 + 1e-3)
    assert 0.0 <= float(rollout.episode["vmax_score"]) <= 1.0

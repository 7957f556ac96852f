"""The package surface: presets, overrides, the registry and every learner's act on pytree observations."""

import dataclasses

import jax
import jax.numpy as jnp
import pytest

from tests.agents import toy
from vmax_sim.agents import ALGORITHMS, PPOConfig, SACConfig, get_config, make_learner


def test_every_algorithm_has_paper_and_default_presets():
    assert set(ALGORITHMS) == {"sac", "ppo", "bc", "bc_sac"}
    for name, algorithm in ALGORITHMS.items():
        assert {"paper", "default"} <= set(algorithm.presets), name
        for preset in algorithm.presets:
            assert type(get_config(name, preset)) is algorithm.config_class


def test_paper_presets_hold_the_papers_numbers():
    sac = get_config("sac", "paper")
    assert (sac.learning_rate, sac.gamma, sac.tau, sac.init_alpha, sac.batch_size) == (1e-4, 0.99, 0.005, 0.2, 64)
    assert (sac.num_envs, sac.updates_per_step, sac.buffer_size, sac.learning_starts) == (16, 4, 1_000_000, 50_000)
    ppo = get_config("ppo", "paper")
    assert (ppo.batch_size, ppo.num_minibatches, ppo.unroll_length, ppo.gae_lambda, ppo.clip_eps, ppo.gamma) == (
        512, 16, 40, 0.95, 0.2, 0.99)
    assert ppo.sequences_per_update == 512 * 16 and ppo.transitions_per_update == 512 * 16 * 40
    bc = get_config("bc", "paper")
    assert (bc.learning_rate, bc.batch_size) == (1e-4, 64)
    bc_sac = get_config("bc_sac", "paper")
    assert bc_sac.bc_every == 8 and isinstance(bc_sac, SACConfig)


def test_overrides_and_errors():
    config = get_config("ppo", "paper", num_epochs=8, policy_hidden_sizes=[32, 32])
    assert config.num_epochs == 8 and config.policy_hidden_sizes == (32, 32)
    hash(config)  # frozen and hashable
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.num_epochs = 1
    with pytest.raises(ValueError, match="no field"):
        get_config("sac", "default", not_a_field=1)
    with pytest.raises(ValueError, match="unknown preset"):
        get_config("sac", "nope")
    with pytest.raises(ValueError, match="unknown algorithm"):
        get_config("dqn")
    with pytest.raises(ValueError, match="gamma"):
        get_config("sac", gamma=1.5)
    with pytest.raises(ValueError, match="entropy_estimate"):
        PPOConfig(entropy_estimate="exact")
    with pytest.raises(TypeError, match="PPOConfig"):
        make_learner("ppo", get_config("sac"), toy.ToyEncoder, 1)


@pytest.mark.parametrize("algo", sorted(ALGORITHMS))
def test_learners_act_on_pytree_observations(algo):
    config = get_config(algo, "debug")
    learner = make_learner(algo, config, lambda: toy.ToyEncoder(8), action_dim=2)
    obs = {"position": jnp.zeros((5, 1)), "nested": {"target": jnp.ones((5, 3, 2))}}
    state = learner.init(jax.random.key(0), obs)
    params = learner.policy_params(state)
    action = jax.jit(learner.act, static_argnums=3)(params, obs, jax.random.key(1), False)
    assert action.shape == (5, 2) and bool(jnp.all(jnp.abs(action) <= 1.0))
    action, info = learner.act_with_info(params, obs, jax.random.key(1), True)
    assert info["log_prob"].shape == (5,)
    assert (learner.value is None) == (algo != "ppo")
    if algo == "ppo":
        assert info["value"].shape == (5,) and learner.value(params, obs).shape == (5,)

"""SAC: losses on hand-worked values, Polyak averaging, a learning check, determinism and no recompiles."""

import dataclasses
import math

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.agents import toy
from vmax_sim.agents import distributions as D
from vmax_sim.agents import get_config, make_learner, polyak_update
from vmax_sim.agents.sac import losses as L
from vmax_sim.agents.sac.networks import make_networks


def test_soft_td_target_takes_twin_min_and_entropy_term():
    reward = jnp.array([1.0, 2.0])
    discount = jnp.array([1.0, 0.0])  # the second transition terminated
    next_q = jnp.array([[3.0, 5.0], [4.0, 1.0]])  # (heads, B): min = [3, 1]
    next_log_prob = jnp.array([-1.0, 2.0])
    # y = r + 0.9 * d * (min Q - 0.5 * logp) = [1 + 0.9 * (3 + 0.5), 2 + 0]
    np.testing.assert_allclose(L.soft_td_target(reward, discount, next_q, next_log_prob, 0.5, 0.9), [4.15, 2.0],
                               rtol=1e-6)
    np.testing.assert_allclose(L.soft_td_target(reward, discount, next_q, next_log_prob, 0.5, 0.9, reward_scale=2.0),
                               [5.15, 4.0], rtol=1e-6)


def test_critic_loss_hand_value():
    q = jnp.array([[4.0, 2.5], [5.0, 1.0]])
    target = jnp.array([4.15, 2.0])
    # head 0: errors (-0.15, 0.5) -> mean sq 0.13625; head 1: (0.85, -1) -> 0.86125; 0.5 * sum
    np.testing.assert_allclose(L.critic_loss(q, target), 0.49875, rtol=1e-6)


def test_actor_loss_hand_value():
    q = jnp.array([[1.0, 2.0], [3.0, 0.0]])  # min over heads [1, 0]
    log_prob = jnp.array([-1.0, 0.5])
    # mean(0.2 * logp - min Q) = mean(-0.2 - 1, 0.1 - 0)
    np.testing.assert_allclose(L.actor_loss(q, log_prob, 0.2), -0.55, rtol=1e-6)


def test_temperature_loss_hand_value_and_direction():
    log_prob = jnp.array([-1.0, -3.0])
    log_alpha = jnp.log(0.5)
    # -log(0.5) * mean(logp + (-1)) = -log(0.5) * -3
    np.testing.assert_allclose(L.temperature_loss(log_alpha, log_prob, -1.0), 3 * math.log(0.5), rtol=1e-6)
    # entropy (-logp = 2 on average) above target (-1): the gradient step lowers alpha
    assert jax.grad(L.temperature_loss)(log_alpha, log_prob, -1.0) > 0
    # entropy below target: alpha rises
    assert jax.grad(L.temperature_loss)(log_alpha, jnp.array([3.0]), -1.0) < 0


def test_polyak_update_hand_values():
    params = {"w": jnp.array([1.0, 2.0]), "b": jnp.array(10.0)}
    target = {"w": jnp.array([3.0, 0.0]), "b": jnp.array(0.0)}
    out = polyak_update(params, target, 0.1)
    np.testing.assert_allclose(out["w"], [0.1 * 1 + 0.9 * 3, 0.1 * 2], rtol=1e-6)
    np.testing.assert_allclose(out["b"], 1.0, rtol=1e-6)
    toy.assert_trees_equal(polyak_update(params, target, 1.0), params)


@pytest.fixture(scope="module")
def tiny():
    config = get_config("sac", "debug", policy_hidden_sizes=(8,), value_hidden_sizes=(8,), gamma=0.9)
    batch = toy.random_batch(jax.random.key(0), 16)
    return config, batch


def test_network_level_losses_on_a_tiny_network_match_the_formulas(tiny):
    config, batch = tiny
    networks = make_networks(config, lambda: toy.ToyEncoder(None), 1)
    losses = L.make_losses(networks, config)
    actor_params = networks.actor.init(jax.random.key(1), batch.obs)
    critic_params = networks.critic.init(jax.random.key(2), batch.obs, batch.action)
    target_params = jax.tree.map(lambda x: x + 0.1, critic_params)
    key, alpha = jax.random.key(3), jnp.float32(0.3)

    @jax.jit
    def by_hand():
        q = networks.critic.apply(critic_params, batch.obs, batch.action)
        next_dist = networks.actor.apply(actor_params, batch.next_obs)
        next_action, next_log_prob = D.sample_and_log_prob(next_dist, key)
        next_q = networks.critic.apply(target_params, batch.next_obs, next_action)
        y = batch.reward + 0.9 * batch.discount * (jnp.minimum(next_q[0], next_q[1]) - alpha * next_log_prob)
        critic = 0.5 * (jnp.mean((q[0] - y) ** 2) + jnp.mean((q[1] - y) ** 2))
        action, log_prob = D.sample_and_log_prob(networks.actor.apply(actor_params, batch.obs), key)
        q_pi = networks.critic.apply(critic_params, batch.obs, action)
        return q, critic, jnp.mean(alpha * log_prob - jnp.minimum(q_pi[0], q_pi[1])), log_prob

    @jax.jit
    def by_losses():
        critic, _ = losses.critic(critic_params, target_params, actor_params, alpha, batch, key)
        actor, (log_prob, _) = losses.actor(actor_params, critic_params, alpha, batch, key)
        return critic, actor, log_prob

    q, critic, actor, log_prob = by_hand()
    assert q.shape == (2, 16) and not np.allclose(q[0], q[1])  # two distinct heads on one encoder
    got = by_losses()
    np.testing.assert_allclose(got[0], critic, rtol=1e-5)
    np.testing.assert_allclose(got[1], actor, rtol=1e-5)
    np.testing.assert_allclose(got[2], log_prob, rtol=1e-6)


def test_critic_gradient_does_not_reach_the_target_or_the_actor(tiny):
    config, batch = tiny
    networks = make_networks(config, lambda: toy.ToyEncoder(4), 1)
    losses = L.make_losses(networks, config)
    actor_params = networks.actor.init(jax.random.key(1), batch.obs)
    critic_params = networks.critic.init(jax.random.key(2), batch.obs, batch.action)
    grads = jax.jit(jax.grad(lambda t, a: losses.critic(critic_params, t, a, 0.2, batch, jax.random.key(0))[0],
                             argnums=(0, 1)))(critic_params, actor_params)
    assert all(float(jnp.max(jnp.abs(g))) == 0.0 for g in jax.tree.leaves(grads))


@pytest.fixture(scope="module")
def learner_and_state(tiny):
    config, batch = tiny
    learner = make_learner("sac", config, lambda: toy.ToyEncoder(8), 1)
    return learner, learner.init(jax.random.key(0), batch.obs)


@pytest.fixture(scope="module")
def update(learner_and_state):
    """The jitted update, shared by the tests below: it must never be traced twice."""
    return jax.jit(chex.assert_max_traces(learner_and_state[0].update, n=1))


def test_update_is_deterministic_and_does_not_retrace(tiny, learner_and_state, update):
    _, batch = tiny
    _, state = learner_and_state
    first, metrics = update(state, batch, jax.random.key(7))
    again, metrics_again = update(state, batch, jax.random.key(7))
    toy.assert_trees_equal((first, metrics), (again, metrics_again))
    other, _ = update(state, batch, jax.random.key(8))
    assert not np.allclose(other.actor_params["params"]["loc_head"]["kernel"],
                           first.actor_params["params"]["loc_head"]["kernel"])
    for i in range(3):
        first, metrics = update(first, toy.random_batch(jax.random.key(i), 16), jax.random.key(i))
    assert int(first.step) == 4
    assert all(m.shape == () and m.dtype == jnp.float32 for m in metrics.values())
    assert {"critic_loss", "actor_loss", "alpha_loss", "alpha", "entropy", "q_mean"} <= set(metrics)


def test_update_moves_the_target_by_tau_and_the_temperature(tiny, learner_and_state, update):
    config, batch = tiny
    _, state = learner_and_state
    new, _ = update(state, batch, jax.random.key(0))
    expected = polyak_update(new.critic_params, state.target_critic_params, config.tau)
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7), new.target_critic_params,
                 expected)
    assert float(new.log_alpha) != float(state.log_alpha)
    np.testing.assert_allclose(jnp.exp(state.log_alpha), config.init_alpha, rtol=1e-6)


def test_fixed_temperature_stays_put(tiny):
    config, batch = tiny
    learner = make_learner("sac", get_config("sac", "debug", learn_alpha=False, init_alpha=0.05),
                           lambda: toy.ToyEncoder(8), 1)
    state = learner.init(jax.random.key(0), batch.obs)
    new, metrics = jax.jit(learner.update)(state, batch, jax.random.key(0))
    assert float(new.log_alpha) == float(state.log_alpha)
    np.testing.assert_allclose(metrics["alpha"], 0.05, rtol=1e-6)


def test_act_is_in_bounds_and_deterministic_mode(tiny, learner_and_state):
    _, batch = tiny
    learner, state = learner_and_state
    params = learner.policy_params(state)
    sampled = learner.act(params, batch.obs, jax.random.key(0), False)
    mode1 = learner.act(params, batch.obs, jax.random.key(0), True)
    mode2 = jax.jit(learner.act)(params, batch.obs, jax.random.key(1), jnp.bool_(True))  # traced flag
    assert sampled.shape == (16, 1) and jnp.all(jnp.abs(sampled) <= 1.0)
    np.testing.assert_allclose(mode1, mode2, rtol=1e-6)
    action, info = learner.act_with_info(params, batch.obs, jax.random.key(0))
    assert info["log_prob"].shape == (16,)


def test_sac_learns_the_toy_task():
    config = get_config("sac", "debug", gamma=0.9, batch_size=128)
    learner = make_learner("sac", config, lambda: toy.ToyEncoder(32), toy.ACTION_DIM)
    state, metrics = toy.train_off_policy(learner, jax.random.key(0), num_envs=16, num_iterations=300,
                                          warmup_iterations=20, updates_per_step=1, batch_size=128)
    params = learner.policy_params(state)
    trained = toy.episode_return(lambda obs, key: learner.act(params, obs, key, True), jax.random.key(1))
    random = toy.episode_return(toy.random_policy, jax.random.key(1))
    assert all(bool(jnp.isfinite(m)) for m in metrics.values())
    assert random < -15.0  # about -23: the random walk drifts away from the target
    assert trained > -3.0, (float(trained), float(random))  # the expert scores about -0.1


def test_shared_encoder_actor_has_no_encoder_and_its_loss_leaves_the_encoder_alone(tiny):
    config, batch = tiny
    config = dataclasses.replace(config, shared_encoder=True)
    learner = make_learner("sac", config, lambda: toy.ToyEncoder(8), 1)
    state = learner.init(jax.random.key(0), batch.obs)
    assert "encoder" not in state.actor_params["params"]  # the actor reads the critic encoder's features
    new, metrics = jax.jit(learner.update)(state, batch, jax.random.key(1))
    assert all(bool(jnp.isfinite(m)) for m in metrics.values())
    # the encoder moved (critic loss) and the actor moved; acting reads both parameter sets
    encoder_before = state.critic_params["params"]["encoder"]
    encoder_after = new.critic_params["params"]["encoder"]
    assert not np.allclose(encoder_before["Dense_0"]["kernel"], encoder_after["Dense_0"]["kernel"])
    params = learner.policy_params(new)
    assert set(params) == {"actor", "critic"}
    action = learner.act(params, batch.obs, jax.random.key(0), True)
    assert action.shape == (16, 1) and bool(jnp.all(jnp.abs(action) <= 1.0))
    # the actor loss gives the encoder no gradient (features are detached)
    networks = make_networks(config, lambda: toy.ToyEncoder(8), 1)
    losses = L.make_losses(networks, config)
    features = networks.actor_input(state.critic_params, batch.obs)
    grads = jax.grad(lambda c: losses.actor(state.actor_params, c, 0.2, batch.replace(obs=features),
                                            jax.random.key(0))[0])(state.critic_params)
    assert float(jnp.max(jnp.abs(grads["params"]["encoder"]["Dense_0"]["kernel"]))) == 0.0


def test_sac_with_a_shared_encoder_learns_the_toy_task():
    config = get_config("sac", "debug", gamma=0.9, batch_size=128, shared_encoder=True)
    learner = make_learner("sac", config, lambda: toy.ToyEncoder(32), toy.ACTION_DIM)
    state, _ = toy.train_off_policy(learner, jax.random.key(0), num_envs=16, num_iterations=300,
                                    warmup_iterations=20, updates_per_step=1, batch_size=128)
    params = learner.policy_params(state)
    trained = toy.episode_return(lambda obs, key: learner.act(params, obs, key, True), jax.random.key(1))
    assert trained > -3.0, float(trained)


@pytest.mark.parametrize("algo", ["sac", "bc_sac"])
def test_masked_rows_never_change_the_update(algo):
    """Self-play's empty and finished agent slots are replay rows with mask 0: whatever they hold, SAC's (and
    BC+SAC's) update is the one on the agent rows alone, and so are the logged Q, entropy and std."""
    learner = make_learner(algo, get_config(algo, "debug"), lambda: toy.ToyEncoder(8), 1)
    batch = toy.random_batch(jax.random.key(0), 16)
    mask = (jnp.arange(16) < 10).astype(jnp.float32)
    garbage = toy.random_batch(jax.random.key(1), 16)
    mixed = jax.tree.map(lambda a, b: jnp.where(mask.reshape((16,) + (1,) * (a.ndim - 1)) > 0, a, b * 5.0),
                         batch, garbage)
    state = learner.init(jax.random.key(2), batch.obs)
    update = jax.jit(learner.update)
    masked, metrics = update(state, batch.replace(mask=mask), jax.random.key(3))
    other, other_metrics = update(state, mixed.replace(mask=mask), jax.random.key(3))
    for name in ("critic_loss", "actor_loss", "alpha_loss", "q_mean", "target_q_mean", "entropy", "policy_std"):
        np.testing.assert_allclose(metrics[name], other_metrics[name], rtol=1e-5, atol=1e-6, err_msg=name)
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6),
                 (masked.actor_params, masked.critic_params, masked.log_alpha),
                 (other.actor_params, other.critic_params, other.log_alpha))
    unmasked, _ = update(state, mixed, jax.random.key(3))  # the same rows, all counted: a different update
    assert any(not np.allclose(a, b) for a, b in zip(jax.tree.leaves(unmasked.critic_params),
                                                     jax.tree.leaves(masked.critic_params)))

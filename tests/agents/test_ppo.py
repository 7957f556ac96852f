"""PPO: GAE on a hand-worked rollout with a termination and a truncation, the clipped objectives, and
learning / determinism / no-recompile checks."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.agents import toy
from vmax_sim.agents import get_config, make_learner
from vmax_sim.agents.ppo import losses as L

GAMMA, LAMBDA = 0.9, 0.8


def test_gae_hand_worked_with_termination_and_truncation():
    # One env, 3 steps: step 0 ordinary, step 1 truncated by the time limit (V(next_obs_1) = 2.0, the true
    # last state; obs_2 starts a new episode), step 2 terminated. The bootstrap value 4.0 must not be used.
    rewards = jnp.array([[1.0], [2.0], [3.0]])
    values = jnp.array([[0.5], [1.0], [1.5]])
    discounts = jnp.array([[1.0], [1.0], [0.0]])
    dones = jnp.array([[False], [True], [True]])
    truncated = jnp.array([[False], [True], [False]])
    truncation_values = jnp.array([[99.0], [2.0], [99.0]])  # V(next_obs) where it is needed
    next_values = L.next_values_with_truncation(values, jnp.array([4.0]), truncated, truncation_values)
    np.testing.assert_allclose(next_values[:, 0], [1.0, 2.0, 4.0])
    advantages, returns = L.compute_gae(rewards, values, next_values, discounts, dones, GAMMA, LAMBDA)
    # delta_2 = 3 - 1.5 = 1.5                         A_2 = 1.5           (terminated: no bootstrap)
    # delta_1 = 2 + 0.9 * 2.0 - 1.0 = 2.8             A_1 = 2.8           (truncated: bootstrap, cut)
    # delta_0 = 1 + 0.9 * 1.0 - 0.5 = 1.4             A_0 = 1.4 + 0.9 * 0.8 * 2.8 = 3.416
    np.testing.assert_allclose(advantages[:, 0], [3.416, 2.8, 1.5], rtol=1e-6)
    np.testing.assert_allclose(returns[:, 0], [3.916, 3.8, 3.0], rtol=1e-6)


def test_gae_bootstraps_past_the_rollout_end_and_runs_per_env():
    rewards = jnp.array([[1.0, 0.0], [2.0, 0.0], [3.0, 1.0]])
    values = jnp.array([[0.5, 0.0], [1.0, 0.0], [1.5, 0.0]])
    ones, falses = jnp.ones((3, 2)), jnp.zeros((3, 2), bool)
    next_values = L.next_values_with_truncation(values, jnp.array([4.0, 10.0]), falses, jnp.zeros((3, 2)))
    advantages, _ = L.compute_gae(rewards, values, next_values, ones, falses, GAMMA, LAMBDA)
    d2 = 3 + 0.9 * 4.0 - 1.5
    d1 = 2 + 0.9 * 1.5 - 1.0
    d0 = 1 + 0.9 * 1.0 - 0.5
    np.testing.assert_allclose(advantages[:, 0], [d0 + 0.72 * (d1 + 0.72 * d2), d1 + 0.72 * d2, d2], rtol=1e-6)
    np.testing.assert_allclose(advantages[:, 1], [0.72 ** 2 * 10.0, 0.72 * 10.0, 1 + 9.0], rtol=1e-6)
    # lambda = 1, gamma = 1: advantages are returns-to-go minus V
    adv1, _ = L.compute_gae(rewards, values, next_values, ones, falses, 1.0, 1.0)
    np.testing.assert_allclose(adv1[:, 0], [1 + 2 + 3 + 4 - 0.5, 2 + 3 + 4 - 1.0, 3 + 4 - 1.5], rtol=1e-6)


def test_clipped_surrogate_hand_values():
    log_prob = jnp.log(jnp.array([1.5, 0.5, 1.5, 0.5, 1.1]))
    old = jnp.zeros(5)
    advantages = jnp.array([1.0, 1.0, -1.0, -1.0, 2.0])
    # min(r A, clip(r) A): 1.2, 0.5, -1.5, -0.8, 2.2
    loss, clip_fraction = L.clipped_surrogate_loss(log_prob, old, advantages, 0.2)
    np.testing.assert_allclose(loss, -(1.2 + 0.5 - 1.5 - 0.8 + 2.2) / 5, rtol=1e-6)
    np.testing.assert_allclose(clip_fraction, 0.8)
    # the clipped side carries no gradient: d/dlogp of the first entry is 0, of the last is r * A / N
    grad = jax.grad(lambda lp: L.clipped_surrogate_loss(lp, old, advantages, 0.2)[0])(log_prob)
    np.testing.assert_allclose(grad, [0.0, -0.5 / 5, -1.5 * -1 / 5, 0.0, -1.1 * 2 / 5], rtol=1e-5, atol=1e-7)


def test_value_loss_plain_and_clipped():
    values, old, returns = jnp.array([1.0, 3.0]), jnp.array([1.5, 1.5]), jnp.array([0.0, 2.0])
    np.testing.assert_allclose(L.value_loss(values, returns), 0.5 * (1 + 1) / 2)
    # clipped predictions [1.3, 1.7] -> squared errors [1.69, 0.09]; max with [1, 1] -> [1.69, 1]
    np.testing.assert_allclose(L.value_loss(values, returns, old, 0.2), 0.5 * (1.69 + 1.0) / 2, rtol=1e-6)


def test_normalize_and_kl():
    x = jnp.array([1.0, 2.0, 3.0, 4.0])
    np.testing.assert_allclose(jnp.mean(L.normalize(x)), 0.0, atol=1e-6)
    np.testing.assert_allclose(jnp.std(L.normalize(x)), 1.0, rtol=1e-5)
    assert float(L.approx_kl(x, x)) == 0.0 and float(L.approx_kl(x, x + 0.1)) > 0


CONFIG = get_config("ppo", "debug", gamma=GAMMA, num_minibatches=4, num_epochs=2, policy_hidden_sizes=(16,),
                    value_hidden_sizes=(16,))


@pytest.fixture(scope="module")
def setup():
    learner = make_learner("ppo", CONFIG, lambda: toy.ToyEncoder(8), toy.ACTION_DIM)
    state = learner.init(jax.random.key(0), toy.observe(toy.reset(jax.random.key(0), 4)))

    @jax.jit
    def rollout(key):  # T = 12, B = 4, truncation mid-rollout (episodes already 15 steps in)
        env_state = toy.reset(key, 4).replace(t=jnp.full((4,), toy.EPISODE_LENGTH - 5, jnp.int32))

        def body(env_state, step_key):
            act_key, env_key = jax.random.split(step_key)
            action, info = learner.act_with_info(learner.policy_params(state), toy.observe(env_state), act_key)
            env_state, tr = toy.step(env_key, env_state, action)
            return env_state, tr.replace(log_prob=info["log_prob"], value=info["value"])

        return jax.lax.scan(body, env_state, jax.random.split(key, 12))[1]

    return learner, state, rollout(jax.random.key(1))


def test_first_minibatch_ratio_is_one(setup):
    learner, state, rollout = setup
    assert bool(jnp.any(rollout.truncated))
    from vmax_sim.agents.ppo.networks import make_networks

    loss = L.make_loss(make_networks(CONFIG, lambda: toy.ToyEncoder(8), 1), CONFIG)
    flat = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), rollout)
    batch = L.PPOBatch(obs=flat.obs, action=flat.action, log_prob=flat.log_prob, value=flat.value,
                       advantage=jnp.ones(48), target=flat.value, mask=jnp.ones(48), expert_action=flat.expert_action)
    _, metrics = jax.jit(loss)(state.params, batch, jax.random.key(0))
    assert float(metrics["clip_fraction"]) == 0.0
    assert abs(float(metrics["approx_kl"])) < 1e-6


def test_masked_rows_do_not_change_the_update(setup):
    """Self-play pads its flat batch with empty or finished agent slots (mask 0): whatever those rows hold, the
    update is the one of the real rows alone."""
    learner, state, rollout = setup
    mask = (jnp.arange(rollout.reward.shape[1]) % 2 == 0).astype(jnp.float32)[None].repeat(rollout.reward.shape[0], 0)
    bootstrap = learner.value(state.params, jax.tree.map(lambda x: x[-1], rollout.next_obs))
    update = jax.jit(learner.update)
    masked = rollout.replace(mask=mask)
    garbage = masked.replace(reward=jnp.where(mask > 0, rollout.reward, 1e3),
                             action=jnp.where(mask[..., None] > 0, rollout.action, -0.99))
    first, metrics = update(state, masked, jax.random.key(3), bootstrap_value=bootstrap)
    second, metrics_garbage = update(state, garbage, jax.random.key(3), bootstrap_value=bootstrap)
    toy.assert_trees_equal(first.params, second.params)
    assert float(metrics["value_loss"]) == float(metrics_garbage["value_loss"])


def _active_learner(size: int = 8):
    import dataclasses

    return make_learner("ppo", dataclasses.replace(CONFIG, active_minibatch_size=size), lambda: toy.ToyEncoder(8),
                        toy.ACTION_DIM)


def _adam_steps(train_state) -> int:
    import optax

    return int(optax.tree_utils.tree_get(train_state.opt_state, "count"))


def _first_rows(rollout, num_active: int) -> jax.Array:
    """(T, B) mask with the first `num_active` transitions of the flattened rollout active."""
    shape = rollout.reward.shape
    return (jnp.arange(shape[0] * shape[1]) < num_active).astype(jnp.float32).reshape(shape)


def test_active_minibatches_take_as_many_steps_as_the_acting_rows_fill(setup):
    """active_minibatch_size=N: each epoch takes ceil(active rows / N) gradient steps (CONFIG: 2 epochs), whatever
    the rollout's size; a rollout with no acting row leaves the parameters as they were."""
    _, state, rollout = setup  # T * B = 48 rows
    learner = _active_learner(8)
    update = jax.jit(learner.update)
    bootstrap = learner.value(state.params, jax.tree.map(lambda x: x[-1], rollout.next_obs))
    for num_active, steps in ((48, 12), (24, 6), (25, 8), (1, 2)):
        after, metrics = update(state, rollout.replace(mask=_first_rows(rollout, num_active)), jax.random.key(3),
                                bootstrap_value=bootstrap)
        assert _adam_steps(after) == steps, num_active
        assert all(bool(jnp.isfinite(m)) for m in metrics.values())
    idle, metrics = update(state, rollout.replace(mask=_first_rows(rollout, 0)), jax.random.key(3),
                           bootstrap_value=bootstrap)
    assert _adam_steps(idle) == 0
    toy.assert_trees_equal(idle.params, state.params)
    assert all(bool(jnp.isfinite(m)) for m in metrics.values())


def test_active_minibatches_never_read_the_empty_slots(setup):
    """The rows with mask 0 are left out of the minibatches, not weighed out: even NaN observations there (which
    the masked minibatches turn into NaN parameters, 0 * NaN) leave the update of the acting rows unchanged."""
    _, state, rollout = setup
    learner = _active_learner(8)
    update = jax.jit(learner.update)
    bootstrap = learner.value(state.params, jax.tree.map(lambda x: x[-1], rollout.next_obs))
    mask = (jnp.arange(rollout.reward.shape[1]) % 2 == 0).astype(jnp.float32)[None].repeat(rollout.reward.shape[0], 0)
    masked = rollout.replace(mask=mask)
    poisoned = masked.replace(
        obs=jax.tree.map(lambda x: jnp.where(mask.reshape(mask.shape + (1,) * (x.ndim - 2)) > 0, x, jnp.nan),
                         rollout.obs),
        reward=jnp.where(mask > 0, rollout.reward, 1e3), action=jnp.where(mask[..., None] > 0, rollout.action, -0.99))
    first, _ = update(state, masked, jax.random.key(3), bootstrap_value=bootstrap)
    second, _ = update(state, poisoned, jax.random.key(3), bootstrap_value=bootstrap)
    toy.assert_trees_equal(first.params, second.params)
    assert all(bool(jnp.all(jnp.isfinite(leaf))) for leaf in jax.tree.leaves(second.params))
    weighed, _ = jax.jit(make_learner("ppo", CONFIG, lambda: toy.ToyEncoder(8), toy.ACTION_DIM).update)(
        state, poisoned, jax.random.key(3), bootstrap_value=bootstrap)
    assert not all(bool(jnp.all(jnp.isfinite(leaf))) for leaf in jax.tree.leaves(weighed.params))


def test_the_imitation_term_pulls_the_policy_mode_to_the_teacher_label(setup):
    """With imitation_coef > 0 each update also fits mode(pi(s)) to the label in Transition.expert_action (the
    rule teacher of self-play): a few updates on the same rollout bring the mode closer to it; masked rows count
    for nothing."""
    import dataclasses

    _, state, rollout = setup
    config = dataclasses.replace(CONFIG, imitation_coef=5.0, learning_rate=3e-3)
    learner = make_learner("ppo", config, lambda: toy.ToyEncoder(8), toy.ACTION_DIM)
    label = jnp.full(rollout.action.shape, 0.6)
    taught = rollout.replace(expert_action=label)
    bootstrap = learner.value(state.params, jax.tree.map(lambda x: x[-1], rollout.next_obs))
    update = jax.jit(learner.update)

    flat_obs = jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:]), rollout.obs)

    def distance(train_state):
        mode = learner.act(learner.policy_params(train_state), flat_obs, jax.random.key(0), True)
        return float(jnp.mean(jnp.abs(mode - 0.6)))

    after, metrics = update(state, taught, jax.random.key(3), bootstrap_value=bootstrap)
    for i in range(4):
        after, metrics = update(after, taught, jax.random.key(4 + i), bootstrap_value=bootstrap)
    assert "imitation_mse" in metrics and distance(after) < 0.5 * distance(state)
    mask = (jnp.arange(rollout.reward.shape[1]) % 2 == 0).astype(jnp.float32)[None].repeat(rollout.reward.shape[0], 0)
    noisy = taught.replace(mask=mask, expert_action=jnp.where(mask[..., None] > 0, label, -0.9))
    first, _ = update(state, taught.replace(mask=mask), jax.random.key(3), bootstrap_value=bootstrap)
    second, _ = update(state, noisy, jax.random.key(3), bootstrap_value=bootstrap)
    toy.assert_trees_equal(first.params, second.params)

    # the likelihood form also narrows the spread round the label (the squared error leaves it to the PPO terms)
    nll = make_learner("ppo", dataclasses.replace(config, imitation_loss="nll", imitation_coef=1.0),
                       lambda: toy.ToyEncoder(8), toy.ACTION_DIM)
    narrowed = state
    for i in range(5):
        narrowed, nll_metrics = jax.jit(nll.update)(narrowed, taught, jax.random.key(4 + i), bootstrap_value=bootstrap)
    assert float(nll_metrics["policy_std"]) < 0.8 * float(metrics["policy_std"])
    assert distance(narrowed) < 0.5 * distance(state)


def test_update_deterministic_and_no_retrace(setup):
    learner, state, rollout = setup
    update = jax.jit(chex.assert_max_traces(learner.update, n=1))
    bootstrap = learner.value(state.params, jax.tree.map(lambda x: x[-1], rollout.next_obs))
    first, metrics = update(state, rollout, jax.random.key(3), bootstrap_value=bootstrap)
    again, metrics_again = update(state, rollout, jax.random.key(3), bootstrap_value=bootstrap)
    toy.assert_trees_equal((first, metrics), (again, metrics_again))
    for i in range(2):
        first, metrics = update(first, rollout, jax.random.key(i), bootstrap_value=bootstrap)
    assert int(first.step) == 3
    assert all(m.shape == () and m.dtype == jnp.float32 and bool(jnp.isfinite(m)) for m in metrics.values())
    assert {"policy_loss", "value_loss", "entropy", "approx_kl", "clip_fraction"} <= set(metrics)


def test_the_moving_average_is_evaluated_while_the_raw_parameters_collect(setup):
    """With ema_decay > 0 the run's policy (evaluated, saved) is the parameters' moving average; the rollouts still
    come from the raw parameters, whose log-probabilities the PPO ratio needs."""
    import dataclasses

    from vmax_sim.agents.common import ema_weight

    _, _, rollout = setup
    config = dataclasses.replace(CONFIG, ema_decay=0.9)
    learner = make_learner("ppo", config, lambda: toy.ToyEncoder(8), toy.ACTION_DIM)
    state = learner.init(jax.random.key(0), toy.observe(toy.reset(jax.random.key(0), 4)))
    update = jax.jit(learner.update)
    after, _ = update(state, rollout, jax.random.key(3))
    toy.assert_trees_equal(learner.behaviour_params(after), after.params)
    weight = float(ema_weight(jnp.int32(0), 0.9))  # the first update moves the average most of the way
    expected = jax.tree.map(lambda new, old: weight * new + (1 - weight) * old, after.params, state.params)
    chex.assert_trees_all_close(learner.policy_params(after), expected, rtol=1e-5, atol=1e-7)
    for i in range(5):
        after, _ = update(after, rollout, jax.random.key(10 + i))
    raw, average = learner.behaviour_params(after), learner.policy_params(after)
    assert not np.allclose(raw.policy["params"]["loc_head"]["kernel"], average.policy["params"]["loc_head"]["kernel"])
    plain = make_learner("ppo", CONFIG, lambda: toy.ToyEncoder(8), toy.ACTION_DIM)  # ema_decay 0: one set
    plain_state = plain.init(jax.random.key(0), toy.observe(toy.reset(jax.random.key(0), 4)))
    assert plain.policy_params(plain_state) is plain_state.params and plain_state.ema_params is None


def test_update_rejects_a_rollout_that_does_not_split_into_minibatches(setup):
    learner, state, rollout = setup
    odd = jax.tree.map(lambda x: x[:11, :3], rollout)  # 33 transitions for 4 minibatches
    with pytest.raises(ValueError, match="minibatches"):
        learner.update(state, odd, jax.random.key(0))


@pytest.mark.parametrize("active_minibatch_size", [0, 128])
def test_ppo_learns_the_toy_task(active_minibatch_size):
    config = get_config("ppo", "debug", gamma=GAMMA, learning_rate=3e-4, num_minibatches=4, num_epochs=4,
                        active_minibatch_size=active_minibatch_size)
    learner = make_learner("ppo", config, lambda: toy.ToyEncoder(32), toy.ACTION_DIM)
    state, metrics = toy.train_on_policy(learner, jax.random.key(0), num_envs=32, unroll_length=16,
                                         num_updates=200, pass_bootstrap=False)
    params = learner.policy_params(state)
    trained = toy.episode_return(lambda obs, key: learner.act(params, obs, key, True), jax.random.key(1))
    random = toy.episode_return(toy.random_policy, jax.random.key(1))
    assert all(bool(jnp.isfinite(m)) for m in metrics.values())
    assert random < -15.0
    assert trained > -4.0, (float(trained), float(random))

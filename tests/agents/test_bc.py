"""BC and BC+SAC: the imitation loss on hand values, BC learning the toy expert, and BC+SAC's schedule."""

import math

import chex
import flax.struct
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.agents import toy
from vmax_sim.agents import Transition, get_config, make_learner
from vmax_sim.agents import distributions as D
from vmax_sim.agents.bc import losses as bc_losses
from vmax_sim.agents.bc_sac.losses import bc_weight_at, make_actor_loss
from vmax_sim.agents.sac.losses import make_losses
from vmax_sim.agents.sac.networks import make_networks


def test_bc_negative_log_likelihood_hand_value():
    # one 1-D sample: pre-tanh N(0, 1), expert action tanh(0.5):
    # -log p = 0.125 + 0.5 log(2 pi) + log(1 - tanh(0.5)^2)
    dist = D.TanhGaussian(loc=jnp.zeros((1, 1)), log_std=jnp.zeros((1, 1)))
    expert = jnp.full((1, 1), math.tanh(0.5))
    expected = 0.125 + 0.5 * math.log(2 * math.pi) + math.log(1 - math.tanh(0.5) ** 2)
    np.testing.assert_allclose(bc_losses.nll_loss(dist, expert, 1e-3), expected, rtol=1e-5)
    # the mode MSE: (tanh(0) - tanh(0.5))^2; the weighted sum
    np.testing.assert_allclose(bc_losses.mode_mse_loss(dist, expert), math.tanh(0.5) ** 2, rtol=1e-6)
    loss, metrics = bc_losses.bc_loss(dist, expert, nll_weight=1.0, mse_weight=0.5, eps=1e-3)
    np.testing.assert_allclose(loss, expected + 0.5 * math.tanh(0.5) ** 2, rtol=1e-5)
    np.testing.assert_allclose(metrics["bc_mae"], math.tanh(0.5), rtol=1e-6)


def _fitted_mode(labels: jax.Array, likelihood: str) -> float:
    """tanh(loc) of one (loc, log_std) fitted by Adam to labels (N,) with BC's likelihood."""
    import optax

    params, optimizer = jnp.zeros(2), optax.adam(0.05)

    def loss(p):
        dist = D.TanhGaussian(loc=jnp.full((len(labels), 1), p[0]), log_std=jnp.full((len(labels), 1), p[1]))
        return bc_losses.nll_loss(dist, labels[:, None], 1e-3, likelihood=likelihood)

    def step(carry, _):
        p, state = carry
        updates, state = optimizer.update(jax.grad(loss)(p), state)
        return (optax.apply_updates(p, updates), state), None

    (params, _), _ = jax.lax.scan(step, (params, optimizer.init(params)), None, length=3000)
    return float(jnp.tanh(params[0]))


def test_laplace_likelihood_follows_the_typical_label_where_rare_hard_brakes_pull_the_gaussian_down():
    # states that look alike: the teacher accelerates gently at nine of ten and brakes hard at one
    labels = jnp.array([0.1] * 9 + [-0.9])
    assert _fitted_mode(labels, "laplace") == pytest.approx(0.1, abs=0.01)
    assert _fitted_mode(labels, "gaussian") < 0.0  # the mean of the atanh labels: the student would slow down
    with pytest.raises(ValueError, match="likelihood must be one of gaussian, laplace"):
        get_config("bc", likelihood="student-t")


def test_bc_clips_expert_actions_on_the_bounds():
    dist = D.TanhGaussian(loc=jnp.zeros((2, 1)), log_std=jnp.zeros((2, 1)))
    at_bound = bc_losses.nll_loss(dist, jnp.array([[1.0], [-1.0]]), 1e-3)
    inside = bc_losses.nll_loss(dist, jnp.array([[1 - 1e-3], [-1 + 1e-3]]), 1e-3)
    assert bool(jnp.isfinite(at_bound))
    np.testing.assert_allclose(at_bound, inside, rtol=1e-6)


def test_bc_row_weights_hand_value_and_standing_rows():
    # two rows: -log p and the squared error of each, then their means weighted 3 : 1
    dist = D.TanhGaussian(loc=jnp.zeros((2, 1)), log_std=jnp.zeros((2, 1)))
    expert = jnp.array([[math.tanh(0.5)], [0.0]])
    per_row = [0.125 + 0.5 * math.log(2 * math.pi) + math.log(1 - math.tanh(0.5) ** 2), 0.5 * math.log(2 * math.pi)]
    weights = jnp.array([3.0, 1.0])
    loss, metrics = bc_losses.bc_loss(dist, expert, mse_weight=1.0, weights=weights)
    np.testing.assert_allclose(metrics["bc_nll"], (3 * per_row[0] + per_row[1]) / 4, rtol=1e-5)
    np.testing.assert_allclose(metrics["bc_mse"], 3 * math.tanh(0.5) ** 2 / 4, rtol=1e-5)
    np.testing.assert_allclose(loss, metrics["bc_nll"] + metrics["bc_mse"], rtol=1e-6)
    # standing is read from the SDC's velocity now (last history step), not from an older step; a standing row
    # whose label moves off weighs pull_away_weight, one whose label holds standing_weight
    sdc = jnp.zeros((4, 2, 6)).at[0, -1, 2].set(0.01).at[1, -1, 3].set(0.03).at[2, 0, 2].set(0.5)
    labels = jnp.array([[0.0, 0.0], [0.3, 0.0], [0.0, 0.0], [0.3, 0.0]])
    np.testing.assert_allclose(bc_losses.row_weights(sdc, labels, 0.5 / 30, 4.0, 0.05, 7.0), [4, 1, 4, 7])
    # a moving row whose label brakes (below braking_accel) weighs braking_weight; a standing one whose label brakes
    # holds (standing_weight), and a moving one that brakes gently weighs 1
    braking = jnp.array([[-0.5, 0.0], [-0.5, 0.0], [-0.1, 0.0], [0.3, 0.0]])
    np.testing.assert_allclose(bc_losses.row_weights(sdc, braking, 0.5 / 30, 4.0, 0.05, 7.0, -0.2, 5.0),
                               [4, 5, 4, 7])


@flax.struct.dataclass
class _SdcOnly:
    sdc: jax.Array  # (B, 1, 6) the SDC's features now


def _fitted_mean_action(batch: Transition, **weights) -> float:
    """The mean deterministic action of a 1-D BC policy fitted for 300 steps to `batch` with the row weights given."""
    config = get_config("bc", "debug", learning_rate=1e-3, **weights)
    learner = make_learner("bc", config, lambda: toy.ToyEncoder(8), 1)
    state = learner.init(jax.random.key(0), batch.obs)
    keys = jax.random.split(jax.random.key(1), 300)
    state, _ = jax.lax.scan(lambda s, k: learner.update(s, batch, k), state, keys)
    return float(jnp.mean(learner.act(learner.policy_params(state), batch.obs, jax.random.key(0), True)))


def test_bc_pull_away_weight_pulls_the_fit_towards_the_standing_labels():
    # rows that look nearly alike, half standing (0.3 m/s) labelled +0.5 (moving off), half moving (0.9 m/s)
    # labelled -0.5: with the moving-off rows weighted 9 : 1 the policy's actions there lean to their label; weighting
    # the standing rows that hold (none here) or none at all leans to neither
    size = 64
    moving = jnp.arange(size) % 2 == 1
    sdc = jnp.zeros((size, 1, 6)).at[:, 0, 2].set(jnp.where(moving, 0.9, 0.3) / 30)
    batch = Transition.make(obs=_SdcOnly(sdc=sdc), action=jnp.zeros((size, 1)), reward=jnp.zeros(size),
                            discount=jnp.ones(size), next_obs=_SdcOnly(sdc=sdc),
                            expert_action=jnp.where(moving, -0.5, 0.5)[:, None])

    plain = _fitted_mean_action(batch)
    assert abs(plain) < 0.15
    assert _fitted_mean_action(batch, pull_away_weight=9.0) > plain + 0.2
    np.testing.assert_allclose(_fitted_mean_action(batch, standing_weight=9.0), plain, atol=1e-5)
    with pytest.raises(ValueError, match="pull_away_weight"):
        get_config("bc", "debug", pull_away_weight=0.0)


def test_bc_braking_weight_pulls_the_fit_towards_the_braking_labels():
    # moving rows that look alike, a quarter labelled -0.6 (the teacher brakes), the rest +0.2: weighting the braking
    # rows 9 : 1 brings the fitted action from the rows' mean towards the brake
    size = 64
    brakes = jnp.arange(size) % 4 == 0
    sdc = jnp.zeros((size, 1, 6)).at[:, 0, 2].set(8.0 / 30)
    labels = jnp.where(brakes, -0.6, 0.2)[:, None]
    batch = Transition.make(obs=_SdcOnly(sdc=sdc), action=jnp.zeros((size, 1)), reward=jnp.zeros(size),
                            discount=jnp.ones(size), next_obs=_SdcOnly(sdc=sdc), expert_action=labels)

    plain = _fitted_mean_action(batch)
    assert plain > -0.1  # the unweighted fit sits near the rows' mean (0.0) or above it
    assert _fitted_mean_action(batch, braking_weight=9.0) < plain - 0.2
    with pytest.raises(ValueError, match="braking_weight"):
        get_config("bc", "debug", braking_weight=-1.0)


def test_bc_learns_the_toy_expert():
    config = get_config("bc", "debug", learning_rate=1e-3)
    learner = make_learner("bc", config, lambda: toy.ToyEncoder(32), toy.ACTION_DIM)
    state = learner.init(jax.random.key(0), toy.observe(toy.reset(jax.random.key(0), 2)))

    @jax.jit
    def train(state):
        def body(state, key):
            return learner.update(state, toy.random_batch(key, 128), key)
        return jax.lax.scan(body, state, jax.random.split(jax.random.key(1), 1000))

    state, metrics = train(state)
    held_out = toy.random_batch(jax.random.key(5), 1000)
    params = learner.policy_params(state)
    action = learner.act(params, held_out.obs, jax.random.key(0), True)
    assert float(jnp.mean(jnp.abs(action - held_out.expert_action))) < 0.03
    assert float(metrics["bc_nll"][-1]) < float(metrics["bc_nll"][0]) - 2.0
    closed_loop = toy.episode_return(lambda obs, key: learner.act(params, obs, key, True), jax.random.key(1))
    assert closed_loop > -0.5  # the expert scores about -0.1, a random policy about -23


def test_bc_masked_rows_do_not_change_the_update():
    """Self-play's replay holds its empty and finished agent slots too (mask 0): whatever labels those rows hold,
    the update is the one of the real rows alone, and a batch of masked rows only leaves the loss finite."""
    learner = make_learner("bc", get_config("bc", "debug"), lambda: toy.ToyEncoder(32), toy.ACTION_DIM)
    state = learner.init(jax.random.key(0), toy.observe(toy.reset(jax.random.key(0), 2)))
    batch = toy.random_batch(jax.random.key(2), 64)
    mask = (jnp.arange(64) % 3 != 0).astype(jnp.float32)
    masked = batch.replace(mask=mask)
    garbage = masked.replace(expert_action=jnp.where(mask[:, None] > 0, batch.expert_action, -0.99))
    update = jax.jit(learner.update)
    first, metrics = update(state, masked, jax.random.key(3))
    second, metrics_garbage = update(state, garbage, jax.random.key(3))
    toy.assert_trees_equal(first.policy_params, second.policy_params)
    assert float(metrics["bc_nll"]) == float(metrics_garbage["bc_nll"])
    unmasked, _ = update(state, garbage.replace(mask=jnp.ones(64)), jax.random.key(3))  # the labels do count
    assert not all(bool(jnp.all(a == b)) for a, b in zip(jax.tree.leaves(unmasked.policy_params),
                                                           jax.tree.leaves(first.policy_params), strict=True))
    _, empty = update(state, batch.replace(mask=jnp.zeros(64)), jax.random.key(3))
    assert math.isfinite(float(empty["bc_nll"]))


def test_bc_moving_average_is_the_policy_that_acts():
    from vmax_sim.agents.common import ema_weight
    config = get_config("bc", "debug", learning_rate=1e-3, ema_decay=0.99)
    learner = make_learner("bc", config, lambda: toy.ToyEncoder(32), toy.ACTION_DIM)
    state = learner.init(jax.random.key(0), toy.observe(toy.reset(jax.random.key(0), 2)))
    np.testing.assert_allclose(float(ema_weight(jnp.int32(0), 0.99)), 0.9, rtol=1e-6)  # leaves the init at once
    np.testing.assert_allclose(float(ema_weight(jnp.int32(10_000), 0.99)), 0.01, rtol=1e-6)
    update = jax.jit(learner.update)
    raw_first = None
    for i in range(300):
        state, _ = update(state, toy.random_batch(jax.random.key(i), 128), jax.random.key(i))
        if i == 0:
            raw_first = state.policy_params
    leaves = jax.tree.leaves
    # the acting parameters are the average, not the last step's, and the average follows the steps
    assert all(bool(jnp.all(a == b)) for a, b in zip(leaves(learner.policy_params(state)), leaves(state.ema_params)))
    assert any(bool(jnp.any(a != b)) for a, b in zip(leaves(state.ema_params), leaves(state.policy_params)))
    assert any(bool(jnp.any(a != b)) for a, b in zip(leaves(state.ema_params), leaves(raw_first)))
    held_out = toy.random_batch(jax.random.key(5), 1000)
    action = learner.act(learner.policy_params(state), held_out.obs, jax.random.key(0), True)
    assert float(jnp.mean(jnp.abs(action - held_out.expert_action))) < 0.1
    # without a decay there is no average and the raw parameters act
    plain = make_learner("bc", get_config("bc", "debug"), lambda: toy.ToyEncoder(32), toy.ACTION_DIM)
    plain_state = plain.init(jax.random.key(0), toy.observe(toy.reset(jax.random.key(0), 2)))
    assert plain_state.ema_params is None and plain.policy_params(plain_state) is plain_state.policy_params
    with pytest.raises(ValueError, match="ema_decay"):
        get_config("bc", "debug", ema_decay=1.0)


def test_bc_learning_rate_share_scales_each_step():
    """With `lr_end_fraction` < 1 the state carries the learning rate's share: 0 leaves the policy where it is,
    0.5 takes half of Adam's step; a constant rate keeps the state's old layout (no share)."""
    from vmax_sim.agents.common import learning_rate_scale
    assert [learning_rate_scale(p, 0.5, 0.1) for p in (0.0, 0.5, 0.75, 1.0, 1.2)] == pytest.approx(
        [1.0, 1.0, 0.55, 0.1, 0.1])
    config = get_config("bc", "debug", learning_rate=1e-3, lr_end_fraction=0.1)
    learner = make_learner("bc", config, lambda: toy.ToyEncoder(32), toy.ACTION_DIM)
    state = learner.init(jax.random.key(0), toy.observe(toy.reset(jax.random.key(0), 2)))
    assert float(state.lr_scale) == 1.0
    batch, update, leaves = toy.random_batch(jax.random.key(1), 128), jax.jit(learner.update), jax.tree.leaves
    full, _ = update(state, batch, jax.random.key(0))
    half, _ = update(state.replace(lr_scale=jnp.float32(0.5)), batch, jax.random.key(0))
    still, _ = update(state.replace(lr_scale=jnp.float32(0.0)), batch, jax.random.key(0))
    for start, a, b, c in zip(leaves(state.policy_params), leaves(full.policy_params), leaves(half.policy_params),
                              leaves(still.policy_params)):
        np.testing.assert_allclose(b - start, 0.5 * (a - start), atol=1e-7)
        np.testing.assert_array_equal(c, start)
    plain = make_learner("bc", get_config("bc", "debug"), lambda: toy.ToyEncoder(32), toy.ACTION_DIM)
    assert not hasattr(plain.init(jax.random.key(0), toy.observe(toy.reset(jax.random.key(0), 2))), "lr_scale")
    with pytest.raises(ValueError, match="lr_end_fraction"):
        get_config("bc", "debug", lr_end_fraction=1.5)
    with pytest.raises(ValueError, match="lr_decay_start"):
        get_config("bc", "debug", lr_decay_start=1.0)


def _member(tree, m: int):
    """Member `m` of a pytree whose leaves carry a leading member axis (M, ...)."""
    return jax.tree.map(lambda leaf: leaf[m], tree)


def test_bc_members_learn_apart_and_act_as_one():
    """`members` M: M students from their own initialisations, each stepping on its own minibatch of the batch (its
    step the one a single student takes on that minibatch), acting with the mean of their actions."""
    obs_example = toy.observe(toy.reset(jax.random.key(0), 2))
    single = make_learner("bc", get_config("bc", "debug", learning_rate=1e-3), lambda: toy.ToyEncoder(16),
                          toy.ACTION_DIM)
    pair = make_learner("bc", get_config("bc", "debug", learning_rate=1e-3, members=2), lambda: toy.ToyEncoder(16),
                        toy.ACTION_DIM)
    state = pair.init(jax.random.key(0), obs_example)
    leaves = jax.tree.leaves
    assert all(leaf.shape[0] == 2 for leaf in leaves(state.policy_params))
    assert any(bool(jnp.any(leaf[0] != leaf[1])) for leaf in leaves(state.policy_params))  # their own initialisations
    batch = toy.random_batch(jax.random.key(1), 2 * 32)  # one minibatch of 32 per member
    stepped, metrics = jax.jit(pair.update)(state, batch, jax.random.key(2))
    for member in range(2):
        alone_state = state.replace(policy_params=_member(state.policy_params, member),
                                    opt_state=_member(state.opt_state, member))
        rows = jax.tree.map(lambda leaf, m=member: leaf[32 * m:32 * (m + 1)], batch)
        alone, _ = jax.jit(single.update)(alone_state, rows, jax.random.key(2))
        for got, want in zip(leaves(_member(stepped.policy_params, member)), leaves(alone.policy_params)):
            np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-7)
    assert metrics["bc_loss"].shape == ()
    held_out = toy.random_batch(jax.random.key(5), 8)
    key, params = jax.random.key(0), pair.policy_params(stepped)
    each = [single.act(_member(params, m), held_out.obs, key, True) for m in range(2)]
    np.testing.assert_allclose(pair.act(params, held_out.obs, key, True), np.mean(each, axis=0), rtol=1e-5,
                               atol=1e-7)

    @jax.jit
    def train(state):  # and together they learn the toy expert as one student does
        return jax.lax.scan(lambda s, k: pair.update(s, toy.random_batch(k, 2 * 128), k), state,
                            jax.random.split(jax.random.key(1), 1000))

    params = pair.policy_params(train(pair.init(jax.random.key(0), obs_example))[0])
    action = pair.act(params, toy.random_batch(jax.random.key(5), 1000).obs, key, True)
    assert float(jnp.mean(jnp.abs(action - toy.random_batch(jax.random.key(5), 1000).expert_action))) < 0.03
    with pytest.raises(ValueError, match="members"):
        get_config("bc", "debug", members=0)


def test_cautious_bc_members_accelerate_with_the_smallest_and_steer_with_the_mean():
    """`member_rule=cautious`: the members' actions combine as the mean with the smallest component 0 (acceleration)."""
    obs_example = toy.observe(toy.reset(jax.random.key(0), 2))
    single = make_learner("bc", get_config("bc", "debug"), lambda: toy.ToyEncoder(16), toy.ACTION_DIM)
    pair = make_learner("bc", get_config("bc", "debug", members=2, member_rule="cautious"),
                        lambda: toy.ToyEncoder(16), toy.ACTION_DIM)
    params = pair.policy_params(pair.init(jax.random.key(0), obs_example))
    obs, key = toy.random_batch(jax.random.key(5), 64).obs, jax.random.key(0)
    each = np.stack([single.act(_member(params, m), obs, key, True) for m in range(2)])
    assert np.min(np.abs(each[0, :, 0] - each[1, :, 0])) > 1e-4  # the smallest is not the mean anywhere
    acted = pair.act(params, obs, key, True)
    np.testing.assert_allclose(acted[:, 0], each[:, :, 0].min(axis=0), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(acted[:, 1:], each[:, :, 1:].mean(axis=0), rtol=1e-5, atol=1e-7)
    with pytest.raises(ValueError, match="member_rule"):
        get_config("bc", "debug", member_rule="vote")


def test_bc_sac_schedule():
    steps = jnp.arange(6)
    np.testing.assert_allclose(jax.vmap(lambda s: bc_weight_at(s, 2, 0.7))(steps), [0.7, 0, 0.7, 0, 0.7, 0],
                               rtol=1e-6)
    np.testing.assert_allclose(jax.vmap(lambda s: bc_weight_at(s, 1, 0.3))(steps), [0.3] * 6, rtol=1e-6)


def test_bc_sac_actor_loss_is_sac_plus_weighted_bc_on_schedule():
    config = get_config("bc_sac", "debug", bc_every=3, bc_weight=0.5, policy_hidden_sizes=(8,),
                        value_hidden_sizes=(8,))
    batch = toy.random_batch(jax.random.key(0), 16)
    networks = make_networks(config, lambda: toy.ToyEncoder(4), 1)
    sac = make_losses(networks, config)
    actor_loss = make_actor_loss(networks, sac, config)
    actor_params = networks.actor.init(jax.random.key(1), batch.obs)
    critic_params = networks.critic.init(jax.random.key(2), batch.obs, batch.action)
    key, alpha = jax.random.key(3), jnp.float32(0.2)

    @jax.jit
    def losses(step):
        total, (log_prob, metrics) = actor_loss(actor_params, critic_params, alpha, batch, key, step)
        rl, _ = sac.actor(actor_params, critic_params, alpha, batch, key)
        bc, _ = bc_losses.bc_loss(networks.actor.apply(actor_params, batch.obs), batch.expert_action,
                                  eps=config.expert_action_eps)
        return total, rl, bc, metrics["bc_weight"]

    total, rl, bc, weight = losses(jnp.int32(3))
    np.testing.assert_allclose(total, rl + 0.5 * bc, rtol=1e-5)
    assert float(weight) == 0.5
    total, rl, _, weight = losses(jnp.int32(4))
    np.testing.assert_allclose(total, rl, rtol=1e-6)
    assert float(weight) == 0.0


@pytest.mark.parametrize("algo", ["bc", "bc_sac"])
def test_update_deterministic_and_no_retrace(algo):
    config = get_config(algo, "debug", policy_hidden_sizes=(8,), **({} if algo == "bc" else
                                                                    {"value_hidden_sizes": (8,)}))
    learner = make_learner(algo, config, lambda: toy.ToyEncoder(8), 1)
    batch = toy.random_batch(jax.random.key(0), 16)
    state = learner.init(jax.random.key(0), batch.obs)
    update = jax.jit(chex.assert_max_traces(learner.update, n=1))
    first, metrics = update(state, batch, jax.random.key(1))
    again, metrics_again = update(state, batch, jax.random.key(1))
    toy.assert_trees_equal((first, metrics), (again, metrics_again))
    for i in range(3):
        first, metrics = update(first, toy.random_batch(jax.random.key(i), 16), jax.random.key(i))
    assert int(first.step) == 4
    assert "bc_loss" in metrics
    assert all(m.shape == () and m.dtype == jnp.float32 and bool(jnp.isfinite(m)) for m in metrics.values())

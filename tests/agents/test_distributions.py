"""Tanh-Gaussian: closed forms, a numerical density check and the stable Jacobian."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

from vmax_sim.agents import distributions as D


def test_stable_jacobian_matches_naive_form_and_stays_finite():
    u = jnp.linspace(-5.0, 5.0, 101)[:, None]
    naive = jnp.log(1.0 - jnp.tanh(u) ** 2)[:, 0]
    np.testing.assert_allclose(D.tanh_log_det_jacobian(u), naive, rtol=1e-4, atol=1e-5)
    far = D.tanh_log_det_jacobian(jnp.array([[30.0], [-30.0]]))  # naive form gives log(0) = -inf here
    np.testing.assert_allclose(far, [2 * (math.log(2) - 30.0)] * 2, rtol=1e-6)


def test_log_prob_hand_value():
    # u = 0.5 under N(0, 1): log N = -0.125 - 0.5 log(2 pi); log(1 - tanh(0.5)^2) subtracted.
    dist = D.TanhGaussian(loc=jnp.zeros((1, 1)), log_std=jnp.zeros((1, 1)))
    expected = -0.125 - 0.5 * math.log(2 * math.pi) - math.log(1 - math.tanh(0.5) ** 2)
    np.testing.assert_allclose(D.log_prob(dist, jnp.full((1, 1), math.tanh(0.5))), [expected], rtol=1e-5)


@pytest.mark.parametrize("loc, std", [(0.0, 1.0), (0.7, 0.3), (-1.5, 1.2)])
def test_log_prob_is_the_derivative_of_the_cdf(loc, std):
    # P(tanh(u) <= a) = Phi((atanh(a) - loc) / std); its finite-difference derivative is the density.
    a = np.linspace(-0.95, 0.95, 39)
    h = 1e-4
    cdf = lambda x: stats.norm.cdf((np.arctanh(x) - loc) / std)  # noqa: E731
    numeric = (cdf(a + h) - cdf(a - h)) / (2 * h)
    dist = D.TanhGaussian(loc=jnp.full((a.size, 1), loc), log_std=jnp.full((a.size, 1), math.log(std)))
    ours = np.exp(np.asarray(D.log_prob(dist, jnp.asarray(a, jnp.float32)[:, None]), np.float64))
    np.testing.assert_allclose(ours, numeric, rtol=2e-3, atol=1e-5)


def test_density_integrates_to_one():
    a = np.linspace(-1 + 1e-6, 1 - 1e-6, 200_001)
    dist = D.TanhGaussian(loc=jnp.full((a.size, 1), 0.3), log_std=jnp.full((a.size, 1), math.log(0.8)))
    density = np.exp(np.asarray(D.log_prob(dist, jnp.asarray(a, jnp.float32)[:, None]), np.float64))
    assert abs(np.trapezoid(density, a) - 1.0) < 2e-3


def test_laplace_density_integrates_to_one_and_hand_value():
    a = np.linspace(-1 + 1e-6, 1 - 1e-6, 200_001)
    spread = D.TanhGaussian(loc=jnp.full((a.size, 1), 0.3), log_std=jnp.full((a.size, 1), math.log(0.4)))
    density = np.exp(np.asarray(D.log_prob(spread, jnp.asarray(a, jnp.float32)[:, None], family="laplace"),
                                np.float64))
    assert abs(np.trapezoid(density, a) - 1.0) < 2e-3
    # at the pre-tanh location: log(1 / (2 b)) - log(1 - tanh(0.3)^2)
    dist = D.TanhGaussian(loc=jnp.array([[0.3]]), log_std=jnp.log(jnp.array([[0.4]])))
    at_loc = D.log_prob(dist, jnp.tanh(jnp.array([[0.3]])), family="laplace")
    np.testing.assert_allclose(at_loc, [math.log(1 / 0.8) - math.log(1 - math.tanh(0.3) ** 2)], rtol=1e-5)


def test_sample_log_prob_agrees_with_log_prob_of_the_action_and_sums_over_dims():
    key = jax.random.key(0)
    dist = D.TanhGaussian(loc=jnp.array([[0.2, -0.4, 1.0]] * 64), log_std=jnp.array([[-0.5, 0.0, -1.0]] * 64))
    action, log_p = D.sample_and_log_prob(dist, key)
    assert action.shape == (64, 3) and log_p.shape == (64,)
    assert jnp.all(jnp.abs(action) <= 1.0)
    np.testing.assert_allclose(log_p, D.log_prob(dist, action), rtol=1e-3, atol=1e-3)
    per_dim = [D.log_prob(D.TanhGaussian(dist.loc[:, i:i + 1], dist.log_std[:, i:i + 1]), action[:, i:i + 1])
               for i in range(3)]
    np.testing.assert_allclose(sum(per_dim), D.log_prob(dist, action), rtol=1e-5, atol=1e-5)


def test_log_prob_of_saturated_action_is_finite():
    dist = D.TanhGaussian(loc=jnp.zeros((2, 1)), log_std=jnp.zeros((2, 1)))
    assert jnp.all(jnp.isfinite(D.log_prob(dist, jnp.array([[1.0], [-1.0]]))))


def test_mode_entropy_and_sample_entropy():
    dist = D.TanhGaussian(loc=jnp.array([[0.3, -2.0]]), log_std=jnp.array([[math.log(0.5), math.log(2.0)]]))
    np.testing.assert_allclose(D.mode(dist), jnp.tanh(dist.loc))
    expected = stats.norm(scale=0.5).entropy() + stats.norm(scale=2.0).entropy()
    np.testing.assert_allclose(D.entropy(dist), [expected], rtol=1e-6)
    # the squashed entropy is the Gaussian one plus E[log(1 - tanh^2)] <= 0
    many = D.TanhGaussian(jnp.repeat(dist.loc, 20_000, 0), jnp.repeat(dist.log_std, 20_000, 0))
    estimate = jnp.mean(D.sample_entropy(many, jax.random.key(1)))
    assert estimate < expected


def test_sample_is_reparameterised():
    def mean_action(loc):
        return jnp.mean(D.sample(D.TanhGaussian(loc, jnp.full_like(loc, -3.0)), jax.random.key(0)))

    grad = jax.grad(mean_action)(jnp.zeros((8, 1)))
    np.testing.assert_allclose(grad, jnp.full((8, 1), 1 / 8), rtol=5e-2)  # d tanh(u)/du ~ 1 near 0

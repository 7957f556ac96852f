"""Tanh-squashed diagonal Gaussian policy distribution, written by hand.

a = tanh(u), u ~ N(loc, exp(log_std)^2) element-wise over the last axis (A). Densities are of the
squashed action a, so the change of variables subtracts log|da/du| = sum_i log(1 - tanh(u_i)^2),
computed in the stable form 2 * (log 2 - u - softplus(-2u)) that never takes the log of 0.

Why not distrax: it pulls in tensorflow-probability (and its pinned JAX ranges); the handful of
functions below is all the learners need and each is tested against closed forms and numerics.
"""

from __future__ import annotations

import math

import flax.struct
import jax
import jax.numpy as jnp

_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)
_LOG_2 = math.log(2.0)
DEFAULT_ACTION_EPS = 1e-6  # squashed actions are clipped to [-1 + eps, 1 - eps] before atanh


@flax.struct.dataclass
class TanhGaussian:
    """Parameters of the pre-tanh Gaussian."""

    loc: jax.Array  # (..., A)
    log_std: jax.Array  # (..., A)


def tanh_log_det_jacobian(pre_tanh: jax.Array) -> jax.Array:
    """sum_i log(1 - tanh(u_i)^2) over the last axis, stably: (..., A) -> (...)."""
    return jnp.sum(2.0 * (_LOG_2 - pre_tanh - jax.nn.softplus(-2.0 * pre_tanh)), axis=-1)


def gaussian_log_prob(loc: jax.Array, log_std: jax.Array, x: jax.Array) -> jax.Array:
    """log N(x; loc, exp(log_std)^2) summed over the last axis: (..., A) x3 -> (...)."""
    z = (x - loc) * jnp.exp(-log_std)
    return jnp.sum(-0.5 * jnp.square(z) - log_std - _HALF_LOG_2PI, axis=-1)


def laplace_log_prob(loc: jax.Array, log_scale: jax.Array, x: jax.Array) -> jax.Array:
    """log Laplace(x; loc, exp(log_scale)) summed over the last axis: (..., A) x3 -> (...). Fitted by maximum
    likelihood, loc follows the median of x, which rare far values (a teacher's hard brakes) do not pull."""
    return jnp.sum(-jnp.abs(x - loc) * jnp.exp(-log_scale) - log_scale - _LOG_2, axis=-1)


# the pre-tanh densities `log_prob` can read a TanhGaussian's (loc, log_std) as: their location and log scale
PRE_TANH_LOG_PROBS = {"gaussian": gaussian_log_prob, "laplace": laplace_log_prob}


def sample_pre_tanh(dist: TanhGaussian, key: jax.Array) -> jax.Array:
    """Reparameterised Gaussian sample u = loc + std * eps: (..., A)."""
    noise = jax.random.normal(key, dist.loc.shape, dist.loc.dtype)
    return dist.loc + jnp.exp(dist.log_std) * noise


def sample_and_log_prob(dist: TanhGaussian, key: jax.Array) -> tuple[jax.Array, jax.Array]:
    """A squashed sample a (..., A) and its exact log-density log p(a) (...), differentiable in the params."""
    pre_tanh = sample_pre_tanh(dist, key)
    log_prob = gaussian_log_prob(dist.loc, dist.log_std, pre_tanh) - tanh_log_det_jacobian(pre_tanh)
    return jnp.tanh(pre_tanh), log_prob


def sample(dist: TanhGaussian, key: jax.Array) -> jax.Array:
    """A squashed sample (..., A)."""
    return jnp.tanh(sample_pre_tanh(dist, key))


def mode(dist: TanhGaussian) -> jax.Array:
    """tanh(loc) (..., A): the deterministic action (the squashed Gaussian mean, not the exact mode)."""
    return jnp.tanh(dist.loc)


def log_prob(dist: TanhGaussian, action: jax.Array, eps: float = DEFAULT_ACTION_EPS,
             family: str = "gaussian") -> jax.Array:
    """log p(a) (...) of a given squashed action (..., A); a is clipped to [-1 + eps, 1 - eps] first. family: a
    PRE_TANH_LOG_PROBS key; "laplace" reads log_std as the Laplace log scale (tanh(loc) is then the median)."""
    clipped = jnp.clip(action, -1.0 + eps, 1.0 - eps)
    pre_tanh = jnp.arctanh(clipped)
    return PRE_TANH_LOG_PROBS[family](dist.loc, dist.log_std, pre_tanh) - tanh_log_det_jacobian(pre_tanh)


def entropy(dist: TanhGaussian) -> jax.Array:
    """Entropy of the pre-tanh Gaussian, sum_i (0.5 log(2 pi e) + log_std_i): (..., A) -> (...).

    The squashed entropy has no closed form; it equals this plus E[log(1 - tanh(u)^2)] (<= 0). The
    Gaussian entropy is deterministic and has no sampling noise, which is why PPO uses it by default.
    """
    return jnp.sum(0.5 + _HALF_LOG_2PI + dist.log_std, axis=-1)


def sample_entropy(dist: TanhGaussian, key: jax.Array) -> jax.Array:
    """One-sample estimate -log p(a) of the squashed entropy (...), unbiased, differentiable."""
    _, log_p = sample_and_log_prob(dist, key)
    return -log_p

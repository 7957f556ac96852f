"""Behaviour-cloning losses (B batch, A action dim).

    L_BC = nll_weight * mean_B(-log pi(a_E | s)) + mse_weight * mean_B sum_A (tanh(loc(s)) - a_E)^2

log pi is the tanh-Gaussian density of the expert action a_E, clipped to [-1 + eps, 1 - eps] first
(expert actions often sit on the bounds, where atanh is infinite).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.agents import distributions as D
from vmax_sim.agents.common import scalar
from vmax_sim.agents.types import Metrics


def nll_loss(dist: D.TanhGaussian, expert_action: jax.Array, eps: float) -> jax.Array:
    """mean_B -log pi(a_E | s): dist (B, A), expert_action (B, A) -> ()."""
    return -jnp.mean(D.log_prob(dist, expert_action, eps))


def mode_mse_loss(dist: D.TanhGaussian, expert_action: jax.Array) -> jax.Array:
    """mean_B sum_A (tanh(loc) - a_E)^2: -> ()."""
    return jnp.mean(jnp.sum(jnp.square(D.mode(dist) - expert_action), axis=-1))


def bc_loss(dist: D.TanhGaussian, expert_action: jax.Array, nll_weight: float = 1.0, mse_weight: float = 0.0,
            eps: float = 1e-3) -> tuple[jax.Array, Metrics]:
    """The weighted BC loss () and its metrics (bc_nll, bc_mse, bc_mae)."""
    nll = nll_loss(dist, expert_action, eps)
    mse = mode_mse_loss(dist, expert_action)
    loss = nll_weight * nll + mse_weight * mse
    metrics = {"bc_loss": scalar(loss), "bc_nll": scalar(nll), "bc_mse": scalar(mse),
               "bc_mae": scalar(jnp.mean(jnp.abs(D.mode(dist) - expert_action)))}
    return loss, metrics

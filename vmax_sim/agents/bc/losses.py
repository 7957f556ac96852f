"""Behaviour-cloning losses (B batch, A action dim).

    L_BC = nll_weight * mean_B(-log pi(a_E | s)) + mse_weight * mean_B sum_A (tanh(loc(s)) - a_E)^2

log pi is the tanh-Gaussian density of the expert action a_E (or with `likelihood="laplace"` the tanh-Laplace one,
whose mode follows the labels' median), clipped to [-1 + eps, 1 - eps] first (expert actions often sit on the
bounds, where atanh is infinite). With row weights w (B,) every mean_B is
the weighted one, sum_B w * x / sum_B w.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from vmax_sim.agents import distributions as D
from vmax_sim.agents.common import row_mean, scalar
from vmax_sim.agents.types import Metrics
from vmax_sim.observation.features import observed_sdc_speed


def nll_loss(dist: D.TanhGaussian, expert_action: jax.Array, eps: float, weights: jax.Array | None = None,
             likelihood: str = "gaussian") -> jax.Array:
    """mean_B -log pi(a_E | s): dist (B, A), expert_action (B, A), weights (B,) or None -> (). likelihood: the
    pre-tanh family (distributions.PRE_TANH_LOG_PROBS)."""
    return -row_mean(D.log_prob(dist, expert_action, eps, likelihood), weights)


def mode_mse_loss(dist: D.TanhGaussian, expert_action: jax.Array, weights: jax.Array | None = None) -> jax.Array:
    """mean_B sum_A (tanh(loc) - a_E)^2: -> ()."""
    return row_mean(jnp.sum(jnp.square(D.mode(dist) - expert_action), axis=-1), weights)


def bc_loss(dist: D.TanhGaussian, expert_action: jax.Array, nll_weight: float = 1.0, mse_weight: float = 0.0,
            eps: float = 1e-3, weights: jax.Array | None = None, likelihood: str = "gaussian"
            ) -> tuple[jax.Array, Metrics]:
    """The weighted BC loss () and its metrics (bc_nll, bc_mse, bc_mae: the row-weighted means)."""
    nll = nll_loss(dist, expert_action, eps, weights, likelihood)
    mse = mode_mse_loss(dist, expert_action, weights)
    loss = nll_weight * nll + mse_weight * mse
    metrics = {"bc_loss": scalar(loss), "bc_nll": scalar(nll), "bc_mse": scalar(mse),
               "bc_mae": scalar(row_mean(jnp.mean(jnp.abs(D.mode(dist) - expert_action), axis=-1), weights))}
    return loss, metrics


def row_weights(sdc_features: jax.Array, expert_action: jax.Array, standing_speed: float, standing_weight: float,
                pull_away_accel: float, pull_away_weight: float, braking_accel: float = -1.0,
                braking_weight: float = 1.0) -> jax.Array:
    """Row weights (B,): where the SDC stands (its speed now below standing_speed, both in the observation's
    normalised units), pull_away_weight if the label's acceleration is above pull_away_accel (the teacher moves
    off), else standing_weight; where it moves, braking_weight if the label's acceleration is below braking_accel
    (the teacher brakes), else 1. sdc_features (B, k, 6): the observation's SDC history, x, y, vx, vy, cos, sin,
    last = now; expert_action (B, A), acceleration first."""
    acceleration = expert_action[:, 0]
    standing = jnp.where(acceleration > pull_away_accel, pull_away_weight, standing_weight)
    moving = jnp.where(acceleration < braking_accel, braking_weight, 1.0)
    return jnp.where(observed_sdc_speed(sdc_features) < standing_speed, standing, moving)

"""Reward of one step as the weighted sum of its terms (pure, jittable, any leading batch dims)."""

from __future__ import annotations

import jax.numpy as jnp

from vmax_sim.metrics import MetricsConfig
from vmax_sim.metrics.config import DEFAULT_METRICS_CONFIG
from vmax_sim.rewards.config import RewardConfig
from vmax_sim.rewards.terms import Metrics, get_term


def check_reward_config(config: RewardConfig) -> None:
    """Raises a one-line ValueError for a term name that does not exist."""
    for name, _ in config.resolved():
        get_term(name)


def reward_terms(metrics: Metrics, previous: Metrics, config: RewardConfig,
                 metrics_config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> dict[str, jnp.ndarray]:
    """Every term the config uses, unweighted. metrics/previous: dicts of (...) arrays -> dict of (...)."""
    return {name: get_term(name)(metrics, previous, metrics_config) for name, _ in config.resolved()}


def compute_reward(metrics: Metrics, previous: Metrics, config: RewardConfig,
                   metrics_config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> jnp.ndarray:
    """sum_i weight_i * term_i. metrics/previous: dicts of (...) arrays -> (...) float32."""
    terms = reward_terms(metrics, previous, config, metrics_config)
    total = jnp.zeros_like(metrics["overlap"], jnp.float32)
    for name, weight in config.resolved():
        total = total + weight * terms[name]
    return total

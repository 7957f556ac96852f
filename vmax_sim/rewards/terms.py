"""Per-step reward terms: each reads the metrics the step already computed (`step_metrics`).

A term is `fn(metrics, previous, config) -> () float32`, where `metrics` is this step's
`step_metrics` dict, `previous` the one of the step before (the progress term compares them) and
`config` the `MetricsConfig` whose thresholds the step used. Terms are indicators (0 / 1) unless said
otherwise, so a reward is a weighted sum of them. Register a new term with `register_term`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import jax.numpy as jnp

from vmax_sim.metrics import MetricsConfig

Metrics = Mapping[str, jnp.ndarray]
RewardTermFn = Callable[[Metrics, Metrics, MetricsConfig], jnp.ndarray]


def _flag(name: str) -> RewardTermFn:
    def term(metrics: Metrics, previous: Metrics, config: MetricsConfig) -> jnp.ndarray:
        del previous, config
        return (metrics[name] > 0.5).astype(jnp.float32)
    term.__doc__ = f"1 when the step metric `{name}` fired."
    return term


def progress(metrics: Metrics, previous: Metrics, config: MetricsConfig) -> jnp.ndarray:
    """1 when the SDC moved forward along its route since the last step (progress(t) > progress(t-1))."""
    del config
    return (metrics["ego_progress"] > previous["ego_progress"]).astype(jnp.float32)


def comfortable(metrics: Metrics, previous: Metrics, config: MetricsConfig) -> jnp.ndarray:
    """1 when this step's longitudinal acceleration and yaw rate are inside nuPlan's comfort bounds.

    The episode comfort metric filters whole trajectories (Savitzky-Golay); a per-step reward can only
    see the finite differences of the last three positions, so jerk terms are left to the episode metric.
    """
    del previous
    accel, yaw_rate = metrics["accel"], metrics["yaw_rate"]
    inside = (accel >= config.min_lon_accel) & (accel <= config.max_lon_accel) & (
        jnp.abs(yaw_rate) <= config.max_abs_yaw_rate)
    return inside.astype(jnp.float32)


def overspeed(metrics: Metrics, previous: Metrics, config: MetricsConfig) -> jnp.ndarray:
    """1 when the SDC is faster than the speed limit of its lane (unknown limits never fire)."""
    del previous, config
    return (metrics["speed_violation"] > 0.0).astype(jnp.float32)


def speed(metrics: Metrics, previous: Metrics, config: MetricsConfig) -> jnp.ndarray:
    """The SDC's speed in m/s (not an indicator)."""
    del previous, config
    return metrics["speed"]


def log_divergence(metrics: Metrics, previous: Metrics, config: MetricsConfig) -> jnp.ndarray:
    """Distance in m between the simulated and the logged SDC (not an indicator)."""
    del previous, config
    return metrics["log_divergence"]


_TERMS: dict[str, RewardTermFn] = {
    "collision": _flag("overlap"),
    "offroad": _flag("offroad"),
    "red_light": _flag("red_light"),
    "off_route": _flag("off_route"),
    "wrong_way": _flag("wrong_way"),
    "at_fault_collision": _flag("at_fault_collision"),
    "ttc_violation": _flag("ttc_violation"),
    "kinematic_infeasibility": _flag("kinematic_infeasibility"),
    "multiple_lanes": _flag("multiple_lanes"),
    "progress": progress,
    "comfortable": comfortable,
    "overspeed": overspeed,
    "speed": speed,
    "log_divergence": log_divergence,
}


def register_term(name: str, fn: RewardTermFn) -> None:
    """Adds a reward term usable in `RewardConfig.weights` (the step and the loop need no change)."""
    if name in _TERMS:
        raise ValueError(f"reward term {name!r} exists already")
    _TERMS[name] = fn


def term_names() -> tuple[str, ...]:
    return tuple(sorted(_TERMS))


def get_term(name: str) -> RewardTermFn:
    try:
        return _TERMS[name]
    except KeyError:
        raise ValueError(f"unknown reward term {name!r}; choose among {', '.join(term_names())}") from None

"""Per-episode metrics and scores from the per-step metrics stacked over time."""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from vmax_sim.metrics.config import DEFAULT_METRICS_CONFIG, MetricsConfig


@functools.lru_cache(maxsize=32)
def savgol_derivative_matrix(num_steps: int, window: int, dt: float) -> np.ndarray:
    """(T, T) matrix D with D @ x = Savitzky-Golay first derivative (quadratic fit, 'interp' edges).

    Each row fits a quadratic to `window` samples (centred, or the first / last window at the
    edges, as scipy's mode='interp') and differentiates it at that row's sample.
    """
    window = min(window, num_steps if num_steps % 2 else num_steps - 1)
    d = np.zeros((num_steps, num_steps))
    if window < 3:  # too short to fit: one-sided differences
        for t in range(num_steps):
            a, b = max(t - 1, 0), min(t + 1, num_steps - 1)
            if b > a:
                d[t, a], d[t, b] = -1.0 / ((b - a) * dt), 1.0 / ((b - a) * dt)
        return d.astype(np.float32)
    half = window // 2
    for t in range(num_steps):
        start = int(np.clip(t - half, 0, num_steps - window))
        u = np.arange(window) - (t - start)
        vander = np.stack([np.ones(window), u, u * u], 1)
        d[t, start:start + window] = np.linalg.pinv(vander)[1] / dt
    return d.astype(np.float32)


def _unwrap(angle: jnp.ndarray) -> jnp.ndarray:
    """Continuous angle along time. (T,) -> (T,)."""
    step = (jnp.diff(angle) + jnp.pi) % (2 * jnp.pi) - jnp.pi
    return jnp.concatenate([angle[:1], angle[0] + jnp.cumsum(step)])


def comfort_signals(x: jnp.ndarray, y: jnp.ndarray, yaw: jnp.ndarray, valid: jnp.ndarray,
                    config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> dict[str, jnp.ndarray]:
    """nuPlan's six comfort signals over an episode, with the steps whose filter window touches an
    invalid step masked out. (T,) x4 -> dict of (T,) float32 plus "comfort_valid" (T,) bool."""
    num_steps = x.shape[0]
    d = jnp.asarray(savgol_derivative_matrix(num_steps, config.comfort_window, config.dt))
    support = (np.abs(savgol_derivative_matrix(num_steps, config.comfort_window, config.dt)) > 0).astype(np.float32)
    support3 = jnp.asarray(((support @ support @ support) > 0).astype(np.float32))
    ok = (support3 @ (~valid).astype(jnp.float32)) == 0
    xy = jnp.stack([x, y], -1)
    vel = d @ xy
    acc = d @ vel
    jerk = d @ acc
    heading = jnp.stack([jnp.cos(yaw), jnp.sin(yaw)], -1)
    left = jnp.stack([-heading[:, 1], heading[:, 0]], -1)
    yaw_rate = d @ _unwrap(yaw)
    return {
        "lon_accel": jnp.sum(acc * heading, -1), "lat_accel": jnp.sum(acc * left, -1),
        "lon_jerk": jnp.sum(jerk * heading, -1), "jerk": jnp.linalg.norm(jerk, axis=-1),
        "yaw_rate": yaw_rate, "yaw_accel": d @ yaw_rate, "comfort_valid": ok & valid,
    }


def comfort_score(signals: dict[str, jnp.ndarray], config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> jnp.ndarray:
    """1 when all six signals stay inside nuPlan's bounds on every checked step, else 0. -> ()."""
    ok = signals["comfort_valid"]
    inside = ((signals["lon_accel"] >= config.min_lon_accel) & (signals["lon_accel"] <= config.max_lon_accel)
              & (jnp.abs(signals["lat_accel"]) <= config.max_abs_lat_accel)
              & (jnp.abs(signals["lon_jerk"]) <= config.max_abs_lon_jerk)
              & (jnp.abs(signals["jerk"]) <= config.max_abs_jerk)
              & (jnp.abs(signals["yaw_rate"]) <= config.max_abs_yaw_rate)
              & (jnp.abs(signals["yaw_accel"]) <= config.max_abs_yaw_accel))
    return jnp.all(inside | ~ok).astype(jnp.float32)


def speed_limit_compliance(violation: jnp.ndarray, valid: jnp.ndarray,
                           config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> jnp.ndarray:
    """nuPlan: max(0, 1 - dt * sum(overspeed) / (2.23 m/s * duration)), duration = dt * (T - 1)."""
    num = jnp.sum(valid)
    duration = config.dt * (num - 1)
    loss = config.dt * jnp.sum(jnp.where(valid, violation, 0.0)) / (max(config.max_overspeed, 1e-3)
                                                                    * jnp.maximum(duration, 1e-6))
    return jnp.where(num > 1, jnp.maximum(0.0, 1.0 - loss), 1.0)


def driving_direction_score(lane_progress: jnp.ndarray, valid: jnp.ndarray,
                            config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> tuple[jnp.ndarray, jnp.ndarray]:
    """Worst distance driven against the lane within any 1 s window -> (score 0 / 0.5 / 1, metres)."""
    n = max(round(config.direction_window_s / config.dt), 1)
    progress = jnp.where(valid, lane_progress, 0.0)
    cum = jnp.concatenate([jnp.zeros(1), jnp.cumsum(progress)])
    window_sum = cum[n:] - cum[:-n] if progress.shape[0] >= n else cum[-1:] - cum[:1]
    against = jnp.maximum(-jnp.min(window_sum), 0.0)
    score = jnp.where(against >= config.direction_fail_m, 0.0,
                      jnp.where(against >= config.direction_warn_m, 0.5, 1.0))
    return score, against


def multiple_lanes_score(time_s: jnp.ndarray, config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> jnp.ndarray:
    """1 if at most 3.4 s on several lanes, 0.5 if at most 5.7 s, else 0."""
    return jnp.where(time_s <= config.multiple_lanes_ok_s, 1.0,
                     jnp.where(time_s <= config.multiple_lanes_warn_s, 0.5, 0.0))


def _weighted(episode: dict, weights) -> jnp.ndarray:
    total = sum(w for _, w in weights)
    return sum(w * episode[k] for k, w in weights) / total


def nuplan_score(episode: dict[str, jnp.ndarray], config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> jnp.ndarray:
    """nuPlan: (no at-fault collision x drivable area x making progress x driving direction)
    x (5 TTC + 5 progress + 4 speed limit + 2 comfort) / 16. Works on () or (E,) entries."""
    multiplier = ((1.0 - episode["at_fault_collision"]) * (1.0 - episode["offroad"])
                  * episode["making_progress"] * episode["driving_direction"])
    return (multiplier * _weighted(episode, config.nuplan_weights)).astype(jnp.float32)


def vmax_score(episode: dict[str, jnp.ndarray], config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> jnp.ndarray:
    """V-Max: the nuPlan score with red light as another multiplier and the multiple-lanes score
    (weight 3) in the average: (5 TTC + 5 progress + 4 speed + 2 comfort + 3 lanes) / 19."""
    multiplier = ((1.0 - episode["at_fault_collision"]) * (1.0 - episode["offroad"]) * (1.0 - episode["red_light"])
                  * episode["making_progress"] * episode["driving_direction"])
    weights = tuple(config.nuplan_weights) + tuple(config.vmax_extra_weights)
    return (multiplier * _weighted(episode, weights)).astype(jnp.float32)


def _last_valid(values: jnp.ndarray, valid: jnp.ndarray) -> jnp.ndarray:
    last = jnp.max(jnp.where(valid, jnp.arange(values.shape[0]), 0))
    return values[last]


def episode_metrics(per_step: dict[str, jnp.ndarray], valid: jnp.ndarray | None = None,
                    config: MetricsConfig = DEFAULT_METRICS_CONFIG) -> dict[str, jnp.ndarray]:
    """Episode metrics from `step_metrics` outputs stacked over time (each (T,)). -> dict of () float32.

    valid (T,) marks the steps that belong to the episode (default all). vmap for batches.
    """
    num_steps = per_step["overlap"].shape[0]
    valid = jnp.ones(num_steps, bool) if valid is None else valid.astype(bool)

    def any_(key):
        return jnp.any(valid & (per_step[key] > 0.5)).astype(jnp.float32)

    comfort = comfort_signals(per_step["sdc_x"], per_step["sdc_y"], per_step["sdc_yaw"], valid, config)
    expert = _last_valid(per_step["expert_progress"], valid)
    ego = _last_valid(per_step["ego_progress"], valid)
    ego_ratio = jnp.where(expert > config.min_expert_progress, jnp.clip(ego / jnp.maximum(expert, 1e-6), 0.0, 1.0), 1.0)
    direction, against = driving_direction_score(per_step["lane_progress"], valid, config)
    lanes_time = jnp.sum(jnp.where(valid, per_step["multiple_lanes"], 0.0)) * config.dt
    out = {
        # Waymax set
        "overlap": any_("overlap"), "offroad": any_("offroad"), "wrong_way": any_("wrong_way"),
        "off_route": any_("off_route"), "kinematic_infeasibility": any_("kinematic_infeasibility"),
        "log_divergence": jnp.sum(jnp.where(valid, per_step["log_divergence"], 0.0)) / jnp.maximum(jnp.sum(valid), 1),
        "progress_ratio": _last_valid(per_step["progress_ratio"], valid),
        # nuPlan set
        "at_fault_collision": any_("at_fault_collision"),
        "ttc_within_bound": 1.0 - any_("ttc_violation"),
        "speed_limit_compliance": speed_limit_compliance(per_step["speed_violation"], valid, config),
        "ego_progress": ego_ratio,
        "making_progress": (ego_ratio >= config.min_progress_ratio).astype(jnp.float32),
        "driving_direction": direction, "distance_against_lane": against,
        "comfort": comfort_score(comfort, config),
        # V-Max additions
        "red_light": any_("red_light"),
        "multiple_lanes_time": lanes_time,
        "multiple_lanes_score": multiple_lanes_score(lanes_time, config),
    }
    out["nuplan_score"] = nuplan_score(out, config)
    out["vmax_score"] = vmax_score(out, config)
    out["accurate"] = (1.0 - out["overlap"]) * (1.0 - out["offroad"]) * (1.0 - out["red_light"])
    out["accurate_at_fault"] = (1.0 - out["at_fault_collision"]) * (1.0 - out["offroad"]) * (1.0 - out["red_light"])
    return {k: jnp.asarray(v, jnp.float32) for k, v in out.items()}


def aggregate_episodes(episodes: dict[str, jnp.ndarray]) -> dict[str, jnp.ndarray]:
    """Mean over episodes of every episode metric (each (E,)); scores are per episode, then averaged.

    Adds "accuracy" (share of episodes with no collision, off-road or red light) and
    "accuracy_at_fault" (the same with at-fault collisions only).
    """
    out = {k: jnp.mean(v) for k, v in episodes.items()}
    out["accuracy"] = out.pop("accurate")
    out["accuracy_at_fault"] = out.pop("accurate_at_fault")
    return out
